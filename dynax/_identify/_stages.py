r"""The stages `identify` runs for a method (`AbstractMethod`'s `prepare`, `fit_stage`, `refine`);
`identify` validates each stage's model on the held-out records itself.

- `fit_once`, every method's default first stage: its `fit` once, the estimate's physical
  consistency checked where the system has conditions.
- the least-squares methods' (`Dynamic`, `Power`, `Energy`): `least_squares_prepare`, each record's
  angle zeros where they apply (`_angle_zeros.py`); `least_squares_fit`, the least-squares stage
  (`_ls_stage.py`: force offsets, the consistency constraint, errors robust to serial correlation)
  and what the records show of friction at rest (`_static_friction.py`); `least_squares_refine`, on
  real two-link arm data the output-error refinement (`_refine.py`).
"""

import contextlib
import contextvars
import dataclasses
from typing import Any
import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._context import set_within
from .._data._spectra import choose_filter
from .._errors import UsageError
from .._model._linear_in_parameters import size_parameter_names
from .._simulate import FixedGrid
from ._angle_zeros import AngleZeros, record_angle_zeros
from ._angle_zeros import applies as _angle_zeros_apply
from ._consistency import check_consistency, Consistency
from ._equations import AbstractLeastSquares, stacked_equations, uniformly_sampled
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
from ._method import AbstractMethod, Fitted, IdentifyJob, Prepared
from ._noise_bias import noise_bias_rule
from ._offsets import record_labels, without_offsets
from ._refine import refine_by_simulation, REFINEMENT_OPTIONS, RefinementStatistics
from ._regressors import split_terms
from ._result import Identification, RecordsDisagreeWarning, Stage, StageKind
from ._simulation_fit import SimulationFit
from ._static_friction import (
    describe,
    joint_levels,
    not_added,
    record_rests,
    rests_under_load,
    SLOW_ROWS,
    StaticFriction,
    with_stiction,
)
from ._validation import HeldOut


def fit_once(method: AbstractMethod, system, prepared: Prepared) -> Fitted:
    """Any method's first stage: its `fit` on the prepared records and the estimate's consistency
    check where the system has conditions (`identify` validates it)."""
    job, fitted = prepared.job, prepared.records
    settings = job.settings
    solution = method.fit(system, fitted, settings)
    check = None
    if _has_conditions(system):
        qs = joint_positions(solution.model, fitted)
        check = check_consistency(
            solution.model, solution.names, jnp.asarray(solution.value), qs, warn=job.consistency != "off"
        )
    stage = Stage(StageKind(method.stage_kind), method.label, solution, consistency=check)
    identification = Identification(
        system=solution.model,
        stages=(stage,),
        n_samples=method.n_samples(solution, fitted),
        friction=settings.friction,
        system_name=job.system_name,
    )
    return Fitted(identification, (solution.model,))


class LeastSquaresState(eqx.Module):
    """A least-squares method's state between its fit and its refinement: the least-squares stage
    (`ls`), what the records show of friction at rest (`static`, or `None` where not looked for) and
    each record's rest stretches (`rests`)."""

    ls: Any
    static: StaticFriction | None
    rests: Any


def least_squares_prepare(method: AbstractLeastSquares, system, records, job: IdentifyJob) -> Prepared:
    """A least-squares method's records as its stages fit them: each record's angle zeros where they
    apply and are chosen, fitted out of the records and of the held-out tails (read from their
    record's zero), with the method then fitting no force offsets; else the records as given. Records whose
    velocity noise the spectra read as negligible but which biases the fit are filtered (`_noise_bias.py`)."""
    zeros = _record_angle_zeros(system, records, method, job.settings.friction, method.rcond)
    if zeros is None or not zeros.chosen:
        rule = noise_bias_rule(system, records, method, job.settings.friction, job.settings.weights, method.rcond)
        return Prepared(method, records, job, zeros, rule)
    held_out = job.held_out  # both stages fit the records less their angle zeros
    if held_out.tails_of is not None and held_out.records:  # a held-out tail is read from its record's zero
        held_out = HeldOut(
            zeros.corrected(held_out.records, system, list(held_out.tails_of)),
            held_out.horizons_s,
            held_out.source + "; each tail less its record's angle zeros, fitted on its head",
            held_out.tails_of,
        )
    method = dataclasses.replace(method, offsets=False)
    records = zeros.corrected(records, system)
    rule = noise_bias_rule(system, records, method, job.settings.friction, job.settings.weights, method.rcond)
    return Prepared(method, records, dataclasses.replace(job, held_out=held_out), zeros, rule)


def least_squares_fit(method: AbstractLeastSquares, system, prepared: Prepared) -> Fitted:
    """A least-squares method's first stage on the prepared records (`_ls_stage.py`: force offsets,
    the consistency constraint, errors robust to serial correlation) and what the records show of
    friction at rest (`_static_friction.py`; the stage refitted without the rests under load where
    the method says so)."""
    fitted, job = prepared.records, prepared.job
    friction, weights, consistency = job.settings.friction, job.settings.weights, job.consistency
    held = job.held_out.records
    rcond = method.rcond
    rests = record_rests(fitted) if _looks_for_rests(system) else None
    first = [() for _ in fitted] if SLOW_ROWS.get()[1] else None  # `slow_rows(first_fit=True)`: no rest, slow rows
    ls = least_squares_stage(system, fitted, method, friction, weights, rcond, consistency, first)
    static = _static_friction(ls, fitted, rests)
    if static is not None and static.joints and not method.adds_static_friction:
        static = not_added(static)
    if static is not None and static.joints and method.refits_without_loaded_rests:
        # Refit without the rows of the rests under load (no law of the speed explains a held torque), nor
        # those inside the Coulomb law's smoothing band (a joint that sticks there has a friction no law of
        # the speed follows, and one record's sign of misfit goes into its offset), and read the rests again
        # with that fit. A rest that holds nothing is an equation like any other.
        loaded = rests if EVERY_REST_OUT.get() else _loaded_rests(static, rests, record_labels(fitted))
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
    stage = Stage(
        StageKind.LEAST_SQUARES,
        ls.label,
        solution,
        relative_equation_error=float(relative_equation_error(ls.a, ls.y, ls.estimate)),
        consistency=ls.consistency,
        poorly_determined=poorly,
        offsets=offsets_json(ls, fitted),
        angle_zeros=prepared.angle_zeros,
        serial_correlation=ls.serial,
        joint_weights=ls.joint_weights,
    )
    state = LeastSquaresState(ls, static, rests)
    return Fitted(_ls_identification(prepared, state, (stage,), ls_model, poorly), (ls_model,), state)


def least_squares_refine(method: AbstractLeastSquares, system, prepared: Prepared, fitted: Fitted) -> Fitted:
    """A least-squares method's refinement: on real two-link arm data, the output-error fit from the
    least-squares stage (`_refine.py`), on the records less their fitted offsets; then the returned
    estimate's poorly determined size parameters, warned."""
    state = fitted.state
    assert isinstance(state, LeastSquaresState)  # what `least_squares_fit` hands on
    ls, static, rests = state.ls, state.static, state.rests
    records, job = prepared.records, prepared.job
    stages, models = fitted.identification.stages, fitted.models
    system_out, poorly = fitted.identification.system, fitted.identification.poorly_determined
    refinement = refinement_method(job.refine, ls.system, method, records)
    if refinement is not None:
        # The windows start from the refinement's own velocities (a local fit of the positions), also at rest:
        # zeroed there by the validation's rule (`refine_by_simulation(..., rests=...)`) the held-out runs that
        # never rest fitted worse in 5 of 9 cells (docs/devdocs/dfki_stiction.md), so that stays opt-in.
        simulated = less_offsets(ls.system, records, ls)
        refined = _refined_stage(
            ls, models[0], (records, simulated), method, job.settings.friction, job.consistency, refinement
        )
        statistics = refined.solution.statistics
        assert isinstance(statistics, RefinementStatistics)  # what `refine_by_simulation` returns
        refined_poorly = _size_errors(
            system, refined.names, refined.solution.value, refined.solution.std_errors, statistics.record_std_errors
        )
        stages += (dataclasses.replace(refined, poorly_determined=refined_poorly),)
        models += (refined.solution.model,)
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
    state = LeastSquaresState(ls, static, rests)
    return Fitted(_ls_identification(prepared, state, stages, system_out, poorly), models, state)


def _ls_identification(prepared: Prepared, state: LeastSquaresState, stages, system_out, poorly) -> Identification:
    """The `Identification` of the least-squares `stages` (validated by `identify`), returning
    `system_out`."""
    final = stages[-1].solution
    covariance = final.covariance
    jointly = (
        jointly_determined(final.names, covariance)
        if covariance is not None and np.shape(covariance)[0] == len(final.names)
        else None
    )
    ls = state.ls
    return Identification(
        system=system_out,
        stages=stages,
        n_samples=ls.n_samples,
        friction=prepared.job.settings.friction,
        system_name=prepared.job.system_name,
        settings=ls.settings,
        record_offsets=ls.offsets,
        angle_zeros=prepared.angle_zeros,
        record_friction=ls.friction,
        poorly_determined=poorly,
        jointly_determined=jointly,
        static_friction=state.static,
    )


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
            stacklevel=7,
        )
    return out


def _signal_band_hz(trajectories) -> float | None:
    """The widest velocity signal band over the records, or `None` when no record's velocities are noisy."""
    bands = [
        c.cutoff_hz for c in (choose_filter(uniformly_sampled(t)) for t in trajectories) if c.cutoff_hz is not None
    ]
    return max(bands) if bands else None


STAGGER = 4  # staggered cuts of the records into segments in the default refinement


def refinement_method(refine, system, method, trajectories):
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


def _refined_stage(ls, start, records, method, friction, consistency, refinement) -> Stage:
    """The output-error refinement from the least-squares stage `ls` (its model `start`, with `Stiction`
    where the records rest under load) on `records = (fitted, simulated)` (the fitted records, and as the
    simulation sees them), with its equation error on the least-squares rows of `fitted` and consistency
    (`identify` validates it)."""
    fitted, simulated = records
    options = {k: v for k, v in (REFINEMENT_OPTIONS.get() or {}).items() if k != "fit"}  # `fit`: read there
    refined = refine_by_simulation(start, ls.names, simulated, refinement, **options)
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
        consistency=check,
        records_disagree=_records_disagree(refined),
    )


REST_SEARCH = contextvars.ContextVar("dynax_rest_search", default=True)  # False: `rest_search_off`


@contextlib.contextmanager
def rest_search_off():
    """Within the block, `identify` does not look for friction at rest (`result.static_friction` is `None`,
    no rows are left out, no `Stiction` is added): the least-squares fit as it is without the rest search,
    for comparing with it and for pricing the search."""
    with set_within(REST_SEARCH, False):
        yield


EVERY_REST_OUT = contextvars.ContextVar("dynax_every_rest_out", default=False)  # True: `all_rests_left_out`


@contextlib.contextmanager
def all_rests_left_out():
    """Within the block, the least-squares refit that `Dynamic(static_friction=True)` makes where a joint rests
    under load leaves out the rows of every rest, loaded or not, instead of the loaded ones only: a what-if for
    comparing the static level read either way."""
    with set_within(EVERY_REST_OUT, True):
        yield


def _looks_for_rests(system) -> bool:
    """Whether `identify` looks for friction at rest on `system`: the arms its refinement knows (unless
    `rest_search_off`)."""
    if not REST_SEARCH.get():
        return False
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
            stacklevel=6,
        )


def _has_conditions(system):
    """Whether the least-squares models know `system` and it has physical-consistency conditions."""
    try:
        base, _ = split_terms(system)
    except UsageError:
        return False
    return bool(base.base_parameter_kinds())
