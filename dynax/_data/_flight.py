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
  [m] in one sample (a motion-capture marker swap or a lost frame).
"""

import dataclasses
import os

import jax.numpy as jnp
import numpy as np

from .._errors import DataError
from ._derivatives import resample
from ._flight_kinematics import check_flight_kinematics, check_thrust_frame
from ._io import load_trajectory, Sampling
from ._trajectory import Trajectory

#: The kinds of glitch `inspect_flight` flags (its `Glitch.kind`).
GLITCH_KINDS = ("rate_range", "input_range", "position_jump")

# A body-to-world quaternion further than this from unit norm is not an attitude measurement.
QUATERNION_TOLERANCE = 0.01


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

    **Fields:** `column` (the contract's name), `kind` (one of `GLITCH_KINDS`), `start`, `stop`
    (seconds from the record's first sample, first and last flagged sample), `row` (the first
    flagged sample's 1-based data row), `n_samples`, `worst` (the most extreme flagged value).
    """

    column: str
    kind: str
    start: float
    stop: float
    row: int
    n_samples: int
    worst: float

    def describe(self) -> str:
        span = (
            f"at t = {self.start:.2f} s" if self.n_samples == 1 else f"from t = {self.start:.2f} to {self.stop:.2f} s"
        )
        return f"{self.column}: {self.kind} {span} (row {self.row}, {self.n_samples} samples, worst {self.worst:.4g})"


@dataclasses.dataclass(frozen=True)
class FlightNotes:
    """What `inspect_flight` found in a record.

    **Fields:**

    - `ground`: `(start, stop)` seconds from the record's first sample of each ground segment.
    - `glitches`: the flagged runs (`Glitch`), in time order.
    - `usable`: per sample, `True` where the vehicle flies and nothing is flagged.
    - `source`: the file.
    """

    ground: tuple[tuple[float, float], ...]
    glitches: tuple[Glitch, ...]
    usable: np.ndarray
    source: str = ""

    def describe(self) -> list[str]:
        """One line per ground segment and glitch, for a note on the terminal or in a report."""
        lines = [f"ground segment from t = {a:.2f} to {b:.2f} s: left out" for a, b in self.ground]
        lines += [f"glitch in {g.describe()}: left out" for g in self.glitches]
        return lines


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """`(first, last)` indices of each run of `True`."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]


def _with_onsets(mask: np.ndarray, values: np.ndarray) -> np.ndarray:
    """`mask` with each run extended back over the monotonic climb that leads into it."""
    mask = mask.copy()
    magnitude = np.abs(values)
    for a, _ in _runs(mask):
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
    # spots differ: a pad, an uneven floor), else the record's lowest height.
    if off.any():
        rests = np.flatnonzero(off)
        after = np.clip(np.searchsorted(rests, np.arange(len(z))), 0, len(rests) - 1)
        before = np.clip(after - 1, 0, len(rests) - 1)
        nearest = np.where(
            np.abs(rests[before] - np.arange(len(z))) <= np.abs(rests[after] - np.arange(len(z))),
            rests[before],
            rests[after],
        )
        floor = z[nearest]
    else:
        floor = np.full_like(z, np.min(z))
    ground = off | (z < floor + checks.clearance)

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
    unexplained = np.linalg.norm(np.diff(position, axis=0) - 0.5 * (velocity[1:] + velocity[:-1]) * dt, axis=1)
    jump = np.concatenate([[False], unexplained > checks.max_jump])
    flagged.append(("x,y,z", "position_jump", jump, np.concatenate([[0.0], unexplained])))

    glitches, bad = [], np.zeros(len(ts), bool)
    for column, kind, mask, values in flagged:
        bad |= mask
        for a, b in _runs(mask):
            worst = values[a : b + 1][np.argmax(np.abs(values[a : b + 1]))]
            glitches.append(Glitch(column, kind, float(rel[a]), float(rel[b]), a + 1, b - a + 1, float(worst)))
    glitches.sort(key=lambda g: (g.start, g.column))
    segments = tuple((float(rel[a]), float(rel[b])) for a, b in _runs(ground))
    return FlightNotes(segments, tuple(glitches), ~ground & ~bad, trajectory.source)


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


def load_flight(
    path: str | os.PathLike,
    *,
    mapping=None,
    scale=None,
    offset=None,
    checks: FlightChecks = FlightChecks(),
) -> tuple[Trajectory, FlightNotes]:
    """Load a quadrotor flight log: the contract's `quadrotor` columns, on a uniform grid, with notes.

    Reads the file (`load_trajectory(path, "quadrotor", ...)`, `.csv.gz` included), refuses a
    quaternion that is not of unit norm (tolerance 0.01, naming the row), makes the quaternion's
    sign continuous, resamples a record with missed frames onto its median interval (states
    interpolated, inputs held), normalises the quaternions and runs `inspect_flight`.

    **Arguments:** `path`; `mapping`, `scale`, `offset` as for `load_trajectory`; `checks`.

    **Returns:** `(trajectory, notes)`.
    """
    path = str(path)
    data = load_trajectory(path, "quadrotor", mapping=mapping, scale=scale, offset=offset, sampling=Sampling(3))
    quats = np.asarray(data.xs[:, 3:7], dtype=float)
    norms = np.linalg.norm(quats, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1) > QUATERNION_TOLERANCE)
    if bad.size:
        k = int(bad[0])
        raise DataError(
            f"the quaternion (qw, qx, qy, qz) has norm {norms[k]:.6g}, not 1 (tolerance "
            f"{QUATERNION_TOLERANCE:g}; {bad.size} such rows): the contract's attitude is a unit "
            "quaternion",
            path=path,
            column=(mapping or {}).get("qw", "qw"),
            row=k + 1,
        )
    xs = np.asarray(data.xs, dtype=float).copy()
    xs[:, 3:7] = _continuous_quaternions(quats / norms[:, None])
    data = Trajectory(
        data.ts, jnp.asarray(xs, data.xs.dtype), data.us, data.state_names, data.input_names, data.system, data.source
    )
    if not data.is_uniform:
        data = resample(data, data.dt)
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
    notes = inspect_flight(data, checks)
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
        check_thrust_frame(rel[a : b + 1], flown, motors, path=path, columns=columns)
        check_flight_kinematics(rel[a : b + 1], flown, path=path, columns=columns, scale=scale)
    return data, notes
