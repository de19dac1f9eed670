"""Forward selection, steps 1 to 3 of `diagnose`: fit the nominal model, show what is wrong, then per
round screen every remaining candidate, refit the shortlist (cross-fitted over the training runs) and
select the best admissible one.
"""

import dataclasses
import functools
from statistics import NormalDist
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._model._linear_in_parameters import size_parameter_names
from .._model._system import AbstractSystem
from .._validate import Horizon
from ._candidates import host_nominal_values
from ._fit import fit_configurations, make_windows, validate_configurations, Windows
from ._problem import Problem
from ._records import reference_horizon
from ._residuals import acceleration_residuals, input_dynamics, Structure, structure_test
from ._rollout_screening import rankable, rollout_screen, with_rollout_evidence
from ._screening import screen
from ._selection import choose, choose_shortlist, judge_round, look_alike_tests, Refitted
from ._summaries import candidate_table, rmse_curve, round_summary, window_scores

# Windows per vector of XLA's CPU loops (AVX-512 holds eight doubles); see `_cross_fit`.
_LANES = 8


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
class Yardstick:
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
class Current:
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


@dataclasses.dataclass(frozen=True)
class Round:
    """Where a round starts: its index, the current model's slots and parameters (every refit of the round starts
    from them), the candidates remaining, their steps from the screening, and the candidate with input dynamics the
    held one-step map is refitted through (`_through_inputs`; `None` where none fits one step better)."""

    index: int
    slots: np.ndarray
    p: np.ndarray
    remaining: list
    deltas: np.ndarray | list
    through: "Through | None" = None


@dataclasses.dataclass
class Nominal:
    """The fitted nominal model and what it gets wrong on held-out data."""

    model: AbstractSystem
    errors: np.ndarray
    rmse: np.ndarray
    structure: Structure
    cost: float
    cv_errors: np.ndarray


def _fit_batch(problem: Problem, slots, new, p_init, say) -> _Batch:
    """Refit a batch of configurations on the training windows (one vmapped `fit_least_squares`) and
    roll every fitted model out on the held-out windows."""
    dtype = problem.family.neutral.dtype
    # Host arrays moved by `device_put`: `jnp.asarray` and `jnp.ones` compile a small program for each new shape.
    slots, new = _on_device(slots), _on_device(new)
    free = _on_device(np.ones(problem.n_params, dtype))
    start = time.perf_counter()
    p, cost, std, steps = fit_configurations(
        problem.family, problem.train_windows, slots, new, _on_device(p_init, dtype), free
    )
    errors = np.asarray(validate_configurations(problem.family, problem.val_windows, slots, new, p))
    batch = _Batch(
        np.asarray(p),
        np.asarray(cost),
        np.asarray(std),
        errors,
        np.asarray(steps),
        np.zeros(errors.shape[:1] + (0,) + errors.shape[2:]),
    )
    say(
        f"  batch of {len(batch.p)} fits done in {time.perf_counter() - start:.1f} s "
        f"(Levenberg-Marquardt, {int(batch.steps.max())} steps for the slowest)"
    )
    return batch


def _on_device(a, dtype=None) -> jax.Array:
    """The host array `a` (as `dtype`) on the device: the same values and dtype as `jnp.asarray(a, dtype)` (strong
    types both), without the copy program that `jnp.asarray` and `jnp.ones` compile for every new shape."""
    return jax.device_put(np.asarray(a, dtype))


def _cross_fit(problem: Problem, yard: Yardstick, current_slots, new, batch: _Batch, say) -> _Batch:
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
    Arlot & Celisse 2010, section 5). With two runs each fold is one run, and a single-run fold can
    predict the other run worse with a term that the held-out runs gain from, so the pool would reject
    a real effect (measured on a real rig: docs/devdocs/code_notes.md).

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
    slots = _on_device(np.tile(current_slots, (n, 1)))
    new = _on_device(new)
    free = _on_device(np.ones(problem.n_params, dtype))
    fold_of = cv_fold_of(problem.folds, yard.cv_windows)
    # Each fold's refit simulates the span of windows that holds the left-out fold's (a third of them with three
    # runs, not all), every span as long as the longest: one shape, so one compiled rollout for all folds. A span
    # starts at a multiple of `_LANES` and its length is the number of windows modulo `_LANES`, so every window
    # keeps its place in the batch modulo `_LANES`: XLA's CPU code rounds a rollout by an ulp differently at
    # another place in its vector loop, and a chaotic window turns that into 1e-14 (measured), where the spans
    # give the numbers of simulating every window, bit for bit.
    total = len(fold_of)
    members = [np.flatnonzero(fold_of == i) for i in range(len(problem.folds))]
    firsts = [int(m[0]) - int(m[0]) % _LANES if len(m) else 0 for m in members]
    width = max((int(m[-1]) + 1 - a for m, a in zip(members, firsts) if len(m)), default=0)
    width = min(width + (total - width) % _LANES, total)
    steps = yard.cv_windows.ts.shape[1]
    cv_errors = np.full((n, total, steps) + batch.errors.shape[3:], np.nan, batch.errors.dtype)
    for fold, member, first in zip(problem.folds, members, firsts):
        if not len(member):
            continue
        # A held-out block's test windows reach one reference horizon past it: the fit leaves out every window
        # that shares a sample with that span (with whole runs as folds, the run).
        left_out = problem.train_windows.without_span(fold.record, fold.start, fold.stop + yard.n_ref)
        p, _, _, _ = fit_configurations(problem.family, left_out, slots, new, _on_device(batch.p, dtype), free)
        first = min(first, total - width)
        span = yard.cv_windows.take(np.arange(first, first + width))
        errors = np.asarray(validate_configurations(problem.family, span, slots, new, p))
        cv_errors[:, member] = errors[:, member - first]
    say(
        f"  cross-fitted: the batch refitted {len(problem.folds)} times, each training run left out once "
        f"({time.perf_counter() - start:.1f} s)"
    )
    return dataclasses.replace(batch, cv_errors=cv_errors)


def cv_fold_of(folds, cv_windows: Windows) -> np.ndarray:
    """The fold of each cross-fitted window: the one whose record and samples hold the window's start."""
    starts = np.asarray(cv_windows.starts)
    fold_of = np.full(len(starts), -1)
    for i, fold in enumerate(folds):
        fold_of[(starts[:, 0] == fold.record) & (starts[:, 1] >= fold.start) & (starts[:, 1] < fold.stop)] = i
    return fold_of


def _scores(problem: Problem, yard: Yardstick, errors, cv_errors):
    """Each configuration's window scores: the held-out windows, then the cross-fitted ones."""
    scores = window_scores(errors, yard.n_ref, problem.state_scale)
    if yard.cv_windows is None:
        return scores
    return np.concatenate([scores, window_scores(cv_errors, yard.n_ref, problem.state_scale)], axis=1)


def _starting_point(problem: Problem):
    """The first round's configuration: no candidate in any slot, the nominal parameters, every coefficient zero."""
    o = problem.selection
    slots = -np.ones(o.max_terms, int)
    given = np.asarray(host_nominal_values(problem.system, problem.names), float)
    p0 = np.concatenate([given, np.zeros(o.max_terms + 1)])
    return slots, p0


def _screened(problem: Problem, current_slots, current_p, remaining):
    """Each of `remaining`'s linearised held-out gain on one-step residuals and its step (`screen`), from the
    configuration `current_slots`, `current_p`."""
    n_nom = len(problem.names)
    return screen(
        problem.family,
        current_p[:n_nom],
        problem.family.host_coefficients(current_slots, -1, current_p),
        problem.train,
        problem.validation,
        remaining,
        acceleration_residuals,
        cross_fit=bool(problem.folds),
    )


def first_screening(problem: Problem) -> dict[str, tuple[float, float]]:
    """`diagnose`'s first-round screening of a prepared `problem` (`prepare_problem`): for every searchable
    candidate, by its label, its linearised held-out gain on one-step residuals and the coefficient step the
    screening estimates (the start its refit takes where that is physical and moderate)."""
    slots, p0 = _starting_point(problem)
    gains, deltas = _screened(problem, slots, p0, list(problem.searchable))
    system = problem.family.model.system
    labels = [problem.family.model.terms[k].label(system) for k in problem.searchable]
    return {label: (float(g), float(d)) for label, g, d in zip(labels, gains, deltas)}


def _screen(problem: Problem, current_slots, current_p, remaining, round_, through, say):
    """Screen: every remaining candidate's linearised held-out gain on one-step residuals; the shortlist."""
    say(f"round {round_ + 1}: screening {len(remaining)} candidates on one-step residuals ...")
    gains, deltas = _screened(problem, current_slots, current_p, remaining)
    short = choose_shortlist(problem.look_alikes, remaining, gains, problem.selection.shortlist)
    if round_ == 0:
        short = with_rest_evidence(problem, remaining, gains, short)
    before = list(short)
    short = with_through_evidence(problem, remaining, gains, short, through)
    if through is not None and through.evidence and through.candidate not in before:
        k = through.candidate
        order = int(np.sum(np.asarray(gains) > gains[remaining.index(k)])) + 1
        left = [j for j in before if j not in short]
        say(
            f"  {problem.candidates[k].label(problem.system)} joins the shortlist"
            + (f" in place of {problem.candidates[left[0]].label(problem.system)}" if left else "")
            + f": the held one-step map refitted through it fits one step better (likelihood ratio "
            f"{through.ratio:.3g}, bar {through.bar:.3g}; screened against the held map it ranked {order} of "
            f"{len(remaining)})"
        )
    return gains, deltas, _with_rollout_evidence(problem, current_slots, current_p, remaining, gains, short, say)


def _with_rollout_evidence(problem: Problem, current_slots, current_p, remaining, gains, short, say):
    """The shortlist with the candidates the output-error screening ranks above shortlisted ones
    (`with_rollout_evidence`: at most a quarter of the shortlist, at least one)."""
    ranked = rankable(problem.family, remaining)
    if len(ranked) <= 1 or all(k in short for k in ranked):
        return short
    rollout_gains = rollout_screen(
        problem.family, problem.train_windows, problem.held_out_fit_windows, current_slots, current_p, ranked
    )
    n_promote = max(1, problem.selection.shortlist // 4)
    before = list(short)
    short, promoted = with_rollout_evidence(
        problem.look_alikes, remaining, gains, short, ranked, rollout_gains, n_promote, problem.selection.min_gain
    )
    label = lambda k: problem.candidates[k].label(problem.system)  # noqa: E731
    for k in promoted:
        order = int(np.sum(np.asarray(gains) > gains[remaining.index(k)])) + 1
        say(
            f"  {label(k)} joins the shortlist in place of {label(before[short.index(k)])}: its first Gauss-Newton "
            f"step gains {rollout_gains[ranked.index(k)]:.0%} on the held-out windows (equation-error screening "
            f"ranked it {order} of {len(remaining)})"
        )
    return short


def with_rest_evidence(problem: Problem, remaining, gains, short):
    """The first round's shortlist with every `stiction` candidate in it (at most all but the two best screened; the
    refit's batch has the shortlist's size, so a stiction takes the place of the lowest-screened other).

    A stiction is proposed only where the records show a joint held at rest under load (`rests_under_load`): that
    evidence is its screening. The one-step screening sees it in the rests' share of the samples only, where the
    residuals of the refitted nominal model in motion dominate, and ranks it among candidates that gain nothing
    (1 to 2 % on records that rest a sixth of the time, whose refit then gains 75 %). In later rounds it is
    screened as the others are: the evidence was read against the nominal model, and a slot held for it in every
    round would push out candidates a later round needs."""
    n = problem.selection.shortlist
    static = [k for k in remaining if problem.candidates[k].cause == "stiction" and k not in short]
    static = sorted(static, key=lambda k: -gains[remaining.index(k)])[: max(n - 2, 0)]
    if not static:
        return short
    kept = [k for k in short if k not in static]
    return kept[: max(n - len(static), 0)] + static


def with_through_evidence(problem: Problem, remaining, gains, short, through: "Through | None"):
    """The shortlist with the lag or delay the held one-step map is refitted through (`_through_inputs`), in place
    of the lowest-screened other (the best screened keeps its place; nothing changes with a shortlist of one).

    Its evidence is the likelihood-ratio test there: the map refitted one step through it fits the one-step
    residuals better than chance allows. The equation-error screening cannot show it: it reads every candidate
    against the held map, which has taken up part of the lag or delay (the least-squares map of the command as
    logged is a smoothed, attenuated map of the one that acts), and a lag or delay added to that map makes it worse
    one step ahead (on the calibration battery's 40 ms dead time and 80 ms lag of one motor, -5.6 and -3.2 %), so
    the candidate that `_refit` would start through the refitted map never reached the shortlist. The held-out
    test then judges it as any other: its Benjamini-Hochberg correction counts every remaining candidate, refitted
    or not, so a place on the shortlist does not lower the bar."""
    n = problem.selection.shortlist
    if (
        through is None
        or not through.evidence
        or n < 2
        or through.candidate in short
        or through.candidate not in remaining
    ):
        return short
    order = sorted(short, key=lambda k: -gains[remaining.index(k)])
    return [k for k in short if k in order[: n - 1]] + [through.candidate]


def _refit(problem: Problem, round_: Round, short, say) -> tuple[np.ndarray, _Batch]:
    """Refit: the current model (member 0) and each shortlisted candidate added to it, jointly with the nominal
    parameters."""
    if short:
        say(
            f"round {round_.index + 1}: simulation-error refit of "
            + ("the nominal model with " if round_.index == 0 else "the current model with ")
            + ", ".join(problem.candidates[k].label(problem.system) for k in short)
            + " (one batch) ..."
        )
    shortlist = problem.selection.shortlist
    new = np.asarray([-1] + short + [-1] * (shortlist - len(short)))
    p_init = np.tile(round_.p, (shortlist + 1, 1))
    through = round_.through
    for i, k in enumerate(new):
        if k >= 0:
            start = problem.inits[k] - problem.neutral[k]
            p_init[i, -1] = _start_value(problem, k, round_.deltas[round_.remaining.index(k)], start)
            if through is not None and k in through.alike_starts:  # a look-alike on the same inputs: its own
                p_init[i] = through.alike_starts[k]
            if through is not None and through.candidate == k:
                p_init[i] = through.p
                c = problem.neutral[k] + through.p[-1]
                label = problem.candidates[k].label(problem.system)
                say(
                    f"  {label}: held map refitted one step through it at {c:.3g} (its one-step optimum"
                    + (
                        ""
                        if through.evidence
                        else f"; likelihood ratio {through.ratio:.3g}, under the bar {through.bar:.3g}"
                    )
                    + ")"
                )
    return new, _fit_batch(problem, np.tile(round_.slots, (shortlist + 1, 1)), new, p_init, say)


@dataclasses.dataclass(frozen=True)
class Through:
    """The lag or delay the held one-step map is refitted through (`_through_inputs`): the `candidate`, the start `p`
    of its configuration (the refitted map, its coefficient in the last place), and the test that chose it: the
    likelihood `ratio` of the one extra coefficient, the `bar`, and whether it passed it (`evidence`: only then is
    it a place on the shortlist; below the bar it is the candidate's start where the screening shortlisted it).
    `alike_starts`: the start of each look-alike with input dynamics on the same inputs (a lag beside a dead
    time), from the map refitted one step through it at its own best coefficient."""

    candidate: int
    p: np.ndarray
    ratio: float
    bar: float
    evidence: bool = True
    alike_starts: dict = dataclasses.field(default_factory=dict)


def _through_inputs(problem: Problem, slots, p, remaining) -> Through | None:
    """The candidate with input dynamics that the held one-step map is refitted through in this round, and its
    configuration's start: where the problem's nominal values are a one-step fit of the recorded inputs
    (`Problem.nominal_through`), the quadrotor's motor map.

    A map fitted one step at a time on commands that act through a lag or a dead time has taken up part of them
    (the least-squares map of the command as logged is a smoothed, attenuated map of the one that acts), and the
    term refitted against that map finds part of its size and gains part of its effect. The one-step criterion
    that fitted the map chooses: each remaining candidate with internal states (a motor's lag, a dead time) at
    `THROUGH_SAMPLES` multiples of the sample interval, with the terms already selected, and the one whose
    one-step fit leaves the least residual, below the held map's, gets that map and starts at that coefficient;
    the others are tested against the held map. One per round, so that a candidate's held-out gain is never a
    refitted map's that another input's dynamics made (through the closed loop every motor's command follows the
    others'); and only where the one-step residual falls by more than chance (a likelihood-ratio test of the one
    coefficient at the diagnosis's level, Bonferroni over the candidates and coefficients tried). That test is also
    the candidate's place on the shortlist (`with_through_evidence`): the screening reads it against the held map.
    Under the bar, the best one-step fit is still the start of that candidate where the screening shortlisted it
    (`Through.evidence` false): refitted from the default start against the held map, which has taken up part of
    it, a lag stops where that map leaves it (the calibration battery's 80 ms lag of one motor, flown again: the
    one-step optimum at 80 ms under a ratio of 11.6 against 13.2, the refit from 20 ms at 24 ms, a 5 % gain and
    `none`, where the truth gains 62 %; from the one-step optimum 75 ms and 60 %).

    **Returns:** the `Through`, or `None` where no lag or delay fits the one-step residual better than the held map
    at all (and where the problem has no `nominal_through` or no candidate has input dynamics)."""
    dynamic = [k for k in remaining if input_dynamics(problem.candidates[k], problem.system)]
    if problem.nominal_through is None or not dynamic:
        return None
    n_nominal = len(problem.names)
    held = []
    for j, slot in enumerate(np.asarray(slots)):
        selected = problem.candidates[slot] if slot >= 0 else None
        if selected is not None and input_dynamics(selected, problem.system):
            held.append(_at(selected, problem.neutral[slot] + p[n_nominal + j]))
    _, held_loss, n_residuals = problem.nominal_through(tuple(held))
    best, each = None, {}
    for k in dynamic:
        for c in problem.neutral[k] + problem.dt * np.asarray(THROUGH_SAMPLES, float):
            values, loss, _ = problem.nominal_through((*held, _at(problem.candidates[k], c)))
            if best is None or loss < best[0]:
                best = (loss, k, c, values)
            if k not in each or loss < each[k][0]:
                each[k] = (loss, k, c, values)
    # The likelihood ratio of the one extra coefficient, Bonferroni over every candidate and coefficient tried:
    # the one-step residual is mostly measurement noise, and the least of many tries is below the held map's by
    # chance about as often as not.
    tries = len(dynamic) * len(THROUGH_SAMPLES)
    bar = NormalDist().inv_cdf(1.0 - problem.selection.alpha / tries / 2.0) ** 2  # chi-square, 1 degree of freedom
    if best is None:
        return None
    ratio = float(n_residuals * np.log(held_loss / best[0]))
    if not ratio > 0:
        return None

    def start_of(found):
        _, k, c, values = found
        start = np.asarray(p, float).copy()
        start[:n_nominal], start[-1] = values, c - problem.neutral[k]
        return start

    k = best[1]
    # A look-alike on the same inputs (the motors' shared lag beside their shared dead time) takes the map refitted
    # through itself: the held map has taken up part of it as much as of the chosen one, and from the default
    # start against that map the refit walks out of its physical range (a 40 ms lag of every motor: to -25 ms,
    # where the dead time it looks like gained 39 %).
    alikes = {
        j: start_of(each[j])
        for j in problem.look_alikes(k)
        if j in each and set(problem.candidates[j].inputs) == set(problem.candidates[k].inputs)
    }
    return Through(k, start_of(best), ratio, float(bar), ratio > bar, alikes)


#: The lags and dead times [samples] at which the held one-step map is refitted through a candidate (`_through_inputs`).
THROUGH_SAMPLES = (1, 2, 3, 4, 6, 8, 12)


def _at(term, coefficient):
    return eqx.tree_at(lambda t: t.coefficient, term, jnp.asarray(coefficient, jnp.result_type(term.coefficient)))


def _fit_nominal(problem: Problem, batch: _Batch, say) -> tuple[AbstractSystem, Yardstick]:
    """Fit the nominal model (member 0 of the first batch) and choose the reference horizon from its training error."""
    model = problem.model_of(-np.ones(problem.selection.max_terms, int), batch.p[0]).system
    _note_moved(problem, batch.p[0])
    given = problem.horizon_settings
    horizon = reference_horizon(
        model,
        problem.train,
        problem.candidates_s,
        given.reference_s,
        given.fraction,
        problem.val_stride,
        problem.position_index,
        problem.dt,
    )
    horizons = problem.horizons
    if horizon.seconds not in horizons:
        horizons = np.sort(np.append(horizons, horizon.seconds))
    n_ref = int(np.round(horizon.seconds / problem.dt))
    cv_windows = make_windows(problem.train, n_ref, problem.val_stride) if problem.folds else None
    window_runs = problem.window_runs
    if cv_windows is not None:
        # Each fold is a run of the test (its windows centred on their own mean, and counted in the agreement).
        window_runs = np.concatenate([window_runs, len(problem.validation) + cv_fold_of(problem.folds, cv_windows)])
    yard = Yardstick(
        horizon=horizon,
        horizons=horizons,
        steps=np.maximum(np.round(horizons / problem.dt).astype(int), 1),
        n_ref=n_ref,
        overlap=max(1, int(np.ceil(n_ref / problem.val_stride))),
        ref_index=int(np.flatnonzero(np.isclose(horizons, horizon.seconds))[0]),
        cv_windows=cv_windows,
        window_runs=window_runs,
        n_val=len(problem.window_runs),
    )
    return model, yard


# A size parameter (an inertia, a mass, a gravity term) off by more than this factor says the model
# describes another machine: a hidden effect biases an estimate by percent, another machine differs by
# an order of magnitude. Used for the refit here and for the CLI's check of its default model.
OTHER_MACHINE_FACTOR = 2.0


def _note_moved(problem: Problem, p) -> None:
    """Say so when the refit moved a size parameter (`size_parameter_names`) by more than
    `OTHER_MACHINE_FACTOR`: the nominal model describes another machine (`DoublePendulum()`'s Drake defaults on a
    much lighter rig), and a refit from so far need not reach this one (it can stop at several times
    the rig's inertia) and the findings then correct the wrong machine."""
    system, names = problem.system, problem.names
    size = set(size_parameter_names(system))
    given = np.asarray(host_nominal_values(system, names), float)
    refit = np.asarray(problem.family.refit)  # read on the host: indexing the array compiles a comparison
    moved = []
    for i, n in enumerate(names):
        if n in size and refit[i] > 0 and given[i] > 0:
            ratio = float(p[i]) / given[i]
            if not 1 / OTHER_MACHINE_FACTOR <= ratio <= OTHER_MACHINE_FACTOR:
                moved.append(f"{n} from {given[i]:.4g} to {float(p[i]):.4g}")
    if moved:
        problem.notes.append(
            "The refit moved "
            + ", ".join(moved)
            + f" (more than a factor {OTHER_MACHINE_FACTOR:g}): the nominal model "
            "describes another machine, and a refit from that far may stop short of this one, leaving the findings "
            "to correct the wrong model. Start from a nominal model of this machine (e.g. `identify(...).system` "
            "with its friction set to zero; `dynax diagnose` without --nominal does this)."
        )


def _show_what_is_wrong(problem: Problem, model, batch: _Batch, yard: Yardstick, say) -> Nominal:
    """Show what is wrong: the nominal model's held-out simulation error and the structure left in its residuals."""
    rmse = rmse_curve(batch.errors[0], yard.steps, problem.position_index)
    say(
        f"reference horizon {yard.horizon.seconds:g} s ({yard.horizon.rule}); nominal model: held-out position RMSE "
        f"{rmse[yard.ref_index]:.4g} there; probing its one-step residuals for structure ..."
    )
    structure = structure_test(model, problem.train, problem.validation)
    return Nominal(
        model=model,
        errors=batch.errors[0],
        rmse=rmse,
        structure=structure,
        cost=float(batch.cost[0]),
        cv_errors=batch.cv_errors[0],
    )


def _select(problem: Problem, yard: Yardstick, current: Current, results, scores, round_, say) -> dict | None:
    """Select: the admissible candidate with the largest held-out gain, as a finding; `None` if none passed."""
    admissible = [k for k in results if results[k]["significant"]]
    if not admissible:
        say(f"round {round_ + 1}: no candidate improves the held-out simulation significantly")
        return None
    best = choose(problem, results, admissible)
    r, term, system = results[best], problem.candidates[best], problem.system
    passed = max(admissible, key=lambda k: results[k]["gain_held_out"])
    if best != passed:
        problem.notes.append(
            f"{term.label(system)} is named for its look-alike {problem.candidates[passed].label(system)}, which "
            f"passed the test (p = {results[passed]['p']:.2g}): the two describe one effect, and "
            f"{term.label(system)} predicts the held-out runs better ({r['gain_held_out']:.0%} against "
            f"{results[passed]['gain_held_out']:.0%}; its own p = {r['p']:.2g})."
        )
    ref = yard.ref_index
    gain = float(1 - r["rmse"][ref] / current.rmse[ref]) if np.isfinite(current.rmse[ref]) else 1.0
    alternatives = look_alike_tests(problem, yard, best, results, scores)
    equivalent = [problem.candidates[k].label(system) for k in problem.equivalents.get(best, [])]
    # A structural equivalent is never told apart, whatever the paired test of two fits of one model says.
    confidence = "high" if all(a["told_apart"] for a in alternatives) else "low"
    if equivalent:
        refit = (
            f"with a refit of the nominal parameters ({', '.join(problem.refit_names)})"
            if problem.refit_names
            else "as the model is written"
        )
        gains = all(problem.candidates[k].cause == "input_gain" for k in [best, *problem.equivalents[best]])
        problem.notes.append(
            f"{term.label(system)} and {', '.join(equivalent)} are one model {refit}: any change of one is a change "
            "of the other, so no data can tell them apart"
            + (
                " (every torque-side parameter and the gains scaled by one factor leave the motion unchanged: the "
                "data determine only the ratio of the gains)"
                if gains
                else ""
            )
            + f". {term.label(system)} is named because it came first; its finding lists the other as a look-alike "
            "it cannot be told apart from."
        )
    coefficient = problem.neutral[best] + r["delta"]
    say(
        f"round {round_ + 1}: found {term.label(system)}, {term.parameter_name(system)} = {coefficient:.4g} "
        f"(held-out gain {gain:.0%} in position RMSE at {yard.horizon.seconds:g} s, {r['gain_held_out']:.0%} in the "
        f"tested window error over every state, p = {r['p']:.2g}, helps on {r['runs_helped']}/{r['n_runs']} held-out "
        f"runs; told apart from look-alikes: {confidence})"
    )
    return {
        "index": best,
        "cause": term.cause,
        "where": term.where(system),
        "coefficient": float(coefficient),
        "std_error": float(r["std"]),
        "gain": gain,
        "parameter": term.parameter_name(system),
        "p_value": r["p"],
        "look_alikes": alternatives,
        "confidence": confidence,
        "runs_helped": f"{r['runs_helped']}/{r['n_runs']}",
        # closed testing: the look-alike whose test established the effect, where it is not the one named
        **(
            {
                "named_for": {
                    "cause": problem.candidates[passed].cause,
                    "where": problem.candidates[passed].where(system),
                    "p_value": results[passed]["p"],
                }
            }
            if best != passed
            else {}
        ),
    }


def _accept(problem: Problem, current: Current, finding: dict, results, batch: _Batch, scores, say) -> Current:
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
    return Current(
        slots=slots,
        p=p,
        std=std,
        score=scores[r["i"]],
        errors=batch.errors[r["i"]],
        rmse=r["rmse"],
        structure=structure,
        cv_errors=batch.cv_errors[r["i"]],
        selected=selected,
        findings=current.findings + [finding],
    )


def _complete_look_alikes(problem: Problem, yard: Yardstick, round_: Round, fits: Refitted, batch: _Batch, judge, say):
    """Refit the look-alikes of the round's best admissible candidate that screening left off the shortlist.

    A finding's confidence rests on beating its look-alikes (same place, same group of causes) in the
    held-out test; one that was never refitted cannot have been beaten. So its missing look-alikes get
    one more batch of fits (the same compiled batch), the round is judged again over both batches
    (Benjamini-Hochberg over the same remaining candidates: an untested one counted as p = 1 before),
    and if the best changes, its own missing look-alikes are added once more.

    **Returns:** `(fits, batch, results)`: the round's refitted configurations, their batch, and `judge(fits)`.
    """
    system, candidates = problem.system, problem.candidates
    results = judge(fits)
    for _ in range(2):
        admissible = [k for k in results if results[k]["significant"]]
        if not admissible:
            break
        best = choose(problem, results, admissible)
        missing = [k for k in problem.look_alikes(best) if k in round_.remaining and k not in results]
        missing = missing[: problem.selection.shortlist]
        if not missing:
            break
        say(
            f"round {round_.index + 1}: {candidates[best].label(system)} leads; refitting its look-alike(s) "
            f"{', '.join(candidates[k].label(system) for k in missing)}, which screening left out ..."
        )
        new, more = _refit(problem, round_, missing, say)
        more = _cross_fit(problem, yard, round_.slots, new, more, say)
        n = 1 + len(fits.short)
        batch = _Batch(
            *(
                np.concatenate([getattr(batch, f.name)[:n], getattr(more, f.name)[1 : 1 + len(missing)]])
                for f in dataclasses.fields(_Batch)
            )
        )
        fits = _refitted(problem, yard, fits.short + missing, batch)
        results = judge(fits)
    return fits, batch, results


def _refitted(problem: Problem, yard: Yardstick, short, batch: _Batch) -> Refitted:
    """The `Refitted` configurations of a batch, scored on the held-out (and cross-fitted) windows."""
    return Refitted(short, batch.p, batch.std, batch.errors, _scores(problem, yard, batch.errors, batch.cv_errors))


@dataclasses.dataclass(frozen=True)
class Forward:
    """What forward selection leaves: the fitted `nominal` model, the `yard`stick, the `current` model reached, the
    first round's candidate `table`, the `last` round's results (`judge_round`), and one `round_summary` per round."""

    nominal: Nominal
    yard: Yardstick
    current: Current
    table: list
    last: dict
    rounds: list


def forward_selection(problem: Problem, say) -> Forward:
    """Fit the nominal model, show what is wrong, then per round screen, refit and select."""
    o = problem.selection
    slots, p0 = _starting_point(problem)
    nominal = yard = current = None
    table, last, rounds = [], {}, []
    for index in range(o.max_terms):
        remaining = [k for k in problem.searchable if current is None or k not in current.selected]
        if not remaining and index > 0:
            break
        cur_slots, cur_p = (slots, p0) if current is None else (current.slots, current.p)
        through = _through_inputs(problem, cur_slots, cur_p, remaining)
        gains, deltas, short = (
            _screen(problem, cur_slots, cur_p, remaining, index, through, say) if remaining else ([], [], [])
        )
        round_ = Round(index, cur_slots, cur_p, remaining, deltas, through)
        new, batch = _refit(problem, round_, short, say)
        if index == 0:
            model, yard = _fit_nominal(problem, batch, say)
            batch = _cross_fit(problem, yard, cur_slots, new, batch, say)
            nominal = _show_what_is_wrong(problem, model, batch, yard, say)
            fits = _refitted(problem, yard, short, batch)
            current = Current(
                slots=slots,
                p=batch.p[0].copy(),
                std=batch.std[0].copy(),
                score=fits.scores[0],
                errors=batch.errors[0],
                rmse=nominal.rmse,
                structure=nominal.structure,
                cv_errors=batch.cv_errors[0],
            )
        else:
            batch = _cross_fit(problem, yard, cur_slots, new, batch, say)
            fits = _refitted(problem, yard, short, batch)
        if not short:
            break
        assert yard is not None and current is not None  # the first round sets them
        judge = functools.partial(judge_round, problem, yard, current, remaining)
        fits, batch, results = _complete_look_alikes(problem, yard, round_, fits, batch, judge, say)
        last = results
        if index == 0:
            table = candidate_table(
                problem.system, problem.candidates, remaining, gains, results, problem.neutral, batch.cost
            )
        finding = _select(problem, yard, current, results, fits.scores, index, say)
        rounds.append(round_summary(problem, yard, index, current, remaining, results, finding))
        if finding is None:
            break
        current = _accept(problem, current, finding, results, batch, fits.scores, say)
    else:
        if rounds:
            rounds[-1]["outcome"] += f"; max_terms = {o.max_terms} reached"
    assert nominal is not None and yard is not None and current is not None  # the first round always runs
    return Forward(nominal, yard, current, table, last, rounds)


def _start_value(problem: Problem, k: int, delta_screened, start):
    """A candidate's starting coefficient: the screening's step if physical and moderate, else the default start."""
    term, scale = problem.candidates[k], problem.scales[k]
    ok = np.isfinite(delta_screened) and problem.physical(k, delta_screened) and abs(delta_screened) < 20 * scale
    lagging = input_dynamics(term, problem.system) and delta_screened < start
    return delta_screened if ok and not lagging else start
