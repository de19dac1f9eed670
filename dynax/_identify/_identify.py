r"""`identify(system, data, method=...)`: fit a system's parameters to measured trajectories.

`identify` is prepare -> fit -> refine -> validate for every method and system, vehicles included
(`fit_vehicle`, `fit_quadrotor` and `dynax fit` are its vehicle spellings), and asks the method (an
`AbstractMethod`) what to run: it checks the records, splits off the held-out data and hands the
method the rest with an `IdentifyJob` (the fit's settings, the held-out records, the consistency
and refinement choices); then it calls the method's `prepare` (the records as the fit reads them),
`fit_stage` (the first stage) and `refine` (the stages after it) in turn (`_stages.py`: any
method's `fit` once, checked for consistency; the least-squares methods' angle zeros, least-squares
stage with friction at rest, and output-error refinement; the vehicle criteria's joined flights),
and validates each stage's model on the held-out records itself (each as the method's `prepare` says:
the vehicle criteria score flights by the vehicle horizon error), returning an `Identification` (`_result.py`).
"""

from collections.abc import Sequence
import contextlib
import dataclasses
from typing import Literal
import warnings

from .._compiled_code import release_compiled_code
from .._data._sampling import check_time_stamps
from .._data._spectra import filter_rule
from .._data._trajectory import check_record_columns, check_record_values, Trajectory
from .._data._velocities import check_trajectory_velocities
from .._errors import DataError, UsageError
from .._model._extensions import Extended
from .._model._linear_axis import LinearAxis
from .._model._system import AbstractSystem
from .._model._two_link import Acrobot, DoublePendulum
from .._precision import warn_if_float32
from ._equations import Dynamic
from ._method import AbstractMethod, FitSettings, Fitted, IdentifyJob
from ._offsets import record_labels
from ._regressors import Friction
from ._result import Identification, NoValidationWarning, warn_if_refinement_left_equations
from ._validation import HeldOut, split_for_validation, Validate

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
    if not isinstance(system, AbstractSystem):
        raise UsageError(f"identify: `system` must be a dynax system instance (e.g. `Acrobot()`), got {system!r:.80}")
    if not trajectories:
        raise UsageError("identify: no records given")
    for k, traj in enumerate(trajectories):
        if not isinstance(traj, Trajectory):
            raise UsageError(f"identify: record {k} must be a Trajectory, got {type(traj).__name__}")
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
    optional = len(system.optional_inputs)  # inputs a record may leave out (a quadrotor's vbat)
    for k, traj in enumerate(trajectories):
        if traj.xs.shape[1] != system.n_states or not system.n_inputs - optional <= traj.us.shape[1] <= system.n_inputs:
            raise UsageError(
                f"identify: trajectory {k} has {traj.xs.shape[1]} states and {traj.us.shape[1]} inputs "
                f"({traj.state_names}, {traj.input_names}) but {type(system).__name__} has "
                f"{system.state_names} and {system.input_names}"
            )
        check_record_columns(traj, system, "identify", f"trajectory {k}")
        check_record_values(traj, "identify", f"record {k}")
        check_trajectory_velocities(traj)  # a velocity in other units than its position: refused, named


def _system_name(system):
    base = system.system if isinstance(system, Extended) else system
    return _SYSTEM_NAMES.get(type(base), type(base).__name__)


_CONSISTENCY = ("constrain", "check", "off")


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


def identify(
    system: AbstractSystem,
    data: Trajectory | Sequence[Trajectory],
    method: AbstractMethod = Dynamic(),
    *,
    friction: Friction | None = None,
    settings: FitSettings = FitSettings(),
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
      (`SimulationFit`); a vehicle (`Helicopter`, `Quadrotor`) with a vehicle criterion
      (`OneStep()`, `Lagged()`, `Backprop()`, `FrequencyDomain()`: the helicopter's only). Its
      parameter values are the starting point of `SimulationFit` and of a warm-started vehicle
      criterion, and are otherwise ignored.
    - `data`: a `Trajectory` or a list of them (same system). A vehicle criterion fits one record:
      several (flights, or a flight's usable runs) are joined in the vehicle's body-frame
      coordinates, no window crossing from one to the next (as `fit_quadrotor` does).
    - `method`: `Dynamic()` (default), `Power()`, `Energy()`, `SimulationFit()`, or any other
      `AbstractMethod`: `identify` runs the method's `prepare`, `fit_stage` and `refine` (by
      default the records as given, its `fit` once with `settings` and the estimate's consistency
      checked where the system has conditions, and nothing to refine; the least-squares methods
      run the stages above, the vehicle criteria join the flights), then validates each stage's
      model.
    - `friction`: `"viscous"` (the default) or `"coulomb"` (adds `fc1`, `fc2`, or the linear
      axis's `coulomb`); the same as `settings.friction`.
    - `settings`: a `FitSettings`, what the fit reads beyond the method's own settings: row
      `weights` for the least-squares problem (one per stacked equation; for `Dynamic`, all of
      joint 1's equations come first, then joint 2's; the numerical rank's threshold is the
      method's `rcond`), and for the vehicle criteria a joined record's `breaks`, `warm_start`
      (`Lagged`, `Backprop` start from `system`'s weights), `callback` and `progress`.
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
      (default 0.1, 0.25, 0.5 s). Records alone are `Validate(records)`. A vehicle is scored by
      the vehicle horizon error (`flight_error`: position, velocity, attitude and body-rate errors
      at the horizons in whole samples), every other system by the open-loop position RMSE
      (`held_out_error`).

    **Returns:** an `Identification`.

    **Raises:** `IdentifiabilityError` (a `DataError`) when the data do not determine all
    parameters, naming the unidentified combinations; `DataError` when a record is too short or holds a
    NaN or an infinity (naming the column and row); `UsageError` for a system or method that does not fit,
    or a record of other columns or of integers.
    """
    warn_if_float32("identification")  # the float64 policy: say so, once, naming the switch
    release_compiled_code()  # many identifications in one process: below Linux's memory-map limit
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
    settings = _fit_settings(friction, settings)
    fitted, held, source, horizons_s = _validation_split(system, trajectories, validation, settings.weights)

    # a held-out tail belongs to the record it was cut from (`None`: records of their own)
    tails_of = (
        tuple(i for i, (whole, head) in enumerate(zip(trajectories, fitted)) if len(head) < len(whole))
        if validation.records is None
        else None
    )
    job = IdentifyJob(
        settings,
        HeldOut(held, horizons_s, source, tails_of),
        consistency=consistency,
        refine=refine,
        system_name=_system_name(system),
    )
    prepared = method.prepare(system, fitted, job)  # the records as the method fits them
    # A rule (noise read as negligible that biases the least squares) filters the least-squares stage; the
    # refinement then follows the records' own spectra (noise that small needs no output-error fit).
    with contextlib.nullcontext() if prepared.filter_rule is None else filter_rule(prepared.filter_rule):
        stages = prepared.method.fit_stage(system, prepared)
    stages = prepared.method.refine(system, prepared, stages)
    result = _validated(stages, prepared.job.held_out)
    warn_if_refinement_left_equations(result)  # a refinement that left the equations: said, with what moved
    _warn_unvalidated(held, source)
    return result


def _fit_settings(friction, settings: FitSettings) -> FitSettings:
    """The fit's `FitSettings`: `settings` with `friction` where given (one friction: refused where they differ)."""
    if not isinstance(settings, FitSettings):
        raise UsageError(f"identify: `settings` must be a FitSettings, got {type(settings).__name__}")
    if friction is None or friction == settings.friction:
        return settings
    if settings.friction != FitSettings().friction:
        raise UsageError(
            f"identify: `friction={friction!r}` and `settings.friction={settings.friction!r}` differ; give one"
        )
    return dataclasses.replace(settings, friction=friction)


def _validated(fitted: Fitted, held_out: HeldOut) -> Identification:
    """`fitted`'s identification with each stage's model validated on the `held_out` records: where the fit
    added `Stiction`, from windows that start at zero speed where a joint rests within the noise
    (`speeds_zeroed_at_rest`)."""
    identification = fitted.identification
    static = identification.static_friction
    if static is not None and static.joints and held_out.records:
        held_out = dataclasses.replace(
            held_out,
            source=held_out.source + "; a joint at rest starts at zero speed where its speed is within the noise",
            start_at_rest=True,
        )
    stages = tuple(
        dataclasses.replace(stage, validation=held_out.validate(model))
        for stage, model in zip(identification.stages, fitted.models, strict=True)
    )
    return dataclasses.replace(identification, stages=stages)


def _warn_unvalidated(held, source) -> None:
    """`NoValidationWarning` where a holdout was asked for and nothing could be held out (`source` says why)."""
    if not held and source:
        warnings.warn(f"identify: {source}", NoValidationWarning, stacklevel=3)
