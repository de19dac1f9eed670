r"""`discover`: search for the term the cause vocabulary lacks, refit it through simulation, keep it only if it pays.

Called by `diagnose` where its verdict would be `unexplained` (structure is left that no named
cause explains). For each coordinate of a manipulator:

1. **Residual.** The one-step acceleration residual of the current model (nominal plus the named
   causes found), turned into a generalised-force residual $M(q)\,r$ (a missing force at one
   joint is then seen at that joint only, however the mass matrix couples the accelerations).
2. **Search.** A sparse model of it over the typed library (`_library.py`), the period of a
   position-periodic pair chosen by a periodogram, with sequentially thresholded least squares,
   the threshold chosen by cross-validation over runs (or contiguous pieces of a single run) and
   stability selection over half-subsamples (`_sparse.py`), at most `max_terms` features.
3. **Named causes first.** Features a named cause of the vocabulary represents exactly (sign of
   the velocity: Coulomb friction, ...) are removed from the proposal: the named cause wins, and a
   proposal that is nothing but named causes is no discovery.
4. **A term like any other.** The proposal becomes a `Discovered` term, refitted through
   simulation (`fit_simulation_error`, Levenberg-Marquardt in optimistix) jointly with the refitted
   nominal parameters and the named causes' coefficients, on the training windows.
5. **Held-out test.** It is kept only if it passes the same test as a named cause: a significant
   improvement of the held-out simulation error (the caller's `significance`, level `alpha`) whose
   typical window gains at least `min_gain` in RMS (`typical_gain`: the geometric mean of the windows'
   error ratios, the test's own measure, not the pooled error, which one run of large error carries),
   and no larger pooled error at the reference horizon. With several coordinates, each term must also
   carry its weight (dropping it must cost the typical window at least `min_gain`).

??? cite

    S. L. Brunton, J. L. Proctor and J. N. Kutz, "Discovering governing equations from data by
    sparse identification of nonlinear dynamical systems", PNAS 113(15), 2016.
    N. Meinshausen and P. Buehlmann, "Stability selection", J. Royal Statistical Society B 72(4), 2010.
    L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, ch. 16 (validation on
    fresh data).
"""

from collections.abc import Callable, Sequence
from typing import cast

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from .._identify._simulation_fit import fit_simulation_error, SimulationFit
from .._model._extensions import Discovered, Extended
from ._fit import nominal_parameter_names
from ._library import evaluate_features, feature_library, is_angle, named_equivalent, physical_readings, search_period
from ._residuals import (
    acceleration_residuals,
    as_measured,
    predicted_accelerations,
    sg_window,
    smoothed_states,
    velocity_indices,
)
from ._sparse import group_cv_r2, SparseSearch, SparseStatistics, Stability
from ._statistics import typical_gain


class Proposal(eqx.Module):
    """The search's answer at one coordinate: the features kept, their one-step coefficients, and why.

    **Fields:** `channel` (0-based coordinate), `features`, `coefficients` (least squares on the
    one-step force residual), `frequency` (stability-selection frequency of each kept feature),
    `cv_r2` (cross-validated share of the force residual they explain), `deferred` (labels of the
    named causes whose features the search selected and gave back), `period` (of the periodic
    pair searched, or `None`).
    """

    channel: int
    features: tuple
    coefficients: np.ndarray
    frequency: tuple
    cv_r2: float
    deferred: tuple
    period: float | None


def _mass_matrices(model, qs):
    system = model.system if isinstance(model, Extended) else model
    terms = model.joint_terms if isinstance(model, Extended) else ()

    def one(q):
        m = system.mass_matrix(q)
        for term in terms:
            m = m.at[term.joint, term.joint].add(term.inertia())
        return m

    return np.asarray(jax.jit(jax.vmap(one))(jnp.asarray(qs)))


def refit_spec(model: Extended, refit: Sequence[str]):
    """The leaves refitted with a discovered term: the nominal parameters `refit` and every term's coefficient(s)."""
    spec = jax.tree.map(lambda _: False, model)
    names = [n for n in nominal_parameter_names(model.system) if n in refit]
    if names:
        spec = eqx.tree_at(lambda m: [getattr(m.system, n) for n in names], spec, [True] * len(names))
    for k, term in enumerate(model.terms):
        leaf = "coefficients" if isinstance(term, Discovered) else "coefficient"
        spec = eqx.tree_at(lambda m: getattr(m.terms[k], leaf), spec, True)
    return spec


@eqx.filter_jit
def _acceleration_sensitivities(fitted, fixed, ts, xs_smooth, us, idx, us_before):
    p0, unravel = jax.flatten_util.ravel_pytree(fitted)
    return jax.jacfwd(
        lambda p: predicted_accelerations(eqx.combine(unravel(p), fixed), ts, xs_smooth, us, idx, us_before)
    )(p0)


def force_residuals(model, records, refit: Sequence[str] = ()) -> tuple[np.ndarray, ...]:
    r"""Generalised-force residuals $M(q)\,(\ddot q_{meas} - \ddot q_{model})$ of `model` on `records`, and their
    nuisance directions.

    The nuisance directions are $-M(q)\,\partial \ddot q_{model} / \partial p$ for the refitted
    parameters $p$ (the nominal parameters `refit` and the named terms' coefficients): what a
    change of the parameters refitted with a discovered term would explain. The search projects
    them out first, so that a nominal fit that has partly absorbed the missing effect does not
    hide it or disguise it.

    **Returns:** `(residuals (time, n_joints), nuisance (time, n_joints, n_refit), smoothed states,
    recorded inputs, record index)`, the records concatenated (the filter's start-up and run-out
    samples dropped).
    """
    model = model if isinstance(model, Extended) else Extended(model, ())
    n = model.system.n_joints
    fitted, fixed = eqx.partition(model, refit_spec(model, refit))
    idx = jnp.asarray(velocity_indices(model.system))
    out, nuisance, xs_all, us_all, runs = [], [], [], [], []
    for r, traj in enumerate(records):
        resid, xs, _, keep = acceleration_residuals(model, traj)
        m = _mass_matrices(model, xs[:, :n])
        out.append(np.einsum("tij,tj->ti", m, resid))
        ts = traj.ts
        smooth = smoothed_states(traj)
        us_before = jnp.concatenate([traj.us[:1], traj.us[:-1]])  # the held input's left limit, as the residuals use
        sens = np.asarray(_acceleration_sensitivities(fitted, fixed, ts, smooth, traj.us, idx, us_before))
        if sens.shape[-1]:  # the residuals filter the prediction (`as_measured`); its sensitivities alike
            flat = sens.reshape(len(ts), -1)
            sens = as_measured(ts, flat, sg_window(traj.dt)).reshape(sens.shape)
        nuisance.append(-np.einsum("tij,tjp->tip", m, sens[keep]))
        xs_all.append(xs)
        us_all.append(np.asarray(traj.us)[keep])
        runs.append(np.full(len(xs), r))
    return (
        np.concatenate(out),
        np.concatenate(nuisance),
        np.concatenate(xs_all),
        np.concatenate(us_all),
        np.concatenate(runs),
    )


def _project_out(nuisance, *arrays):
    """Remove from each array (columns) its least-squares fit on the nuisance columns (Frisch-Waugh-Lovell)."""
    if nuisance.shape[1] == 0:
        return arrays
    scale = np.sqrt(np.mean(nuisance**2, axis=0))
    Q, s, _ = np.linalg.svd(nuisance / np.where(scale > 0, scale, 1.0), full_matrices=False)
    Q = Q[:, s > 1e-8 * s.max()]
    return tuple(a - Q @ (Q.T @ a) for a in arrays)


class DiscoverySearch(eqx.Module):
    """What the discovery search knows of the diagnosis, and how it searches (steps 1-3 of the module docs).

    **Fields:** `refit` (nominal parameters refitted with a discovered term: their directions are projected
    out); `vocabulary` (labels `cause@where` of the named causes that were tested: their features are given
    back, the named cause wins); `absorbed` (labels of named causes a refit reproduces exactly: their features
    are left out of the library); `max_terms` (features per coordinate); `min_cv_r2` (the smallest
    cross-validated share of the force residual a proposal must explain); `n_pieces` (a single run is cut into
    this many contiguous pieces for cross-validation); `seed`.
    """

    refit: tuple[str, ...] = eqx.field(default=(), converter=tuple, static=True)
    vocabulary: tuple[str, ...] = eqx.field(default=(), converter=tuple, static=True)
    absorbed: tuple[str, ...] = eqx.field(default=(), converter=tuple, static=True)
    max_terms: int = eqx.field(default=3, static=True)
    min_cv_r2: float = eqx.field(default=0.01, static=True)
    n_pieces: int = eqx.field(default=5, static=True)
    seed: int = eqx.field(default=0, static=True)


class HeldOutTest(eqx.Module):
    """The held-out test a discovered term must pass: the caller's, the one its named causes passed.

    **Fields:** `held_out` (`held_out(model) -> (window_scores, rmse_curve, rmse_at_reference)`, the caller's
    held-out simulation error); `significance` (`significance(scores_reference, scores_new) -> p_value`,
    one-sided); `alpha` and `min_gain` (the level and the smallest typical gain of a window's RMS error).
    """

    held_out: Callable = eqx.field(static=True)
    significance: Callable = eqx.field(static=True)
    alpha: float = eqx.field(default=0.01, static=True)
    min_gain: float = eqx.field(default=0.05, static=True)


def propose(model, records, search: DiscoverySearch = DiscoverySearch()) -> list[Proposal]:
    """The discovery search on the training `records` (steps 1-3 of the module docs), one `Proposal` per coordinate that
    has one.

    **Arguments:** `model` (the current model: nominal, or `Extended` with named causes); `records` (training
    trajectories); `search` (a `DiscoverySearch`: what the diagnosis refits, named and set aside, and the
    search's bounds).

    **Returns:** proposals, the best explained coordinate first.
    """
    refit, vocabulary, absorbed = search.refit, search.vocabulary, search.absorbed
    max_terms, min_cv_r2, n_pieces, seed = search.max_terms, search.min_cv_r2, search.n_pieces, search.seed
    system = model.system if isinstance(model, Extended) else model
    if not system.joints:  # forces at joints: only a manipulator has them
        return []
    n = system.n_joints
    tau, nuisance, xs, us, runs = force_residuals(model, list(records), refit)
    if len(np.unique(runs)) >= 2:
        groups = runs
    else:
        groups = np.minimum(np.arange(len(tau)) * n_pieces // len(tau), n_pieces - 1)
    dt = float(np.median(np.diff(np.asarray(records[0].ts))))
    block = max(1, int(round(0.5 / dt)))
    proposals = []
    for j in range(n):
        (y,) = _project_out(nuisance[:, j], tau[:, j])
        period = None if is_angle(system, j) else _position_period(system, j, nuisance[:, j], xs, us, y, dt)
        library = feature_library(system, j, xs, period=period)
        raw = evaluate_features(library, n, xs, us)
        phi = np.array(_project_out(nuisance[:, j], raw)[0])  # a writable copy: with nothing refitted it is `raw`
        # A feature the refitted parameters reproduce (sin q1 at the shoulder: gravity) is not a discovery.
        inert = np.sqrt(np.mean(phi**2, axis=0)) < 1e-6 * np.maximum(np.sqrt(np.mean(raw**2, axis=0)), 1e-300)
        # So is a feature equivalent to a named cause that the refit reproduces exactly (an input gain
        # when the mass is refitted): in simulation it is not identifiable either.
        inert |= np.asarray([named_equivalent(system, f, j) in absorbed for f in library])
        phi[:, inert] = 0.0
        fit = SparseSearch(max_terms=max_terms, stability=Stability(block=block, seed=seed + j)).search(phi, y, groups)
        stats = cast(SparseStatistics, fit.statistics)
        chosen = list(stats.selected)
        deferred = []
        for k in list(chosen):
            label = named_equivalent(system, library[k], j)
            if label is not None and label in vocabulary:
                deferred.append(label)
                chosen.remove(k)
        periodic = [k for k, f in enumerate(library) if f.kind.startswith("periodic")]
        allowed = [
            k
            for k, f in enumerate(library)
            if not inert[k] and k not in periodic and named_equivalent(system, f, j) not in vocabulary
        ]
        chosen = _look_alike_by_cross_validation(chosen, allowed, phi, y, groups)
        if any(k in chosen for k in periodic):  # a phase needs both halves of the pair
            chosen = sorted(set(chosen) | set(periodic))
        if not chosen:
            if deferred and stats.cv_r2 >= min_cv_r2:  # the search points at a named cause: say so, propose nothing
                proposals.append(Proposal(j, (), np.zeros(0), (), float(stats.cv_r2), tuple(deferred), None))
            continue
        cols = phi[:, chosen]
        coef = np.linalg.lstsq(cols, y, rcond=None)[0]

        cv_r2, per_group = group_cv_r2(cols, y, groups, lambda Z, t: np.linalg.lstsq(Z, t, rcond=None)[0])
        # It must predict left-out runs: overall, and in most of them (a law, not one run's accident).
        if cv_r2 < min_cv_r2 or np.mean(per_group > 0) < 0.8:
            if deferred and stats.cv_r2 >= min_cv_r2:
                proposals.append(Proposal(j, (), np.zeros(0), (), float(stats.cv_r2), tuple(deferred), None))
            continue
        proposals.append(
            Proposal(
                channel=j,
                features=tuple(library[k] for k in chosen),
                coefficients=coef,
                frequency=tuple(float(stats.frequency[k]) for k in chosen),
                cv_r2=float(cv_r2),
                deferred=tuple(deferred),
                period=period if any(library[k].kind.startswith("periodic") for k in chosen) else None,
            )
        )
    proposals.sort(key=lambda p: (not p.features, -p.cv_r2))
    return proposals


def _position_period(system, j, nuisance, xs, us, y, dt) -> float | None:
    """The period of a force periodic in a prismatic coordinate `j` (a lead screw's ripple), by periodogram of the
    residual left after the non-periodic library; `None` where the travel is too short to resolve one."""
    n = system.n_joints
    base = feature_library(system, j, xs)
    phi, y0 = _project_out(nuisance, evaluate_features(base, n, xs, us), y)
    y0 = y0 - phi @ np.linalg.lstsq(phi, y0, rcond=None)[0]
    q = xs[:, j]
    span = float(np.ptp(q))
    v_rms = float(np.sqrt(np.mean(xs[:, n + j] ** 2)))
    p_min = max(span / 200, 20 * dt * v_rms)  # resolved in time: at most 1/20 of the sampling rate
    if span / 2 <= 1.5 * p_min:
        return None
    period, _ = search_period(q, y0, p_min=p_min, p_max=span / 2)
    return period


def _look_alike_by_cross_validation(chosen, allowed, phi, y, groups, *, min_correlation: float = 0.9):
    r"""Swap a selected feature for a near-equivalent one ($q_2$ for $\sin q_2$ on a wide swing) where
    that predicts the left-out runs better; the thresholding alone picks between them by chance."""
    fit = lambda Z, t: np.linalg.lstsq(Z, t, rcond=None)[0]  # noqa: E731
    score = lambda cols: group_cv_r2(phi[:, cols], y, groups, fit)[0] if cols else -np.inf  # noqa: E731
    chosen = list(chosen)
    best = score(chosen)
    norms = np.sqrt(np.sum(phi**2, axis=0)) + 1e-300
    for pos in range(len(chosen)):
        k = chosen[pos]
        if k not in allowed:
            continue
        for alt in allowed:
            if alt in chosen or abs(phi[:, k] @ phi[:, alt]) / (norms[k] * norms[alt]) < min_correlation:
                continue
            trial = chosen[:pos] + [alt] + chosen[pos + 1 :]
            value = score(trial)
            if value > best:
                best, chosen = value, trial
    return sorted(chosen)


class Discovery(eqx.Module):
    """The answer of `discover`.

    **Fields:** `kept` (whether a discovered term passed the held-out test); `model` (the current
    model extended with the kept discovered terms, refitted; the input model if none was kept);
    `findings` (report findings with cause `discovered`, most important first); `proposals` (what
    the search proposed, kept or not); `gain` and `p_value` of the discovered terms together
    against the current model on held-out data; `held_out` (the caller's `held_out` of `model`);
    `notes`.
    """

    kept: bool
    model: eqx.Module
    findings: list
    proposals: list
    gain: float
    p_value: float
    held_out: tuple | None
    notes: list

    def summary(self, system) -> dict:
        """The search in `report.json`'s `discovery` entry: kept or not, the held-out test, and every proposal."""
        return {
            "kept": self.kept,
            "tested": any(p.features for p in self.proposals),
            "gain": self.gain,
            "p_value": self.p_value,
            "proposals": [
                {
                    "where": system.state_names[p.channel],
                    "features": [f.name(system) for f in p.features],
                    "one_step_coefficients": [float(c) for c in p.coefficients],
                    "selection_frequency": list(p.frequency),
                    "cv_r2_one_step": p.cv_r2,
                    "period": p.period,
                    "deferred_to_named_causes": list(p.deferred),
                }
                for p in self.proposals
            ],
        }


class _SimulationRefit(eqx.Module):
    """The simulation refit of a model with discovered terms: on the training `records`, the nominal parameters
    `refit`, windows `fit_window_s` long, states weighted by `state_scale`."""

    records: list
    refit: tuple
    fit_window_s: float
    state_scale: np.ndarray

    def __call__(self, model, terms):
        return _fit_with(model, terms, self.records, self.refit, self.fit_window_s, self.state_scale)


def _fit_with(model, terms, records, refit, fit_window_s, state_scale):
    """Refit `model` + `terms` through simulation: refitted nominal parameters, named and discovered coefficients."""
    system = model.system if isinstance(model, Extended) else model
    named = model.terms if isinstance(model, Extended) else ()
    extended = Extended(system, tuple(named) + tuple(terms))
    spec = refit_spec(extended, refit)
    result = fit_simulation_error(
        extended,
        records,
        SimulationFit(segment_s=fit_window_s, fit_initial_states=False, max_steps=60),
        filter_spec=spec,
        state_scale=state_scale,
    )
    fitted, _ = eqx.partition(extended, spec)
    _, unravel = jax.flatten_util.ravel_pytree(fitted)
    std_tree = unravel(result.std_errors)
    stds = [np.asarray(t.coefficients) for t in std_tree.terms[len(named) :]]
    return result.model, stds


def discover(
    model,
    train,
    validation,
    *,
    test: HeldOutTest,
    search: DiscoverySearch = DiscoverySearch(),
    fit_window_s: float = 1.0,
    current: tuple | None = None,
    progress: Callable[[str], None] | None = None,
) -> Discovery:
    r"""Search for the missing term, refit it through simulation with the model, keep it only if it pays on held-out
    data.

    See the module docs for the steps and their guards.

    **Arguments:**

    - `model`: the current model (a nominal manipulator, or `Extended` with the named causes found).
    - `train`, `validation`: lists of `Trajectory` (training: search and refit; validation: the test).
    - `test`: the `HeldOutTest` (the caller's held-out simulation error and significance, its level and
      smallest gain).
    - `search`: the `DiscoverySearch` (the nominal parameters refitted with the new term, as in the diagnosis
      mode; the named causes tested, which win over equivalent features, and those the refit reproduces
      exactly; the bound on the features of each discovered term).
    - `fit_window_s`: segment length of the simulation refit [s].
    - `current`: `test.held_out(model)` if the caller has it already.
    - `progress`: called with a line of text at each stage.

    **Returns:** a `Discovery`.
    """
    say = progress or (lambda _: None)
    system = model.system if isinstance(model, Extended) else model
    notes: list[str] = []
    empty = lambda why, proposals=(): Discovery(False, model, [], list(proposals), 0.0, 1.0, None, notes + [why])  # noqa: E731
    if not system.joints:
        return empty(f"Discovery searches forces at the joints of a manipulator; {type(system).__name__} is not one.")
    say("discovery: sparse search of the one-step force residuals over the feature library ...")
    searched = propose(model, train, search)
    for p in searched:
        if p.deferred:
            notes.append(
                f"The discovery search at {system.state_names[p.channel]} selected features of "
                f"{', '.join(p.deferred)}, which the vocabulary names and tested; the named cause wins "
                "over the equivalent discovered formula."
            )
    proposals = [p for p in searched if p.features]
    if not proposals:
        return empty(
            "The discovery search found no stable sparse formula beyond the vocabulary for the structure left "
            "(no feature set selected in most subsamples and explaining a cross-validated share of the residual).",
            searched,
        )
    terms = [Discovered(p.channel, p.features, p.coefficients) for p in proposals]
    say("discovery: proposed " + "; ".join(t.formula(system) for t in terms) + "; refitting through simulation ...")
    xs_train = np.concatenate([np.asarray(r.xs) for r in train])
    state_scale = np.maximum(xs_train.std(axis=0), 1e-9)
    current = current if current is not None else test.held_out(model)
    refit = _SimulationRefit(train, search.refit, fit_window_s, state_scale)
    outcome = _refit_and_test(model, terms, proposals, refit, test, current, say)
    if not outcome.passed:
        notes.append(
            "The discovery search proposed "
            + "; ".join(t.formula(system) for t in outcome.terms)
            + f", but refitted through simulation it did not pass the held-out test (gain {outcome.gain:.0%}, "
            f"p = {outcome.p_value:.2g}); no discovered term is kept."
        )
        return Discovery(False, model, [], outcome.proposals, outcome.gain, outcome.p_value, None, notes)
    n_named = len(model.terms) if isinstance(model, Extended) else 0
    findings = _findings(system, outcome, n_named, test.held_out)
    return Discovery(
        True,
        outcome.fitted,
        findings,
        outcome.proposals,
        outcome.gain,
        outcome.p_value,
        (outcome.scores, outcome.curve, outcome.rmse),
        notes,
    )


class _Test(eqx.Module):
    """The outcome of refitting the proposed terms and testing them on held-out data."""

    passed: bool
    terms: list
    proposals: list
    fitted: eqx.Module
    stds: list
    gain: float
    p_value: float
    scores: object
    curve: object
    rmse: float


def _weak_terms(held_out, fitted, n_terms: int, n_named: int, scores_new, min_gain: float) -> list[int]:
    """The discovered terms that do not carry their weight: dropped one at a time (no refit), the typical window's
    RMS error grows by less than `min_gain`."""
    weak = []
    for k in range(n_terms):
        others = tuple(t for i, t in enumerate(fitted.terms) if i != n_named + k)
        scores_without, _, _ = held_out(type(fitted)(fitted.system, others))
        if typical_gain(scores_without, scores_new, rms=True) < min_gain:
            weak.append(k)
    return weak


def _refit_and_test(model, terms, proposals, refit: _SimulationRefit, test: HeldOutTest, current, say) -> _Test:
    """Refit the proposed terms through simulation and test them on held-out data against `current` (the current
    model's `test.held_out`); where several pass together, drop each that does not carry its weight (dropping it
    costs the typical window less than `test.min_gain`) and refit once more."""
    held_out, significance, alpha, min_gain = test.held_out, test.significance, test.alpha, test.min_gain
    scores_cur, _, rmse_cur = current
    n_named = len(model.terms) if isinstance(model, Extended) else 0
    for _ in range(2):
        fitted, stds = refit(model, terms)
        scores_new, curve_new, rmse_new = held_out(fitted)
        gain = float(1 - rmse_new / rmse_cur) if np.isfinite(rmse_cur) and rmse_cur > 0 else 0.0
        p_value = float(significance(scores_cur, scores_new))
        passed = p_value < alpha and typical_gain(scores_cur, scores_new, rms=True) >= min_gain and gain > 0
        say(f"discovery: held-out gain {gain:.0%}, p = {p_value:.2g}" + ("" if passed else " (not kept)"))
        if not passed or len(terms) == 1:
            break
        weak = _weak_terms(held_out, fitted, len(terms), n_named, scores_new, min_gain)
        if not weak:
            break
        terms = [t for k, t in enumerate(terms) if k not in weak]
        proposals = [p for k, p in enumerate(proposals) if k not in weak]
        if not terms:
            passed = False
            break
    return _Test(passed, terms, proposals, fitted, stds, gain, p_value, scores_new, curve_new, rmse_new)


def _findings(system, test: _Test, n_named: int, held_out) -> list[dict]:
    """One finding (cause `discovered`) per kept term, with its own held-out gain, most important first."""
    findings = []
    fitted = test.fitted
    discovered = fitted.terms[n_named:]
    for k, (term, std, proposal) in enumerate(zip(discovered, test.stds, test.proposals)):
        if len(discovered) > 1:
            others = tuple(t for i, t in enumerate(fitted.terms) if i != n_named + k)
            _, _, rmse_without = held_out(Extended(fitted.system, others))
            term_gain = float(1 - test.rmse / rmse_without)
        else:
            term_gain = test.gain
        coefficients = np.asarray(term.coefficients, float)
        single = len(coefficients) == 1
        names = term.feature_names(system)
        findings.append(
            {
                "cause": "discovered",
                "where": term.where(system),
                "coefficient": float(coefficients[0]) if single else float(np.linalg.norm(coefficients)),
                "std_error": float(std[0]) if single else float(np.linalg.norm(std)),
                "gain": term_gain,
                "parameter": term.parameter_names(system)[0] if single else f"|c_{term.where(system)}|",
                "formula": term.formula(system),
                "acceleration_formula": term.acceleration_formula(system),
                "features": list(names),
                "coefficients": dict(zip(names, map(float, coefficients))),
                "std_errors": dict(zip(names, map(float, std))),
                "readings": physical_readings(system, term),
                "period": proposal.period,
                "selection_frequency": dict(zip(names, proposal.frequency)),
                "cv_r2_one_step": proposal.cv_r2,
                "p_value": test.p_value,
                "look_alikes": [],
                "confidence": "high" if min(proposal.frequency) >= 0.9 else "low",
            }
        )
    findings.sort(key=lambda f: -f["gain"])
    return findings


def discovery_markdown(j: dict) -> list[str]:
    """The `report.md` section of the discovered terms (kept apart from the named causes), from `report.json`."""
    found = [f for f in j["findings"] if f["cause"] == "discovered"]
    search = j.get("discovery")
    if not found and not search:
        return []
    lines = ["## Discovered terms (beyond the vocabulary)", ""]
    if found:
        lines += [
            "Sparse search of the one-step force residuals, refitted through simulation and kept because it "
            "passed the same held-out test as a named cause:",
            "",
            "| where | formula | std. errors | gain | p | selection frequency | reading |",
            "|---|---|---|---|---|---|---|",
        ]
        for f in found:
            stds = ", ".join(f"{n}: {v:.2g}" for n, v in f["std_errors"].items())
            freq = ", ".join(f"{n}: {v:.0%}" for n, v in f["selection_frequency"].items())
            lines.append(
                f"| `{f['where']}` | `{f['formula']}` | {stds} | {f['gain']:.0%} | {f['p_value']:.2g} | {freq} | "
                f"{'; '.join(f['readings']) or 'no known physical reading'} |"
            )
        lines += [
            "",
            "A discovered term is a description of what is missing, not a named cause: read the formula "
            "and its reading as a lead for the model's next version.",
            "",
        ]
    else:
        lines += [
            "The search for a term beyond the vocabulary kept nothing"
            + (
                f" (the proposal's held-out gain was {search['gain']:.0%}, p = {search['p_value']:.2g})"
                if search.get("tested")
                else ""
            )
            + "; see the notes.",
            "",
        ]
    return lines
