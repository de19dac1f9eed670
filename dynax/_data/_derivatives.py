"""Derivative estimation and filtering of measured signals.

Central and backward differences work on irregular grids. Savitzky-Golay and Butterworth filters assume a uniform
grid: resample irregular records first with `resample` (they raise otherwise).
"""

import contextlib
import contextvars

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float
import numpy as np

from .._context import set_within
from .._errors import UsageError
from .._precision import host_times
from ._trajectory import Trajectory


def central_difference(ts: Float[ArrayLike, " time"], ys: Float[ArrayLike, "time ..."]) -> Float[Array, "time ..."]:
    r"""Second-order central differences $dy/dt$ on a possibly irregular grid (one-sided at the ends).

    `jnp.gradient(ys, ts, axis=0)`: on an irregular grid, the exact derivative of the quadratic
    through each three neighbouring samples (as `numpy.gradient`), first-order one-sided at the two
    ends. Jittable, vmappable and differentiable. Concrete times are taken relative to the first
    sample in float64 on the host before they reach the device, so long records lose less in
    float32 (see the float64 policy in the docs).

    **Arguments:**

    - `ts`: sample times, shape `(time,)`, strictly increasing.
    - `ys`: samples, shape `(time, ...)`.

    **Returns:** $dy/dt$ at `ts`, same shape as `ys`.
    """
    ts, ys = _times_and_samples(ts, ys, "central_difference", 3)
    return jnp.gradient(ys, ts, axis=0)


def _times_and_samples(ts, ys, function: str, min_samples: int):
    """`(ts, ys)` as arrays, concrete times relative to the first sample (float64 on the host first)
    and in the samples' float type; `ValueError` naming `function` for mismatched or too few samples."""
    ts = host_times(ts)
    if not isinstance(ts, jax.core.Tracer):
        ts = ts - ts[0] if ts.ndim == 1 and ts.size else ts
    ts = jnp.asarray(ts)
    ys = jnp.asarray(ys)
    if ts.ndim != 1 or ys.shape[:1] != ts.shape or ts.shape[0] < min_samples:
        raise ValueError(
            f"{function}: need `ts` (time,) with time >= {min_samples} and `ys` (time, ...); got {ts.shape}, {ys.shape}"
        )
    return ts.astype(jnp.result_type(ys, float)), ys


def backward_difference(ts: Float[ArrayLike, " time"], ys: Float[ArrayLike, "time ..."]) -> Float[Array, "time ..."]:
    r"""Backward differences $(y_i - y_{i-1}) / (t_i - t_{i-1})$ on a possibly irregular grid.

    The velocity a motor driver or logger computes from an encoder, one sample at a time: the DFKI
    rig's logged `vel_meas` is exactly this difference of `pos_meas` on the logged time stamps (to
    round-off, all six runs in `shared/datasets`). It is the exact derivative at the midpoint
    $(t_{i-1} + t_i)/2$ of anything quadratic, so at $t_i$ it lags by half an interval. Its noise
    density from white encoder noise, $4 \sin^2(\pi f \Delta t) / \Delta t^2$ times the encoder's,
    rises to the Nyquist frequency, where a central difference's vanishes: the noise floor that
    `choose_filter` reads from the upper half of the band is then the noise the derivative carries
    at its largest. The first sample takes the second's value. Jittable, vmappable, differentiable;
    concrete times are taken relative to the first sample in float64 on the host (as
    `central_difference`).

    **Arguments:**

    - `ts`: sample times, shape `(time,)`, strictly increasing.
    - `ys`: samples, shape `(time, ...)`.

    **Returns:** $dy/dt$ at `ts`, same shape as `ys`.
    """
    ts, ys = _times_and_samples(ts, ys, "backward_difference", 2)
    dt = jnp.diff(ts)
    slopes = jnp.diff(ys, axis=0) / dt.reshape(dt.shape + (1,) * (ys.ndim - 1))
    return jnp.concatenate([slopes[:1], slopes], axis=0)


# A stamp is replaced by the time its positions imply where that time is this many of its errors away...
STAMP_SIGNIFICANCE = 8.0
# ... and a quarter of the median interval or more from the stamp (smaller disagreements move a velocity by
# less than the positions' own noise does)
STAMP_SHIFT_FRACTION = 0.25


def _interpolants(ts: np.ndarray, qs: np.ndarray, rows: np.ndarray, at: np.ndarray):
    """At the time `at[m]` of each interior row `rows[m]` ($2 \\le i \\le n - 3$), from its four neighbours
    alone (their times `ts`): the cubic through them (value, slope, the squared weights of its value) and
    the two quadratics through three of them, each less the cubic, with the noise gain of that difference."""
    stencil = np.stack([rows - 2, rows - 1, rows + 1, rows + 2], axis=1)
    dt = ts[stencil] - at[:, None]
    value, slope = np.empty_like(dt), np.empty_like(dt)
    for k in range(4):
        a, b, c = (dt[:, m] for m in range(4) if m != k)
        denominator = (dt[:, k] - a) * (dt[:, k] - b) * (dt[:, k] - c)
        value[:, k] = -a * b * c / denominator
        slope[:, k] = (a * b + a * c + b * c) / denominator
    q = qs[stencil]
    differences = []
    for keep in ((0, 1, 2), (1, 2, 3)):
        weights = -value
        for s in keep:
            a, b = (dt[:, m] for m in keep if m != s)
            weights[:, s] += a * b / ((dt[:, s] - a) * (dt[:, s] - b))
        differences.append((np.einsum("mk,mkj->mj", weights, q), np.sqrt(np.sum(weights**2, axis=1))))
    cubic, velocity = np.einsum("mk,mkj->mj", value, q), np.einsum("mk,mkj->mj", slope, q)
    return cubic, velocity, np.sum(value**2, axis=1), differences


def even_grid_fit(ts: ArrayLike, qs: ArrayLike) -> tuple[float, float]:
    """How much better the positions `qs` (time x positions) follow the ticks of a steady clock (`steady_ticks`:
    an even grid fitted to the stamps, a dropped sample leaving its tick out) than the stamps `ts` themselves:
    `(ratio, stray)`, the ratio of the typical (median-square) residual of each interior sample from the cubic
    through its four neighbours on the ticks to that on the stamps (the least over the positions that move: one
    that barely does, its residual its noise on either time base, cannot hide the others), and the stamps'
    RMS distance from their ticks in median intervals. A logger whose
    samples are evenly spaced but whose stamps jitter (stamped when received, not when read) gives a ratio far
    below one; a clean record, or one read at jittered times that its stamps tell truly, about one or above.
    Host numpy."""
    ts = np.asarray(ts, dtype=float)
    qs = np.asarray(qs, dtype=float).reshape(len(ts), -1)
    if len(ts) < 7:
        return 1.0, 0.0
    from ._sampling import steady_ticks

    ticks = steady_ticks(ts)
    if ticks is None:
        return 1.0, 0.0
    times, even = ts - ts[0], ticks[0] - ts[0]
    interior = np.arange(2, len(ts) - 2)
    typical = [
        np.median((qs[interior] - _interpolants(t, qs, interior, t[interior])[0]) ** 2, axis=0) for t in (times, even)
    ]
    stamps, grid = typical
    moving = stamps > 0
    if not moving.any():
        return 1.0, 0.0
    ratio = float(np.sqrt(np.min(grid[moving] / stamps[moving])))
    interval = float(np.median(np.diff(ts)))
    return ratio, float(np.sqrt(np.mean((times - even) ** 2)) / interval)


def _time_shift(qs, rows, cubic, velocity):
    """The time shift that moves the cubic onto the rows' positions along the motion (one Newton step)."""
    speed2 = np.sum(velocity**2, axis=1)
    return np.sum(velocity * (qs[rows] - cubic), axis=1) / np.where(speed2 > 0, speed2, np.inf), speed2


def sample_times_from_positions(
    ts: Float[ArrayLike, " time"], qs: Float[ArrayLike, "time n_positions"], *, passes: int = 5
) -> tuple[np.ndarray, np.ndarray]:
    r"""The record's time stamps, with each stamp that disagrees with its positions replaced by the time they imply.

    A logger that reads the encoders, then stalls (a write, a scheduler), then reads the clock stamps the
    angles late: the DFKI rig's run 12 has 43 such rows, each 0.5 to 4.1 ms late at a 1.6 ms median interval
    (runs 00 to 02: 14 rows, most about 3 ms late at 2 ms). Differences of the angles divide by the wrong interval
    there: during a 12 rad/s spin central differences read 27 and 23 rad/s, the backward differences 3.9 then
    34 rad/s. Here each interior sample's positions are compared with the cubic through its four neighbours
    on their stamps; a disagreement along the motion, $r = q_i - p(t_i)$, is read as a time shift
    $s = \dot p \cdot r / |\dot p|^2$. It is taken where it is `STAMP_SIGNIFICANCE` errors from zero and at
    least `STAMP_SHIFT_FRACTION` of the median interval; the error is the positions' noise (the robust
    spread of $r$ over the record, times the cubic's noise gain) and, added in quadrature, the cubic's own
    error at that sample (how far the two quadratics through three of the neighbours differ from it beyond
    two errors of their noise), so that motion too fast for the neighbours to follow is not read as a late
    stamp. A pass moves one stamp in five samples at most (a wrong stamp moves its neighbours' cubics too),
    then every stamp moved so far to where the cubic meets its positions (Newton steps on the shift), kept
    between the neighbours'.
    Where the positions barely move a stamp cannot be read, and then matters as little; two late stamps
    side by side are not read. Clean records, with stamps jittered or not, move no stamp
    (`tests/data/test_derivatives.py`). Host numpy.

    **Arguments:**

    - `ts`: sample times, shape `(time,)`, strictly increasing.
    - `qs`: the positions sampled together at those times, shape `(time, n_positions)`.
    - `passes`: how many times the reading is repeated after moving stamps.

    **Returns:** `(times, rows)`: the times, and the 0-based rows whose stamp was replaced.
    """
    stamps = np.asarray(ts, dtype=float)
    qs = np.asarray(qs, dtype=float).reshape(len(stamps), -1)
    if len(stamps) < 7:
        return stamps.copy(), np.zeros(0, int)
    times, moved = stamps - stamps[0], set()  # relative to the first: an epoch's seconds keep their digits
    interval = float(np.median(np.diff(stamps)))
    interior = np.arange(2, len(stamps) - 2)
    cubic, *_ = _interpolants(times, qs, interior, times[interior])
    residual = qs[interior] - cubic
    spread = 1.4826 * np.median(np.abs(residual - np.median(residual, axis=0)), axis=0)
    noise = float(np.sqrt(np.mean(spread**2)))
    for _ in range(passes):
        cubic, velocity, gain, differences = _interpolants(times, qs, interior, times[interior])
        shift, speed2 = _time_shift(qs, interior, cubic, velocity)
        # the cubic's own error: how far the quadratics differ from it beyond two errors of the noise
        model = np.max([np.maximum(np.sqrt(np.sum(d**2, axis=1)) - 2 * noise * g, 0.0) for d, g in differences], axis=0)
        error = np.sqrt(noise**2 * (1 + gain) + model**2)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.nan_to_num(np.abs(shift) * np.sqrt(speed2) / error, posinf=0.0)
        z = np.where((z >= STAMP_SIGNIFICANCE) & (np.abs(shift) >= STAMP_SHIFT_FRACTION * interval), z, 0.0)
        padded = np.pad(z, 2)
        largest = np.all([z >= padded[2 + s : 2 + s + len(z)] for s in (-2, -1, 1, 2)], axis=0)
        pick = (z > 0) & largest
        times[interior[pick]] += shift[pick]
        moved.update(interior[pick].tolist())
        # the stamps moved so far, this pass's and those whose neighbours this pass moved, to where the cubic
        # meets their positions: the shift is linear in the cubic's slope, so a large one takes a few steps
        rows = np.array(sorted(moved), dtype=int)
        low, high = times[rows - 1] + 0.1 * interval, times[rows + 1] - 0.1 * interval
        at = np.clip(times[rows], low, high)
        for _ in range(4):
            cubic, velocity, _, _ = _interpolants(times, qs, rows, at)
            at = np.clip(at + _time_shift(qs, rows, cubic, velocity)[0], low, high)
        times[rows] = at
        if not pick.any():
            break
    # two stamps moved side by side may have crossed: such a pair keeps its stamps
    while (crossed := np.flatnonzero(np.diff(times) <= 0)).size:
        pair = np.union1d(crossed, crossed + 1)
        times[pair] = stamps[pair] - stamps[0]
        moved -= set(pair.tolist())
    rows = np.array(sorted(moved), dtype=int)
    sampled = stamps.copy()  # every other stamp exactly as given
    sampled[rows] = times[rows] + stamps[0]
    return sampled, rows


def _uniform_dt(ts, function):
    ts = np.asarray(ts)
    d = np.diff(ts)
    dt = float(np.median(d))
    if np.any(np.abs(d - dt) > 0.01 * dt):
        raise UsageError(
            f"{function}: the sampling is irregular (intervals {d.min():.3g} to {d.max():.3g} s); "
            "resample it first with dynax.resample(trajectory, dt)"
        )
    return dt


def savitzky_golay(
    ts: Float[ArrayLike, " time"], ys: Float[ArrayLike, "time ..."], *, window: int, order: int = 3, deriv: int = 0
) -> Float[Array, "time ..."]:
    """Savitzky-Golay smoothing or differentiation along time (uniform sampling).

    **Arguments:**

    - `ts`: uniform sample times, shape `(time,)`.
    - `ys`: samples, shape `(time, ...)`.
    - `window`: window length in samples (odd, > `order`).
    - `order`: polynomial order.
    - `deriv`: derivative order (0 smooths).

    **Returns:** the filtered signal or its `deriv`-th derivative, same shape as `ys`.

    ??? cite

        A. Savitzky and M. J. E. Golay, "Smoothing and differentiation of data by simplified least
        squares procedures", Analytical Chemistry 36(8), 1964.
    """
    if window % 2 == 0 or window <= order:
        raise UsageError(f"savitzky_golay: `window` must be odd and larger than `order`, got {window} (order {order})")
    dt = _uniform_dt(ts, "savitzky_golay")
    import scipy.signal  # lazily: keeps `import dynax` light

    out = scipy.signal.savgol_filter(np.asarray(ys), window, order, deriv=deriv, delta=dt, axis=0, mode="interp")
    return jax.device_put(out)  # not `jnp.asarray`: that compiles a copy for every new shape


def butterworth_filtfilt(
    ts: Float[ArrayLike, " time"], ys: Float[ArrayLike, "time ..."], *, cutoff_hz: float, order: int = 4
) -> Float[Array, "time ..."]:
    """Zero-phase low-pass Butterworth filter (forward-backward, `scipy.signal.sosfiltfilt`).

    The forward-backward pass doubles the effective order and cancels the phase, so filtered
    positions can be differentiated without a time shift (the usual recipe before inverse-dynamics
    identification).

    **Arguments:**

    - `ts`: uniform sample times, shape `(time,)`.
    - `ys`: samples, shape `(time, ...)`.
    - `cutoff_hz`: the -3 dB frequency of one pass [Hz], below the Nyquist frequency.
    - `order`: the filter order of one pass.

    **Returns:** the filtered signal, same shape as `ys`.
    """
    dt = _uniform_dt(ts, "butterworth_filtfilt")
    nyquist = 0.5 / dt
    if not 0 < cutoff_hz < nyquist:
        raise UsageError(f"butterworth_filtfilt: `cutoff_hz` must be in (0, {nyquist:g}) Hz, got {cutoff_hz}")
    import scipy.signal

    sos = scipy.signal.butter(order, cutoff_hz / nyquist, output="sos")
    return jnp.asarray(scipy.signal.sosfiltfilt(sos, np.asarray(ys), axis=0))


INPUT_RESAMPLING: contextvars.ContextVar[str] = contextvars.ContextVar("dynax_input_resampling", default="hold")
_INPUT_RULES = ("hold", "average", "linear")


@contextlib.contextmanager
def input_resampling(inputs: str):
    """Within the block, `resample` (and so `identify`'s own resampling of irregular records) puts the inputs on
    its grid by `inputs` (as its argument of that name) where it is not given: a what-if for the input timing."""
    if inputs not in _INPUT_RULES:
        raise UsageError(f"input_resampling: `inputs` must be one of {', '.join(_INPUT_RULES)}, got {inputs!r}")
    with set_within(INPUT_RESAMPLING, inputs):
        yield


def resample(trajectory: Trajectory, dt: float, *, inputs: str | None = None) -> Trajectory:
    """Resample a trajectory onto a uniform grid of step `dt` from its first sample.

    States are interpolated linearly. Inputs are, by `inputs`:

    - `"hold"` (the default): the value in force at each new sample time, as a zero-order hold logged at its
      changes gives it. An input logged at irregular stamps then reaches the grid up to an interval late: on
      a record of true stamps jittered by 0.1-0.3 ms at 100 Hz, the viscous dampings `identify` fits from it
      move by 5 to 12 % (`experiments/input_resampling.py`).
    - `"average"`: the time average of the recorded zero-order hold over each new interval (the input's
      integral kept; the recorded value where grid and stamps meet).
    - `"linear"`: interpolated linearly, as the states (a measured, continuous signal such as a torque).

    **Arguments:** `trajectory`; `dt` [s]; `inputs` (`None`: `"hold"`, or what `input_resampling` sets).

    **Returns:** a new `Trajectory` on the uniform grid.
    """
    if not dt > 0:
        raise UsageError(f"resample: `dt` must be positive, got {dt}")
    how = INPUT_RESAMPLING.get() if inputs is None else inputs
    if how not in _INPUT_RULES:
        raise UsageError(f"resample: `inputs` must be one of {', '.join(_INPUT_RULES)}, got {how!r}")
    ts = np.asarray(trajectory.ts)
    grid = ts[0] + dt * np.arange(int(np.floor((ts[-1] - ts[0]) / dt + 1e-9)) + 1)
    xs = np.stack([np.interp(grid, ts, col) for col in np.asarray(trajectory.xs).T], axis=1)
    recorded = np.asarray(trajectory.us)
    if how == "linear":
        us = np.stack([np.interp(grid, ts, col) for col in recorded.T], axis=1).reshape(len(grid), -1)
    elif how == "average":  # the recorded hold's integral, exact between stamps, held on past the last stamp
        ends = np.append(ts, max(ts[-1], grid[-1]) + dt)
        integral = np.vstack([np.zeros(recorded.shape[1]), np.cumsum(recorded * np.diff(ends)[:, None], axis=0)])
        at = [np.stack([np.interp(t, ends, col) for col in integral.T], axis=1) for t in (grid, grid + dt)]
        us = ((at[1] - at[0]) / dt).reshape(len(grid), -1)
    else:
        # a stamp on a grid point is in force there, however the grid's sums round (1e-6 of an interval: far
        # below any clock's jitter, far above round-off)
        us = recorded[np.clip(np.searchsorted(ts, grid + 1e-6 * dt, side="right") - 1, 0, len(ts) - 1)]
    return Trajectory(
        grid,
        jnp.asarray(xs),
        jnp.asarray(us),  # times stay float64 on the host
        trajectory.state_names,
        trajectory.input_names,
        trajectory.system,
        trajectory.source,
    )
