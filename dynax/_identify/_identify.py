r"""`identify(system, data, method=...)`: fit a system's parameters to measured trajectories.

`identify` is prepare -> fit -> refine -> validate, and asks the method (an `AbstractMethod`) what
to run: a method whose `least_squares_stage` is set (`Dynamic()`, `Power()`, `Energy()`, whose
equations `dynax._identify._equations` builds) runs the least-squares stage (`_ls_stage.py`:
force offsets or angle zeros, checked for physical consistency and constrained to it), then on real
two-link arm data the output-error refinement (`_refine.py`); any other method (`SimulationFit()`,
or one of a user's own) is its `fit`, checked for consistency. Every result is validated by
open-loop simulation on held-out records (`_validation.py`) and returned as an `Identification`
(`_result.py`).
"""

from collections.abc import Sequence
import dataclasses
import typing
from typing import Literal
import warnings

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from .._data._sampling import check_time_stamps
from .._data._spectra import choose_filter
from .._data._trajectory import Trajectory
from .._data._velocities import check_trajectory_velocities
from .._errors import DataError, UsageError
from .._model._extensions import Extended
from .._model._linear_axis import LinearAxis
from .._model._linear_in_parameters import size_parameter_names
from .._model._system import AbstractSystem
from .._model._two_link import Acrobot, DoublePendulum
from .._precision import warn_if_float32
from .._simulate import FixedGrid
from ._angle_zeros import AngleZeros, record_angle_zeros
from ._angle_zeros import applies as _angle_zeros_apply
from ._consistency import check_consistency, Consistency
from ._equations import AbstractLeastSquares, Dynamic, stacked_equations, uniformly_sampled
from ._least_squares import (
    describe_poorly_determined,
    IdentifiabilityError,
    jointly_determined,
    POORLY_DETERMINED,
    poorly_determined,
    PoorlyDeterminedWarning,
)
from ._ls_stage import (
    joint_positions,
    least_squares_stage,
    less_offsets,
    offsets_json,
    relative_equation_error,
)
from ._method import AbstractMethod, FitSettings
from ._offsets import record_labels, without_offsets
from ._refine import refine_by_simulation
from ._regressors import Friction, split_terms
from ._result import Identification, NoValidationWarning, RecordsDisagreeWarning, Stage, StageKind
from ._simulation_fit import SimulationFit
from ._static_friction import (
    describe,
    joint_levels,
    not_added,
    record_rests,
    rests_under_load,
    speeds_zeroed_at_rest,
    StaticFriction,
    with_stiction,
)
from ._validation import held_out_error, split_for_validation, Validate

_SYSTEM_NAMES = {Acrobot: "acrobot", DoublePendulum: "double_pendulum", LinearAxis: "linear_axis"}


def _as_list(data) -> list[Trajectory]:
    if isinstance(data, Trajectory):
        return [data]
    if isinstance(data, Sequence) and data and all(isinstance(d, Trajectory) for d in data):
        return list(data)
    raise UsageError(
        f"identify: `data` must be a Trajectory or a non-empty list of Trajectory, got {type(data).__name__}"
    )


MIN_RECORD_SAMPLES = 3  # the fewest samples a derivative is estimated from; fewer fail in every method


def _check_data(system, trajectories):
    if not trajectories:
        raise UsageError("identify: no records given")
    for k, traj in enumerate(trajectories):
        if len(traj) < MIN_RECORD_SAMPLES:
            raise DataError(
                f"record {k} has {len(traj)} sample(s): too few for a fit (at least {MIN_RECORD_SAMPLES} "
                "for a derivative, and as many equations as parameters)",
                path=traj.source or None,
            )
        # A record built in Python has not met the loader's time checks: times that do not increase are refused
        # here (irregular steps and gaps are the caller's to allow), before any derivative divides by a step.
        try:
            check_time_stamps(traj.ts, path=traj.source or None, max_gap=None, min_step=None)
        except DataError as error:
            if traj.source:
                raise
            raise UsageError(f"identify: record {k} of `data`: {error}") from None
    for k, traj in enumerate(trajectories):
        if traj.xs.shape[1] != system.n_states or traj.us.shape[1] != system.n_inputs:
            raise UsageError(
                f"identify: trajectory {k} has {traj.xs.shape[1]} states and {traj.us.shape[1]} inputs "
                f"({traj.state_names}, {traj.input_names}) but {type(system).__name__} has "
                f"{system.state_names} and {system.input_names}"
            )
        check_trajectory_velocities(traj)  # a velocity in other units than its position: refused, named


def _system_name(system):
    base = system.system if isinstance(system, Extended) else system
    return _SYSTEM_NAMES.get(type(base), type(base).__name__)


_CONSISTENCY = ("constrain", "check", "off")


RECORDS_DISAGREE = 2.5  # record-jackknife over within-record standard error that says the records differ


def _records_disagree(refined) -> dict[str, float]:
    r"""The parameters whose delete-one-record standard error exceeds the within-record one
    `RECORDS_DISAGREE` times, name -> ratio, with a warning naming them.

    With $G$ records that agree, $(G-1)$ times the squared ratio is about $\chi^2_{G-1}$: a ratio of
    2.5 has $p \approx 3 \cdot 10^{-4}$ per parameter with four records, 0.002 with three (measured on
    MuJoCo records of one arm: at most 2.0 over ten parameters; with the dry friction changed for
    each record, 2.5 to 6.6 on the Coulomb friction, $\theta_2$ and $\theta_5$)."""
    record_std = refined.statistics.record_std_errors
    if record_std is None:
        return {}
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.asarray(record_std) / np.asarray(refined.std_errors)
    out = {n: float(r) for n, r in zip(refined.names, ratio) if np.isfinite(r) and r > RECORDS_DISAGREE}
    if out:
        cells = ", ".join(f"{n} ({r:.1f}x)" for n, r in out.items())
        warnings.warn(
            f"the records disagree more than their noise explains: leaving one record out moves {cells} by more "
            f"than {RECORDS_DISAGREE:g} times the standard error estimated within the records. Something changed "
            "between the recordings (friction, an offset, a payload): read `record_std_errors` as these "
            "parameters' uncertainty, and validate on a recording of another day.",
            RecordsDisagreeWarning,
            stacklevel=4,
        )
    return out


def _signal_band_hz(trajectories) -> float | None:
    """The widest velocity signal band over the records, or `None` when no record's velocities are noisy."""
    bands = [
        c.cutoff_hz for c in (choose_filter(uniformly_sampled(t)) for t in trajectories) if c.cutoff_hz is not None
    ]
    return max(bands) if bands else None


STAGGER = 4  # staggered cuts of the records into segments in the default refinement


def _refinement_method(refine, system, method, trajectories):
    """The `SimulationFit` that refines the least-squares estimate, or `None`.

    `"auto"`: two-link arms whose velocities carry measurement noise (real data), with segments of
    one period of the signal band's edge (long enough to show the motion, short enough that a
    chaotic run's divergence does not swamp the fit) in `STAGGER` staggered cuts, 60
    Levenberg-Marquardt steps, and 4 integrator steps per sample.
    """
    if refine is None or refine is False:
        return None
    arm = split_terms(system)[0].refinement_terms() is not None
    if not (refine is True or isinstance(refine, SimulationFit) or (isinstance(refine, str) and refine == "auto")):
        raise UsageError(f"identify: `refine` must be 'auto', True, False or a SimulationFit(), got {refine!r}")
    if not arm:
        if isinstance(refine, str):
            return None
        raise UsageError(
            "identify: the output-error refinement is for two-link arms; use SimulationFit() as the method"
        )
    if isinstance(refine, SimulationFit):
        return refine
    band = _signal_band_hz(trajectories)
    if band is None and isinstance(refine, str):
        return None  # noise-free velocities: least squares is not biased, nothing to refine
    segment = 1.0 / band if band is not None else 0.25
    # Four integrator steps per sample of the fitted grid (40 per band period): the smoothed Coulomb
    # friction (tanh at 0.01 rad/s) is stiff, and two steps left a visible bias on synthetic data.
    # Four staggered cuts into segments: with one, where the segments start moves a real rig's
    # held-out error by several per cent; with four, by a third of that.
    return SimulationFit(
        segment_s=segment, fit_initial_states=False, max_steps=60, simulation=FixedGrid(substeps=4), stagger=STAGGER
    )


def _validation_split(system, trajectories, settings: Validate, weights):
    """`(fitted, held, source, horizons)`: the records to fit, the held-out records, what they are
    and the horizons to validate at.

    The `validation` records when given (all of the data is fitted); otherwise the last `holdout`
    fraction of each record (`"auto"`: 0.2, or 0 when row weights are given: they index every row).
    Where no record (tail) is longer than the longest horizon, the horizons the longest one holds
    (a 1.5 s record's last 0.3 s: 0.1 and 0.25 s); where it holds none, a warning says that
    nothing is validated and why (`source`, with `held` empty: `identify` warns it once the fit is done)."""
    validation, holdout, horizons_s = settings.records, settings.holdout, settings.horizons_s
    if validation is not None:
        held = _as_list(validation)
        _check_data(system, held)
        usable, _ = _horizons_held(held, horizons_s)
        if usable == horizons_s:
            return trajectories, held, "validation records", horizons_s
        if not usable:
            lengths = ", ".join(f"{name} {r.duration:.3g} s" for name, r in zip(record_labels(held), held))
            raise DataError(
                f"identify: the validation records are too short for the shortest horizon "
                f"({min(horizons_s):g} s): {lengths}"
            )
        return (
            trajectories,
            held,
            f"validation records; horizons up to {max(usable):g} s, as long as the records allow",
            usable,
        )
    fraction = (0.0 if weights is not None else 0.2) if holdout == "auto" else float(holdout)
    if fraction <= 0:
        return trajectories, [], "", horizons_s
    usable, longest = _horizons_held([r.split(1 - fraction)[1] for r in trajectories], horizons_s)
    if not usable:
        return (
            trajectories,
            [],
            (
                f"nothing is held out for validation: the last {fraction:.0%} of every record is at "
                f"most {max(longest, 0.0):.3g} s long, shorter than the shortest horizon "
                f"({min(horizons_s):g} s); give a record of its own as `validation` (CLI: "
                "--validation), or longer records"
            ),
            horizons_s,
        )
    fitted, held = split_for_validation(trajectories, fraction, max(usable))
    source = f"held-out last {fraction:.0%} of each record (not fitted)"
    if usable != horizons_s:
        source += f"; horizons up to {max(usable):g} s, as long as the tails allow"
    return fitted, held, source, usable


def _horizons_held(records, horizons_s) -> tuple[tuple[float, ...], float]:
    """`(usable, longest)`: the horizons at which `held_out_error` can validate on `records` (shorter
    than the longest record less one interval: it skips a record no longer than its horizon and a
    step), and that length."""
    longest = max((r.duration - r.dt for r in records if len(r) > 1), default=0.0)
    return tuple(h for h in horizons_s if h < longest), longest


def _fitted_once(system, fitted, method, settings, consistency, validate) -> Identification:
    """`identify` by a method without a least-squares stage: its `fit`, the estimate's consistency
    check where the system has conditions, and the held-out validation."""
    solution = method.fit(system, fitted, settings)
    check = None
    if _has_conditions(system):
        qs = joint_positions(solution.model, fitted)
        check = check_consistency(
            solution.model, solution.names, jnp.asarray(solution.value), qs, warn=consistency != "off"
        )
    stage = Stage(
        StageKind(method.stage_kind),
        method.label,
        solution,
        consistency=check,
        validation=validate(solution.model),
    )
    return Identification(
        system=solution.model,
        stages=(stage,),
        n_samples=method.n_samples(solution, fitted),
        friction=settings.friction,
        system_name=_system_name(system),
    )


def _refined_stage(ls, start, records, method, friction, consistency, refinement, validate) -> Stage:
    """The output-error refinement from the least-squares stage `ls` (its model `start`, with `Stiction`
    where the records rest under load) on `records = (fitted, simulated)` (the fitted records, and as the
    simulation sees them), with its equation error on the least-squares rows of `fitted`, consistency and
    validation."""
    fitted, simulated = records
    refined = refine_by_simulation(start, ls.names, simulated, refinement)
    estimate = jnp.asarray(refined.value)
    _, a, y, _, _, _, _, _, _, _ = stacked_equations(refined.model, fitted, method, friction, None, method.rcond)
    if ls.groups is not None:  # the same equations as the least-squares stage's: offsets free
        a, y, _, _ = without_offsets(a, y, None, ls.groups)
    error = relative_equation_error(jnp.asarray(a), jnp.asarray(y), estimate)
    qs = joint_positions(refined.model, fitted)
    check = check_consistency(refined.model, refined.names, estimate, qs, warn=consistency != "off")
    check = Consistency(check.violated, active=(), constrained=True, min_mass_eigenvalue=check.min_mass_eigenvalue)
    return Stage(
        StageKind.OUTPUT_ERROR,
        "simulation",
        refined,
        relative_equation_error=float(error),
        validation=validate(refined.model),
        consistency=check,
        records_disagree=_records_disagree(refined),
    )


def identify(
    system: AbstractSystem,
    data: Trajectory | Sequence[Trajectory],
    method: AbstractMethod = Dynamic(),
    *,
    friction: Friction = "viscous",
    weights: Float[Array, " rows"] | None = None,
    consistency: Literal["constrain", "check", "off"] = "constrain",
    refine="auto",
    validation: Validate | Trajectory | Sequence[Trajectory] | None = None,
) -> Identification:
    r"""Fit the parameters of `system` to measured trajectories, and validate the result.

    The least-squares methods (`Dynamic`, `Power`, `Energy`) build the linear-in-parameter model
    of each trajectory, stack the rows of all of them and solve one weighted least-squares problem
    (QR and SVD of the column-scaled regressor); they return standard errors from the residual
    variance, the condition number and the numerical rank. `SimulationFit` minimises the
    simulation error through the integrator instead (see `fit_simulation_error`).

    By default, on top:

    - `Dynamic`'s filter and derivative settings are chosen per record from its spectra
      (`choose_filter`) and reported in `settings`;
    - the estimate is checked for physical consistency (`check_consistency`); an inconsistent
      least-squares estimate is replaced by the constrained fit over the consistent set
      (`consistent_least_squares`), and `consistency.active` names what had to be enforced;
    - `Dynamic` estimates one constant offset of the recorded force per record and driven joint
      with the parameters (`Dynamic(offsets=...)`; reported in the least-squares stage, not part
      of the model), or, on an arm whose every joint is a driven angle and where they leave the
      smaller equation error, one zero of each angle per record (`angle_zeros`: encoders zeroed
      where the arm stood when each recording began); both stages then fit the records less them;
    - for two-link arms whose velocities carry measurement noise (real data), the least-squares
      estimate is refined by the output-error fit with the elbow motor's rotor inertia and the
      input timing, consistent by construction (`refine_by_simulation`, on the records less their
      offsets), and both stages are reported;
    - the returned model is simulated open loop on held-out data (`validation`, or the last 20 %
      of each record, which then does not enter the fit) and the position RMSE against horizon is
      reported next to the equation error;
    - with `Dynamic` on two records or more, each record's constant offset on each joint's
      recorded force is estimated (from each half of the record too) and tested for differing
      between records (`record_offsets`, a sensor zero that changes from one recording to the
      next), with a note where they do.

    **Arguments:**

    - `system`: `Acrobot`, `DoublePendulum` or `LinearAxis` (least squares), or any system
      (`SimulationFit`; a `Helicopter` also with a vehicle criterion, `OneStep()`, `Lagged()`, ...,
      which then fits the one record as `fit_vehicle` does). Its parameter values are the starting
      point of `SimulationFit` and are otherwise ignored.
    - `data`: a `Trajectory` or a list of them (same system).
    - `method`: `Dynamic()` (default), `Power()`, `Energy()`, `SimulationFit()`, or any other
      `AbstractMethod`: `identify` runs its `fit` once (with `friction` and `weights` in a
      `FitSettings`), checks the estimate's consistency where the system has conditions, and
      validates the fitted model.
    - `friction`: `"viscous"` (default) or `"coulomb"` (adds `fc1`, `fc2`, or the linear axis's
      `coulomb`).
    - `weights`: optional row weights for the least-squares problem, one per stacked equation
      (for `Dynamic`, all of joint 1's equations come first, then joint 2's). The numerical rank's
      threshold is the method's `rcond`.
    - `consistency`: `"constrain"` (default: fit over the consistent set when the plain estimate
      is inconsistent), `"check"` (return the plain estimate; warn with
      `InconsistentEstimateWarning` naming each violated condition) or `"off"`. With either of
      the first two, an inconsistent plain estimate is also tested for a reversed input and, on a
      two-link arm, for angles in degrees or measured from upright; one that explains it is named
      in an `InconsistentEstimateWarning` with the fix.
    - `refine`: `"auto"` (default: refine two-link arms on noisy data), `True`, `False`, or the
      `SimulationFit` settings to refine with.
    - `validation`: a `Validate`: held-out records (when given, all of `data` is fitted), or else
      the fraction of each record held out at its end (default: the last 20 %, none with row
      `weights`; `Validate(holdout=0)` fits everything and reports no validation), and the horizons
      (default 0.1, 0.25, 0.5 s). Records alone are `Validate(records)`.

    **Returns:** an `Identification`.

    **Raises:** `IdentifiabilityError` (a `DataError`) when the data do not determine all
    parameters, naming the unidentified combinations; `DataError` when a record is too short;
    `UsageError` for a system or method that does not fit.
    """
    warn_if_float32("identification")  # the float64 policy: say so, once, naming the switch
    if not isinstance(method, AbstractMethod):
        raise UsageError(
            f"identify: `method` must be Dynamic(), Power(), Energy(), SimulationFit() or another AbstractMethod, "
            f"got {type(method).__name__}"
        )

    trajectories = _as_list(data)
    _check_data(system, trajectories)
    from .._data._sanity import check_records

    # located faults (a glitch, a stuck sensor, a stretch where a velocity is not its angle's derivative): said
    if not isinstance(validation, Validate):  # records alone, or none
        validation = Validate(validation)
    check_records(trajectories, _as_list(validation.records) if validation.records is not None else ()).warn(
        stacklevel=2
    )
    if consistency not in _CONSISTENCY:
        raise UsageError(f"identify: `consistency` must be one of {_CONSISTENCY}, got {consistency!r}")
    fitted, held, source, horizons_s = _validation_split(system, trajectories, validation, weights)

    def validate(model):
        return held_out_error(model, held, horizons_s, source=source) if held else None

    if not method.least_squares_stage:
        result = _fitted_once(system, fitted, method, FitSettings(friction, weights), consistency, validate)
        _warn_unvalidated(held, source)
        return result

    method = typing.cast(AbstractLeastSquares, method)  # `least_squares_stage` says so
    rcond = method.rcond
    zeros = _record_angle_zeros(system, fitted, method, friction, rcond)
    if zeros is not None and zeros.chosen:  # both stages fit the records less their angle zeros
        if validation.records is None and held:  # a held-out tail is read from its record's zero: less it too
            owners = [i for i, (whole, head) in enumerate(zip(trajectories, fitted)) if len(head) < len(whole)]
            held = zeros.corrected(held, system, owners)
            source += "; each tail less its record's angle zeros, fitted on its head"
        fitted = zeros.corrected(fitted, system)
        method = dataclasses.replace(method, offsets=False)
    rests = record_rests(fitted) if _holds_at_rest(system) else None
    ls = least_squares_stage(system, fitted, method, friction, weights, rcond, consistency)
    static = _static_friction(ls, fitted, rests)
    if static is not None and static.joints and not method.adds_static_friction:
        static = not_added(static)
    if static is not None and static.joints and method.refits_without_loaded_rests:
        # Refit without the rows of the rests under load (no law of the speed explains a held torque), and
        # read the rests again with that fit's gravity. A rest that holds nothing is an equation like any other.
        loaded = _loaded_rests(static, rests, record_labels(fitted))
        try:
            ls = least_squares_stage(system, fitted, method, friction, weights, rcond, consistency, loaded)
            static = _static_friction(ls, fitted, rests)
        except IdentifiabilityError:  # the records rest throughout: the rows at rest are all there is
            static = dataclasses.replace(
                static,
                note=f"{static.note}; the dynamic rows at rest are kept: without them the records identify nothing",
            )
    if static is not None and not static.stretches and held:
        unfitted = sum(s.duration for stretches in record_rests(held) for s in stretches)
        if unfitted:
            static = dataclasses.replace(
                static,
                note=f"{static.note}; the held-out records rest {unfitted:.2f} s, which is not fitted (fit all "
                "of the data, or validate on other records, to read a static level from it)",
            )
    ls_model = with_stiction(ls.system, static.joints) if static is not None else ls.system
    solution = eqx.tree_at(lambda s: (s.model, s.value), ls.fit, (ls.estimate, jnp.asarray(ls.estimate)))
    poorly = _size_errors(system, ls.names, ls.estimate, ls.fit.std_errors)  # the returned estimate's, unless refined
    stages = (
        Stage(
            StageKind.LEAST_SQUARES,
            ls.label,
            solution,
            relative_equation_error=float(relative_equation_error(ls.a, ls.y, ls.estimate)),
            validation=validate(ls_model),
            consistency=ls.consistency,
            poorly_determined=poorly,
            offsets=offsets_json(ls, fitted),
            angle_zeros=zeros,
            serial_correlation=ls.serial,
        ),
    )
    system_out = ls_model
    refinement = _refinement_method(refine, ls.system, method, fitted)
    if refinement is not None:
        simulated = less_offsets(ls.system, fitted, ls)
        if static is not None and static.joints:  # windows that start at rest start at zero speed there
            simulated = speeds_zeroed_at_rest(ls.system, simulated, rests)
        refined = _refined_stage(ls, ls_model, (fitted, simulated), method, friction, consistency, refinement, validate)
        statistics = refined.solution.statistics
        refined_poorly = _size_errors(
            system, refined.names, refined.solution.value, refined.solution.std_errors, statistics.record_std_errors
        )
        stages += (dataclasses.replace(refined, poorly_determined=refined_poorly),)
        system_out = refined.solution.model
        if not refined.kept_start:  # a kept least-squares model is judged by its own errors
            poorly = refined_poorly
        if static is not None and static.joints:
            levels = dict(zip(refined.names, np.asarray(refined.solution.value)))
            static = dataclasses.replace(
                static,
                joints=tuple(dataclasses.replace(j, refined=float(levels[j.name])) for j in static.joints),
            )
    _warn_poorly_determined(poorly)
    _warn_unvalidated(held, source)
    final = stages[-1].solution
    covariance = final.covariance
    jointly = (
        jointly_determined(final.names, covariance)
        if covariance is not None and np.shape(covariance)[0] == len(final.names)
        else None
    )
    return Identification(
        system=system_out,
        stages=stages,
        n_samples=ls.n_samples,
        friction=friction,
        system_name=_system_name(system),
        settings=ls.settings,
        record_offsets=ls.offsets,
        angle_zeros=zeros,
        record_friction=ls.friction,
        poorly_determined=poorly,
        jointly_determined=jointly,
        static_friction=static,
    )


def _holds_at_rest(system) -> bool:
    """Whether `identify` looks for friction at rest on `system`: the arms its refinement knows."""
    try:
        return split_terms(system)[0].refinement_terms() is not None
    except UsageError:
        return False


def _static_friction(ls, records, rests) -> StaticFriction | None:
    """What the records show of friction at rest (`dynax._identify._static_friction`), read with the
    least-squares model from the records less their fitted offsets; `None` where not looked for."""
    if rests is None:
        return None
    left_out, rows = ls.rest_rows
    if not any(rests):
        return StaticFriction((), (), left_out, rows, describe((), (), left_out, rows))
    stretches = rests_under_load(
        ls.system,
        ls.names,
        ls.estimate,
        ls.fit.covariance,
        less_offsets(ls.system, records, ls),
        rests,
        record_labels(records),
    )
    joints = joint_levels(stretches)
    return StaticFriction(stretches, joints, left_out, rows, describe(stretches, joints, left_out, rows))


def _loaded_rests(static: StaticFriction, rests, labels):
    """Each record's rest stretches that `static` found under load."""
    loaded = {(s.record, s.joint, s.start_s) for s in static.stretches if s.loaded}
    return [tuple(r for r in record if (label, r.joint, r.start_s) in loaded) for record, label in zip(rests, labels)]


def _record_angle_zeros(system, records, method, friction, rcond) -> AngleZeros | None:
    """Each record's angle zeros (`record_angle_zeros`) where the method's `angle_zeros_mode` lets them
    be fitted on this system (`Dynamic`: `offsets="angles"`, or `"auto"` with the settings chosen from
    the data on an arm whose every joint is a driven angle, then weighed against force offsets); else
    `None`."""
    mode = method.angle_zeros_mode
    if mode is None:
        return None
    if not _angle_zeros_apply(system):
        if mode == "always":
            raise UsageError(
                f"Dynamic(offsets='angles'): {type(split_terms(system)[0]).__name__} is not an arm whose every "
                "joint is an angle that an input drives"
            )
        return None
    return record_angle_zeros(system, records, method, friction, rcond, compare=mode == "compare")


def _size_errors(system, names, estimate, std, record_std=None) -> dict[str, float] | None:
    """`poorly_determined` of an estimate's size parameters, judged by the larger of its standard
    error and its leave-one-record-out error (`record_std`, where there is one); `None` for a system
    without size parameters."""
    try:
        sizes = size_parameter_names(split_terms(system)[0])
    except UsageError:
        return None
    if not sizes:
        return None
    std = np.asarray(std, dtype=float)
    if record_std is not None:
        std = np.fmax(std, np.asarray(record_std, dtype=float))
    return poorly_determined(names, estimate, std, sizes)


def _warn_unvalidated(held, source) -> None:
    """`NoValidationWarning` where a holdout was asked for and nothing could be held out (`source` says why)."""
    if not held and source:
        warnings.warn(f"identify: {source}", NoValidationWarning, stacklevel=3)


def _warn_poorly_determined(poorly: dict[str, float] | None) -> None:
    """A `PoorlyDeterminedWarning` naming the returned estimate's size parameters that the data leave
    to the noise (`_size_errors`).

    Judged on what `identify` returns: after the output-error refinement, on its standard errors
    (clustered over segments) and the leave-one-record-out ones where larger. The least-squares
    stage's own errors see only the noise in the torques; where the filter and the differentiated
    velocities bias its estimate they say nothing of it (a single short run can give small
    least-squares errors on an estimate tens of per cent off, which the refined errors show;
    docs/devdocs/identification_notes.md)."""
    if poorly:
        warnings.warn(
            f"the data determine these size parameters poorly (relative standard error above "
            f"{100 * POORLY_DETERMINED:.0f} %): {describe_poorly_determined(poorly)}. Noise, model error or the "
            "consistency constraint, not the motion, sets their estimates. Usually the records hardly excite them: "
            "record more motion in every joint (larger, richer inputs, longer records, more records) before trusting "
            "them; otherwise the model misses something large (see the relative equation error).",
            PoorlyDeterminedWarning,
            stacklevel=3,
        )


def _has_conditions(system):
    """Whether the least-squares models know `system` and it has physical-consistency conditions."""
    try:
        base, _ = split_terms(system)
    except UsageError:
        return False
    return bool(base.base_parameter_kinds())
