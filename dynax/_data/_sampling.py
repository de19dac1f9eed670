"""Checks on a record's time stamps: strictly increasing, no gap to interpolate over, no near-duplicates.

Irregular sampling is allowed (real rigs jitter: a logged step can be a fraction of the median
interval or several times it). What is refused is a step so far from the typical interval that every method
would silently do the wrong thing across it: a gap (a zero-order-hold input held for minutes, an
interpolation drawn across a missing stretch, a central difference over it) or a near-duplicate
stamp (a derivative estimated over $10^{-12}$ s amplifies measurement noise by $10^{10}$).
"""

import numpy as np

from .._errors import DataError, UsageError
from ._trajectory import Trajectory

# A step longer than this many median intervals is a gap in the record, not jitter.
MAX_GAP = 10.0
# A step shorter than this fraction of the median interval is a duplicated or corrupted stamp.
MIN_STEP = 0.01


def time_label(t: float, resolution: float, digits: int = 6) -> str:
    """`t` [s] written short (`digits` significant digits) where that is within `resolution` of it, else in
    fixed point to `resolution`: a Unix time stamp (1.77e9 s) keeps its milliseconds, so a message or an
    `--exclude` span names the sample meant and not a time thousands of seconds away."""
    short = f"{t:.{digits}g}"
    if abs(float(short) - t) <= resolution:
        return short
    return f"{t:.{max(0, int(np.ceil(-np.log10(resolution))))}f}"


def check_time_stamps(
    ts, *, path=None, column="t", max_gap: float | None = MAX_GAP, min_step: float | None = MIN_STEP
) -> None:
    """Refuse time stamps that do not strictly increase, jump across a gap or nearly repeat.

    **Arguments:**

    - `ts`: the time column (float64 on the host).
    - `path`, `column`: named in the error.
    - `max_gap`: largest step allowed, in median intervals (default 10); `None` allows any gap.
    - `min_step`: smallest step allowed, as a fraction of the median interval (default 0.01);
      `None` allows any positive step.

    **Raises:** `DataError` naming the file, the column and the (1-based data) row where the bad
    step ends, with both time stamps.
    """
    ts = np.asarray(ts, dtype=np.float64)
    steps = np.diff(ts)
    bad = np.flatnonzero(~(steps > 0))
    if bad.size:
        k = int(bad[0]) + 1
        raise DataError(
            f"time does not strictly increase ({float(ts[k - 1])!r} then {float(ts[k])!r})",
            path=path,
            column=column,
            row=k + 1,
        )
    if steps.size < 2:
        return
    median = float(np.median(steps))
    if max_gap is not None:
        gap = np.flatnonzero(steps > max_gap * median)
        if gap.size:
            k = int(gap[0]) + 1
            raise DataError(
                f"a gap in the record: time jumps from {float(ts[k - 1])!r} to {float(ts[k])!r} s, "
                f"{steps[k - 1] / median:.3g} times the "
                f"median interval {median:.6g} s (more than {max_gap:g} is refused: it would be interpolated or held "
                f"across); {gap.size} such gap(s). Split the record there into separate files",
                path=path,
                column=column,
                row=k + 1,
            )
    if min_step is not None:
        tiny = np.flatnonzero(steps < min_step * median)
        if tiny.size:
            k = int(tiny[0]) + 1
            raise DataError(
                f"near-duplicate time stamps {float(ts[k - 1])!r} and {float(ts[k])!r}: a step of {steps[k - 1]:.3g} s "
                f"is {steps[k - 1] / median:.2g} times the median interval {median:.6g} s (less than {min_step:g} is "
                "refused: derivatives across it are noise)",
                path=path,
                column=column,
                row=k + 1,
            )


def steady_ticks(ts) -> tuple[np.ndarray, np.ndarray] | None:
    """The ticks of a steady clock that the stamps `ts` jitter about: `(ticks, k)`, each sample's tick time
    `start + k * interval` and its tick count `k`, with `start` and `interval` fitted by least squares to the
    stamps and each stamp taken to its nearest tick. A sample dropped leaves a tick out (a step of two
    intervals), where an even grid between the first and last stamps would shift every later sample. `None`
    where two samples fall on one tick or the record is too short to fit (stamps jittered by half an interval or
    more: a steady clock cannot be read from them). Host numpy, float64, relative to the first stamp."""
    ts = np.asarray(ts, dtype=float)
    if len(ts) < 3:
        return None
    times = ts - ts[0]
    interval = float(np.median(np.diff(times)))
    if not interval > 0:
        return None
    # counts from sample to sample (a step of about one interval is one tick, of about two a dropped sample), then
    # the clock's start and interval fitted to them, then every stamp to its nearest tick of that clock, twice
    k = np.concatenate([[0.0], np.cumsum(np.maximum(np.round(np.diff(times) / interval), 1.0))])
    for _ in range(2):
        interval, start = (float(c) for c in np.polyfit(k, times, 1))
        if not interval > 0:
            return None
        k = np.round((times - start) / interval)
    if np.any(np.diff(k) < 1):
        return None
    return ts[0] + start + k * interval, k.astype(np.int64)


def split_at_gaps(trajectory: Trajectory, max_gap: float = MAX_GAP) -> list[Trajectory]:
    """Split a record into runs at every step longer than `max_gap` median intervals.

    For records with pauses in them: load with `load_trajectory(..., sampling=Sampling(max_gap=None))`, then fit or
    diagnose each run (or only the long ones) instead of bridging the pause.

    **Arguments:** `trajectory`; `max_gap` in median intervals (default 10).

    **Returns:** the runs, in order, as `Trajectory`s (a run may hold a single sample).
    """
    if not max_gap > 1:
        raise UsageError(f"split_at_gaps: `max_gap` must be more than 1 median interval, got {max_gap}")
    steps = np.diff(np.asarray(trajectory.ts, dtype=np.float64))
    if steps.size == 0:
        return [trajectory]
    cuts = (np.flatnonzero(steps > max_gap * np.median(steps)) + 1).tolist()
    bounds = [0, *cuts, len(trajectory)]
    return [trajectory.slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]
