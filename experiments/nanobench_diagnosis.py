"""Diagnosis of the real NanoBench flights: what the rigid-body model gets wrong, the cause, the held-out gain.

Fits the quadrotor's rigid-body nominal model (one-step least squares, battery-scaled motor features)
on the circle, figure-eight, helix, linear-ramp and lissajous flights, and diagnoses it against the
star, trefoil and oval flights (`../shared/datasets/nanobench`), as `dynax diagnose quadrotor` does:
held-out simulation error against horizon, screening of the multirotor causes (rotor drag, body
bias, motor lag and gain per motor), the candidates' simulation-error fits, and the paired held-out
test, and the nominal and extended models' held-out scores per group (position, velocity, attitude, body
rate) at h = 1, 10, 50 steps beside the constant-velocity baseline (the report's `flight_error`).

`--nominal lagged` diagnoses instead the rigid body fitted by the lagged criterion at the reference horizon,
trusted (`Known()`): the map a 0.5 s judgement calls for, where the one-step map of a closed-loop flight predicts
the rates 0.5 s ahead worse than holding them.

Run: `python experiments/nanobench_diagnosis.py [--out DIR] [--max-terms N] [--min-samples N]`
(default DIR `experiments/results/nanobench_diagnosis`). Writes `DIR/diagnosis.json` (findings with
held-out gain and p-value, the per-group table), `DIR/diagnosis.md`, the diagnosis report
(`DIR/report/report.json`, `report.md`, figures) and `DIR/groups.png` (MAE per group against horizon).
"""

import argparse
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import dynax
from dynax.internal import write_json, write_report

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_heldout import flights, TEST, TRAIN  # noqa: E402


def middle(run, seconds):
    """`seconds` of `run` from its middle (the whole run when shorter)."""
    n = int(round(seconds / run.dt)) + 1
    if len(run) <= n:
        return run
    a = (len(run) - n) // 2
    return dynax.Trajectory(
        run.ts[a : a + n],
        run.xs[a : a + n],
        run.us[a : a + n],
        run.state_names,
        run.input_names,
        run.system,
        run.source,
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="experiments/results/nanobench_diagnosis")
    parser.add_argument("--max-terms", type=int, default=3)
    parser.add_argument(
        "--min-samples",
        type=int,
        default=1000,
        help="leave out usable runs shorter than this (the ramp's short hops between ground segments)",
    )
    parser.add_argument("--cross-fit", action="store_true", help="also hold out each training run in turn (slow)")
    parser.add_argument(
        "--slice-s",
        type=float,
        default=10.0,
        help="diagnose on this many seconds from the middle of each run (default 10; 0: whole runs); "
        "the diagnosis scores the same held-out stretches per group",
    )
    parser.add_argument("--no-discovery", action="store_true", help="no search beyond the vocabulary")
    parser.add_argument("--shortlist", type=int, default=8, help="candidates refitted by simulation error per round")
    parser.add_argument(
        "--reference-horizon",
        type=float,
        default=0.5,
        help="judge the gain at this horizon [s] (default 0.5, h = 50: where flight models are scored; "
        "0: the predictability horizon)",
    )
    parser.add_argument(
        "--refit",
        choices=("none", "thrust", "moments"),
        default="none",
        help="nominal weights refitted by simulation error with each candidate: none (the one-step map held), "
        "the thrust map (dynax.internal.thrust_parameters) or the roll, pitch and yaw motor weights",
    )
    parser.add_argument(
        "--nominal",
        choices=("one-step", "lagged"),
        default="one-step",
        help="the rigid body diagnosed: 'one-step' (Refit() mode: the one-step fit, its weights held or refitted as "
        "--refit says) or 'lagged' (fitted by the lagged criterion at the reference horizon on the same "
        "training stretches, then trusted: Known() mode)",
    )
    parser.add_argument(
        "--candidates",
        default="",
        help="comma-separated cause@where of the vocabulary to test, e.g. 'motor_delay@motors,rotor_drag@q' "
        "(default the whole quadrotor vocabulary)",
    )
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    (out / "report").mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()

    train, _ = flights(TRAIN)
    test, _ = flights(TEST)
    train = [r for r in train if len(r) >= args.min_samples]
    test = [r for r in test if len(r) >= args.min_samples]
    print(
        f"train: {len(train)} runs, {sum(len(r) for r in train)} samples; "
        f"test: {len(test)} runs, {sum(len(r) for r in test)} samples",
        flush=True,
    )
    quad = dynax.Quadrotor.from_flights("nominal", train)
    say = lambda line: print(f"[{time.perf_counter() - start:7.1f} s] {line}", flush=True)  # noqa: E731
    cut = lambda runs: [middle(r, args.slice_s) for r in runs] if args.slice_s > 0 else runs  # noqa: E731
    diag_train, diag_test = cut(train), cut(test)
    print(
        f"diagnosing on {sum(len(r) for r in diag_train)} training and {sum(len(r) for r in diag_test)} held-out "
        "samples",
        flush=True,
    )
    from dynax.internal import body_frame_system, moment_parameters, quadrotor_candidates, thrust_parameters

    candidates = quadrotor_candidates(body_frame_system(quad, train[0].input_names))
    if args.candidates:
        wanted = {c.strip() for c in args.candidates.split(",")}
        body = body_frame_system(quad, train[0].input_names)
        candidates = tuple(t for t in candidates if t.label(body) in wanted)
        print(f"candidates: {[t.label(body) for t in candidates]}", flush=True)
    refit = {
        "none": None,
        "thrust": thrust_parameters(quad),
        "moments": moment_parameters(quad),
    }[args.refit]
    mode = dynax.Refit(parameters=refit)
    if args.nominal == "lagged":
        if refit is not None:
            parser.error("--nominal lagged trusts the fitted weights: it takes no --refit")
        lagged = dynax.Lagged(horizon=args.reference_horizon or 0.5, stride=20, max_iterations=10)
        quad = dynax.fit_quadrotor(quad, diag_train, lagged).model
        say(f"nominal fitted by the lagged criterion (H = {lagged.horizon:g} s)")
        mode = dynax.Known()
    report = dynax.diagnose(
        quad,
        diag_train,
        diag_test,
        mode=mode,
        candidates=candidates,
        selection=dynax.Selection(
            max_terms=args.max_terms,
            cross_fit=args.cross_fit,
            discovery=not args.no_discovery,
            shortlist=args.shortlist,
        ),
        horizons=dynax.Horizons(reference_s=args.reference_horizon or None),
        progress=say,
    )
    from dynax.internal import body_frame_records

    errors, note = report.flight_error.models, report.flight_error.note  # scored by the diagnosis
    j = report.to_json()
    steps, dt = j["flight_error"]["steps"], j["flight_error"]["dt_s"]
    write_report(report, out / "report", body_frame_records(quad, diag_test), write_json=write_json)
    table = {
        name: {
            "mae": e.table("mae"),
            "rmse": e.table("rmse"),
            "cumulative_mae": {g: float(v) for g, v in zip(e.state_names, e.cumulative_mae)},
        }
        for name, e in errors.items()
    }
    result = {
        "train": sorted({r.source for r in train}),
        "test": sorted({r.source for r in test}),
        "slice_s": args.slice_s,
        "refit": args.refit,
        "nominal": args.nominal,
        "vocabulary": args.candidates or "all",
        "diagnosed_samples": {"train": sum(len(r) for r in diag_train), "test": sum(len(r) for r in diag_test)},
        "verdict": j["verdict"],
        "reference_horizon_s": j["reference_horizon_s"],
        "gain": j["gain"],
        "findings": [
            {
                k: f.get(k)
                for k in ("cause", "where", "parameter", "coefficient", "std_error", "gain", "p_value", "confidence")
            }
            for f in j["findings"]
        ],
        "test_summary": j.get("test"),
        "nominal_sim_error": j["nominal"]["sim_error"],
        "extended_sim_error": j["extended"]["sim_error"],
        "extended_terms": j["extended"]["terms"],
        "not_identifiable": [f"{c['cause']}@{c['where']}" for c in j["not_identifiable"]],
        "candidates": j["candidates"],
        "steps": steps,
        "groups": table,
        "short_horizon_note": note,
        "seconds": time.perf_counter() - start,
    }
    write_json(out / "diagnosis.json", result)
    lines = [
        f"Verdict: {j['verdict']}; gain at {j['reference_horizon_s']:g} s: {j['gain']:.1%}",
        "",
        "| cause | where | coefficient | gain | p |",
        "|---|---|---|---|---|",
    ]
    for f in result["findings"]:
        lines.append(
            f"| {f['cause']} | {f['where']} | {f['coefficient']:.4g} ± {f['std_error']:.2g} | "
            f"{f['gain']:.1%} | {f['p_value']:.2g} |"
        )
    lines += [
        "",
        "MAE at h = " + " / ".join(map(str, steps)) + f" steps (cumulative MAE over 1..{max(steps)}):",
        "",
        "| model | position [m] | velocity [m/s] | attitude [rad] | body rate [rad/s] |",
        "|---|---|---|---|---|",
    ]
    for name, t in table.items():
        cells = [
            " / ".join(f"{v:.4f}" for v in t["mae"][g]) + f" ({t['cumulative_mae'][g]:.4f})"
            for g in ("position", "velocity", "attitude", "body_rate")
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    if note is not None:
        lines += ["", note]
    (out / "diagnosis.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines), flush=True)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(14, 3.2))
    for ax, g in zip(axes, ("position", "velocity", "attitude", "body_rate")):
        for name, t in table.items():
            ax.plot(np.asarray(steps) * dt, t["mae"][g], "o-", label=name)
        ax.set_title(g)
        ax.set_xlabel("horizon [s]")
        ax.set_yscale("log")
    axes[0].set_ylabel("held-out MAE")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "groups.png", dpi=120)
    print(f"wrote {out} in {time.perf_counter() - start:.0f} s", flush=True)


if __name__ == "__main__":
    main()
