"""What the report says about a diagnosis: the error measures (window scores, RMSE against horizon, gains)
and the tables built from the selection's results (each round, the first round's candidates, each run,
the test, merged findings).

The functions take the problem, yardstick and models of `_diagnose` as they are; nothing here fits or
simulates.
"""

import numpy as np

from ._residuals import Structure


def merge_repeated_causes(findings: list[dict]) -> list[dict]:
    """One finding per cause and place. The wind's north, east and down components are separate
    candidates at `world`, so a wind blowing in two directions is found in two rounds; report it
    once: `coefficient` is the wind speed (the norm of the components, its standard error
    propagated to first order), `components` the components, `gain` the two rounds' gains
    compounded, `p_value` the weaker round's, and `confidence` high only if every round's was. A round
    named for its look-alike (closed testing, `named_for`) keeps that: `component_named_for` maps each
    such component to the look-alike whose test established it, and `named_for` is the weaker round's
    where it has one, so the merged finding's large `p_value` shows the test it rests on."""
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
        look_alikes: dict[tuple, dict] = {}
        weakness = lambda a: (a["told_apart"], -a["p_value"])  # noqa: E731 (not told apart first, then the largest p)
        for f in group:
            for alt in f["look_alikes"]:  # keep the weakest separation from each look-alike cause
                key = (alt["cause"], alt.get("where"))
                if key not in look_alikes or weakness(alt) < weakness(look_alikes[key]):
                    look_alikes[key] = alt
        merged.append(
            {
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
                **_merged_named_for(group),
            }
        )
    return merged


def _merged_named_for(group: list[dict]) -> dict:
    """The `named_for` fields of a merged finding: every component's, and the weaker round's as the finding's."""
    named = {f["parameter"]: f["named_for"] for f in group if "named_for" in f}
    if not named:
        return {}
    weakest = max(group, key=lambda f: f["p_value"])
    return {"component_named_for": named} | ({"named_for": weakest["named_for"]} if "named_for" in weakest else {})


_RULE_TEXT = {
    "significance": lambda r, o: (
        f"significance: p = {r['p']:.2g} not rejected by Benjamini-Hochberg at false-discovery "
        f"rate {o.alpha:g} over the {r['n_tested']} candidates remaining"
    ),
    "min_gain": lambda r, o: (
        f"min_gain: the typical window-error gain {r['gain_typical']:.1%} is below {o.min_gain:.0%}"
    ),
    "sign": lambda r, o: (
        "sign: a coefficient of the joint refit (this term's or an earlier finding's) is on its unphysical side"
    ),
    "above_coulomb": lambda r, o: (
        "above_coulomb: a static friction level of the joint refit is not above the Coulomb level at its joint "
        "(by a tenth of it and two standard errors): what it holds at rest, a Coulomb friction holds too"
    ),
    "agreement": lambda r, o: f"agreement: helps on {r['runs_helped']} of {r['n_runs']} runs, not on more than half",
    "held_out": lambda r, o: (
        f"held_out: the held-out runs' window error is {-r['gain_held_out']:.1%} larger with it"
        + (
            " (the cross-fitted runs' windows carried the pooled test)"
            if r["gain_windows"] > r["gain_held_out"]
            else ""
        )
    ),
}


def round_summary(problem, yard, round_, current, remaining, results, finding) -> dict:
    """One round of the forward selection for the report: every refitted candidate's held-out gains and p,
    and whether it was selected, passed but lost to a larger held-out gain, or which rules stopped it."""
    system, o = problem.system, problem.selection
    selected = finding["index"] if finding is not None else None
    rows = []
    for k, r in results.items():
        term = problem.candidates[k]
        rows.append(
            {
                "cause": term.cause,
                "where": term.where(system),
                "parameter": term.parameter_name(system),
                "coefficient": float(problem.neutral[k] + r["delta"]),
                "gain": float(r["gain_held_out"]),
                "gain_pooled": float(r["gain_windows"]),
                "gain_typical": float(r["gain_typical"]),
                "sim_error_gain": _finite_or_none(rmse_gain(r["rmse"], current.rmse, yard.ref_index)),
                "p_value": float(r["p"]),
                "runs_helped": f"{r['runs_helped']}/{r['n_runs']}",
                "outcome": "selected" if k == selected else ("passed" if r["significant"] else "stopped"),
                "stopped_by": [_RULE_TEXT[name](r, o) for name, ok in r["rules"].items() if not ok],
            }
        )
    rows.sort(key=lambda e: (e["outcome"] != "selected", e["outcome"] != "passed", -e["gain"]))
    model = [problem.candidates[k].label(system) for k in current.selected]
    if finding is not None:
        outcome = f"selected {problem.candidates[selected].label(system)}"
    elif results:
        outcome = "no candidate passed every rule: the selection stops"
    else:
        outcome = "no candidate left to refit: the selection stops"
    return {
        "round": round_ + 1,
        "model": model,
        "screened": len(remaining),
        "refitted": len(results),
        "candidates": rows,
        "outcome": outcome,
    }


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def rmse_gain(rmse, nominal_rmse, ref) -> float:
    return float(1 - rmse[ref] / nominal_rmse[ref]) if np.isfinite(nominal_rmse[ref]) else 0.0


def window_scores(errors, n_ref, state_scale):  # (batch, window, step, state) -> (batch, window)
    e = np.nan_to_num(errors[:, :, 1 : n_ref + 1] / state_scale, nan=1e3, posinf=1e3, neginf=1e3)
    return np.mean(np.minimum(e**2, 1e6), axis=(2, 3))


def rmse_curve(errors, steps, position_index):  # (window, step, state) -> per horizon
    at = errors[:, steps][:, :, position_index]
    finite = np.isfinite(at).all(axis=(1, 2))
    if finite.mean() < 0.95:
        return np.full(len(steps), np.inf)
    return np.sqrt(np.mean(at[finite] ** 2, axis=(0, 2)))


def candidate_table(system, candidates, remaining, gains_scr, results, neutral, cost):
    """Every candidate of the first round: screening gain, and for those refitted the held-out gain, p,
    coefficient, runs helped and `training_gain` (the reduction of the training fit's cost: a candidate
    that lowers it but not the held-out error was fitted to what does not transfer)."""
    table = []
    for i, k in enumerate(remaining):
        entry = {
            "cause": candidates[k].cause,
            "where": candidates[k].where(system),
            "screening_gain": float(gains_scr[i]),
        }
        if k in results:
            r = results[k]
            entry.update(
                gain=float(r["gain_held_out"]),
                gain_pooled=float(r["gain_windows"]),
                gain_typical=float(r["gain_typical"]),
                p_value=r["p"],
                coefficient=float(neutral[k] + r["delta"]),
                runs_helped=f"{r['runs_helped']}/{r['n_runs']}",
                training_gain=float(1 - cost[r["i"]] / cost[0]),
            )
        table.append(entry)
    table.sort(key=lambda e: (-e.get("gain", -np.inf), -e["screening_gain"]))
    return table


def test_summary(alpha, min_gain, power, verdict, named=False) -> dict:
    """How candidates were judged; with `none` or `inconclusive` the gain the test could have detected, and
    wherever nothing was named the `power` block (`_verdict.Power`)."""
    detectable = None
    if verdict in ("none", "inconclusive") and power.detectable_gain is not None:
        detectable = max(power.detectable_gain, min_gain)
    return {
        "paired": "log ratio of each held-out window's mean squared error, nominal (or current) against extended; "
        "HAC variance within each run (flat-top lag window over the windows' correlation length, "
        "corrected for centring on the run's mean), Student t with its equivalent degrees of freedom",
        "multiple_comparisons": f"Benjamini-Hochberg over the candidates remaining in each round, false-discovery "
        f"rate {alpha:g} (family-wise {alpha:g} when no candidate has an effect)",
        "run_agreement": "a cause must improve the mean window error on more than half of the held-out runs "
        "(cross-fitted training runs included), and must not raise the held-out runs' own "
        "(the cross-fitted windows add power; the runs no fit has seen keep a veto)",
        "alpha": alpha,
        "min_gain": min_gain,
        "detectable_gain": detectable,
        **({"power": power.to_json()} if not named else {}),
    }


def per_run_table(problem, yard, nominal, judgement) -> list[dict]:
    """Position RMSE at the reference horizon on each held-out run, nominal and extended; with cross-fitting
    also on each training run, simulated by the models refitted without it (`held_out: "cross-fitted"`)."""
    n_ref, index = np.asarray([yard.n_ref]), problem.position_index
    parts = [("validation", problem.validation, problem.window_runs, nominal.errors, judgement.errors, 0)]
    if yard.cv_windows is not None:
        runs = np.asarray(yard.cv_windows.starts)[:, 0]
        parts.append(
            ("cross-fitted", problem.train, runs, nominal.cv_errors, judgement.cv_errors, len(problem.validation))
        )
    rows = []
    for kind, records, window_runs, err_nominal, err_extended, _offset in parts:
        for r, rec in enumerate(records):
            mine = window_runs == r
            nom = rmse_curve(err_nominal[mine], n_ref, index)[0]
            ext = rmse_curve(err_extended[mine], n_ref, index)[0]
            fine = np.isfinite(nom) and np.isfinite(ext) and nom > 0
            name = rec.source or (f"held-out run {r + 1}" if kind == "validation" else f"train run {r + 1}")
            rows.append(
                {
                    "run": name,
                    "held_out": kind,
                    "n_windows": int(mine.sum()),
                    "nominal_rmse": float(nom) if np.isfinite(nom) else None,
                    "extended_rmse": float(ext) if np.isfinite(ext) else None,
                    "gain": float(1 - ext / nom) if fine else None,
                }
            )
    return rows


def unexplained_note(s: Structure) -> str:
    return (
        "Structure is left that the candidates do not explain: the residual probe explains "
        f"{s.r2:.0%} of the held-out one-step residuals (p = {s.p_value:.2g}), mostly through "
        + ", ".join(f"{n} ({w:.0%})" for n, w in s.top_features[:3])
        + f"; largest in {', '.join(f'{k} ({v:.0%})' for k, v in s.by_state.items())}; worst around t = "
        + ", ".join(f"{t:.1f} s" for t in s.worst_times)
        + " of the held-out record."
    )
