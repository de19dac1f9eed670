r"""Data sanity, located: what in a record would make any fit wrong, and where it is.

A fit of a record with a corrupt stretch in it returns numbers, and nothing downstream says that they
are wrong. So before any fit each record is read for the faults real logs carry, and each fault is
reported with its column and its rows and times (`Finding`), with a fix only where the fix is right
for the whole record (a unit that holds in every stretch); otherwise the stretch is named so that it
can be cut (`exclude_stretches`, the command line's `--exclude t0:t1`).

What is checked (`Check` names them):

- `time_units`: a median sampling interval of half a second or more: no rig these models describe is
  sampled that slowly, and an interval of 10 "seconds" is a 100 Hz record stamped in milliseconds.
- `glitch`: samples (one to three in a row) that leave their neighbours by more than one and a half
  times the column's (1-99 %) range and 20 times its typical sample-to-sample step: a corrupt reading
  (a gyro sample of 460 rad/s among samples of 1). A median of seven samples follows steps and turning
  points, so motion, however sharp, is not flagged; a velocity's spike that its position shares (a
  difference over a short, jittered interval) is not one, and a resampled jittered record's blurred
  spikes (up to 1.2 times the range on the DFKI runs) stay under the bound.
- `stuck`: a state column that repeats one value exactly for a quarter of a second or more (and 25
  samples, and three times its longest other run: a quantised column repeats itself everywhere)
  while other states move and the column itself moves elsewhere: a sensor that stopped
  updating (a joint held by friction while the others swing looks the same when its velocity is
  estimated from its angle; the message says so).
- `wrapped`: an angle that jumps by a multiple of $2\pi$ (to 15 %) between two samples, many times its
  typical step: an angle folded into $(-\pi, \pi]$; every derivative across the jump is wrong.
- `jump`: a position that leaps from one sample to the next, not as a wrap and not out and back: 20
  times the largest step within three samples either side, 10 of its smallest steps, 5 % of its range, and
  more than its measured velocity moves it: a break in the record (a logger that dropped, replayed or
  spliced rows; an encoder re-zeroed), across which every derivative is wrong. Motion cannot do it: a
  rigid body's position steps change smoothly, so a real step has neighbours of its own size.
- `velocity`: a stretch where a measured velocity stops being the derivative of its position (block
  means against secant slopes over 50 ms blocks, as `dynax._data._velocities`, but block by block):
  a spinning link past the encoder's range, a sign that flips half way. A gain that is wrong in every
  stretch is a unit, refused by `load_trajectory` with the `scale` that fixes it.
- `lag`: a measured velocity that lags (or leads) its position throughout or in a run of stretches (a
  driver's causal filter or backward difference): its error follows the acceleration, and a fit trades
  damping for inertia (`lag_findings`).
- `stamps`: time stamps that jitter about evenly spaced samples (the positions follow a steady clock's ticks
  far more closely than their stamps: a logger that stamps on receipt; `jitter_findings`, fixed by putting
  each sample on its tick), or that disagree with the positions read at them (`sample_times_from_positions`): a
  logger that stalls between reading its sensors and its clock stamps them late, and every difference
  over such an interval (a logged backward difference, central differences on the stamps) reads the
  velocity wrong there, by several rad/s in a fast spin (`stamp_findings`).
- `constant`, `zero`: a column that never changes (a dead sensor, a joint that never moves) or an
  input that is zero or constant throughout (nothing excites the dynamics, or a constant force that
  cannot be told from the offset a fit estimates): the parameters' scale is then not determined.
- `duplicate`: the same record given twice, or as its own validation (held-out error in-sample); a
  stretch of one record that is rows of another, one for one (an excerpt given beside the record it was
  cut from, logs that overlap, a copy saved with fewer digits: `dynax._data._overlap`), located in both
  and cut from the training record; two columns of one record equal in every sample (one file column
  mapped to two coordinates or inputs).

Inputs the system ignores (a non-zero `tau1` in a file read as `acrobot`) are refused by
`load_trajectory`, which alone sees the file's other columns.

Each finding is `refuse` (the command line exits with status 2 and names it) or `warn` (a
`DataWarning` in Python, a line on the command line). The thresholds are physical or statistical
scales of the record itself, never of one rig.
"""

from collections.abc import Sequence
import dataclasses
import enum
import math
import pathlib
import warnings

import numpy as np

from .._errors import DataError, UsageError
from ._overlap import shared_either_way
from ._sampling import time_label
from ._screens import SCREENS
from ._trajectory import Trajectory
from ._velocities import BLOCK_S, velocity_pairs


class Check(enum.StrEnum):
    """The kinds of fault `check_records` reports (see the module notes)."""

    TIME_UNITS = "time_units"
    GLITCH = "glitch"
    STUCK = "stuck"
    WRAPPED = "wrapped"
    VELOCITY = "velocity"
    CONSTANT = "constant"
    ZERO = "zero"
    DUPLICATE = "duplicate"
    LAG = "lag"
    STAMPS = "stamps"
    JUMP = "jump"


class Severity(enum.StrEnum):
    """`refuse`: no fit is run on the record as it is; `warn`: the fit runs and the finding is said."""

    REFUSE = "refuse"
    WARN = "warn"


class DataWarning(UserWarning):
    """A located finding of `check_records` in a record that was read (Python); the command line refuses
    or prints the same findings."""


@dataclasses.dataclass(frozen=True)
class Finding:
    """One fault in one record.

    **Fields:** `kind` (a `Check`), `severity` (a `Severity`), `source` (the record's file or
    name), `column` (contract name, or `None` for the whole record), `rows` (first and last
    1-based data row, or `None`), `times` (first and last time [s], or `None`), `message`, and
    `fix` (what to do: an `--exclude` / `exclude_stretches` span, a `--scale` right for the whole
    record, or `None`).
    """

    kind: Check
    severity: Severity
    source: str
    column: str | None
    rows: tuple[int, int] | None
    times: tuple[float, float] | None
    message: str
    fix: str | None = None

    def describe(self) -> str:
        where = [f"file {self.source}" if self.source else "record"]
        if self.column is not None:
            where.append(f"column '{self.column}'")
        if self.rows is not None:
            a, b = self.rows
            where.append(f"row {a}" if a == b else f"rows {a}-{b}")
        if self.times is not None:
            a, b = self.times
            a, b = time_label(a, 1e-4), time_label(b, 1e-4)
            where.append(f"t = {a} s" if a == b else f"t = {a} to {b} s")
        return ", ".join(where) + f": {self.message}" + (f"; fix: {self.fix}" if self.fix else "")

    def to_json(self) -> dict:
        return {
            "kind": str(self.kind),
            "severity": str(self.severity),
            "source": self.source,
            "column": self.column,
            "rows": None if self.rows is None else list(self.rows),
            "times": None if self.times is None else list(self.times),
            "message": self.message,
            "fix": self.fix,
        }


@dataclasses.dataclass(frozen=True)
class DataCheck:
    """The findings of `check_records`, in record order. `refusals` and `warnings` split them by severity."""

    findings: tuple[Finding, ...] = ()

    @property
    def refusals(self) -> tuple[Finding, ...]:
        return tuple(f for f in self.findings if f.severity == Severity.REFUSE)

    @property
    def warnings(self) -> tuple[Finding, ...]:
        return tuple(f for f in self.findings if f.severity == Severity.WARN)

    def __bool__(self) -> bool:
        return bool(self.findings)

    def raise_refusals(self) -> None:
        """Raise a `DataError` naming every refused finding (the first one's file and column as its own)."""
        if self.refusals:
            first = self.refusals[0]
            text = "; ".join(f.describe() for f in self.refusals[:6])
            more = f" (and {len(self.refusals) - 6} more)" if len(self.refusals) > 6 else ""
            error = DataError("the data cannot be fitted as they are: " + text + more)
            error.path, error.column = first.source or None, first.column
            error.row = None if first.rows is None else first.rows[0]
            raise error

    def warn(self, stacklevel: int = 2) -> None:
        """One `DataWarning` per finding (refusals included: in Python the caller decides)."""
        for f in self.findings:
            warnings.warn(f.describe(), DataWarning, stacklevel=stacklevel + 1)

    def to_json(self) -> list[dict]:
        return [f.to_json() for f in self.findings]


# --- thresholds (scales of the record itself) ------------------------------------------------------

MAX_INTERVAL_S = 0.5  # a median sampling interval at least this long is not a record of these dynamics
GLITCH_RANGE = 1.5  # a glitch leaves its neighbours by this multiple of the column's (1-99 %) range ...
GLITCH_STEPS = 20.0  # ... and this many typical sample-to-sample steps
GLITCH_WINDOW = 7  # samples of the running median a glitch is measured from (runs of up to 3 samples)
STUCK_S, STUCK_SAMPLES = 0.25, 25  # an exactly repeated value this long (both) is a stuck sensor
WRAP_TOLERANCE = 0.15  # a jump within this fraction of 2 pi k (k >= 1) is a wrap
JUMP_STEPS = 20.0  # a break's step is this many times its neighbours' largest ...
JUMP_NEIGHBOURS = 3  # ... the neighbours: this many steps either side (a glitch of up to 3 samples returns within them)
JUMP_RANGE = 0.05  # ... and this fraction of the position's (1-99 %) range
VELOCITY_ERROR = 0.25  # a block whose mean velocity misses the secant slope by this fraction ...
VELOCITY_NOISE = 5.0  # ... and this many robust noise standard deviations ...
VELOCITY_MOTION = 0.05  # ... and this fraction of the record's rms slope is a bad block
MIN_BAD_BLOCKS = 3  # a stretch holds at least this many bad blocks (150 ms), at least half of its blocks
LAG_SIGNIFICANCE = 8.0  # a velocity's lag is read as one when it is this many standard errors from zero ...
LAG_STRETCH_SIGNIFICANCE = 3.0  # ... and the stretches it holds in, this many of their own
LAG_RUN_SIGNIFICANCE = 8.0  # or two neighbouring stretches or more, each this many of their own
LAG_PHASE_WARN = 0.004  # ... and its phase error at the motion's frequency (lag times frequency) is this [rad]
LAG_PHASE_REFUSE = 0.02  # ... a refusal from this phase error [rad] (see `lag_findings`)


def _row_time(ts, span, source, kind, severity, column, message, fix=None):
    """A `Finding` over the samples `span = (i, j)`: rows counted from 1, and their times."""
    i, j = span
    return Finding(kind, severity, source, column, (int(i) + 1, int(j) + 1), (float(ts[i]), float(ts[j])), message, fix)


def _span(ts, i, j) -> str:
    """An `--exclude` span around samples i..j: from the sample before to the sample after, open at the ends."""
    n = len(ts)
    resolution = float(np.median(np.diff(ts))) / 10 if n > 1 else 1e-4
    a = "" if i == 0 else time_label(float(ts[i - 1]), resolution)
    b = "" if j >= n - 1 else time_label(float(ts[j + 1]), resolution)
    return f"--exclude {a}:{b}"


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of True."""
    if not mask.any():
        return []
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return [(int(a), int(b)) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1)]


def _time_units(tr, ts, source, dt):
    if dt < MAX_INTERVAL_S:
        return []
    fix = None
    for factor, unit in ((1e-3, "milliseconds"), (1e-6, "microseconds")):
        if 1e-5 <= dt * factor < MAX_INTERVAL_S:
            fix = f"--scale t={factor:g} (time in {unit}; in Python `scale={{'t': {factor:g}}}`)"
            break
    message = (
        f"the median sampling interval is {dt:.6g} s: no record of these dynamics is sampled that slowly "
        "(a derivative over it is meaningless)"
        + (f"; the time column reads as {unit}" if fix else "; check the time column's unit")
    )
    return [Finding(Check.TIME_UNITS, Severity.REFUSE, source, "t", None, None, message, fix)]


def _robust_range(x):
    lo, hi = np.percentile(x, [1, 99])
    return float(hi - lo)


def _position_supports(ts, q, v, k, jump) -> bool:
    """Whether the position `q` moved as the velocity sample `v[k]` says: a logged difference over a short
    (jittered) interval spikes with its position, which a corrupt reading does not. The one-step
    differences of the position within two samples either side are compared."""
    lo, hi = max(k - 2, 0), min(k + 2, len(ts) - 1)
    steps = np.diff(q[lo : hi + 1]) / np.diff(ts[lo : hi + 1])
    return bool(steps.size) and bool(np.any(np.abs(v[k] - steps) < 0.5 * jump))


def median_reach(x: np.ndarray, window: int, steps: np.ndarray | None = None) -> float:
    """The most any sample of `x` can lie from `glitch_findings`' running median of `window` (odd) samples: the
    median of a full window is one of its samples, so a sample in the middle of it lies from it by at most
    its largest difference to a sample `window // 2` or fewer steps away; the first and last `window // 2`
    samples are measured from the median of the first and last full window, so by at most that window's
    range. Exact in floating point (each difference is the one rounded subtraction the median's residual
    makes, or a range at least as wide); NaN where `x` holds a NaN. `steps`: `np.abs(np.diff(x))` where
    already known."""
    h = window // 2
    if len(x) < window:
        return float(np.ptp(x)) if len(x) else 0.0
    steps = np.abs(np.diff(x)) if steps is None else steps
    reaches = [np.max(steps), np.ptp(x[:window]), np.ptp(x[-window:])]
    reaches += [np.max(np.abs(x[d:] - x[:-d])) for d in range(2, h + 1)]
    return float(np.max(reaches))  # numpy's maximum carries a NaN through (Python's `max` may drop it)


def typical_step_covers(steps: np.ndarray, reach: float) -> bool:
    """Whether `reach <= GLITCH_STEPS * typical` with `glitch_findings`' typical step (1.4826 times `np.median(steps)`)
    holds, decided without the median where a count can: numpy's median is the middle sorted value or the
    mean of the two middle ones, so it is at least `low` where at most `(len - 1) // 2` steps are below `low`,
    and the typical step's floating-point formula is monotone in the median. `False` where it cannot tell."""
    if not (np.isfinite(reach) and steps.size):
        return False
    low = reach / (GLITCH_STEPS * 1.4826) * (1.0 + 1e-9)
    if not GLITCH_STEPS * (low * 1.4826 + 1e-300) >= reach:
        return False
    return int(np.count_nonzero(steps < low)) <= (steps.size - 1) // 2


def glitch_findings(tr, ts, source, columns, positions=None):
    import scipy.signal

    positions = positions or {}

    out = []
    n = len(ts)
    if n < 2 * GLITCH_WINDOW:
        return out
    screened = SCREENS.get()
    for name, x, is_input in columns:
        steps = np.abs(np.diff(x))
        # the threshold is at least GLITCH_STEPS typical steps: a column whose samples stay that close to
        # their neighbours within the running median's reach has no glitch, whatever its range; a count
        # says whether the median step is large enough for that before the median itself is taken
        # (screens off: no reach is known, and every column is searched)
        reach = median_reach(x, GLITCH_WINDOW, steps) if screened else math.inf
        if typical_step_covers(steps, reach):
            continue
        typical = float(np.median(steps)) * 1.4826 + 1e-300
        if reach <= GLITCH_STEPS * typical:
            continue
        spread = _robust_range(x)
        threshold = max(GLITCH_RANGE * spread, GLITCH_STEPS * typical)
        if is_input:  # inputs may legitimately step and pulse: only readings far beyond their range
            threshold = max(threshold, 3.0 * spread)
        if not threshold > 0:
            continue
        # no sample leaves the running median below by more than `reach` (at most the column's range)
        if reach <= threshold:
            continue
        median = scipy.signal.medfilt(x, GLITCH_WINDOW)
        # at the ends the filter pads with zeros: measure from the nearest full window instead
        h = GLITCH_WINDOW // 2
        median[:h], median[-h:] = median[h], median[-h - 1]
        residual = np.abs(x - median)
        for i, j in _runs(residual > threshold):
            if j - i >= GLITCH_WINDOW // 2:
                continue  # a plateau of four samples or more is not a glitch (stuck or a stretch: other checks)
            k = i + int(np.argmax(residual[i : j + 1]))
            value, near = float(x[k]), float(median[k])
            if name in positions and all(
                _position_supports(ts, positions[name], x, m, residual[m]) for m in range(i, j + 1)
            ):
                continue  # the position moved so too: a difference over a short interval, not a corrupt reading
            out.append(
                _row_time(
                    ts,
                    (i, j),
                    source,
                    Check.GLITCH,
                    Severity.REFUSE,
                    name,
                    f"{'a sample' if i == j else f'{j - i + 1} samples'} of {value:.6g} where the neighbouring samples "
                    f"are about {near:.4g} (a jump of {abs(value - near) / max(spread, 1e-300):.3g} times the column's "
                    "range in one sample): a corrupt reading",
                    _span(ts, i, j),
                )
            )
    return out


def held_still(ts, x, v) -> bool:
    """Whether a position `x` that repeats one value over a stretch was held there, by its measured velocity `v`
    over the same samples: the velocity's running integral never leaves the position's resolution (its smallest
    step in the record, an encoder's count) or the reach of the velocity's own noise (four times its robust
    standard deviation, read from its differences, integrated over the stretch: a random walk's). A sensor
    stuck while its joint moves reads a velocity that carries the joint away; a joint held by friction reads
    noise about zero."""
    steps = np.abs(np.diff(x))
    quantum = float(steps[steps > 0].min()) if np.any(steps > 0) else 0.0
    span = np.diff(ts)
    reach = np.abs(np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * span)]))
    dv = np.diff(v)  # the noise from sample to sample (a motion's spread is not noise)
    noise = 1.4826 * float(np.median(np.abs(dv - np.median(dv)))) / np.sqrt(2.0) if dv.size else 0.0
    return bool(float(reach.max()) <= max(2.0 * quantum, 4.0 * noise * float(np.sqrt(np.sum(span**2)))))


def stuck_findings(tr, ts, source, names, xs, paired_estimated, dt):
    out = []
    need = max(STUCK_SAMPLES, math.ceil(STUCK_S / dt))
    for c, name in enumerate(names):
        x = xs[:, c]
        if np.ptp(x) == 0:
            continue  # constant throughout: `_constant`
        same = np.concatenate([[False], np.diff(x) == 0])
        runs = [(i - 1, j) for i, j in _runs(same)]  # a run starts at the sample its first repeat repeats
        lengths = [j - i + 1 for i, j in runs]
        for k, (i, j) in enumerate(runs):
            # a quantised column (an encoder, rounded values) repeats itself everywhere: a stuck stretch is one
            # far longer than any other run of the column
            elsewhere = max(lengths[:k] + lengths[k + 1 :], default=1)
            if j - i + 1 < max(need, 3 * elsewhere):
                continue
            others = [o for o in range(xs.shape[1]) if o != c and np.ptp(xs[i : j + 1, o]) > 0]
            if not others:
                continue  # everything at rest: a record that holds still, not a stuck sensor
            own = f"d{name}"
            if (
                own in names
                and name not in paired_estimated
                and held_still(ts[i : j + 1], x, xs[i : j + 1, names.index(own)])
            ):
                continue  # its own measured velocity says the joint stood still there (friction holding it)
            reason = (
                " (or a joint held still by friction while the others move: its velocity is estimated from "
                "it, so the two cannot be told apart; cut the stretch either way, a fit across it would "
                "read a stuck sensor as physics)"
                if name in paired_estimated
                else ""
            )
            out.append(
                _row_time(
                    ts,
                    (i, j),
                    source,
                    Check.STUCK,
                    Severity.REFUSE,
                    name,
                    f"repeats the value {float(x[i]):.6g} exactly for {j - i + 1} samples "
                    f"({float(ts[j] - ts[i]):.3g} s) while {', '.join(names[o] for o in others[:3])} change: "
                    f"a sensor that stopped updating{reason}",
                    _span(ts, i, j),
                )
            )
    return out


def _under_half_turn(steps: np.ndarray) -> bool:
    """Whether every step is well under half a turn (`False` for a NaN): then none rounds to a whole turn, and
    `_wrapped` finds no wrap (a wrap is a step within `WRAP_TOLERANCE` of one or more whole turns)."""
    return bool(float(np.max(np.abs(steps), initial=0.0)) < 0.9 * np.pi)


def _wrapped(tr, ts, source, angles):
    out = []
    screened = SCREENS.get()
    for name, x in angles:
        steps = np.diff(x)
        if screened and _under_half_turn(steps):
            continue
        typical = float(np.median(np.abs(steps))) + 1e-300
        turns = np.round(steps / (2 * np.pi))
        wraps = np.flatnonzero(_wraps(steps) & (np.abs(steps) > 20.0 * typical))
        if wraps.size:
            k = int(wraps[0])
            out.append(
                _row_time(
                    ts,
                    (k, k + 1),
                    source,
                    Check.WRAPPED,
                    Severity.REFUSE,
                    name,
                    f"jumps by {float(steps[k]):+.4g} rad ({int(turns[k]):+d} turn) from one sample to the next, "
                    f"{wraps.size} such jump(s) in the record: an angle folded into one turn, across which every "
                    "derivative is wrong",
                    "unwrap the angle before reading it (numpy.unwrap on the column): it is the same angle, counted on",
                )
            )
    return out


def _wraps(steps: np.ndarray) -> np.ndarray:
    """Where a step is a whole number of turns (to `WRAP_TOLERANCE`): `_wrapped`'s test without its size."""
    turns = np.round(steps / (2 * np.pi))
    return (turns != 0) & (np.abs(steps - 2 * np.pi * turns) < WRAP_TOLERANCE * 2 * np.pi)


def jump_findings(tr, ts, source, values, pairs, measured, dt):
    """Breaks in each position (see the module notes): one finding per sample a position leaps at, naming
    every position that leaps there."""
    from numpy.lib.stride_tricks import sliding_window_view

    if len(ts) < 2 * JUMP_NEIGHBOURS + 2:
        return []
    dts = np.diff(ts)
    velocity_of = {q: v for v, q in measured.items()}
    angles = tr.system in ("acrobot", "double_pendulum")
    at: dict[int, list[tuple[str, float, float, float | None]]] = {}
    for q in dict.fromkeys(pairs.values()):
        x = values[q]
        steps = np.diff(x)
        size = np.abs(steps)
        floor = JUMP_RANGE * _robust_range(x)
        if not floor > 0 or not np.any(size > floor):
            continue  # no step reaches 5 % of the range: nothing to read further
        h = JUMP_NEIGHBOURS
        around = sliding_window_view(np.pad(size, h), 2 * h + 1).copy()
        around[:, h] = 0.0
        near = around.max(axis=1)
        quantum = float(np.min(size[size > 0]))  # an encoder's count: a flicker of one count is no break
        leap = (size > floor) & (size > JUMP_STEPS * near) & (size > 10.0 * quantum) & (dts < 1.5 * dt)
        if angles:
            leap &= ~_wraps(steps)  # `wrapped` names those
        v = velocity_of.get(q)
        moved = None
        if v is not None:
            moved = 0.5 * (values[v][1:] + values[v][:-1]) * dts
            leap &= ~(np.abs(steps - moved) < 0.5 * size)  # its velocity moves it so: motion, however fast
        for k in np.flatnonzero(leap):
            at.setdefault(int(k), []).append(
                (q, float(steps[k]), float(steps[k] / near[k]), None if moved is None else float(moved[k]))
            )
    out = []
    for k, leaps in sorted(at.items()):
        q, step, ratio, moved = leaps[0]
        said = f" while {velocity_of[q]} moves it by {moved:+.3g}" if moved is not None else ""
        others = "".join(f"; {o} leaps there too, by {s:+.4g}" for o, s, _, _ in leaps[1:])
        out.append(
            _row_time(
                ts,
                (k, k + 1),
                source,
                Check.JUMP,
                Severity.REFUSE,
                q,
                f"leaps by {step:+.4g} from one sample to the next, {abs(ratio):.3g} times its largest step within "
                f"{JUMP_NEIGHBOURS} samples either side{said}{others}: a break in the record (a logger that dropped, "
                "replayed or spliced rows; an encoder re-zeroed), across which every derivative is wrong; cut there, "
                "and the pieces either side are fitted as separate records",
                _span(ts, k, k + 1),
            )
        )
    return out


def velocity_stretch_findings(tr, ts, source, values, pairs, dt):
    """Stretches of bad 50 ms blocks (see the module notes) for each measured velocity."""
    from ._velocities import stretch_edges

    out = []
    edges = stretch_edges(ts, dt)
    if len(edges) < 2 * MIN_BAD_BLOCKS + 1:
        return out
    start, stop = edges[:-1], edges[1:]
    for velocity, position in pairs.items():
        q, v = values[position], values[velocity]
        slopes = (q[stop] - q[start]) / (ts[stop] - ts[start])
        area = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(ts))])
        means = (area[stop] - area[start]) / (ts[stop] - ts[start])
        residual = means - slopes
        motion = float(np.sqrt(np.mean(slopes**2)))
        if not motion > 0:
            continue
        off = (np.abs(residual) > VELOCITY_ERROR * np.maximum(np.abs(slopes), np.abs(means))) & (
            np.abs(residual) > VELOCITY_MOTION * motion
        )
        if not off.any():
            continue  # no block is bad whatever the noise: its two medians are not needed
        noise = 1.4826 * float(np.median(np.abs(residual - np.median(residual))))
        bad = off & (np.abs(residual) > VELOCITY_NOISE * noise)
        if bad.mean() > 0.8:
            continue  # wrong nearly everywhere: a unit or a column, `load_trajectory`'s global check names it
        # join bad blocks less than three blocks apart into stretches
        idx = np.flatnonzero(bad)
        close = np.diff(idx) <= 3
        fill = np.zeros(len(bad) + 1, int)  # +1 from each of a pair of close bad blocks to after the second
        np.add.at(fill, idx[:-1][close], 1)
        np.add.at(fill, idx[1:][close] + 1, -1)
        joined = bad | (np.cumsum(fill[:-1]) > 0)
        gain_elsewhere = None  # said only where a stretch is named
        for a, b in _runs(joined):
            if bad[a : b + 1].sum() < MIN_BAD_BLOCKS or bad[a : b + 1].mean() < 0.5:
                continue
            if gain_elsewhere is None:
                sg = slopes[~joined]
                gain_elsewhere = float(sg @ means[~joined] / (sg @ sg)) if sg.size and sg @ sg > 0 else float("nan")
            # a stretch that reaches the first or last block reaches the record's end (the blocks stop short of it)
            i = 0 if a == 0 else int(start[a])
            j = len(ts) - 1 if b == len(start) - 1 else int(stop[b])
            s, m = slopes[a : b + 1], means[a : b + 1]
            gain = float(s @ m / (s @ s)) if s @ s > 0 else float("nan")
            out.append(
                _row_time(
                    ts,
                    (i, j),
                    source,
                    Check.VELOCITY,
                    Severity.REFUSE,
                    velocity,
                    f"is not the derivative of {position} in this stretch ({b - a + 1} blocks of {BLOCK_S * 1e3:g} ms; "
                    f"its mean is {gain:.3g} times the position's change per second there, {gain_elsewhere:.3g} in the "
                    "rest of the record): a fault of the stretch, not a unit, so no scale fixes it",
                    _span(ts, i, j),
                )
            )
    return out


def lag_findings(tr, ts, source, values, pairs, dt):
    r"""A measured velocity that lags (or leads) its position (`velocity_lag`): a driver's causal filter, a
    backward difference, a velocity stamped later than its angle. The lag's error in the velocity is
    about $-d\,\ddot q$, so a fit that reads damping from velocities against inertia from accelerations
    trades one for the other: the damping it reads is short by about $M d \omega^2$, a fraction
    $|d|\,\omega \cdot M\omega / b$ of it, which no data check can know ($M\omega/b$ is the system's).
    On the acrobot at 100 Hz one sample (10 ms, a phase error of 0.05 rad) takes 55-60 % off both
    dampings, a backward difference (5 ms, 0.024 rad) 27-30 %, with standard errors that exclude the
    truth (`experiments/velocity_lag.py`). So the check reads the phase error $|d|\,\omega$ at the
    motion's frequency: a lag `LAG_SIGNIFICANCE` standard errors from zero (or, in a run of stretches
    only, `LAG_RUN_SIGNIFICANCE` of their own in each) is a warning from `LAG_PHASE_WARN` (the DFKI rig's
    logged backward differences, half of its 2 ms interval, read 0.005 to 0.010 rad and move its fitted
    parameters by less than their standard errors) and a refusal from `LAG_PHASE_REFUSE`. The fix is
    to let dynax estimate the velocities from the angles by central differences, which do not lag (on the
    times the angles imply where a stamp disagrees with them: `sample_times_from_positions`); on 12 to 16-bit counts
    at 100 Hz to 1 kHz it is right or even, since a central and a backward difference of the same counts carry the
    same noise in the band `identify` keeps (`experiments/velocity_advice.py`). A lag
    read in some stretches only has its start and end placed inside the stretches to a few samples
    (`lag_change_point`; on 116 arm records lagged from 2 to 5 s at 100 and 500 Hz, 115 within 0.05 s and none
    placed more than 0.05 s late, `experiments/velocity_lag.py --edges`)."""
    from ._velocities import lag_change_point, velocity_lag

    out = []
    for velocity, position in pairs.items():
        read = velocity_lag(ts, values[position], values[velocity])
        if read is None:
            continue
        z = np.nan_to_num(read.stretch_lags / read.stretch_errors)
        free = np.zeros(len(z), bool)
        if abs(read.lag) > LAG_SIGNIFICANCE * read.std_error:
            sign = np.sign(read.lag)
            # it spans the record but for stretches that read no lag and differ from the record's (its start
            # or end before a filter was switched on or off); a stretch too still to tell is not one
            off = np.nan_to_num(np.abs(read.stretch_lags - read.lag) / read.stretch_errors)
            free = (np.abs(z) < LAG_STRETCH_SIGNIFICANCE) & (off >= LAG_STRETCH_SIGNIFICANCE)
            spread = True
        else:  # a lag in a run of stretches only (a filter switched on part way): each one far from zero
            strong = np.abs(z) >= LAG_RUN_SIGNIFICANCE
            runs = [(a, b) for a, b in _runs(strong) if b > a and len(set(np.sign(z[a : b + 1]))) == 1]
            if not runs:
                continue
            sign, spread = np.sign(z[runs[0][0]]), False
        # the stretches it is read in: a lag of the same sign, LAG_STRETCH_SIGNIFICANCE errors from zero there
        held = np.flatnonzero(z * sign >= LAG_STRETCH_SIGNIFICANCE)
        if not held.size:
            continue
        # read over the whole record: the stretches around those it is read in, up to one that reads no lag (a
        # stretch too still to tell beyond such a one is not joined to it)
        a, b = int(held[0]), int(held[-1])
        while spread and a > 0 and not free[a - 1]:
            a -= 1
        while spread and b < len(z) - 1 and not free[b + 1]:
            b += 1
        span = np.arange(a, b + 1) if spread else held
        weight = 1.0 / read.stretch_errors[held] ** 2
        lag = float(np.sum(weight * read.stretch_lags[held]) / np.sum(weight))
        phase = abs(lag) * read.frequency
        if phase < LAG_PHASE_WARN:
            continue
        i, j = int(read.bounds[span[0]]), int(read.bounds[span[-1] + 1]) - 1
        # a lag that starts or ends part way: placed to a few samples between two stretches before the span
        # (a stretch the change falls in reads a lag of neither sign) and the first stretch it is read in (the
        # span may begin at one too still to tell), and likewise at its end
        q, v = values[position], values[velocity]
        if span[0] > 0:
            lo, hi = int(read.bounds[max(span[0] - 2, 0)]), int(read.bounds[max(held[0], span[0]) + 1])
            i = lag_change_point(ts, q, v, lo, hi)
        if span[-1] < len(z) - 1:
            lo, hi = int(read.bounds[min(held[-1], span[-1])]), int(read.bounds[min(span[-1] + 3, len(z))])
            j = lag_change_point(ts, q, v, lo, hi, lagging_after=False) - 1
        if i > j:  # placed past each other (a lag of a stretch or two, and still): the stretches' edges
            i, j = int(read.bounds[span[0]]), int(read.bounds[span[-1] + 1]) - 1
        intervals = f"{abs(lag) / dt:.2g}"
        where = "read in every stretch" if held.size == len(z) else f"read in {held.size} of {len(z)} stretches"
        out.append(
            _row_time(
                ts,
                (i, j),
                source,
                Check.LAG,
                Severity.REFUSE if phase >= LAG_PHASE_REFUSE else Severity.WARN,
                velocity,
                f"{'lags' if lag > 0 else 'leads'} {position} by {abs(lag) * 1e3:.3g} ms ({intervals} sampling "
                f"interval{'' if intervals == '1' else 's'}, {where}; a phase error of {phase:.2g} rad at the motion's "
                f"{read.frequency / (2 * np.pi):.2g} Hz): "
                + (
                    "a driver's filter or backward difference"
                    if lag > 0
                    else "a forward difference, or a velocity stamped ahead of its angle"
                )
                + ", whose error follows the acceleration, so a fit trades "
                "damping for inertia (one sample at 100 Hz halves a fitted damping)",
                "--velocities positions (dynax differentiates the angles by central differences, which do not "
                "lag, on the times the angles imply where a time stamp disagrees with them; in Python "
                "`load_trajectory(..., velocities='positions')`)",
            )
        )
    return out


EVEN_RATIO = 0.5  # positions that follow an even grid this much more closely than their stamps: the stamps jitter
JITTER_WARN = 0.01  # ... said from this RMS distance of the stamps from the grid [median intervals]
JITTER_REFUSE = 0.05  # ... refused from this one


def jitter_findings(ts, source, values, pairs):
    """Stamps that jitter about evenly spaced samples (`even_grid_fit`): the positions follow the ticks of a
    steady clock fitted to the stamps `1 / EVEN_RATIO` times more closely than the stamps, which stray from
    their ticks by `JITTER_WARN` median intervals RMS or more (`JITTER_REFUSE`: a refusal). A logger that
    stamps each sample when it receives or writes it (a message's arrival time; a clock of coarser resolution
    than the interval) while the sensors are read on a steady clock: every difference over a jittered
    interval is wrong, and the fit with it (stamps jittered by 0.12 intervals RMS about an even 100 Hz record
    move a fitted damping by 13 %). The fix puts each sample on its tick (`Sampling(even=True)`,
    `--even-times`). A record read at jittered times that its stamps tell truly follows its stamps, not the
    grid, and is not flagged."""
    from ._derivatives import even_grid_fit

    positions = list(dict.fromkeys(pairs.values()))
    if not positions or len(ts) < 7:
        return []
    ratio, stray = even_grid_fit(ts, np.column_stack([values[q] for q in positions]))
    if not (ratio < EVEN_RATIO and stray >= JITTER_WARN):
        return []
    severity = Severity.REFUSE if stray >= JITTER_REFUSE else Severity.WARN
    message = (
        f"the time stamps jitter by {stray:.2g} median intervals RMS about evenly spaced samples: the positions "
        f"follow a steady clock's ticks fitted to the stamps {1 / max(ratio, 1e-12):.3g} times more closely "
        "than the stamps (a logger that stamps each sample when it receives or writes it), so every "
        "derivative and fit over the stamps is wrong"
    )
    fix = (
        "--even-times (re-stamps each sample to its tick of that clock; in Python "
        "load_trajectory(..., sampling=Sampling(even=True)))"
    )
    return [_row_time(ts, (0, len(ts) - 1), source, Check.STAMPS, severity, "t", message, fix)]


def stamp_findings(tr, ts, source, values, pairs, measured):
    """Time stamps that disagree with the positions read at them: where the positions of a sample sit off the
    cubic through its four neighbours along the motion, by `STAMP_SIGNIFICANCE` errors and a quarter of the
    median interval in time (`sample_times_from_positions`; clean records, jittered or not, move none). A
    logger that reads its encoders, stalls, then reads its clock stamps the angles late (the DFKI rig's run 12:
    43 rows, 0.5 to 4.1 ms late at a 1.6 ms median interval). A warning: the finding names the rows and how late;
    where the measured velocities (`measured`: velocity -> position) miss there by more than twice their worst
    elsewhere against central differences on the times the positions imply (a logger that differences its
    stamps), by how much, with the fix (`--velocities positions`) that differentiates the angles on those times;
    else that they agree (read with the angles). The positions themselves stay on their stamps."""
    from ._derivatives import sample_times_from_positions

    positions = list(dict.fromkeys(pairs.values()))
    if not positions:
        return []
    qs = np.column_stack([values[q] for q in positions])
    times, rows = sample_times_from_positions(ts, qs)
    if not rows.size:
        return []
    shifts = (ts[rows] - times[rows]) * 1e3  # [ms], positive where the stamp is later than the positions say
    dt = float(np.median(np.diff(ts)))
    shown = ", ".join(str(int(r) + 1) for r in rows[:6]) + (f" and {rows.size - 6} more" if rows.size > 6 else "")
    low, high = float(np.min(np.abs(shifts))), float(np.max(np.abs(shifts)))
    sense = "late" if np.all(shifts > 0) else "early" if np.all(shifts < 0) else "late or early"
    message = (
        f"{rows.size} time stamp{'s' if rows.size > 1 else ''} (row{'s' if rows.size > 1 else ''} {shown}) "
        f"disagree{'' if rows.size > 1 else 's'} with the positions read at {'them' if rows.size > 1 else 'it'}: "
        f"{low:.2g} to {high:.2g} ms "
        f"{sense} against a {dt * 1e3:.3g} ms median interval (a logger that stalls between reading its sensors "
        "and its clock)"
    )
    if rows.size == 1:
        message = message.replace(f"{low:.2g} to {high:.2g} ms", f"{high:.2g} ms")
    fix = None
    if measured:
        touched = np.zeros(len(ts), bool)
        touched[np.clip(np.concatenate([rows - 1, rows, rows + 1]), 0, len(ts) - 1)] = True
        misses = {v: np.abs(values[v] - np.gradient(values[q], times)) for v, q in measured.items()}
        worst = {v: float(np.max(m[touched])) for v, m in misses.items()}
        # the logged velocities are harmed where they miss there by more than twice their worst elsewhere (a
        # logger that differences its stamps); read with the angles, they agree there as anywhere else
        harmed = {v for v, m in misses.items() if worst[v] > 2.0 * float(np.percentile(m[~touched], 99))}
        if harmed:
            column = max(harmed, key=worst.__getitem__)
            message += (
                f"; the logged velocities there miss the positions' rate of change on the times they imply by up "
                f"to {worst[column]:.3g} in {column}'s unit"
            )
            fix = "--velocities positions (central differences of the angles on the times they imply)"
        else:
            message += (
                "; the logged velocities agree with the positions there (read with them: only the stamps are "
                "off), and the positions are resampled from the stamps as logged"
            )
    return [_row_time(ts, (int(rows[0]), int(rows[-1])), source, Check.STAMPS, Severity.WARN, "t", message, fix)]


def _constant(tr, ts, source, system):
    out = []
    xs, us = np.asarray(tr.xs, dtype=float), np.asarray(tr.us, dtype=float)
    vehicle = system == "helicopter"
    for c, name in enumerate(tr.state_names):
        x = xs[:, c]
        if np.ptp(x) == 0:
            severity = Severity.WARN if vehicle else Severity.REFUSE
            out.append(
                Finding(
                    Check.ZERO if x[0] == 0 else Check.CONSTANT,
                    severity,
                    source,
                    name,
                    (1, len(ts)),
                    (float(ts[0]), float(ts[-1])),
                    f"is {x[0]:.6g} in every sample: the coordinate never moves (a dead sensor, or a joint "
                    "that is locked), so nothing in the record determines what depends on it",
                )
            )
    if us.shape[1] == 0:
        return out
    flat = [np.ptp(us[:, k]) == 0 for k in range(us.shape[1])]
    zero = [flat[k] and us[0, k] == 0 for k in range(us.shape[1])]
    for k, name in enumerate(tr.input_names):
        if not flat[k]:
            continue
        if all(flat):
            severity = Severity.WARN if vehicle else Severity.REFUSE
            why = (
                "nothing drives the system, so the parameters' scale is not determined (the equations of a free "
                "motion are homogeneous in them)"
                if zero[k]
                else "a constant input cannot be told from a constant offset (which a fit estimates per record) and "
                "does not determine the parameters' scale"
            )
        else:
            severity = Severity.WARN
            why = "that input excites nothing; only the others drive the record"
        out.append(
            Finding(
                Check.ZERO if zero[k] else Check.CONSTANT,
                severity,
                source,
                name,
                (1, len(ts)),
                (float(ts[0]), float(ts[-1])),
                f"is {us[0, k]:.6g} in every sample: {why}",
            )
        )
    return out


def _repeated_columns(tr, ts, source):
    """Two columns of one record equal in every sample (one file column read twice: a `--map` that names the
    same column for two coordinates, a logger that wrote one channel twice). No two coordinates or inputs of
    these machines move alike throughout, and a fit ascribes the one's effect to the other. Columns that never
    change are `_constant`'s."""
    xs, us = np.asarray(tr.xs, dtype=float), np.asarray(tr.us, dtype=float)
    columns = [(n, xs[:, i]) for i, n in enumerate(tr.state_names)]
    columns += [(n, us[:, i]) for i, n in enumerate(tr.input_names)]
    out = []
    for j, (name, x) in enumerate(columns):
        if np.ptp(x) == 0:
            continue
        same = next((other for other, y in columns[:j] if np.array_equal(x, y)), None)
        if same is not None:
            out.append(
                Finding(
                    Check.DUPLICATE,
                    Severity.REFUSE,
                    source,
                    name,
                    (1, len(ts)),
                    (float(ts[0]), float(ts[-1])),
                    f"is the same as column '{same}' in every sample: one column read twice (a --map that names "
                    f"one file column for both?); no two coordinates or inputs of a machine move alike throughout, "
                    f"and a fit would ascribe the one's effect to the other",
                    f"map {name} to its own column",
                )
            )
    return out


def estimated_velocities(trajectory: Trajectory) -> tuple[str, ...]:
    """The velocity columns that are the central differences of their positions (to round-off): estimated
    from encoder angles by `load_trajectory`, not measured."""
    ts = np.asarray(trajectory.ts, dtype=float)
    if len(ts) < 3:
        return ()
    names = tuple(trajectory.state_names)
    xs = np.asarray(trajectory.xs, dtype=float)
    out = []
    for v, q in velocity_pairs(names).items():
        c = np.gradient(xs[:, names.index(q)], ts - ts[0])  # `central_difference`'s formula, on the host
        x = xs[:, names.index(v)]
        if np.allclose(
            x, c, rtol=1e-9, atol=1e-12 * (1.0 + float(np.max(np.abs(c), initial=0.0, where=np.isfinite(c))))
        ):
            out.append(v)
    return tuple(out)


def check_record(trajectory: Trajectory, *, estimated: Sequence[str] | None = None) -> DataCheck:
    """The located faults of one record (see the module notes).

    **Arguments:** `trajectory` (as `load_trajectory` gives it; `system` and `source` are read);
    `estimated`: the velocity columns that were estimated from their positions rather than measured
    (their agreement is not checked, and a stuck angle beside one is only a warning); `None` (the
    default) finds them (`estimated_velocities`).

    **Returns:** a `DataCheck`.
    """
    ts = np.asarray(trajectory.ts, dtype=float)
    source = trajectory.source or ""
    if len(ts) < 3:
        return DataCheck()
    if estimated is None:
        estimated = estimated_velocities(trajectory)
    dt = float(np.median(np.diff(ts)))  # the median interval, read by several checks
    findings = list(_time_units(trajectory, ts, source, dt))
    if findings:  # every other check reads the time scale
        return DataCheck(tuple(findings))
    names = tuple(trajectory.state_names)
    xs = np.asarray(trajectory.xs, dtype=float)
    us = np.asarray(trajectory.us, dtype=float)
    values = {n: xs[:, i] for i, n in enumerate(names)}
    pairs = velocity_pairs(names)
    measured = {v: q for v, q in pairs.items() if v not in estimated}
    paired_estimated = {q for v, q in pairs.items() if v in estimated}
    findings += _constant(trajectory, ts, source, trajectory.system)
    findings += _repeated_columns(trajectory, ts, source)
    columns = [(n, xs[:, i], False) for i, n in enumerate(names) if n not in estimated]
    columns += [(n, us[:, i], True) for i, n in enumerate(trajectory.input_names)]
    glitches = glitch_findings(trajectory, ts, source, columns, {v: values[q] for v, q in measured.items()})
    findings += glitches
    angles = [(q, values[q]) for q in pairs.values()] if trajectory.system in ("acrobot", "double_pendulum") else []
    wrapped = _wrapped(trajectory, ts, source, angles)
    findings += wrapped
    jumps = [] if wrapped else jump_findings(trajectory, ts, source, values, pairs, measured, dt)
    findings += jumps
    findings += stuck_findings(trajectory, ts, source, names, xs, paired_estimated, dt)
    if not glitches and not wrapped and not jumps:  # each spoils its blocks too; said once, at its sample
        stretches = velocity_stretch_findings(trajectory, ts, source, values, measured, dt)
        findings += stretches
        wrong = {f.column for f in stretches}  # a velocity wrong in a stretch has no one lag: said once
        findings += lag_findings(
            trajectory, ts, source, values, {v: q for v, q in measured.items() if v not in wrong}, dt
        )
        jitter = jitter_findings(ts, source, values, pairs)
        findings += jitter or stamp_findings(trajectory, ts, source, values, pairs, measured)
    return DataCheck(tuple(findings))


def same_data(a: Trajectory, b: Trajectory) -> bool:
    """Whether two records hold the same times, states and inputs, sample for sample."""
    return (
        len(a) == len(b)
        and a.xs.shape == b.xs.shape
        and a.us.shape == b.us.shape
        and np.array_equal(np.asarray(a.ts), np.asarray(b.ts))
        and np.array_equal(np.asarray(a.xs), np.asarray(b.xs))
        and np.array_equal(np.asarray(a.us), np.asarray(b.us))
    )


def check_records(
    records: Sequence[Trajectory], validation: Sequence[Trajectory] = (), *, estimated: Sequence[str] | None = None
) -> DataCheck:
    """`check_record` on each record and held-out record, and the same record given twice.

    **Arguments:** `records` (training), `validation` (held-out; may be empty), `estimated` as in
    `check_record`.

    **Returns:** a `DataCheck` with every finding, record by record.
    """
    records, validation = list(records), list(validation or ())
    findings = []
    for r in records + validation:
        findings += check_record(r, estimated=estimated).findings
    everything = [("record", r) for r in records] + [("validation record", r) for r in validation]
    for a in range(len(everything)):
        for b in range(a + 1, len(everything)):
            (ka, ra), (kb, rb) = everything[a], everything[b]
            if same_data(ra, rb):
                held = ka != kb
                message = f"is the same data as the {ka} {ra.source or a + 1}: " + (
                    "held-out error on the training data is in-sample, no validation"
                    if held
                    else "the same record counted twice doubles its weight and shrinks every standard error by about "
                    "1.4 (the square root of 2)"
                )
                findings.append(
                    Finding(
                        Check.DUPLICATE,
                        Severity.REFUSE,
                        rb.source or "",
                        None,
                        None,
                        None,
                        message,
                        "give a different record"
                        + (" for validation (or none: the tail is held out)" if held else ", or this one once"),
                    )
                )
            else:
                findings += shared_stretch_findings(ka, ra, a + 1, kb, rb)
    return DataCheck(tuple(findings))


def _file_name(record: Trajectory) -> str:
    """The file a record (or a piece `--exclude` left of it) was read from, as `--exclude FILE@` names it."""
    source = record.source or ""
    if source.endswith(" s]") and " [" in source:
        source = source.rsplit(" [", 1)[0]
    return pathlib.Path(source).name if source else ""


def _ordinal(n: int) -> str:
    return f"{n}{'nd' if n == 2 else 'rd' if n == 3 else 'th'}"


def shared_stretch_findings(
    ka: str, ra: Trajectory, number: int, kb: str, rb: Trajectory, *, exclude: bool = True
) -> list[Finding]:
    """A refusal for each stretch of `rb` that is rows of `ra` (`shared_either_way`: one for one, a copy at a
    whole fraction or multiple of the rate, or one resampled between its rows): held-out error there is
    in-sample (`rb` held out, `ra` not: `ka != kb`), or the stretch is counted twice. The fix cuts it from
    the training record (`ra` when `rb` is held out; else `rb`) with `--exclude`, or where the command has
    none (`exclude=False`), asks for other records."""
    held = ka != kb
    findings = []
    for shared in shared_either_way(ra, rb):
        (i, j), (k, m) = shared.rows_a, shared.rows_b
        ta, tb = np.asarray(ra.ts, float), np.asarray(rb.ts, float)
        resolution = float(np.median(np.diff(ta))) / 10
        there = f"{time_label(float(ta[i]), resolution)} to {time_label(float(ta[j]), resolution)} s"
        source = ra.source or number
        if shared.step == 1:
            what = (
                f"holds {m - k + 1} samples that are the {ka} {source}'s, one for one (its rows {i + 1}-{j + 1}, "
                f"t = {there})"
            )
        elif shared.step > 1:
            what = (
                f"holds {m - k + 1} samples that are every {_ordinal(shared.step)} row of the {ka} {source}'s rows "
                f"{i + 1}-{j + 1} (t = {there}; a copy at a lower rate)"
            )
        elif shared.step < 0:
            what = (
                f"holds the {ka} {source}'s rows {i + 1}-{j + 1} (t = {there}) at every {_ordinal(-shared.step)} of "
                f"its own rows (a copy at a higher rate)"
            )
        else:
            what = (
                f"holds {m - k + 1} samples that lie on the path of the {ka} {source}'s rows {i + 1}-{j + 1} "
                f"(t = {there}), {shared.ratio:.4g} of its rows a row: a copy resampled at another rate"
            )
        message = (
            what
            + ": "
            + (
                "held-out error there is in-sample, not validation"
                if held
                else "that stretch counted twice doubles its weight; the standard errors shrink as if it were new"
            )
        )
        cut, (first, last), times = (ra, (i, j), ta) if held else (rb, (k, m), tb)
        whole = first == 0 and last == len(cut) - 1
        if whole or not exclude:  # nothing is left to fit once it is cut, or the command cuts nothing
            fix = (
                "give a held-out record that holds none of the training records' samples"
                if held
                else "give the record once"
                if whole
                else "give each stretch in one record only"
            )
        else:
            name = _file_name(cut)
            fix = _span(times, first, last).replace("--exclude ", f"--exclude {name}@" if name else "--exclude ")
            fix += f" (cuts it from the {'training ' if held else ''}record" + (
                f" {cut.source})" if cut.source else ")"
            )
        findings.append(_row_time(tb, (k, m), rb.source or "", Check.DUPLICATE, Severity.REFUSE, None, message, fix))
    return findings


# --- cutting stretches out -----------------------------------------------------------------------


def parse_exclude(text: str | None) -> list[tuple[str | None, float, float]]:
    """Parse `--exclude [FILE@]T0:T1,...` into `(file or None, t0, t1)`; an empty end is open (`8.8:`)."""
    spans = []
    if not text:
        return spans
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        where, at, span = item.rpartition("@")
        a, colon, b = span.partition(":")
        if not colon:
            raise UsageError(f"--exclude: '{item}' is not of the form T0:T1 (seconds; an end may be left open: 8.8:)")
        try:
            t0 = -math.inf if not a.strip() else float(a)
            t1 = math.inf if not b.strip() else float(b)
        except ValueError:
            raise UsageError(f"--exclude: '{item}' holds a time that is not a number") from None
        if math.isnan(t0) or math.isnan(t1) or not t0 < t1:
            raise UsageError(f"--exclude: '{item}' is not a stretch of time (T0 < T1)")
        spans.append((where if at else None, t0, t1))
    return spans


def exclude_stretches(
    trajectory: Trajectory, spans: Sequence[tuple[float, float]], *, min_samples: int = 3
) -> list[Trajectory]:
    """`trajectory` without the samples in each stretch `(t0, t1)` (both ends included; `-inf`/`inf`
    for open ends), as the records that remain between them (a cut inside a record leaves two). Pieces
    shorter than `min_samples` are dropped. Each piece's `source` names its file and time span.

    The Python equivalent of the command line's `--exclude t0:t1`.
    """
    ts = np.asarray(trajectory.ts, dtype=float)
    keep = np.ones(len(ts), bool)
    for t0, t1 in spans:
        keep &= ~((ts >= t0) & (ts <= t1))
    if keep.all():
        return [trajectory]
    pieces = []
    for i, j in _runs(keep):
        if j - i + 1 < min_samples:
            continue
        piece = trajectory.slice(int(i), int(j) + 1)
        name = f"{trajectory.source or 'record'} [{time_label(float(ts[i]), 1e-3)}-{time_label(float(ts[j]), 1e-3)} s]"
        pieces.append(
            Trajectory(piece.ts, piece.xs, piece.us, piece.state_names, piece.input_names, piece.system, name)
        )
    return pieces
