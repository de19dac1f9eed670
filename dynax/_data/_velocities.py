r"""A check that each measured velocity column is the derivative of its position column.

A velocity logged in other units than its angle (degrees per second, revolutions, rpm, the motor's
side of a gear), with the opposite sign, or mapped from another joint's column, makes every model
fitted to the record wrong, and nothing downstream names the cause: the least-squares fit and the
simulation both go on. So `load_trajectory` compares them. Over blocks of about 50 ms, the mean of a
velocity column equals the change of its position over the block divided by the block's duration
(the secant slope) whatever the velocity's noise, filter or lag, up to the curvature inside a block.
The gain $g$ of the block means $m$ on the secant slopes $s$ (least squares, $m \approx g s$) is 1 for
a velocity in the position's units per second. Noise in $m$ averages out of $g$ (it is in the
regression's output); noise in $s$ is the encoder's, divided by the block's duration (a few per cent
of the motion for a 1e-4 rad encoder, even without averaging). A record is refused where $g$ is
off by more than `MAX_GAIN_ERROR` and by more than `SIGNIFICANCE` of its own standard errors: a
record that barely moves cannot tell, and is let through.

Where the position's noise is not small against its change over a block (a flight held level within a
few centimetres under millimetre motion-capture noise), the noise in $s$ pulls $g$ towards zero: the
regression's errors in the variables (Fuller 1987, sec. 1.1). Then $s \cdot s$ holds, besides the
motion, the slopes' noise $\sum_k 2\sigma_q^2 / T_k^2$, with $\sigma_q$ the position's white noise
read from its third differences (`position_noise_std`), and the gain read without it
(`corrected_gain`) is what the record says. A record is refused only where both readings are off (a
velocity computed by the logger from the same noisy positions carries the same noise, and its
uncorrected gain is the right one); one whose slopes are no larger than their noise cannot tell.
"""

from typing import NamedTuple

import numpy as np

from .._errors import DataError
from ._screens import SCREENS

BLOCK_S = 0.05  # block duration [s]: long against the encoder noise, short against the motion
MIN_BLOCKS = 20  # fewer blocks than this: too short to tell, no check
MAX_GAIN_ERROR = 0.2  # |g - 1| above this (and significant) refuses the record
SIGNIFICANCE = 5.0  # ... by this many standard errors of g

# Factors a velocity's gain takes when its unit differs from its position's (velocity unit per
# position unit per second), named in the error, with the scales that make both the contract's units
# (radians or metres, per second): the velocity's, and the position's where the position is the one off.
_KNOWN_FACTORS = {
    "degrees per second, the position in radians": (180.0 / np.pi, np.pi / 180.0, None),
    "radians per second, the position in degrees": (np.pi / 180.0, None, np.pi / 180.0),
    "revolutions per second, the position in radians": (1.0 / (2.0 * np.pi), 2.0 * np.pi, None),
    "radians per second, the position in revolutions": (2.0 * np.pi, None, 2.0 * np.pi),
    "rpm, the position in radians": (60.0 / (2.0 * np.pi), 2.0 * np.pi / 60.0, None),
    "rpm, the position in degrees": (60.0 / 360.0, 2.0 * np.pi / 60.0, np.pi / 180.0),
    "millimetres per second, the position in metres": (1000.0, 1e-3, None),
    "metres per second, the position in millimetres": (1e-3, None, 1e-3),
    "the opposite sign (an encoder or a velocity counted the other way)": (-1.0, -1.0, None),
}


def velocity_pairs(state_names) -> dict[str, str]:
    """Velocity name -> position name for the states named `dX` beside an `X` (the manipulators' and
    the linear axis's joints; a helicopter's body-frame velocities have no such pair)."""
    return {v: v[1:] for v in state_names if v.startswith("d") and v[1:] in state_names}


def stretch_edges(ts: np.ndarray, dt: float | None = None) -> np.ndarray:
    """Block boundaries (sample indices) of about `BLOCK_S` each, at least `MIN_BLOCKS` if the record allows;
    `dt`, the median sampling interval where already known."""
    duration = float(ts[-1] - ts[0])
    dt = float(np.median(np.diff(ts))) if dt is None else dt
    block = max(min(BLOCK_S, duration / MIN_BLOCKS), 2.0 * dt)
    edges = np.searchsorted(ts, ts[0] + block * np.arange(int(duration / block) + 1))
    return edges[np.concatenate([[True], np.diff(edges) != 0])]  # sorted already: `np.unique` without a sort


def _block_slopes(ts, q, v, edges=None):
    """`(slopes, means)`: the secant slopes of the position `q` and the mean velocities `v` over the blocks of
    `stretch_edges` (`edges` where already known), or `None` for fewer than `MIN_BLOCKS` blocks."""
    ts, q, v = (np.asarray(a, dtype=float) for a in (ts, q, v))
    edges = stretch_edges(ts) if edges is None else edges
    if len(edges) < MIN_BLOCKS + 1:
        return None
    return block_slopes(ts, q, v, edges)


def block_slopes(ts, q, v, edges) -> tuple[np.ndarray, np.ndarray]:
    """`(slopes, means)`: the secant slopes of the position `q` and the mean velocities `v` (trapezoid rule on the
    samples) over the blocks between consecutive sample indices `edges`, however few."""
    start, stop = edges[:-1], edges[1:]  # block k: samples start[k] .. stop[k] (its last shared with the next)
    slopes = (q[stop] - q[start]) / (ts[stop] - ts[start])
    area = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(ts))])
    means = (area[stop] - area[start]) / (ts[stop] - ts[start])
    return slopes, means


def _block_gain(ts, q, v, edges=None):
    """`(gain, slopes, means, slopes @ slopes)` of `velocity_gain` (its gain alone, and what its errors are
    computed from), or `None` as there; `edges`, the record's `stretch_edges` where already known."""
    return _gain_of(_block_slopes(ts, q, v, edges))


def _gain_of(blocks):
    """`_block_gain` from `_block_slopes`' `(slopes, means)` (or its `None`)."""
    if blocks is None:
        return None
    slopes, means = blocks
    ss = float(slopes @ slopes)
    if not ss > 0:
        return None
    return float(slopes @ means) / ss, slopes, means, ss


def gain_surely_within(slopes: np.ndarray, means: np.ndarray, error: float) -> bool:
    r"""Whether `_block_gain`'s gain `float(slopes @ means) / float(slopes @ slopes)` is surely within `error`
    of 1, read from numpy's sums of the products instead of the two BLAS dot products (on a record of
    100,000 samples these wake BLAS's threads, which cost more than the rest of the check): any order of
    summing `k` products lies within $(k + 1) u \sum |s_i m_i|$ of the exact sum ($u$ the unit round-off),
    so the two ways differ by at most twice that, and the gain by what follows from it. `True` only where
    the BLAS gain is within `error` of 1 however the two sums round (then `ss > 0` too); `False` where that
    is not certain (a gain near the bound, or not finite), and the caller computes it."""
    k = len(slopes)
    sm, ss = float(np.sum(slopes * means)), float(np.sum(slopes * slopes))
    scale = 8.0 * (k + 2) * np.finfo(float).eps  # twice the bound, and twice again for the bound's own rounding
    d_sm, d_ss = scale * float(np.sum(np.abs(slopes * means))), scale * ss
    if not (ss > 0 and d_ss < 0.5 * ss):
        return False
    gain = sm / ss
    bound = (d_sm + abs(sm) * d_ss / ss) / (ss - d_ss) + 4.0 * np.finfo(float).eps * (abs(gain) + 1.0)
    return bool(abs(gain - 1.0) + bound <= error)


def velocity_gain(ts, q, v) -> tuple[float, float, float] | None:
    """`(gain, std_error, correlation)` of a velocity column's block means on its position's secant
    slopes (see the module notes), or `None` when the record has fewer than `MIN_BLOCKS` blocks
    (of two intervals or more), or does not move."""
    found = _block_gain(ts, q, v)
    if found is None:
        return None
    gain, slopes, means, ss = found
    residual = means - gain * slopes
    std = float(np.sqrt(residual @ residual / max(len(slopes) - 1, 1) / ss))
    spread = float(np.std(means)) * float(np.std(slopes))
    corr = float(np.mean((means - means.mean()) * (slopes - slopes.mean())) / spread) if spread > 0 else 0.0
    return gain, std, corr


def position_noise_std(q) -> float:
    r"""The standard deviation of a position's white measurement noise, from the median absolute deviation
    of its third differences ($\sqrt{20}\,\sigma$ for white noise; a smooth motion's jerk times $\Delta t^3$
    adds little at the rates motion is logged at, and the median ignores the few samples where it does)."""
    d3 = np.diff(np.asarray(q, dtype=float), 3)
    if d3.size < 8:
        return 0.0
    return 1.4826 * float(np.median(np.abs(d3 - np.median(d3)))) / np.sqrt(20.0)


def corrected_gain(ts, q, slopes, means, edges) -> tuple[float, float] | None:
    """`(gain, factor)`: the gain of `velocity_gain` with the position's noise taken out of the slopes' sum of
    squares (see the module notes) and the factor that took it out (it scales the gain's standard error too),
    or `None` where the slopes are no larger than their noise (the record cannot tell)."""
    ts = np.asarray(ts, dtype=float)
    durations = ts[edges[1:]] - ts[edges[:-1]]
    noise = 2.0 * position_noise_std(q) ** 2 * float(np.sum(1.0 / durations**2))
    ss = float(slopes @ slopes)
    if not ss > 2.0 * noise:
        return None
    return float(slopes @ means) / (ss - noise), ss / (ss - noise)


def _refused(gain: float, std: float) -> bool:
    return bool(abs(gain - 1.0) > MAX_GAIN_ERROR and abs(gain - 1.0) > SIGNIFICANCE * std)


STRETCHES = 8  # the record is cut into this many stretches to ask whether a wrong gain holds in all of them


def stretch_gains(ts, q, v):
    """`velocity_gain` in each of `STRETCHES` stretches of the record in turn (`None` for a stretch too short
    to tell), lazily: the callers stop at the first stretch that disagrees."""
    ts, q, v = (np.asarray(a, dtype=float) for a in (ts, q, v))
    bounds = np.linspace(0, len(ts), STRETCHES + 1).astype(int)
    for a, b in zip(bounds[:-1], bounds[1:]):
        yield velocity_gain(ts[a:b], q[a:b], v[a:b]) if b - a > 4 * MIN_BLOCKS else None


def gain_holds_everywhere(ts, q, v, gain: float) -> bool:
    """Whether a velocity's gain on its position's derivative is `gain` (to `MAX_GAIN_ERROR`) in each of
    `STRETCHES` stretches of the record that move: then it is a unit or a sign, and one `scale` fixes the
    whole record; otherwise a stretch is at fault (`dynax._data._sanity` names it) and no scale is right."""
    seen = 0
    for found in stretch_gains(ts, q, v):
        if found is None or not found[1] < MAX_GAIN_ERROR * max(abs(gain), 1.0):
            continue  # too short or too still to tell
        seen += 1
        if abs(found[0] - gain) > MAX_GAIN_ERROR * max(abs(gain), 1.0):
            return False
    return seen > 0


def wrong_in_every_stretch(ts, q, v) -> list[float] | None:
    """The gains of `stretch_gains` where the velocity is off its position's derivative (`_refused`) in every
    stretch that moves enough to tell, at least two: a column that is no derivative of this position anywhere
    (another joint's, another signal), by no one gain; `None` where some stretch agrees or too few can tell."""
    gains = []
    for found in stretch_gains(ts, q, v):
        if found is None or not found[1] < MAX_GAIN_ERROR:
            continue  # too short or too still to tell
        if not _refused(found[0], found[1]):
            return None
        gains.append(found[0])
    return gains if len(gains) >= 2 else None


def check_velocities(
    ts, values: dict, pairs: dict[str, str], *, path=None, columns: dict | None = None, scale: dict | None = None
) -> None:
    """Refuse a record whose velocity column is not the derivative of its position column.

    **Arguments:**

    - `ts`: sample times; `values`: column arrays by contract name.
    - `pairs`: velocity name -> position name, the measured velocities to check (`{"dq1": "q1", ...}`).
    - `path`, `columns` (contract name -> file column): named in the error.
    - `scale`: the factors already applied (contract name -> factor), so that the `scale` the error
      suggests replaces them.

    A gain that is wrong in some stretches of the record only (`gain_holds_everywhere`) is no unit, and
    is not refused here: `dynax._data._sanity` names the stretch. A gain of 1000 (or $10^6$) with a
    median interval of 0.1 or more is time in milliseconds (microseconds), one of 1/60 with an interval
    under 1/600 time in minutes, and the error says so.

    **Raises:** `DataError` naming the file and the velocity column, its gain on the position's
    derivative with its standard error, the unit mix-up that gain matches where one does, the
    position column it does follow where that is another one, and the `scale` that makes it agree.
    """
    columns, scale = columns or {}, scale or {}
    named = lambda n: f"'{columns.get(n, n)}'" + (f" ({n})" if columns.get(n, n) != n else "")  # noqa: E731
    edges = stretch_edges(np.asarray(ts, dtype=float)) if pairs else None
    screened = SCREENS.get()
    for velocity, position in pairs.items():
        # the gain alone decides where it is within `MAX_GAIN_ERROR` of 1 (never refused, whatever its error)
        blocks = _block_slopes(ts, values[position], values[velocity], edges)
        if blocks is None or (screened and gain_surely_within(*blocks, MAX_GAIN_ERROR)):
            continue
        first = _gain_of(blocks)
        if first is None or abs(first[0] - 1.0) <= MAX_GAIN_ERROR:
            continue
        found = velocity_gain(ts, values[position], values[velocity])
        if found is None or not _refused(found[0], found[1]):
            continue
        gain, std, corr = found
        if abs(gain) < 1.0 - MAX_GAIN_ERROR:  # attenuated by the position's noise?
            corrected = corrected_gain(ts, values[position], *blocks, edges)
            if corrected is None or not _refused(corrected[0], std * corrected[1]):
                continue
        follows_another = any(
            (m := velocity_gain(ts, values[other], values[velocity])) is not None and abs(m[0] - 1.0) <= MAX_GAIN_ERROR
            for other in pairs.values()
            if other != position
        )
        if not follows_another and not gain_holds_everywhere(ts, values[position], values[velocity], gain):
            gains = wrong_in_every_stretch(ts, values[position], values[velocity])
            if gains is None:
                continue  # wrong in some stretches only: no scale is right; the sanity check names the stretch
            raise DataError(
                f"it is not the derivative of {named(position)} in any stretch of the record: over "
                f"{BLOCK_S * 1e3:g} ms blocks its mean is {gain:.4g} +- {std:.2g} times the position's change per "
                f"second (correlation {corr:.2f}), and from {min(gains):.3g} to {max(gains):.3g} times it in the "
                f"record's {STRETCHES} stretches: no one scale fixes that; is {columns.get(velocity, velocity)!r} "
                f"the velocity of {columns.get(position, position)!r}? If the record has no velocity, leave its "
                "columns out (unmapped): `load_trajectory` then estimates every velocity from the positions",
                path=path,
                column=columns.get(velocity, velocity),
            )
        dt = float(np.median(np.diff(np.asarray(ts, dtype=float))))
        for factor, unit in ((1e3, "milliseconds"), (1e6, "microseconds"), (1 / 60, "minutes")):
            if abs(gain / factor - 1.0) < 0.05 and (dt >= 0.1 if factor > 1 else dt < 0.1 * factor):
                raise DataError(
                    f"the time column reads as {unit}: the velocity {named(velocity)} is {gain:.4g} times its "
                    f"position's change per time unit and the median interval is {dt:.6g}; scale the time, not the "
                    f"velocity (`scale={{'t': {1 / factor:g}}}`, `--scale t={1 / factor:g}`)",
                    path=path,
                    column=columns.get("t", "t"),
                )
        what = [
            f"it is not the derivative of {named(position)}: over {BLOCK_S * 1e3:g} ms blocks its mean is "
            f"{gain:.4g} +- {std:.2g} times the position's change per second (correlation {corr:.2f}; 1 is "
            "the same quantity in the same units)"
        ]
        factor, matched = 1.0 / gain if gain != 0 else None, None
        for meaning, (known, velocity_factor, position_factor) in _KNOWN_FACTORS.items():
            if abs(gain / known - 1.0) < (MAX_GAIN_ERROR if known < 0 else 0.03):
                what.append(f"it reads as {meaning}" if known > 0 else f"it has {meaning}")
                matched = {velocity: velocity_factor, position: position_factor}
                matched = {c: f * float(scale.get(c, 1.0)) for c, f in matched.items() if f is not None}
        swapped = False
        for other_velocity, other in pairs.items():
            if other != position:
                match = velocity_gain(ts, values[other], values[velocity])
                if match is not None and abs(match[0] - 1.0) <= MAX_GAIN_ERROR:
                    swapped = True
                    what.append(
                        f"it is the derivative of {named(other)} (gain {match[0]:.4g}): are the columns "
                        f"of {velocity} and {other_velocity} swapped?"
                    )
        if not swapped and matched:
            what.append(
                "if so, scale "
                + ("it" if list(matched) == [velocity] else "them" if len(matched) > 1 else "the position")
                + " (`scale={"
                + ", ".join(f"'{c}': {f:.6g}" for c, f in matched.items())
                + "}`, `--scale "
                + ",".join(f"{c}={f:.6g}" for c, f in matched.items())
                + "`)"
            )
        elif not swapped and abs(gain) < MAX_GAIN_ERROR:
            what.append(
                "if the record has no velocity, leave its columns out (unmapped): `load_trajectory` then "
                "estimates every velocity from the positions"
            )
        elif not swapped and factor is not None:
            factor *= float(scale.get(velocity, 1.0))
            lead = "if that is a unit or a gear ratio, scale it"
            what.append(f"{lead} (`scale={{'{velocity}': {factor:.6g}}}`, `--scale {velocity}={factor:.6g}`)")
        raise DataError("; ".join(what), path=path, column=columns.get(velocity, velocity))


def check_trajectory_velocities(trajectory) -> None:
    """`check_velocities` on a `Trajectory`'s states: each `dX` against `X` (the manipulators' and the
    linear axis's joints; a helicopter's body-frame velocities are not derivatives of its states
    and have no such pair). Named by the record's `source` and the contract's column names."""
    names = tuple(trajectory.state_names)
    pairs = velocity_pairs(names)
    if not pairs:
        return
    xs = np.asarray(trajectory.xs, dtype=float)
    values = {n: xs[:, i] for i, n in enumerate(names)}
    check_velocities(np.asarray(trajectory.ts, dtype=float), values, pairs, path=trajectory.source or None)


LAG_WINDOW_S = 0.5  # windows whose offset and drift are taken out before the lag is read [s]
LAG_STRETCHES = 16  # the record is cut into this many stretches, each with its own lag and standard error
MIN_LAG_WINDOWS = 16  # fewer windows than this (of 4 samples or more): too short to tell


class VelocityLag(NamedTuple):
    """`velocity_lag`'s reading. `lag` [s] (positive: the velocity is late) and its `std_error` [s] over
    the whole record; `frequency` [rad/s], the motion's typical angular frequency (so that `lag * frequency` is
    the phase error the lag makes); `stretch_lags`, `stretch_errors` [s], the same in each of `LAG_STRETCHES` stretches
    (NaN where one is too still to tell), whose sample indices are `bounds[k]` to `bounds[k + 1] - 1`."""

    lag: float
    std_error: float
    frequency: float
    stretch_lags: np.ndarray
    stretch_errors: np.ndarray
    bounds: np.ndarray


def _window_residuals(ts: np.ndarray, window: np.ndarray, count: int, columns) -> list[np.ndarray]:
    """Each of `columns` less its own straight line in `ts` within each window (`window`: the window index
    of each sample, `count` windows): an integrated velocity's offset and its drift (a velocity's bias
    integrates to one) leave the regression."""
    n = np.bincount(window, minlength=count).astype(float)
    tc = ts - (np.bincount(window, ts, count) / np.maximum(n, 1.0))[window]
    tt = np.bincount(window, tc * tc, count)
    out = []
    for x in columns:
        mean = np.bincount(window, x, count) / np.maximum(n, 1.0)
        slope = np.bincount(window, tc * x, count) / np.where(tt > 0, tt, 1.0)
        out.append(x - mean[window] - slope[window] * tc)
    return out


def _lag_of(sums: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""`(lag, information)` of the regression $q \approx a V + b v$ from its sums (rows: $VV, Vv, vv, Vq, vq$;
    any trailing shape): $b / a$, and $a^2 / (S^{-1})_{bb}$, the inverse of its variance per unit noise
    variance (0 where the window is too still or $a \le 0$)."""
    svv, svd, sdd, svq, sdq = sums
    det = svv * sdd - svd * svd
    ok = (det > 1e-9 * svv * sdd) & (svv > 0)
    det = np.where(ok, det, 1.0)
    a, b = (sdd * svq - svd * sdq) / det, (svv * sdq - svd * svq) / det
    ok &= a > 0
    lag = np.where(ok, b / np.where(ok, a, 1.0), np.nan)
    return lag, np.where(ok, a * a * det / np.where(svv > 0, svv, 1.0), 0.0)


def velocity_lag(ts, q, v) -> VelocityLag | None:
    r"""How far a measured velocity column lags its position column (a `VelocityLag`), or `None` for a
    record too short or too still to tell.

    A velocity late by $d$ integrates to the position late by $d$: $V(t) = \int v = q(t - d) + c$, so
    $q(t) \approx a\,V(t) + b\,v(t)$ with $b / a = d$ (to first order in $d$; $a$ absorbs a gain). The
    regression runs in windows of `LAG_WINDOW_S` (at least `MIN_LAG_WINDOWS` of them), each less its own
    offset and drift, so a velocity's bias (which integrates to a drift) and the integration constant
    leave it. Noise in $q$ is the regression's output noise; noise in $v$ is smoothed by the integral in
    $V$ and only shrinks $b$ (towards no lag: never a false lag). A gain error does not move $d$; a
    causal first-order filter of time constant $\tau$ reads as a lag of about $\tau$, a backward
    difference as half an interval.

    Each stretch's own lag $d_k$, with an information $I_k$ (its inverse variance per unit noise
    variance), has the standard error $\sigma / \sqrt{I_k}$, $\sigma$ the rms of the differences of
    neighbouring stretches' lags, each divided by its own standard deviation, less the largest one: a
    lag that starts part way through the record moves one difference, not the scale. The record's lag
    has the larger of two standard errors: $\sigma / \sqrt{\sum I_k}$ and the jackknife over the
    stretches left out in turn (robust to the noise's colour: an integrated velocity's noise is a random
    walk, smooth within a window); either alone is, now and then, several times too small. The frequency is
    $\sqrt{\sum v_r^2 / \sum V_r^2}$ over the windows' residuals: a ratio of velocity to position,
    which the velocity's noise hardly moves (an acceleration's would)."""
    ts, q, v = (np.asarray(a, dtype=float) for a in (ts, q, v))
    duration = float(ts[-1] - ts[0]) if len(ts) > 1 else 0.0
    width = min(LAG_WINDOW_S, duration / MIN_LAG_WINDOWS)
    if len(ts) < 4 * MIN_LAG_WINDOWS or not width > 0:
        return None
    count = int(duration / width)
    window = np.minimum(((ts - ts[0]) / width).astype(int), count - 1)
    V = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(ts))])
    qr, Vr, vr = _window_residuals(ts, window, count, (q, V, v))
    pairs = ((Vr, Vr), (Vr, vr), (vr, vr), (Vr, qr), (vr, qr))
    stretch = np.minimum(window * LAG_STRETCHES // count, LAG_STRETCHES - 1)
    sums = np.stack([np.bincount(stretch, x * y, LAG_STRETCHES) for x, y in pairs])  # (5, stretches)
    total = sums.sum(axis=1)
    lag = float(_lag_of(total)[0])
    left_out = _lag_of(total[:, None] - sums)[0]
    per, info = _lag_of(sums)
    if not (np.isfinite(lag) and np.all(np.isfinite(left_out))) or np.sum(info > 0) < LAG_STRETCHES // 2:
        return None
    jackknife = float(np.sqrt((LAG_STRETCHES - 1) / LAG_STRETCHES * np.sum((left_out - left_out.mean()) ** 2)))
    used = info > 0
    d, i = per[used], info[used]
    scaled = np.sort(np.abs(np.diff(d)) / np.sqrt(1.0 / i[1:] + 1.0 / i[:-1]))
    sigma = float(np.sqrt(np.mean(scaled[:-1] ** 2)))  # the largest left out: a lag that starts part way
    std = max(jackknife, sigma / float(np.sqrt(i.sum())))  # two estimates of one error: the larger
    errors = np.where(used, sigma / np.sqrt(np.where(used, info, 1.0)), np.nan)
    first = np.searchsorted(stretch, np.arange(LAG_STRETCHES))
    bounds = np.concatenate([first, [len(ts)]])
    frequency = float(np.sqrt(total[2] / total[0]))
    return VelocityLag(lag, std, frequency, per, errors, bounds)


def lag_change_point(ts, q, v, lo: int, hi: int, lagging_after: bool = True) -> int:
    r"""The sample in `lo .. hi - 1` from which a velocity lags its position (`lagging_after`; else the first
    sample where it no longer does): a lag read in whole stretches of `velocity_lag` (0.5 s or more) starts
    somewhere inside the stretch at its edge, and this places it to a few samples.

    Over the samples `lo .. hi - 1` the position is regressed, as in `velocity_lag`, on the integrated
    velocity $V$, each `LAG_WINDOW_S` window less its own line in time, and on two columns of a candidate
    change point: $v\,H$ and $H$, $H$ the step that is 1 from the candidate on (before it, when not
    `lagging_after`), each less its windows' lines too. $b\,v H$ is the lag's term where it holds, $c\,H$
    the offset the lag leaves in $V$ from there on (a velocity late by $d$ integrates to $q(t - d) +
    d\,\dot q(t_0)$ from the $t_0$ it starts at). The candidate whose fit leaves the least residual sum of
    squares is the change point (one three-column fit per sample of the range; called only for a lag found)."""
    ts, q, v = (np.asarray(a, dtype=float)[lo:hi] for a in (ts, q, v))
    n = len(ts)
    if n < 8:
        return lo
    V = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(ts))])
    count = max(int((ts[-1] - ts[0]) / LAG_WINDOW_S), 1)
    window = np.minimum(((ts - ts[0]) / LAG_WINDOW_S).astype(int), count - 1)
    qr, Vr = _window_residuals(ts, window, count, (q, V))

    def rss(k):
        step = (np.arange(n) >= k) if lagging_after else (np.arange(n) < k)
        columns = np.column_stack([Vr, *_window_residuals(ts, window, count, (v * step, step.astype(float)))])
        coef, *_ = np.linalg.lstsq(columns, qr, rcond=None)
        return float(np.sum((qr - columns @ coef) ** 2))

    # every `stride`-th candidate, then every sample around the best: at most a few hundred fits however fast;
    # the range's far edge is one (the lag holds through the range: a stretch that read no lag only by chance)
    first, last = (0, n - 2) if lagging_after else (2, n)
    stride = max(1, n // 200)
    coarse = min([*range(first, last, stride), last], key=rss)
    fine = min(range(max(first, coarse - stride), min(last, coarse + stride) + 1), key=rss)
    return lo + fine
