"""`diagnose`: show what a model's simulation gets wrong, name the cause, extend the model, measure the gain.

`diagnose` is `dynax._fit.fit_least_squares` (the candidate refits, `vmap`ped over configurations,
`_fit.py`), `dynax._simulate._sim_error.window_rollouts` (every held-out rollout), the statistics
(`_statistics.py`) and the selection rules (`_selection.py`), in named steps, one module each:

- `_problem.py`: prepare the problem (records on one grid, candidates, what is identifiable, windows);
- `_forward.py`: fit the nominal model, show what is wrong, then per round screen, refit, select;
- here: extend, judge and (where structure is left) discover, and the `Report`.

The records (checked, on one grid, the hold-out cut, velocities, the horizons read from the training
runs) are prepared in `_records.py`.
"""

from collections.abc import Callable, Sequence
import contextlib
import dataclasses

import equinox as eqx
import numpy as np

from .._compiled_code import release_compiled_code
from .._data._trajectory import check_record_columns, check_record_values, Trajectory
from .._errors import DataError, UsageError
from .._model._extensions import AbstractTerm, Extended
from .._model._quadrotor import Quadrotor
from .._model._system import AbstractSystem
from .._precision import warn_if_float32
from .._progress import ProgressBar
from .._simulate import SimulationError
from ._candidates import host_nominal_values
from ._discovery import discover, DiscoverySearch, HeldOutTest
from ._fit import window_errors
from ._forward import Current, Forward, forward_selection, Nominal, Yardstick
from ._problem import check_arguments, prepare_problem, Problem
from ._problem import Known as Known
from ._problem import Refit as Refit
from ._quadrotor import frame_quadrotor
from ._records import as_records
from ._residuals import shared_length, Structure, structure_test
from ._result import DataSummary, ModelSummary
from ._result import Report as Report
from ._selection import paired_test
from ._settings import Horizons, Selection
from ._summaries import (
    merge_repeated_causes,
    per_run_table,
    rmse_curve,
    rmse_gain,
    test_summary,
    unexplained_note,
    window_scores,
)
from ._validation import validation_summary
from ._verdict import decide, inconclusive_note, Power, power_of, PRACTICAL_R2, Verdict

_CONTRACT_NAMES = {
    "Acrobot": "acrobot",
    "DoublePendulum": "double_pendulum",
    "LinearAxis": "linear_axis",
    "Helicopter": "helicopter",
}


@contextlib.contextmanager
def stage_reporter(progress: Callable[[str], None] | bool | None):
    """The `say(line)` a diagnosis reports its stages through.

    A callable is used as given. Otherwise a `dynax.internal.ProgressBar` with one step per stage and per
    candidate batch, on stderr: `True` / `False` force it on / off; `None` follows
    `dynax.internal.progress_mode` (a bar only when stderr is a terminal; the CLI's `--quiet` silences it).
    Without a bar the library prints nothing (the CLI prints the lines as a log instead).
    """
    if callable(progress):
        yield progress
        return
    with ProgressBar(None, "diagnose", progress=progress, unit="stage") as bar:
        yield bar.say if bar.enabled else (lambda _: None)


def _extend(problem: Problem, current: Current) -> tuple[Extended, list[dict]]:
    """Extend: the nominal model with the selected terms, every coefficient from the final joint fit
    (earlier rounds' values move when later terms join); repeated causes merged into one finding."""
    n_nom = len(problem.names)
    findings = [dict(f) for f in current.findings]
    for m, (finding, k) in enumerate(zip(findings, current.selected)):
        finding["coefficient"] = float(problem.neutral[k] + current.p[n_nom + m])
        finding["std_error"] = float(current.std[n_nom + m])
    model = problem.model_of(current.slots, current.p)
    return Extended(model.system, tuple(model.terms[k] for k in current.selected)), merge_repeated_causes(findings)


@dataclasses.dataclass
class _Judgement:
    """The verdict and what it rests on: the final model, its findings, held-out errors and structure."""

    verdict: Verdict
    model: AbstractSystem
    findings: list
    errors: np.ndarray
    rmse: np.ndarray
    structure: Structure
    gain: float
    discovery: dict
    cv_errors: np.ndarray  # the named causes' model on the cross-fitted windows (discovered terms are not cross-fitted)
    power: Power


def _power(problem: Problem, yard: Yardstick, last: dict) -> Power:
    """The last round's test power (`_verdict.power_of`) over the record time its windows cover."""
    labels = {k: (problem.candidates[k].cause, problem.candidates[k].where(problem.system)) for k in last}
    tested_s = len(yard.window_runs) * problem.val_stride * problem.dt
    return power_of(last, labels, problem.selection.alpha, tested_s)


def _judge(problem: Problem, forward: Forward, say) -> _Judgement:
    """Judge: `explained`, `unexplained`, `none` or `inconclusive` from the findings, the structure left and the
    test's power (`_verdict.decide`); then, where it is not `explained` and discovery is on, search beyond the
    vocabulary with the same held-out test."""
    nominal, yard, current, last = forward.nominal, forward.yard, forward.current, forward.last
    model, findings = _extend(problem, current)
    power = _power(problem, yard, last)
    diverged = not np.isfinite(nominal.rmse[yard.ref_index])
    verdict = decide(bool(current.selected), current.structure, diverged, power)
    gain = rmse_gain(current.rmse, nominal.rmse, yard.ref_index) if current.selected else 0.0
    judgement = _Judgement(
        verdict, model, findings, current.errors, current.rmse, current.structure, gain, {}, current.cv_errors, power
    )
    # Beyond the vocabulary: search, refit, the same held-out test. Also after a `none`: the generic
    # probe cannot see every structure (a force periodic in position), the search's own guards can.
    if problem.selection.discovery and verdict != Verdict.EXPLAINED:
        judgement = _discover(problem, nominal, yard, current, judgement, say)
    return judgement


def _discover(problem: Problem, nominal: Nominal, yard: Yardstick, current: Current, judgement: _Judgement, say):
    o = problem.selection
    held_out_errors = eqx.filter_jit(window_errors)
    last_errors = {}

    def held_out(model):
        errors = np.asarray(held_out_errors(model, problem.val_windows))
        last_errors[id(model)] = errors
        curve = rmse_curve(errors, yard.steps, problem.position_index)
        return window_scores(errors[None], yard.n_ref, problem.state_scale)[0], curve, curve[yard.ref_index]

    system = problem.system
    found = discover(
        judgement.model if current.selected else nominal.model,
        problem.train,
        problem.validation,
        test=HeldOutTest(
            held_out,
            lambda ref, new: paired_test(ref, new, problem.window_runs, yard.overlap).p_value,
            alpha=o.alpha,
            min_gain=o.min_gain,
        ),
        search=DiscoverySearch(
            refit=problem.refit_names,
            vocabulary=[problem.candidates[k].label(system) for k in problem.searchable],
            absorbed=[f"{c['cause']}@{c['where']}" for c in problem.not_identifiable],
        ),
        fit_window_s=problem.fit_window_s,
        current=(current.score[: yard.n_val], current.rmse, current.rmse[yard.ref_index]),
        progress=say,
    )
    problem.notes.extend(found.notes)
    judgement.discovery = found.summary(system)
    if found.kept:
        say("probing the residuals of the model with the discovered terms for structure ...")
        structure = structure_test(found.model, problem.train, problem.validation)
        errors = last_errors.get(id(found.model))
        if errors is None:
            errors = np.asarray(held_out_errors(found.model, problem.val_windows))
        judgement = _Judgement(
            decide(True, structure, False, judgement.power),
            found.model,
            judgement.findings + found.findings,
            errors,
            found.held_out[1],
            structure,
            rmse_gain(found.held_out[1], nominal.rmse, yard.ref_index),
            judgement.discovery,
            judgement.cv_errors,
            judgement.power,
        )
    return judgement


def _model_summary(problem: Problem, model, errors, rmse, yard: Yardstick, terms=None) -> ModelSummary:
    """The `nominal` / `extended` object: parameters by report name, held-out error curve, validation block."""
    system = model.system if isinstance(model, Extended) else model
    parameters = dict(zip(problem.names, map(float, host_nominal_values(system, problem.names))))
    if isinstance(model, Extended):
        parameters.update({k: float(v) for t in model.terms for k, v in t.parameters(problem.system).items()})
    measured = np.asarray(problem.val_windows.xs)[:, yard.n_ref]
    validation = validation_summary(
        model,
        problem.validation,
        np.asarray(errors)[:, yard.n_ref],
        measured,
        yard.horizon.seconds,
        length=shared_length(problem.train + problem.validation),
    )
    errors = np.asarray(errors)
    sim_error = SimulationError(
        horizons_s=tuple(float(h) for h in yard.horizons),
        n_windows=errors.shape[0],
        diverged_fraction=float(np.mean(~np.isfinite(errors).all(axis=(1, 2)))),
        rmse=np.asarray(rmse, dtype=float),
        states=tuple(problem.system.state_names[i] for i in problem.position_index),
        steps=tuple(int(k) for k in yard.steps),
        dt=float(problem.dt),
    )
    return ModelSummary(parameters=parameters, sim_error=sim_error, terms=terms, validation=validation)


def _data_summary(problem: Problem, train, validation) -> DataSummary:
    given = as_records(train, "train")
    held_out = problem.validation
    if validation is not None:
        validation_name = ", ".join(r.source or "(held out)" for r in held_out)
    else:
        validation_name = "last {:.0%} of {}".format(
            problem.selection.holdout_fraction, ", ".join(r.source or "train" for r in given)
        )
    return DataSummary(
        train=", ".join(r.source or "(train)" for r in given),
        validation=validation_name,
        n_train=int(sum(len(r) for r in problem.train)),
        n_validation=int(sum(len(r) for r in held_out)),
        dt=problem.dt,
        train_runs=tuple(r.source or f"train run {i + 1}" for i, r in enumerate(problem.train)),
        validation_runs=tuple(r.source or f"held-out run {i + 1}" for i, r in enumerate(held_out)),
        velocities=problem.velocities,
    )


def _report(problem: Problem, forward: Forward, judgement, *, mode, train, validation) -> Report:
    """The typed `Report` that `report.json` and `report.md` are written from."""
    system, o, nominal, yard = problem.system, problem.selection, forward.nominal, forward.yard
    notes = list(problem.notes)
    verdict = judgement.verdict
    if verdict == Verdict.UNEXPLAINED:
        notes.append(unexplained_note(judgement.structure))
    elif judgement.structure.significant:
        s = judgement.structure
        notes.append(
            f"The residual probe still explains {s.r2:.0%} of the held-out one-step residuals' mean square "
            f"(p = {s.p_value:.2g}): significant, but a term capturing all of it would lower it by that much at most, "
            f"less than a structure of practical size (R2 >= {PRACTICAL_R2:.2f}; see the verdict rule)."
        )
    test = test_summary(o.alpha, o.min_gain, judgement.power, verdict, named=bool(judgement.findings))
    blocks = len(problem.folds) > len(problem.train)
    test["cross_fitting"] = (
        (
            f"the training run cut into {len(problem.folds)} contiguous blocks, each held out in turn, every "
            "configuration refitted on the rest; their windows pooled with the held-out runs'"
            if blocks
            else f"each of the {len(problem.folds)} training runs also held out in turn, every configuration "
            "refitted on the other training runs; its windows pooled with the held-out runs'"
        )
        if problem.folds
        else None
    )
    runs = "held-out and cross-fitted runs" if problem.folds else "held-out runs"
    if verdict == Verdict.INCONCLUSIVE:
        notes.append(inconclusive_note(judgement.power, yard.horizon.seconds, runs))
    elif verdict == Verdict.NONE and test["detectable_gain"] is not None:
        notes.append(
            f"No candidate passed the test. With these {runs} the test would have detected a gain of "
            f"about {test['detectable_gain']:.0%} in mean squared window error at {yard.horizon.seconds:g} s "
            f"(power 80 %) if its window-to-window "
            f"variation is like {judgement.power.variation}; a smaller effect, or one that varies more (friction "
            f"acting in the slow segments only), may be present."
        )
    extended = judgement.model
    terms = tuple(dict.fromkeys(t.label(system) for t in extended.terms))  # wind@world once
    return Report(
        system=problem.train[0].system or _CONTRACT_NAMES.get(type(system).__name__, type(system).__name__.lower()),
        data=_data_summary(problem, train, validation),
        mode="refit" if isinstance(mode, Refit) else "known",
        nominal=_model_summary(problem, nominal.model, nominal.errors, nominal.rmse, yard),
        verdict=verdict,
        findings=judgement.findings,
        extended=_model_summary(problem, extended, judgement.errors, judgement.rmse, yard, terms=terms),
        gain=judgement.gain,
        reference_horizon_s=float(yard.horizon.seconds),
        structure={"nominal": nominal.structure, "extended": judgement.structure},
        not_identifiable=problem.not_identifiable,
        candidates=forward.table,
        notes=notes,
        horizon=yard.horizon,
        runs=per_run_table(problem, yard, nominal, judgement),
        test=test,
        nominal_model=nominal.model,
        extended_model=extended,
        discovery=judgement.discovery,
        rounds=forward.rounds,
        not_proposed=problem.not_proposed,
    )


def diagnose(
    system: AbstractSystem,
    train: Trajectory | Sequence[Trajectory],
    validation: Trajectory | Sequence[Trajectory] | None = None,
    *,
    candidates: Sequence[AbstractTerm] | None = None,
    mode: Refit | Known = Refit(),
    horizons: Horizons = Horizons(),
    selection: Selection = Selection(),
    progress: Callable[[str], None] | bool | None = None,
) -> Report:
    r"""Diagnose what `system` gets wrong on measured data, name the cause and measure the gain.

    1. **Fit** the nominal parameters on `train` (simulation-error fit on windows; `Refit` mode)
       or keep them (`Known` mode).
    2. **Choose the reference horizon** from the training runs (unless given) and **show what
       it gets wrong** on held-out data: open-loop simulation error against horizon,
       and a probe of its one-step acceleration residuals for structure (see `structure_test`).
    3. **Name the cause**: forward selection over `candidates`. Each round refits every remaining
       candidate's coefficient in one `vmap` (screening), then refits the best few and their
       look-alikes jointly with the nominal parameters, and keeps the best if its held-out
       improvement at the reference horizon is significant (one-sided paired test over windows
       with their correlation estimated from the data, Benjamini-Hochberg over the candidates remaining, level
       `selection.alpha`; see `_statistics`), at least `selection.min_gain`, helps on most held-out runs, and has a
       physical sign. With three or more training runs the test also holds out each training run
       in turn (cross-fitting: every configuration refitted on the other training runs) and pools
       those windows with the held-out ones; a candidate must then still not make the held-out runs
       worse. Candidates a refit of the nominal parameters reproduces exactly are set
       aside as not identifiable. The residual probe never stops the search.
    4. **Extend** the model with the selected terms, refitted jointly.
    5. **Measure the gain**: held-out simulation error, nominal against extended.
    6. **Verdict** (`dynax.Verdict`; the rule is `dynax._diagnose._verdict`): `explained` (causes found and
       what the extended model leaves has no structure of practical size), `unexplained` (structure of
       practical size the candidates do not fully explain, or a nominal model that diverges on the
       held-out windows; partial findings are listed), `none` (nothing named, nothing of practical size
       left, and the test had the power to see a 25 % gain), `inconclusive` (nothing named, but the test
       could not have seen a 25 % gain, or a candidate gained that much without being established; the
       notes name it and the held-out length that would decide).
    7. **Discover** (where the verdict would not be `explained` and `selection.discovery` is on): a sparse
       search for the missing term beyond the vocabulary, refitted through simulation and kept
       only if it passes the same held-out test (see `dynax._diagnose._discovery.discover`);
       findings with cause `discovered`. The verdict is then `explained` if the named and
       discovered terms leave no significant structure.

    Where the runs' recorded forces carry constant offsets that differ from run to run (a sensor's
    zero, which no candidate can carry to another run; `dynax.internal.record_offsets` on the nominal model's
    inverse-dynamics equations, two-link arms and the linear axis), the report's notes say so.

    **Arguments:**

    - `system`: the nominal model (its parameters are the start of the fit, or trusted in `Known`).
    - `train`: the training record(s).
    - `validation`: held-out record(s); default the last `selection.holdout_fraction` of each training record.
    - `candidates`: terms at neutral values (default `default_candidates(system)`: the contract's
      vocabulary).
    - `mode`: `Refit()` (default) or `Known()`.
    - `horizons`: how far it simulates (`dynax.Horizons`): where the held-out simulation error is reported
      (`horizons_s`) and judged (`reference_s`; default the predictability horizon of the nominal model on
      the training runs, at `fraction` of the positions' spread), and the fit windows (`fit_window_s`).
    - `selection`: how causes are tested and chosen (`dynax.Selection`): at most `max_terms` causes, the
      test's level `alpha` and smallest gain `min_gain`, `shortlist` candidates refitted jointly per round,
      `cross_fit`, `discovery`, the `holdout_fraction` held out without validation records, and the
      `velocities` the records are compared with.
    - `progress`: a callable is called with a line of text at each stage (e.g. `print`, or a
      `dynax.internal.ProgressBar`'s `say`); otherwise a progress bar on stderr, one step per stage and per
      candidate batch: `True` / `False` force it on / off, `None` (default) draws it when stderr is a
      terminal (see `dynax.internal.progress_mode`; the CLI's `--quiet` silences it).

    **Returns:** a `Report`. For a `Quadrotor` it also scores the held-out flights per group (position, velocity,
    attitude, body rate) at 1, 10 and 50 steps, nominal and extended beside constant velocity (`Report.flight_error`),
    and notes an extended model that predicts a group much worse one step ahead (`dynax.internal.score_flights`).

    ??? cite

        L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, ch. 16 (model
        structure selection and validation). N. R. Draper and H. Smith, *Applied Regression
        Analysis*, 3rd ed., 1998, ch. 15 (forward selection).
    """
    warn_if_float32("diagnosis")  # the float64 policy: say so, once, naming the switch
    release_compiled_code()  # many diagnoses in one process: below Linux's memory-map limit (`_compiled_code`)
    check_arguments(system, mode, horizons, selection)
    _check_record_values(system, train, validation)
    framed = None
    if isinstance(system, Quadrotor):  # its body-frame form, the multirotor causes (`_quadrotor.py`)
        framed = frame_quadrotor(system, train, validation, candidates, mode, horizons, selection)
        system, train, validation = framed.system, framed.train, framed.validation
        candidates, mode, horizons = framed.candidates, framed.mode, framed.horizons
        check_arguments(system, mode, horizons, selection)
    warn_data_faults(train, validation)
    with stage_reporter(progress) as say:
        problem = prepare_problem(system, train, validation, candidates, mode, horizons, selection)
        if framed is not None and framed.through is not None:
            problem.nominal_through = framed.through(problem.names)
        report = diagnose_problem(problem, mode, train, validation, say)
        if framed is not None:  # the quadrotor's names, and its held-out flights scored per group
            report = framed.finish(report, say)
    return report


def _check_record_values(system, train, validation):
    """Records a fit cannot read (not Trajectories, another system's columns, fewer than 3 samples, integer
    columns, a NaN or an infinity) refused before the data checks and any fit, naming the argument, the column
    and the row; `prepare_records` checks the lengths the windows need."""
    for argument, records in (("train", train), ("validation", validation)):
        if records is None and argument == "validation":
            continue
        listed = [records] if isinstance(records, Trajectory) else records
        if not isinstance(listed, (list, tuple)) or not listed:
            raise UsageError(
                f"diagnose: `{argument}` must be a Trajectory or a non-empty list of them, got {type(records).__name__}"
            )
        for k, record in enumerate(listed):
            if not isinstance(record, Trajectory):
                raise UsageError(f"diagnose: `{argument}` record {k} must be a Trajectory, got {type(record).__name__}")
            check_record_columns(record, system, "diagnose", f"`{argument}` record {k}")
            if len(record) < 3:
                raise DataError(
                    f"diagnose: `{argument}` record {k} has {len(record)} sample(s): too few for a derivative, "
                    "let alone a fit window",
                    path=record.source or None,
                )
            check_record_values(record, "diagnose", f"`{argument}` record {k}")


def diagnose_problem(problem: Problem, mode: Refit | Known, train, validation, say) -> Report:
    """Steps 1 to 7 of `diagnose` on a prepared `Problem` (`prepare_problem`)."""
    forward = forward_selection(problem, say)
    judgement = _judge(problem, forward, say)
    say("validation: fit % and residual tests of the nominal and the extended model ...")
    return _report(problem, forward, judgement, mode=mode, train=train, validation=validation)


def warn_data_faults(train, validation):
    """Located faults of the records (`dynax.check_records`) as `DataWarning`s, before any fit."""
    from .._data import Trajectory
    from .._data._sanity import check_records

    as_list = lambda d: [] if d is None else [d] if isinstance(d, Trajectory) else list(d)  # noqa: E731
    check_records(as_list(train), as_list(validation)).warn(stacklevel=3)
