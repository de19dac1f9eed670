"""Time to fit a quadrotor model to 10 minutes of 100 Hz flight (60 000 samples).

The usable runs of the 16 NanoBench flights (ground segments and glitches left out), repeated from
the first until they hold 60 000 samples, are fitted with the acceleration model (battery-scaled
motor features, 55 weights) by each criterion as `dynax fit quadrotor` runs it: one-step least
squares, and the lagged criterion (H = 0.5 s, EM-free, from the one-step fit, every start up to the
CLI's 600 windows: `--stride auto`). Each fit is timed cold (compilation included, as a first
command-line run pays) and warm (compiled once already). The lagged fit runs after the one-step
one, so its cold time excludes the one-step compilation it starts from: a lagged fit from a cold
start costs about both cold times. The backprop refinement (30 L-BFGS steps on the same lagged
loss, warm-started from the lagged fit, as `experiments/nanobench_heldout.py` makes its best
model) is timed on its own: the best model costs the lagged fit plus it. Loading the files is
timed apart.

Run: `python benchmarks/quadrotor_fit.py [--out DIR] [--samples N]` (default DIR
`benchmarks/results`). Writes `DIR/quadrotor_fit.json`. Timings on a shared CPU are indicative; run
it on an idle 2-core machine for the figure of record (`taskset -c 0,1`).
"""

import argparse
import os
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

import dynax
from dynax.internal import auto_stride, write_json

DATA = pathlib.Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "nanobench"
NANOBENCH_MAP = {
    "x": "px",
    "y": "py",
    "z": "pz",
    "p": "wx_vicon",
    "q": "wy_vicon",
    "r": "wz_vicon",
    "m1": "motor_motor_m1",
    "m2": "motor_motor_m2",
    "m3": "motor_motor_m3",
    "m4": "motor_motor_m4",
    "vbat": "pwr_pm_vbat",
}
HORIZON_S = 0.5
AUTO_WINDOWS = 600  # the CLI's --stride auto
BACKPROP_STEPS = 30  # as experiments/nanobench_heldout.py refines its lagged fit


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--samples", type=int, default=60_000)
    args = parser.parse_args()
    start = time.perf_counter()
    runs = []
    for path in sorted(DATA.glob("*.csv.gz")):
        trajectory, notes = dynax.load_flight(path, mapping=NANOBENCH_MAP)
        runs += dynax.usable_segments(trajectory, notes, 52)
    load_s = time.perf_counter() - start
    flights, total, i = [], 0, 0
    while total < args.samples:
        run = runs[i % len(runs)]
        take = min(len(run), args.samples - total)
        if take >= 52:
            flights.append(run.slice(0, take))
        total += take
        i += 1
    print(f"{len(flights)} runs, {sum(len(f) for f in flights)} samples; loading 16 files {load_s:.1f} s", flush=True)
    start_model = dynax.Quadrotor.from_flights("acceleration", flights)
    stride = auto_stride(sum(len(f) for f in flights), int(HORIZON_S / 0.01), AUTO_WINDOWS)
    criteria = {
        "one-step": dynax.OneStep(),
        "lagged": dynax.Lagged(horizon=HORIZON_S, stride=stride),
        "backprop refinement": dynax.Backprop(horizon=HORIZON_S, stride=stride, max_steps=BACKPROP_STEPS),
    }
    result = {
        "samples": sum(len(f) for f in flights),
        "runs": len(flights),
        "load_seconds": load_s,
        "cpu_count": os.cpu_count(),
        "affinity": len(os.sched_getaffinity(0)),
        "stride": stride,
        "fits": {},
    }
    lagged_model = start_model
    for name, criterion in criteria.items():
        times = []
        for _ in range(2):
            t0 = time.perf_counter()
            if isinstance(criterion, dynax.Backprop):  # refines the lagged fit, as the held-out study does
                solution = dynax.fit_quadrotor(lagged_model, flights, criterion, progress=False, warm_start=True)
            else:
                solution = dynax.fit_quadrotor(start_model, flights, criterion, progress=False)
            jax.block_until_ready(solution.value)
            times.append(time.perf_counter() - t0)
        if name == "lagged":
            lagged_model = solution.model
        result["fits"][name] = {
            "cold_seconds": times[0],
            "warm_seconds": times[1],
            "loss": float(solution.loss),
            "steps": int(solution.steps),
        }
        print(f"{name:10s} cold {times[0]:6.1f} s  warm {times[1]:6.1f} s  loss {float(solution.loss):.5g}", flush=True)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "quadrotor_fit.json", result)
    print(f"wrote {out / 'quadrotor_fit.json'}")


if __name__ == "__main__":
    main()
