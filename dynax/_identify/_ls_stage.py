"""The least-squares stage of `identify`: the equations solved (with each record's force offsets and
weights), checked for physical consistency and constrained to it, with standard errors robust to
rows correlated in time."""

import contextlib
import contextvars
import functools
from typing import NamedTuple
import warnings

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array
import numpy as np

from .._context import set_within
from .._data._sampling import time_label
from .._data._trajectory import Trajectory
from .._errors import located, UsageError
from .._fit import serial_covariance, Solution
from .._model._linear_in_parameters import size_parameter_names
from .._model._system import AbstractSystem
from ._consistency import check_consistency, Consistency, consistent_least_squares, InconsistentEstimateWarning
from ._equations import joint_weights, row_times, stacked_equations
from ._least_squares import IdentifiabilityError, least_squares, poorly_determined
from ._offsets import driven_joints, offset_groups, record_labels, record_offsets, RecordOffsets, without_offsets
from ._record_friction import coulomb_columns, record_friction, RecordFriction
from ._regressors import positions_and_velocities, split_terms, with_parameters
from ._static_friction import rest_row_weights, slow_row_weights

SEEN: contextvars.ContextVar[list | None] = contextvars.ContextVar(
    "dynax_least_squares_seen", default=None
)  # `least_squares_seen`'s list


class SeenStage(NamedTuple):
    """One least-squares stage as `least_squares_seen` shows it: the stacked equations as built (`a`, `y`, the
    columns' `names`, each record's rows per joint `counts`), before any force offset is taken out, the rows'
    weights from the rests and slow rows left out (`keep`, `None` where every row counts) and the stage."""

    a: np.ndarray
    y: np.ndarray
    names: tuple[str, ...]
    counts: tuple[int, ...]
    keep: np.ndarray | None
    stage: "_LeastSquaresStage"


@contextlib.contextmanager
def least_squares_seen():
    """Within the block, each least-squares stage `identify` runs (the first fit, and the refit without the
    loaded rests) appends a `SeenStage` to the list the block is given, in the order they run; the refits
    that only test a warning's explanation (columns swapped or reversed) are not shown."""
    seen: list[SeenStage] = []
    with set_within(SEEN, seen):
        yield seen


def fitted_system(system, names, estimate):
    """`system` carrying the estimate; base parameters the fitted model leaves out are as the system's
    `with_base_parameters` sets them (a linear axis fitted without Coulomb friction gets `coulomb = 0`)."""
    return with_parameters(system, names, jnp.asarray(estimate))


class _LeastSquaresStage(eqx.Module):
    system: AbstractSystem
    names: tuple[str, ...] = eqx.field(static=True)
    estimate: Array
    fit: Solution
    a: Array
    y: Array
    n_samples: int = eqx.field(static=True)
    label: str = eqx.field(static=True)
    settings: tuple
    consistency: Consistency
    offsets: RecordOffsets | None
    groups: list | None = None  # rows that share one fitted offset (`Dynamic(offsets=...)`), or None
    fitted_offsets: np.ndarray | None = None  # (records, driven joints) estimated with the parameters
    driven: tuple[str, ...] = ()
    friction: RecordFriction | None = None
    serial: dict | None = None  # what the errors robust to serial correlation changed (`_serially_robust`)
    rest_rows: tuple[int, int] = (0, 0)  # (rows at rest given zero weight, rows)
    joint_weights: dict | None = eqx.field(static=True, default=None)  # `Dynamic(weighting="joint")`: joint -> weight


def joint_positions(system, trajectories):
    """The records' joint positions, stacked (one compiled call: slicing op by op costs more than the check)."""
    return _stacked_positions(system, [t.xs for t in trajectories])


@eqx.filter_jit
def _stacked_positions(system, states):
    return jnp.concatenate([positions_and_velocities(system, xs)[0] for xs in states])


def _offset_rows(system, method, counts):
    """The row groups that each carry a fitted offset under `method` (see `Dynamic`'s `offsets`), or None."""
    if not counts:  # rows stacked joint by joint, per record: `Dynamic`'s
        return None
    wanted = method.force_offsets
    if isinstance(wanted, str):
        if wanted not in ("auto", "angles"):
            raise UsageError(f"Dynamic: `offsets` must be True, False, 'auto' or 'angles', got {wanted!r}")
        wanted = wanted == "auto" and isinstance(method.lowpass_hz, str) and method.lowpass_hz == "auto"
    if not wanted:
        return None
    groups = offset_groups(system, counts)
    if groups is None and method.force_offsets is True:
        raise UsageError(
            f"Dynamic(offsets=True): {type(split_terms(system)[0]).__name__} has a constant term of its own "
            "(or no driven joint); fit its offset as a parameter instead"
        )
    return groups


def least_squares_stage(system, trajectories, method, friction, weights, rcond, consistency, rests=None):
    """The least-squares stage; `rests` (each record's `Rest` stretches, `Dynamic` only: the refit once a
    static level is read) gives a joint's rows while it rests zero weight (`rest_row_weights`: no friction law
    of the speed explains them), and its rows at low speed too (`slow_row_weights`: the Coulomb law's
    smoothing, which such a joint's friction does not follow)."""
    given = (system, method, friction, weights, rcond)
    system, raw_a, raw_y, weights, names, n_samples, label, settings, counts, record_rows = stacked_equations(
        system, trajectories, method, friction, weights, rcond
    )
    groups = _offset_rows(system, method, counts)
    keep = None
    if rests is not None and counts:  # `counts`: rows stacked joint by joint (`Dynamic`)
        n_joints = raw_a.shape[0] // sum(counts)
        keep = rest_row_weights(trajectories, settings, counts, rests, n_joints)
        keep = slow_row_weights(keep, system, trajectories, settings, counts, n_joints)
    joint_weight = None
    if method.joint_weighted and weights is None:
        # Each joint's residual variance from an ordinary fit of the equations that will be solved.
        plain = (raw_a, raw_y) if groups is None else without_offsets(raw_a, raw_y, keep, groups)[:2]
        if keep is not None:  # rows at rest left out of the variances too
            plain = (np.asarray(plain[0]) * keep[:, None], np.asarray(plain[1]) * keep)
        n_joints = raw_a.shape[0] // sum(counts)  # rows stacked joint by joint, `counts` per record and joint
        weights = joint_weights(
            jnp.asarray(plain[0], raw_a.dtype), jnp.asarray(plain[1], raw_y.dtype), names, rcond, n_joints
        )
        if keep is not None:  # the mean square over the kept rows of each joint
            share = keep.reshape(n_joints, -1).mean(axis=1)
            weights = weights * jnp.asarray(np.repeat(share, len(keep) // n_joints), weights.dtype)
        per_joint = np.asarray(weights).reshape(n_joints, -1)[:, 0]  # one weight for each joint's block of rows
        joint_weight = dict(zip(split_terms(system)[0].joint_names, map(float, per_joint)))
    if keep is not None:
        weights = jnp.asarray(keep, raw_a.dtype) * (1.0 if weights is None else jnp.asarray(weights, raw_a.dtype))
    a, y = raw_a, raw_y
    if groups is not None:
        a, y, a_means, y_means = without_offsets(raw_a, raw_y, weights, groups)
        a, y = jnp.asarray(a, raw_a.dtype), jnp.asarray(y, raw_y.dtype)
    try:
        fit = least_squares(a, y, names=names, weights=weights, rcond=rcond)
    except IdentifiabilityError as error:
        if groups is None:
            raise
        raise IdentifiabilityError(
            f"{error} Each record's constant force offset at the driven joints is estimated with the parameters "
            "(a sensor's zero), so a constant force tells nothing about them; Dynamic(offsets=False) fixes the "
            "offsets at zero.",
            unidentified=error.unidentified,
            rank=error.rank,
            n_params=error.n_params,
            condition_number=error.condition_number,
        ) from None
    estimate = fit.value
    fitted = fitted_system(system, names, estimate)
    qs = joint_positions(system, trajectories)
    check = check_consistency(fitted, names, estimate, qs, warn=consistency == "check")
    reversed_named = False
    error = float(relative_equation_error(a, y, estimate))
    if check.violated and consistency != "off":
        solve = functools.partial(least_squares, a, names=names, weights=weights, rcond=rcond)
        reversed_named = _warn_if_inputs_reversed(system, names, (a, y), solve, qs, error, trajectories[0].input_names)
        _warn_if_angle_unit(given, trajectories, error)
        _warn_if_swapped(given, trajectories, error)
        _warn_if_absolute(given, trajectories, error)
        plain_std = _serially_robust(fit, a, y, weights, estimate, record_rows)[0].std_errors
        _warn_if_zero_upright(fitted, names, estimate, plain_std, qs)
    if counts and consistency != "off" and rests is None and not reversed_named:  # not a refit of this stage

        def fit_rows(ys):  # `a` has its offsets taken out already; `ys` the same way, column by column
            w = np.ones(len(ys)) if weights is None else np.asarray(weights, dtype=float)
            for rows in groups or ():
                ys[rows] -= w[rows] @ ys[rows] / max(float(np.sum(w[rows])), np.finfo(float).tiny)
            return np.asarray(a, dtype=float), ys, w

        _warn_if_input_scaled_partway(
            system,
            names,
            (raw_a, raw_y),
            (fit_rows, functools.partial(least_squares, a, names=names, weights=weights, rcond=rcond), record_rows),
            qs,
            (error, bool(check.violated)),
            (trajectories, settings, counts),
        )
    if consistency == "constrain" and check.violated:
        estimate, _ = consistent_least_squares(system, names, a, y, weights, start=fit.value)
        fitted = fitted_system(system, names, estimate)
        after = check_consistency(fitted, names, estimate, qs, warn=False)
        check = Consistency(
            after.violated, active=check.violated, constrained=True, min_mass_eigenvalue=after.min_mass_eigenvalue
        )
        if after.violated:
            warnings.warn(
                "the constrained fit did not reach a consistent estimate: " + "; ".join(after.violated),
                InconsistentEstimateWarning,
                stacklevel=6,
            )
    fit, serial = _serially_robust(fit, a, y, weights, estimate, record_rows)
    joint_names = split_terms(system)[0].joint_names
    labels = record_labels(trajectories)
    offsets = record_offsets(raw_a, raw_y, counts, joint_names, labels) if counts else None
    per_record_friction = (
        record_friction(raw_a, raw_y, counts, names, coulomb_columns(system, friction), labels) if counts else None
    )
    fitted_offsets, driven = None, ()
    if groups is not None:
        values = y_means - a_means @ np.asarray(estimate)  # what each record's recorded force has in excess
        driven = tuple(joint_names[j] for j in driven_joints(system))  # the order of `offset_groups`
        fitted_offsets = values.reshape(len(driven), len(counts)).T
    stage = _LeastSquaresStage(
        fitted,
        names,
        estimate,
        fit,
        a,
        y,
        int(n_samples),
        label,
        settings,
        check,
        offsets,
        groups,
        fitted_offsets,
        driven,
        per_record_friction,
        serial,
        (0 if keep is None else int(np.sum(keep == 0)), int(raw_a.shape[0])),
        joint_weight,
    )
    if (seen := SEEN.get()) is not None:
        seen.append(SeenStage(np.asarray(raw_a), np.asarray(raw_y), tuple(names), tuple(counts or ()), keep, stage))
    return stage


def _serially_robust(fit, a, y, weights, estimate, record_rows):
    """`fit` with its covariance and standard errors robust to residuals correlated in time
    (`serial_covariance`: Newey-West with Andrews' bandwidth over each record's time steps), and
    what that changed (`{"bandwidth_steps", "inflation"}`: each error over the one that counts
    every row as independent); `fit` itself, and `None`, where the rank is short or there are no
    records' rows to go by.

    Equations sampled in time are not independent: the low-pass filter spreads each sample's noise
    over its neighbours, and a model error follows the motion. On real filtered rows the robust
    errors are several times the independent-row ones, and estimates from two filter settings lie
    within about one robust error of each other where they lay many independent-row errors apart
    (docs/devdocs/identification_notes.md)."""
    n = a.shape[1]
    total = int(sum(record_rows))
    if not total or int(fit.statistics.rank) < n or a.shape[0] % total:
        return fit, None
    w = np.ones(a.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    sw = np.sqrt(w)
    a_np = np.asarray(a, dtype=float)
    jac = a_np * sw[:, None]
    residuals = (np.asarray(y, dtype=float) - a_np @ np.asarray(estimate, dtype=float)) * sw
    steps = np.arange(a.shape[0]) % total  # rows are stacked in blocks (the joints), each through every record
    covariance, bandwidth = serial_covariance(jac, residuals, steps, tuple(record_rows))
    covariance = jnp.asarray(covariance, fit.covariance.dtype)
    std = jnp.sqrt(jnp.diag(covariance))
    independent = np.asarray(fit.std_errors)
    # an exact fit (no residual) has no error either way: nothing grew
    inflation = np.divide(np.asarray(std), independent, out=np.ones(n), where=independent > 0)
    robust = eqx.tree_at(lambda f: (f.std_errors, f.covariance), fit, (std, covariance))
    return robust, {
        "bandwidth_steps": bandwidth,
        "inflation": {name: float(v) for name, v in zip(fit.names, inflation)},
    }


def less_offsets(system, records, ls):
    """The records with each one's fitted offsets taken off its inputs (through the input matrix), as
    the refinement fits them; the records themselves where no offsets were fitted."""
    if ls.fitted_offsets is None:
        return records
    return records_less_offsets(system, records, ls.driven, ls.fitted_offsets)


def records_less_offsets(system, records, joints, offsets):
    """`records` with each one's force offsets taken off its inputs (through `system`'s input matrix), as the
    output-error refinement fits them: `offsets[r][k]` the offset of record `r`'s recorded force at the driven
    joint `joints[k]` (the least-squares stage's `offsets`, `values` at `joints`)."""
    base = split_terms(system)[0]
    b = np.asarray(base.input_matrix())
    to_inputs = np.linalg.pinv(b)  # joint forces -> the inputs that produce them
    rows = [base.joint_names.index(j) for j in joints]
    out = []
    for record, offset in zip(records, offsets):
        force = np.zeros(b.shape[0])
        force[rows] = offset
        shift = to_inputs @ force
        out.append(
            Trajectory(
                record.ts,
                record.xs,
                record.us - jnp.asarray(shift, record.us.dtype)[None, :],
                record.state_names,
                record.input_names,
                record.system,
                record.source,
            )
        )
    return out


def offsets_json(ls, trajectories):
    if ls.fitted_offsets is None:
        return None
    return {
        "records": record_labels(trajectories),
        "joints": list(ls.driven),
        "values": [[float(v) for v in row] for row in ls.fitted_offsets],
        "meaning": "each record's constant offset of the recorded force at each driven joint, estimated with the "
        "parameters (a sensor's zero) and not part of the model; the output-error refinement fits the "
        "records less them",
    }


def relative_equation_error(a, y, estimate):
    return jnp.linalg.norm(a @ estimate - y) / jnp.linalg.norm(y)


REVERSED_GAIN = 0.5  # a sign flip must at least halve the equation error to be named


def _best_subset(n: int, refit, error: float):
    """The subset of `n` candidates (inputs to negate, joints to read in degrees) that best explains an
    inconsistent estimate, with its equation error, or `None`. `refit(subset)` returns `(consistent,
    error, physics_alone)` for the records changed so, or `None` where they cannot be fitted. A subset
    explains the estimate where the refit is consistent with at most `REVERSED_GAIN` of `error`, or
    consistent at all where `physics_alone` (negating every input negates the estimate and keeps its
    error)."""
    import itertools

    best = None
    for size in range(1, n + 1):
        for subset in itertools.combinations(range(n), size):
            found = refit(subset)
            if found is None or not found[0]:
                continue
            if (found[1] <= REVERSED_GAIN * error or found[2]) and (best is None or found[1] < best[1]):
                best = (subset, found[1])
    return best


def _warn_if_inputs_reversed(system, names, equations, solve, qs, error, input_names) -> bool:
    """Where the estimate is inconsistent, try each set of the recorded inputs with its sign flipped:
    if one gives a consistent estimate and at most `REVERSED_GAIN` of the equation error, warn that
    those inputs look reversed, with the `scale` that fixes them.

    `equations` is the stage's `(a, y)`, `solve(y)` its weighted least-squares fit of `a` to other
    right-hand sides, `error` its relative equation error and `input_names` the records' inputs.
    Returns whether it warned.

    A torque counted the other way than the model's joint angle (a motor mounted the other way, a
    current's sign) is the commonest mix-up of real data, and least squares meets it with an estimate
    that the consistency constraint then squeezes to nothing (near-zero inertias and a large
    equation error), which names no cause. Flipping an input negates the equation rows of the joint it drives, so each
    candidate is one more least-squares solve. Systems whose inputs share a joint are not probed.
    """
    a, y = equations
    driven = _driven_joints(system, a.shape[0])
    if driven is None:
        return False
    rows = a.shape[0] // len(split_terms(system)[0].joint_names)  # rows stacked joint by joint
    inputs = tuple(input_names)

    def refit(flipped):
        sign = np.ones(a.shape[0])
        for k in flipped:
            for j in driven[k]:
                sign[j * rows : (j + 1) * rows] = -1.0
        y_flipped = y * jnp.asarray(sign, y.dtype)
        try:
            candidate = solve(y_flipped).value
        except IdentifiabilityError:
            return None
        consistent = not check_consistency(
            fitted_system(system, names, candidate), names, candidate, qs, warn=False
        ).violated
        # Every input negated negates the estimate and leaves the error as it is: there the physics
        # alone (masses are positive) tells the two apart.
        return consistent, float(relative_equation_error(a, y_flipped, candidate)), len(flipped) == len(driven)

    best = _best_subset(len(driven), refit, error)
    if best is None:
        return False
    which = [inputs[k] for k in best[0]]
    change = (
        f"the equation error falls from {error:.0%} to {best[1]:.0%}"
        if best[1] < error * (1 - 1e-6)
        else "its equation error is the same (negating every input negates the estimate: only the physics tells)"
    )
    warnings.warn(
        f"the recorded {', '.join(which)} look{'s' if len(which) == 1 else ''} reversed against the model's joint "
        f"positions: the least-squares estimate is physically inconsistent, and with "
        f"{'that input' if len(which) == 1 else 'those inputs'} negated it is consistent and {change}. A motor or "
        "a current counted the other way? If so, load the records with scale={"
        + ", ".join(f"'{n}': -1" for n in which)
        + "} (`--scale "
        + ",".join(f"{n}=-1" for n in which)
        + "`).",
        InconsistentEstimateWarning,
        stacklevel=7,
    )
    return True


def _driven_joints(system, n_rows: int) -> list[np.ndarray] | None:
    """The joints each input drives (the base system's input matrix), or `None` where a sign flip of an input
    is not one of its joints' equation rows: inputs that share a joint, an input that drives none, or rows
    that are not stacked joint by joint."""
    base = split_terms(system)[0]
    b = np.asarray(base.input_matrix())
    driven = [np.flatnonzero(np.abs(b[:, k]) > 0) for k in range(b.shape[1])]
    if (
        n_rows % b.shape[0]
        or any(len(d) == 0 for d in driven)
        or len(np.concatenate(driven)) != len(set(np.concatenate(driven).tolist()))
    ):
        return None
    return driven


class PartwayStretch(NamedTuple):
    """The best stretch of one `_warn_if_input_scaled_partway` search, as `partway_search_seen` shows it: the
    record's label, the input, the cut row (among the record's equation rows per joint) and whether the stretch
    runs from it to the end (`after`) or from the start to it, the stretch's gain fitted with the parameters, and
    the squared equation error it keeps over the stage's (`ratio`, before any gate: a stretch is named at
    `FLIP_GAIN` or less, with a consistent estimate, a determined gain and determined size parameters)."""

    record: str
    input: str
    row: int
    after: bool
    gain: float
    ratio: float


PARTWAY_SEEN: contextvars.ContextVar[list | None] = contextvars.ContextVar("dynax_partway_seen", default=None)


@contextlib.contextmanager
def partway_search_seen():
    """Within the block, each search for an input whose gain changes part way through a record (one per
    `Dynamic` least-squares stage that runs it) appends its best stretch (`PartwayStretch`) to the list the block
    is given, whether or not a warning names it: how near a clean record comes to being named, how far a faulted
    one is past the gate."""
    seen: list[PartwayStretch] = []
    with set_within(PARTWAY_SEEN, seen):
        yield seen


FLIP_STRETCHES = 16  # where a record's input may change its gain: at each sixteenth of it, then refined row by row
FLIP_GAIN = 0.5  # the stretch's gain must remove at least half of the squared equation error
SIGN_TURN = 0.25  # a stretch gain within this of -1 reads as a sign that turned
GAIN_DETERMINED = 3.0  # the stretch's gain this many standard errors (robust to serial correlation) from no change


def _warn_if_input_scaled_partway(system, names, raw, solvers, qs, fitted, records) -> None:
    r"""Look for an input whose gain changes part way through a record (a sign that turns, a current limit, a unit,
    a gear or a torque constant changed while recording): for each input and each of `FLIP_STRETCHES - 1` cuts of
    each record, add the input's rows from the cut to the record's end (or from its start to the cut) as one more
    regressor column, and refine the best cut row by row. The input enters the equations linearly
    ($Y\theta = u$): where the stretch's logged input is $g$ times what acts, $Y\theta + c\,u_s = u$ with
    $c = 1 - 1/g$, so one least-squares solve per candidate estimates the parameters and the stretch's gain
    together. If one such stretch keeps at most `FLIP_GAIN` of the stage's squared equation error, with a
    consistent estimate for the input so corrected, a gain `GAIN_DETERMINED` standard errors from 1 (as $g$ and
    as $c$) and size parameters the records determine (relative standard errors robust to serial correlation
    under `POORLY_DETERMINED`), warn with the record, the input, the time and the gain (a gain near -1, within
    `SIGN_TURN`, as a sign that turned), and the `--exclude` that leaves the stretch out: no `scale` is right
    for the whole record.

    `raw` is the stage's equations `(a, y)` as built (before force offsets are taken out); `solvers` holds
    `fit_rows(y)`, the stage's equations for other right-hand sides `y` (columns) as solved (offsets taken
    out) with the rows' weights, `solve(y)`, the stage's least-squares fit to one of them, and each record's
    rows per joint; `fitted = (error, inconsistent)` is the stage's relative equation error and whether its
    estimate is physically inconsistent, and `records = (trajectories, settings, counts)` the records, their
    equations' settings and each one's rows per joint.

    On a record whose inputs are right, a free gain on a stretch takes up little of the model's misfit (the
    measurements on real and synthetic records are in docs/devdocs/identification_notes.md), where a gain of 2
    from mid-record or a sign turn takes up most of it. A gain between 0.7 and 1.5 is not named: it adds less
    error than the model's misfit. Where the motion is too small to determine the model, the error is the
    model's misfit, which a gain can move as much (an arm held by its friction): such a fit names nothing, as
    its size parameters are left to the noise. So the search runs on every `Dynamic` fit: a consistent
    estimate may hide the fault too (both joints driven and one torque negated for the second half fits
    consistently, with most of the equation error left).

    A motor's direction, a current's scale or a unit that changes while recording leaves each stretch a fine
    signal; least squares then fits the two stretches' contradiction, and an output-error refinement may fit
    inertias a thousand times too large. All candidates are one batched least-squares solve
    (numpy); the consistency of the best few is checked.
    """
    a_raw, y_raw = (np.asarray(v, dtype=float) for v in raw)
    fit_rows, solve, record_rows = solvers
    error, inconsistent = fitted
    trajectories, settings, counts = records
    driven = _driven_joints(system, a_raw.shape[0])
    if driven is None or not counts:
        return
    total = sum(counts)
    starts = np.concatenate([[0], np.cumsum(counts)])

    def stretch(record, k, cut, after):
        inside = np.zeros(len(y_raw))
        span = slice(cut, counts[record]) if after else slice(0, cut)
        for j in driven[k]:
            first = j * total + starts[record]
            inside[first + span.start : first + span.stop] = 1.0
        return inside

    a_fit, y_fit, w_fit = fit_rows(y_raw[:, None].copy())
    y_fit = y_fit[:, 0]
    sw = np.sqrt(w_fit)
    u, s, _ = np.linalg.svd(a_fit * sw[:, None], full_matrices=False)
    basis = u[:, s > s[0] * max(a_fit.shape) * np.finfo(float).eps] if s.size and s[0] > 0 else u[:, :0]
    stage_left = sw * y_fit - basis @ (basis.T @ (sw * y_fit))  # the stage's weighted residual
    scale = max(float(np.linalg.norm(y_fit)), np.finfo(float).tiny)

    def errors(candidates):
        """Each candidate's stretch column as solved, its coefficient `c` ($1 - 1/g$), the right-hand side with
        the stretch's input so corrected, its least-squares estimate and its error: the joint fit's residual over
        the stage's right-hand side or over the corrected one, whichever is larger (a gain that shrinks the
        stretch's input to nothing leaves a small residual of a right-hand side it has emptied: where one input
        drives everything, an acrobot's, a stretch over most of the record would fit nothing)."""
        columns = fit_rows(np.stack([y_raw * stretch(*c) for c in candidates], axis=1))[1]
        weighted = columns * sw[:, None]
        apart = weighted - basis @ (basis.T @ weighted)  # each column less what the parameters' columns explain
        size = np.sum(apart * apart, axis=0)
        usable = size > 1e-12 * np.maximum(np.sum(weighted * weighted, axis=0), np.finfo(float).tiny)
        c = np.where(usable, (apart.T @ stage_left) / np.where(usable, size, 1.0), 0.0)
        ys = y_fit[:, None] - columns * c[None, :]
        estimates = np.linalg.lstsq(a_fit * sw[:, None], ys * sw[:, None], rcond=None)[0]
        left = np.linalg.norm(a_fit @ estimates - ys, axis=0)
        left = left / np.minimum(scale, np.maximum(np.linalg.norm(ys, axis=0), np.finfo(float).tiny))
        return columns, c, ys, estimates, np.where(usable, left, np.inf)

    lowest_cut = 0 if len(counts) > 1 else 1  # of several records, one may be scaled throughout (cut 0)
    coarse = [
        (r, k, cut, after)
        for r, count in enumerate(counts)
        if count >= 2 * FLIP_STRETCHES
        for k in range(len(driven))
        for cut in sorted({int(c) for c in np.linspace(0, count, FLIP_STRETCHES + 1)[lowest_cut:-1]})
        for after in (True, False)
    ]
    if not coarse:
        return
    found = errors(coarse)[-1]
    enough = np.sqrt(FLIP_GAIN) * error
    watching, passed = PARTWAY_SEEN.get(), bool(found.min() <= enough)
    if not passed and watching is None:
        return
    r, k, cut, _ = coarse[int(np.argmin(found))]
    step = counts[r] // FLIP_STRETCHES  # refine the cut row by row between its neighbours
    # both sides: where every input's equations are this input's (an acrobot's), a gain on one side is its
    # inverse on the other and the whole input's scale, which only the consistency of the estimate tells apart
    fine = [
        (r, k, c, side)
        for c in range(max(lowest_cut, cut - step), min(counts[r], cut + step + 1))
        for side in (True, False)
    ]
    columns, coefficients, ys, estimates, found = errors(fine)
    if watching is not None:  # `partway_search_seen`: the best stretch, whatever the gates say of it
        best = int(np.argmin(found))
        c = float(coefficients[best])
        watching.append(
            PartwayStretch(
                record_labels(trajectories)[r],
                trajectories[0].input_names[k],
                fine[best][2],
                fine[best][3],
                1.0 / (1.0 - c) if c != 1.0 else np.inf,
                float(found[best] / error) ** 2 if error > 0 else np.inf,
            )
        )
        if not passed:  # watched, as it would run unwatched
            return
    for i in np.argsort(found)[:4]:  # the best few: consistency is the costly check
        if found[i] > enough:
            break
        candidate, kept = jnp.asarray(estimates[:, i]), float(found[i])
        if check_consistency(fitted_system(system, names, candidate), names, candidate, qs, warn=False).violated:
            # short of consistency (a friction level a little below zero, as a clean record's own estimate may
            # be): judged by the consistent estimate's equation error, as the stage will fit it
            candidate = consistent_least_squares(system, names, a_fit, ys[:, i], w_fit, start=candidate)[0]
            kept = float(
                np.linalg.norm(a_fit @ np.asarray(candidate) - ys[:, i]) / min(scale, np.linalg.norm(ys[:, i]))
            )
            if kept > enough:
                continue
        if _leaves_sizes_to_noise(system, names, (a_fit, ys[:, i], w_fit), solve, candidate, record_rows):
            continue
        c = float(coefficients[i])
        c_std = _coefficient_std(a_fit, columns[:, i], y_fit, w_fit, record_rows)
        if not abs(c) > GAIN_DETERMINED * c_std:
            continue
        gain = 1.0 / (1.0 - c) if c != 1.0 else np.inf
        gain_std = gain**2 * c_std  # g = 1 / (1 - c): dg/dc = g^2
        if not abs(gain - 1.0) > GAIN_DETERMINED * gain_std:  # determined as the gain too, not only as `c`
            continue
        corrected = float(relative_equation_error(jnp.asarray(a_fit), jnp.asarray(ys[:, i]), candidate))
        _warn_scaled_stretch(
            (record_labels(trajectories)[r], trajectories[0].input_names[k], fine[i][2:]),
            (gain, gain_std),
            (error, inconsistent, corrected, kept),
            (trajectories[r : r + 1], settings[r : r + 1], counts[r : r + 1]),
        )
        return


def _coefficient_std(a, column, y, weights, record_rows) -> float:
    """The standard error, robust to serial correlation, of the coefficient of `column` fitted with `a`'s
    columns to `y` (weighted least squares, `weights` per row)."""
    sw = np.sqrt(np.asarray(weights, dtype=float))
    jac = np.column_stack([a, column]) * sw[:, None]
    z = np.linalg.lstsq(jac, y * sw, rcond=None)[0]
    total = int(sum(record_rows))
    if not total or jac.shape[0] % total:
        return float("inf")
    steps = np.arange(jac.shape[0]) % total
    covariance, _ = serial_covariance(jac, y * sw - jac @ z, steps, tuple(record_rows))
    return float(np.sqrt(max(float(np.asarray(covariance)[-1, -1]), 0.0)))


def _warn_scaled_stretch(where, gain, errors, record) -> None:
    """The warning of `_warn_if_input_scaled_partway`: `where = (file label, input, (cut row, after))`,
    `gain = (g, its standard error)`, `errors = (the stage's relative equation error, whether its estimate is
    inconsistent, the corrected equations' error, the
    joint fit's residual over the stage's right-hand side)` and `record = (trajectories, settings, counts)` of the one
    record."""
    label, input_name, (at, after) = where
    g, g_std = gain
    error, inconsistent, corrected, _ = errors
    turned = abs(g + 1.0) <= SIGN_TURN
    whole = False  # a stretch over nearly the whole of one record: the input's gain against the others
    if at == 0:
        where_text = "throughout"
        fix = (
            f"the other records agree with the model: correct its {'sign' if turned else 'scale'} in that file"
            + ("" if turned else f" (multiply its {input_name} by {1.0 / g:.4g})")
            + ", or leave it out"
        )
    else:
        times = row_times(*record)[0]
        t = float(times[at - 1] if after else times[at])  # the span to leave out holds both rows of the change
        about = time_label(t, 0.05, digits=4)
        where_text = (
            f"from about t = {about} s to the record's end" if after else f"from its start to about t = {about} s"
        )
        cut = time_label(t, float(np.median(np.diff(times))) / 10)
        span = f"{label}@{cut}:" if after else f"{label}@:{cut}"
        fix = (
            f"no scale is right for the whole record: leave the stretch out (`--exclude {span}`; in Python "
            f"`exclude_stretches`), or correct its {'sign' if turned else 'scale'} in the file"
        )
        rows = int(record[2][0])
        if 0 < (at if after else rows - at) <= rows / FLIP_STRETCHES:
            # The rest is shorter than the search's coarsest stretch: no change part way, the input's gain against
            # the other inputs throughout; leaving the stretch out would leave nothing.
            where_text, whole = f"over nearly the whole record ({where_text})", True
            factor = 1.0 / g
            fix = (
                "one record shows only its gain against the other inputs, and no stretch is at fault: if "
                f"{input_name}'s {'sign' if turned else 'torque constant or unit'} is off, "
                + (
                    f"negate it (`--scale {input_name}=-1`)"
                    if turned
                    else f"multiply it by {factor:.4g} (`--scale {input_name}={factor:.4g}`)"
                )
                + "; if another input's is, correct that one instead"
            )
    inconsistency = " and is physically inconsistent" if inconsistent else ""
    if turned:
        text = (
            f"file {label}: the recorded {input_name} looks reversed {where_text} (and agrees with the model's joint "
            f"positions elsewhere; gain {g:.3g} +- {g_std:.2g}): the least-squares estimate leaves an equation error "
            f"of {error:.0%}{inconsistency}, and with {input_name} negated there a consistent estimate's falls to "
            f"{corrected:.0%}. A motor's direction or a current's sign that changed while recording? If so, {fix}."
        )
    else:
        against = "the other inputs" if whole else "the other records" if at == 0 else "the rest of the record"
        cause = (
            "A torque constant, a unit or a gear of one input that is off?"
            if whole
            else "A current limit, a unit, a gear or a torque constant that changed while recording?"
        )
        text = (
            f"file {label}: the recorded {input_name} looks scaled by {g:.3g} +- {g_std:.2g} {where_text} against "
            f"{against} (it reads {g:.3g} times what the model's joint positions need there): the least-squares "
            f"estimate leaves an equation error of {error:.0%}{inconsistency}, and with {input_name} divided by "
            f"{g:.3g} there a consistent estimate's falls to {corrected:.0%}. {cause} If so, {fix}."
        )
    span = (
        None if at == 0 or whole else (t, None) if after else (None, t)
    )  # the open end: the record's (its held-out part too)
    warnings.warn(  # located: the command line writes the file, the input and the stretch into its JSON
        located(InconsistentEstimateWarning(text), file=label, column=input_name, times=span, fix=fix), stacklevel=8
    )


def _leaves_sizes_to_noise(system, names, equations, solve, estimate, record_rows) -> bool:
    """Whether the least-squares fit of `equations = (a, y, weights)` (by `solve(y)`) leaves a size parameter
    of `estimate` to the noise: a relative standard error, robust to serial correlation, above
    `POORLY_DETERMINED`."""
    a, y, weights = equations
    try:
        sizes = size_parameter_names(split_terms(system)[0])
        fit = solve(jnp.asarray(y))
    except (UsageError, IdentifiabilityError):
        return True
    std = _serially_robust(fit, a, y, weights, estimate, record_rows)[0].std_errors
    return bool(poorly_determined(names, np.asarray(estimate), np.asarray(std), sizes)) if sizes else False


# Angle units a logger writes instead of radians, each with the factor that makes radians: degrees, gradians,
# milliradians, and encoder counts (binary and decimal resolutions per turn, quadrature included).
_COUNTS_PER_TURN = (*(2**n for n in range(8, 25)), 1000, 2000, 2500, 4000, 5000, 10000, 20000, 40000, 100000)
ANGLE_UNITS = (
    ("degrees", np.pi / 180.0),
    ("gradians", np.pi / 200.0),
    ("milliradians", 1e-3),
    *((f"encoder counts ({n} a turn)", 2 * np.pi / n) for n in _COUNTS_PER_TURN),
)
MANY_TURNS = 4 * np.pi  # an angle's range beyond two turns: another unit is tried beside degrees


def _warn_if_angle_unit(given, trajectories, error) -> None:
    """Where the estimate is inconsistent, refit the records with each set of the system's joint
    angles (`angle_indices`; a two-link arm's both, a linear axis none) and their velocities read in
    another unit (degrees; where an angle spans more than two turns, also gradians, milliradians and
    encoder counts of the common resolutions, `ANGLE_UNITS`): if one gives a consistent estimate and at
    most `REVERSED_GAIN` of the equation error, warn that those angles look like that unit (the one of
    least equation error, where several explain it).

    Velocities are checked against their positions at load (`dynax._data._velocities`), but a file
    with both in degrees (or counts) passes that check, and the arm's equations, whose gravity and
    Coriolis terms are trigonometric in the angles, then fit nothing (a large equation error, and an
    estimate of near-zeros with small negative terms). One more least-squares stage per unit and set,
    built from scaled records; the units beyond degrees are tried only where an angle spans more than
    two turns, which an arm whose estimate is inconsistent rarely does in radians, and where they would
    make its span a readable motion (3 degrees to 30 turns).
    """
    base = split_terms(given[0])[0]
    names = tuple(trajectories[0].state_names)
    angles = [base.joint_names[k] for k in base.angle_indices if k < len(base.joint_names)]
    if not angles or any("d" + q not in names for q in angles):
        return
    joints = [(names.index(q), names.index("d" + q)) for q in angles]
    span = max(float(np.ptp(np.concatenate([np.asarray(t.xs[:, i]) for t in trajectories]))) for i, _ in joints)
    # degrees always; another unit where an angle spans two turns or more and would span between a few degrees
    # and about 30 turns in radians (a motion a fit can read, of an arm)
    units = [u for k, u in enumerate(ANGLE_UNITS) if k == 0 or (span > MANY_TURNS and 0.05 <= span * u[1] <= 200.0)]

    def refit(chosen, unit):
        factor = np.ones(len(names))
        factor[[c for j in chosen for c in joints[j]]] = unit
        scaled = [
            Trajectory(
                t.ts,
                t.xs * jnp.asarray(factor, t.xs.dtype)[None, :],
                t.us,
                t.state_names,
                t.input_names,
                t.system,
                t.source,
            )
            for t in trajectories
        ]
        refit = _consistent_refit(given, scaled)  # an inconsistent refit explains nothing (`_best_subset`)
        return None if refit is None else (True, refit, False)

    found = []
    for label, unit in units:
        best = _best_subset(len(joints), functools.partial(refit, unit=unit), error)
        if best is not None:
            found.append((best[1], label, unit, best[0]))
    if not found:
        return
    explained, label, unit, chosen = min(found, key=lambda f: f[0])
    which = [angles[j] for j in chosen]
    columns = [c for j in chosen for c in (angles[j], "d" + angles[j])]
    factor = f"{unit:.7g}"
    many = len(which) > 1
    warnings.warn(
        f"the joint angle{'s' if many else ''} {', '.join(which)} look{'' if many else 's'} "
        f"like {label}: the least-squares estimate is physically inconsistent, and with "
        f"{'them' if many else 'it'} "
        f"(and {'their' if many else 'its'} velocit{'ies' if many else 'y'}) read as {label} the "
        f"estimate is consistent and the equation error falls from {error:.0%} to {explained:.0%}. The contract's "
        "angles are radians: load the records with scale={"
        + ", ".join(f"'{c}': {factor}" for c in columns)
        + "} (`--scale "
        + ",".join(f"{c}={factor}" for c in columns)
        + "`).",
        InconsistentEstimateWarning,
        stacklevel=7,
    )


def _consistent_refit(given, records) -> float | None:
    """The relative equation error of the least-squares stage on `records` (another reading of the data: columns
    swapped, an angle made relative), or `None` where that estimate is inconsistent or not identifiable."""
    system, method, friction, weights, rcond = given
    try:
        with set_within(SEEN, None):
            stage = least_squares_stage(system, records, method, friction, weights, rcond, "off")
    except (IdentifiabilityError, UsageError):
        return None
    return float(relative_equation_error(stage.a, stage.y, stage.estimate)) if stage.consistency.consistent else None


def _warn_if_swapped(given, trajectories, error) -> None:
    """Where the estimate is inconsistent, refit the records with the two joints' columns swapped (`q1, dq1`
    for `q2, dq2`) and, where there are two inputs, with the inputs swapped (`tau1` for `tau2`), and with both
    (the joints numbered the other way round): if one gives
    a consistent estimate and at most `REVERSED_GAIN` of the equation error, warn that those columns look
    swapped, with the `--map` that swaps them back.

    A mapping that reads one motor's or encoder's column as the other's passes every check of the data
    (each column is a fine signal, each velocity the derivative of its angle) and least squares meets it
    with an estimate the consistency constraint squeezes towards zero, which names no cause. One more
    least-squares stage per candidate, built from the swapped records.
    """
    names, inputs = tuple(trajectories[0].state_names), tuple(trajectories[0].input_names)
    states, same_inputs = list(range(len(names))), list(range(len(inputs)))
    candidates = []
    if len(inputs) == 2:
        candidates.append(((inputs[0], inputs[1]), states, [1, 0]))
    if all(n in names for n in ("q1", "q2", "dq1", "dq2")):
        order = list(states)
        for a, b in (("q1", "q2"), ("dq1", "dq2")):
            order[names.index(a)], order[names.index(b)] = names.index(b), names.index(a)
        candidates.append((("q1", "q2", "dq1", "dq2"), order, same_inputs))
        if len(inputs) == 2:  # the joints named the other way round, motors and all
            candidates.append((("q1", "q2", "dq1", "dq2", inputs[0], inputs[1]), order, [1, 0]))

    found = []
    for columns, state_order, input_order in candidates:
        swapped = [
            Trajectory(
                t.ts, t.xs[:, state_order], t.us[:, input_order], t.state_names, t.input_names, t.system, t.source
            )
            for t in trajectories
        ]
        refit = _consistent_refit(given, swapped)
        if refit is not None and refit <= REVERSED_GAIN * error:
            found.append((refit, columns))
    if not found:
        return
    refit, columns = min(found)
    pairs = list(zip(columns[0::2], columns[1::2]))
    mapping = ",".join(f"{a}={b},{b}={a}" for a, b in pairs)
    warnings.warn(
        f"the columns read as {' and '.join(f'{a}, {b}' for a, b in pairs)} look swapped: the least-squares "
        f"estimate is physically inconsistent, and with each pair swapped it is consistent and the equation error "
        f"falls from {error:.0%} to {refit:.0%}. A mapping that reads one joint's (or motor's) column as the "
        f"other's? If so, swap them back (`--map {mapping}` for a file with the contract's names; in Python "
        "`mapping=`).",
        InconsistentEstimateWarning,
        stacklevel=7,
    )


def _warn_if_absolute(given, trajectories, error) -> None:
    """Where a two-link arm's estimate is inconsistent, refit the records with `q2, dq2` read as link 2's absolute
    angle and rate (from the vertical, as a motion-capture system or an IMU on the link measures them): the elbow's
    `q2 - q1`, `dq2 - dq1`. If that gives a consistent estimate and at most `REVERSED_GAIN` of the equation error,
    warn that `q2` looks absolute. The contract's `q2` is the elbow's angle relative to link 1; an absolute one
    passes every check of the data and meets least squares with an estimate that names no cause. One more
    least-squares stage, built from the converted records."""
    names = tuple(trajectories[0].state_names)
    if not all(n in names for n in ("q1", "q2", "dq1", "dq2")):
        return
    convert = np.eye(len(names))
    convert[names.index("q1"), names.index("q2")] = -1.0  # new[:, q2] = q2 - q1 (x @ convert)
    convert[names.index("dq1"), names.index("dq2")] = -1.0
    relative = [
        Trajectory(
            t.ts, t.xs @ jnp.asarray(convert, t.xs.dtype), t.us, t.state_names, t.input_names, t.system, t.source
        )
        for t in trajectories
    ]
    refit = _consistent_refit(given, relative)
    if refit is None or refit > REVERSED_GAIN * error:
        return
    warnings.warn(
        f"q2 looks like link 2's absolute angle (from the vertical), not the elbow's angle relative to link 1: the "
        f"least-squares estimate is physically inconsistent, and with q2 - q1 and dq2 - dq1 in their place it is "
        f"consistent and the equation error falls from {error:.0%} to {refit:.0%}. The contract's q2 is relative: "
        "subtract q1 from q2 and dq1 from dq2 in the records before loading (no --scale or --map does it).",
        InconsistentEstimateWarning,
        stacklevel=7,
    )


UPRIGHT_DETERMINED = 10.0  # each negated parameter this many standard errors from zero


def _warn_if_zero_upright(fitted, names, estimate, std, qs) -> None:
    """Where an arm's estimate is inconsistent, warn when its angles look measured from upright:
    negating the base parameters such a zero negates (the system's `upright_zero_signs`) makes the
    estimate consistent, and each is far (`UPRIGHT_DETERMINED` standard errors) from zero.

    The contract's angles are 0 hanging down; a rig calibrated for balancing often reads 0 upright.
    That is an exact change of sign of two gravity or geometry terms (q1 shifted by pi negates
    theta4 and theta5 and leaves everything else as it was),
    so nothing in the equations tells it from a physically impossible arm; the physics does, and a
    gravity term decided to 1 % is not noise. (An unfiltered fit of noisy records, inconsistent from noise,
    has small negative gravity terms and a negative friction as well, and is not named.)
    """
    signs = split_terms(fitted)[0].upright_zero_signs()
    estimate, std = np.asarray(estimate, dtype=float), np.asarray(std, dtype=float)
    for joints, flipped in signs.items():
        if any(n not in names for n in flipped):
            continue
        index = [names.index(n) for n in flipped]
        if not all(estimate[i] < 0 and abs(estimate[i]) > UPRIGHT_DETERMINED * std[i] for i in index):
            continue
        candidate = estimate.copy()
        candidate[index] = -candidate[index]
        system = fitted_system(fitted, names, jnp.asarray(candidate))
        if check_consistency(system, names, candidate, qs, warn=False).violated:
            continue
        warnings.warn(
            f"the joint angle{'s' if len(joints) > 1 else ''} {', '.join(joints)} look{'' if len(joints) > 1 else 's'} "
            f"measured from upright: the least-squares estimate is physically inconsistent only in the signs of "
            f"{' and '.join(flipped)} "
            f"({', '.join(f'{n} = {estimate[i]:.4g} +- {std[i]:.2g}' for n, i in zip(flipped, index))}), "
            "which a zero at upright reverses exactly; with them positive it is consistent. The contract's angles are "
            f"0 hanging straight down: load the records with offset={{"
            + ", ".join(f"'{j}': {np.pi:.6f}" for j in joints)
            + "} (`--offset "
            + ",".join(f"{j}={np.pi:.6f}" for j in joints)
            + "`).",
            InconsistentEstimateWarning,
            stacklevel=7,
        )
        return
