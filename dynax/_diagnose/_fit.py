r"""Batched simulation-error fits of a nominal model plus candidate terms (one `vmap` over candidates).

All candidates live in one `Extended` model at their neutral values; a *configuration* says which
of them are active: up to `n_slots` already selected terms plus one new candidate. Because a term
at its neutral value is the nominal model, every configuration has the same structure, and the
fits of all candidates of a forward-selection round run as one `vmap`ped, jit-compiled
Levenberg-Marquardt solve (compiled once for the whole diagnosis).

The cost is the output error of open-loop rollouts on windows of the record, each started from
the measured state (internal states of input terms driven by the input history before the window),
scaled per state by the data's spread.

??? cite

    K. Levenberg, "A method for the solution of certain non-linear problems in least squares",
    Quarterly of Applied Mathematics 2, 1944; D. W. Marquardt, "An algorithm for least-squares
    estimation of nonlinear parameters", SIAM J. Applied Mathematics 11(2), 1963.
    L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, section 7.3
    (output-error methods).
"""

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._model._extensions import Extended
from .._model._helicopter import Helicopter, QUATERNION
from .._simulate import FixedGrid, simulate

# The Runge-Kutta stages in a plain scan: forward-mode differentiable (the Jacobians use jacfwd).
# One step per sample keeps the batched fits cheap; at 100 Hz and above its error is far below
# measurement noise for these models.
FORWARD_GRID = FixedGrid(solver=diffrax.Tsit5(scan_kind="lax"), substeps=1)


def nominal_parameter_names(system) -> tuple[str, ...]:
    """The fittable parameters of a nominal system: its scalar array fields (physical or base
    parameters), or for a `Helicopter` the free weights of its body model (`du/u`, `dv/1`, ...)."""
    if isinstance(system, Helicopter):
        return tuple(system.body_model.parameter_names)
    return tuple(
        f.name
        for f in dataclasses.fields(system)
        if isinstance(getattr(system, f.name), jax.Array) and jnp.shape(getattr(system, f.name)) == ()
    )


def nominal_values(system, names: tuple[str, ...]) -> Float[Array, " n_nominal"]:
    """The values of the parameters `names` (from `nominal_parameter_names`) of `system`."""
    if isinstance(system, Helicopter):
        return jnp.asarray(system.body_model.parameter_vector()) if names else jnp.zeros(0)
    return jnp.asarray([getattr(system, n) for n in names])


def with_nominal_values(system, names: tuple[str, ...], values):
    """A copy of `system` with the parameters `names` set to `values`."""
    if not names:
        return system
    if isinstance(system, Helicopter):
        body = system.body_model.with_parameter_vector(jnp.stack(list(values)))
        return eqx.tree_at(lambda h: h.body_model, system, body)
    return eqx.tree_at(lambda m: [getattr(m, n) for n in names], system, [v for v in values])


class Windows(eqx.Module):
    """Windows of measured records, stacked: `ts (window, step)`, `xs (window, step, n)`, `us (window, step, m)`.

    `ts_before`, `us_before` hold the `n_before` samples of input history before each window (the
    first input repeated where the record has none): internal states of input terms (a lag's output,
    a delay's filter) are driven through them, so each window starts with the internal state the
    input history implies rather than at rest.
    """

    ts: Float[Array, "window step"]
    xs: Float[Array, "window step n_states"]
    us: Float[Array, "window step n_inputs"]
    ts_before: Float[Array, "window before"]
    us_before: Float[Array, "window before n_inputs"]
    starts: tuple = eqx.field(static=True)  # (record index, start sample) per window


def make_windows(trajectories, n_steps: int, stride: int, *, history_s: float = 0.5) -> Windows:
    """Cut records into windows of `n_steps + 1` samples every `stride` samples, with `history_s` of input history."""
    ts, xs, us, tb, ub, starts = [], [], [], [], [], []
    for r, traj in enumerate(trajectories):
        t_all, x_all, u_all = np.asarray(traj.ts), np.asarray(traj.xs), np.asarray(traj.us)
        dt = float(np.median(np.diff(t_all)))
        n_before = max(1, int(round(history_s / dt)))
        for k in range(0, len(traj) - n_steps, stride):
            ts.append(t_all[k : k + n_steps + 1])
            xs.append(x_all[k : k + n_steps + 1])
            us.append(u_all[k : k + n_steps + 1])
            idx = np.arange(k - n_before, k + 1)
            tb.append(t_all[k] + dt * (idx - k))
            ub.append(u_all[np.maximum(idx, 0)])
            starts.append((r, k))
    if not ts:
        raise ValueError(f"the records are shorter than one window of {n_steps} samples")
    stack = lambda a: jnp.asarray(np.stack(a))  # noqa: E731
    return Windows(stack(ts), stack(xs), stack(us), stack(tb), stack(ub), tuple(starts))


def hidden_at_start(model, ts_before, us_before):
    """Internal states of `model`'s input terms at the end of an input history (from rest at its start; RK4)."""
    if not isinstance(model, Extended) or model.n_states == model.system.n_states:
        return jnp.zeros((0,), us_before.dtype)
    n = model.system.n_states
    z0 = model.initial_state(jnp.zeros(n, us_before.dtype), us_before[0])[n:]

    def f(z, u):
        return model.applied_input(u, z)[1]

    def interval(z, inputs):
        h, u = inputs
        for _ in range(2):
            k1 = f(z, u)
            k2 = f(z + 0.25 * h * k1, u)
            k3 = f(z + 0.25 * h * k2, u)
            k4 = f(z + 0.5 * h * k3, u)
            z = z + h / 12 * (k1 + 2 * k2 + 2 * k3 + k4)
        return z, None

    z, _ = jax.lax.scan(interval, z0, (jnp.diff(ts_before), us_before[:-1]))
    return z


class Family(eqx.Module):
    """The nominal system with every candidate term, and how parameters map onto it.

    **Fields:** `model` (the `Extended` model at neutral values), `names` (refittable nominal
    parameter names), `refit` (1 where a nominal parameter is refitted), `nominal_scale`,
    `candidate_scale`, `candidate_init` (start value of each candidate's coefficient),
    `neutral`, `state_scale`.
    """

    model: Extended
    names: tuple[str, ...] = eqx.field(static=True)
    refit: Float[Array, " n_nominal"]
    nominal_scale: Float[Array, " n_nominal"]
    candidate_scale: Float[Array, " n_candidates"]
    candidate_init: Float[Array, " n_candidates"]
    neutral: Float[Array, " n_candidates"]
    state_scale: Float[Array, " n_states"]

    @property
    def n_candidates(self) -> int:
        return len(self.model.terms)

    def build(self, nominal_values: Float[Array, " n_nominal"], coefficients: Float[Array, " n_candidates"]) -> Extended:
        """The `Extended` model with these nominal parameter values and candidate coefficients."""
        model = self.model
        if self.names:
            model = eqx.tree_at(lambda m: m.system, model, with_nominal_values(model.system, self.names, nominal_values))
        return eqx.tree_at(lambda m: [t.coefficient for t in m.terms], model, [c for c in coefficients])

    def coefficients(self, slots: Int[Array, " n_slots"], new: Int[Array, ""], p: Float[Array, " n_params"]):
        """All candidates' coefficients for a configuration: neutral except the slots and the new term."""
        n_nominal = len(self.names)
        n_slots = slots.shape[0]
        onehot = jax.nn.one_hot(slots, self.n_candidates, dtype=p.dtype)  # -1 gives a zero row
        delta = onehot.T @ p[n_nominal : n_nominal + n_slots] + jax.nn.one_hot(new, self.n_candidates, dtype=p.dtype) * p[-1]
        return self.neutral + delta

    def scale(self, slots, new):
        """Per-parameter scale of a configuration (zero for parameters that are not fitted)."""
        cand = lambda i: jnp.where(i >= 0, self.candidate_scale[jnp.maximum(i, 0)], 0.0)  # noqa: E731
        return jnp.concatenate([self.refit * self.nominal_scale, jax.vmap(cand)(slots), cand(new)[None]])

    def model_for(self, slots, new, p):
        n_nominal = len(self.names)
        return self.build(p[:n_nominal], self.coefficients(slots, new, p))


def window_errors(model, windows: Windows, method=FORWARD_GRID):
    """Simulated minus measured states on every window, `(window, step, n_measured)`, NaN past a divergence."""
    n = windows.xs.shape[-1]

    nominal = model.system if isinstance(model, Extended) else model

    def one(t, x, u, tb, ub):
        x0 = jnp.concatenate([x[0], hidden_at_start(model, tb, ub)])
        xs = simulate(model, x0, t, u, method=method, throw=False).xs[:, :n]
        if isinstance(nominal, Helicopter):  # q and -q are one attitude: compare on the measured hemisphere
            quat = xs[:, QUATERNION]
            sign = jnp.where(jnp.sum(quat * x[:, QUATERNION], axis=1, keepdims=True) < 0, -1.0, 1.0)
            xs = xs.at[:, QUATERNION].set(sign * quat)
        return xs - x

    return jax.vmap(one)(windows.ts, windows.xs, windows.us, windows.ts_before, windows.us_before)


def _residuals(family, windows, slots, new, p):
    e = window_errors(family.model_for(slots, new, p), windows)[:, 1:]
    e = e / jnp.broadcast_to(family.state_scale, e.shape)
    return e.reshape(-1)


def fit_configuration(family: Family, windows: Windows, slots, new, p_init, free, n_iter: int = 16):
    """Levenberg-Marquardt on the window output error for one configuration (vmap this over configurations).

    The parameter vector `p` holds the nominal values, the slot coefficients and the new term's
    coefficient (both relative to neutral). Only the entries where `free` is 1 move (all of them
    for a joint refit; only the last to fit the new term alone), each scaled by `family.scale`.
    Each iteration costs one forward-mode Jacobian: the trial point's residuals come with it, and
    a rejected trial leaves the last accepted point (and its Jacobian) in place.

    **Returns:** `(p, cost, std_error)`: fitted parameters, the sum of squared scaled residuals,
    and standard errors from the Gauss-Newton covariance $\\hat\\sigma^2 (J^\\top J)^{-1}$ (too
    small when the residuals are correlated in time; read them as a lower bound).
    """
    s = family.scale(slots, new) * free

    def residual(v):
        r = _residuals(family, windows, slots, new, p_init + s * v)
        return r, r

    def step(carry, _):
        v_acc, J_acc, r_acc, cost_acc, lam, v_trial = carry
        J, r = jax.jacfwd(residual, has_aux=True)(v_trial)
        finite = jnp.all(jnp.isfinite(r)) & jnp.all(jnp.isfinite(J))
        cost = jnp.where(finite, jnp.sum(jnp.where(jnp.isfinite(r), r, 0.0) ** 2), jnp.inf)
        accept = cost < cost_acc
        v_acc = jnp.where(accept, v_trial, v_acc)
        J_acc = jnp.where(accept, jnp.where(jnp.isfinite(J), J, 0.0), J_acc)
        r_acc = jnp.where(accept, jnp.where(jnp.isfinite(r), r, 0.0), r_acc)
        cost_acc = jnp.where(accept, cost, cost_acc)
        lam = jnp.clip(jnp.where(accept, lam * 0.3, lam * 8.0), 1e-9, 1e9)
        H = J_acc.T @ J_acc
        d = jnp.diag(H)
        damping = jnp.where(d > 0, lam * d, 1.0)  # Marquardt's scaling; inert directions stay put
        v_next = v_acc - jnp.linalg.solve(H + jnp.diag(damping), J_acc.T @ r_acc)
        return (v_acc, J_acc, r_acc, cost_acc, lam, v_next), None

    n_res = windows.xs.shape[0] * (windows.xs.shape[1] - 1) * windows.xs.shape[2]
    v0 = jnp.zeros_like(p_init)
    init = (v0, jnp.zeros((n_res, v0.shape[0]), p_init.dtype), jnp.zeros(n_res, p_init.dtype),
            jnp.asarray(jnp.inf, p_init.dtype), jnp.asarray(1e-3, p_init.dtype) / 0.3, v0)
    (v, J, r, cost, _, _), _ = jax.lax.scan(step, init, None, length=n_iter)
    n_free = jnp.sum(s != 0)
    sigma2 = cost / jnp.maximum(n_res - n_free, 1)
    cov_v = sigma2 * jnp.linalg.pinv(J.T @ J, hermitian=True)
    std = jnp.abs(s) * jnp.sqrt(jnp.maximum(jnp.diag(cov_v), 0.0))
    return p_init + s * v, cost, std


@eqx.filter_jit
def fit_configurations(family, windows, slots, new, p_init, free, n_iter: int = 16):
    """`fit_configuration` for a batch: `slots (batch, n_slots)`, `new (batch,)`, `p_init (batch, n_params)`, `free (n_params,)`."""
    return jax.vmap(lambda s_, n_, p_: fit_configuration(family, windows, s_, n_, p_, free, n_iter))(slots, new, p_init)


@eqx.filter_jit
def validate_configurations(family, windows, slots, new, p):
    """Held-out window errors of a batch of fitted configurations, `(batch, window, step, n_measured)`."""
    return jax.vmap(lambda s_, n_, p_: window_errors(family.model_for(s_, n_, p_), windows))(slots, new, p)
