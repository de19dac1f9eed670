"""What does one DFKI run alone tell `identify`, and does the answer say so?

    python experiments/dfki_single_run.py --runs 00,01,02 --out A
    python experiments/dfki_single_run.py --runs 03,05,12 --out B
    python experiments/dfki_single_run.py --merge A B --out experiments/results/dfki_single_run

A user with one recording: `identify(DoublePendulum(), run, Dynamic(), friction="coulomb")` with the
defaults (the last 20 % of the run held out for validation). Each answer is then simulated open loop
on the five other runs (`held_out_error`, 200 windows per run, q1 and q2 pooled), and set against
the lab's `model_3.0` on the same windows and against the answer's own validation on the tail of its
run. What the answer says about itself is recorded with it: `poorly_determined` (the
`PoorlyDeterminedWarning`), and the relative standard errors of theta1..theta5.

About 30 to 45 s per run on the 2-core machine; run as two halves in parallel.

Writes `OUT/single_run.json` and, after `--merge` or with all six runs, `OUT/single_run.png` (the
RMSE at 0.5 s on every other run, over the lab's; warned answers marked).

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets.
"""

import argparse
import json
import pathlib
import sys
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax import held_out_error  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from dfki_default_identification import HORIZONS, lab_model, lab_parameters, load, read_parameters, RUNS  # noqa: E402

SIZES = ("theta1", "theta2", "theta3", "theta4", "theta5")


def fit_one(run, records, lab, lab_errors) -> dict:
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = dynax.identify(
            dynax.DoublePendulum(),
            records[run],
            dynax.Dynamic(),
            friction="coulomb",
            validation=dynax.Validate(horizons_s=HORIZONS),
        )
    seconds = time.perf_counter() - start
    others = {r: list(held_out_error(result.system, [records[r]], HORIZONS).rmse) for r in RUNS if r != run}
    return {
        "fit_seconds": seconds,
        "parameters": result.parameters,
        "relative_std_errors": {n: result.standard_errors[n] / abs(result.parameters[n]) for n in SIZES},
        "poorly_determined": result.poorly_determined,
        "warnings": sorted({type(w.message).__name__ for w in caught}),
        "own_tail_rmse": list(result.validation.rmse),
        "other_runs_rmse": others,
        "lab_other_runs_rmse": {r: lab_errors[r] for r in others},
        "parameters_over_lab": {n: result.parameters[n] / lab[n] for n in SIZES},
    }


def figure(results, out):
    runs = [r for r in RUNS if r in results["runs"]]
    ratio = np.full((len(runs), len(RUNS)), np.nan)
    for i, fitted in enumerate(runs):
        entry = results["runs"][fitted]
        for j, other in enumerate(RUNS):
            if other in entry["other_runs_rmse"]:
                ratio[i, j] = entry["other_runs_rmse"][other][-1] / entry["lab_other_runs_rmse"][other][-1]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    image = ax.imshow(np.log2(ratio), cmap="RdBu_r", vmin=-3, vmax=3)
    for i in range(len(runs)):
        for j in range(len(RUNS)):
            if np.isfinite(ratio[i, j]):
                ax.text(j, i, f"{ratio[i, j]:.2g}", ha="center", va="center", fontsize=8)
    ax.set_xticks(range(len(RUNS)), [f"run {r}" for r in RUNS])
    ax.set_yticks(
        range(len(runs)),
        [f"fit on {r}" + (" (warned)" if results["runs"][r]["poorly_determined"] else "") for r in runs],
    )
    ax.set_xlabel("simulated open loop on")
    ax.set_title(f"one run alone: RMSE at {HORIZONS[-1]} s over the lab's model_3.0")
    fig.colorbar(image, ax=ax, label="log2 ratio")
    fig.tight_layout()
    fig.savefig(out / "single_run.png", dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--runs", default=",".join(RUNS), help="runs to fit alone (default all six)")
    parser.add_argument(
        "--merge",
        nargs="+",
        type=pathlib.Path,
        default=(),
        metavar="DIR",
        help="fit nothing: merge the single_run.json of earlier runs",
    )
    args = parser.parse_args(argv)
    results = {"horizons_s": list(HORIZONS), "runs": {}}
    for part in args.merge:
        results["runs"].update(json.loads((part / "single_run.json").read_text())["runs"])
    if not args.merge:
        fitted = args.runs.split(",")
        unknown = sorted(set(fitted) - set(RUNS))
        if unknown:
            parser.error(f"--runs: no DFKI run {', '.join(unknown)} (the runs are {', '.join(RUNS)})")
        records = {r: load(r) for r in RUNS}
        lab = lab_model(read_parameters("model_3.0"))
        lab_errors = {r: list(held_out_error(lab, [records[r]], HORIZONS).rmse) for r in RUNS}
        lab_values = lab_parameters(read_parameters("model_3.0"))
        for run in fitted:
            entry = fit_one(run, records, lab_values, lab_errors)
            results["runs"][run] = entry
            worst = max(
                entry["other_runs_rmse"],
                key=lambda r: entry["other_runs_rmse"][r][-1] / entry["lab_other_runs_rmse"][r][-1],
            )
            print(
                f"run {run} alone ({entry['fit_seconds']:.0f} s): warned {sorted(entry['poorly_determined'])}, "
                f"own tail at {HORIZONS[-1]} s {entry['own_tail_rmse'][-1]:.3f} rad, other runs "
                + " ".join(
                    f"{r}: {v[-1]:.3f}/{entry['lab_other_runs_rmse'][r][-1]:.3f}"
                    for r, v in entry["other_runs_rmse"].items()
                )
                + f" (dynax/lab); worst on run {worst}",
                flush=True,
            )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "single_run.json").write_text(json.dumps(results, indent=1))
    if len(results["runs"]) == len(RUNS):
        figure(results, args.out)
    print(f"wrote {args.out / 'single_run.json'}")


if __name__ == "__main__":
    main()
