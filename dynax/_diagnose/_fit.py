r"""Batched simulation-error fits of a nominal model plus candidate terms, on dynax's fitting engine.

All candidates live in one `Extended` model at their neutral values; a *configuration* says which
of them are active: up to `n_slots` already selected terms plus one new candidate. Because a term
at its neutral value is the nominal model, every configuration has the same structure, and the
fits of all candidates of a forward-selection round are one `dynax._fit.fit_least_squares`
(optimistix Levenberg-Marquardt with its convergence test) `vmap`ped over configurations,
compiled once for the whole diagnosis.

The nominal parameters are the system's own (`parameter_filter()` / `parameter_labels()`, read
and written through `dynax._fit.Parameters`); the rollouts are `dynax._simulate._sim_error.window_rollouts`,
the one windowed rollout `simulation_error` uses too. The cost is the output error of open-loop
rollouts on windows of the record, each started from the measured state (internal states of input
terms driven by the input history before the window, a candidate's states of its own by the measured
states and inputs there), scaled per state by the data's spread.

??? cite

    K. Levenberg, "A method for the solution of certain non-linear problems in least squares",
    Quarterly of Applied Mathematics 2, 1944; D. W. Marquardt, "An algorithm for least-squares
    estimation of nonlinear parameters", SIAM J. Applied Mathematics 11(2), 1963.
    L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, section 7.3
    (output-error methods).
"""

from collections.abc import Callable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int
import lineax as lx
import numpy as np
import optimistix as optx

from .._fit import clustered_covariance, fit_least_squares, LeastSquaresOptions, levenberg_marquardt, Parameters
from .._model._extensions import Extended
from .._simulate import FixedGrid, window_rollouts

# Forward-mode differentiable (the Jacobians are forward mode). One step per sample keeps the
# batched fits cheap; at 100 Hz and above its error is far below measurement noise for these models.
# The stages rolled: the family's vector field holds every candidate term, and written out six times
# per step it made the fit, screening and validation programs most of a diagnosis's compile time.
FORWARD_GRID = FixedGrid(solver=diffrax.Tsit5(scan_kind="lax"), substeps=1, roll_stages=True)

# Levenberg-Marquardt's stopping rule (optimistix's Cauchy test on an RMS norm): the scaled
# parameters are O(1) (see `Family.scale`) and the residuals are in units of each state's spread, so
# a step that moves the scaled parameters and the residuals by less than 1e-3 (RMS, plus 1e-3 of
# their size) is converged far below the standard errors and what the held-out test resolves. On
# the demo's records a batch converges in 6 to 10 steps (the former fixed loop took 16). Under `vmap`
# the batch stops when its slowest member has converged; `MAX_STEPS` bounds a member that creeps.
# The damped step from the normal equations (a Cholesky factorisation of the n x n
# J^T J + lambda I) rather than optimistix's default QR of the (m + n) x n damped Jacobian: with
# thousands of residuals and a dozen parameters that QR cost more than the rollouts themselves
# (three times the former loop's time per step); the parameters are scaled to O(1), so the squared
# condition number is harmless.
SOLVER = levenberg_marquardt(rtol=1e-3, atol=1e-3, norm=optx.rms_norm, linear_solver=lx.Normal(lx.Cholesky()))
MAX_STEPS = 32


def nominal_parameters(system) -> Parameters:
    """The fittable parameters of a nominal system: the system's own `parameter_filter()` and
    `parameter_labels()` (base parameters `theta1..theta7`, a helicopter's free body-model weights `du/u`, ...)."""
    return Parameters.of(system)


def nominal_parameter_names(system) -> tuple[str, ...]:
    """The names of `nominal_parameters(system)`."""
    return nominal_parameters(system).names


def nominal_values(system, names: tuple[str, ...]) -> Float[Array, " n_nominal"]:
    """The values of the parameters `names` (all of `nominal_parameter_names`) of `system`."""
    parameters = nominal_parameters(system)
    if tuple(names) != parameters.names:
        raise ValueError(
            f"nominal_values: {names} are not the parameters {parameters.names} of {type(system).__name__}"
        )
    return parameters.vector(system) if names else jnp.zeros(0)


def with_nominal_values(system, names: tuple[str, ...], values):
    """A copy of `system` with the parameters `names` (all of `nominal_parameter_names`) set to `values`."""
    if not names:
        return system
    parameters = nominal_parameters(system)
    if tuple(names) != parameters.names:
        raise ValueError(
            f"with_nominal_values: {names} are not the parameters {parameters.names} of {type(system).__name__}"
        )
    return parameters.with_vector(system, jnp.stack([jnp.asarray(v) for v in values]))


class Windows(eqx.Module):
    """Windows of measured records, stacked: `ts (window, step)`, `xs (window, step, n)`, `us (window, step, m)`.

    `ts_before`, `us_before` hold the `n_before` samples of input history before each window (the
    first input repeated where the record has none): internal states of input terms (a lag's output,
    a delay's filter) are driven through them, so each window starts with the internal state the
    input history implies rather than at rest. `xs_before` holds the measured states there (the first
    state repeated where the record has none): a candidate term's states of its own (a lagged speed) are
    integrated along them and the inputs (`complete_state`), so they too start where the record puts them.
    """

    ts: Float[Array, "window step"]
    xs: Float[Array, "window step n_states"]
    us: Float[Array, "window step n_inputs"]
    ts_before: Float[Array, "window before"]
    us_before: Float[Array, "window before n_inputs"]
    xs_before: Float[Array, "window before n_states"]
    # (record index, start sample) per window, read on the host only. An array, not a static
    # field: a static field would compile every fit anew for records cut at other places.
    starts: Int[Array, "window 2"] | Int[np.ndarray, "window 2"]
    # Each window's weight in a fit (1 by default; 0 leaves it out). Cross-fitting leaves a record
    # out by zero weights rather than by cutting its windows out: the same shapes, so the same
    # compiled fit serves every fold.
    weights: Float[Array, " window"]

    def without_span(self, record: int, start: int, stop: int) -> "Windows":
        """These windows with weight zero where they share a sample with `start:stop` of record `record` (a
        cross-fitting fold; the whole record with `start = 0` and `stop` its length)."""
        starts = np.asarray(self.starts)
        n_steps = self.ts.shape[1] - 1
        near = (starts[:, 0] == record) & (starts[:, 1] + n_steps >= start) & (starts[:, 1] < stop)
        # On the host (a product by 0 or 1 is exact in numpy as in XLA): eagerly, each would compile a program.
        weights = np.asarray(self.weights)
        return eqx.tree_at(lambda w: w.weights, self, jax.device_put(np.asarray(~near, weights.dtype) * weights))

    def take(self, index) -> "Windows":
        """The windows at `index` (host integers), in that order; gathered on the host, so no compiled gather."""
        index = np.asarray(index)
        return jax.tree.map(
            lambda a: jax.device_put(np.asarray(a)[index]) if isinstance(a, jax.Array) else a[index], self
        )


def make_windows(trajectories, n_steps: int, stride: int, *, history_s: float = 0.5) -> Windows:
    """Cut records into windows of `n_steps + 1` samples every `stride` samples, with `history_s` of input (and
    measured state) history."""
    ts, xs, us, tb, ub, xb, starts = [], [], [], [], [], [], []
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
            xb.append(x_all[np.maximum(idx, 0)])
            starts.append((r, k))
    if not ts:
        raise ValueError(f"the records are shorter than one window of {n_steps} samples")
    stack = lambda a: jax.device_put(np.stack(a))  # noqa: E731  # `jnp.asarray` would compile a copy per shape
    xs_ = stack(xs)
    return Windows(
        stack(ts),
        xs_,
        stack(us),
        stack(tb),
        stack(ub),
        stack(xb),
        np.asarray(starts, dtype=np.int64),
        jax.device_put(np.ones(len(ts), xs_.dtype)),
    )


class Family(eqx.Module):
    """The nominal system with every candidate term, and how parameters map onto it.

    **Fields:** `model` (the `Extended` model at neutral values), `names` (the nominal system's
    parameter names, `nominal_parameter_names`), `refit` (1 where a nominal parameter is refitted),
    `nominal_scale`, `candidate_scale`, `candidate_init` (start value of each candidate's
    coefficient), `neutral`, `state_scale`.
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

    def build(
        self, nominal_values: Float[Array, " n_nominal"], coefficients: Float[Array, " n_candidates"] | np.ndarray
    ) -> Extended:
        """The `Extended` model with these nominal parameter values and candidate coefficients (a numpy array of
        them is moved to the device as one scalar each)."""
        model = self.model
        if self.names:
            system = nominal_parameters(model.system).with_vector(model.system, nominal_values)
            model = eqx.tree_at(lambda m: m.system, model, system)
        if isinstance(coefficients, np.ndarray):  # from the host: each on the device, no compiled unstacking
            each = [jax.device_put(c) for c in coefficients]
        else:
            each = [c for c in coefficients]
        return eqx.tree_at(lambda m: [t.coefficient for t in m.terms], model, each)

    def coefficients(self, slots: Int[Array, " n_slots"], new: Int[Array, ""], p: Float[Array, " n_params"]):
        """All candidates' coefficients for a configuration: neutral except the slots and the new term."""
        n_nominal = len(self.names)
        n_slots = slots.shape[0]
        onehot = jax.nn.one_hot(slots, self.n_candidates, dtype=p.dtype)  # -1 gives a zero row
        delta = (
            onehot.T @ p[n_nominal : n_nominal + n_slots]
            + jax.nn.one_hot(new, self.n_candidates, dtype=p.dtype) * p[-1]
        )
        return self.neutral + delta

    def host_coefficients(self, slots, new: int, p) -> np.ndarray:
        """`coefficients` computed by numpy, for the host. `coefficients`' one-hot product adds to each candidate
        at most one parameter and products of zero, so placing that parameter is the same number (a zero's sign
        aside, which the neutral value's sum settles alike: no neutral value is -0); called eagerly,
        `coefficients`' operations compile a small program each."""
        n_nominal = len(self.names)
        slots, p = np.asarray(slots), np.asarray(p, self.neutral.dtype)
        delta = np.zeros(self.n_candidates, p.dtype)
        for i, k in enumerate(slots):
            if k >= 0:
                delta[k] += p[n_nominal + i]
        if new >= 0:
            delta[new] += p[-1]
        return np.asarray(self.neutral) + delta

    def scale(self, slots, new):
        """Per-parameter scale of a configuration (zero for parameters that are not fitted)."""
        cand = lambda i: jnp.where(i >= 0, self.candidate_scale[jnp.maximum(i, 0)], 0.0)  # noqa: E731
        return jnp.concatenate([self.refit * self.nominal_scale, jax.vmap(cand)(slots), cand(new)[None]])

    def host_scale(self, slots, new: int) -> np.ndarray:
        """`scale` computed by numpy (the same products), for the host: called eagerly, `scale`'s operations
        compile a small program each."""
        slots = np.asarray(slots)
        candidate_scale = np.asarray(self.candidate_scale)
        cand = lambda i: np.where(i >= 0, candidate_scale[np.maximum(i, 0)], 0.0)  # noqa: E731
        return np.concatenate([np.asarray(self.refit) * np.asarray(self.nominal_scale), cand(slots), [cand(new)]])

    def model_for(self, slots, new, p):
        n_nominal = len(self.names)
        return self.build(p[:n_nominal], self.coefficients(slots, new, p))


def window_errors(model, windows: Windows, method=FORWARD_GRID):
    """Simulated minus measured states (`state_error`) on every window, `(window, step, n_measured)`, NaN past a
    divergence. Every internal state starts where the history before the window puts it (`complete_state`)."""
    errors, _ = window_rollouts(
        model,
        windows.ts,
        windows.xs,
        windows.us,
        windows.ts_before,
        windows.us_before,
        windows.xs_before,
        method=method,
    )
    return errors


def _window_residuals(p, args):
    family, windows, slots, new = args
    e = window_errors(family.model_for(slots, new, p), windows)[:, 1:]
    e = e / jnp.broadcast_to(family.state_scale, e.shape)
    # A left-out window (weight 0) contributes nothing, even where its rollout diverged (NaN).
    w = windows.weights[:, None, None]
    e = jnp.where(w > 0, e * jnp.sqrt(w), 0.0)
    return e.reshape(-1)


def _movable_residuals(q, args):
    """`_window_residuals` of the parameter vector `p` with its entries `movable` set to `q`."""
    family, windows, slots, new, p, movable = args
    return _window_residuals(p.at[np.asarray(movable, int)].set(q), (family, windows, slots, new))


def movable_parameters(family: Family, n_params: int) -> tuple[int, ...]:
    """The entries of a configuration's parameter vector that a fit can move: the refitted nominal parameters,
    every slot and the new term (`Family.scale` is zero everywhere else, so those never move).

    The fit differentiates only these: `jac="dense"` forms the Jacobian by one `jacfwd`, one tangent per
    unknown, and a quadrotor's held motor map is 35 nominal weights beside the one to four coefficients a round
    fits, so differentiating the held ones too made each Levenberg-Marquardt step about ten times the work for
    the same step (their columns are zero). All entries where `family.refit` is not concrete (traced)."""
    try:
        refit = np.asarray(family.refit)
    except jax.errors.TracerArrayConversionError:
        return tuple(range(n_params))
    n_nominal = len(family.names)
    refitted = np.flatnonzero(refit > 0)
    return tuple(int(i) for i in np.concatenate([refitted, np.arange(n_nominal, n_params)]))


class _AsOverAll(eqx.Module):
    """`norm` of a vector of the `n_movable` unknowns as of the whole parameter vector (`n_all` entries, the held ones'
    zeros appended): the stopping rule of a fit over the `movable_parameters` is the one over every entry (an RMS
    norm counts the held entries), so that the fit takes the same steps as before it left them out."""

    norm: Callable = eqx.field(static=True)
    n_movable: int = eqx.field(static=True)
    n_all: int = eqx.field(static=True)

    def __call__(self, x):
        if jnp.ndim(x) == 1 and x.shape[0] == self.n_movable:
            x = jnp.concatenate([x, jnp.zeros(self.n_all - self.n_movable, x.dtype)])
        return self.norm(x)


def fit_configuration(
    family: Family,
    windows: Windows,
    slots,
    new,
    p_init,
    free,
    *,
    solver=SOLVER,
    max_steps: int = MAX_STEPS,
    movable: tuple[int, ...] | None = None,
):
    """The simulation-error fit of one configuration through `fit_least_squares` (vmap this over configurations).

    The parameter vector `p` holds the nominal values, the slot coefficients and the new term's
    coefficient (both relative to neutral). Only the entries where `free` is 1 move (all of them
    for a joint refit; only the last to fit the new term alone), each scaled by `family.scale`
    (a zero scale freezes a parameter in the engine). `movable` (`movable_parameters`, default every
    entry): the entries the engine sees as unknowns; the others are held at `p_init` (their scale is zero).

    **Returns:** `(p, cost, std_error, steps)`: fitted parameters, the sum of squared scaled
    residuals, standard errors (`window_clustered_std_errors`), and the solver's iterations.
    """
    movable = tuple(range(p_init.shape[-1])) if movable is None else tuple(movable)
    index = np.asarray(movable, int)
    s = (family.scale(slots, new) * free)[index]
    if len(movable) < p_init.shape[-1] and hasattr(solver, "norm"):
        solver = eqx.tree_at(lambda sv: sv.norm, solver, _AsOverAll(solver.norm, len(movable), p_init.shape[-1]))
    # jac="dense": the whole Jacobian by one `jacfwd` per step (all parameter tangents through one
    # rollout), applied as a matrix; far less compilation than linearising the rollout itself.
    solution = fit_least_squares(
        _movable_residuals,
        p_init[index],
        True,
        (family, windows, slots, new, p_init, movable),
        solver=solver,
        scale=s,
        max_steps=max_steps,
        options=LeastSquaresOptions(jac="dense"),
    )
    p = p_init.at[index].set(solution.value)
    std = jnp.zeros_like(p_init).at[index].set(window_clustered_std_errors(solution, windows, s))
    return p, 2.0 * solution.loss, std, solution.steps


def window_clustered_std_errors(solution, windows: Windows, scale):
    r"""Standard errors of a window fit, cluster-robust with each window a cluster.

    Each window is simulated from its measured state, whose noise it carries all along, and where
    the model is not exact its error drifts with the manoeuvre: a window's residuals are correlated,
    and the Gauss-Newton covariance $\hat\sigma^2 (J^\top J)^{+}$, which counts them as independent,
    is too small (on MuJoCo-made data a hidden dry friction came out as 0.1009 +- 0.00005 N m for a
    true 0.10: 19 of its standard errors away). The training windows do not overlap, so each is a
    cluster of the engine's sandwich (`dynax._fit.clustered_covariance`; a left-out window, weight 0,
    holds no residual and does not count). With fewer windows in the fit than twice the free
    parameters, Gauss-Newton's.

    `solution` is the engine's (its Jacobian in the scaled unknowns), `scale` the unknowns' scale.
    """
    jac, r = solution.jacobian, solution.residuals
    n_windows = windows.ts.shape[0]
    covariance, used = clustered_covariance(jac, r, jnp.arange(r.shape[0]) // (r.shape[0] // n_windows), n_windows)
    robust = jnp.sqrt(jnp.maximum(jnp.diag(covariance), 0.0)) * jnp.abs(scale)
    return jnp.where(used >= 2 * jnp.sum(scale != 0), robust, solution.std_errors)


def fit_configurations(
    family, windows, slots, new, p_init, free, *, solver=SOLVER, max_steps: int = MAX_STEPS, movable=None
):
    """`fit_configuration` for a batch: `slots (batch, n_slots)`, `new (batch,)`, `p_init (batch, n_params)`, `free
    (n_params,)`; the unknowns `movable` (default `movable_parameters`: the Jacobian over what can move only).

    Under `vmap` every member iterates until all have converged (a converged member's step is zero).
    """
    movable = movable_parameters(family, p_init.shape[-1]) if movable is None else tuple(int(i) for i in movable)
    return _fit_configurations(family, windows, slots, new, p_init, free, movable, solver=solver, max_steps=max_steps)


@eqx.filter_jit
def _fit_configurations(family, windows, slots, new, p_init, free, movable, *, solver, max_steps: int):
    def fit(s_, n_, p_):
        return fit_configuration(family, windows, s_, n_, p_, free, solver=solver, max_steps=max_steps, movable=movable)

    return jax.vmap(fit)(slots, new, p_init)


@eqx.filter_jit
def validate_configurations(family, windows, slots, new, p):
    """Held-out window errors of a batch of fitted configurations, `(batch, window, step, n_measured)`."""
    return jax.vmap(lambda s_, n_, p_: window_errors(family.model_for(s_, n_, p_), windows))(slots, new, p)
