"""Do `identify`'s leave-one-record-out standard errors say how far the DFKI estimate moves without a run?

    python experiments/dfki_record_jackknife.py --leave all,00,01 --out A
    python experiments/dfki_record_jackknife.py --leave 02,03,05 --out B
    python experiments/dfki_record_jackknife.py --merge A B --out experiments/results/dfki_record_jackknife

`identify(DoublePendulum(), runs, Dynamic(), friction="coulomb", validation=[run 12])`, defaults
otherwise, on the five runs 00, 01, 02, 03 and 05 (`all`), and again on each four of them. Its
`record_std_errors` (the delete-one-record jackknife, linearised: one Gauss-Newton step per left-out
record, `dynax.internal.jackknife_covariance`) are set against the jackknife of the five real refits,
$\\sqrt{(G-1)/G \\sum_g (\\hat\\theta_{(g)} - \\bar\\theta)^2}$, and against `std_errors` (estimated
within the records). About 90 s per fit on the 2-core machine; run as two halves in parallel.

Writes `OUT/jackknife.json` (each fit's parameters and errors; after `--merge` also the comparison).

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

import numpy as np  # noqa: E402

import dynax  # noqa: E402
import dynax.internal  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from dfki_default_identification import load  # noqa: E402

RUNS = ("00", "01", "02", "03", "05")
VALIDATION = "12"


def fit(leave: str) -> dict:
    """`identify` with defaults on `RUNS` less `leave` (`"all"`: none left out)."""
    train = [load(r) for r in RUNS if r != leave]
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = dynax.identify(
            dynax.DoublePendulum(), train, dynax.Dynamic(), friction="coulomb", validation=[load(VALIDATION)]
        )
    return {
        "training_runs": [r for r in RUNS if r != leave],
        "seconds": time.perf_counter() - start,
        "parameters": result.parameters,
        "std_errors": result.standard_errors,
        "record_std_errors": None
        if result.record_std_errors is None
        else {n: float(v) for n, v in zip(result.names, np.asarray(result.record_std_errors))},
        "records_disagree": (result.to_json()["stages"].get("output_error") or {}).get("records_disagree"),
        "warnings": sorted({type(w.message).__name__ for w in caught}),
    }


def compare(fits: dict) -> dict:
    """Per parameter: the refits' jackknife, the linearised one and the within-record error, relative."""
    full, names = fits["all"], list(fits["all"]["parameters"])
    g = len(RUNS)
    out = {}
    for n in names:
        left = np.array([fits[r]["parameters"][n] for r in RUNS])
        refit = float(np.sqrt((g - 1) / g * np.sum((left - left.mean()) ** 2)))
        value = abs(full["parameters"][n])
        out[n] = {
            "estimate": full["parameters"][n],
            "refit_jackknife": refit,
            "linearised_jackknife": full["record_std_errors"][n],
            "within_records": full["std_errors"][n],
            "linearised_over_refit": full["record_std_errors"][n] / refit,
            "refit_jackknife_relative": refit / value,
            "within_relative": full["std_errors"][n] / value,
        }
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--leave", default="all," + ",".join(RUNS), help="fits to run: all and/or runs to leave out")
    parser.add_argument("--merge", nargs="+", type=pathlib.Path, help="merge these output folders instead of fitting")
    parser.add_argument("--out", required=True, type=pathlib.Path)
    args = parser.parse_args(argv)
    if args.merge:
        fits = {}
        for folder in args.merge:
            fits.update(json.loads((folder / "jackknife.json").read_text())["fits"])
    else:
        fits = {}
        for leave in args.leave.split(","):
            if leave != "all" and leave not in RUNS:
                parser.error(f"--leave: {leave!r} is not one of all, {', '.join(RUNS)}")
            print(f"fitting without {leave} ...", flush=True)
            fits[leave] = fit(leave)
            print(f"  {fits[leave]['seconds']:.0f} s", flush=True)
    result = {"runs": list(RUNS), "validation": VALIDATION, "fits": fits}
    if set(fits) >= {"all", *RUNS}:
        result["comparison"] = compare(fits)
        print(f"{'':8s} {'refit jackknife':>16s} {'linearised':>11s} {'within':>8s}  (relative to the estimate)")
        for n, c in result["comparison"].items():
            print(
                f"{n:8s} {100 * c['refit_jackknife_relative']:15.2f}% "
                f"{100 * c['linearised_jackknife'] / abs(c['estimate']):10.2f}% {100 * c['within_relative']:7.2f}%"
            )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "jackknife.json").write_text(json.dumps(result, indent=1))
    print(f"wrote {args.out / 'jackknife.json'}")


if __name__ == "__main__":
    main()
