"""Which way to integrate on a fixed sample grid: diffrax steps in `lax.scan` or `diffeqsolve`.

The acrobot over 5 s at 100 Hz with zero-order-hold inputs (the recorded-data case), float64.
Each path is timed on a single rollout and on a vmapped batch, and its accuracy is measured
against scipy's DOP853 at rtol 1e-11, restarted at every sample so that no step straddles an
input jump.

Paths:

- `FixedGrid(solver, substeps)`: `dynax.simulate`'s default; explicit Runge-Kutta steps inside
  `lax.scan`, restarted at every sample (the input is constant within each step).
- `Adaptive(...)`: `dynax.simulate` through `diffrax.diffeqsolve` with a PID controller, the
  sample times as `jump_ts` and `SaveAt(ts=...)`.
- `diffeqsolve StepTo + SaveAt(ts)`: one `diffeqsolve` with constant steps (`StepTo` on the
  substep grid) and the input looked up by `searchsorted`, as one would write it by hand.
  A stage at the end of a step reads the next sample's input, so it loses accuracy at the jumps.
- `diffeqsolve per sample in scan`: a constant-step `diffeqsolve` per sample interval inside
  `lax.scan`; as accurate as `FixedGrid`, but pays `diffeqsolve`'s set-up in every interval.

    python benchmarks/simulate_paths.py [--batch 256] [--reps 5] [--json FILE]
"""

import argparse
import os
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)  # a script may; the library never does

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

try:
    import dynax
except ImportError:  # run from a checkout without installing it
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
    import dynax

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from rollout import _best_time  # noqa: E402  (the same timing as the rollout benchmark)


def _problem(batch, seed=0):
    rng = np.random.default_rng(seed)
    ts = np.linspace(0.0, 5.0, 501)
    x0 = np.concatenate([rng.uniform(-1.5, 1.5, (batch, 2)), rng.uniform(-1.0, 1.0, (batch, 2))], axis=1)
    amplitude = rng.uniform(0.5, 2.0, (batch, 1))
    frequency = rng.uniform(0.2, 2.0, (batch, 1))
    square = np.where(np.sin(2 * np.pi * 0.7 * ts)[None] > 0, 1.0, -1.0)  # jumps of 2 N m
    us = amplitude * np.sin(2 * np.pi * frequency * ts[None]) + 0.5 * square
    return ts, x0, us[..., None]


def scipy_reference(system, x0, ts, us):
    """DOP853 at rtol 1e-11, restarted at every sample (zero-order-hold inputs)."""
    f = jax.jit(lambda t, x, u: system.vector_field(t, x, u))
    x = np.asarray(x0, dtype=float)
    out = [x]
    for k in range(len(ts) - 1):
        u = jnp.asarray(us[k])
        sol = solve_ivp(
            lambda t, y: np.asarray(f(t, jnp.asarray(y), u)),
            (ts[k], ts[k + 1]),
            x,
            method="DOP853",
            rtol=1e-11,
            atol=1e-12,
        )
        x = sol.y[:, -1]
        out.append(x)
    return np.asarray(out)


def _diffeqsolve_stepto(system, solver, substeps):
    """One `diffeqsolve` over the whole record: constant steps, inputs by `searchsorted`."""

    def rollout(x0, ts, us):
        fractions = jnp.arange(substeps)[None] / substeps
        fine = jnp.concatenate([(ts[:-1, None] + (ts[1:, None] - ts[:-1, None]) * fractions).reshape(-1), ts[-1:]])

        def vector_field(t, x, args):
            k = jnp.clip(jnp.searchsorted(ts, t, side="right") - 1, 0, us.shape[0] - 1)
            return system.vector_field(t, x, us[k])

        solution = diffrax.diffeqsolve(
            diffrax.ODETerm(vector_field),
            solver,
            t0=ts[0],
            t1=ts[-1],
            dt0=None,
            y0=x0,
            saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.StepTo(ts=fine),
            max_steps=fine.shape[0],
        )
        return solution.ys

    return rollout


def _diffeqsolve_per_interval(system, solver, substeps):
    """A constant-step `diffeqsolve` per sample interval, inside `lax.scan`."""

    def rollout(x0, ts, us):
        term = diffrax.ODETerm(lambda t, x, u: system.vector_field(t, x, u))

        def interval(x, inputs):
            t0, t1, u = inputs
            solution = diffrax.diffeqsolve(
                term,
                solver,
                t0=t0,
                t1=t1,
                dt0=(t1 - t0) / substeps,
                y0=x,
                args=u,
                saveat=diffrax.SaveAt(t1=True),
                max_steps=substeps,
            )
            x = solution.ys[-1]
            return x, x

        _, xs = jax.lax.scan(interval, x0, (ts[:-1], ts[1:], us[:-1]))
        return jnp.concatenate([x0[None], xs])

    return rollout


def _simulate(system, method):
    def rollout(x0, ts, us):
        return dynax.simulate(system, x0, ts, us, method=method, throw=False).xs

    return rollout


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, default=256, help="rollouts in the vmapped batch (default 256)")
    parser.add_argument("--references", type=int, default=4, help="rollouts checked against scipy (default 4)")
    parser.add_argument("--reps", type=int, default=5, help="timed repetitions; the best is reported (default 5)")
    parser.add_argument("--json", type=pathlib.Path, help="also write the results to this JSON file")
    args = parser.parse_args()

    system = dynax.Acrobot()
    ts, x0, us = _problem(args.batch)
    print(f"Acrobot, 5 s at 100 Hz, zero-order-hold inputs, float64; load average {os.getloadavg()[0]:.1f}")
    print(f"scipy DOP853 (rtol 1e-11) reference for {args.references} rollouts ...", flush=True)
    references = np.stack([scipy_reference(system, x0[i], ts, us[i]) for i in range(args.references)])

    paths = {
        "FixedGrid(Tsit5, substeps=2)  [default]": _simulate(system, dynax.FixedGrid()),
        "FixedGrid(Tsit5, substeps=1)": _simulate(system, dynax.FixedGrid(diffrax.Tsit5(), substeps=1)),
        "FixedGrid(RK4, substeps=1)": _simulate(system, dynax.FixedGrid(dynax.RK4(), substeps=1)),
        "FixedGrid(Dopri8, substeps=1)": _simulate(system, dynax.FixedGrid(diffrax.Dopri8(), substeps=1)),
        "Adaptive(Dopri8, rtol=atol=1e-10)": _simulate(system, dynax.Adaptive()),
        "Adaptive(Tsit5, rtol=atol=1e-8)": _simulate(system, dynax.Adaptive(diffrax.Tsit5(), rtol=1e-8, atol=1e-8)),
        "diffeqsolve StepTo(Tsit5, 2/sample) + SaveAt(ts)": _diffeqsolve_stepto(system, diffrax.Tsit5(), 2),
        "diffeqsolve per sample in scan (Tsit5, 2 steps)": _diffeqsolve_per_interval(system, diffrax.Tsit5(), 2),
    }
    ts_j, x0_j, us_j = jnp.asarray(ts), jnp.asarray(x0), jnp.asarray(us)
    header = (
        f"{'path':50s} {'max err [rad]':>13s} {'compile s':>9s} {'1 rollout ms':>12s} "
        f"{f'{args.batch} rollouts ms':>16s} {'batch CPU ms':>12s}"
    )
    print(header)
    results = {}
    for name, rollout in paths.items():
        single = jax.jit(rollout)
        batched = jax.jit(jax.vmap(rollout, in_axes=(0, None, 0)))
        start = time.perf_counter()
        batched = batched.lower(x0_j, ts_j, us_j).compile()
        compile_s = time.perf_counter() - start
        xs = np.asarray(batched(x0_j, ts_j, us_j))[: args.references]
        error = float(np.max(np.abs(xs[..., :2] - references[..., :2])))
        single_wall, _, _ = _best_time(single, x0_j[0], ts_j, us_j[0], reps=args.reps)
        batch_wall, _, batch_cpu = _best_time(batched, x0_j, ts_j, us_j, reps=args.reps)
        results[name] = dict(
            max_angle_error_rad=error,
            compile_s=compile_s,
            single_ms=single_wall * 1e3,
            batch_ms=batch_wall * 1e3,
            batch_cpu_ms=batch_cpu * 1e3,
        )
        print(
            f"{name:50s} {error:13.1e} {compile_s:9.2f} {single_wall * 1e3:12.2f} "
            f"{batch_wall * 1e3:16.1f} {batch_cpu * 1e3:12.1f}",
            flush=True,
        )
    if args.json is not None:
        meta = dict(
            batch=args.batch,
            references=args.references,
            reps=args.reps,
            jax=jax.__version__,
            date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            cpu_count=os.cpu_count(),
        )
        import json

        args.json.write_text(json.dumps(dict(meta=meta, results=results), indent=2))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
