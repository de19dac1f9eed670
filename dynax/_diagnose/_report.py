"""Writing a diagnosis `Report`: `report.json` (the contract), `report.md` (for a person) and figures."""

import pathlib

import numpy as np

from .._data._derivatives import resample
from ._discovery import discovery_markdown
from ._figures import plot_error_vs_horizon, plot_measured_vs_simulated, plot_residuals
from ._residuals import acceleration_residuals, velocity_indices
from ._verdict import Verdict


def _fmt(x, digits=4):
    return "n/a" if x is None else f"{x:.{digits}g}"


def report_markdown(report) -> str:
    """The report as Markdown, written for a person."""
    j = report.to_json()
    lines = [f"# Discrepancy diagnosis: {j['system']}", "", f"Verdict: {Verdict(j['verdict']).text}", ""]
    if j["findings"]:
        lines += [
            f"Held-out simulation error at {j['reference_horizon_s']:g} s is reduced by **{j['gain']:.0%}** by the "
            f"extended model ({', '.join(j['extended']['terms'])}).",
            "",
        ]
    lines += _data_markdown(j) + _error_markdown(j) + _flight_markdown(j) + _validation_markdown(j)
    lines += [
        "![measured against simulated](measured_vs_simulated.png)",
        "",
        "![error against horizon](sim_error.png)",
        "",
        "The nominal model's one-step residuals over time, against velocity (friction shows here), "
        "their autocorrelation and spectrum (white noise is flat):",
        "",
        "![residuals](residuals.png)",
        "",
    ]
    lines += (
        _causes_markdown(j) + discovery_markdown(j) + _candidates_markdown(j) + _rounds_markdown(j) + _test_markdown(j)
    )
    said = set(j["notes"]) | {f"warning: {n}" for n in j["notes"]}  # the notes name what the command line noted
    warned = [w for w in j.get("warnings") or () if w["message"] not in said and f"warning: {w['message']}" not in said]
    if warned:  # what the run warned of besides (report.json's `warnings`, written by the command line)
        lines += ["## Warnings", ""] + [f"- {w['category']}: {w['message']}" for w in warned] + [""]
    if j["notes"]:
        lines += ["## Notes", ""] + [f"- {n}" for n in j["notes"]] + [""]
    lines += ["## Parameters", "", "| parameter | nominal | extended |", "|---|---|---|"]
    ext = j["extended"]["parameters"]
    for name in dict.fromkeys(list(j["nominal"]["parameters"]) + list(ext)):
        lines.append(f"| {name} | {_fmt(j['nominal']['parameters'].get(name))} | {_fmt(ext.get(name))} |")
    return "\n".join(lines) + "\n"


def _data_markdown(j: dict) -> list[str]:
    return [
        "## Data",
        "",
        f"- training: {j['data']['train']} ({j['data']['n_train']} samples)",
        f"- held out: {j['data']['validation']} ({j['data']['n_validation']} samples)",
        f"- mode: `{j['mode']}` ("
        + (
            "the nominal parameters were refitted on the training data"
            if j["mode"] == "refit"
            else "the nominal parameters were trusted and kept"
        )
        + ")",
        "",
    ]


def _error_markdown(j: dict) -> list[str]:
    """What the nominal simulation gets wrong: error against horizon, per run, and the residual probe."""
    ref = j["reference_horizon_s"]
    h = j["nominal"]["sim_error"]["horizons_s"]
    lines = [
        "## What the nominal simulation gets wrong",
        "",
        "Open-loop simulation from measured states, position RMSE on the held-out data:",
        "",
        "| horizon [s] | " + " | ".join(f"{x:g}" for x in h) + " |",
        "|---|" + "---|" * len(h),
        "| nominal | " + " | ".join(_fmt(x) for x in j["nominal"]["sim_error"]["rmse"]) + " |",
    ]
    if j["findings"]:
        lines.append("| extended | " + " | ".join(_fmt(x) for x in j["extended"]["sim_error"]["rmse"]) + " |")
    if j.get("runs"):
        lines += [
            "",
            f"Per held-out run, position RMSE at the reference horizon {ref:g} s (cross-fitted: a training "
            "run simulated by the models refitted on the other training runs):",
            "",
            "| run | held out | windows | nominal | extended | gain |",
            "|---|---|---|---|---|---|",
        ]
        for r in j["runs"]:
            gain = "n/a" if r["gain"] is None else f"{r['gain']:.0%}"
            lines.append(
                f"| {r['run']} | {r.get('held_out', 'validation')} | {r['n_windows']} | {_fmt(r['nominal_rmse'])} | "
                f"{_fmt(r['extended_rmse'])} | {gain} |"
            )
    if j.get("horizon"):
        lines += ["", f"Reference horizon {ref:g} s: {j['horizon']['rule']}."]
    s = j["structure"]["nominal"]
    lines += [
        "",
        f"Residual analysis of one-step accelerations (nominal model): a generic probe explains "
        f"{max(s['r2'], 0):.0%} of the held-out residual variance (p = {s['p_value']:.2g}; "
        f"{'significant' if s['significant'] else 'not significant'}). "
        "Features carrying it: "
        + ", ".join(f"{f['feature']} ({f['share']:.0%})" for f in s["top_features"][:3])
        + ". Share of residual energy by state: "
        + ", ".join(f"{k} {v:.0%}" for k, v in s["by_state"].items())
        + ". Largest residuals around t = "
        + ", ".join(f"{t:.1f} s" for t in s["worst_times_s"])
        + ".",
        "",
    ]
    return lines


def _flight_markdown(j: dict) -> list[str]:
    """A flight diagnosis' held-out MAE per group beside constant velocity (`flight_error`), where there is one."""
    from .._simulate import FLIGHT_UNITS

    if "flight_error" not in j:
        return []
    f = j["flight_error"]
    groups, steps = list(FLIGHT_UNITS), f["steps"]
    seconds = " / ".join(f"{s * f['dt_s']:.3g}" for s in steps)
    lines = [
        "## Held-out error per group",
        "",
        f"MAE of the open-loop prediction from every held-out sample at h = {' / '.join(map(str, steps))} steps "
        f"({seconds} s), the cumulative MAE over 1..{max(steps)} in brackets:",
        "",
        "| model | " + " | ".join(f"{g} [{FLIGHT_UNITS[g]}]" for g in groups) + " |",
        "|---|" + "---|" * len(groups),
    ]
    for name, m in f["models"].items():
        cells = [" / ".join(f"{v:.4g}" for v in m["mae"][g]) + f" ({m['cumulative_mae'][g]:.4g})" for g in groups]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    if f["note"]:
        lines += ["", "One step ahead the extended model predicts some group worse than the nominal: see the notes."]
    return lines + [""]


def _causes_markdown(j: dict) -> list[str]:
    lines = ["## Causes", ""]
    named = [f for f in j["findings"] if f["cause"] != "discovered"]
    if not named:
        return lines + ["No candidate improved the held-out simulation significantly.", ""]
    lines += [
        "| cause | where | coefficient | std. error | gain | p | told apart from look-alikes |",
        "|---|---|---|---|---|---|---|",
    ]
    for f in named:
        alts = (
            "; ".join(
                f"{a['cause']}@{a.get('where', f['where'])} (gain {a['gain']:.0%}, p = {a['p_value']:.2g}, "
                f"the finding's error {a['gain_over']:.1%} lower"
                + (
                    "; one model with it in this mode"
                    if a.get("equivalent")
                    else "; not told apart: one of the two is too short for the rollouts' step to simulate"
                    if not a.get("resolved", True)
                    else ""
                    if a["told_apart"]
                    else "; not told apart"
                )
                + ")"
                for a in f["look_alikes"]
            )
            or "none in the library"
        )
        components = "".join(f"; {n} = {v:.4g}" for n, v in f.get("components", {}).items())
        lines.append(
            f"| `{f['cause']}` | `{f['where']}` | {f['parameter']} = {f['coefficient']:.4g}{components} | "
            f"{f['std_error']:.2g} | "
            f"{f['gain']:.0%} | {f['p_value']:.2g}{_named_for(f)} | {f['confidence']}: {alts} |"
        )
    return lines + [
        "",
        "Standard errors come from the Gauss-Newton covariance and assume white residuals; read them as lower bounds.",
        "",
    ]


def _candidates_markdown(j: dict) -> list[str]:
    lines = []
    if j["candidates"]:
        lines += [
            "Every candidate in the first round (held-out improvement of the window error over the nominal model):",
            "",
            "| candidate | gain (screening) | gain (joint refit) | p |",
            "|---|---|---|---|",
        ]
        for c in j["candidates"]:
            refit = f"{c['gain']:+.0%} | {c['p_value']:.2g}" if "gain" in c else "not refitted | "
            lines.append(f"| `{c['cause']}@{c['where']}` | {c['screening_gain']:+.0%} | {refit} |")
        lines.append("")
    if j["not_identifiable"]:
        lines += ["## Not identifiable in this mode", ""]
        lines += [f"- `{c['cause']}@{c['where']}`: {c['reason']}." for c in j["not_identifiable"]]
        lines.append("")
    if j.get("not_proposed"):
        lines += ["## Not proposed on these records", ""]
        lines += [f"- `{c['cause']}@{c['where']}`: {c['reason']}." for c in j["not_proposed"]]
        lines.append("")
    return lines


def _rounds_markdown(j: dict) -> list[str]:
    """Each selection round: what was refitted, what passed, and which rule stopped the others."""
    if not j.get("rounds"):
        return []
    lines = [
        "## Selection rounds",
        "",
        "Each round refits the shortlisted candidates jointly with the current model and tests them on held-out "
        "windows. gain: the held-out runs' mean window error; pooled: "
        + (
            "with the cross-fitted runs' windows"
            if j.get("test", {}).get("cross_fitting")
            else "the same windows (not cross-fitted: the test pools nothing more)"
        )
        + f"; at {j['reference_horizon_s']:g} s: the position RMSE at the reference horizon (the findings' gain).",
        "",
    ]
    for r in j["rounds"]:
        model = " + ".join(f"`{m}`" for m in r["model"]) or "the nominal model"
        lines += [
            f"**Round {r['round']}** (from {model}; {r['screened']} screened, {r['refitted']} refitted): "
            f"{r['outcome']}.",
            "",
            "| candidate | coefficient | gain | pooled | at ref. | p | runs | outcome |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for c in r["candidates"]:
            at_ref = "n/a" if c["sim_error_gain"] is None else f"{c['sim_error_gain']:+.0%}"
            outcome = c["outcome"] if not c["stopped_by"] else "stopped by " + "; ".join(c["stopped_by"])
            lines.append(
                f"| `{c['cause']}@{c['where']}` | {c['parameter']} = {c['coefficient']:.4g} | {c['gain']:+.0%} | "
                f"{c['gain_pooled']:+.0%} | {at_ref} | {c['p_value']:.2g} | {c['runs_helped']} | {outcome} |"
            )
        lines.append("")
    return lines


def _test_markdown(j: dict) -> list[str]:
    if not j.get("test"):
        return []
    t = j["test"]
    lines = [
        "## The test",
        "",
        f"- paired: {t['paired']}",
        f"- multiple comparisons: {t['multiple_comparisons']}",
        f"- across runs: {t['run_agreement']}",
        f"- smallest gain that counts: {t['min_gain']:.0%}",
    ]
    if t.get("cross_fitting"):
        lines.append(f"- cross-fitting: {t['cross_fitting']}")
    if t["detectable_gain"] is not None:
        runs = "held-out and cross-fitted runs" if t.get("cross_fitting") else "held-out runs"
        variation = (t.get("power") or {}).get("variation")
        lines.append(
            f"- with these {runs} it would have detected a gain of about {t['detectable_gain']:.0%} "
            "in mean squared window error, like the candidates' gains (power 80 %, at the best candidate's level"
            + (f", window-to-window variation like {variation}" if variation else "")
            + ")"
        )
    power = t.get("power")
    if power and power["best_candidate"]:
        b = power["best_candidate"]
        lines.append(
            f"- best candidate: {b['cause']}@{b['where']}, held-out gain {b['gain']:.0%}"
            + (f" ({b['gain_typical']:.0%} on the typical window)" if b.get("gain_typical") is not None else "")
            + f", p = {b['p_value']:.2g}"
        )
    if power and power["needed_s"] is not None and power["needed_s"] > power["tested_s"]:
        lines.append(
            f"- a {power['min_practical_gain']:.0%} gain (same unit) would be detected with about "
            f"{power['needed_s']:.3g} s of such windows (now {power['tested_s']:.3g} s)"
        )
    return lines + [""]


def _validation_markdown(j: dict) -> list[str]:
    """The validation block (fit % and residual tests) of each model as a table."""
    models = [
        (name, j[name]["validation"])
        for name in ("nominal", "extended")
        if "validation" in j[name] and (name == "nominal" or j["findings"])
    ]
    if not models:
        return []
    states = list(models[0][1]["fit_percent"])
    lines = [
        f"Fit % of the {models[0][1]['horizon_s']:g} s-ahead open-loop prediction from every held-out window "
        "(MATLAB `compare`), and tests of the one-step residuals (MATLAB `resid`, confidence 99 %: "
        "Ljung-Box whiteness, cross-correlation with the inputs):",
        "",
        "| model | " + " | ".join(f"fit {s}" for s in states) + " | white | independent of inputs |",
        "|---|" + "---|" * (len(states) + 2),
    ]
    for name, v in models:
        tests = v["residual_tests"]
        white = (
            ", ".join(
                f"{'yes' if t['white'] else 'no'} (min p {min(c['p_value'] for c in t['whiteness'].values()):.2g})"
                for t in tests
            )
            or "n/a"
        )
        independent = (
            ", ".join(
                f"{'yes' if t['independent'] else 'no'} (min p "
                f"{min(u['p_value'] for c in t['cross_correlation'].values() for u in c.values()):.2g})"
                for t in tests
            )
            or "n/a"
        )
        fits = " | ".join("n/a" if v["fit_percent"][s] is None else f"{v['fit_percent'][s]:.1f} %" for s in states)
        lines.append(f"| {name} | {fits} | {white} | {independent} |")
    return lines + [""]


def write_report(report, out_dir, validation, *, write_json) -> None:
    """Write `report.json`, `report.md` and the figures into `out_dir` (which must exist).

    **Arguments:** `report`; `out_dir`; `validation` the held-out record(s) the figures show (a
    `Trajectory` or a list: one `measured_vs_simulated.png` for the first run and
    `measured_vs_simulated_run2.png`, ... for the others, each titled with its run; the residual
    figure shows the first run); `write_json` the atomic JSON writer.
    """
    out = pathlib.Path(out_dir)
    runs = list(validation) if isinstance(validation, (list, tuple)) else [validation]
    # `diagnose` resampled irregular records to one grid (`report.data.dt`); the figures are drawn on that grid too.
    runs = [run if run.is_uniform else resample(run, report.data.dt) for run in runs]
    validation = runs[0]
    write_json(out / "report.json", report.to_json())
    (out / "report.md").write_text(report.to_markdown())
    models = {"nominal": report.nominal_model}
    if report.findings:
        models["extended"] = report.extended_model
    for i, run in enumerate(runs):
        name = "measured_vs_simulated.png" if i == 0 else f"measured_vs_simulated_run{i + 1}.png"
        plot_measured_vs_simulated(run, models, out / name, run_name=run.source or f"held-out run {i + 1}")
    j = report.to_json()
    curves = {"nominal": (j["nominal"]["sim_error"]["horizons_s"], j["nominal"]["sim_error"]["rmse"])}
    if report.findings:
        curves["extended"] = (j["extended"]["sim_error"]["horizons_s"], j["extended"]["sim_error"]["rmse"])
    unit = "m" if report.system in ("linear_axis", "helicopter") else "rad"
    plot_error_vs_horizon(
        {k: (h, [np.nan if r is None else r for r in rs]) for k, (h, rs) in curves.items()},
        out / "sim_error.png",
        unit=unit,
    )
    residuals, xs, _, keep = acceleration_residuals(report.nominal_model, validation)
    nominal = report.nominal_model
    idx = velocity_indices(nominal)
    names = [nominal.state_names[i] for i in idx]
    ts = np.asarray(validation.ts)[keep]
    plot_residuals(
        ts,
        residuals,
        names,
        out / "residuals.png",
        features={n: xs[:, i] for n, i in zip(names, idx)},
        run_name=validation.source or "held-out run 1",
    )


def _named_for(finding) -> str:
    """The look-alike whose test established a finding named in its place (closed testing), for the p column."""
    other = finding.get("named_for")
    if other is None:
        return ""
    return f" (effect established by `{other['cause']}@{other['where']}`, p = {other['p_value']:.2g})"
