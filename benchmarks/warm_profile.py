"""Where a warm `identify` spends its time, and what its data checks and its reading of friction at rest cost.

The workload is `benchmarks/identify.py`'s (100,000 acrobot samples, float64; `Dynamic(lowpass_hz=None)`,
`Power()`, `Energy()`, no refinement, nothing held out, consistency off). For each method, after two
calls that compile: the best CPU and wall time of `--calls` warm calls, alternately with the rest search
(`record_rests`, `rests_under_load`) switched off (`dynax.internal.rest_search_off`), and of `--calls` calls
of the data sanity checks alone (`check_records` on the record, as `identify` calls it), so that their price
is read on the same machine at the same load; then a cProfile of `--calls` warm calls with everything on,
by cumulative time in dynax's functions.

    python benchmarks/warm_profile.py [--methods dynamic,power,energy] [--calls 5] [--rows 30]

Prints only. On a machine shared with other work, read the CPU times (user + system of every thread,
including BLAS threads that spin while they wait).
"""

import jax

jax.config.update("jax_enable_x64", True)

import argparse  # noqa: E402
import cProfile  # noqa: E402
import io  # noqa: E402
import pstats  # noqa: E402
import time  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax import Dynamic, Energy, identify, Power, Trajectory  # noqa: E402
from dynax.internal import rest_search_off  # noqa: E402

METHODS = {"dynamic": Dynamic(lowpass_hz=None), "power": Power(), "energy": Energy()}


def workload(samples: int) -> Trajectory:
    """`benchmarks/identify.py`'s record: the acrobot under torque steps held 0.5 s."""
    system = dynax.Acrobot()
    ts = 0.01 * np.arange(samples)
    levels = np.random.default_rng(0).uniform(-2, 2, size=samples // 50 + 1)
    us = np.repeat(levels, 50)[:samples, None]
    xs = dynax.simulate(system, jnp.array([0.2, 0.0, 0.0, 0.0]), jnp.asarray(ts), jnp.asarray(us)).xs
    return Trajectory(jnp.asarray(ts), jnp.asarray(xs), jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",))


def best_times(call, calls: int) -> tuple[float, float]:
    cpu, wall = [], []
    for _ in range(calls):
        c, w = time.process_time(), time.perf_counter()
        jax.block_until_ready(call())
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - w)
    return min(cpu), min(wall)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", default="dynamic,power,energy")
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--calls", type=int, default=5)
    parser.add_argument("--rows", type=int, default=30)
    args = parser.parse_args()
    system, data = dynax.Acrobot(), workload(args.samples)
    for name in args.methods.split(","):
        method = METHODS[name]

        def call():
            result = identify(
                system, data, method, refine=False, validation=dynax.Validate(holdout=0), consistency="off"
            )
            return result.estimate

        call()
        call()
        for _ in range(2):  # on, off, on, off: the same load for both
            on = best_times(call, args.calls)
            with rest_search_off():
                off = best_times(call, args.calls)
            checks = best_times(lambda: len(dynax.check_records([data]).findings), args.calls)
            print(
                f"{name}: warm CPU {on[0]:.3f} s (wall {on[1]:.3f} s); without the rest search {off[0]:.3f} s "
                f"(wall {off[1]:.3f} s); the data checks alone {checks[0]:.3f} s (wall {checks[1]:.3f} s)",
                flush=True,
            )
        profile = cProfile.Profile()
        profile.enable()
        for _ in range(args.calls):
            jax.block_until_ready(call())
        profile.disable()
        out = io.StringIO()
        pstats.Stats(profile, stream=out).sort_stats("cumulative").print_stats(r"dynax/", args.rows)
        print(f"--- {name}: {args.calls} warm calls, cumulative seconds in dynax's functions")
        print("\n".join(line for line in out.getvalue().splitlines() if "dynax/" in line or "ncalls" in line))


if __name__ == "__main__":
    main()
