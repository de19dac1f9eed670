"""Levenberg-Marquardt that forms the Jacobian only where it takes a step, against optimistix's, which
forms it at every trial point: `dynax.identify` on real DFKI runs with default settings, whose
output-error refinement is the fit in question.

Both run in one process on the same data, each once cold (compilation included) and then warm
`--repeats` times; the ratio is optimistix's time over dynax's. The two solvers take the same
iterates (same search, same descent, same Jacobian at the points taken), so the parameters must
agree to rounding: checked and printed. optimistix's order is selected by patching the solver that
`fit_simulation_error` builds (`levenberg_marquardt(..., jacobian="every_step")`), nothing else.

    python benchmarks/levenberg_marquardt.py [--train 00,01,02] [--held-out 03] [--repeats 1] [--json FILE]
    python benchmarks/levenberg_marquardt.py --solvers every_step   # (or accepted) alone: its own cold time

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

import numpy as np  # noqa: E402

import dynax  # noqa: E402
from _device import describe, device_info  # noqa: E402
from dynax._fit import levenberg_marquardt  # noqa: E402
from dynax._identify import _simulation_fit  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[1]
DFKI = REPO.parent / "shared" / "datasets" / "dfki_double_pendulum" / "sys_id"
MAPPING = {"t": "time", "q1": "pos_meas1", "q2": "pos_meas2", "dq1": "vel_meas1", "dq2": "vel_meas2",
           "tau1": "tau_meas1", "tau2": "tau_meas2"}


def load(run: str) -> dynax.Trajectory:
    raw = dynax.load_trajectory(DFKI / f"trajectory_{run}.csv", "double_pendulum", mapping=MAPPING)
    return dynax.resample(raw, raw.dt)


def timed_identify(train, held, jacobian: str) -> tuple[float, float, list[int], dict[str, float]]:
    """One `identify` call with the refinement's solver forming its Jacobian as `jacobian` says:
    (total seconds, seconds in the refinement's fits, their step counts, the parameters)."""
    fits, steps = [], []
    solve = _simulation_fit._solve

    def solver(**kwargs):
        return levenberg_marquardt(**{**kwargs, "jacobian": jacobian})

    def timed_solve(*args, **kwargs):
        start = time.perf_counter()
        out = solve(*args, **kwargs)
        jax.block_until_ready(out[1])
        fits.append(time.perf_counter() - start)
        steps.append(int(out[0].steps))
        return out

    _simulation_fit.levenberg_marquardt, _simulation_fit._solve = solver, timed_solve
    try:
        start = time.perf_counter()
        result = dynax.identify(dynax.DoublePendulum(), train, dynax.Dynamic(), friction="coulomb", validation=[held])
        total = time.perf_counter() - start
    finally:
        _simulation_fit.levenberg_marquardt, _simulation_fit._solve = levenberg_marquardt, solve
    return total, sum(fits), steps, {k: float(v) for k, v in result.parameters.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--train", default="00,01,02")
    parser.add_argument("--held-out", default="03")
    parser.add_argument("--repeats", type=int, default=1, help="warm calls of each (default 1)")
    parser.add_argument("--solvers", default="every_step,accepted",
                        help="which to run (one alone in its own process gives its cold time without the other's "
                             "compilation of what both share)")
    parser.add_argument("--json", type=pathlib.Path, default=None)
    args = parser.parse_args(argv)
    print(describe(device_info()), flush=True)
    train = [load(r) for r in args.train.split(",")]
    held = load(args.held_out)
    out = {"device": device_info(), "machine": platform.processor() or platform.machine(),
           "train": args.train.split(","), "held_out": args.held_out, "solvers": {}}
    for jacobian in args.solvers.split(","):
        cold = timed_identify(train, held, jacobian)
        warm = [timed_identify(train, held, jacobian) for _ in range(args.repeats)]
        best = min(warm, key=lambda w: w[0])
        out["solvers"][jacobian] = {"cold_s": cold[0], "cold_fits_s": cold[1], "warm_s": best[0],
                                    "warm_fits_s": best[1], "fit_steps": best[2], "parameters": best[3]}
        print(f"jacobian={jacobian:10s} identify cold {cold[0]:6.1f} s (fits {cold[1]:5.1f}), warm {best[0]:6.1f} s "
              f"(fits {best[1]:5.1f}), fit steps {best[2]}", flush=True)
    if len(out["solvers"]) < 2:
        return
    eager, lazy = out["solvers"]["every_step"], out["solvers"]["accepted"]
    names = list(lazy["parameters"])
    difference = max(abs(lazy["parameters"][k] / eager["parameters"][k] - 1) for k in names)
    out["parameters_max_relative_difference"] = difference
    out["ratio_warm_identify"] = eager["warm_s"] / lazy["warm_s"]
    out["ratio_warm_fits"] = eager["warm_fits_s"] / lazy["warm_fits_s"]
    out["ratio_cold_identify"] = eager["cold_s"] / lazy["cold_s"]
    print(f"optimistix / dynax: identify warm {out['ratio_warm_identify']:.2f}x, refinement fits warm "
          f"{out['ratio_warm_fits']:.2f}x, identify cold {out['ratio_cold_identify']:.2f}x; parameters agree to "
          f"{difference:.1e} (relative)")
    if not np.isfinite(difference) or difference > 1e-6:
        raise SystemExit(f"the two solvers disagree: parameters differ by {difference:.2e} (relative)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
