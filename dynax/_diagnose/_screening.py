r"""Equation-error screening of candidates: cheap, linearised, on one-step acceleration residuals.

Around the current model, adding candidate $c$ with a small coefficient $\delta_c$ and moving the
refitted nominal parameters by $\Delta\theta$ changes the predicted acceleration by
$J_\theta \Delta\theta + J_c \delta_c$, with the sensitivities $J$ from forward-mode autodiff of
the vector field at the measured (smoothed) states. Regressing the training residuals on
$[J_\theta, J_c]$ and measuring the reduction of the *held-out* residuals ranks every candidate in
one linear least-squares solve each. A delay or lag at zero has no sensitivity (it is a dynamic
term); to first order both act as $-\tau\,\partial f/\partial u\,\dot u$. That first order holds only
while $\omega\tau \ll 1$ for the input's frequencies: a 0.15 s lag on a helicopter collective that a
closed-loop controller moves at a few hertz is far outside it, and the linear direction ranked it
below a constant bias. So a delay or lag is screened at finite sizes too: on a
grid of time constants $\tau_g$ (from two samples to `MAX_SCREEN_TIME` s) the direction is
$\partial f/\partial u\,(a_{\tau_g}(t) - u(t))$, with $a_\tau$ the recorded input passed through the
lag ($\tau \dot a = u - a$, exact for a held input) or shifted by the delay; the grid point that
fits the *training* residuals best is kept, its held-out gain is the candidate's screening gain and
its $\tau_g$ (times the fitted scale, if that is near one) the refit's start value.
The output-error refit that follows tells a delay from a lag. A term not `smooth_at_neutral` is screened on
the secant to its start value: a static friction level (`stiction`) at neutral sits on a tie of its clipping
(the joint's holding force is clipped to $\pm f_s$, and at $f_s = 0$ both bounds meet), where its derivative
is half the one above zero; its start is the largest force the records show held at rest.

??? cite

    S. Chen, S. A. Billings and W. Luo, "Orthogonal least squares methods and their application
    to non-linear system identification", International Journal of Control 50(5), 1989
    (ranking candidate terms by their reduction of the equation error).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._data._derivatives import savitzky_golay
from ._residuals import (
    as_measured,
    DEAD_TIMES,
    hidden_trajectory,
    input_dynamics,
    LAGS,
    padded,
    sg_window,
    shared_length,
    smoothed_states,
    velocity_indices,
)


@eqx.filter_jit
def _directions(family, values, coefficients, xs, zs, us, us_before):
    model = family.build(values, coefficients)
    idx = jnp.asarray(velocity_indices(model.system))

    def accel(v, c, x, z, u):
        m = family.build(v, c)
        return m.vector_field(0.0, jnp.concatenate([x, z]), u)[idx]

    jac = jax.jacfwd(accel, argnums=(0, 1, 4))

    def both(x, z, u, ub):
        a = jac(values, coefficients, x, z, u)
        b = jac(values, coefficients, x, z, ub)
        return tuple(0.5 * (p + q) for p, q in zip(a, b))

    del model
    return jax.vmap(both)(xs, zs, us, us_before)


@eqx.filter_jit
def _secant(family, values, coefficients, step, xs, zs, us, us_before):
    """`(f(c + step) - f(c)) / |step|` of the accelerations, the held input's two limits averaged."""
    idx = jnp.asarray(velocity_indices(family.model.system))
    size = jnp.max(jnp.abs(step))

    def accel(c, x, z, u):
        m = family.build(values, c)
        return m.vector_field(0.0, jnp.concatenate([x, z]), u)[idx]

    def both(x, z, u, ub):
        return 0.5 * sum((accel(coefficients + step, x, z, v) - accel(coefficients, x, z, v)) / size for v in (u, ub))

    return jax.vmap(both)(xs, zs, us, us_before)


def screening_data(family, values, coefficients, trajectory, residual_fn, length: int = 0):
    """Residuals and sensitivities on one record: `(r (time, n_vel), J_nominal (time, n_vel, n_nom), J_candidates (time,
    n_vel, n_cand))`; the per-sample functions run on the record padded to `length` samples or more (`padded`)."""
    # Moved by `device_put` and, the coefficients, as one scalar each (`Family.build`): `jnp.asarray` of a host array
    # and the unstacking of a device one compile a program each.
    values, coefficients = jax.device_put(np.asarray(values)), np.asarray(coefficients)
    model = family.build(values, coefficients)
    r, _, _, keep = residual_fn(model, trajectory, length=length)
    ts = trajectory.ts
    w = sg_window(trajectory.dt)
    xs = smoothed_states(trajectory)
    n = len(ts)  # the jitted per-sample functions run on the padded record (`padded`), cut back to its samples
    ts_p, us_p, xs_p = padded(ts, trajectory.us, xs, length=length)
    # Cut and shifted on the host: in JAX each slice would compile a program for its record's length.
    zs = np.asarray(hidden_trajectory(model, ts_p, us_p, xs_p))[:n]
    us = trajectory.us
    us_host = np.asarray(us)
    us_before = np.concatenate([us_host[:1], us_host[:-1]])
    on_grid = padded(ts, xs, zs, us, us_before, length=length)[1:]
    directions = _directions(family, values, jax.device_put(coefficients), *on_grid)
    J_nom, J_c, J_u = (np.asarray(a)[:n] for a in directions)
    du = savitzky_golay(ts, us, window=w, order=2, deriv=1)  # (time, n_inputs)
    J_c = np.array(J_c)
    system = family.model.system
    for k, term in enumerate(family.model.terms):
        if not term.smooth_at_neutral:
            # The derivative at neutral does not show it (a static level sits on a tie of its clipping there); screen
            # it at finite size (its start value), as delays and lags are: the secant to the data-based start.
            size = float(family.candidate_init[k] - family.neutral[k])
            if size > 0 and float(coefficients[k]) == float(family.neutral[k]):
                step = jnp.zeros_like(jnp.asarray(coefficients)).at[k].set(size)
                J_c[:, :, k] = np.asarray(
                    _secant(family, jnp.asarray(values), jnp.asarray(coefficients), step, *on_grid)
                )[:n]
    for k, term in enumerate(family.model.terms):
        if input_dynamics(term, system) and not np.any(J_c[:, :, k]):
            J_c[:, :, k] = -sum(np.asarray(J_u)[:, :, i] * np.asarray(du)[:, None, i] for i in term.inputs)
    smooth = lambda a: as_measured(ts, a, w)  # noqa: E731  # as the residuals' prediction
    grid = screening_grid(trajectory.dt)
    J_grid = {}
    for k, term in enumerate(family.model.terms):
        if input_dynamics(term, system) and term.cause in DEAD_TIMES + LAGS:
            change = 0.0  # a term on several inputs moves each of them
            for i in term.inputs:
                J_u_k = np.asarray(J_u)[:, :, i]
                u = np.asarray(us)[:, i]
                shifted = np.stack(
                    [_lagged(ts, u, tau) if term.cause in LAGS else _delayed(ts, u, tau) for tau in grid], axis=1
                )
                change = change + J_u_k[:, :, None] * (shifted - u[:, None])[:, None, :]
            J_grid[k] = smooth(change)[keep]  # (time, n_vel, n_grid)
    return r, smooth(np.asarray(J_nom))[keep], smooth(J_c)[keep], J_grid


MAX_SCREEN_TIME = 0.5  # [s] the longest delay or lag screened at finite size


def screening_grid(dt: float) -> np.ndarray:
    """Time constants at which delays and lags are screened: geometric from two samples to `MAX_SCREEN_TIME`."""
    lo = 2.0 * float(dt)
    return np.geomspace(lo, max(MAX_SCREEN_TIME, 2 * lo), 10)


def _lagged(ts, u, tau):
    """`u` (held between samples) through the first-order lag `tau a' = u - a`, started at steady state."""
    ts, u = np.asarray(ts, float), np.asarray(u, float)
    decay = np.exp(-np.diff(ts) / tau)
    out = np.empty_like(u)
    out[0] = u[0]
    for i in range(1, u.size):
        out[i] = u[i - 1] + (out[i - 1] - u[i - 1]) * decay[i - 1]
    return out


def _delayed(ts, u, delay):
    """`u` (held between samples) `delay` seconds late; the first value held back in time."""
    ts, u = np.asarray(ts, float), np.asarray(u, float)
    i = np.clip(np.searchsorted(ts, ts - delay, side="right") - 1, 0, u.size - 1)
    return u[i]


def screen(
    family,
    values,
    coefficients,
    train,
    validation,
    candidates_to_screen,
    residual_fn,
    *,
    cross_fit: bool = False,
):
    """Held-out equation-error gain of each candidate in `candidates_to_screen` (indices), linearised at the nominal
    parameters `values` and the candidates' `coefficients`, the family's refitted nominal parameters (`family.refit`)
    refitted with each.

    The regression is fitted on `train` and scored on `validation`; with `cross_fit` (and two or more
    training records) also fitted on all training records but one and scored on that one, for each
    (leave-one-run-out, as `diagnose`'s held-out test does). A candidate's gain is then the mean of its
    gains on these splits: each held-out split counts once, whatever its residuals' size (summed sums of
    squares would let the run with the largest residuals rank the candidates alone; on a real rig, for
    example, input offsets, which one training run's fit carries over to another but not to the held-out runs).

    **Returns:** `(gain, delta)` arrays: the fraction by which the candidate reduces the held-out
    residual sum of squares (beyond refitting the nominal parameters), and its coefficient step
    (from the fit on all of `train`).
    """
    length = shared_length(list(train) + list(validation))  # one compilation for the training and held-out records
    data = {
        name: [screening_data(family, values, coefficients, rec, residual_fn, length) for rec in records]
        for name, records in (("train", train), ("validation", validation))
    }
    grid = screening_grid(float(np.median(np.diff(np.asarray(train[0].ts)))))
    scale = np.concatenate([d[0] for d in data["train"]]).std(axis=0) + 1e-12
    refit = np.asarray(family.refit) > 0
    # (fitted on, scored on): all training records against the validation records, then each training
    # record against the others.
    splits = [(data["train"], data["validation"])]
    if cross_fit and len(train) >= 2:
        splits += [([d for j, d in enumerate(data["train"]) if j != r], [data["train"][r]]) for r in range(len(train))]

    def stacked(records):
        r, Jn, Jc = (np.concatenate([d[i] for d in records]) for i in range(3))
        return (r / scale).reshape(-1), Jn, Jc, {k: np.concatenate([d[3][k] for d in records]) for k in records[0][3]}

    splits = [(stacked(fitted), stacked(scored)) for fitted, scored in splits]

    def design(Jn, Jc, k, column=None):
        cols = [Jn[:, :, refit]] if refit.any() else []
        if column is not None:
            cols.append(column[:, :, None])
        elif k is not None:
            cols.append(Jc[:, :, k : k + 1])
        if not cols:
            return np.zeros((Jn.shape[0] * Jn.shape[1], 0))
        X = np.concatenate(cols, axis=2) / scale[None, :, None]
        return X.reshape(-1, X.shape[2])

    def sse(split, k, g=None):
        """Training and held-out sums of squares and the last coefficient (`g`: grid point of a delay or lag)."""
        (y_tr, Jn_tr, Jc_tr, grid_tr), (y_va, Jn_va, Jc_va, grid_va) = split
        col_tr = None if g is None else grid_tr[k][:, :, g]
        col_va = None if g is None else grid_va[k][:, :, g]
        X_tr, X_va = design(Jn_tr, Jc_tr, k, col_tr), design(Jn_va, Jc_va, k, col_va)
        if X_tr.shape[1] == 0:
            return float(np.sum(y_tr**2)), float(np.sum(y_va**2)), 0.0
        norms = np.linalg.norm(X_tr, axis=0)
        norms[norms == 0] = 1.0
        beta = np.linalg.lstsq(X_tr / norms, y_tr, rcond=None)[0] / norms
        return float(np.sum((y_tr - X_tr @ beta) ** 2)), float(np.sum((y_va - X_va @ beta) ** 2)), float(beta[-1])

    def held_out_sse(split, k):
        """The held-out sum of squares of candidate `k` on one split, and its coefficient step."""
        train_sse, held_out, delta = sse(split, k)
        if k in split[0][3]:
            # Finite sizes: the grid point that fits the training residuals best (its direction's
            # coefficient must be positive: a lag or delay of that size, scaled), if it beats first order.
            fits = [sse(split, k, g) for g in range(len(grid))]
            ok = [g for g, f in enumerate(fits) if f[2] > 0]
            if ok:
                g = min(ok, key=lambda g: fits[g][0])
                if fits[g][0] < train_sse:
                    held_out, delta = fits[g][1], float(grid[g] * min(max(fits[g][2], 0.5), 2.0))
        return held_out, delta

    bases = [sse(split, None)[1] for split in splits]
    gains, deltas = [], []
    for k in candidates_to_screen:
        per_split = [held_out_sse(split, k) for split in splits]
        gains.append(float(np.mean([1 - h / base for (h, _), base in zip(per_split, bases)])))
        deltas.append(per_split[0][1])
    return np.asarray(gains), np.asarray(deltas)
