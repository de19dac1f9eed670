r"""Per-record zeros of the angle encoders: does each record measure its angles from a zero of its own?

An incremental encoder counts from where the joint stood when it was powered up or reset. A rig
that resets its encoders at the start of each recording, with the arm hanging "about" straight down,
gives every record its own angle zero: off by however far static friction held the arm from the
vertical, or by how much it still swung. Such a rig's records all start at $q = (0, 0)$ to within
a few encoder counts.

The measured angle of record $r$ is then $q + c_r$, and its inverse-dynamics equations are
$\tau = Y(q_{meas} - c_r, \dot q, \ddot q)\,\theta$: an angle zero acts through the gravity terms
($\theta_4 \sin q_1$ becomes $\theta_4 \sin(q_1 - c_1)$, a $\cos q_1$ term that no base parameter
carries) and through the inertia's dependence on the elbow angle. Near the hanging rest it looks
like a constant torque; a record that moves far from it (a swing-up) tells the two apart, since a
gravity torque changes sign where the arm passes the horizontal and a sensor's torque offset does
not.

`record_angle_zeros` estimates one zero per record and joint with the base parameters, by
Gauss-Newton on the separable problem: linearised about the current zeros,
$Y(q - c - \delta)\theta \approx Y(q - c)\theta - \delta\, \partial_q (Y\theta)$, so $\theta$
and $\delta$ are one linear least-squares problem, whose columns $\partial_q(Y\theta)$ come from
forward differences of the equations in each record's angle (a constant shift of an angle passes
the zero-phase filters unchanged, so each record is filtered once and only its regressor is rebuilt
at the shifted angles), at each step (three builds of the regressor per step; a chord method that keeps the first
step's columns settles elsewhere, some mrad off, since its fixed point is orthogonal to
the wrong columns). It settles to $10^{-5}$ rad in a few steps on real records. It also fits the zeros of each half
of each record at the converged parameters: a sensor's zero is the same in both halves, where a model
error that looks like one follows the motion.

`identify` uses them where `Dynamic(offsets="auto")` has the choice (every joint an angle and
driven, the settings chosen from the data): it solves the equations once with one force offset per
record and joint and once with one angle zero per record and joint (as many unknowns), and keeps the
zeros where they leave an equation error at least 1 % smaller (`MARGIN`), the force offsets
otherwise; `offsets="angles"` asks for the zeros whatever the error. The records less their
zeros are then what both stages fit; the returned model has no zero of its own, and held-out records
are simulated as recorded.

??? cite

    G. H. Golub and V. Pereyra, "Separable nonlinear least squares: the variable projection method
    and its applications", Inverse Problems 19(2), 2003 (one linear and one nonlinear set of
    unknowns); J. Hollerbach, W. Khalil and M. Gautier, "Model identification", in *Springer
    Handbook of Robotics*, 2016, sec. 6.2 (joint offsets as calibration parameters of a robot's
    kinematic model).
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from .._data._trajectory import Trajectory
from ._equations import Dynamic, dynamic_rows_of, dynamic_signals, stacked_dynamic_equations
from ._offsets import driven_joints, offset_groups, record_labels
from ._regressors import split_terms, with_friction

STEP = 1e-4  # [rad] the forward differences' step
MAX_STEPS = 8  # Gauss-Newton steps at most
CONVERGED = 1e-5  # [rad] no zero moved more than this in the last step
LARGEST = 0.3  # [rad] zeros beyond this are not believed: a mix-up (degrees, upright) more likely
# The zeros are chosen over force offsets where they leave an equation error at least 1 % smaller: where
# neither explains anything (records read from their true zero, no sensor offset: 0.1300 against 0.1302 on
# the tests' synthetic rig) the force offsets stay; records with real encoder zeros gain several per cent.
MARGIN = 0.99


@dataclasses.dataclass(frozen=True)
class AngleZeros:
    r"""Each record's angle zeros, fitted with the base parameters, and whether `identify` used them.

    **Fields:** `records` (labels: file names where known), `joints` (position names), `values`
    `(record, joint)` [rad]: what the record's measured angle exceeds the model's by; `halves`
    `(record, 2, joint)` the same from each half of the record, at the converged parameters;
    `relative_error` the equation error with the zeros fitted and `force_relative_error` with one
    force offset per record and joint instead (as many unknowns); `steps` the Gauss-Newton steps
    taken and `converged`; `chosen` whether the fit used them, and `reason` why or why not.
    """

    records: tuple[str, ...]
    joints: tuple[str, ...]
    values: np.ndarray
    halves: np.ndarray
    relative_error: float
    force_relative_error: float
    steps: int
    converged: bool
    chosen: bool
    reason: str

    def corrected(self, records: list[Trajectory], system, owners=None) -> list[Trajectory]:
        """`records` with each one's zeros taken off its angles (what the fit uses where `chosen`);
        `owners[k]`, where given, is the fitted record whose zeros `records[k]` is read from (a
        held-out tail: the same recording, so the same encoder zero)."""
        rows = _angle_rows(system)
        owners = range(len(records)) if owners is None else owners
        return [shifted(r, rows, self.values[i]) for r, i in zip(records, owners)]

    def to_json(self) -> dict:
        return {
            "kind": "angle",
            "records": list(self.records),
            "joints": list(self.joints),
            "values": self.values.tolist(),
            "halves": self.halves.tolist(),
            "relative_error": self.relative_error,
            "force_offsets_relative_error": self.force_relative_error,
            "steps": self.steps,
            "converged": self.converged,
            "chosen": self.chosen,
            "reason": self.reason,
            "meaning": "each record's zero of each angle [rad]: its measured angle less the model's (an encoder "
            "zeroed where the arm stood when the recording began), estimated with the parameters; "
            "where chosen, both stages fit the records less them; not part of the model",
        }

    def note(self) -> str:
        cells = "; ".join(
            f"{record} " + ", ".join(f"{j} {v:+.4f}" for j, v in zip(self.joints, row))
            for record, row in zip(self.records, self.values)
        )
        return f"angle zeros per record [rad] ({'fitted' if self.chosen else 'not used'}: {self.reason}): {cells}"


def applies(system) -> bool:
    """Whether every joint of `system` is an angle that an input drives (a two-link arm)."""
    base = split_terms(system)[0]
    joints = getattr(base, "joint_names", ()) or ()
    driven = driven_joints(system)
    return bool(joints) and driven is not None and set(base.angle_indices) == set(range(len(joints))) == set(driven)


def _angle_rows(system) -> tuple[int, ...]:
    return tuple(split_terms(system)[0].angle_indices)


def shifted(record: Trajectory, rows, values) -> Trajectory:
    """`record` with `values` taken off its position states `rows` (velocities unchanged)."""
    return Trajectory(
        record.ts,
        record.xs - _shift(record.xs, rows, values),
        record.us,
        record.state_names,
        record.input_names,
        record.system,
        record.source,
    )


def _shift(xs, rows, values):
    """`(1, states)`: `values` in the position states `rows`, zero elsewhere, in `xs`'s dtype."""
    shift = np.zeros(xs.shape[1])
    shift[list(rows)] = np.asarray(values)
    return jnp.asarray(shift, xs.dtype)[None, :]


def _joint_major_columns(derivative, counts, cuts):
    """One column per (cut, joint): the rows of `derivative` (stacked joint by joint, `counts` rows per
    record and joint) that fall into each cut `(start, stop)` of the time rows, zero elsewhere."""
    n = int(sum(counts))
    n_joints = derivative[0].shape[0] // n
    columns = []
    for lo, hi in cuts:
        for d in derivative:
            column = np.zeros_like(d)
            for k in range(n_joints):
                column[k * n + lo : k * n + hi] = d[k * n + lo : k * n + hi]
            columns.append(column)
    return np.stack(columns, axis=1)


def _solve(a, y, extra):
    """Least squares of `[a, extra]` (columns scaled to unit norm); `(solution, relative error)`."""
    full = np.concatenate([a, extra], axis=1)
    scale = np.linalg.norm(full, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    solution = np.linalg.lstsq(full / scale, y, rcond=None)[0] / scale
    return solution, float(np.linalg.norm(full @ solution - y) / np.linalg.norm(y))


def record_angle_zeros(
    system, trajectories: list[Trajectory], method: Dynamic, friction, rcond, compare: bool = True
) -> AngleZeros:
    """Fit each record's angle zeros with the base parameters (see the module); with `compare` they
    are chosen only where they leave a smaller equation error than force offsets, else wherever the
    fit converges to zeros below `LARGEST`."""
    rows = _angle_rows(system)
    plain = dataclasses.replace(method, offsets=False)
    system = with_friction(system, friction)
    # Each record's settings and filtered signals once: a zero shifts the filtered angles as it shifts
    # the record's (the zero-phase filters pass constants), so only the regressor is rebuilt per shift.
    signals = [dynamic_signals(r, plain) for r in trajectories]

    def equations(zeros):
        parts = []
        for s, z in zip(signals, zeros):
            moved = dataclasses.replace(s, xs=s.xs - _shift(s.xs, rows, z))
            parts.append(dynamic_rows_of(system, moved, friction))
        a, y, counts = stacked_dynamic_equations(parts)
        return np.asarray(a, dtype=float), np.asarray(y, dtype=float), counts

    zeros = np.zeros((len(trajectories), len(rows)))
    a, y, counts = equations(zeros)
    force_error = _solve(a, y, _group_columns(len(y), offset_groups(system, counts)))[1] if compare else float("nan")
    bounds = np.cumsum((0,) + counts)
    records = list(zip(bounds[:-1], bounds[1:]))
    theta = np.linalg.lstsq(a, y, rcond=None)[0]
    n = a.shape[1]

    def slope_of_a():
        """d a / d c at the current zeros, each joint's, by forward differences (a record's zero moves
        only its own rows)."""
        out = []
        for j in range(len(rows)):
            step = np.zeros(len(rows))
            step[j] = STEP
            out.append((equations(zeros + step)[0] - a) / STEP)
        return out

    steps, converged, error = 0, False, float("nan")
    while steps < MAX_STEPS and not converged:
        slope = [d @ theta for d in slope_of_a()]
        solution, error = _solve(a, y, _joint_major_columns(slope, counts, records))
        theta, delta = solution[:n], solution[n:].reshape(len(trajectories), len(rows))
        zeros = zeros + delta
        a, y, _ = equations(zeros)
        steps += 1
        converged = bool(np.max(np.abs(delta)) < CONVERGED)
    slope = [d @ theta for d in slope_of_a()]
    # at the converged zeros: the error, and each half's zero (one more linearised solve, a column per half)
    solution, error = _solve(a, y, _joint_major_columns(slope, counts, records))
    halves_cuts = [cut for lo, hi in records for cut in ((lo, (lo + hi) // 2), ((lo + hi) // 2, hi))]
    halves_solution, _ = _solve(a, y, _joint_major_columns(slope, counts, halves_cuts))
    halves = zeros[:, None, :] + halves_solution[n:].reshape(len(trajectories), 2, len(rows))
    names = tuple(split_terms(system)[0].joint_names[i] for i in rows)
    if not converged:
        chosen, reason = False, f"Gauss-Newton did not settle in {MAX_STEPS} steps"
    elif np.max(np.abs(zeros)) > LARGEST:
        chosen, reason = (
            False,
            (
                f"a zero of {np.max(np.abs(zeros)):.2f} rad is more than {LARGEST} rad: "
                "more likely a mix-up (degrees, an upright zero) than an encoder's start"
            ),
        )
    elif compare and not error < MARGIN * force_error:
        chosen, reason = (
            False,
            (
                f"they do not leave a clearly smaller equation error than force offsets ({error:.4f} "
                f"against {force_error:.4f}; at least {1 - MARGIN:.0%} smaller is needed)"
            ),
        )
    elif compare:
        chosen, reason = (
            True,
            (
                f"they leave a smaller equation error than force offsets ({error:.4f} against "
                f"{force_error:.4f}, as many unknowns)"
            ),
        )
    else:
        chosen, reason = True, "asked for (Dynamic(offsets='angles'))"
    return AngleZeros(
        tuple(record_labels(trajectories)), names, zeros, halves, error, force_error, steps, converged, chosen, reason
    )


def _group_columns(n_rows, groups):
    """One constant column per row group (`offset_groups`: one force offset per record and driven
    joint), the alternative `identify` weighs the zeros against."""
    columns = np.zeros((n_rows, len(groups)))
    for k, group in enumerate(groups):
        columns[group, k] = 1.0
    return columns
