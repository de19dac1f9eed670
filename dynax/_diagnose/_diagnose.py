"""`diagnose`: show what a model's simulation gets wrong, name the cause, extend the model, measure the gain.

`diagnose` is `dynax._fit.fit_least_squares` (the candidate refits, `vmap`ped over configurations,
`_fit.py`), `dynax._sim_error.window_rollouts` (every held-out rollout), the statistics
(`_statistics.py`) and the selection rules (`_selection.py`), in named steps: prepare the problem,
fit the nominal model, show what is wrong, then per round screen, refit, select; finally extend,
judge and (where structure is left) discover.
The records (checked, on one grid, the hold-out cut, velocities, the horizons read from the training
runs) are prepared in `_records.py`.
"""

import contextlib
import dataclasses
import time
from collections.abc import Callable, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._identify._record_friction import compare_records
from .._model._extensions import AbstractInputTerm, AbstractTerm, Extended
from .._model._system import AbstractSystem, friction_parameter_names, size_parameter_names
from .._precision import warn_if_float32
from .._progress import ProgressBar
from ._candidates import (
    candidate_scales,
    default_candidates,
    held_partners,
    look_alikes,
    sampled_sensitivities,
    structurally_absorbed,
    structurally_equivalent,
)
from ._discovery import discover
from ._fit import (
    Family,
    fit_configurations,
    make_windows,
    nominal_parameter_names,
    nominal_values,
    validate_configurations,
    window_errors,
    Windows,
)
from ._horizon import DEFAULT_FRACTION, Horizon
from ._records import (
    _as_records,
    _fit_window,
    _horizon_grid,
    _prepare_records,
    _reference_horizon,
    _velocity_estimates,
    HOLDOUT_FRACTION,
)
from ._residuals import acceleration_residuals, Structure, structure_test
from ._result import DataSummary, ModelSummary, Report as Report, SimErrorCurve
from ._screening import screen
from ._selection import choose_shortlist, judge_round, look_alike_tests, on_physical_side, paired_test, rank
from ._summaries import (
    _candidate_table,
    _gain,
    _merge_repeated_causes,
    _per_run_table,
    _rmse_curve,
    _round_summary,
    _test_summary,
    _unexplained_note,
    _window_scores,
)
from ._validation import validation_summary


# Cross-fitting needs every fold to fit two runs or more (see `_cross_fit`).
MIN_CROSS_FIT_RUNS = 3

_CONTRACT_NAMES = {"Acrobot": "acrobot", "DoublePendulum": "double_pendulum", "LinearAxis": "linear_axis", "Helicopter": "helicopter"}


class Refit(eqx.Module):
    """Diagnosis mode: the nominal parameters are refitted on the training data with every candidate.

    By default every nominal parameter is refitted **but the nominal model's friction** (the
    parameters `base_parameter_meanings` puts in the group `"friction"`: `theta6`, `theta7` of a
    two-link arm), which keeps its nominal value: friction is what the diagnosis names, and a
    refit of it would absorb the very effects under test (a refitted viscous coefficient soaks up
    most of a Coulomb friction's effect on short windows). The friction candidates test it
    instead; a viscous friction candidate adds to the nominal's own coefficient and may lower it,
    not below zero. Causes that a change of the refitted parameters reproduces exactly, alone or
    with a change of the kept friction, are not identifiable in this mode (a rotor inertia at the
    acrobot's shoulder adds to theta1; its input gain rescales theta1..theta5 and the friction) and
    are reported as such.

    **Arguments:** `parameters`, the names of the nominal parameters to refit (default all but the
    friction, e.g. `theta1..theta5`; all of them, `theta1..theta7`, to let the refit absorb
    viscous friction as before 2026-11-25; `("mass", "viscous")` for a linear axis whose nominal
    viscous friction is not trusted).
    """

    parameters: tuple[str, ...] | None = None


class Known(eqx.Module):
    """Diagnosis mode: the nominal parameters are trusted (datasheet, CAD, an earlier identification) and kept.

    Every candidate is identifiable; only the candidates' coefficients are fitted.
    """


@dataclasses.dataclass
class _Options:
    """The knobs of one diagnosis (see `diagnose`'s arguments)."""

    horizons_s: Sequence[float]
    reference_horizon_s: float | None
    horizon_fraction: float
    fit_window_s: float | None
    max_terms: int
    alpha: float
    min_gain: float
    holdout_fraction: float
    shortlist: int
    discovery: bool
    velocities: str = "auto"
    cross_fit: bool = True


@dataclasses.dataclass
class _Problem:
    """Everything fixed for one diagnosis: records, candidates, the candidate family, windows."""

    system: AbstractSystem
    train: list
    validation: list
    dt: float
    notes: list
    candidates: tuple
    refit_names: tuple
    family: Family
    scales: np.ndarray
    inits: np.ndarray
    searchable: list
    not_identifiable: list
    partners: list
    fit_window_s: float
    train_windows: Windows
    val_windows: Windows
    window_runs: np.ndarray
    val_stride: int
    horizons: np.ndarray
    candidates_s: np.ndarray
    options: _Options
    velocities: str = "as measured"
    # The training records each held out in turn (leave-one-run-out cross-fitting); empty when off.
    folds: tuple = ()
    # Candidates that are one model with a refit of the nominal parameters (`structurally_equivalent`).
    equivalents: dict = dataclasses.field(default_factory=dict)

    def look_alikes(self, k: int) -> list[int]:
        """The candidates data could mistake for candidate `k`: its look-alikes and its structural equivalents."""
        return list(dict.fromkeys(look_alikes(self.system, self.candidates[k], self.candidates)
                                  + self.equivalents.get(k, [])))

    @property
    def names(self) -> tuple[str, ...]:
        return self.family.names

    @property
    def neutral(self) -> np.ndarray:
        return np.asarray(self.family.neutral)

    @property
    def state_scale(self) -> np.ndarray:
        return np.asarray(self.family.state_scale)

    @property
    def position_index(self) -> list[int]:
        return list(self.system.position_indices)

    @property
    def n_params(self) -> int:
        return len(self.names) + self.options.max_terms + 1

    def physical(self, k: int, delta: float) -> bool:
        """Whether candidate `k` at `delta` from neutral is physical: on the physical side of neutral
        (friction, inertia, delay), and, where it adds to a nominal parameter that is not refitted,
        with the sum inside that parameter's consistency bound (a viscous coefficient stays non-negative)."""
        return on_physical_side(self.candidates[k], delta, self.partners[k], self.names, self.system)

    def model_of(self, slots, p):
        """The extended model (every candidate; neutral but for `slots`) at parameters `p`."""
        return self.family.model_for(jnp.asarray(slots), jnp.asarray(-1), jnp.asarray(p, self.family.neutral.dtype))


@dataclasses.dataclass
class _Batch:
    """Fits of a batch of configurations: parameters, training cost, standard errors, held-out window errors, steps."""

    p: np.ndarray
    cost: np.ndarray
    std: np.ndarray
    errors: np.ndarray
    steps: np.ndarray
    # (batch, cross-fitted window, step, state): each training run's windows simulated by the
    # configuration refitted on the other training runs; no windows without cross-fitting.
    cv_errors: np.ndarray


@dataclasses.dataclass
class _Yardstick:
    """Where held-out errors are judged: the reference horizon and the indices derived from it."""

    horizon: Horizon
    horizons: np.ndarray
    steps: np.ndarray
    n_ref: int
    overlap: int
    ref_index: int
    # Where the paired test looks: the held-out windows, then (with cross-fitting) the training runs'
    # windows of the reference horizon (`cv_windows`); `window_runs` labels every window's run
    # (held-out runs first, then the training runs after them), `n_val` counts the held-out windows.
    cv_windows: Windows | None
    window_runs: np.ndarray
    n_val: int


@dataclasses.dataclass
class _Current:
    """The model selection has reached: selected candidates, parameters, held-out scores and errors, structure."""

    slots: np.ndarray
    p: np.ndarray
    std: np.ndarray
    score: np.ndarray
    errors: np.ndarray
    rmse: np.ndarray
    structure: Structure
    cv_errors: np.ndarray
    selected: list = dataclasses.field(default_factory=list)
    findings: list = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class _Nominal:
    """The fitted nominal model and what it gets wrong on held-out data."""

    model: AbstractSystem
    errors: np.ndarray
    rmse: np.ndarray
    structure: Structure
    cost: float
    cv_errors: np.ndarray


@contextlib.contextmanager
def stage_reporter(progress: Callable[[str], None] | bool | None):
    """The `say(line)` a diagnosis reports its stages through.

    A callable is used as given. Otherwise a `dynax.ProgressBar` with one step per stage and per
    candidate batch, on stderr: `True` / `False` force it on / off; `None` follows
    `dynax.progress_mode` (a bar only when stderr is a terminal; the CLI's `--quiet` silences it).
    Without a bar the library prints nothing (the CLI prints the lines as a log instead).
    """
    if callable(progress):
        yield progress
        return
    with ProgressBar(None, "diagnose", progress=progress, unit="stage") as bar:
        yield bar.say if bar.enabled else (lambda _: None)


def _check_arguments(system, mode, max_terms) -> None:
    if not isinstance(system, AbstractSystem) or isinstance(system, Extended):
        raise UsageError(f"diagnose: `system` must be a nominal dynax system, got {type(system).__name__}")
    if not isinstance(mode, (Refit, Known)):
        raise UsageError(f"diagnose: `mode` must be Refit() or Known(), got {type(mode).__name__}")
    if max_terms < 1:
        raise UsageError(f"diagnose: `max_terms` must be at least 1, got {max_terms}")


def _refit_names(system, mode) -> tuple[str, ...]:
    names = nominal_parameter_names(system)
    if isinstance(mode, Known):
        return ()
    friction = friction_parameter_names(system)
    refit = tuple(n for n in names if n not in friction) if mode.parameters is None else tuple(mode.parameters)
    unknown = set(refit) - set(names)
    if unknown:
        raise UsageError(f"diagnose: Refit(parameters=...) names {sorted(unknown)}, not parameters of {type(system).__name__} {names}")
    return refit


def _candidate_family(system, candidates, refit_names, train_records):
    """The `Family` (nominal system with every candidate at neutral), the candidates' scales and start values."""
    names = nominal_parameter_names(system)
    dtype = jnp.result_type(float)
    scales, inits = candidate_scales(system, candidates, train_records)
    p0 = np.asarray(nominal_values(system, names), float)
    xs_train = np.concatenate([np.asarray(r.xs) for r in train_records])
    family = Family(
        model=Extended(system, candidates),
        names=names,
        refit=jnp.asarray([1.0 if n in refit_names else 0.0 for n in names], dtype),
        nominal_scale=jnp.asarray(np.maximum(np.abs(p0), 1e-2), dtype),
        candidate_scale=jnp.asarray(scales, dtype),
        candidate_init=jnp.asarray(inits, dtype),
        neutral=jnp.asarray(np.asarray([t.neutral for t in candidates], float), dtype),
        state_scale=jnp.asarray(np.maximum(xs_train.std(axis=0), 1e-9), dtype),
    )
    return family, scales, inits


def _identifiable(system, candidates, family, refit_names, partners, mode, sensitivities):
    """`(searchable indices, not_identifiable entries)`: candidates a refit of the nominal parameters reproduces are set aside.

    In `Refit` mode the kept parameters that candidates test (the nominal friction, `partners`) are not
    trusted either: a candidate that a refit reproduces together with a change of them (the acrobot's input
    gain: rescaling theta1..theta5 *and* the friction) cannot be told from a friction error, and is set aside
    too. The candidates that are those parameters (viscous friction) stay.
    """
    refit = np.asarray(family.refit) > 0
    absorbed = structurally_absorbed(family, refit, sensitivities=sensitivities)
    tested = sorted({p[0] for p in partners if p is not None})
    if isinstance(mode, Refit) and tested:
        with_tested = refit.copy()
        with_tested[tested] = True
        absorbed_with_tested = structurally_absorbed(family, with_tested, sensitivities=sensitivities)
    else:
        absorbed_with_tested = absorbed
    not_identifiable, searchable = [], []
    for k, term in enumerate(candidates):
        if absorbed[k]:
            reason = (f"a refit of the nominal parameters ({', '.join(refit_names)}) reproduces it exactly; "
                      "diagnose in Known() mode with trusted parameters to test it")
        elif absorbed_with_tested[k] and partners[k] is None:
            kept = ", ".join(family.names[i] for i in tested)
            reason = (f"a refit of the nominal parameters ({', '.join(refit_names)}) with a change of the kept ones "
                      f"the candidates test ({kept}) reproduces it exactly, so it cannot be told from an error in "
                      "those; diagnose in Known() mode with trusted parameters to test it")
        else:
            searchable.append(k)
            continue
        not_identifiable.append({"cause": term.cause, "where": term.where(system), "reason": reason})
    if not searchable:
        raise UsageError("diagnose: no candidate is identifiable in this mode")
    return searchable, not_identifiable


def _prepare(system, train, validation, candidates, mode, options: _Options) -> _Problem:
    """Step 0: records on one grid, the candidates and their identifiability, the training and held-out windows."""
    notes: list[str] = []
    train_records, validation_records, dt = _prepare_records(system, train, validation, options.holdout_fraction, notes)
    _note_record_differences(system, train_records + (validation_records if validation is not None else []), notes)
    train_records, validation_records, velocities = _velocity_estimates(system, train_records, validation_records,
                                                                        options.velocities, notes)
    candidates = tuple(default_candidates(system, train_records) if candidates is None else candidates)
    if not candidates:
        raise UsageError("diagnose: `candidates` is empty")
    Extended(system, candidates)  # checks every candidate fits this system
    refit_names = _refit_names(system, mode)
    family, scales, inits = _candidate_family(system, candidates, refit_names, train_records)
    sensitivities = sampled_sensitivities(family)  # the structural tests' one sample of the vector field's derivatives
    partners = held_partners(family, 1.0 - np.asarray(family.refit), sensitivities=sensitivities)
    searchable, not_identifiable = _identifiable(system, candidates, family, refit_names, partners, mode, sensitivities)
    # Candidates that add to a held nominal parameter (viscous friction) are that parameter, not an equivalent.
    equivalents = structurally_equivalent(family, family.refit, [k for k in searchable if partners[k] is None],
                                          sensitivities=sensitivities)
    _note_held(system, family, refit_names, mode, notes)
    fit_window_s = _fit_window(system, train_records, options.fit_window_s, options.horizon_fraction, dt, notes)
    n_fit = max(2, int(round(fit_window_s / dt)))
    horizons, candidates_s = _horizon_grid(options.horizons_s, options.reference_horizon_s, train_records,
                                           validation_records, notes)
    val_stride = max(1, int(round(0.05 / dt)))
    val_windows = make_windows(validation_records, int(round(horizons.max() / dt)), val_stride)
    folds = tuple(range(len(train_records))) if options.cross_fit and len(train_records) >= MIN_CROSS_FIT_RUNS else ()
    if options.cross_fit and len(train_records) == MIN_CROSS_FIT_RUNS - 1:
        notes.append(f"Not cross-fitted: with {len(train_records)} training runs each fold would fit one run alone, and "
                     "a model refitted on one run is judged for that run's excitation (two-fold cross-validation "
                     "penalises every added term); the test is on the held-out runs alone. Three or more training "
                     "runs are cross-fitted.")
    if folds:
        notes.append(f"Cross-fitting: besides the held-out runs, each of the {len(folds)} training runs was held out in "
                     "turn, every configuration refitted on the other training runs (leave-one-run-out), and the test "
                     "pools those windows with the held-out ones; the gains reported are the held-out runs' "
                     "(cross_fit=False tests on the held-out runs alone).")
    return _Problem(
        system=system, train=train_records, validation=validation_records, dt=dt, notes=notes, candidates=candidates,
        refit_names=refit_names, family=family, scales=scales, inits=inits, searchable=searchable,
        not_identifiable=not_identifiable, partners=partners, fit_window_s=fit_window_s,
        train_windows=make_windows(train_records, n_fit, n_fit), val_windows=val_windows,
        window_runs=np.asarray(val_windows.starts)[:, 0], val_stride=val_stride, horizons=horizons,
        candidates_s=candidates_s, options=options, velocities=velocities, folds=folds, equivalents=equivalents,
    )


def _fit_batch(problem: _Problem, slots, new, p_init, say) -> _Batch:
    """Refit a batch of configurations on the training windows (one vmapped `fit_least_squares`) and
    roll every fitted model out on the held-out windows."""
    dtype = problem.family.neutral.dtype
    slots, new = jnp.asarray(slots), jnp.asarray(new)
    free = jnp.ones(problem.n_params, dtype)
    start = time.perf_counter()
    p, cost, std, steps = fit_configurations(problem.family, problem.train_windows, slots, new, jnp.asarray(p_init, dtype), free)
    errors = np.asarray(validate_configurations(problem.family, problem.val_windows, slots, new, p))
    batch = _Batch(np.asarray(p), np.asarray(cost), np.asarray(std), errors, np.asarray(steps),
                   np.zeros(errors.shape[:1] + (0,) + errors.shape[2:]))
    say(f"  batch of {len(batch.p)} fits done in {time.perf_counter() - start:.1f} s "
        f"(Levenberg-Marquardt, {int(batch.steps.max())} steps for the slowest)")
    return batch


def _cross_fit(problem: _Problem, yard: _Yardstick, current_slots, new, batch: _Batch, say) -> _Batch:
    """Cross-fitting: refit the batch's configurations once per training run with that run left out
    (its fit windows at weight zero: the same compiled fit), and simulate each on the left-out run's
    windows of the reference horizon. Each fold's fit starts from the batch's fit on all training runs.

    Held-out runs are what judge a candidate, but a short or chaotic one (6 s of a large-amplitude
    swing) tests with little power, and the training runs then hold most of the evidence: a model
    refitted on the other runs predicts the left-out one as it would a new run. This is K-fold
    cross-validation with the runs as folds (no window crosses a run, so the folds are independent
    records, as the blocked cross-validation of time series asks).

    Only with `MIN_CROSS_FIT_RUNS` (3) training runs or more, so that every fold still fits on two runs
    or more: cross-validation estimates the error of a model fitted on the fold's share of the data, and
    that estimate is pessimistic, more so for the richer model, the smaller the share (Kohavi 1995;
    Arlot & Celisse 2010, section 5). With two runs each fold is one run: on the DFKI split S1 the two
    held-out runs gain 43 % from Coulomb friction at the shoulder after the elbow's (p = 0.004), while
    each single-run fold predicts the other run worse with it, and the pool rejected the lab's effect.

    ??? cite

        R. Kohavi, "A study of cross-validation and bootstrap for accuracy estimation and model
        selection", IJCAI 1995. S. Arlot and A. Celisse, "A survey of cross-validation procedures
        for model selection", Statistics Surveys 4, 2010.
        M. Stone, "Cross-validatory choice and assessment of statistical predictions", Journal of the
        Royal Statistical Society B 36(2), 1974. J. Racine, "Consistent cross-validatory model-selection
        for dependent data: hv-block cross-validation", Journal of Econometrics 99(1), 2000.
        C. Bergmeir and J. M. Benitez, "On the use of cross-validation for time series predictor
        evaluation", Information Sciences 191, 2012.
    """
    if yard.cv_windows is None:
        return batch
    dtype = problem.family.neutral.dtype
    start = time.perf_counter()
    n = len(batch.p)
    slots = jnp.asarray(np.tile(current_slots, (n, 1)))
    new = jnp.asarray(new)
    free = jnp.ones(problem.n_params, dtype)
    runs = np.asarray(yard.cv_windows.starts)[:, 0]
    cv_errors = None
    for r in problem.folds:
        p, _, _, _ = fit_configurations(problem.family, problem.train_windows.without_record(r), slots, new,
                                        jnp.asarray(batch.p, dtype), free)
        # Every training run's windows are simulated and the left-out run's kept: one shape, so one
        # compiled rollout for all folds (the windows are one reference horizon long, so this is cheap).
        errors = np.asarray(validate_configurations(problem.family, yard.cv_windows, slots, new, p))
        if cv_errors is None:
            cv_errors = np.full_like(errors, np.nan)
        cv_errors[:, runs == r] = errors[:, runs == r]
    say(f"  cross-fitted: the batch refitted {len(problem.folds)} times, each training run left out once "
        f"({time.perf_counter() - start:.1f} s)")
    return dataclasses.replace(batch, cv_errors=cv_errors)


def _scores(problem: _Problem, yard: _Yardstick, errors, cv_errors):
    """Each configuration's window scores: the held-out windows, then the cross-fitted ones."""
    scores = _window_scores(errors, yard.n_ref, problem.state_scale)
    if yard.cv_windows is None:
        return scores
    return np.concatenate([scores, _window_scores(cv_errors, yard.n_ref, problem.state_scale)], axis=1)


def _screen(problem: _Problem, current_slots, current_p, remaining, round_, say):
    """Screen: every remaining candidate's linearised held-out gain on one-step residuals; the shortlist."""
    say(f"round {round_ + 1}: screening {len(remaining)} candidates on one-step residuals ...")
    dtype = problem.family.neutral.dtype
    n_nom = len(problem.names)
    coefficients = problem.family.coefficients(jnp.asarray(current_slots), jnp.asarray(-1), jnp.asarray(current_p, dtype))
    gains, deltas = screen(problem.family, current_p[:n_nom], np.asarray(coefficients), problem.family.refit,
                           problem.train, problem.validation, remaining, acceleration_residuals,
                           cross_fit=bool(problem.folds))
    short = choose_shortlist(problem.look_alikes, remaining, gains, problem.options.shortlist)
    return gains, deltas, short


def _refit(problem: _Problem, current_slots, current_p, short, remaining, deltas, round_, say) -> tuple[np.ndarray, _Batch]:
    """Refit: the current model (member 0) and each shortlisted candidate added to it, jointly with the nominal parameters."""
    if short:
        say(f"round {round_ + 1}: simulation-error refit of "
            + ("the nominal model with " if round_ == 0 else "the current model with ")
            + ", ".join(problem.candidates[k].label(problem.system) for k in short) + " (one batch) ...")
    shortlist = problem.options.shortlist
    new = np.asarray([-1] + short + [-1] * (shortlist - len(short)))
    p_init = np.tile(current_p, (shortlist + 1, 1))
    for i, k in enumerate(new):
        if k >= 0:
            start = problem.inits[k] - problem.neutral[k]
            p_init[i, -1] = _start_value(problem, k, deltas[remaining.index(k)], start)
    return new, _fit_batch(problem, np.tile(current_slots, (shortlist + 1, 1)), new, p_init, say)


def _fit_nominal(problem: _Problem, batch: _Batch, say) -> tuple[AbstractSystem, _Yardstick]:
    """Fit the nominal model (member 0 of the first batch) and choose the reference horizon from its training error."""
    model = problem.model_of(-np.ones(problem.options.max_terms, int), batch.p[0]).system
    _note_moved(problem, batch.p[0])
    o = problem.options
    horizon = _reference_horizon(model, problem.train, problem.candidates_s, o.reference_horizon_s, o.horizon_fraction,
                                 problem.val_stride, problem.position_index, problem.dt)
    horizons = problem.horizons
    if horizon.seconds not in horizons:
        horizons = np.sort(np.append(horizons, horizon.seconds))
    n_ref = int(np.round(horizon.seconds / problem.dt))
    cv_windows = make_windows(problem.train, n_ref, problem.val_stride) if problem.folds else None
    window_runs = problem.window_runs
    if cv_windows is not None:
        window_runs = np.concatenate([window_runs, len(problem.validation) + np.asarray(cv_windows.starts)[:, 0]])
    yard = _Yardstick(horizon=horizon, horizons=horizons, steps=np.maximum(np.round(horizons / problem.dt).astype(int), 1),
                      n_ref=n_ref, overlap=max(1, int(np.ceil(n_ref / problem.val_stride))),
                      ref_index=int(np.flatnonzero(np.isclose(horizons, horizon.seconds))[0]),
                      cv_windows=cv_windows, window_runs=window_runs, n_val=len(problem.window_runs))
    return model, yard


# A size parameter (an inertia, a mass, a gravity term) off by more than this factor says the model
# describes another machine: a hidden effect biases an estimate by percent, another machine differs by
# an order of magnitude. Used for the refit here and for the CLI's check of its default model.
OTHER_MACHINE_FACTOR = 2.0


def _note_moved(problem: _Problem, p) -> None:
    """Say so when the refit moved a size parameter (`size_parameter_names`) by more than
    `OTHER_MACHINE_FACTOR`: the nominal model describes another machine (`DoublePendulum()`'s Drake defaults on a
    rig 25 times lighter), and a refit from so far need not reach this one (on the DFKI rig it stopped at
    three times its inertia) and the findings then correct the wrong machine."""
    system, names = problem.system, problem.names
    size = set(size_parameter_names(system))
    given = np.asarray(nominal_values(system, names), float)
    moved = []
    for i, n in enumerate(names):
        if n in size and problem.family.refit[i] > 0 and given[i] > 0:
            ratio = float(p[i]) / given[i]
            if not 1 / OTHER_MACHINE_FACTOR <= ratio <= OTHER_MACHINE_FACTOR:
                moved.append(f"{n} from {given[i]:.4g} to {float(p[i]):.4g}")
    if moved:
        problem.notes.append(
            "The refit moved " + ", ".join(moved) + f" (more than a factor {OTHER_MACHINE_FACTOR:g}): the nominal model "
            "describes another machine, and a refit from that far may stop short of this one, leaving the findings "
            "to correct the wrong model. Start from a nominal model of this machine (e.g. `identify(...).system` "
            "with its friction set to zero; `dynax diagnose` without --nominal does this).")


def _show_what_is_wrong(problem: _Problem, model, batch: _Batch, yard: _Yardstick, say) -> _Nominal:
    """Show what is wrong: the nominal model's held-out simulation error and the structure left in its residuals."""
    rmse = _rmse_curve(batch.errors[0], yard.steps, problem.position_index)
    say(f"reference horizon {yard.horizon.seconds:g} s ({yard.horizon.rule}); nominal model: held-out position RMSE "
        f"{rmse[yard.ref_index]:.4g} there; probing its one-step residuals for structure ...")
    structure = structure_test(model, problem.train, problem.validation)
    return _Nominal(model=model, errors=batch.errors[0], rmse=rmse, structure=structure, cost=float(batch.cost[0]),
                    cv_errors=batch.cv_errors[0])


def _select(problem: _Problem, yard: _Yardstick, current: _Current, results, scores, round_, say) -> dict | None:
    """Select: the admissible candidate with the largest held-out gain, as a finding; `None` if none passed."""
    admissible = [k for k in results if results[k]["significant"]]
    if not admissible:
        say(f"round {round_ + 1}: no candidate improves the held-out simulation significantly")
        return None
    best = max(admissible, key=rank(results))
    r, term, system = results[best], problem.candidates[best], problem.system
    ref = yard.ref_index
    gain = float(1 - r["rmse"][ref] / current.rmse[ref]) if np.isfinite(current.rmse[ref]) else 1.0
    alternatives = look_alike_tests(problem, yard, best, results, scores)
    equivalent = [problem.candidates[k].label(system) for k in problem.equivalents.get(best, [])]
    # A structural equivalent is never told apart, whatever the paired test of two fits of one model says.
    confidence = "high" if all(a["told_apart"] for a in alternatives) else "low"
    if equivalent:
        refit = (f"with a refit of the nominal parameters ({', '.join(problem.refit_names)})" if problem.refit_names
                 else "as the model is written")
        gains = all(problem.candidates[k].cause == "input_gain" for k in [best, *problem.equivalents[best]])
        problem.notes.append(
            f"{term.label(system)} and {', '.join(equivalent)} are one model {refit}: any change of one is a change "
            "of the other, so no data can tell them apart"
            + (" (every torque-side parameter and the gains scaled by one factor leave the motion unchanged: the "
               "data determine only the ratio of the gains)" if gains else "")
            + f". {term.label(system)} is named because it came first; its finding lists the other as a look-alike "
            "it cannot be told apart from.")
    coefficient = problem.neutral[best] + r["delta"]
    say(f"round {round_ + 1}: found {term.label(system)}, {term.parameter_name(system)} = {coefficient:.4g} "
        f"(held-out gain {gain:.0%}, p = {r['p']:.2g}, helps on {r['runs_helped']}/{r['n_runs']} held-out runs; "
        f"told apart from look-alikes: {confidence})")
    return {"index": best, "cause": term.cause, "where": term.where(system), "coefficient": float(coefficient),
            "std_error": float(r["std"]), "gain": gain, "parameter": term.parameter_name(system), "p_value": r["p"],
            "look_alikes": alternatives, "confidence": confidence, "runs_helped": f"{r['runs_helped']}/{r['n_runs']}"}


def _accept(problem: _Problem, current: _Current, finding: dict, results, batch: _Batch, scores, say) -> _Current:
    """Add the selected candidate to the current model (its coefficient moves into the next free slot)."""
    best = finding.pop("index")
    r = results[best]
    selected = current.selected + [best]
    slot = len(problem.names) + len(selected) - 1
    slots = current.slots.copy()
    slots[len(selected) - 1] = best
    p, std = batch.p[r["i"]].copy(), batch.std[r["i"]].copy()
    p[slot], p[-1] = p[-1], 0.0
    std[slot] = std[-1]
    say("probing the extended model's residuals for structure ...")
    structure = structure_test(problem.model_of(slots, p), problem.train, problem.validation)
    # The probe never vetoes: selection goes on while a candidate's own held-out test passes.
    return _Current(slots=slots, p=p, std=std, score=scores[r["i"]], errors=batch.errors[r["i"]], rmse=r["rmse"],
                    structure=structure, cv_errors=batch.cv_errors[r["i"]], selected=selected,
                    findings=current.findings + [finding])


def _complete_look_alikes(problem, yard, cur_slots, cur_p, short, remaining, deltas, batch, scores, results, judge,
                          round_, say):
    """Refit the look-alikes of the round's best admissible candidate that screening left off the shortlist.

    A finding's confidence rests on beating its look-alikes (same place, same group of causes) in the
    held-out test; one that was never refitted cannot have been beaten. So its missing look-alikes get
    one more batch of fits (the same compiled batch), the round is judged again over both batches
    (Benjamini-Hochberg over the same remaining candidates: an untested one counted as p = 1 before),
    and if the best changes, its own missing look-alikes are added once more.
    """
    system, candidates = problem.system, problem.candidates
    for _ in range(2):
        admissible = [k for k in results if results[k]["significant"]]
        if not admissible:
            break
        best = max(admissible, key=rank(results))
        missing = [k for k in problem.look_alikes(best) if k in remaining and k not in results]
        missing = missing[: problem.options.shortlist]
        if not missing:
            break
        say(f"round {round_ + 1}: {candidates[best].label(system)} leads; refitting its look-alike(s) "
            f"{', '.join(candidates[k].label(system) for k in missing)}, which screening left out ...")
        new, more = _refit(problem, cur_slots, cur_p, missing, remaining, deltas, round_, say)
        more = _cross_fit(problem, yard, cur_slots, new, more, say)
        n = 1 + len(short)
        batch = _Batch(*(np.concatenate([getattr(batch, f.name)[:n], getattr(more, f.name)[1 : 1 + len(missing)]])
                         for f in dataclasses.fields(_Batch)))
        scores = _scores(problem, yard, batch.errors, batch.cv_errors)
        short = short + missing
        results = judge(short, batch, scores)
    return short, batch, scores, results


def _forward_selection(problem: _Problem, say):
    """Fit the nominal model, show what is wrong, then per round screen, refit and select.

    **Returns:** `(nominal, yardstick, current, candidate_table, last_round_results, rounds)`; `rounds`
    one `_round_summary` per round.
    """
    o = problem.options
    slots = -np.ones(o.max_terms, int)
    p0 = np.concatenate([np.asarray(nominal_values(problem.system, problem.names), float), np.zeros(o.max_terms + 1)])
    nominal = yard = current = None
    table, last, rounds = [], {}, []
    for round_ in range(o.max_terms):
        remaining = [k for k in problem.searchable if current is None or k not in current.selected]
        if not remaining and round_ > 0:
            break
        cur_slots, cur_p = (slots, p0) if current is None else (current.slots, current.p)
        gains, deltas, short = _screen(problem, cur_slots, cur_p, remaining, round_, say) if remaining else ([], [], [])
        new, batch = _refit(problem, cur_slots, cur_p, short, remaining, deltas, round_, say)
        if round_ == 0:
            model, yard = _fit_nominal(problem, batch, say)
            batch = _cross_fit(problem, yard, cur_slots, new, batch, say)
            nominal = _show_what_is_wrong(problem, model, batch, yard, say)
            scores = _scores(problem, yard, batch.errors, batch.cv_errors)
            current = _Current(slots=slots, p=batch.p[0].copy(), std=batch.std[0].copy(), score=scores[0],
                               errors=batch.errors[0], rmse=nominal.rmse, structure=nominal.structure,
                               cv_errors=batch.cv_errors[0])
        else:
            batch = _cross_fit(problem, yard, cur_slots, new, batch, say)
            scores = _scores(problem, yard, batch.errors, batch.cv_errors)
        if not short:
            break
        judge = lambda short, batch, scores: judge_round(  # noqa: E731
            problem.physical, short, remaining, current.selected, len(problem.names), batch.p, batch.std, batch.errors,
            scores, current.score, yard.window_runs, yard.overlap, o.alpha, o.min_gain, yard.steps,
            problem.position_index, yard.n_val)
        results = judge(short, batch, scores)
        short, batch, scores, results = _complete_look_alikes(problem, yard, cur_slots, cur_p, short, remaining, deltas,
                                                              batch, scores, results, judge, round_, say)
        last = results
        if round_ == 0:
            table = _candidate_table(problem.system, problem.candidates, remaining, gains, results, problem.neutral, batch.cost)
        finding = _select(problem, yard, current, results, scores, round_, say)
        rounds.append(_round_summary(problem, yard, round_, current, remaining, results, finding))
        if finding is None:
            break
        current = _accept(problem, current, finding, results, batch, scores, say)
    else:
        if rounds:
            rounds[-1]["outcome"] += f"; max_terms = {o.max_terms} reached"
    return nominal, yard, current, table, last, rounds


def _extend(problem: _Problem, current: _Current) -> tuple[Extended, list[dict]]:
    """Extend: the nominal model with the selected terms, every coefficient from the final joint fit
    (earlier rounds' values move when later terms join); repeated causes merged into one finding."""
    n_nom = len(problem.names)
    findings = [dict(f) for f in current.findings]
    for m, (finding, k) in enumerate(zip(findings, current.selected)):
        finding["coefficient"] = float(problem.neutral[k] + current.p[n_nom + m])
        finding["std_error"] = float(current.std[n_nom + m])
    model = problem.model_of(current.slots, current.p)
    return Extended(model.system, tuple(model.terms[k] for k in current.selected)), _merge_repeated_causes(findings)


@dataclasses.dataclass
class _Judgement:
    """The verdict and what it rests on: the final model, its findings, held-out errors and structure."""

    verdict: str
    model: AbstractSystem
    findings: list
    errors: np.ndarray
    rmse: np.ndarray
    structure: Structure
    gain: float
    discovery: dict
    cv_errors: np.ndarray  # the named causes' model on the cross-fitted windows (discovered terms are not cross-fitted)


def _judge(problem: _Problem, nominal: _Nominal, yard: _Yardstick, current: _Current, say) -> _Judgement:
    """Judge: `explained`, `none` or `unexplained` from the findings and the structure left; then, where
    it is not `explained` and discovery is on, search beyond the vocabulary with the same held-out test."""
    model, findings = _extend(problem, current)
    if not current.selected:
        verdict = "unexplained" if nominal.structure.significant else "none"
    else:
        verdict = "unexplained" if current.structure.significant else "explained"
    gain = _gain(current.rmse, nominal.rmse, yard.ref_index) if current.selected else 0.0
    judgement = _Judgement(verdict, model, findings, current.errors, current.rmse, current.structure, gain, {},
                           current.cv_errors)
    # Beyond the vocabulary: search, refit, the same held-out test. Also after a `none`: the generic
    # probe cannot see every structure (a force periodic in position), the search's own guards can.
    if problem.options.discovery and verdict != "explained":
        judgement = _discover(problem, nominal, yard, current, judgement, say)
    return judgement


def _discover(problem: _Problem, nominal: _Nominal, yard: _Yardstick, current: _Current, judgement: _Judgement, say):
    o = problem.options
    held_out_errors = eqx.filter_jit(window_errors)
    last_errors = {}

    def held_out(model):
        errors = np.asarray(held_out_errors(model, problem.val_windows))
        last_errors[id(model)] = errors
        curve = _rmse_curve(errors, yard.steps, problem.position_index)
        return _window_scores(errors[None], yard.n_ref, problem.state_scale)[0], curve, curve[yard.ref_index]

    system = problem.system
    found = discover(
        judgement.model if current.selected else nominal.model, problem.train, problem.validation, held_out=held_out,
        significance=lambda ref, new: paired_test(ref, new, problem.window_runs, yard.overlap).p_value,
        refit=problem.refit_names, vocabulary=[problem.candidates[k].label(system) for k in problem.searchable],
        absorbed=[f"{c['cause']}@{c['where']}" for c in problem.not_identifiable], alpha=o.alpha, min_gain=o.min_gain,
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
        judgement = _Judgement("unexplained" if structure.significant else "explained", found.model,
                               judgement.findings + found.findings, errors, found.held_out[1], structure,
                               _gain(found.held_out[1], nominal.rmse, yard.ref_index), judgement.discovery,
                               judgement.cv_errors)
    return judgement


def _model_summary(problem: _Problem, model, errors, rmse, yard: _Yardstick, terms=None) -> ModelSummary:
    """The `nominal` / `extended` object: parameters by report name, held-out error curve, validation block."""
    system = model.system if isinstance(model, Extended) else model
    parameters = dict(zip(problem.names, map(float, nominal_values(system, problem.names))))
    if isinstance(model, Extended):
        parameters.update({k: float(v) for t in model.terms for k, v in t.parameters(problem.system).items()})
    measured = np.asarray(problem.val_windows.xs)[:, yard.n_ref]
    validation = validation_summary(model, problem.validation, np.asarray(errors)[:, yard.n_ref], measured,
                                    yard.horizon.seconds)
    return ModelSummary(parameters=parameters, sim_error=SimErrorCurve.of(yard.horizons, rmse), terms=terms,
                        validation=validation)


def _data_summary(problem: _Problem, train, validation) -> DataSummary:
    given = _as_records(train, "train")
    held_out = problem.validation
    if validation is not None:
        validation_name = ", ".join(r.source or "(held out)" for r in held_out)
    else:
        validation_name = "last {:.0%} of {}".format(problem.options.holdout_fraction,
                                                     ", ".join(r.source or "train" for r in given))
    return DataSummary(
        train=", ".join(r.source or "(train)" for r in given), validation=validation_name,
        n_train=int(sum(len(r) for r in problem.train)), n_validation=int(sum(len(r) for r in held_out)), dt=problem.dt,
        train_runs=tuple(r.source or f"train run {i + 1}" for i, r in enumerate(problem.train)),
        validation_runs=tuple(r.source or f"held-out run {i + 1}" for i, r in enumerate(held_out)),
        velocities=problem.velocities,
    )


def _report(problem, nominal, yard, judgement, table, last, rounds, *, mode, system_name, train, validation) -> Report:
    """The typed `Report` that `report.json` and `report.md` are written from."""
    system, o = problem.system, problem.options
    notes = list(problem.notes)
    if judgement.verdict == "unexplained":
        notes.append(_unexplained_note(judgement.structure))
    test = _test_summary(o.alpha, o.min_gain, last, judgement.verdict)
    test["cross_fitting"] = (f"each of the {len(problem.folds)} training runs also held out in turn, every configuration "
                             "refitted on the other training runs; its windows pooled with the held-out runs'"
                             if problem.folds else None)
    if test["detectable_gain"] is not None:
        runs = "held-out and cross-fitted runs" if problem.folds else "held-out runs"
        notes.append(f"No candidate passed the test. With these {runs} the test would have detected a gain of "
                     f"about {test['detectable_gain']:.0%} at {yard.horizon.seconds:g} s (power 80 %) if its window-to-window "
                     f"variation is like the refitted candidates'; a smaller effect, or one that varies more (friction "
                     f"acting in the slow segments only), may be present.")
    extended = judgement.model
    terms = tuple(dict.fromkeys(t.label(system) for t in extended.terms))  # wind@world once
    return Report(
        system=system_name or problem.train[0].system or _CONTRACT_NAMES.get(type(system).__name__, type(system).__name__.lower()),
        data=_data_summary(problem, train, validation),
        mode="refit" if isinstance(mode, Refit) else "known",
        nominal=_model_summary(problem, nominal.model, nominal.errors, nominal.rmse, yard),
        verdict=judgement.verdict,
        findings=judgement.findings,
        extended=_model_summary(problem, extended, judgement.errors, judgement.rmse, yard, terms=terms),
        gain=judgement.gain,
        reference_horizon_s=float(yard.horizon.seconds),
        structure={"nominal": nominal.structure, "extended": judgement.structure},
        not_identifiable=problem.not_identifiable,
        candidates=table,
        notes=notes,
        horizon=yard.horizon,
        runs=_per_run_table(problem, yard, nominal, judgement),
        test=test,
        nominal_model=nominal.model,
        extended_model=extended,
        discovery=judgement.discovery,
        rounds=rounds,
    )


def diagnose(
    system: AbstractSystem,
    train: Trajectory | Sequence[Trajectory],
    validation: Trajectory | Sequence[Trajectory] | None = None,
    *,
    candidates: Sequence[AbstractTerm] | None = None,
    mode: Refit | Known = Refit(),
    horizons_s: Sequence[float] = (0.1, 0.25, 0.5, 1.0, 2.0),
    reference_horizon_s: float | None = None,
    horizon_fraction: float = DEFAULT_FRACTION,
    fit_window_s: float | None = None,
    max_terms: int = 3,
    alpha: float = 0.01,
    min_gain: float = 0.05,
    holdout_fraction: float = HOLDOUT_FRACTION,
    shortlist: int = 4,
    system_name: str | None = None,
    discovery: bool = True,
    velocities: str = "auto",
    cross_fit: bool = True,
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
       `alpha`; see `_statistics`), at least `min_gain`, helps on most held-out runs, and has a
       physical sign. With three or more training runs the test also holds out each training run
       in turn (cross-fitting: every configuration refitted on the other training runs) and pools
       those windows with the held-out ones; a candidate must then still not make the held-out runs
       worse. Candidates a refit of the nominal parameters reproduces exactly are set
       aside as not identifiable. The residual probe never stops the search.
    4. **Extend** the model with the selected terms, refitted jointly.
    5. **Measure the gain**: held-out simulation error, nominal against extended.
    6. **Verdict**: `none` (no candidate helps and the probe finds no structure), `explained`
       (causes found and the extended model's residuals have no structure left), `unexplained`
       (structure the candidates do not fully explain; partial findings are listed).
    7. **Discover** (where the verdict would be `unexplained` or `none` and `discovery` is on): a sparse
       search for the missing term beyond the vocabulary, refitted through simulation and kept
       only if it passes the same held-out test (see `dynax._diagnose._discovery.discover`);
       findings with cause `discovered`. The verdict is then `explained` if the named and
       discovered terms leave no significant structure.

    Where the runs' recorded forces carry constant offsets that differ from run to run (a sensor's
    zero, which no candidate can carry to another run; `dynax.record_offsets` on the nominal model's
    inverse-dynamics equations, two-link arms and the linear axis), the report's notes say so.

    **Arguments:**

    - `system`: the nominal model (its parameters are the start of the fit, or trusted in `Known`).
    - `train`: the training record(s).
    - `validation`: held-out record(s); default the last `holdout_fraction` of each training record.
    - `candidates`: terms at neutral values (default `default_candidates(system)`: the contract's
      vocabulary).
    - `mode`: `Refit()` (default) or `Known()`.
    - `horizons_s`: where the held-out simulation error is reported.
    - `reference_horizon_s`: where it is judged; default the *predictability horizon*: the
      longest horizon at which the nominal model's open-loop position error on the training runs
      is at most `horizon_fraction` of the positions' spread (see `predictability_horizon`).
    - `fit_window_s`: window length of the simulation-error fits; default from the data: 2.5 times
      the starting model's predictability horizon on the training runs, between 0.25 s and 1 s
      (a fit over windows longer than the model can predict fits chaos, not physics).
    - `max_terms`: at most this many causes are selected.
    - `alpha`, `min_gain`: significance level and smallest held-out gain that counts.
    - `shortlist`: candidates refitted jointly per round.
    - `system_name`: the contract name for the report (default the records' `system`).
    - `discovery`: search for a term beyond the vocabulary when structure is left (default on).
    - `velocities`: `"auto"` (default): for a system whose states are joint positions and velocities,
      each measured velocity that carries white noise larger than the bias of a local cubic fit of
      its positions (Savitzky-Golay over half a period of the signal band's edge; see
      `dynax._identify._defaults.with_velocities_from_positions`) is replaced by that fit's
      derivative before anything is fitted or compared: the windows then start from better
      velocities and are compared with them, so the held-out errors measure the model, not the
      velocity sensor. `"measured"` keeps the records as they are. The report's
      `data.velocities` says which was used.
    - `cross_fit`: with three or more training runs (default on), each training run is also held out
      in turn (with two, each fold would fit one run alone, a pessimistic judge of every added term;
      the report's notes say so): the screening's regression and every refit of a round are repeated on the other
      training runs, the left-out run is simulated over the reference horizon, and the paired test and
      the run agreement pool those windows with the held-out runs' (leave-one-run-out
      cross-validation; see `_cross_fit`). A short held-out run (a few seconds of a chaotic swing)
      then no longer decides alone; each round costs one more batch of fits per training run. The
      reported gains and error curves stay those of the held-out runs; `report.runs` lists the
      cross-fitted runs too. `False` tests on the held-out runs alone, as before 2026-11-25.
    - `progress`: a callable is called with a line of text at each stage (e.g. `print`, or a
      `dynax.ProgressBar`'s `say`); otherwise a progress bar on stderr, one step per stage and per
      candidate batch: `True` / `False` force it on / off, `None` (default) draws it when stderr is a
      terminal (see `dynax.progress_mode`; the CLI's `--quiet` silences it).

    **Returns:** a `Report`.

    ??? cite

        L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, ch. 16 (model
        structure selection and validation). N. R. Draper and H. Smith, *Applied Regression
        Analysis*, 3rd ed., 1998, ch. 15 (forward selection).
    """
    warn_if_float32("diagnosis")  # the float64 policy: say so, once, naming the switch
    _check_arguments(system, mode, max_terms)
    if velocities not in ("auto", "measured"):
        raise UsageError(f"diagnose: `velocities` must be 'auto' or 'measured', got {velocities!r}")
    options = _Options(horizons_s, reference_horizon_s, horizon_fraction, fit_window_s, max_terms, alpha, min_gain,
                       holdout_fraction, shortlist, discovery, velocities, cross_fit)
    with stage_reporter(progress) as say:
        problem = _prepare(system, train, validation, candidates, mode, options)
        nominal, yard, current, table, last, rounds = _forward_selection(problem, say)
        judgement = _judge(problem, nominal, yard, current, say)
        say("validation: fit % and residual tests of the nominal and the extended model ...")
        return _report(problem, nominal, yard, judgement, table, last, rounds, mode=mode, system_name=system_name,
                       train=train, validation=validation)


def _start_value(problem: _Problem, k: int, delta_screened, start):
    """A candidate's starting coefficient: the screening's step if physical and moderate, else the default start."""
    term, scale = problem.candidates[k], problem.scales[k]
    ok = np.isfinite(delta_screened) and problem.physical(k, delta_screened) and abs(delta_screened) < 20 * scale
    lagging = isinstance(term, AbstractInputTerm) and term.n_hidden and delta_screened < start
    return delta_screened if ok and not lagging else start


def _note_record_differences(system, records, notes) -> None:
    """Say so when the runs' recorded forces carry constant offsets that differ from run to run
    (`dynax.record_offsets`, on the inverse-dynamics equations of the nominal model's structure as
    `identify` builds them; the held-out runs too when they are the user's own): a sensor zero that
    no candidate can carry from one run to another, and that stays in each held-out run's error
    whatever is named (the DFKI shoulder torque: 0.14 N m in run 00, 0.07 in run 01). Likewise when
    the runs' Coulomb friction differs (`dynax.record_friction`; the DFKI elbow: 0.05 to 0.13 N m).
    Notes only: they enter no test."""
    for check in compare_records(system, records):
        if check is not None and check.differ():
            notes.append(check.note())


def _note_held(system, family, refit_names, mode, notes) -> None:
    """Say which nominal parameters a `Refit()` keeps, and why."""
    if not isinstance(mode, Refit):
        return
    held = [n for n, r in zip(family.names, np.asarray(family.refit)) if r == 0]
    if held and mode.parameters is None:
        values = nominal_values(system, family.names)
        notes.append("Refit mode refits " + ", ".join(refit_names) + "; the nominal model's friction ("
                     + ", ".join(f"{n} = {float(values[family.names.index(n)]):.4g}" for n in held)
                     + ") keeps its value and the friction candidates test it (Refit(parameters=...) "
                     "chooses otherwise).")

