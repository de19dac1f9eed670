"""Where `simulate`'s fixed-grid rollouts spend their work against a hand-written RK4 `lax.scan`: the
compiled programs compared op by op.

The same 1,024 acrobot rollouts of 1,000 RK4 steps as `benchmarks/rollout.py` (float32), compiled
three ways: `dynax.simulate` with `FixedGrid(RK4())`, a hand-written scan with the step size as a
compile-time constant, and the same scan reading the step size from the grid. For each it prints the
instructions of the compiled loop body by kind (XLA's CPU backend runs each fusion as one loop over
the batch), the bytes the whole program accesses by XLA's cost analysis (the difference outside the
loop is `simulate`'s prepending of the initial state and its NaN mask after a divergence, fused into
one pass over the output), and the best wall time of 5 calls.

    python benchmarks/rollout_profile.py [--batch 1024] [--steps 1000]
"""

import argparse
import collections
import re
import time

import jax
import jax.numpy as jnp
import numpy as np
from rollout import rollout_programs

import dynax


def _loop_body_ops(hlo: str) -> collections.Counter:
    """Instruction kinds of the outermost `while` loop's body in an optimised HLO module."""
    body = re.findall(r"while\(.*?body=%?([\w.\-]+)", hlo)[0]
    header = re.search(r"\n%?" + re.escape(body) + r" \(", hlo)
    lines = hlo[header.end() :].splitlines()[1:]
    ops = collections.Counter()
    for line in lines:
        if line.startswith("}"):
            break
        match = re.search(r"= \S+ ([\w\-]+)\(", line)
        if match:
            ops[match.group(1)] += 1
    return ops


def _best(fn, *args, reps=5):
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(reps):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - start)
    return min(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--steps", type=int, default=1000)
    args = parser.parse_args()
    dt, dtype = 0.01, jnp.float32
    system = jax.tree.map(lambda p: jnp.asarray(p, dtype), dynax.Acrobot())
    ts = jnp.asarray(dt * np.arange(args.steps + 1), dtype)
    rng = np.random.default_rng(0)
    x0 = jnp.asarray(rng.uniform(-1, 1, (args.batch, 4)), dtype)
    us = jnp.asarray(rng.uniform(-1, 1, (args.batch, args.steps + 1, 1)), dtype)
    dynax_rollouts, hand, hand_grid = rollout_programs(system, ts, dt)

    print(f"{args.batch} acrobot rollouts of {args.steps} RK4 steps, float32, {jax.devices()[0].device_kind}")
    for name, fn in (
        ("dynax simulate", dynax_rollouts),
        ("hand-written, dt constant", hand),
        ("hand-written, dt from grid", hand_grid),
    ):
        compiled = jax.jit(fn).lower(x0, us).compile()
        ops = _loop_body_ops(compiled.as_text())
        cost = compiled.cost_analysis()
        cost = cost[0] if isinstance(cost, list) else cost
        seconds = _best(compiled, x0, us)
        kinds = ", ".join(f"{k} {v}" for k, v in ops.most_common())
        print(
            f"  {name:28s} loop body: {sum(ops.values())} instructions ({kinds}); "
            f"program: {cost.get('bytes accessed', float('nan')) / 2**20:.1f} MiB accessed; best {1e3 * seconds:.1f} ms"
        )


if __name__ == "__main__":
    main()
