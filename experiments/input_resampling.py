"""How `dynax.resample` should put a record's inputs on the uniform grid: the hold it uses, or two alternatives.

`resample` lays a uniform grid from a record's first stamp, interpolates the states linearly and holds each input
from the last stamp at or before each grid point (`hold`). With stamps a little either side of the grid, about
half the inputs then come from a whole interval earlier. Alternatives, with the same grid and states:

- `average`: the time average of the recorded zero-order hold over each new interval `[g_k, g_k + dt)` (gives
  `u_k` back where the grid meets the stamps, and keeps the input's integral where it does not);
- `linear`: the inputs interpolated linearly (right for measured torques, which are continuous signals).

Records are resampled here by `dynax.resample(..., inputs=...)`, before `identify` (which then finds them uniform
and resamples nothing); `--inside` gives `identify` the raw record and sets its own resampling's rule with
`dynax.internal.input_resampling`.

    python experiments/input_resampling.py --synthetic [--rates 100,1000] [--seeds 0,1] [--jitters 0.1,0.3]
    python experiments/input_resampling.py --synthetic --inside --out FILE.json
    python experiments/input_resampling.py --dfki

`--synthetic`: `experiments/time_jitter.py`'s acrobot records (DOP853 at rtol 1e-10, outside dynax's model
code, 8 s, no noise) sampled unevenly at `k h + e_k`, `e_k` uniform in +-J, and stamped truly; each fit by
`identify(Acrobot(), [record], refine=True)`; prints each parameter's percent error against the truth for
the least-squares stage and the refined fit. `--dfki`: each DFKI `sys_id` run alone through the
least-squares stage with `dfki_default_identification.py`'s settings (`Dynamic()`, `friction="coulomb"`,
`refine=False`): its relative equation (torque) error and parameters.
"""

import argparse
import contextlib
import json
import pathlib
import sys
import warnings

REPO = pathlib.Path(__file__).resolve().parents[1]
HOWS = ("hold", "average", "linear")


def synthetic(args):
    import dynax
    from dynax.internal import input_resampling

    sys.path.insert(0, str(REPO / "experiments"))
    from time_jitter import jittered_record, NAMES, TRUTH

    rows = []
    for rate in map(float, args.rates.split(",")):
        for seed in map(int, args.seeds.split(",")):
            for jitter_ms in [0.0, *map(float, args.jitters.split(","))]:
                ts, xs, tau = jittered_record(rate, seed, jitter_ms * 1e-3, "both")
                record = dynax.Trajectory(
                    ts, xs, tau[:, None], ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot", "run.csv"
                )
                for how in HOWS if jitter_ms > 0 else ("none",):
                    if args.inside:  # the raw record, resampled by identify's stages
                        data, inside = record, input_resampling("hold" if how == "none" else how)
                    else:
                        data = record if how == "none" else dynax.resample(record, record.dt, inputs=how)
                        inside = contextlib.nullcontext()
                    with warnings.catch_warnings(), inside:
                        warnings.simplefilter("ignore")
                        fit = dynax.identify(dynax.Acrobot(), [data], refine=True)
                    stages = fit.to_json()["stages"]
                    out = {"rate_hz": rate, "seed": seed, "jitter_ms": jitter_ms, "inputs": how}
                    for stage in ("least_squares", "output_error"):
                        p = stages[stage]["parameters"]
                        out[stage] = [100.0 * (p[n] / t - 1.0) for n, t in zip(NAMES, TRUTH)]
                    rows.append(out)
                    print(
                        f"{rate:6.0f} Hz seed {seed} J {jitter_ms:3.1f} ms {how:>7}: LS "
                        + " ".join(f"{v:+6.1f}" for v in out["least_squares"])
                        + " | refined "
                        + " ".join(f"{v:+6.1f}" for v in out["output_error"]),
                        flush=True,
                    )
                    pathlib.Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")


def dfki(args):
    import dynax

    sys.path.insert(0, str(REPO))
    from tests.conftest import DFKI_MAPPING

    folder = REPO.parent / "shared" / "datasets" / "dfki_double_pendulum" / "sys_id"
    rows = {}
    for n in args.runs.split(","):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            raw = dynax.load_trajectory(folder / f"trajectory_{n}.csv", "double_pendulum", mapping=DFKI_MAPPING)
        for how in HOWS:
            data = dynax.resample(raw, raw.dt, inputs=how)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fit = dynax.identify(dynax.DoublePendulum(), [data], dynax.Dynamic(), friction="coulomb", refine=False)
            stage = fit.to_json()["stages"]["least_squares"]
            rows.setdefault(n, {})[how] = {
                "relative_equation_error": stage["relative_equation_error"],
                "parameters": stage["parameters"],
            }
            print(
                f"run {n} {how:>7}: rel. equation error {stage['relative_equation_error']:.5f}  "
                + " ".join(f"{k}={v:.4g}" for k, v in stage["parameters"].items()),
                flush=True,
            )
            pathlib.Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--synthetic", action="store_true")
    parser.add_argument("--dfki", action="store_true")
    parser.add_argument(
        "--inside", action="store_true", help="pass the raw records and swap the resampler inside identify's stages"
    )
    parser.add_argument("--seeds", default="0,1")
    parser.add_argument("--rates", default="100,1000")
    parser.add_argument("--jitters", default="0.1,0.3", help="J in ms (comma-separated)")
    parser.add_argument("--runs", default="00,01,02,03,05,12")
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    import jax

    jax.config.update("jax_enable_x64", True)
    kind = "dfki" if args.dfki else "synthetic"
    args.out = args.out or str(REPO / "experiments" / "results" / f"input_resampling_{kind}.json")
    (dfki if args.dfki else synthetic)(args)


if __name__ == "__main__":
    main()
