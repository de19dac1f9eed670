r"""Residual analysis of one-step accelerations, and a probe for structure left in them.

The measured acceleration is the Savitzky-Golay derivative of the measured velocities; the
model's is its vector field at the (equally smoothed) measured state, with the terms' internal states
driven along the record (`hidden_trajectory`). What is left,
$r_k = \dot v_k^{\text{meas}} - f_v(x_k, u_k)$, should be noise if the model is right.

The *structure probe* regresses the residuals of the training record on a generic library of
features of state and input (velocity, its sign, $|v|v$, position, $\sin q$, $\cos q$, the
model's own acceleration, the input, its derivative and a delayed copy) and asks whether the
fitted regression predicts the residuals of the *held-out* record better than zero, with a paired
test over one-second blocks. It knows nothing of the candidate causes, so it sees structure the
vocabulary does not cover (a spring at a joint) and tells `none` from `unexplained`.

??? cite

    L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, section 16.6 (model
    validation: residual analysis, correlation of residuals with past inputs).
    S. A. Billings and W. S. F. Voon, "Correlation based model validity tests for non-linear
    models", International Journal of Control 44(1), 1986.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._data._derivatives import savitzky_golay
from .._model._extensions import AbstractInputTerm, Extended
from .._simulate import AlongStates, FixedGrid, InputStates, RK4, simulate
from ._probe import cross_validated_ridge, ridge_fit


def sg_window(dt: float) -> int:
    """The Savitzky-Golay window (samples: odd, at least 7, about 0.1 s) that smooths a record sampled every `dt`
    for its one-step residuals."""
    w = int(round(0.1 / dt)) | 1
    return max(w, 7)


STATE_ORDER = 5  # the local polynomial the states are read through (the accelerations' derivative fit is cubic)


def smoothed_states(trajectory) -> jax.Array:
    r"""The states the model's accelerations are evaluated at: a local quintic fit over `sg_window` samples.

    A cubic fit over the same window is biased by the motion's fourth derivative ($\propto (\omega T)^4$ over a
    window $T$): on an arm whose motion is fast for the window (a 5 cm double pendulum, 15 rad/s, at 0.1 s) the
    model's accelerations at those states leave a structured residual of 4 % of the accelerations even in the true
    model, which the probe reads as a missing effect. The quintic fit's bias is of order $(\omega T)^6$; it passes
    somewhat more noise, which the residuals' own derivative filter then averages."""
    return savitzky_golay(trajectory.ts, trajectory.xs, window=sg_window(trajectory.dt), order=STATE_ORDER)


def as_measured(ts, accelerations, window: int, left=None) -> np.ndarray:
    r"""Model accelerations (`(time, ...)`, at the samples) through the filter the measured ones pass.

    The measured acceleration is the cubic Savitzky-Golay derivative $D$ of the measured velocity. The model's
    is integrated along the record (trapezoids: the held input's two limits averaged at each sample) and passed
    through the same $D$, so that both see one frequency response: smoothing the model's acceleration instead
    (a cubic fit of it) leaves the difference of two responses, $(H_D - H_S)\,a$, structured in the accelerations
    themselves. Sensitivities of the accelerations go through the same filter (the operator is linear).
    """
    ts = np.asarray(ts)
    right = np.asarray(accelerations)
    left = right if left is None else np.asarray(left)
    h = np.diff(ts).reshape((-1,) + (1,) * (right.ndim - 1))
    increments = 0.5 * h * (right[:-1] + left[1:])  # each interval under its own held input
    velocity = np.concatenate([np.zeros_like(right[:1]), np.cumsum(increments, axis=0)])
    return np.asarray(savitzky_golay(ts, velocity, window=window, order=3, deriv=1))


# Four RK4 steps per sample interval: the one-step residuals compare accelerations, so the input
# terms' states must be accurate at every sample, not only at a window's end.
_HIDDEN_GRID = FixedGrid(solver=RK4(scan_kind="lax"), substeps=4)


@eqx.filter_jit
def hidden_trajectory(model, ts, us, xs=None):
    """Internal states of the model's terms along the recorded inputs (RK4 with 4 steps per sample): the input terms'
    from rest under the first input (`simulate` on `InputStates`); where any other term has states of its own
    (`Extended.state_terms`), every state along the measured states `xs` (required then), from
    `Extended.initial_state` at the first sample."""
    n_extra = model.n_states - model.system.n_states if isinstance(model, Extended) else 0
    if n_extra == 0:
        return jnp.zeros((ts.shape[0], 0), us.dtype)
    n = model.system.n_states
    if model.state_terms:
        if xs is None:
            raise ValueError("hidden_trajectory: a model with states of terms other than input terms needs `xs`")
        z0 = model.initial_state(xs[0], us[0])[n:]
        along = AlongStates(model, ts, xs)  # pyright: ignore[reportCallIssue]
        return simulate(along, z0, ts, us, method=_HIDDEN_GRID, throw=False).xs
    z0 = model.initial_state(jnp.zeros(n, us.dtype), us[0])[n:]
    return simulate(InputStates(model), z0, ts, us, method=_HIDDEN_GRID, throw=False).xs


@eqx.filter_jit
def predicted_accelerations(model, ts, xs_smooth, us, idx, us_before, limits: bool = False):
    """The model's acceleration at each sample: the mean of its left and right limits under the held input
    (with `limits`, the two: `(right, left)`).

    The input is a zero-order hold, so the true acceleration jumps at every sample: at t_k it is
    the mean of the left limit (input u_{k-1}) and the right limit (u_k).
    """
    zs = hidden_trajectory(model, ts, us, xs_smooth)
    full = jnp.concatenate([xs_smooth, zs], axis=1)
    field = jax.vmap(lambda t, x, u: model.vector_field(t, x, u))
    right, left = field(ts, full, us)[:, idx], field(ts, full, us_before)[:, idx]
    return (right, left) if limits else 0.5 * (right + left)


_INTERVAL_SUBSTEPS = 4  # RK4 steps per sample interval of the one-step increments


@eqx.filter_jit
def interval_increments(model, ts, xs_smooth, us, idx):
    """The model's velocity increment over each sample interval under the held input: one RK4 integration
    (`_INTERVAL_SUBSTEPS` steps) from the smoothed state and the input terms' internal state at the interval's
    start. Exact to the integrator's order where a trapezoid of the end accelerations is not: an input lag's
    applied input curves within the interval, by an amount that follows the input's rate."""
    zs = hidden_trajectory(model, ts, us, xs_smooth)
    full = jnp.concatenate([xs_smooth, zs], axis=1)

    def increment(t, x, u, dt):
        h = dt / _INTERVAL_SUBSTEPS

        def rk4(carry, _):
            s, y = carry
            k1 = model.vector_field(s, y, u)
            k2 = model.vector_field(s + h / 2, y + h / 2 * k1, u)
            k3 = model.vector_field(s + h / 2, y + h / 2 * k2, u)
            k4 = model.vector_field(s + h, y + h * k3, u)
            return (s + h, y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)), None

        (_, end), _ = jax.lax.scan(rk4, (t, x), None, length=_INTERVAL_SUBSTEPS)
        return (end - x)[idx]

    return jax.vmap(increment)(ts[:-1], full[:-1], us[:-1], jnp.diff(ts))


def velocity_indices(system) -> list[int]:
    """The states whose derivatives the residual analysis looks at: the system's `velocity_indices`
    (a manipulator's joint velocities, a helicopter's body velocities and rates)."""
    return list(system.velocity_indices)


def _held_average(ts, u, a, b):
    """The mean of the zero-order-hold signal `u` (held from each sample time) over `[a, b]` (arrays of times)."""
    cumulative = np.concatenate([[0.0], np.cumsum(u[:-1] * np.diff(ts))])

    def integral(s):
        i = np.clip(np.searchsorted(ts, s, side="right") - 1, 0, len(ts) - 1)
        return cumulative[i] + u[i] * (s - ts[i])  # before the record: the first value held back in time

    return (integral(b) - integral(a)) / (b - a)


#: The causes that are a dead time on their inputs (`InputDelay`, `MotorDelay`): run as the shifted input.
DEAD_TIMES = ("input_delay", "motor_delay")
#: The causes that are a first-order lag on their inputs (`InputLag`, `MotorLag`).
LAGS = ("input_lag", "motor_lag")


def input_dynamics(term, system) -> bool:
    """Whether `term` is an input term with internal states (`AbstractTerm.hidden_names`): a lag or a dead time,
    whose coefficient is a time of the input's dynamics and has no derivative at zero (the input passes through)."""
    return isinstance(term, AbstractInputTerm) and bool(term.hidden_names(system))


#: The fewest samples a record is padded to for the jitted per-sample functions (`padded_length`).
MIN_PADDED = 256


def padded_length(n: int) -> int:
    """The samples a record of `n` samples is evaluated on by the jitted per-sample functions here
    (`predicted_accelerations`, `interval_increments`, `hidden_trajectory`, the screening's directions): the next
    power of two, at least `MIN_PADDED`.

    Each is compiled once per shape, and whole flight logs each have their own length: three flights cost three
    compilations of each (tens of seconds apiece on two cores, most of a diagnosis's screening), where flights
    padded to one length share one. Every one of these functions is per sample or causal (an integration forward
    in time), so the first `n` samples of its result on the padded record are its result on the record: the
    padding (`padded`) is cut off again, and no number changes."""
    return max(MIN_PADDED, 1 << (max(int(n), 1) - 1).bit_length())


def shared_length(records) -> int:
    """The length every one of `records` is padded to (`padded`'s `length`): `padded_length` of the longest.

    A diagnosis's training and held-out records differ in length (70 and 30 % of one file: two powers of two), and
    each length compiled the per-sample functions of every model anew; padded to the longest, they share one
    compilation of each (about 3 s of a first diagnosis), and the per-sample work of the held-out records grows
    by less than it takes to compile."""
    return padded_length(max(len(r) for r in records))


def padded(ts, *samples, length: int = 0) -> tuple:
    """`ts` and the per-sample arrays `samples` (leading axis time) extended to `padded_length(len(ts))` samples,
    or to `length` where that is more (`shared_length`): the times on, at the last interval, the samples as their
    last value (host-side, so that the padding itself compiles nothing)."""
    ts_ = np.asarray(ts)
    n = len(ts_)
    extra = max(padded_length(n), int(length)) - n
    dt = ts_[-1] - ts_[-2] if n > 1 else 1.0
    out = [np.concatenate([ts_, ts_[-1] + dt * np.arange(1, extra + 1, dtype=ts_.dtype)])]
    for a in samples:
        a = np.asarray(a)
        out.append(np.concatenate([a, np.repeat(a[-1:], extra, axis=0)]))
    return tuple(jax.device_put(a) for a in out)  # not `jnp.asarray`: that compiles a copy for every new shape


def exact_delays(model, trajectory, interval: bool = False):
    """Run an active input delay as the dead time it stands for, not as its Pade filter.

    A model found with `input_delay` or `motor_delay` simulates it with a Pade approximant, which passes a held
    input's every step through at once (its high-frequency gain is one) and then rings. Judged on
    one-step residuals, that model would still show `du/dt` structure where the rig has a pure
    dead time. Here each active delay is replaced by the recorded input itself, shifted by the delay (several
    delays on one input one after the other, as `Extended.with_shifted_inputs` shifts them: a dead time commutes
    with the other input terms, a gain, an offset, a lag): the held input's mean over the sample interval
    centred on `t - T` (what the left and right limits average to at `T` a whole number of samples, and
    continuous in `T` in between), and the term is set to zero delay (it then passes the shifted input through).

    With `interval`, a delayed input is instead its mean over the sample interval that starts at
    `t - T` (what acts over `[t, t + dt]`), for comparisons of velocity increments over the intervals.

    **Returns:** `(model, us, us_before)`: the model to evaluate, and the input's right and left
    limits at each sample (equal, the interval mean, for a delayed input).
    """
    ts = np.asarray(trajectory.ts)
    us = np.array(trajectory.us)
    us_before = np.concatenate([us[:1], us[:-1]])
    if not isinstance(model, Extended):
        return model, jnp.asarray(us), jnp.asarray(us_before)
    half = 0.5 * float(np.median(np.diff(ts)))
    for k, term in enumerate(model.terms):
        if not (isinstance(term, AbstractInputTerm) and term.cause in DEAD_TIMES and float(term.coefficient) > 0):
            continue
        centre = ts - float(term.coefficient) + (half if interval else 0.0)
        for i in term.inputs:  # on the input as the delays before this one left it
            us[:, i] = us_before[:, i] = _held_average(ts, us[:, i].copy(), centre - half, centre + half)
        model = eqx.tree_at(lambda m: m.terms[k].coefficient, model, jnp.zeros_like(term.coefficient))
    dtype = jax.dtypes.canonicalize_dtype(trajectory.us.dtype)  # float32 where JAX's float64 mode is off, silently
    return model, jnp.asarray(us, dtype), jnp.asarray(us_before, dtype)


def applied_inputs(system, terms, trajectory) -> np.ndarray:
    """The inputs that act over each sample interval of `trajectory` when its recorded inputs pass through the
    input `terms` (at their coefficients) of an `Extended(system, terms)`: a dead time as the shifted input's
    interval mean (`exact_delays`), a lag as its output's mean over the interval (trapezoid of the internal
    state at the interval's ends, `hidden_trajectory`). Other inputs as recorded. **Returns:** `(time, n_inputs)`."""
    extended = Extended(system, tuple(terms))  # pyright: ignore[reportCallIssue]
    model, us, _ = exact_delays(extended, trajectory, interval=True)
    us = np.array(us)
    ts = jnp.asarray(trajectory.ts, us.dtype)
    for term in model.input_terms:
        if not input_dynamics(term, system) or (term.cause in DEAD_TIMES and not float(term.coefficient) > 0):
            continue
        alone = Extended(system, (term,))  # pyright: ignore[reportCallIssue]
        ts_p, us_p = padded(ts, us)
        zs = np.asarray(hidden_trajectory(alone, ts_p, us_p))[: len(us)]  # causal: the padding changes nothing
        applied = jax.vmap(term.applied)
        for i, z in zip(term.inputs, np.split(zs, len(term.inputs), axis=1)):  # each input's states in turn
            z = jnp.asarray(z)
            u = jnp.asarray(us[:, i])
            start, end = np.asarray(applied(u, z)), np.asarray(applied(u[:-1], z[1:]))
            us[:-1, i] = 0.5 * (start[:-1] + end)
            us[-1, i] = start[-1]
    return us


def acceleration_residuals(model, trajectory, *, length: int = 0):
    """One-step acceleration residuals of `model` on `trajectory` (its per-sample functions run on the record
    padded to `length` samples where that is more than its own `padded_length`: see `shared_length`).

    **Returns:** `(residuals (time, n_velocities), smoothed states (time, n_states), model accelerations,
    keep)`, `keep` the slice of samples they cover (the filter's start-up and run-out left out).
    """
    nominal = model.system if isinstance(model, Extended) else model
    ts = trajectory.ts
    dt = trajectory.dt
    w = sg_window(dt)
    xs_smooth = smoothed_states(trajectory)
    idx = velocity_indices(nominal)
    given = model  # before its delays are replaced by the shifted inputs
    model, us, us_before = exact_delays(model, trajectory)
    n = len(ts)  # evaluated on the padded record (one compilation for records of any length near it), cut back
    ts_p, xs_p, us_p, before_p = padded(ts, xs_smooth, us, us_before, length=length)
    # Cut on the host (in JAX the slice compiles a program per record length).
    right, left = predicted_accelerations(model, ts_p, xs_p, us_p, jnp.asarray(idx), before_p, limits=True)
    # The model's acceleration as the measured one is read (the probe's feature, the report's prediction).
    predicted = as_measured(ts, np.asarray(right)[:n], w, np.asarray(left)[:n])
    # The residual: the measured velocity's change over each sample interval less the model's, integrated under
    # the held input from the interval's start (exact where accelerations at the samples are not: the input jumps
    # at every sample, and the acceleration curves within the interval), accumulated and differentiated by the
    # filter the measured acceleration is read with.
    interval_model, interval_us, _ = exact_delays(given, trajectory, interval=True)
    _, interval_p = padded(ts, interval_us, length=length)
    increments = np.asarray(interval_increments(interval_model, ts_p, xs_p, interval_p, jnp.asarray(idx)))[: n - 1]
    drift = np.diff(np.asarray(trajectory.xs)[:, idx], axis=0) - increments
    accumulated = np.concatenate([np.zeros((1, len(idx)), drift.dtype), np.cumsum(drift, axis=0)])
    drift_rate = np.asarray(savitzky_golay(ts, accumulated, window=w, order=3, deriv=1))
    # The filter's start-up and run-out samples are not trusted.
    keep = slice(w, len(ts) - w)
    return drift_rate[keep], np.asarray(xs_smooth)[keep], predicted[keep], keep


def probe_features(system, xs, us, predicted, dt) -> tuple[np.ndarray, list[str]]:
    """The generic feature library the probe regresses residuals on (columns standardised later)."""
    cols, names = system.residual_features(xs, predicted)  # what differs per system is a method on it
    lag = max(1, int(round(0.03 / dt)))
    for i, c in enumerate(system.input_names):
        u = us[:, i]
        du = np.gradient(u, dt)
        cols += [u, np.concatenate([np.full(lag, u[0]), u[:-lag]]), du]
        names += [c, f"{c} {lag * dt * 1000:.0f} ms earlier", f"d{c}/dt"]
    cols.append(np.ones(xs.shape[0]))
    names.append("constant")
    return np.stack(cols, axis=1), names


class Structure(eqx.Module):
    """The probe's answer: is there structure left in a model's one-step residuals?

    **Fields:** `significant`; `r2` the fraction of held-out residual variance the probe
    explains; `p_value` of the paired block test; `top_features` (name, share) most responsible;
    `worst_times` (start [s] of the held-out blocks with the largest residuals); `by_state` the
    share of residual energy per velocity.
    """

    significant: bool
    r2: float
    p_value: float
    top_features: tuple
    worst_times: tuple
    by_state: dict


def structure_test(
    model, train, validation, *, alpha: float = 0.01, min_r2: float = 0.05, block_s: float = 0.25
) -> Structure:
    """Fit the probe on the training residuals, test it on the held-out residuals (see module docs).

    **Arguments:** `model`; `train`, `validation` (a `Trajectory` or a list of them); `alpha` level;
    `min_r2` smallest held-out share of residual variance that counts as structure; `block_s`
    block length of the paired test [s].

    **Returns:** a `Structure`.
    """
    import scipy.stats  # lazily: keeps `import dynax` light

    nominal = model.system if isinstance(model, Extended) else model
    train = list(train) if isinstance(train, (list, tuple)) else [train]
    validation = list(validation) if isinstance(validation, (list, tuple)) else [validation]
    feats, resid, times, sizes = [], [], [], []
    length = shared_length(train + validation)
    for records in (train, validation):
        parts = [acceleration_residuals(model, traj, length=length) for traj in records]
        phis = [
            probe_features(nominal, xs, np.asarray(traj.us)[keep], pred, traj.dt)
            for traj, (_, xs, pred, keep) in zip(records, parts)
        ]
        names = phis[0][1]
        feats.append(np.concatenate([phi for phi, _ in phis]))
        resid.append(np.concatenate([r for r, *_ in parts]))
        times.append(np.concatenate([np.asarray(traj.ts)[keep] for traj, (*_, keep) in zip(records, parts)]))
        sizes.append([r.shape[0] for r, *_ in parts])
    scale = resid[0].std(axis=0) + 1e-12
    mu, sd = feats[0].mean(axis=0), feats[0].std(axis=0)
    sd[sd == 0] = 1.0
    mu[-1] = 0.0
    Phi_tr, Phi_va = (feats[0] - mu) / sd, (feats[1] - mu) / sd
    Phi_tr[:, -1], Phi_va[:, -1] = 1.0, 1.0
    R_tr, R_va = resid[0] / scale, resid[1] / scale
    # The ridge strength by leave-one-run-out cross-validation: only structure that transfers to a
    # run the probe was not fitted on counts (see `cross_validated_ridge`).
    strength, _ = cross_validated_ridge(Phi_tr, R_tr, sizes[0])
    beta = ridge_fit(Phi_tr, R_tr, strength)
    E_va = R_va - Phi_va @ beta
    sse0 = (R_va**2).sum(axis=1)
    sse1 = (E_va**2).sum(axis=1)
    r2 = float(1 - sse1.sum() / sse0.sum())
    block = max(1, int(round(block_s / validation[0].dt)))
    b0, b1, t_blocks, start = [], [], [], 0
    for size in sizes[1]:  # blocks never cross a run boundary
        nb_run = size // block
        sl = slice(start, start + nb_run * block)
        b0.append(sse0[sl].reshape(nb_run, block).sum(axis=1))
        b1.append(sse1[sl].reshape(nb_run, block).sum(axis=1))
        t_blocks.append(times[1][sl][::block])
        start += size
    b0, b1, t_blocks = np.concatenate(b0), np.concatenate(b1), np.concatenate(t_blocks)
    nb = b0.size
    d = (
        (b0 - b1) / b0.mean() if nb else np.zeros(0)
    )  # per-block improvement; a log ratio would let near-empty blocks dominate
    if nb >= 3 and d.std(ddof=1) > 0:
        t = d.mean() / (d.std(ddof=1) / np.sqrt(nb))
        p = float(scipy.stats.t.sf(t, nb - 1))
    else:
        p = 1.0
    # Which features carry the explained part: drop each one and see what is lost on held-out data.
    share = np.abs(beta).sum(axis=1) * Phi_va.std(axis=0)
    share[-1] = 0.0
    share = share / max(share.sum(), 1e-300)
    order = np.argsort(share)[::-1][:4]
    worst = np.argsort(b0)[::-1][:3] if nb else []
    vel_names = [nominal.state_names[i] for i in velocity_indices(nominal)]
    energy = (R_va**2).sum(axis=0)
    return Structure(
        significant=bool(p < alpha and r2 > min_r2),
        r2=r2,
        p_value=p,
        top_features=tuple((names[k], float(share[k])) for k in order),
        worst_times=tuple(float(t_blocks[k]) for k in worst),
        by_state={n: float(e / energy.sum()) for n, e in zip(vel_names, energy)},
    )
