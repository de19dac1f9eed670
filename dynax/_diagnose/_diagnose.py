"""`diagnose`: show what a model's simulation gets wrong, name the cause, extend the model, measure the gain."""

from collections.abc import Callable, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import scipy.stats

from .._data._derivatives import resample
from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._model._extensions import AbstractInputTerm, AbstractTerm, Extended
from .._model._helicopter import Helicopter
from .._model._system import AbstractManipulator, AbstractSystem
from ._candidates import candidate_scales, default_candidates, look_alikes, structurally_absorbed
from ._discovery import discover
from ._fit import Family, fit_configurations, make_windows, nominal_parameter_names, nominal_values, validate_configurations, window_errors
from ._residuals import acceleration_residuals, Structure, structure_test
from ._screening import screen


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
    `notes`, and the fitted models `nominal_model` and `extended_model`.
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


def _paired_test(score_ref, score_new, n_eff):
    """One-sided paired test that `score_new` is smaller than `score_ref` over windows; n_eff independent ones."""
    # Improvements are multiplicative, so the test is on log ratios; a floor of a tenth of the typical
    # window error keeps windows where both models are at the noise floor (a machine at rest) from
    # counting as large changes either way.
    floor = 0.1 * float(np.median(score_ref)) + 1e-300
    d = np.log((score_ref + floor) / (score_new + floor))
    sd = float(np.std(d, ddof=1)) if d.size > 1 else 0.0
    if sd == 0.0:
        return 0.0 if np.mean(d) > 0 else 1.0
    t = float(np.mean(d)) / (sd / np.sqrt(n_eff))
    return float(scipy.stats.t.sf(t, max(n_eff - 1, 1)))


def diagnose(
    system: AbstractSystem,
    train: Trajectory | Sequence[Trajectory],
    validation: Trajectory | Sequence[Trajectory] | None = None,
    *,
    candidates: Sequence[AbstractTerm] | None = None,
    mode: Refit | Known = Refit(),
    horizons_s: Sequence[float] = (0.1, 0.25, 0.5, 1.0, 2.0),
    reference_horizon_s: float = 1.0,
    fit_window_s: float = 1.0,
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
    2. **Show what it gets wrong** on held-out data: open-loop simulation error against horizon,
       and a probe of its one-step acceleration residuals for structure (see `structure_test`).
    3. **Name the cause**: forward selection over `candidates`. Each round refits every remaining
       candidate's coefficient in one `vmap` (screening), then refits the best few and their
       look-alikes jointly with the nominal parameters, and keeps the best if its held-out
       improvement at `reference_horizon_s` is significant (one-sided paired test over windows,
       Bonferroni over the candidates tested, level `alpha`) and at least `min_gain`, with a
       physical sign. Candidates a refit of the nominal parameters reproduces exactly are set
       aside as not identifiable.
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
    - `horizons_s`, `reference_horizon_s`: where the simulation error is reported and judged.
    - `fit_window_s`: window length of the simulation-error fits.
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
    say = progress or (lambda _: None)
    if not isinstance(system, AbstractSystem) or isinstance(system, Extended):
        raise UsageError(f"diagnose: `system` must be a nominal dynax system, got {type(system).__name__}")
    if not isinstance(mode, (Refit, Known)):
        raise UsageError(f"diagnose: `mode` must be Refit() or Known(), got {type(mode).__name__}")
    if max_terms < 1:
        raise UsageError(f"diagnose: `max_terms` must be at least 1, got {max_terms}")
    notes: list[str] = []
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
    train_records = [_cast(r, dtype) for r in train_records]
    validation_records = [_cast(r, dtype) for r in validation_records]

    # --- candidates and their identifiability in this mode -------------------------------------
    candidates = tuple(default_candidates(system) if candidates is None else candidates)
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
    n_fit = max(2, int(round(fit_window_s / dt)))
    train_windows = make_windows(train_records, n_fit, n_fit)
    shortest = min(r.duration for r in validation_records)
    horizons = np.asarray([h for h in horizons_s if h <= 0.5 * shortest + 1e-9] or [min(horizons_s)], float)
    if reference_horizon_s > horizons.max():
        notes.append(f"The held-out record is short: the reference horizon was lowered from {reference_horizon_s:g} s to {horizons.max():g} s.")
        reference_horizon_s = float(horizons.max())
    if reference_horizon_s not in horizons:
        horizons = np.sort(np.append(horizons, reference_horizon_s))
    steps = np.maximum(np.round(horizons / dt).astype(int), 1)
    n_ref = int(np.round(reference_horizon_s / dt))
    val_stride = max(1, int(round(0.05 / dt)))
    val_windows = make_windows(validation_records, int(steps.max()), val_stride)
    covered = sum(max(r.duration - horizons.max() + reference_horizon_s, reference_horizon_s) for r in validation_records)
    n_eff = max(2.0, covered / reference_horizon_s)
    if isinstance(system, AbstractManipulator):
        position_index = list(range(system.n_joints))
    elif isinstance(system, Helicopter):
        position_index = [0, 1, 2]  # world position x, y, z [m]
    else:
        position_index = [i for i, s in enumerate(system.state_names) if not s.startswith("d")]

    n_nom, n_slots = len(names), max_terms
    n_params = n_nom + n_slots + 1
    free_all = jnp.ones(n_params, dtype)
    state_scale = np.asarray(family.state_scale)

    def run_fits(slots, new, p_init, free):
        p, cost, std = fit_configurations(family, train_windows, jnp.asarray(slots), jnp.asarray(new), jnp.asarray(p_init, dtype), free)
        errors = validate_configurations(family, val_windows, jnp.asarray(slots), jnp.asarray(new), p)
        return np.asarray(p), np.asarray(cost), np.asarray(std), np.asarray(errors)

    def window_scores(errors):  # (batch, window, step, state) -> (batch, window)
        e = np.nan_to_num(errors[:, :, 1 : n_ref + 1] / state_scale, nan=1e3, posinf=1e3, neginf=1e3)
        return np.mean(np.minimum(e**2, 1e6), axis=(2, 3))

    def rmse_curve(errors):  # (window, step, state) -> per horizon
        at = errors[:, steps][:, :, position_index]
        finite = np.isfinite(at).all(axis=(1, 2))
        if finite.mean() < 0.95:
            return np.full(len(steps), np.inf)
        return np.sqrt(np.mean(at[finite] ** 2, axis=(0, 2)))

    def model_of(slots, p):
        return family.model_for(jnp.asarray(slots), jnp.asarray(-1), jnp.asarray(p, dtype))

    # --- forward selection; round 1 also fits the nominal model --------------------------------
    findings, candidate_table, selected = [], [], []
    slots_cur = -np.ones(n_slots, int)
    p_cur = np.concatenate([p0_nominal, np.zeros(n_slots + 1)])
    batch = shortlist + 1
    ref_index = int(np.flatnonzero(np.isclose(horizons, reference_horizon_s))[0])
    nominal_rmse = structure_nominal = structure_current = nominal_model = None
    for round_ in range(max_terms):
        remaining = [k for k in searchable if k not in selected]
        short = []
        if remaining:
            say(f"round {round_ + 1}: screening {len(remaining)} candidates on one-step residuals ...")
            coefficients = family.coefficients(jnp.asarray(slots_cur), jnp.asarray(-1), jnp.asarray(p_cur, dtype))
            gains_scr, deltas_scr = screen(family, p_cur[:n_nom], np.asarray(coefficients), family.refit,
                                           train_records, validation_records, remaining, acceleration_residuals)
            order = [remaining[i] for i in np.argsort(-gains_scr)]
            short = order[: max(1, shortlist - 2)]
            for k in look_alikes(system, candidates[order[0]], candidates):
                if k in remaining and k not in short:
                    short.append(k)
            short += [k for k in order if k not in short][: max(0, shortlist - len(short))]
            short = short[:shortlist]
            say(f"round {round_ + 1}: simulation-error refit of "
                + ("the nominal model with " if round_ == 0 else "the current model with ")
                + ", ".join(candidates[k].label(system) for k in short) + " (one batch) ...")
        elif round_ > 0:
            break
        new_j = np.asarray([-1] + short + [-1] * (shortlist - len(short)))
        p_init_j = np.tile(p_cur, (batch, 1))
        for i, k in enumerate(new_j):
            if k >= 0:
                d = deltas_scr[remaining.index(k)]
                start = inits[k] - neutral[k]
                term = candidates[k]
                ok = np.isfinite(d) and (term.sign == 0 or d * term.sign > 0) and abs(d) < 20 * scales[k]
                p_init_j[i, -1] = d if ok and not (isinstance(term, AbstractInputTerm) and term.n_hidden and d < start) else start
        p_j, _, std_j, err_j = run_fits(np.tile(slots_cur, (batch, 1)), new_j, p_init_j, free_all)
        scores_j = window_scores(err_j)
        if round_ == 0:  # the nominal model, refitted
            p_cur, score_cur, nominal_rmse = p_j[0].copy(), scores_j[0], rmse_curve(err_j[0])
            rmse_current = nominal_rmse
            nominal_model = model_of(slots_cur, p_cur).system
            say(f"nominal model: held-out position RMSE {nominal_rmse[ref_index]:.4g} at {reference_horizon_s:g} s; "
                "probing its one-step residuals for structure ...")
            structure_nominal = structure_current = structure_test(nominal_model, train_records, validation_records)
        if not short:
            break
        results = {}
        for i, k in enumerate(short, start=1):
            term = candidates[k]
            delta = p_j[i, -1]
            gain_windows = 1 - scores_j[i].mean() / score_cur.mean()
            p_value = _paired_test(score_cur, scores_j[i], n_eff)
            physical = term.sign == 0 or delta * term.sign > 0
            significant = p_value < alpha / len(remaining) and gain_windows >= min_gain and physical
            results[k] = dict(i=i, delta=delta, std=std_j[i, -1], gain_windows=gain_windows, p=p_value,
                              rmse=rmse_curve(err_j[i]), physical=physical, significant=significant)
        if round_ == 0:
            for i, k in enumerate(remaining):
                entry = {"cause": candidates[k].cause, "where": candidates[k].where(system),
                         "screening_gain": float(gains_scr[i])}
                if k in results:
                    entry.update(gain=float(results[k]["gain_windows"]), p_value=results[k]["p"],
                                 coefficient=float(neutral[k] + results[k]["delta"]))
                candidate_table.append(entry)
            candidate_table.sort(key=lambda e: (-e.get("gain", -np.inf), -e["screening_gain"]))
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
                    "p_value": _paired_test(scores_j[results[k]["i"]], scores_j[r["i"]], n_eff),
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
        })
        say(f"round {round_ + 1}: found {term.label(system)}, {term.parameter_name(system)} = {neutral[best] + r['delta']:.4g} "
            f"(held-out gain {gain_rmse:.0%}, p = {r['p']:.2g}; told apart from look-alikes: {confidence})")
        selected.append(best)
        slots_cur = slots_cur.copy()
        slots_cur[len(selected) - 1] = best
        p_cur = p_j[r["i"]].copy()
        p_cur[n_nom + len(selected) - 1] = p_cur[-1]
        p_cur[-1] = 0.0
        std_cur = std_j[r["i"]].copy()
        std_cur[n_nom + len(selected) - 1] = std_cur[-1]
        score_cur, rmse_current = scores_j[r["i"]], r["rmse"]
        say("probing the extended model's residuals for structure ...")
        structure_current = structure_test(model_of(slots_cur, p_cur), train_records, validation_records)
        if not structure_current.significant:
            break

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
            curve = rmse_curve(errors)
            return window_scores(errors[None])[0], curve, curve[ref_index]

        found = discover(
            extended_model if selected else nominal_model, train_records, validation_records, held_out=held_out,
            significance=lambda ref, new: _paired_test(ref, new, n_eff), refit=refit_names,
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
        s = structure_current
        notes.append(
            "Structure is left that the candidates do not explain: the residual probe explains "
            f"{s.r2:.0%} of the held-out one-step residuals (p = {s.p_value:.2g}), mostly through "
            + ", ".join(f"{n} ({w:.0%})" for n, w in s.top_features[:3])
            + f"; largest in {', '.join(f'{k} ({v:.0%})' for k, v in s.by_state.items())}; worst around t = "
            + ", ".join(f"{t:.1f} s" for t in s.worst_times) + " of the held-out record."
        )
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
        reference_horizon_s=float(reference_horizon_s),
        structure={"nominal": _structure_json(structure_nominal), "extended": _structure_json(structure_current)},
        not_identifiable=not_identifiable,
        candidates=candidate_table,
        notes=notes,
        nominal_model=nominal_model,
        extended_model=extended_model,
        discovery=discovery_json,
    )


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
