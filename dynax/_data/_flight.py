r"""Flight records: load a multirotor's log, find its ground segments and flag its glitches.

A real flight log holds more than flight: the vehicle rests on the floor before take-off and after
landing (motors off, or spinning up against the floor's reaction), and its sensors and logger
glitch (a gyro sample of hundreds of rad/s, a motor command beyond any the controller sends, a
motion-capture position that jumps). None of it is flight dynamics, and fitting it would teach
the model the floor's reaction force or a corrupt sample. `inspect_flight` finds both and says
where; `usable_segments` cuts a record into the runs of flight between them, which the vehicle
criteria fit and score without a window crossing a cut.

The thresholds are physics of small multirotors, not of one rig (`FlightChecks`):

- ground: every motor input at or below `motor_off` times the median in-flight input, or the
  vehicle within `clearance` of the floor (its height at the nearest motors-off sample: take-off
  and landing spots may differ; else the record's lowest height), where the floor carries it;
- `max_rate`: a body rate beyond the full scale of the MEMS gyros of small multirotors
  (2000 deg/s = 34.9 rad/s) is no measurement;
- `max_input_ratio`: a motor input beyond this multiple of its median in flight: thrust grows
  with the square of the input, and no multirotor has the thrust-to-weight ratio (9 at 3x the
  hover command) that a larger one would need. A corrupt input usually ramps away from its
  last good value, so the flagged run is extended back to where its climb began (the last
  sample before it that is not below the next);
- `max_jump`: a position step that the recorded velocity does not explain by more than this
  [m] in one sample (a motion-capture marker swap or a lost frame);
- a frozen position: `x`, `y` and `z` all repeated exactly for `FREEZE_SAMPLES` samples or more
  while the logged velocity moves the vehicle by more than `FREEZE_NOISE` times the position's
  noise over them (the robust scale of the step the velocity does not explain). Honest motion
  capture never repeats all three while the vehicle moves (the 16 NanoBench flights: not once in
  flight; a single repeat on the floor), so a freeze too short for `stuck` and with a catch-up
  below `max_jump` is still a fault, noted as `stuck` in `x,y,z`.

Beside these, the record's own statistics (the located checks of `dynax.check_records`, with the
velocities `vx, vy, vz` paired with `x, y, z`): a `spike`, up to three samples that leave the
column's running median by more than 1.5 times its 1-99 % range and 20 typical steps (a gyro
sample of 15 rad/s in a flight whose rates span 3 is no measurement, though within the gyro's
range); `stuck`, a value repeated exactly for 0.25 s and 25 samples or more while other columns
change (motion capture that lost the vehicle and holds its last position); `velocity`, a stretch
of 150 ms or more where a velocity's block means are off its position's change by a factor of 2
or more, or of the other sign (the rates' rule in `_flight_kinematics`: a motion-capture velocity
filter lags its position by up to a third in sharp turns, which is no fault). `load_flight` adds
`gap`: a stretch of more than `MAX_FLIGHT_GAP` median intervals with no sample, interpolated when
the record is resampled and left out. A flight's body rates change within a few samples: interpolated
across 4 intervals, the NanoBench flights' rates miss the recorded ones by 3 times their noise, across
3 by 2 times (`experiments/flight_freezes_and_gaps.py`); the logger's occasional 20-30 ms gaps (2-3
intervals) are bridged.
"""

import dataclasses
import os
import warnings

import jax.numpy as jnp
import numpy as np

from .._errors import DataError
from ._derivatives import resample
from ._flight_kinematics import (
    check_flight_kinematics,
    check_position_units,
    check_quaternion_order,
    check_rate_frame,
    check_thrust_frame,
    check_unit_quaternions,
    check_up_axis,
    check_velocity_frame,
)
from ._io import load_columns, Sampling
from ._sanity import Check, DataWarning, glitch_findings, stuck_findings, velocity_stretch_findings
from ._trajectory import Trajectory
from ._velocities import block_slopes, stretch_edges

#: The kinds of glitch `inspect_flight` flags (its `Glitch.kind`), and `load_flight`'s `gap`.
GLITCH_KINDS = ("rate_range", "input_range", "position_jump", "spike", "stuck", "velocity", "gap")
_RECORD_KINDS = {Check.GLITCH: "spike", Check.STUCK: "stuck", Check.VELOCITY: "velocity"}
WORLD_VELOCITIES = {"vx": "x", "vy": "y", "vz": "z"}
STRETCH_FACTOR = 2.0  # a velocity off its position's change by this factor in a stretch (or of the other sign)

# A gap of more than this many sample intervals is noted and its interpolated samples left out (module notes).
MAX_FLIGHT_GAP = 3


@dataclasses.dataclass(frozen=True)
class FlightChecks:
    """The thresholds of `inspect_flight` (see the module docstring for their physics).

    **Fields:** `motor_off` (fraction of the median in-flight input, default 0.05), `clearance`
    [m] (default 0.01), `max_rate` [rad/s] (default 34.9), `max_input_ratio` (default 3.0),
    `max_jump` [m] (default 0.05).
    """

    motor_off: float = 0.05
    clearance: float = 0.01
    max_rate: float = 34.9
    max_input_ratio: float = 3.0
    max_jump: float = 0.05


@dataclasses.dataclass(frozen=True)
class Glitch:
    """A run of flagged samples in one column.

    **Fields:** `column` (the contract's name; `x,y,z` for the three at once), `kind` (one of
    `GLITCH_KINDS`), `start`, `stop` (seconds from the record's first sample, first and last flagged
    sample; for a `gap`, the samples either side of it), `row` (the first flagged sample's 1-based
    data row), `n_samples`, `worst` (the most extreme flagged value; for a `velocity` stretch, its
    gain on the position's change; for a `gap`, its length in seconds).
    """

    column: str
    kind: str
    start: float
    stop: float
    row: int
    n_samples: int
    worst: float

    def describe(self) -> str:
        if self.kind == "gap":
            return (
                f"{self.column}: gap, no sample from t = {self.start:.2f} to {self.stop:.2f} s (row {self.row}, "
                f"{self.n_samples} samples interpolated)"
            )
        span = (
            f"at t = {self.start:.2f} s" if self.n_samples == 1 else f"from t = {self.start:.2f} to {self.stop:.2f} s"
        )
        worst = "gain" if self.kind == "velocity" else "worst"
        return f"{self.column}: {self.kind} {span} (row {self.row}, {self.n_samples} samples, {worst} {self.worst:.4g})"


@dataclasses.dataclass(frozen=True)
class FlightNotes:
    """What `inspect_flight` found in a record.

    **Fields:**

    - `ground`: `(start, stop)` seconds from the record's first sample of each ground segment.
    - `glitches`: the flagged runs (`Glitch`), in time order.
    - `usable`: per sample, `True` where the vehicle flies and nothing is flagged.
    - `source`: the file.
    - `resampled`: how `load_flight` put an unevenly stamped record on its grid (`resampling_note`), or `""`.
    - `estimated`: the states the file does not have and `load_flight` estimated (`estimated_note`), or `""`.
    """

    ground: tuple[tuple[float, float], ...]
    glitches: tuple[Glitch, ...]
    usable: np.ndarray
    source: str = ""
    resampled: str = ""
    estimated: str = ""

    def describe(self) -> list[str]:
        """One line per ground segment and glitch, for a note on the terminal or in a report (the resampling,
        which `load_flight` says apart, is `resampled`)."""
        lines = [f"ground segment from t = {a:.2f} to {b:.2f} s: left out" for a, b in self.ground]
        lines += [f"glitch in {g.describe()}: left out" for g in self.glitches]
        return lines


def estimated_note(names) -> str:
    """What `load_flight` estimated of the states a log does not have, in one line (`""`: none)."""
    said = []
    if "vx" in names:
        said.append("vx, vy, vz from x, y, z")
    if "p" in names:
        said.append("p, q, r from the attitude (its body-frame steps, qw..qz)")
    if not said:
        return ""
    return (
        f"not in the file, estimated by central differences (zero phase; they carry the differenced noise): "
        f"{'; '.join(said)}"
    )


def resampling_note(recorded: np.ndarray, dt: float) -> str:
    """What resampling a record stamped at `recorded` onto its median interval `dt` did, in one line: the frames
    missed (whole intervals with no sample) and the longest interval, and how far the stamps stray from the
    grid's whole intervals (jitter)."""
    steps = np.diff(np.asarray(recorded, dtype=float))
    whole = np.maximum(np.rint(steps / dt), 1.0)
    missed = int(np.sum(whole - 1.0))
    jitter = float(np.max(np.abs(steps - whole * dt))) if steps.size else 0.0
    said = []
    if missed:
        said.append(f"{missed} frame(s) missed, the longest interval {steps.max() * 1e3:.3g} ms")
    if jitter > 1e-6 * dt:
        said.append(f"stamps off the grid by up to {jitter * 1e3:.3g} ms")
    return (
        f"t: unevenly stamped ({'; '.join(said) or 'intervals differ'}): resampled onto its median interval of "
        f"{dt * 1e3:.4g} ms, states interpolated and inputs averaged over each interval"
    )


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """`(first, last)` indices of each run of `True`."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]


FREEZE_SAMPLES = 2  # repeated samples (three identical rows): one repeat is a frame logged twice, as on the floor
FREEZE_NOISE = 10.0  # the displacement a freeze hides, in the position's noise, beyond any chance of noise
SPIKE_SAMPLES = 3  # a flagged run this short is a corrupt sample or three, not a log that runs away
IDLE_S = 0.5  # every motor below half its level this long, where none stops, is the vehicle idling on its pad


def _lasting(mask: np.ndarray, rel: np.ndarray, seconds: float) -> np.ndarray:
    """`mask` with only its runs that last `seconds` or more."""
    out = np.zeros_like(mask)
    for a, b in _runs(mask):
        if rel[b] - rel[a] >= seconds:
            out[a : b + 1] = True
    return out


def _with_onsets(mask: np.ndarray, values: np.ndarray) -> np.ndarray:
    """`mask` with each run longer than `SPIKE_SAMPLES` (a log that runs away) extended back over the
    monotonic climb that leads into it; a spike has no climb (a smooth command's rise before it is flight)."""
    mask = mask.copy()
    magnitude = np.abs(values)
    for a, b in _runs(mask):
        if b - a + 1 <= SPIKE_SAMPLES:
            continue
        k = a
        while k > 0 and magnitude[k - 1] < magnitude[k]:
            k -= 1
        mask[k:a] = True
    return mask


def _column(trajectory: Trajectory, name: str) -> np.ndarray:
    return np.asarray(
        trajectory.xs[:, trajectory.state_names.index(name)]
        if name in trajectory.state_names
        else trajectory.us[:, trajectory.input_names.index(name)],
        dtype=float,
    )


def _motors_off(trajectory: Trajectory, checks: FlightChecks) -> tuple[np.ndarray, np.ndarray]:
    """Per sample, whether every motor is off (at most `motor_off` times its in-flight level: the median
    over the samples with any motor running), and those levels."""
    motors = np.stack([_column(trajectory, f"m{i}") for i in range(1, 5)], axis=1)
    running = np.max(np.abs(motors), axis=1) > 0
    level = np.median(np.abs(motors[running]), axis=0) if running.any() else np.ones(4)
    level = np.where(level > 0, level, 1.0)
    return np.all(np.abs(motors) <= checks.motor_off * level, axis=1), level


def motors_running_run(trajectory: Trajectory, checks: FlightChecks = FlightChecks()) -> tuple[int, int] | None:
    """`(first, last)` sample indices of the longest run with any motor running (`_motors_off` negated),
    or `None` where the motors never run: the stretch `load_flight` checks the columns' agreement on."""
    runs = _runs(~_motors_off(trajectory, checks)[0])
    return max(runs, key=lambda r: r[1] - r[0]) if runs else None


def inspect_flight(trajectory: Trajectory, checks: FlightChecks = FlightChecks()) -> FlightNotes:
    """Find the ground segments and flag the glitches of a quadrotor record.

    **Arguments:**

    - `trajectory`: a record with the contract's `quadrotor` columns (`dynax.load_trajectory(path,
      "quadrotor", mapping=...)`), uniformly sampled or not.
    - `checks`: the thresholds (`FlightChecks`).

    **Returns:** `FlightNotes`: ground segments, glitches (column, kind, time, row) and the
    per-sample `usable` mask (neither ground nor flagged).
    """
    ts = np.asarray(trajectory.ts, dtype=float)
    rel = ts - ts[0]
    motors = np.stack([_column(trajectory, f"m{i}") for i in range(1, 5)], axis=1)
    z = _column(trajectory, "z")
    off, level = _motors_off(trajectory, checks)
    # The floor under the vehicle: its height at the nearest motors-off sample (take-off and landing
    # spots differ: a pad, an uneven floor), else at the nearest sample with every motor idling (below half
    # its level for `IDLE_S` or more: not a dive). A log with neither (started in the air) shows no floor:
    # its lowest pass is flight.
    idle = off if off.any() else _lasting(np.all(np.abs(motors) < 0.5 * level, axis=1), rel, IDLE_S)
    if idle.any():
        rests = np.flatnonzero(idle)
        after = np.clip(np.searchsorted(rests, np.arange(len(z))), 0, len(rests) - 1)
        before = np.clip(after - 1, 0, len(rests) - 1)
        nearest = np.where(
            np.abs(rests[before] - np.arange(len(z))) <= np.abs(rests[after] - np.arange(len(z))),
            rests[before],
            rests[after],
        )
        ground = off | (z < z[nearest] + checks.clearance)
    else:
        ground = off

    flagged: list[tuple[str, str, np.ndarray, np.ndarray]] = []
    for name in ("p", "q", "r"):
        col = _column(trajectory, name)
        flagged.append((name, "rate_range", np.abs(col) > checks.max_rate, col))
    for i in range(4):
        col = motors[:, i]
        flagged.append(
            (f"m{i + 1}", "input_range", _with_onsets(np.abs(col) > checks.max_input_ratio * level[i], col), col)
        )
    position = np.stack([_column(trajectory, c) for c in ("x", "y", "z")], axis=1)
    velocity = np.stack([_column(trajectory, c) for c in ("vx", "vy", "vz")], axis=1)
    dt = np.diff(ts)[:, None]
    residual = np.diff(position, axis=0) - 0.5 * (velocity[1:] + velocity[:-1]) * dt
    unexplained = np.linalg.norm(residual, axis=1)
    jump = np.concatenate([[False], unexplained > checks.max_jump])
    flagged.append(("x,y,z", "position_jump", jump, np.concatenate([[0.0], unexplained])))

    glitches, bad = [], np.zeros(len(ts), bool)
    for column, kind, mask, values in flagged:
        bad |= mask
        for a, b in _runs(mask):
            worst = values[a : b + 1][np.argmax(np.abs(values[a : b + 1]))]
            glitches.append(Glitch(column, kind, float(rel[a]), float(rel[b]), a + 1, b - a + 1, float(worst)))
    frozen = _frozen_positions(ts, position, velocity, residual)
    for glitch, (a, b) in _record_glitches(trajectory, ts, flagged, ground, frozen):
        bad[a : b + 1] = True
        glitches.append(glitch)
    glitches.sort(key=lambda g: (g.start, g.column))
    segments = tuple((float(rel[a]), float(rel[b])) for a, b in _runs(ground))
    return FlightNotes(segments, tuple(glitches), ~ground & ~bad, trajectory.source)


def _frozen_positions(ts, position, velocity, residual) -> list[tuple[int, int]]:
    """`(first, last)` of each run of `FREEZE_SAMPLES` or more samples repeating `x, y, z` exactly (from
    the first repeat) over which the logged velocity moves the vehicle more than
    `FREEZE_NOISE` times the position's noise (1.4826 times the median absolute unexplained step, per axis;
    the largest)."""
    if len(ts) < 3:
        return []
    noise = float(np.max(1.4826 * np.median(np.abs(residual), axis=0)))
    repeated = np.concatenate([[False], np.all(position[1:] == position[:-1], axis=1)])
    out = []
    for a, b in _runs(repeated):
        if b - a + 1 < FREEZE_SAMPLES:
            continue
        steps = 0.5 * (velocity[a : b + 1] + velocity[a - 1 : b]) * np.diff(ts[a - 1 : b + 1])[:, None]
        moved = float(np.linalg.norm(np.sum(steps, axis=0)))
        if moved > FREEZE_NOISE * noise:
            out.append((a, b))
    return out


def _record_glitches(
    trajectory: Trajectory, ts: np.ndarray, flagged, ground: np.ndarray, frozen=()
) -> list[tuple[Glitch, tuple[int, int]]]:
    """The record's statistical glitches (see the module notes) as `(Glitch, (first, last))`: spikes, stuck
    columns and velocity stretches, from `dynax.check_records`' located checks, less what the physical
    ranges flagged already and what lies on the `ground` (a touch-down jolts the gyro: motion the flight's
    statistics do not describe, left out as ground already); a run found in `x`, `y` and `z` alike is one
    motion-capture glitch, `x,y,z`, as is each `frozen` run `(first, last)` of `_frozen_positions`."""
    rel = ts - ts[0]
    names = tuple(trajectory.state_names)
    xs, us = np.asarray(trajectory.xs, dtype=float), np.asarray(trajectory.us, dtype=float)
    values = {n: xs[:, i] for i, n in enumerate(names)}
    dt = float(np.median(np.diff(ts))) if len(ts) > 1 else 1.0
    columns = [(n, xs[:, i], False) for i, n in enumerate(names)]
    columns += [(n, us[:, i], True) for i, n in enumerate(trajectory.input_names)]
    pairs = {v: q for v, q in WORLD_VELOCITIES.items() if v in values and q in values}
    findings = glitch_findings(trajectory, ts, "", columns, {v: values[q] for v, q in pairs.items()})
    findings += stuck_findings(trajectory, ts, "", names, xs, set(), dt)
    findings += velocity_stretch_findings(trajectory, ts, "", values, pairs, dt)
    covered = {column: mask for column, _, mask, _ in flagged}
    position_faults = [
        (f.column, f.rows[0] - 1, f.rows[1] - 1)
        for f in findings
        if f.kind in (Check.STUCK, Check.GLITCH) and f.column in ("x", "y", "z") and f.rows is not None
    ]
    position_faults += [(c, a, b) for a, b in frozen for c in ("x", "y", "z")]
    spans: dict[tuple[str, int, int], list[str]] = {}
    for f in findings:
        if f.rows is None or f.column is None or f.kind not in _RECORD_KINDS:
            continue
        a, b = f.rows[0] - 1, f.rows[1] - 1
        if f.kind == Check.STUCK:
            a += 1  # the samples that repeat the last good one
        if ground[a : b + 1].all() or (f.column in covered and covered[f.column][a : b + 1].all()):
            continue  # on the floor, or beyond the sensor's range: said once, as that
        if f.kind == Check.VELOCITY and any(
            c == pairs.get(f.column) and i <= b and j >= a for c, i, j in position_faults
        ):
            continue  # the velocity misses a position that stuck or spiked: said once, as the position's
        spans.setdefault((_RECORD_KINDS[f.kind], a, b), []).append(f.column)
    stuck = [(a, b) for (kind, a, b), found in spans.items() if kind == "stuck" and "x" in found]
    for a, b in frozen:  # too short for `stuck`'s rule, or said by it already
        if not ground[a : b + 1].all() and not any(i <= b and j >= a for i, j in stuck):
            spans.setdefault(("stuck", a, b), []).extend(["x", "y", "z"])
    out = []
    for (kind, a, b), found in spans.items():
        gains = {}
        if kind == "velocity":  # a fault where off by `STRETCH_FACTOR` or more, or of the other sign (a lag is not)
            gains = {v: _stretch_gain(ts, values[pairs[v]], values[v], a, b) for v in found}
            found = [v for v in found if not (1.0 / STRETCH_FACTOR < gains[v] < STRETCH_FACTOR)]
        position = {"x", "y", "z"} <= set(found) and kind != "velocity"
        groups = [[c] for c in found if not (position and c in ("x", "y", "z"))]
        groups += [["x", "y", "z"]] if position else []
        for group in groups:
            if kind == "velocity":
                worst = gains[group[0]]
            else:
                seg = _column(trajectory, group[0])[a : b + 1]
                worst = float(seg[np.argmax(np.abs(seg))])
            glitch = Glitch(",".join(group), kind, float(rel[a]), float(rel[b]), a + 1, b - a + 1, worst)
            out.append((glitch, (a, b)))
    return out


def _stretch_gain(ts, position, velocity, a, b) -> float:
    """A velocity's gain on its position's change over the 50 ms blocks of samples `a..b`."""
    edges = stretch_edges(ts)
    edges = edges[(edges >= a) & (edges <= b)]
    if len(edges) < 2:
        edges = np.array([a, b])
    slopes, means = block_slopes(ts, position, velocity, edges)
    return float(slopes @ means / (slopes @ slopes)) if slopes @ slopes > 0 else float("nan")


def usable_segments(trajectory: Trajectory, notes: FlightNotes, min_samples: int = 2) -> list[Trajectory]:
    """The runs of usable samples (`notes.usable`) as separate `Trajectory`s of at least `min_samples`."""
    return [trajectory.slice(a, b + 1) for a, b in _runs(np.asarray(notes.usable)) if b + 1 - a >= min_samples]


def _continuous_quaternions(quats: np.ndarray) -> np.ndarray:
    """Each quaternion on the hemisphere of the one before ($q$ and $-q$ are one attitude), so that
    interpolating between samples interpolates attitudes."""
    out = quats.copy()
    flips = np.concatenate([[False], np.sum(quats[1:] * quats[:-1], axis=1) < 0])
    sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
    return out * sign[:, None]


def _with_gaps(notes: FlightNotes, ts: np.ndarray, gaps) -> FlightNotes:
    """`notes` with each gap `(t_before, t_after)` of the recorded times noted as a `gap` glitch, the samples
    resampling interpolated inside it (on the grid `ts`) left out."""
    if not gaps:
        return notes
    usable, found = np.array(notes.usable), list(notes.glitches)
    tolerance = 1e-3 * float(np.median(np.diff(ts)))  # the grid's times and the recorded ones differ in the last bits
    for before, after in gaps:
        inside = np.flatnonzero((ts > before + tolerance) & (ts < after - tolerance))
        if inside.size:
            usable[inside] = False
            start, stop, n = float(before - ts[0]), float(after - ts[0]), int(inside.size)
            found.append(Glitch("t", "gap", start, stop, int(inside[0]) + 1, n, float(after - before)))
    found.sort(key=lambda g: (g.start, g.column))
    return FlightNotes(notes.ground, tuple(found), usable, notes.source, notes.resampled, notes.estimated)


# A battery's voltage while the motors run stays within this factor of itself over a flight: a lithium cell from
# full charge (4.35 V for high-voltage cells) to the deepest sag under load a flight logs (2.0 V, a NanoBench
# flight whose battery is dying: 1.66 between its 1st and 99th percentiles in flight; 1.08-1.17 on the others).
# A column that spans more is no voltage (a state of charge in percent, a current).
MAX_VBAT_SPAN = 3.0


def check_input_columns(data: Trajectory, *, path=None, columns=None, checks=None) -> None:
    """Refuse motor and battery columns that no flight logs: a motor zero while the others run, constant, or the
    copy of another motor, throughout; a battery at 0 V or below throughout, or at 0 V or below, or spanning
    more than `MAX_VBAT_SPAN` (1st to 99th percentile), while the motors run. Each makes the motor map's
    features collinear or void, so a fit returns numbers that mean nothing.

    **Raises:** `DataError` naming the file and the column (as the file names it)."""
    columns = columns or {}
    named = lambda n: columns.get(n, n)  # noqa: E731
    motors = {f"m{i}": _column(data, f"m{i}") for i in range(1, 5)}
    for name, m in motors.items():
        others = [o for o, v in motors.items() if o != name and np.any(v != 0)]
        if not np.any(m != 0) and others:
            raise DataError(
                f"is zero in every row while {', '.join(named(o) for o in others)} run: a motor that never turns "
                "lifts nothing, so this is not its log; map the motor's own column",
                path=path,
                column=named(name),
            )
        if np.any(m != 0) and np.ptp(m) == 0:
            raise DataError(
                f"is constant ({m[0]:.6g}) in every row: a flying multirotor's motor commands or speeds move with "
                "every correction of its attitude; map the motor's own column",
                path=path,
                column=named(name),
            )
        for other in list(motors)[: list(motors).index(name)]:
            if np.any(m != 0) and np.array_equal(m, motors[other]):
                raise DataError(
                    f"is the same as column '{named(other)}' in every row: one motor's log mapped twice? Map "
                    f"{name} to the motor's own column",
                    path=path,
                    column=named(name),
                )
    if "vbat" in data.input_names:
        vbat = _column(data, "vbat")
        if np.max(vbat) <= 0:
            raise DataError(
                f"is {np.max(vbat):.4g} V or below in every row: no battery that flies reads that; map vbat to the "
                "battery voltage's column (`--map vbat=COLUMN`), or leave the column out of the file",
                path=path,
                column=named("vbat"),
            )
        running = ~_motors_off(data, checks or FlightChecks())[0]
        if running.sum() >= 3:
            low, high = np.percentile(vbat[running], [1, 99])
            if not (low > 0 and high <= MAX_VBAT_SPAN * low):
                ts = np.asarray(data.ts, dtype=float)
                rows = np.flatnonzero(running)
                raise DataError(
                    f"reads {low:.4g} to {high:.4g} (1st to 99th percentile) while the motors run (t = "
                    f"{ts[rows[0]] - ts[0]:.2f} to {ts[rows[-1]] - ts[0]:.2f} s): a battery's voltage under load stays "
                    f"within a factor of {MAX_VBAT_SPAN:g} of itself over a flight and above 0, so this is no voltage "
                    "(a state of charge in percent? a current?); map vbat to the battery voltage's column "
                    "(`--map vbat=COLUMN`), or leave it out",
                    path=path,
                    column=named("vbat"),
                )


# Flights of one vehicle given together whose in-flight motor or battery levels differ by more than this factor
# are in different units: the 16 NanoBench flights' median motor levels lie within 6 % of their median (battery
# charge and manoeuvre), their batteries' within 13 % (`experiments/flight_input_levels.py`); twice the hover
# command would be four times the hover thrust.
MAX_INPUT_LEVEL_RATIO = 2.0
_LEVEL_WHAT = {  # contract column -> (what, its verbs, a likely pair of units)
    "m1": ("motor inputs", "run at", "are", "percent against 0-65535, a normalised command against PWM counts?"),
    "vbat": ("battery voltage", "reads", "is", "millivolts against volts?"),
}


def input_levels(trajectory: Trajectory, usable) -> dict[str, float]:
    """A flight's levels in flight (over the `usable` samples): `"m1"`, the median of the mean motor input `m1..m4`
    (its hover command), and `"vbat"`, the battery voltage's median, where the flight logs it."""
    keep = np.asarray(usable, bool)
    us = np.asarray(trajectory.us, dtype=float)[keep]
    if not len(us):
        return {}
    out = {"m1": float(np.median(us[:, :4].mean(axis=1)))}
    if "vbat" in trajectory.input_names:
        out["vbat"] = float(np.median(us[:, trajectory.input_names.index("vbat")]))
    return out


def check_input_levels(levels: dict, *, columns=None, reference=None, reference_name: str = "") -> None:
    """Refuse flights given together whose motors or battery voltage are logged in different units: one flight's
    level in flight (`input_levels`) beyond `MAX_INPUT_LEVEL_RATIO` times, or below its inverse, the median of all
    (of two flights, the other's), or the `reference` where given (a model's training flights', `reference_name`).
    One motor map is fitted to all of them (or the model's is applied), so such a mix runs without a word and
    predicts nothing: a percent command among 0-65535 ones, a normalised one among PWM counts, millivolts among
    volts.

    **Arguments:** `levels`, file -> `input_levels`; `columns` (contract name -> file column) named in the error;
    `reference` (`{"m1": level, "vbat": level}`), `reference_name`.

    **Raises:** `DataError` naming the file and the column read as `m1` (or `vbat`).
    """
    columns, reference = columns or {}, reference or {}
    for key, (what, verb, be, guess) in _LEVEL_WHAT.items():
        found = {p: v[key] for p, v in levels.items() if key in v and np.isfinite(v[key]) and v[key] > 0}
        paths, values = list(found), np.array(list(found.values()))
        if key in reference and reference[key] > 0:
            ref = np.full(len(values), float(reference[key]))
            against = reference_name
        elif len(values) >= 2:
            # two flights: each against the other; more: against the median of all, which one odd flight cannot move
            ref = values[::-1] if len(values) == 2 else np.full(len(values), float(np.median(values)))
            against = "the other flight" if len(values) == 2 else "the median of the flights given together"
        else:
            continue
        if not len(values):
            continue
        ratio = values / ref
        worst = int(np.argmax(np.abs(np.log(ratio))))
        if 1 / MAX_INPUT_LEVEL_RATIO <= ratio[worst] <= MAX_INPUT_LEVEL_RATIO:
            continue
        where = "one of the two" if against == "the other flight" else "this flight"
        raise DataError(
            f"its {what} {verb} a median of {values[worst]:.4g} in flight, {ratio[worst]:.3g} times that of {against} "
            f"({ref[worst]:.4g}; flights of one vehicle agree to within {MAX_INPUT_LEVEL_RATIO:g} times): the {what} "
            f"{be} logged in another unit in {where} ({guess}); convert to one unit before "
            f"{'using the model' if key in reference else 'fitting the flights together'}",
            path=paths[worst],
            column=columns.get(key, key),
        )


def warn_if_units_differ(flights, stacklevel: int = 3) -> None:
    """Warn (`DataWarning`) where the flights given together log their motors or battery in different units, by
    `check_input_levels` (every sample of each flight taken as flown: the usable runs `dynax.usable_segments`
    gives). A warning here, not the command line's refusal: a Python caller may have reasons of its own."""
    if isinstance(flights, Trajectory) or len(flights) < 2:
        return
    levels = {
        f"{flight.source or 'flight'} (flights[{i}])": input_levels(flight, np.ones(len(flight), bool))
        for i, flight in enumerate(flights)
    }
    try:
        check_input_levels(levels)
    except DataError as e:
        warnings.warn(str(e), DataWarning, stacklevel=stacklevel)


def load_flight(
    path: str | os.PathLike,
    *,
    mapping=None,
    scale=None,
    offset=None,
    checks: FlightChecks = FlightChecks(),
) -> tuple[Trajectory, FlightNotes]:
    """Load a quadrotor flight log: the contract's `quadrotor` columns, on a uniform grid, with notes.

    Reads the file (`load_trajectory(path, "quadrotor", ...)`, `.csv.gz` included; world velocities or body rates
    the file does not have are estimated from the positions or the attitude, `FlightNotes.estimated`), refuses a
    quaternion that is not of unit norm (tolerance 0.01, naming the row) and a motor or battery column that no
    flight logs (a motor zero, constant or another motor's copy throughout, a battery at 0 V or below, or one that
    is no voltage in flight), makes the quaternion's sign continuous, resamples a record with missed frames or
    uneven stamps onto its median interval, and says so in the notes (`FlightNotes.resampled`; states interpolated,
    inputs the interval's mean of the logged hold, `resample(..., inputs="average")`, whatever `input_resampling`
    says: a hold read at each grid point takes the previous command wherever a stamp falls a hair after its grid
    point; the samples inside a gap of more than `MAX_FLIGHT_GAP` intervals are noted as a `gap` and left out),
    normalises the quaternions, runs `inspect_flight`, and refuses columns that contradict each other
    (`dynax._data._flight_kinematics`).

    **Arguments:** `path`; `mapping`, `scale`, `offset` as for `load_trajectory`; `checks`.

    **Returns:** `(trajectory, notes)`.
    """
    path = str(path)
    # gaps are kept (and left out below), and the located checks are `inspect_flight`'s, said once as notes
    sampling = Sampling(3, max_gap=None)
    data, estimated = load_columns(
        path, "quadrotor", mapping=mapping, scale=scale, offset=offset, sampling=sampling, check=False
    )
    check_input_columns(data, path=path, columns=dict(mapping or {}), checks=checks)
    quats = np.asarray(data.xs[:, 3:7], dtype=float)
    norms = check_unit_quaternions(quats, path, mapping)
    xs = np.asarray(data.xs, dtype=float).copy()
    xs[:, 3:7] = _continuous_quaternions(quats / norms[:, None])
    data = Trajectory(
        data.ts, jnp.asarray(xs, data.xs.dtype), data.us, data.state_names, data.input_names, data.system, data.source
    )
    gaps, resampled = [], ""
    if not data.is_uniform:
        recorded = np.asarray(data.ts, dtype=float)
        resampled = resampling_note(recorded, data.dt)
        long = np.flatnonzero(np.rint(np.diff(recorded) / data.dt) > MAX_FLIGHT_GAP)  # whole intervals: jitter aside
        gaps = [(recorded[k], recorded[k + 1]) for k in long]
        data = resample(data, data.dt, inputs="average")  # each interval's mean of the logged hold
        q = np.asarray(data.xs[:, 3:7])
        data = Trajectory(
            data.ts,
            jnp.asarray(data.xs).at[:, 3:7].set(q / np.linalg.norm(q, axis=1, keepdims=True)),
            data.us,
            data.state_names,
            data.input_names,
            data.system,
            data.source,
        )
    values = {n: np.asarray(data.xs[:, i], dtype=float) for i, n in enumerate(data.state_names)}
    columns = dict(mapping or {})
    notes = _with_gaps(inspect_flight(data, checks), np.asarray(data.ts, dtype=float), gaps)
    notes = dataclasses.replace(notes, resampled=resampled, estimated=estimated_note(estimated))
    # The columns' agreement on the longest run with the motors running (glitches kept: a column in the
    # wrong unit is flagged as glitches throughout, and the check must see it to name it; the height is
    # not used, as a z axis pointing down is one of the faults).
    rel = np.asarray(data.ts, dtype=float) - float(data.ts[0])
    run = motors_running_run(data, checks)
    if run is not None:
        a, b = run
        flown = {n: v[a : b + 1] for n, v in values.items()}
        # the frame first: in another frame the rates disagree with the attitude too, and a scale is no fix
        motors = np.asarray(data.us[a : b + 1, :4], dtype=float)
        if "p" not in estimated:  # rates estimated from the attitude agree with it whatever its order or frame
            check_quaternion_order(rel[a : b + 1], flown, path=path, columns=columns)
            check_rate_frame(rel[a : b + 1], flown, motors, path=path, columns=columns, scale=scale)
        check_up_axis(rel[a : b + 1], flown, path=path, columns=columns)
        check_velocity_frame(rel[a : b + 1], flown, path=path, columns=columns)
        check_position_units(rel[a : b + 1], flown, motors, path=path, columns=columns, scale=scale)
        check_thrust_frame(rel[a : b + 1], flown, motors, path=path, columns=columns)
        check_flight_kinematics(rel[a : b + 1], flown, path=path, columns=columns, scale=scale)
    return data, notes
