"""`dynax.simulate` called eagerly in a loop over parameter values, against diffrax's `diffeqsolve`.

A user who generates data or sweeps a parameter calls `simulate` from Python, not under `jit`.
Each call here simulates the DFKI-like double pendulum (Coulomb friction, rotor inertia) for 6 s at
2 ms (3000 samples, 4 substeps each of `FixedGrid`'s default solver) with a different elbow friction, so the system's
structure is the same and only an array leaf changes. Three paths, one process:

- `dynax.simulate` (its fixed-grid rollout compiled once per system structure and grid shape);
- the same rollout as a bare `lax.scan`, as `simulate` ran it before 2026-11-26 (a new closure
  per call, compiled anew on every call);
- `diffrax.diffeqsolve` with the same solver at the same constant substep and `SaveAt(ts=...)` (the input looked
  up by `searchsorted`), itself `filter_jit`-compiled once.

The same for `dynax.control.simulate_closed_loop`: the acrobot under Drake's Spong swing-up controller for
10 s at 100 Hz, the controller's gains scaled anew each call, against its bare `lax.scan` (before).

Reported: the first call (compilation included) and the median of the next `--reps` calls, and
each path's median over `dynax.simulate`'s.

    python benchmarks/eager_simulate.py [--reps 10] [--json FILE]
"""

import argparse
import json
import pathlib
import statistics
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)  # a script may; the library never does

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

try:
    import dynax
except ImportError:  # run from a checkout without installing it
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
    import dynax
from dynax.internal import closed_loop_rollout, fixed_grid_rollout  # noqa: E402

RIG = dict(theta1=0.0536, theta2=0.0533, theta3=0.0362, theta4=2.365, theta5=1.777, theta6=0.01, theta7=0.01)


def arm(fc2):
    return dynax.Extended(
        dynax.DoublePendulum.from_base_parameters(RIG),
        (dynax.CoulombFriction(0, 0.15), dynax.CoulombFriction(1, fc2), dynax.RotorInertia(1, 0.0042)),
    )


def _field(t, x, args):
    system, ts, us = args
    i = jnp.clip(jnp.searchsorted(ts, t, side="right") - 1, 0, us.shape[0] - 2)
    return system.vector_field(t, x, us[i])


TERM = diffrax.ODETerm(_field)


def timed(call, reps):
    start = time.perf_counter()
    jax.block_until_ready(call(0))
    first = time.perf_counter() - start
    times = []
    for k in range(1, reps + 1):
        start = time.perf_counter()
        jax.block_until_ready(call(k))
        times.append(time.perf_counter() - start)
    return first, statistics.median(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--reps", type=int, default=10)
    parser.add_argument("--json", type=pathlib.Path, default=None)
    args = parser.parse_args(argv)
    dt, n = 0.002, 3000
    ts = jnp.arange(n + 1) * dt
    rng = np.random.default_rng(0)
    us = jnp.asarray(0.3 * np.sin(2 * np.pi * np.outer(np.arange(n + 1) * dt, [0.7, 1.3]) + rng.uniform(0, 6, 2)))
    x0 = jnp.zeros(4)
    method = dynax.FixedGrid(substeps=4)
    frictions = 0.10 + 0.001 * np.arange(args.reps + 1)

    def with_dynax(k):
        return dynax.simulate(arm(frictions[k]), x0, ts, us, method=method).xs

    bare = getattr(fixed_grid_rollout, "__wrapped__", None)

    def with_bare_scan(k):
        return bare(arm(frictions[k]), x0, ts, us, method, 1e6)[0]

    def with_diffrax(k):  # the system through `args`, as diffrax's docs pass parameters: one compilation
        return diffrax.diffeqsolve(
            TERM,
            method.solver,
            t0=ts[0],
            t1=ts[-1],
            dt0=dt / 4,
            y0=x0,
            args=(arm(frictions[k]), ts, us),
            saveat=diffrax.SaveAt(ts=ts),
            max_steps=4 * n + 8,
        ).ys

    rows = {"dynax.simulate": timed(with_dynax, args.reps)}
    if bare is not None:
        rows["bare lax.scan (before)"] = timed(with_bare_scan, args.reps)
    rows["diffrax.diffeqsolve"] = timed(with_diffrax, args.reps)

    # Closed loop: the acrobot under Drake's Spong swing-up controller for 10 s at 100 Hz, its gains
    # scaled by a different factor each call.
    plant, controller = dynax.Acrobot(), dynax.control.SpongController()
    times, start = jnp.arange(0.0, 10.0, 0.01), jnp.array([0.1, 0.0, 0.0, 0.0])

    def with_closed_loop(k):
        return dynax.control.simulate_closed_loop(
            plant, controller.with_params(controller.params * (1 + 0.01 * k)), start, times
        ).xs

    bare_loop = getattr(closed_loop_rollout, "__wrapped__", None)

    def with_bare_closed_loop(k):
        gains = controller.with_params(controller.params * (1 + 0.01 * k))
        return bare_loop(plant, gains, start, times, dynax.FixedGrid(), 1e6).xs

    rows["dynax.control.simulate_closed_loop"] = timed(with_closed_loop, args.reps)
    if bare_loop is not None:
        rows["closed loop, bare lax.scan (before)"] = timed(with_bare_closed_loop, args.reps)

    def base(name):  # each path against dynax's own on the same problem
        return rows["dynax.control.simulate_closed_loop" if "closed" in name else "dynax.simulate"][1]

    print(f"{'path':36s} {'first call s':>13s} {'median next s':>14s} {'ratio to dynax':>15s}")
    for name, (first, median) in rows.items():
        print(f"{name:36s} {first:13.3f} {median:14.4f} {median / base(name):15.1f}")
    if args.json:
        args.json.write_text(
            json.dumps({k: {"first_s": f, "median_s": m, "ratio": m / base(k)} for k, (f, m) in rows.items()}, indent=2)
            + "\n"
        )


if __name__ == "__main__":
    main()
