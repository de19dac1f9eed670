"""`diagnose`: show what a model's simulation gets wrong, name the cause, extend the model, measure the gain."""

from collections.abc import Callable, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._precision import warn_if_float32
from .._data._derivatives import resample
from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._model._extensions import AbstractInputTerm, AbstractTerm, Extended
from .._model._helicopter import Helicopter
from .._model._system import AbstractManipulator, AbstractSystem
from ._candidates import candidate_scales, default_candidates, look_alikes, structurally_absorbed
from ._fit import Family, fit_configurations, make_windows, nominal_parameter_names, nominal_values, validate_configurations
from ._horizon import DEFAULT_FRACTION, Horizon, predictability_horizon, relative_position_error
from ._discovery import discover
from ._fit import window_errors
from ._residuals import acceleration_residuals, Structure, structure_test
from ._screening import screen
from ._statistics import benjamini_hochberg, detectable_gain, helps_on_most_runs, log_ratio_differences, paired_block_test


MIN_BATCHES = 10  # the data-driven reference horizon leaves the paired test at least this many batches

_CONTRACT_NAMES = {"Acrobot": "acrobot", "DoublePendulum": "double_pendulum", "LinearAxis": "linear_axis", "Helicopter": "helicopter"}


class Refit(eqx.Module):
    """Diagnosis mode: the nominal parameters are refitted on the training data with every candidate.

    Causes that a change of the refitted parameters reproduces exactly are not identifiable in this
    mode (an input gain on the acrobot rescales theta1..theta7) and are reported as such.

    **Arguments:** `parameters`, the names of the nominal parameters to refit (default all, e.g.
    `theta1..theta7`; `("mass", "viscous")` for a linear axis whose nominal model is mass and
    viscous friction).
    """

    parameters: tuple[str, ...] | None = None


class Known(eqx.Module):
    """Diagnosis mode: the nominal parameters are trusted (datasheet, CAD, an earlier identification) and kept.

    Every candidate is identifiable; only the candidates' coefficients are fitted.
    """


class Report(eqx.Module):
    """The result of `diagnose`. `to_json()` is the contract's `report.json`; `to_markdown()` is for a person.

    **Fields:** `system` (contract name), `data` (record names and sizes), `mode`, `nominal`
    (parameters and held-out simulation error), `verdict` (`explained`, `none`, `unexplained`),
    `findings` (most important first), `extended` (terms, parameters, simulation error), `gain`,
    `reference_horizon_s`, `structure` (the residual probe on the nominal and the extended model),
    `not_identifiable`, `candidates` (every candidate's held-out gain in the first round),
    `notes`, `horizon` (the reference horizon and how it was chosen), `runs` (held-out error per
    run), `test` (the significance test, and with verdict `none` the gain it could have detected),
    and the fitted models `nominal_model` and `extended_model`.
    """

    system: str
    data: dict
    mode: str
    nominal: dict
    verdict: str
    findings: list
    extended: dict
    gain: float
    reference_horizon_s: float
    structure: dict
    not_identifiable: list
    candidates: list
    notes: list
    horizon: dict
    runs: list
    test: dict
    nominal_model: AbstractSystem
    extended_model: AbstractSystem
    discovery: dict = eqx.field(default_factory=dict)

    def to_json(self) -> dict:
        """The contract's `report.json` (section 3), with extra keys after the contract's."""
        return {
            "system": self.system,
            "data": self.data,
            "nominal": self.nominal,
            "verdict": self.verdict,
            "findings": self.findings,
            "extended": self.extended,
            "gain": self.gain,
            "reference_horizon_s": self.reference_horizon_s,
            "mode": self.mode,
            "structure": self.structure,
            "not_identifiable": self.not_identifiable,
            "candidates": self.candidates,
            "notes": self.notes,
            "horizon": self.horizon,
            "runs": self.runs,
            "test": self.test,
            **({"discovery": self.discovery} if self.discovery else {}),
        }

    def to_markdown(self) -> str:
        from ._report import report_markdown

        return report_markdown(self)


def _as_records(data, name) -> list[Trajectory]:
    if isinstance(data, Trajectory):
        return [data]
    if isinstance(data, Sequence) and data and all(isinstance(t, Trajectory) for t in data):
        return list(data)
    raise UsageError(f"diagnose: `{name}` must be a Trajectory or a non-empty sequence of them, got {type(data).__name__}")


def _merge_repeated_causes(findings: list[dict]) -> list[dict]:
    """One finding per cause and place. The wind's north, east and down components are separate
    candidates at `world`, so a wind blowing in two directions is found in two rounds; report it
    once: `coefficient` is the wind speed (the norm of the components, its standard error
    propagated to first order), `components` the components, `gain` the two rounds' gains
    compounded, `p_value` the weaker round's, and `confidence` high only if every round's was."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for finding in findings:
        groups.setdefault((finding["cause"], finding["where"]), []).append(finding)
    merged = []
    for (cause, where), group in groups.items():
        if len(group) == 1:
            merged.append(group[0])
            continue
        values = np.array([f["coefficient"] for f in group])
        stds = np.array([f["std_error"] for f in group])
        size = float(np.linalg.norm(values))
        std = float(np.sqrt(np.sum((values / size) ** 2 * stds**2))) if size > 0 else float(np.linalg.norm(stds))
        look_alikes: dict[str, dict] = {}
        for f in group:
            for alt in f["look_alikes"]:  # keep the weakest separation from each look-alike cause
                if alt["cause"] not in look_alikes or alt["p_value"] > look_alikes[alt["cause"]]["p_value"]:
                    look_alikes[alt["cause"]] = alt
        merged.append({
            "cause": cause,
            "where": where,
            "coefficient": size,
            "std_error": std,
            "gain": float(1 - np.prod([1 - f["gain"] for f in group])),
            "parameter": f"{cause}_speed" if cause == "wind" else f"|{cause}|",
            "components": {f["parameter"]: f["coefficient"] for f in group},
            "component_std_errors": {f["parameter"]: f["std_error"] for f in group},
            "p_value": max(f["p_value"] for f in group),
            "look_alikes": list(look_alikes.values()),
            "confidence": "high" if all(f["confidence"] == "high" for f in group) else "low",
        })
    return merged


def _paired_test(score_ref, score_new, runs, overlap):
    """One-sided paired test that `score_new` is smaller than `score_ref` over held-out windows (see `_statistics`)."""
    return paired_block_test(log_ratio_differences(score_ref, score_new), runs, overlap)


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
    holdout_fraction: float = 0.3,
    shortlist: int = 4,
    system_name: str | None = None,
    discovery: bool = True,
    progress: Callable[[str], None] | None = None,
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
       physical sign. Candidates a refit of the nominal parameters reproduces exactly are set
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
    - `progress`: called with a line of text at each stage (e.g. `print`).

    **Returns:** a `Report`.

    ??? cite

        L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, ch. 16 (model
        structure selection and validation). N. R. Draper and H. Smith, *Applied Regression
        Analysis*, 3rd ed., 1998, ch. 15 (forward selection).
    """
    warn_if_float32("diagnosis")  # the float64 policy: say so, once, naming the switch
    say = progress or (lambda _: None)
    if not isinstance(system, AbstractSystem) or isinstance(system, Extended):
        raise UsageError(f"diagnose: `system` must be a nominal dynax system, got {type(system).__name__}")
    if not isinstance(mode, (Refit, Known)):
        raise UsageError(f"diagnose: `mode` must be Refit() or Known(), got {type(mode).__name__}")
    if max_terms < 1:
        raise UsageError(f"diagnose: `max_terms` must be at least 1, got {max_terms}")
    notes: list[str] = []
    train_records, validation_records, dt = _prepare_records(system, train, validation, holdout_fraction, notes)
    dtype = jnp.result_type(float)

    # --- candidates and their identifiability in this mode -------------------------------------
    candidates = tuple(default_candidates(system, train_records) if candidates is None else candidates)
    if not candidates:
        raise UsageError("diagnose: `candidates` is empty")
    Extended(system, candidates)  # checks every candidate fits this system
    names = nominal_parameter_names(system)
    if isinstance(mode, Refit):
        refit_names = names if mode.parameters is None else tuple(mode.parameters)
        unknown = set(refit_names) - set(names)
        if unknown:
            raise UsageError(f"diagnose: Refit(parameters=...) names {sorted(unknown)}, not parameters of {type(system).__name__} {names}")
    else:
        refit_names = ()
    scales, inits = candidate_scales(system, candidates, train_records)
    neutral = np.asarray([t.neutral for t in candidates], float)
    p0_nominal = np.asarray(nominal_values(system, names), float)
    xs_train = np.concatenate([np.asarray(r.xs) for r in train_records])
    family = Family(
        model=Extended(system, candidates),
        names=names,
        refit=jnp.asarray([1.0 if n in refit_names else 0.0 for n in names], dtype),
        nominal_scale=jnp.asarray(np.maximum(np.abs(p0_nominal), 1e-2), dtype),
        candidate_scale=jnp.asarray(scales, dtype),
        candidate_init=jnp.asarray(inits, dtype),
        neutral=jnp.asarray(neutral, dtype),
        state_scale=jnp.asarray(np.maximum(xs_train.std(axis=0), 1e-9), dtype),
    )

    absorbed = structurally_absorbed(family, family.refit)
    not_identifiable, searchable = [], []
    for k, term in enumerate(candidates):
        if absorbed[k]:
            not_identifiable.append(
                {"cause": term.cause, "where": term.where(system),
                 "reason": f"a refit of the nominal parameters ({', '.join(refit_names)}) reproduces it exactly; "
                           "diagnose in Known() mode with trusted parameters to test it"}
            )
        else:
            searchable.append(k)
    if not searchable:
        raise UsageError("diagnose: no candidate is identifiable in this mode")

    # --- windows ---------------------------------------------------------------------------
    fit_window_s = _fit_window(system, train_records, fit_window_s, horizon_fraction, dt, notes)
    n_fit = max(2, int(round(fit_window_s / dt)))
    train_windows = make_windows(train_records, n_fit, n_fit)
    horizons, candidates_s = _horizon_grid(horizons_s, reference_horizon_s, train_records, validation_records, notes)
    val_stride = max(1, int(round(0.05 / dt)))
    val_windows = make_windows(validation_records, int(round(horizons.max() / dt)), val_stride)
    window_runs = np.asarray([r for r, _ in val_windows.starts])
    position_index = _position_index(system)

    n_nom, n_slots = len(names), max_terms
    n_params = n_nom + n_slots + 1
    free_all = jnp.ones(n_params, dtype)
    state_scale = np.asarray(family.state_scale)

    def run_fits(slots, new, p_init, free):
        p, cost, std = fit_configurations(family, train_windows, jnp.asarray(slots), jnp.asarray(new), jnp.asarray(p_init, dtype), free)
        errors = validate_configurations(family, val_windows, jnp.asarray(slots), jnp.asarray(new), p)
        return np.asarray(p), np.asarray(cost), np.asarray(std), np.asarray(errors)

    def model_of(slots, p):
        return family.model_for(jnp.asarray(slots), jnp.asarray(-1), jnp.asarray(p, dtype))

    # --- forward selection; round 1 also fits the nominal model --------------------------------
    findings, candidate_table, selected, tests_last = [], [], [], {}
    slots_cur = -np.ones(n_slots, int)
    p_cur = np.concatenate([p0_nominal, np.zeros(n_slots + 1)])
    batch = shortlist + 1
    nominal_rmse = structure_nominal = structure_current = nominal_model = horizon = None
    for round_ in range(max_terms):
        remaining = [k for k in searchable if k not in selected]
        short = []
        if remaining:
            say(f"round {round_ + 1}: screening {len(remaining)} candidates on one-step residuals ...")
            coefficients = family.coefficients(jnp.asarray(slots_cur), jnp.asarray(-1), jnp.asarray(p_cur, dtype))
            gains_scr, deltas_scr = screen(family, p_cur[:n_nom], np.asarray(coefficients), family.refit,
                                           train_records, validation_records, remaining, acceleration_residuals)
            short = _shortlist(system, candidates, remaining, gains_scr, shortlist)
            say(f"round {round_ + 1}: simulation-error refit of "
                + ("the nominal model with " if round_ == 0 else "the current model with ")
                + ", ".join(candidates[k].label(system) for k in short) + " (one batch) ...")
        elif round_ > 0:
            break
        new_j = np.asarray([-1] + short + [-1] * (shortlist - len(short)))
        p_init_j = np.tile(p_cur, (batch, 1))
        for i, k in enumerate(new_j):
            if k >= 0:
                p_init_j[i, -1] = _start_value(candidates[k], deltas_scr[remaining.index(k)], inits[k] - neutral[k], scales[k])
        p_j, cost_j, std_j, err_j = run_fits(np.tile(slots_cur, (batch, 1)), new_j, p_init_j, free_all)
        if round_ == 0:  # the nominal model, refitted; the reference horizon from its training error
            p_cur = p_j[0].copy()
            nominal_model = model_of(slots_cur, p_cur).system
            horizon = _reference_horizon(nominal_model, train_records, candidates_s, reference_horizon_s,
                                         horizon_fraction, val_stride, position_index, dt)
            if horizon.seconds not in horizons:
                horizons = np.sort(np.append(horizons, horizon.seconds))
            steps = np.maximum(np.round(horizons / dt).astype(int), 1)
            n_ref = int(np.round(horizon.seconds / dt))
            overlap = max(1, int(np.ceil(n_ref / val_stride)))
            ref_index = int(np.flatnonzero(np.isclose(horizons, horizon.seconds))[0])
            scores_j = _window_scores(err_j, n_ref, state_scale)
            score_cur, err_cur = scores_j[0], err_j[0]
            err_nominal = err_j[0]
            nominal_rmse = rmse_current = _rmse_curve(err_j[0], steps, position_index)
            say(f"reference horizon {horizon.seconds:g} s ({horizon.rule}); nominal model: held-out position RMSE "
                f"{nominal_rmse[ref_index]:.4g} there; probing its one-step residuals for structure ...")
            structure_nominal = structure_current = structure_test(nominal_model, train_records, validation_records)
        else:
            scores_j = _window_scores(err_j, n_ref, state_scale)
        if not short:
            break
        results = _judge_round(candidates, short, remaining, p_j, std_j, err_j, scores_j, score_cur, window_runs,
                               overlap, alpha, min_gain, steps, position_index)
        tests_last = results
        if round_ == 0:
            candidate_table = _candidate_table(system, candidates, remaining, gains_scr, results, neutral, cost_j)
        admissible = [k for k in short if results[k]["significant"]]
        if not admissible:
            say(f"round {round_ + 1}: no candidate improves the held-out simulation significantly")
            break
        best = max(admissible, key=lambda k: results[k]["gain_windows"])
        r = results[best]
        term = candidates[best]
        gain_rmse = float(1 - r["rmse"][ref_index] / rmse_current[ref_index]) if np.isfinite(rmse_current[ref_index]) else 1.0
        alternatives = []
        for k in look_alikes(system, term, candidates):
            if k in results:
                alternatives.append({
                    "cause": candidates[k].cause,
                    "gain": float(results[k]["gain_windows"]),
                    "p_value": _paired_test(scores_j[results[k]["i"]], scores_j[r["i"]], window_runs, overlap).p_value,
                })
        confidence = "high" if all(a["p_value"] < alpha for a in alternatives) else "low"
        findings.append({
            "cause": term.cause,
            "where": term.where(system),
            "coefficient": float(neutral[best] + r["delta"]),
            "std_error": float(r["std"]),
            "gain": gain_rmse,
            "parameter": term.parameter_name(system),
            "p_value": r["p"],
            "look_alikes": alternatives,
            "confidence": confidence,
            "runs_helped": f"{r['runs_helped']}/{r['n_runs']}",
        })
        say(f"round {round_ + 1}: found {term.label(system)}, {term.parameter_name(system)} = {neutral[best] + r['delta']:.4g} "
            f"(held-out gain {gain_rmse:.0%}, p = {r['p']:.2g}, helps on {r['runs_helped']}/{r['n_runs']} held-out runs; "
            f"told apart from look-alikes: {confidence})")
        selected.append(best)
        slots_cur = slots_cur.copy()
        slots_cur[len(selected) - 1] = best
        p_cur = p_j[r["i"]].copy()
        p_cur[n_nom + len(selected) - 1] = p_cur[-1]
        p_cur[-1] = 0.0
        std_cur = std_j[r["i"]].copy()
        std_cur[n_nom + len(selected) - 1] = std_cur[-1]
        score_cur, err_cur, rmse_current = scores_j[r["i"]], err_j[r["i"]], r["rmse"]
        say("probing the extended model's residuals for structure ...")
        structure_current = structure_test(model_of(slots_cur, p_cur), train_records, validation_records)
        # The probe never vetoes: selection goes on while a candidate's own held-out test passes.

    # Every finding's coefficient from the final joint fit (earlier rounds' values move when later terms join).
    for m, (finding, k) in enumerate(zip(findings, selected)):
        finding["coefficient"] = float(neutral[k] + p_cur[n_nom + m])
        finding["std_error"] = float(std_cur[n_nom + m])
    findings = _merge_repeated_causes(findings)
    extended_model = model_of(slots_cur, p_cur)
    extended_model = Extended(extended_model.system, tuple(extended_model.terms[k] for k in selected))
    if not selected:
        verdict = "unexplained" if structure_nominal.significant else "none"
    else:
        verdict = "unexplained" if structure_current.significant else "explained"
    gain = float(1 - rmse_current[ref_index] / nominal_rmse[ref_index]) if selected and np.isfinite(nominal_rmse[ref_index]) else 0.0
    discovery_json: dict = {}
    # Beyond the vocabulary: search, refit, the same held-out test. Also after a `none`: the generic
    # probe cannot see every structure (a force periodic in position), the search's own guards can.
    if discovery and verdict != "explained":
        held_out_errors = eqx.filter_jit(window_errors)

        def held_out(model):
            errors = np.asarray(held_out_errors(model, val_windows))
            curve = _rmse_curve(errors, steps, position_index)
            return _window_scores(errors[None], n_ref, state_scale)[0], curve, curve[ref_index]

        found = discover(
            extended_model if selected else nominal_model, train_records, validation_records, held_out=held_out,
            significance=lambda ref, new: _paired_test(ref, new, window_runs, overlap).p_value, refit=refit_names,
            vocabulary=[candidates[k].label(system) for k in searchable],
            absorbed=[f"{c['cause']}@{c['where']}" for c in not_identifiable], alpha=alpha, min_gain=min_gain, fit_window_s=fit_window_s,
            current=(score_cur, rmse_current, rmse_current[ref_index]), progress=say,
        )
        notes += found.notes
        discovery_json = found.summary(system)
        if found.kept:
            findings, extended_model, rmse_current = findings + found.findings, found.model, found.held_out[1]
            say("probing the residuals of the model with the discovered terms for structure ...")
            structure_current = structure_test(extended_model, train_records, validation_records)
            verdict = "unexplained" if structure_current.significant else "explained"
            gain = float(1 - rmse_current[ref_index] / nominal_rmse[ref_index]) if np.isfinite(nominal_rmse[ref_index]) else 0.0
    if verdict == "unexplained":
        notes.append(_unexplained_note(structure_current))
    test = _test_summary(alpha, min_gain, tests_last, len(searchable), verdict)
    if test["detectable_gain"] is not None:
        notes.append(f"No candidate passed the test. With these held-out runs the test would have detected a gain of "
                     f"about {test['detectable_gain']:.0%} at {horizon.seconds:g} s (power 80 %); a smaller effect may be present.")
    runs = _per_run_table(validation_records, window_runs, err_nominal, err_cur, n_ref, position_index)
    nominal_parameters = dict(zip(names, map(float, nominal_values(nominal_model, names))))
    extended_parameters = dict(zip(names, map(float, nominal_values(extended_model.system, names))))
    extended_parameters.update({k: float(v) for t in extended_model.terms for k, v in t.parameters(system).items()})
    horizons_list = [float(h) for h in horizons]
    return Report(
        system=system_name or train_records[0].system or _CONTRACT_NAMES.get(type(system).__name__, type(system).__name__.lower()),
        data={
            "train": ", ".join(r.source or "(train)" for r in _as_records(train, "train")),
            "validation": ", ".join(r.source or "(held out)" for r in validation_records) if validation is not None
            else "last {:.0%} of {}".format(holdout_fraction, ", ".join(r.source or "train" for r in _as_records(train, "train"))),
            "n_train": int(sum(len(r) for r in train_records)),
            "n_validation": int(sum(len(r) for r in validation_records)),
            "dt": dt,
            "train_runs": [r.source or f"train run {i + 1}" for i, r in enumerate(train_records)],
            "validation_runs": [r.source or f"held-out run {i + 1}" for i, r in enumerate(validation_records)],
        },
        mode="refit" if isinstance(mode, Refit) else "known",
        nominal={"parameters": nominal_parameters, "sim_error": {"horizons_s": horizons_list, "rmse": _floats(nominal_rmse)}},
        verdict=verdict,
        findings=findings,
        extended={
            "terms": list(dict.fromkeys(t.label(system) for t in extended_model.terms)),  # wind@world once
            "parameters": extended_parameters,
            "sim_error": {"horizons_s": horizons_list, "rmse": _floats(rmse_current)},
        },
        gain=gain,
        reference_horizon_s=float(horizon.seconds),
        structure={"nominal": _structure_json(structure_nominal), "extended": _structure_json(structure_current)},
        not_identifiable=not_identifiable,
        candidates=candidate_table,
        notes=notes,
        horizon=horizon.to_json(),
        runs=runs,
        test=test,
        nominal_model=nominal_model,
        extended_model=extended_model,
        discovery=discovery_json,
    )


def _prepare_records(system, train, validation, holdout_fraction, notes):
    """The training and held-out runs, checked against `system`, on one uniform grid, in the default float type.

    Runs are kept apart (never concatenated): every window lies inside one run.
    """
    train_records = _as_records(train, "train")
    for rec in train_records:
        if tuple(rec.state_names) != tuple(system.state_names) or tuple(rec.input_names) != tuple(system.input_names):
            raise UsageError(
                f"diagnose: the record {rec.source or ''} has states {rec.state_names} and inputs {rec.input_names}, "
                f"but {type(system).__name__} has {system.state_names} and {system.input_names}"
            )
    if validation is None:
        if not 0 < holdout_fraction < 1:
            raise UsageError(f"diagnose: `holdout_fraction` must be in (0, 1), got {holdout_fraction}")
        split = []
        for rec in train_records:
            k = int(round(len(rec) * (1 - holdout_fraction)))
            split.append((rec, k))
        train_records = [_slice(rec, 0, k) for rec, k in split]
        validation_records = [_slice(rec, k, len(rec)) for rec, k in split]
        notes.append(
            f"No validation record was given: the last {holdout_fraction:.0%} of each training record was held out."
        )
    else:
        validation_records = _as_records(validation, "validation")
    dt = float(np.median(np.concatenate([np.diff(np.asarray(r.ts)) for r in train_records + validation_records])))
    if not all(r.is_uniform for r in train_records + validation_records):
        train_records = [resample(r, dt) for r in train_records]
        validation_records = [resample(r, dt) for r in validation_records]
        notes.append(f"The sampling was irregular; the records were resampled to {dt * 1000:.3g} ms (states linearly, inputs as held).")
    dtype = jnp.result_type(float)

    return [_cast(r, dtype) for r in train_records], [_cast(r, dtype) for r in validation_records], dt


def _position_index(system) -> list[int]:
    if isinstance(system, AbstractManipulator):
        return list(range(system.n_joints))
    if isinstance(system, Helicopter):
        return [0, 1, 2]  # world position x, y, z [m]
    return [i for i, s in enumerate(system.state_names) if not s.startswith("d")]


def _horizon_grid(horizons_s, reference_horizon_s, train_records, validation_records, notes):
    """The reported horizons (at most half the shortest held-out record) and the candidates for the reference horizon."""
    shortest = min(r.duration for r in validation_records)
    horizons = np.asarray([h for h in horizons_s if h <= 0.5 * shortest + 1e-9] or [min(horizons_s)], float)
    if reference_horizon_s is not None:
        if reference_horizon_s > horizons.max():
            notes.append(f"The held-out record is short: the reference horizon was lowered from {reference_horizon_s:g} s "
                         f"to {horizons.max():g} s.")
            reference_horizon_s = float(horizons.max())
        if reference_horizon_s not in horizons:
            horizons = np.sort(np.append(horizons, reference_horizon_s))
        return horizons, np.asarray([reference_horizon_s])
    # The paired test compares batches of windows twice the horizon long: a horizon of at most a
    # twentieth of the held-out time leaves it at least ten batches (their *length* is looked at,
    # never their errors).
    held_out_s = sum(r.duration for r in validation_records)
    longest = min(horizons.max(), 0.5 * min(r.duration for r in train_records), held_out_s / MIN_BATCHES / 2)
    candidates_s = np.round(np.arange(0.1, longest + 1e-9, 0.05), 6)
    return horizons, candidates_s if candidates_s.size else np.asarray([horizons.min()])


def _reference_horizon(nominal_model, train_records, candidates_s, given, fraction, stride, position_index, dt):
    """The reference horizon: `given`, or the predictability horizon of the nominal model on the training runs."""
    from .._sim_error import simulation_error  # the public rollout over windows

    if given is not None:
        return Horizon(float(candidates_s[0]), "given (reference_horizon_s)", None, candidates_s, [np.nan])
    errors = [np.asarray(simulation_error(nominal_model, rec, candidates_s, stride=stride).errors) for rec in train_records]
    positions = np.concatenate([np.asarray(r.xs)[:, position_index] for r in train_records])
    spread = np.maximum(positions.std(axis=0), 1e-12)
    relative = relative_position_error(np.concatenate(errors), position_index, spread)
    return predictability_horizon(relative, dt, candidates_s, fraction)


def _fit_window(system, train_records, given, fraction, dt, notes) -> float:
    """The fit windows: `given`, or 2.5 times the starting model's predictability horizon on the training runs, in [0.25, 1] s."""
    if given is not None:
        return float(given)
    longest = min(1.0, 0.5 * min(r.duration for r in train_records))
    candidates_s = np.round(np.arange(0.1, longest + 1e-9, 0.05), 6)
    if candidates_s.size == 0:
        return longest
    start = _reference_horizon(system, train_records, candidates_s, None, fraction, max(1, int(round(0.05 / dt))),
                               _position_index(system), dt)
    window = float(np.clip(2.5 * start.seconds, 0.25, longest))
    if window < longest:
        notes.append(f"The starting model predicts the training runs for {start.seconds:g} s only: the simulation-error "
                     f"fits use {window:g} s windows (2.5 times that) instead of {longest:g} s.")
    return window


def _shortlist(system, candidates, remaining, gains_scr, shortlist):
    """The best screened candidates and the look-alikes of the best, `shortlist` in all."""
    order = [remaining[i] for i in np.argsort(-gains_scr)]
    short = order[: max(1, shortlist - 2)]
    for k in look_alikes(system, candidates[order[0]], candidates):
        if k in remaining and k not in short:
            short.append(k)
    short += [k for k in order if k not in short][: max(0, shortlist - len(short))]
    return short[:shortlist]


def _start_value(term, delta_screened, start, scale):
    """A candidate's starting coefficient: the screening's step if physical and moderate, else the default start."""
    ok = np.isfinite(delta_screened) and (term.sign == 0 or delta_screened * term.sign > 0) and abs(delta_screened) < 20 * scale
    lagging = isinstance(term, AbstractInputTerm) and term.n_hidden and delta_screened < start
    return delta_screened if ok and not lagging else start


def _window_scores(errors, n_ref, state_scale):  # (batch, window, step, state) -> (batch, window)
    e = np.nan_to_num(errors[:, :, 1 : n_ref + 1] / state_scale, nan=1e3, posinf=1e3, neginf=1e3)
    return np.mean(np.minimum(e**2, 1e6), axis=(2, 3))


def _rmse_curve(errors, steps, position_index):  # (window, step, state) -> per horizon
    at = errors[:, steps][:, :, position_index]
    finite = np.isfinite(at).all(axis=(1, 2))
    if finite.mean() < 0.95:
        return np.full(len(steps), np.inf)
    return np.sqrt(np.mean(at[finite] ** 2, axis=(0, 2)))


def _judge_round(candidates, short, remaining, p_j, std_j, err_j, scores_j, score_cur, window_runs, overlap,
                 alpha, min_gain, steps, position_index):
    """Each shortlisted candidate's held-out test: paired block test, Benjamini-Hochberg over every remaining candidate
    (those not refitted count with p = 1), the smallest gain, a physical sign, and agreement across runs."""
    tests = {k: _paired_test(score_cur, scores_j[i], window_runs, overlap) for i, k in enumerate(short, start=1)}
    rejected = benjamini_hochberg([tests[k].p_value for k in short] + [1.0] * (len(remaining) - len(short)), alpha)
    results = {}
    for i, k in enumerate(short, start=1):
        term, test = candidates[k], tests[k]
        delta = p_j[i, -1]
        gain_windows = 1 - scores_j[i].mean() / score_cur.mean()
        physical = term.sign == 0 or delta * term.sign > 0
        helped = sum(v > 0 for v in test.per_run.values())
        agree = helps_on_most_runs(test.per_run)
        results[k] = dict(i=i, delta=delta, std=std_j[i, -1], gain_windows=gain_windows, p=test.p_value, test=test,
                          rmse=_rmse_curve(err_j[i], steps, position_index), physical=physical,
                          runs_helped=helped, n_runs=len(test.per_run), n_tested=len(remaining),
                          significant=bool(rejected[i - 1] and gain_windows >= min_gain and physical and agree))
    return results


def _candidate_table(system, candidates, remaining, gains_scr, results, neutral, cost):
    """Every candidate of the first round: screening gain, and for those refitted the held-out gain, p,
    coefficient, runs helped and `training_gain` (the reduction of the training fit's cost: a candidate
    that lowers it but not the held-out error was fitted to what does not transfer)."""
    table = []
    for i, k in enumerate(remaining):
        entry = {"cause": candidates[k].cause, "where": candidates[k].where(system), "screening_gain": float(gains_scr[i])}
        if k in results:
            r = results[k]
            entry.update(gain=float(r["gain_windows"]), p_value=r["p"], coefficient=float(neutral[k] + r["delta"]),
                         runs_helped=f"{r['runs_helped']}/{r['n_runs']}", training_gain=float(1 - cost[r["i"]] / cost[0]))
        table.append(entry)
    table.sort(key=lambda e: (-e.get("gain", -np.inf), -e["screening_gain"]))
    return table


def _test_summary(alpha, min_gain, results, n_searchable, verdict) -> dict:
    """How candidates were judged; with verdict `none`, the gain the test could have detected."""
    detectable = None
    if verdict == "none" and results:
        r = next(iter(results.values()))
        detectable = detectable_gain(float(np.median([r["test"].std_error for r in results.values()])),
                                     max(r["test"].df, 1), alpha / max(r["n_tested"], 1))
        detectable = max(detectable, min_gain)
    return {
        "paired": "log ratio of each held-out window's mean squared error, nominal (or current) against extended; "
                  "HAC variance within each run (flat-top lag window over the windows' correlation length, "
                  "corrected for centring on the run's mean), Student t with its equivalent degrees of freedom",
        "multiple_comparisons": f"Benjamini-Hochberg over the candidates remaining in each round, false-discovery "
                                f"rate {alpha:g} (family-wise {alpha:g} when no candidate has an effect)",
        "run_agreement": "a cause must improve the mean window error on more than half of the held-out runs",
        "alpha": alpha,
        "min_gain": min_gain,
        "detectable_gain": detectable,
    }


def _per_run_table(validation_records, window_runs, err_nominal, err_extended, n_ref, position_index) -> list[dict]:
    """Held-out position RMSE at the reference horizon on each held-out run, nominal and extended."""
    rows = []
    for r, rec in enumerate(validation_records):
        mine = window_runs == r
        nominal = _rmse_curve(err_nominal[mine], np.asarray([n_ref]), position_index)[0]
        extended = _rmse_curve(err_extended[mine], np.asarray([n_ref]), position_index)[0]
        rows.append({"run": rec.source or f"held-out run {r + 1}", "n_windows": int(mine.sum()),
                     "nominal_rmse": float(nominal) if np.isfinite(nominal) else None,
                     "extended_rmse": float(extended) if np.isfinite(extended) else None,
                     "gain": float(1 - extended / nominal) if np.isfinite(nominal) and np.isfinite(extended) and nominal > 0 else None})
    return rows


def _unexplained_note(s: Structure) -> str:
    return ("Structure is left that the candidates do not explain: the residual probe explains "
            f"{s.r2:.0%} of the held-out one-step residuals (p = {s.p_value:.2g}), mostly through "
            + ", ".join(f"{n} ({w:.0%})" for n, w in s.top_features[:3])
            + f"; largest in {', '.join(f'{k} ({v:.0%})' for k, v in s.by_state.items())}; worst around t = "
            + ", ".join(f"{t:.1f} s" for t in s.worst_times) + " of the held-out record.")


def _floats(a):
    return [float(x) if np.isfinite(x) else None for x in np.asarray(a)]


def _structure_json(s: Structure) -> dict:
    return {
        "significant": s.significant,
        "r2": s.r2,
        "p_value": s.p_value,
        "top_features": [{"feature": n, "share": w} for n, w in s.top_features],
        "worst_times_s": list(s.worst_times),
        "by_state": s.by_state,
    }


def _slice(rec: Trajectory, a: int, b: int) -> Trajectory:
    return Trajectory(rec.ts[a:b], rec.xs[a:b], rec.us[a:b], rec.state_names, rec.input_names, rec.system, rec.source)


def _cast(rec: Trajectory, dtype) -> Trajectory:
    return Trajectory(rec.ts.astype(dtype), rec.xs.astype(dtype), rec.us.astype(dtype), rec.state_names,
                      rec.input_names, rec.system, rec.source)
