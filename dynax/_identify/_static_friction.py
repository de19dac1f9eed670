r"""The static friction level read from the records: where a joint rests under load, and where it breaks away.

A friction law of the speed (viscous, Coulomb smoothed through zero) holds nothing at rest, so a
joint that stands still while the rigid-body model leaves a net torque at it,
$\tau_j - [M(q)\ddot q + h(q, \dot q)]_j$ (at rest mostly $\tau_j - g_j(q)$), shows a friction the
speed cannot explain: the static friction (`Stiction`). This module finds those stretches and reads
the level from them.

**Where a joint rests.** `rest_stretches`: its encoder position moves less than 0.05 rad/s times
any 0.25 s window of the stretch (the position decides; a velocity at rest is mostly noise), and the
stretch is no reversal (one parabola, a steady deceleration through zero speed, does not explain it).

**Under load.** Over each rest, where every joint of the arm rests with it (the longest such run),
the net torque the least-squares model leaves at the joint is computed from the measured torques and
positions at zero speed and acceleration: $\tau_j - g_j(q)$. Where another joint moves, the torque
its motion puts on the resting joint hangs on that joint's acceleration, which noisy records do
not give finely enough (on the test rig's records a swinging shoulder made an elbow that creeps under
its Coulomb level read as holding 1 N m), so such a rest is not read. Its noise $\sigma$
has two parts: the torque's white-noise scatter within the stretch (from successive differences,
which a slow trend does not enter) and the standard error of the model's torque at that state
(the least-squares covariance carried through the regressor row), and it is at least `FLOOR` (1 %) of
the joint's rms recorded torque: a torque sensor or a motor current resolves little finer, and on
noise-free simulated records a biased model (the records' offsets absorb a Stribeck curve the model
lacks) leaves a few 1e-4 N m at a rest that holds nothing. The rest is **under load** where
the net torque, averaged over `WINDOW_S` windows, reaches `LOADED` (3) times $\sigma$ somewhere in
the stretch: a held torque three times the scatter of a single sample, not of a mean.

**Held, not swinging.** Still to the range test is not at rest: a heavy, damped arm swings through
zero speed so slowly that a joint stays in the band for a second, and the torque read at zero speed
is then what accelerates it (on the stick-slip battery's record, a shoulder swinging with the stuck
elbow as one body reads 0.8 N m where it holds nothing). So each loaded stretch is checked against
the motion measured over it (`rest_motion`): the joint's equation of motion integrated twice, which
needs the positions, not their derivatives, gives the friction $F$ the joint supplies (the net torque
less the inertia and damping of the whole arm's measured motion), with its standard error, and the
torque the joint's own acceleration and speed carry. The rest stays under load only where $F$ is
`LOADED` standard errors from zero and larger than that own share: held, the friction carries the
torque and the joint does not accelerate; free, its motion carries it. Otherwise (`moves`) the
stretch gives no level, and the note says so with the three numbers. The level itself is still read
as below, at zero speed.

**The static level.** Which stretches are under load is decided as above; the level is read from them
again with the rest of the arm free (`needed_friction`): the friction the joint needs to stay put while
the joints not held by friction move as the model's equations say (Karnopp's constraint force, no
acceleration read off the positions), where the zero-speed reading takes what accelerates them for
friction. On the stick-slip battery's heavy arm, read with the truth's rigid body, the elbow drifting
inside the still band puts 0.2 N m on the resting shoulder, and the largest window mean at zero speed
and acceleration reads 0.93 for a level of 0.8 and 0.70 for a sticking Coulomb level of 0.5: above what
static friction can hold. A joint at rest holds every torque it is under, so the largest
held (`held`, the largest `WINDOW_S` mean over the arm-still run, the last window before the joint is
seen to leave left out) is a **lower bound** on $f_s$, not an estimate: the joint may hold much more
than it was asked to. Where the joint leaves its rest before the record's end, the **breakaway** is the
level at which the joint's own stick-slip under that load matches its positions
(`breakaway_from_positions`): that is $f_s$ itself, read where it slipped, not where the encoder first
sees it move ($3\sigma_q$ later, while the load goes on rising: 0.92 where the shoulder broke away at
0.80), and it finds a slip inside the still band too. It counts where the slip is significant in the
positions, the level three standard errors from zero, and the load rose through it by at most
`RESOLUTION` (5 %) per sample (a torque that jumps resolves nothing). With the truth's rigid body the
battery's two breakaways read 0.7995 (0.8) and 0.5023 (0.5). The **level** is then the median
breakaway at that joint (`kind = "breakaway"`); without one it is the largest held torque, reported as
a lower bound (`kind = "lower_bound"`). The reading is as good as the model's gravity and force
offsets: with the least-squares model, its gravity 4 to 9 % low on that arm, the same breakaways read 0.851
and 0.544 (the refit's rows at low speed left out, below).

**In the refinement.** The output-error refinement fits the level with the other parameters, but
never below the largest torque held nor below the joint's Coulomb level
(`dynax.internal.ConsistentParametrisation`). Both are hard bounds, not estimates: the joint held
that torque without moving, and static friction is at least the sliding friction it falls to. The
torque held is the force applied less the gravity at the rest (`Stiction.held_force`,
`held_position`), and the gravity is that of the rigid body being refined, not the least-squares
one: the rest reading is only as good as the model's gravity (on a heavy arm a least-squares
gravity a tenth low reads a joint that holds nothing as holding newton metres). Left
free, the refinement lowers the level wherever motion dominates its segments, because a level above
the Coulomb one makes the motion's reversals stick, which a rig's reversals mostly do not, while
nothing pulls it up: a level above the torque held changes no simulated rest, so the rest gives no
gradient. The level then ends where the reversals allow, below what the records show the joint
holding; bounded, it ends at the bound where the reversals push down, and above it only where the
data ask for more. Holding the level fixed at the reading instead would forbid the second, and a
breakaway, measured on one or a few events, is an estimate the refinement may correct down to the
largest torque held.

**The stick band and the start state.** Two things are kept apart. `Stiction`'s band of speeds
(`velocity_scale`) is the friction law's stick region: a physical property, kept at `Stiction`'s
default (the Coulomb friction's smoothing, 0.01 rad/s), so that a joint in motion passes through zero
speed at a reversal without being caught. The measured speed at rest is another matter: there the true
speed is zero and the record shows the sensor's noise (`dynax.internal.speed_noise_at_rest`, reported
as `speed_noise`), and a simulation window that starts from it starts the joint moving faster than any
narrow band holds. So where the model has `Stiction` the validation starts its windows by a rule
(`speeds_zeroed_at_rest`): over each rest stretch of a record, where a joint's measured speed is
within three times that record's own noise at rest, the window starts at zero speed; beyond it (the
joint arriving or leaving) from the measured speed. The start state is corrected as a measurement,
and the friction law is not widened to swallow the noise. The output-error refinement starts from its
own local fit of the positions instead of the measured speed (`motion_records`: on run 12's rests
0.01 to 0.04 rad/s rms, up to 0.14); the same rule there (`refine_by_simulation(..., rests=...)`)
is opt-in: on DFKI it fitted the held-out runs, which never rest, worse in 5 of 9 cells.

**The memory of rest.** A rest of a second is not a reversal's passage through zero speed: the static
level a contact holds grows with the time it has rested (rising static friction). On DFKI the level the
rest of run 12 shows cost the runs that never rest at their reversals, where it made the joint hold or
brake, which their records do not show. So `Stiction` is added with a dwell time (`dwell_time`,
`REST_DWELL_TIME` = 0.1 s: 92 % built over the shortest rest the search accepts, 0.25 s, a few % over a
reversal's few milliseconds in the band): its level builds while the joint is in the band and wears off
once it slides. A window that starts at rest starts with it built (`Extended.initial_state`), one that
starts in motion without it.

**The least-squares rows at rest.** No friction law of the speed explains a held torque (the
Coulomb column at rest is the sign of the velocity's noise), so where a rest is under load `identify`
fits `Dynamic` again with the rows of that joint over that rest at zero weight (`rest_row_weights`),
and reads the rests again with the second fit; the count is reported. A rest that holds nothing
(an arm hanging still) is an equation like any other and stays in; on records without rest under
load nothing changes. (The `Power` and `Energy` rows are not affected: at rest the friction does no work.)
The refit also leaves out each joint's rows at low speed (`slow_row_weights`): below `SLOW` (3) times
the Coulomb law's smoothing speed (0.03 rad/s for the default 0.01), the speed as the equations read it.
A joint that sticks or slides slowly there has a friction the smoothed law does not follow (sticking at
zero speed, the full level however slowly it slides), and the misfit, of one sign over a record, went
into that record's force offset and from it into the level: on the stick-slip battery's sticking elbow
the offsets the truth's own parameters need were +0.048 and -0.026 N m, +0.038 and -0.024 of them from
rows under 0.01 rad/s, and the breakaway read 0.562 for 0.5; without those rows 0.544 (0.875 to 0.851
for 0.8 at the shoulder). A Coulomb and viscous law does not describe friction at low speed (stiction,
the Stribeck curve, presliding: Armstrong-Hélouvry et al. 1994, sec. 2), so its rows there are not its
data.

??? cite

    B. Armstrong-Hélouvry, P. Dupont, C. Canudas de Wit, "A survey of models, analysis tools and
    compensation methods for the control of machines with friction", Automatica 30(7), 1994 (sec.
    2.1 and 4: breakaway force measured at the onset of motion under a slowly rising force).
"""

import contextlib
import contextvars
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from .._context import set_within
from .._data._derivatives import butterworth_filtfilt
from .._data._rest import Rest, rest_stretches, speed_noise_at_rest, WITHIN_NOISE
from .._data._trajectory import Trajectory
from .._model._extensions import CoulombFriction, Extended
from .._model._extensions._stiction import LEAST_STICK_BAND, REST_DWELL_TIME, Stiction
from .._model._extensions._terms import AbstractJointTerm
from ._equations import row_times, uniformly_sampled
from ._regressors import applied_force, dynamic_regressor, positions_and_velocities, split_terms

WINDOW_S = 0.05  # averaging window of the held torque: short against a ramp to breakaway, ten samples or more
LOADED = 3.0  # held torque over its single-sample noise that counts as load
FLOOR = 0.01  # the least noise of a torque: 1 % of the joint's rms recorded torque (a sensor's resolution)
RESOLUTION = 0.05  # a breakaway counts where the load rises by at most 5 % of it per sample (a slow rise)
SLOW = 3.0  # a row is slow below 3 widths of the Coulomb law's smoothing (tanh(3): within 0.5 % of its level)
SLOW_ROWS: contextvars.ContextVar[tuple[float | None, bool]] = contextvars.ContextVar(
    "dynax_slow_rows", default=(None, False)
)  # `slow_rows`: (band, first fit)


@contextlib.contextmanager
def slow_rows(band: float | None = None, *, first_fit: bool = False):
    """Within the block, the least-squares refit without the loaded rests leaves out each joint's rows whose speed
    (as the equations read it) is below `band` rad/s, whatever the joint's friction law, instead of below `SLOW`
    times its Coulomb law's smoothing (`band=None`: that rule); `band=0` leaves out no slow row (the refit as it
    was before the rule). `first_fit=True`: the first least-squares fit leaves out the same rows too. A what-if
    for taking apart where the fitted force offsets and the static level come from."""
    with set_within(SLOW_ROWS, (band, first_fit)):
        yield


@dataclasses.dataclass(frozen=True)
class RestUnderLoad:
    """One stretch in which a joint rests, and the net torque it holds there.

    **Fields:** `record`, `joint` (0-based), `coordinate` (`q1`, ...), `start_s`, `stop_s` [s];
    `held`, the largest window-averaged net torque held (signed) [N m or N], for a loaded stretch the
    friction needed with the rest of the arm free (`needed_friction`); `mean`, the mean net torque over
    the stretch; `noise`, its single-sample noise $\\sigma$; `loaded`, whether `|held|`
    reaches `LOADED` times `noise`; `breakaway`, the level at which the joint slipped under a slowly
    rising load (signed, `breakaway_from_positions`), or `None` (the record ends at rest, or no slip is
    resolved); `speed_noise`, the joint's measured-speed noise at rest over all of its rests in the
    records (`speed_noise_at_rest`);
    `held_force`, `held_position`, the generalised force applied and the joint positions over the window
    where the most was held (its mean): the rest the refinement bounds the level by; `friction`,
    `friction_noise`, the friction the joint supplies over the stretch less what the measured motion
    of the arm explains, and its standard error; `motion`, the net torque its own motion accounts for
    (`rest_motion`); `moves`, whether that motion, not friction, carries the torque (the stretch is
    then not under load)."""

    record: str
    joint: int
    coordinate: str
    start_s: float
    stop_s: float
    held: float
    mean: float
    noise: float
    loaded: bool
    breakaway: float | None
    speed_noise: float = 0.0
    held_force: float = 0.0
    held_position: tuple[float, ...] | None = None
    friction: float = 0.0
    friction_noise: float = 0.0
    motion: float = 0.0
    moves: bool = False

    @property
    def duration(self) -> float:
        return self.stop_s - self.start_s

    def to_json(self) -> dict:
        return {**dataclasses.asdict(self), "duration_s": self.duration}


@dataclasses.dataclass(frozen=True)
class JointStaticFriction:
    """The static friction level found at one joint.

    **Fields:** `joint`, `coordinate`; `level`, the level the model's `Stiction` starts from (the
    least-squares stage's); `kind`, `"breakaway"` (the median torque at which the joint broke away) or
    `"lower_bound"` (no breakaway in the records: the largest torque held, which the true level is at
    least); `lower_bound`, the largest torque held at rest; `breakaways`, the torques at each breakaway
    (magnitudes); `records`, the records it rests in under load; `rest_s`, the seconds of rest under
    load; `velocity_scale`, the band of speeds its `Stiction` sticks in (the friction law's stick
    region, `Stiction`'s default: the Coulomb friction's smoothing); `speed_noise`, the measured speed's
    noise at rest (the noise a window that starts at rest starts from, which the refinement takes off by
    starting such windows at zero speed, not by widening the band); `held_force`, `held_position`, the
    rest where the most was held (as `RestUnderLoad`'s), which the output-error refinement keeps the
    level above under the rigid body it fits, with the Coulomb level; `refined`, the level after that
    refinement, or `None` where it did not run."""

    joint: int
    coordinate: str
    level: float
    kind: str
    lower_bound: float
    breakaways: tuple[float, ...]
    records: tuple[str, ...]
    rest_s: float
    velocity_scale: float = LEAST_STICK_BAND
    held_force: float = 0.0
    held_position: tuple[float, ...] | None = None
    refined: float | None = None
    speed_noise: float = 0.0

    @property
    def name(self) -> str:
        return f"fs{self.joint + 1}"

    def to_json(self) -> dict:
        return {**dataclasses.asdict(self), "name": self.name}


@dataclasses.dataclass(frozen=True)
class StaticFriction:
    """What `identify` found of friction at rest: the rests, which of them are under load, the
    static level of each joint that rests under load, and the least-squares rows left out.

    **Fields:** `stretches` (every `RestUnderLoad`, loaded or not); `joints` (a `JointStaticFriction`
    per joint the model got a `Stiction` at; empty where none); `rows_left_out`, the dynamic
    least-squares rows given zero weight because their joint rests (or, in the refit, moves at low
    speed: `slow_row_weights`), and `rows`, all of them; `note`,
    one sentence of what was done and why."""

    stretches: tuple[RestUnderLoad, ...]
    joints: tuple[JointStaticFriction, ...]
    rows_left_out: int
    rows: int
    note: str

    @property
    def rest_s(self) -> float:
        """Seconds of rest over every joint and record."""
        return float(sum(s.duration for s in self.stretches))

    def to_json(self) -> dict:
        return {
            "joints": [j.to_json() for j in self.joints],
            "stretches": [s.to_json() for s in self.stretches],
            "rest_s": self.rest_s,
            "least_squares_rows_left_out": self.rows_left_out,
            "least_squares_rows": self.rows,
            "note": self.note,
        }


def record_rests(records: list[Trajectory]) -> list[tuple[Rest, ...]]:
    """Each record's rest stretches (`rest_stretches` of the record at its median interval)."""
    return [rest_stretches(uniformly_sampled(r), record=f"record {i}") for i, r in enumerate(records)]


def rest_row_weights(records, settings, counts, rests, n_joints: int) -> np.ndarray | None:
    """`Dynamic`'s row weights (stacked joint by joint, each through every record) that leave out a joint's
    rows while it rests: 0 there, 1 elsewhere; `None` where no row rests.

    Each row's time is `row_times`'."""
    blocks = []
    times = row_times(records, settings, counts)
    for joint in range(n_joints):
        for t, count, stretches in zip(times, counts, rests):
            keep = np.ones(count)
            for s in stretches:
                if s.joint == joint:
                    keep[(t >= s.start_s) & (t <= s.stop_s)] = 0.0
            blocks.append(keep)
    keep = np.concatenate(blocks)
    return None if keep.all() else keep


def slow_row_weights(keep, system, records, settings, counts, n_joints: int) -> np.ndarray | None:
    """`keep` (`rest_row_weights`'s, or `None`) with each joint's rows at low speed also at 0: where its speed,
    as the equations read it (the record filtered by its `settings`), is below `SLOW` times the smoothing
    speed $v_s$ of its Coulomb law (`CoulombFriction.velocity_scale`): there the smoothed sign is short of the
    level by more than 0.5 %, where a joint that sticks or slides slowly has a friction it does not follow.
    A joint without Coulomb friction keeps its rows. `None` where every row is kept."""
    _, terms = split_terms(system)
    smoothing = {t.joint: float(t.velocity_scale) for t in terms if isinstance(t, CoulombFriction)}
    keep = np.ones(n_joints * sum(counts)) if keep is None else np.array(keep, dtype=float)
    offset = np.concatenate([[0], np.cumsum(counts)])
    chosen = SLOW_ROWS.get()[0]
    for r, (record, setting, count) in enumerate(zip(records, settings, counts)):
        xs = np.asarray(record.xs)
        if setting.get("lowpass_hz") is not None:
            record = uniformly_sampled(record)
            xs = np.asarray(
                butterworth_filtfilt(
                    record.ts, record.xs, cutoff_hz=setting["lowpass_hz"], order=setting["lowpass_order"]
                )
            )
        samples = np.minimum(setting["trim"] + np.arange(count) * setting["decimate"], len(xs) - 1)
        speeds = np.asarray(positions_and_velocities(system, jnp.asarray(xs))[1])[samples]
        for joint in range(n_joints):
            band = SLOW * smoothing.get(joint, 0.0) if chosen is None else chosen
            rows = joint * sum(counts) + offset[r] + np.arange(count)
            keep[rows[np.abs(speeds[:, joint]) < band]] = 0.0
    return None if keep.all() else keep


def _friction_columns(system, names, joint):
    """The columns of friction terms at `joint` (their law of the speed is what rest contradicts)."""
    base, terms = split_terms(system)
    own = {
        t.parameter_name(base) for t in terms if isinstance(t, AbstractJointTerm) and t.friction and t.joint == joint
    }
    return [i for i, n in enumerate(names) if n in own]


def _white_noise(x: np.ndarray, order: int = 1) -> float:
    """The white-noise standard deviation of `x` from its `order`-th differences (median absolute, Gaussian)."""
    d = np.diff(x, n=order)
    if d.size == 0:
        return 0.0
    scale = np.sqrt({1: 2.0, 2: 6.0}[order])
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / scale)


def _window_means(x: np.ndarray, width: int) -> np.ndarray:
    if len(x) < width:
        return np.asarray([x.mean()])
    return np.convolve(x, np.ones(width) / width, mode="valid")


def held_torques(system, names, estimate, covariance, record: Trajectory, force: np.ndarray, rows: np.ndarray):
    """The net torque the rigid-body model (`system` without its friction at each joint) leaves at each
    joint at the samples `rows` of `record` (uniformly sampled), where every joint of the arm rests
    (zero speed and acceleration), from the generalised `force` applied, `(time, joints)`; and its
    standard error from the estimate's `covariance`; both `(rows, joints)`."""
    base, _ = split_terms(system)
    n = len(base.joints)
    # At rest the state is the positions alone: the regressor of the whole record at zero speed and
    # acceleration (one compiled shape per record length), read at `rows`.
    xs = np.array(record.xs, dtype=float)
    xs[:, n:] = 0.0
    dtype = record.xs.dtype
    regressor = dynamic_regressor(system, jnp.asarray(xs, dtype), jax.device_put(np.zeros((len(xs), n), dtype)))
    regressor = np.asarray(regressor, dtype=float)
    estimate = np.asarray(estimate, dtype=float)
    net = np.empty((len(rows), n))
    std = np.zeros((len(rows), n))
    cov = None if covariance is None else np.nan_to_num(np.asarray(covariance, dtype=float))
    for j in range(n):
        y = regressor[:, j, :].copy()
        y[:, _friction_columns(system, names, j)] = 0.0
        # the product over the whole record, then read: a matrix-vector product's rounding depends on
        # how many rows it is given
        net[:, j] = (force[:, j] - y @ estimate)[rows]
        if cov is not None:
            y = y[rows]
            std[:, j] = np.sqrt(np.maximum(np.einsum("tp,pq,tq->t", y, cov, y), 0.0))
    return net, std


def _arm_matrices(system, names, estimate, q: np.ndarray, dtype):
    """The mass matrix $M(q)$ and the damping $D = \\partial h / \\partial \\dot q$ at zero speed of the
    model (`estimate`) at the positions `q`, each row `j` without the friction terms at joint `j` (as
    `held_torques`): from the regressor at unit accelerations and at speeds $\\pm\\varepsilon$."""
    n = len(q)
    eps = 1e-3  # the central difference cancels the Coriolis terms (even in a speed) exactly; float32 resolves it
    xs = np.zeros((1 + 3 * n, 2 * n))
    xs[:, :n] = q
    ddq = np.zeros((1 + 3 * n, n))
    for k in range(n):
        ddq[1 + k, k] = 1.0
        xs[1 + n + k, n + k] = eps
        xs[1 + 2 * n + k, n + k] = -eps
    y = np.asarray(dynamic_regressor(system, jnp.asarray(xs, dtype), jnp.asarray(ddq, dtype)), dtype=float)
    mass, damping = np.empty((n, n)), np.empty((n, n))
    for j in range(n):
        theta = np.asarray(estimate, dtype=float).copy()
        theta[_friction_columns(system, names, j)] = 0.0
        row = y[:, j, :] @ theta
        mass[j] = row[1 : 1 + n] - row[0]
        damping[j] = (row[1 + n : 1 + 2 * n] - row[1 + 2 * n :]) / (2 * eps)
    return mass, damping


def rest_motion(ts: np.ndarray, qs: np.ndarray, net: np.ndarray, mass: np.ndarray, damping: np.ndarray, joint: int):
    r"""`(friction, noise, motion)`: the friction joint `joint` supplies over a stretch where the arm
    is still, less what the measured motion explains, its standard error, and the net torque the
    joint's own motion accounts for.

    The joint's equation of motion, $\text{net}_j(t) = \sum_k M_{jk}\ddot q_k + D_{jk}\dot q_k + f_j(t)$
    ($\text{net}$ the torque the model leaves at zero speed and acceleration), integrated twice from
    the stretch's start, needs no derivative of the positions:
    $\iint \text{net}_j = \sum_k M_{jk}(q_k - q_k(0)) + D_{jk}\int (q_k - q_k(0)) + \iint f_j$ up to
    a line in time (the start speeds). With $f_j = F + G(t - \bar t)$ the residual is fitted by
    $c_0 + c_1 t + F t^2/2 + G(t^3/6 - \bar t t^2/2)$; $F$ is the friction at the middle of the
    stretch, its standard error from the fit's residual. `motion` is the same coefficient of the
    joint's own term $M_{jj}(q_j - q_j(0)) + D_{jj}\int (q_j - q_j(0))$: the torque its own
    acceleration and speed carry. A joint at rest has $F \approx \text{net}_j$ and no motion; a slow
    swing through zero speed (a reversal of a heavy, damped arm) has its motion carrying the torque
    and $F$ near zero."""
    t = ts - ts[0]
    if len(t) < 5:  # too short to tell a rest from a swing: no friction shown
        return 0.0, 0.0, 0.0
    dt = np.diff(t)

    def integral(x):
        return np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * dt)])

    moved = qs - qs[0]
    swept = np.stack([integral(moved[:, k]) for k in range(qs.shape[1])], 1)
    own = mass[joint, joint] * moved[:, joint] + damping[joint, joint] * swept[:, joint]
    residual = integral(integral(net)) - moved @ mass[joint] - swept @ damping[joint]
    mid = 0.5 * t[-1]
    design = np.stack([np.ones_like(t), t, t**2 / 2, t**3 / 6 - mid * t**2 / 2], 1)
    coefficients, *_ = np.linalg.lstsq(design, np.stack([residual, own], 1), rcond=None)
    fitted = design @ coefficients[:, 0]
    scatter = np.sqrt(np.sum((residual - fitted) ** 2) / max(len(t) - design.shape[1], 1))
    covariance = np.linalg.pinv(design.T @ design)
    return float(coefficients[2, 0]), float(scatter * np.sqrt(covariance[2, 2])), float(coefficients[2, 1])


def _longest_run(mask: np.ndarray, start: int, stop: int) -> tuple[int, int]:
    """The longest run `[a, b)` of `True` in `mask[start:stop]` (the last of equal ones), `(start, start)` if none."""
    best = (start, start)
    a = None
    for i in range(start, stop + 1):
        inside = i < stop and bool(mask[i])
        if inside and a is None:
            a = i
        elif not inside and a is not None:
            if i - a >= best[1] - best[0]:
                best = (a, i)
            a = None
    return best


def _leaves(q: np.ndarray, a: int, b: int, n: int) -> int:
    r"""Where a joint that rests over rows `[a, b)` of its positions `q` leaves its rest: the first row from
    the stretch's middle on whose position is more than $3\sigma_q$ (at least 1e-6) from the median of
    the stretch's first half; `b` for a stretch that lasts to the record's end (`n` rows), or that
    never departs so far (the rest criterion lets a resting joint creep a little)."""
    if b >= n:
        return b
    half = max((b - a) // 2, 1)
    q_rest = float(np.median(q[a : a + half]))
    tol = max(3.0 * _white_noise(q[a : a + half], 2), 1e-6)
    away = np.flatnonzero(np.abs(q[a + half : b] - q_rest) > tol)
    return a + half + int(away[0]) if away.size else b


def rests_under_load(system, names, estimate, covariance, records, rests, labels) -> tuple[RestUnderLoad, ...]:
    """Each rest stretch with the net torque it holds (see the module)."""
    out = []
    record_forces = [applied_force(system, r.us) for r in records]
    floor = FLOOR * np.sqrt(np.mean(np.concatenate(record_forces) ** 2, axis=0))  # per joint
    n_joints = len(split_terms(system)[0].joints)
    # each record at its median interval, and where each of its joints leaves each rest
    sampled = [uniformly_sampled(r) if stretches else r for r, stretches in zip(records, rests)]
    xss = [np.asarray(r.xs, dtype=float) for r in sampled]
    leaves = [[_leaves(xs[:, s.joint], s.start, s.stop, len(xs)) for s in st] for xs, st in zip(xss, rests)]
    noise_at_rest = _speed_noise(n_joints, xss, rests, leaves)
    for original, record, xs, stretches, ends, label, forces_of in zip(
        records, sampled, xss, rests, leaves, labels, record_forces
    ):
        if not stretches:
            continue
        ts = np.asarray(record.ts, dtype=float)
        qs = xs[:, :n_joints]
        still = np.zeros((len(ts), n_joints), bool)
        for s, end in zip(stretches, ends):
            still[s.start : end, s.joint] = True
        arm_still = np.asarray(still.all(axis=1))
        runs = [_longest_run(arm_still, s.start, end) for s, end in zip(stretches, ends)]
        width = max(int(round(WINDOW_S / record.dt)), 1)
        # the torque is read only where the whole arm rests for a window or more
        read = np.zeros(len(ts), bool)
        for a, b in runs:
            if b - a >= width:
                read[a:b] = True
        rows = np.flatnonzero(read)
        if record is not original:  # resampled
            forces_of = applied_force(system, record.us)
        net, std = np.zeros((len(ts), n_joints)), np.zeros((len(ts), n_joints))
        if rows.size:
            net[rows], std[rows] = held_torques(system, names, estimate, covariance, record, forces_of, rows)
        found = []
        for s, (a, b) in zip(stretches, runs):
            j = s.joint
            if b - a < width:  # the other joints move throughout: the coupling is not read at rest
                found.append(
                    RestUnderLoad(
                        label, j, s.coordinate, s.start_s, s.stop_s, 0.0, 0.0, 0.0, False, None, noise_at_rest[j]
                    )
                )
                continue
            torque = net[a:b, j]
            noise = max(float(np.hypot(_white_noise(torque), np.median(std[a:b, j]))), float(floor[j]))
            means = _window_means(torque, width)
            k = int(np.argmax(np.abs(means)))
            held = float(means[k])
            window = slice(a + k, a + k + min(width, b - a))
            held_force = float(np.mean(forces_of[window, j]))
            held_position = tuple(float(v) for v in np.mean(qs[window], axis=0))
            mass, damping = _arm_matrices(system, names, estimate, np.mean(qs[a:b], axis=0), record.xs.dtype)
            friction, friction_noise, motion = rest_motion(ts[a:b], qs[a:b], torque, mass, damping, j)
            # held: the friction carries the torque, significantly, and more of it than the joint's own
            # acceleration and speed do; else the joint moves under the torque, or the stretch cannot tell
            moves = not (abs(friction) >= LOADED * friction_noise and abs(friction) > abs(motion))
            loaded = bool(abs(held) >= LOADED * noise and abs(held) > 0.0)
            moves, loaded = loaded and moves, loaded and not moves
            breakaway = None  # a loaded stretch's level is read again with the arm free, below
            found.append(
                RestUnderLoad(
                    label,
                    j,
                    s.coordinate,
                    s.start_s,
                    s.stop_s,
                    held,
                    float(torque.mean()),
                    noise,
                    loaded,
                    breakaway,
                    noise_at_rest[j],
                    held_force,
                    held_position,
                    friction,
                    friction_noise,
                    motion,
                    moves,
                )
            )
        out += _levels_with_the_arm_free(system, names, estimate, record, forces_of, stretches, ends, runs, found)
    return tuple(out)


def _levels_with_the_arm_free(system, names, estimate, record, force, stretches, ends, runs, found):
    """`found` (one `RestUnderLoad` per stretch of `stretches`) with the level of each loaded stretch read again
    from the friction the joint needs to stay put while the joints not held move as the model says
    (`needed_friction`): `breakaway`, where the joint leaves its rest before the record's end, the level at
    which it slipped (`breakaway_from_positions`, over the whole rest to where it is seen to leave, `ends`);
    `held`, the largest window mean of that friction over the arm-still run (`runs`) before it slipped. Where
    another joint moves, its friction law at a measured speed near zero (noise, on a driver that reads zero
    between counts) sets the load, so the largest held is read only where the whole arm is still (on run 12
    of the DFKI records 0.21 N m at q1 over the 0.13 s before the elbow rests, against 0.080 where both
    rest). Which stretches are under load, and the torque the refinement bounds the level by (`held_force`,
    at the arm-still window), are as read at zero speed (see the module)."""
    loaded = [(s, end) for s, end, f in zip(stretches, ends, found) if f.loaded]
    if not loaded:
        return found
    n = len(split_terms(system)[0].joints)
    held_by_friction = np.zeros((len(record.ts), n), bool)
    for s, end in loaded:  # to the sample it is first seen to have left, which the breakaway's fit reads
        held_by_friction[s.start : end + 1, s.joint] = True
    still = np.zeros((len(record.ts), n), bool)
    for s, end in zip(stretches, ends):
        still[s.start : end, s.joint] = True
    needed, inertia = needed_friction(system, names, estimate, record, force, still, held_by_friction)
    ts = np.asarray(record.ts, dtype=float)
    qs = np.asarray(record.xs, dtype=float)[:, :n]
    width = max(int(round(WINDOW_S / record.dt)), 1)
    out = list(found)
    for i, f in enumerate(found):
        if not f.loaded:
            continue
        (s, end, (a, b)), j = (stretches[i], ends[i], runs[i]), stretches[i].joint
        # the encoder sees a joint leave some samples after it did (3 sigma_q of creep; under a torque that
        # jumps, some 0.05 s): the last window before the departure is not read as held
        stuck = b if end >= s.stop else min(b, max(end - width, a + 1))
        breakaway = None
        if end < s.stop:  # it left its rest before the record's end
            half = max((end - s.start) // 2, 1)
            sigma_q = max(_white_noise(qs[s.start : s.start + half, j], 2), 1e-6)
            rows = slice(s.start, end + 1)  # to the sample it is first seen to have left
            fitted = breakaway_from_positions(ts[rows], qs[rows, j], needed[rows, j], inertia[rows, j], sigma_q)
            if fitted is not None and np.sign(fitted[0]) == np.sign(f.held):
                breakaway, stuck = fitted[0], min(stuck, max(s.start + fitted[2], a + 1))
        means = _window_means(needed[a:stuck, j], width)
        held = float(means[int(np.argmax(np.abs(means)))])
        out[i] = dataclasses.replace(f, held=held, breakaway=breakaway)
    return out


def needed_friction(system, names, estimate, record: Trajectory, force, still, held) -> tuple[np.ndarray, np.ndarray]:
    r"""`(friction, inertia)`, each `(time, joints)`: at each sample, the friction each joint needs to stay at
    rest (Karnopp's constraint force) while the joints not `held` move as the model says, from the generalised
    `force` applied; and the inertia that the excess of its load over its friction accelerates it through.

    With the arm's equations $M\ddot q = b - f$ ($b = \tau - h(q, \dot q)$ without the joint's own friction
    law), joint $j$ held ($\ddot q_j = 0$) and the free joints $F$ obeying theirs with their friction law of the
    speed, $\ddot q_F = M_{FF}^{-1} b_F$ and $f_j = b_j - M_{jF} M_{FF}^{-1} b_F$: no acceleration is read off
    the positions (a noisy encoder does not resolve it; on the stick-slip battery's heavy arm the acceleration
    of an elbow that drifts inside the still band put 0.2 N m on the resting shoulder), the free joints' is the
    one their torques give. Where the joint does move, $(M_{jj} - M_{jF} M_{FF}^{-1} M_{Fj})\,\ddot q_j = f_j -
    \text{friction}$: that Schur complement is `inertia`. The speeds are the measured ones, zero where a joint
    is `still` (there the measured speed is noise); a joint `held` by its own friction is held in the others'
    equations too."""
    base, _ = split_terms(system)
    n = len(base.joints)
    xs = np.array(record.xs, dtype=float)
    xs[:, n:] = np.where(still, 0.0, xs[:, n:])
    dtype = record.xs.dtype
    estimate = np.asarray(estimate, dtype=float)
    rows = [
        np.asarray(dynamic_regressor(system, jnp.asarray(xs, dtype), jnp.asarray(ddq, dtype)), dtype=float)
        for ddq in [np.zeros((len(xs), n))] + [np.tile(np.eye(n)[k], (len(xs), 1)) for k in range(n)]
    ]
    h = rows[0] @ estimate  # (time, joints): every joint's friction law in its own row
    mass = np.stack([r @ estimate - h for r in rows[1:]], -1)  # (time, row, column)
    friction, inertia = np.zeros((len(xs), n)), np.zeros((len(xs), n))
    for j in range(n):
        theta = estimate.copy()
        theta[_friction_columns(system, names, j)] = 0.0
        b = force - h
        b[:, j] = force[:, j] - rows[0][:, j, :] @ theta
        for t in np.flatnonzero(held[:, j]):
            free = [k for k in range(n) if k != j and not held[t, k]]
            gain = np.linalg.solve(mass[t][np.ix_(free, free)], mass[t, free, j]) if free else np.zeros(0)
            friction[t, j] = b[t, j] - gain @ b[t, free]
            inertia[t, j] = mass[t, j, j] - gain @ mass[t, free, j]
    return friction, inertia


def breakaway_from_positions(ts, q, load, inertia, sigma_q) -> tuple[float, float, int] | None:
    r"""`(level, standard error, row)`: the static level at which a joint that rests over `ts` slipped, and the
    first row where it did; `None` where its positions show no slip, or do not resolve the level.

    Karnopp's stick, run on the joint alone under the `load` it is under (`needed_friction`): it sticks while
    $|f_j| \le f_s$; once the load exceeds the level the excess accelerates it through its `inertia` $m$,
    against a friction of $f_s$ (the top of the Stribeck curve, where a creep stays), until its speed crosses
    zero under a load it holds. $f_s$ is the value whose simulated positions match the measured ones (least
    squares over a grid, then a finer one, the rest position fitted); its standard error is the position noise
    `sigma_q` over the norm of $\partial q / \partial f_s$ there. The encoder shows a slip only once the joint
    has crept some $3\sigma_q$, and the load goes on rising meanwhile: the largest load before that reads the
    rise as level (on the stick-slip battery's shoulder 0.92 N m where it broke away at 0.80; a sticking
    Coulomb elbow that slipped 1.4 mrad inside its still band read 0.67 for 0.5). A slip counts where the fit
    leaves less than the standstill's misfit by more than the positions' noise explains (a drop of
    $9\sigma_q^2$ in the sum of squares, three standard errors of one parameter), the level is `LOADED`
    standard errors from zero, and the load rises by at most `RESOLUTION` of the level per sample where the
    joint first slips (a torque that jumps past the level resolves nothing)."""
    if len(ts) < 5 or not np.all(inertia > 0.0):  # a mass matrix that is not positive moves nothing physically
        return None
    dt = np.diff(ts, prepend=ts[0])
    top = float(np.max(np.abs(load)))
    if top <= 0.0:
        return None

    def simulated(levels):
        """Positions at each level, and the row where the slip began that first moves the joint by `sigma_q`."""
        x, v = np.zeros_like(levels), np.zeros_like(levels)
        stuck = np.ones(levels.shape, bool)
        began, first = np.zeros(levels.shape, int), np.full(levels.shape, -1)
        out = np.zeros((len(ts), len(levels)))
        for k in range(len(ts)):
            f, m = load[k], inertia[k]
            breaks = stuck & (abs(f) > levels)
            began = np.where(breaks, k, began)
            stuck = stuck & ~breaks
            direction = np.where(v != 0.0, np.sign(v), np.sign(f))
            w = np.where(stuck, 0.0, v + dt[k] * (f - levels * direction) / m)
            sticks = ~stuck & (np.sign(w) != direction) & (abs(f) <= levels)
            stuck = stuck | sticks
            v = np.where(stuck, 0.0, w)
            x = x + dt[k] * v
            first = np.where((first < 0) & (abs(x) > sigma_q), began, first)
            out[k] = x
        return out, first

    def misfits(levels):
        xs, first = simulated(levels)
        r = q[:, None] - xs
        return np.sum((r - r.mean(axis=0)) ** 2, axis=0), xs, first

    grid = np.linspace(0.0, top, 201)
    sse, _, _ = misfits(grid)
    k = int(np.argmin(sse))
    fine = np.linspace(grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)], 41)
    fine_sse, xs, first = misfits(fine)
    best = int(np.argmin(fine_sse))
    level, row = float(fine[best]), int(first[best])
    standstill = float(np.sum((q - q.mean()) ** 2))
    if row < 1 or standstill - fine_sse[best] < 9.0 * sigma_q**2:
        return None
    step = top / 200
    around, _ = simulated(np.asarray([level - step, level + step]))
    sensitivity = (around[:, 1] - around[:, 0]) / (2 * step)
    error = sigma_q / max(float(np.linalg.norm(sensitivity - sensitivity.mean())), 1e-300)
    rise = abs(load[row] - load[row - 1])
    if level < LOADED * error or rise > RESOLUTION * level:
        return None
    return float(np.sign(load[row]) * level), error, row


def _speed_noise(n: int, xss, rests, leaves) -> list[float]:
    """Per joint (of `n`), the noise of its measured speed over all of its rests in the records' states `xss`
    (`speed_noise_at_rest`), each up to where the joint leaves it (`leaves`, `_leaves`: the motion after is not
    noise)."""
    pooled = [[] for _ in range(n)]
    for xs, stretches, ends in zip(xss, rests, leaves):
        for s, end in zip(stretches, ends):
            pooled[s.joint].append(xs[s.start : end, n + s.joint])
    return [speed_noise_at_rest(np.concatenate(p)) if p else 0.0 for p in pooled]


def joint_levels(stretches: tuple[RestUnderLoad, ...]) -> tuple[JointStaticFriction, ...]:
    """The static level of each joint that rests under load (see the module)."""
    out = []
    for j in sorted({s.joint for s in stretches if s.loaded}):
        mine = [s for s in stretches if s.joint == j and s.loaded]
        most = max(mine, key=lambda s: abs(s.held))
        lower = abs(most.held)
        breaks = tuple(abs(s.breakaway) for s in mine if s.breakaway is not None)
        level, kind = (float(np.median(breaks)), "breakaway") if breaks else (lower, "lower_bound")
        out.append(
            JointStaticFriction(
                j,
                mine[0].coordinate,
                level,
                kind,
                lower,
                breaks,
                tuple(dict.fromkeys(s.record for s in mine)),
                float(sum(s.duration for s in mine)),
                LEAST_STICK_BAND,
                most.held_force,
                most.held_position,
                speed_noise=mine[0].speed_noise,
            )
        )
    return tuple(out)


def with_stiction(system, joints: tuple[JointStaticFriction, ...]):
    """`system` extended with `Stiction` at each joint at its level (replacing one it has there)."""
    if not joints:
        return system
    base, terms = split_terms(system)
    at = {j.joint for j in joints}
    dtype = jnp.result_type(*[t.coefficient for t in terms], float) if terms else float
    kept = [t for t in terms if not (isinstance(t, Stiction) and t.joint in at)]
    added = [
        Stiction(
            j.joint,
            jnp.asarray(j.level, dtype),
            velocity_scale=j.velocity_scale,
            held_force=j.held_force if j.held_position is not None else j.lower_bound,
            held_position=None if j.held_position is None else np.asarray(j.held_position),
            dwell_time=REST_DWELL_TIME,
        )
        for j in joints
    ]
    # pyright reads the abstract state_names / input_names as fields of the generated __init__
    return Extended(system=base, terms=tuple(kept + added))  # pyright: ignore[reportCallIssue]


def describe(stretches, joints, rows_left_out, rows) -> str:
    """The note of `StaticFriction`: what was found and why the model has (or has no) `Stiction`."""
    if not stretches:
        return (
            "no record rests (no joint's position stays within 0.05 rad/s for 0.25 s): the data show no friction "
            "at rest, so the model has no Stiction"
        )
    total = sum(s.duration for s in stretches)
    swings = _swings(stretches, joints)
    left_out = (
        f"; {rows_left_out} of {rows} dynamic rows at rest or at low speed left out of the fit" if rows_left_out else ""
    )
    if not joints:
        held = (
            "no joint is held there by friction"
            if any(s.moves for s in stretches)
            else f"hold no net torque above {LOADED:g} times its noise"
        )
        return (
            f"the records rest ({total:.2f} s over {len(stretches)} stretch(es)) but {held}: nothing to read a "
            "static level from, so the model has no Stiction" + swings + left_out
        )
    parts = []
    for j in joints:
        what = (
            f"breakaway at {j.level:.4g} (median of {len(j.breakaways)})"
            if j.kind == "breakaway"
            else f"at least {j.level:.4g} (the largest torque held; no breakaway in the records)"
        )
        parts.append(
            f"{j.coordinate} rests under load {j.rest_s:.2f} s in {', '.join(j.records)}: {what}; sticks below "
            f"{j.velocity_scale:.3g}, its level built over {REST_DWELL_TIME:g} s there and worn off by a slip; a "
            f"validation window that starts at rest starts at zero speed where the measured "
            f"one is within {WITHIN_NOISE:g} times its record's noise at rest (pooled over the records: "
            f"{j.speed_noise:.3g})"
        )
    return "Stiction added: " + "; ".join(parts) + swings + left_out


def _swings(stretches, joints) -> str:
    """The note's part on each stretch whose torque read at zero speed the motion explains
    (`RestUnderLoad.moves`), at a joint left without `Stiction`: the torque, how much of it the joint's own
    motion carries, and the friction left with its standard error."""
    added = {j.joint for j in joints}
    parts = [
        f"{s.coordinate} at {s.start_s:.2f} to {s.stop_s:.2f} s in {s.record} (torque {abs(s.held):.3g} read at "
        f"zero speed; its own acceleration and speed carry {abs(s.motion):.3g}, friction {abs(s.friction):.3g} "
        f"+- {s.friction_noise:.2g})"
        for s in stretches
        if s.moves and s.joint not in added
    ]
    if not parts:
        return ""
    return (
        f"; no static level where the measured motion leaves no friction of {LOADED:g} standard errors, or its "
        "own motion carries more of the torque than friction: " + "; ".join(parts)
    )


def not_added(static: StaticFriction) -> StaticFriction:
    """`static` without its joints, for a method that leaves the model's friction as it is
    (`adds_static_friction` false): the rests under load stay in `stretches`, and the note says where
    the records rest under load, how long, and how to fit the static level."""
    parts = [
        f"{j.coordinate} {j.rest_s:.2f} s in {', '.join(j.records)} (holds at least {j.lower_bound:.3g})"
        for j in static.joints
    ]
    return dataclasses.replace(
        static,
        joints=(),
        note="the records rest under load ("
        + "; ".join(parts)
        + "), which a friction law of the speed cannot hold; the model has no Stiction "
        "(Dynamic(static_friction=True) adds it)",
    )
