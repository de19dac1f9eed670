"""The refinement's Levenberg-Marquardt against optimistix's: `dynax.identify` on real DFKI runs with
default settings, whose output-error refinement is the fit in question.

Three solvers, each given to the refinement's fits (`fit_simulation_error(..., solver=...)`, through
`dynax.internal.refinement_options(fit=...)`), nothing else changed:

- `optimistix`: optimistix's order, the Jacobian at every trial point, its damping update
  (`levenberg_marquardt(..., jacobian="every_step", damping="classical")`);
- `accepted`: the Jacobian only at the points taken (`jacobian="accepted"`): the same iterates, so
  the parameters must agree with optimistix's to rounding (checked);
- `dynax` (the default): that and Nielsen's damping update (`damping="nielsen"`): another path to
  the same minimum, so the parameters agree to the fit's tolerance (printed).

All run in one process on the same data, each once cold (compilation included) and then warm
`--repeats` times; the ratios are optimistix's time over each one's.

    python benchmarks/levenberg_marquardt.py [--train 00,01,02] [--held-out 03] [--repeats 1] [--json FILE]
    python benchmarks/levenberg_marquardt.py --solvers optimistix   # (or accepted, dynax) alone: its own cold time

The cold time of the second solver in one process leaves out what both compile (the least-squares
stage, the validation), so the cold comparison is made one solver per process.

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets.
"""

import jax

jax.config.update("jax_enable_x64", True)

import argparse  # noqa: E402
import json  # noqa: E402
import pathlib  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

from _device import describe, device_info  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax.internal import levenberg_marquardt, refinement_options  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[1]
DFKI = REPO.parent / "shared" / "datasets" / "dfki_double_pendulum" / "sys_id"
MAPPING = {
    "t": "time",
    "q1": "pos_meas1",
    "q2": "pos_meas2",
    "dq1": "vel_meas1",
    "dq2": "vel_meas2",
    "tau1": "tau_meas1",
    "tau2": "tau_meas2",
}


def load(run: str) -> dynax.Trajectory:
    raw = dynax.load_trajectory(DFKI / f"trajectory_{run}.csv", "double_pendulum", mapping=MAPPING)
    return dynax.resample(raw, raw.dt)


SOLVERS = {
    "optimistix": dict(jacobian="every_step", damping="classical"),
    "accepted": dict(jacobian="accepted", damping="classical"),
    "dynax": dict(jacobian="accepted", damping="nielsen"),
}


def timed_identify(train, held, name: str) -> tuple[float, float, list[int], dict[str, float]]:
    """One `identify` call with the refinement's solver `SOLVERS[name]`: (total seconds, seconds in
    the refinement's fits (each `fit_simulation_error` call whole: its segments, the solve, the covariance),
    their step counts, the parameters)."""
    fits, steps = [], []

    def timed_fit(system, records, method, **kwargs):
        solver = levenberg_marquardt(rtol=method.rtol, atol=method.atol, **SOLVERS[name])
        start = time.perf_counter()
        out = dynax.fit_simulation_error(system, records, method, solver=solver, **kwargs)
        jax.block_until_ready(out.value)
        fits.append(time.perf_counter() - start)
        steps.append(int(out.steps))
        return out

    with refinement_options(fit=timed_fit):
        start = time.perf_counter()
        result = dynax.identify(dynax.DoublePendulum(), train, dynax.Dynamic(), friction="coulomb", validation=[held])
        total = time.perf_counter() - start
    return total, sum(fits), steps, {k: float(v) for k, v in result.parameters.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--train", default="00,01,02")
    parser.add_argument("--held-out", default="03")
    parser.add_argument("--repeats", type=int, default=1, help="warm calls of each (default 1)")
    parser.add_argument(
        "--solvers",
        default="optimistix,accepted,dynax",
        help="which to run (one alone in its own process gives its cold time without the other's "
        "compilation of what both share)",
    )
    parser.add_argument("--json", type=pathlib.Path, default=None)
    args = parser.parse_args(argv)
    print(describe(device_info()), flush=True)
    train = [load(r) for r in args.train.split(",")]
    held = load(args.held_out)
    out = {
        "device": device_info(),
        "machine": platform.processor() or platform.machine(),
        "train": args.train.split(","),
        "held_out": args.held_out,
        "solvers": {},
    }
    for name in args.solvers.split(","):
        cold = timed_identify(train, held, name)
        warm = [timed_identify(train, held, name) for _ in range(args.repeats)]
        best = min(warm, key=lambda w: w[0])
        out["solvers"][name] = {
            **SOLVERS[name],
            "cold_s": cold[0],
            "cold_fits_s": cold[1],
            "warm_s": best[0],
            "warm_fits_s": best[1],
            "fit_steps": best[2],
            "parameters": best[3],
        }
        print(
            f"{name:10s} identify cold {cold[0]:6.1f} s (fits {cold[1]:5.1f}), warm {best[0]:6.1f} s "
            f"(fits {best[1]:5.1f}), fit steps {best[2]}",
            flush=True,
        )
    if "optimistix" not in out["solvers"]:
        return
    base = out["solvers"]["optimistix"]
    for name, entry in out["solvers"].items():
        if name == "optimistix":
            continue
        # parameters at a bound (a viscous friction at zero) agree absolutely, not relatively
        difference = max(
            abs(entry["parameters"][k] - base["parameters"][k]) / max(abs(base["parameters"][k]), 1e-6)
            for k in base["parameters"]
        )
        entry.update(
            parameters_max_relative_difference=difference,
            ratio_warm_identify=base["warm_s"] / entry["warm_s"],
            ratio_warm_fits=base["warm_fits_s"] / entry["warm_fits_s"],
            ratio_cold_identify=base["cold_s"] / entry["cold_s"],
        )
        print(
            f"optimistix / {name}: identify warm {entry['ratio_warm_identify']:.2f}x, refinement fits warm "
            f"{entry['ratio_warm_fits']:.2f}x, identify cold {entry['ratio_cold_identify']:.2f}x; parameters agree "
            f"to {difference:.1e} (relative)"
        )
        if not np.isfinite(difference) or difference > (1e-6 if name == "accepted" else 1e-3):
            raise SystemExit(f"{name} disagrees with optimistix: parameters differ by {difference:.2e} (relative)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
