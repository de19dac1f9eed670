r"""Where a joint rests: stretches in which its measured position stays still.

A joint rests where its position moves less than `speed` times the window over every window of
`min_duration` seconds in the stretch: the position's range, not its measured velocity, decides,
because a velocity at rest is mostly noise (on the DFKI rig's driver about 0.1 rad/s rms while the
encoder angle moves by 2 to 8 mrad in 0.75 s). The default `speed` 0.05 rad/s (or m/s) is slower
than any motion a light arm's swing or reversal makes over a quarter second.

A reversal passes through zero speed under a steady deceleration $a$ and stays within the range $\delta$
= `speed` $\cdot$ `min_duration` for $T_{rev} = 2\sqrt{2\delta/|a|}$: a heavy arm that turns slowly (0.4
rad/s$^2$) stays half a second, longer than `min_duration`, and a range test alone reads it as a rest.
So a stretch is a reversal, not a rest, where one parabola explains it: its residual within `EXPLAINED`
(2) times the position's white noise (from second differences), its acceleration `CURVATURE` (3)
standard errors from zero, its vertex inside the stretch, and the stretch lasting the $T_{rev}$ of that
acceleration to within a factor `SCATTER` (1.5) either way (a reversal fills the range; on noisy records
its stretch lasts 0.7 to 1.1 times $T_{rev}$, while a held joint's slight drift has a $T_{rev}$ far
longer than its rest). A joint at rest holds a flat position (a creep is a line) as long as it is held,
and an arm that settles into its rest leaves a curve no single parabola fits within the noise.

Rest matters to friction: a joint at rest under a net torque is held by its static friction
(`Stiction`), which a friction law of the speed alone cannot do.
"""

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._trajectory import Trajectory

EXPLAINED = 2.0  # a parabola explains a stretch whose residual is within this many times the white noise
CURVATURE = 3.0  # standard errors of the parabola's acceleration from zero: a deceleration, not noise
SCATTER = 1.5  # a reversal's stretch lasts its stay in the range to within this factor either way


@dataclasses.dataclass(frozen=True)
class Rest:
    """One stretch in which a joint rests.

    **Fields:** `record` (the record's source, or its index as text), `joint` (0-based), `coordinate`
    (its state name, e.g. `q2`), `start`, `stop` (rows, `stop` excluded), `start_s`, `stop_s` (times [s]).
    """

    record: str
    joint: int
    coordinate: str
    start: int
    stop: int
    start_s: float
    stop_s: float

    @property
    def duration(self) -> float:
        return self.stop_s - self.start_s


def rest_stretches(
    trajectory: Trajectory,
    positions: tuple[int, ...] | None = None,
    *,
    speed: float = 0.05,
    min_duration: float = 0.25,
    record: str = "",
) -> tuple[Rest, ...]:
    """The stretches of at least `min_duration` seconds in which a joint rests: still windows, no
    reversal (see the module).

    **Arguments:** `trajectory`; `positions`, the state columns of the joint positions (default: the
    columns named `q`, `q1`, `q2`, ...); `speed` [rad/s or m/s]; `min_duration` [s]; `record`, the label
    the stretches carry (default the trajectory's source).

    **Returns:** a tuple of `Rest`, by joint then time.
    """
    if not (speed > 0 and min_duration > 0):
        raise ValueError(f"rest_stretches: `speed` and `min_duration` must be positive, got {speed}, {min_duration}")
    ts = np.asarray(trajectory.ts, dtype=float)
    xs = np.asarray(trajectory.xs, dtype=float)
    names = trajectory.state_names
    if positions is None:
        positions = position_columns(names)
    label = record or trajectory.source
    out = []
    if len(ts) < 2:
        return ()
    dt = float(np.median(np.diff(ts)))
    width = max(int(round(min_duration / dt)), 2)
    if width > len(ts):
        return ()
    for joint, column in enumerate(positions):
        q = xs[:, column]
        still = _window_ranges(q, width) <= speed * min_duration
        # every sample of a still window rests: window i covers samples i .. i + width - 1
        covering = np.zeros(len(ts) + 1, int)
        covering[: len(still)] += still
        covering[width : width + len(still)] -= still
        resting = np.cumsum(covering[:-1]) > 0
        edges = np.flatnonzero(np.diff(np.concatenate([[0], resting.astype(int), [0]])))
        for start, stop in zip(edges[::2], edges[1::2]):
            if _reversal(ts[start:stop], q[start:stop], speed * min_duration):
                continue
            out.append(Rest(label, joint, names[column], int(start), int(stop), float(ts[start]), float(ts[stop - 1])))
    return tuple(out)


def _window_ranges(q: np.ndarray, width: int) -> np.ndarray:
    """The range (max - min) of `q` over each window of `width` samples, `(len(q) - width + 1,)`: running
    extrema (exact, as `np.ptp` of each window, in one pass)."""
    if not np.all(np.isfinite(q)):  # running extrema do not carry NaN as `np.ptp` does
        return np.ptp(np.lib.stride_tricks.sliding_window_view(q, width), axis=1)
    import scipy.ndimage

    # origin -(width // 2): the output at i is the window q[i : i + width]
    start = -(width // 2)
    top = scipy.ndimage.maximum_filter1d(q, width, origin=start)[: len(q) - width + 1]
    bottom = scipy.ndimage.minimum_filter1d(q, width, origin=start)[: len(q) - width + 1]
    return top - bottom


def _reversal(ts: np.ndarray, q: np.ndarray, band: float) -> bool:
    """Whether the positions `q` at times `ts` of a still stretch (range `band` over every window) are a
    reversal: one parabola explains them (see the module)."""
    t = ts - ts.mean()
    if len(t) < 8:
        return False
    coefficients, residual, *_ = np.polyfit(t, q, 2, full=True)
    dof = len(t) - 3
    rms = float(np.sqrt(residual[0] / dof)) if residual.size else 0.0
    acceleration = 2.0 * float(coefficients[0])
    p2 = t**2 - np.mean(t**2)
    std_error = 2.0 * rms / float(np.sqrt(np.sum(p2**2)))
    if not (acceleration != 0.0 and abs(acceleration) > CURVATURE * std_error):
        return False
    d2 = np.diff(q, 2)  # the white noise (two medians) only where the curvature has not already said no
    white = float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))
    if not rms <= EXPLAINED * white:
        return False
    vertex = -float(coefficients[1]) / (2.0 * float(coefficients[0]))
    stay = 2.0 * np.sqrt(2.0 * band / abs(acceleration))
    return bool(t[0] < vertex < t[-1] and stay / SCATTER <= ts[-1] - ts[0] <= SCATTER * stay)


ZERO_READINGS = 0.1  # share of exact zeros above which a speed is gated by its driver, not continuous noise


def speed_noise_at_rest(speeds: np.ndarray) -> float:
    r"""The noise of a measured speed, from its samples at rest (`speeds`, pooled over the rest stretches
    of one joint): the velocity noise a simulation that starts from a measured state at rest starts from.

    At rest the true speed is zero, so the samples are the noise. It is $1.4826\,\mathrm{median}|\dot q|$
    (the standard deviation of Gaussian noise, robust to the settling at a stretch's ends), unless more
    than `ZERO_READINGS` (10 %) of the samples read exactly zero: a driver that reports zero between
    encoder counts and a difference of counts otherwise (the DFKI rig's reads zero at 57 to 60 % of its
    samples at rest, the rest scattered to 0.24 rad/s), whose median magnitude is zero or biased low
    while its starting states are not. There the noise is the rms of the samples.

    **Returns:** the noise [rad/s or m/s]; 0 for no samples.
    """
    speeds = np.asarray(speeds, dtype=float).ravel()
    if speeds.size == 0:
        return 0.0
    if np.mean(speeds == 0.0) > ZERO_READINGS:
        return float(np.sqrt(np.mean(speeds**2)))
    return 1.4826 * float(np.median(np.abs(speeds)))


WITHIN_NOISE = 3.0  # a speed at rest within this many times its noise at rest is noise: the joint stands still


def speeds_zeroed_at_rest(records: list[Trajectory], rests=None) -> list[Trajectory]:
    r"""`records` with each joint's measured speed set to zero where the joint rests and the speed is noise
    (`resting_speeds`): the start states of simulation windows, corrected as measurements.

    A joint rests over the stretches of `rests` (each record's `rest_stretches`, found where `None`): its
    position moves less than 0.05 rad/s on average over every quarter second. There its true speed is zero
    and the measured one is the sensor's noise (on a driver that reads zero between encoder counts, some
    0.1 rad/s rms), and a simulation window that starts from it starts the joint moving, which no physical
    stick region of a friction law stops. The rule reads each record's own noise: $\sigma_j$, the noise of
    joint $j$'s measured speed over that record's rests (`speed_noise_at_rest`), and a sample of the rest
    whose speed is within `WITHIN_NOISE` (3) $\sigma_j$ of zero reads zero. A sample beyond it is kept as
    measured: at a rest's edges the joint is still arriving or already leaving (on DFKI run 12 the elbow
    arrives at 0.3 to 0.4 rad/s inside the stretch the positions call still). Where the noise is zero
    (a record whose speed at rest reads exactly zero) nothing changes.

    `identify` validates by it where the fitted model holds at rest (`Stiction`);
    `held_out_error(..., start_at_rest=True)` scores any model by it. The output-error refinement starts
    its windows from its own local fit of the positions, which at rest reads the encoder's counts (0.01
    to 0.04 rad/s rms on DFKI run 12); `refine_by_simulation(..., rests=...)` zeroes that by this rule, at
    the samples it picks on the measured record (opt-in: on DFKI it fitted the held-out runs worse in 5 of
    9 cells, `docs/devdocs/dfki_stiction.md`).
    """
    out = []
    for k, record in enumerate(records):
        stretches = rest_stretches(record) if rests is None else rests[k]
        if not stretches:
            out.append(record)
            continue
        xs = zeroed_at_rest(record.xs, record, stretches)
        xs = xs.astype(record.xs.dtype) if isinstance(record.xs, np.ndarray) else jnp.asarray(xs, record.xs.dtype)
        out.append(eqx.tree_at(lambda r: r.xs, record, xs))
    return out


def zeroed_at_rest(xs, record: Trajectory, stretches) -> np.ndarray:
    """A copy of the states `xs` (the record's own, or states estimated on its samples) with the joints' speeds
    zero where `resting_speeds` says the measured `record` rests within its noise."""
    xs, columns = np.array(xs), speed_columns(record)
    xs[:, columns] = np.where(resting_speeds(record, stretches), 0.0, xs[:, columns])
    return xs


def position_columns(names) -> tuple[int, ...]:
    """The state columns named `q`, `q1`, `q2`, ...: the joints' positions."""
    return tuple(i for i, n in enumerate(names) if n == "q" or (n.startswith("q") and n[1:].isdigit()))


def speed_columns(record: Trajectory) -> list[int]:
    """The state columns of the joints' speeds, joint by joint: `dq2` for `q2` where there is such a column, else
    the one as many columns after the positions as there are joints."""
    names = record.state_names
    positions = position_columns(names)
    return [
        names.index("d" + names[p]) if "d" + names[p] in names else len(positions) + j for j, p in enumerate(positions)
    ]


def resting_speeds(record: Trajectory, stretches) -> np.ndarray:
    """`(time, joints)`: where a joint of `record` rests (over `stretches`, its `rest_stretches`) and its measured
    speed is within `WITHIN_NOISE` times that record's noise at rest (`speeds_zeroed_at_rest`'s rule).
    Stretches are matched by time, not row: they may be read on the record resampled at its median interval."""
    ts, xs, columns = np.asarray(record.ts, dtype=float), np.asarray(record.xs), speed_columns(record)
    out = np.zeros((len(ts), len(columns)), bool)
    for joint in sorted({s.joint for s in stretches}):
        resting = np.zeros(len(ts), bool)
        for s in stretches:
            if s.joint == joint:
                resting |= (ts >= s.start_s) & (ts <= s.stop_s)
        speed = xs[:, columns[joint]]
        noise = speed_noise_at_rest(speed[resting])
        out[:, joint] = resting & (np.abs(speed) <= WITHIN_NOISE * noise)
    return out
