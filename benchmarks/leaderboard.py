"""The acrobot leaderboard's costs in time: one robot-loop call of a saved controller, and one evaluation.

    python benchmarks/leaderboard.py [--policy P.npz] [--out FILE.json]

Timed side by side in one process:

- `call_numpy`: one call `controller(t, x)` of the loaded `RobotController` (pure numpy, float64),
  on the states of the nominal episode in order (the loop a robot runs at 500 Hz); median and
  99th percentile over 5,000 calls, after 500 warm-up calls;
- `call_jax_jit`: the same controller's JAX `step`, jitted, called eagerly once per step (what
  a robot loop would pay to call the JAX version directly), for the ratio;
- `performance`: the nominal episode (5,000 RK4 steps) simulated and scored, compiled;
- `robustness`: the 722 rollouts of the robustness score in one vmapped call: cold (compilation
  included) and warm.
"""

import argparse
import json
import os
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
import dynax
from dynax import control

POLICY = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "results" / "leaderboard" / "acrobot_policy.npz"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--policy", default=str(POLICY))
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    robot = dynax.control.load_controller(args.policy)
    controller = robot.to_benchmark()
    rollout = control.simulate_leaderboard(controller)
    xs = np.asarray(rollout.xs)
    results = {"cpu_count": os.cpu_count(), "load_average": os.getloadavg()}

    robot.reset()
    for k in range(500):
        robot(k * 0.002, xs[k])
    robot.reset()
    times = np.empty(5000)
    for k in range(5000):
        t0 = time.perf_counter_ns()
        robot(k * 0.002, xs[k])
        times[k] = time.perf_counter_ns() - t0
    results["call_numpy_us"] = {"median": float(np.median(times) / 1e3), "p99": float(np.percentile(times, 99) / 1e3)}

    step = eqx.filter_jit(controller.step)
    state = controller.init(jnp.asarray(xs[0]))
    jtimes = np.empty(500)
    for k in range(550):
        x = jnp.asarray(xs[k])
        t0 = time.perf_counter_ns()
        state, u = step(state, jnp.asarray(k * 0.002), x)
        u.block_until_ready()
        if k >= 50:
            jtimes[k - 50] = time.perf_counter_ns() - t0
    results["call_jax_jit_us"] = {
        "median": float(np.median(jtimes) / 1e3),
        "p99": float(np.percentile(jtimes, 99) / 1e3),
    }

    t0 = time.perf_counter()
    control.performance(controller).score.block_until_ready()
    results["performance_s"] = time.perf_counter() - t0
    cases = control.robustness_cases()
    cold = control.robustness(controller, cases=cases)
    warm = control.robustness(controller, cases=cases)
    results["robustness_cold_s"] = cold.seconds
    results["robustness_warm_s"] = warm.seconds
    results["robustness_rollouts"] = len(cases.family)
    results["ratio_jax_call_to_numpy_call"] = results["call_jax_jit_us"]["median"] / results["call_numpy_us"]["median"]
    print(json.dumps(results, indent=2))
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
