"""Lagged EM-free against backprop: time to the same loss, and the backprop's memory against horizon.

1. **Time.** 60 s of 100 Hz hover data from the truth simulator, horizon H = 1 s, the rich
   acceleration model. Both fits start from the one-step fit. The EM-free iteration runs to
   convergence; backprop (L-BFGS through the checkpointed rollouts) then runs until it reaches the
   EM-free loss (or its step budget); Gauss-Newton on the true loss (`Lagged(state_sensitivities=True)`)
   runs to convergence. Reported: wall time to the EM-free loss for all three, and the final losses.
2. **Memory.** The peak temporary memory of one compiled backprop gradient (XLA's
   `memory_analysis()` of the jitted gradient) for H = 0.5, 1 and 2 s, with `jax.checkpoint` segments
   of $\\lceil\\sqrt{H}\\rceil$ steps and without checkpointing.

Run: `python benchmarks/helicopter_learning.py [--stride N] [--out DIR]` (default stride 10: 590 start
times; `--stride 1` uses all 5900). Writes `DIR/helicopter_learning.json`. Timings on a shared CPU
are indicative; the memory figures are exact for the compiled program.
"""

import argparse
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

from dynax import Backprop, Lagged  # noqa: E402
from dynax.internal import (  # noqa: E402
    fit_backprop,
    fit_lagged,
    fit_one_step,
    initial_helicopter,
    lagged_loss,
    recorded_loss,
    valid_starts,
    with_theta,
    write_json,
)
from dynax.synthetic import generate_helicopter_flight  # noqa: E402


def log(message):
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


def gradient_memory(system, data, horizon_s, stride, segment):
    n_steps = int(round(horizon_s / data.dt))
    starts = jnp.asarray(valid_starts(len(data), n_steps, stride))
    theta = system.body_model.parameter_vector()

    def loss(th):
        return lagged_loss(with_theta(system, th), data, n_steps, starts=starts, checkpoint_segment=segment)

    compiled = jax.jit(jax.grad(loss)).lower(theta).compile()
    analysis = compiled.memory_analysis()
    return int(analysis.temp_size_in_bytes) if analysis is not None else None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stride", type=int, default=10)
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--skip-timing", action="store_true")
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    data = generate_helicopter_flight("hover", 60.0, seed=31)
    system = fit_one_step(initial_helicopter("acceleration", "rich"), data).model
    log(f"60 s hover flight, {len(data)} samples; one-step fit done")

    memory = []
    for horizon in (0.5, 1.0, 2.0):
        row = {"horizon_s": horizon}
        for name, segment in (("checkpointed_bytes", None), ("plain_bytes", 0)):
            row[name] = gradient_memory(system, data, horizon, args.stride, segment)
        memory.append(row)
        log(
            f"H = {horizon} s: gradient temporaries {row['checkpointed_bytes'] / 2**20:.1f} MiB checkpointed, "
            f"{row['plain_bytes'] / 2**20:.1f} MiB without"
        )
    result = {"stride": args.stride, "n_samples": len(data), "memory": memory}

    if not args.skip_timing:
        t0 = time.perf_counter()
        lagged = fit_lagged(
            system,
            data,
            Lagged(horizon=1.0, stride=args.stride, max_iterations=30),
            callback=lambda i, loss: log(f"EM-free iteration {i + 1}: {loss:.6g}"),
        )
        em_time = time.perf_counter() - t0
        log(f"EM-free: loss {recorded_loss(lagged):.6g} in {em_time:.1f} s ({len(lagged.history) - 1} iterations)")
        t0 = time.perf_counter()
        direct = fit_backprop(
            system,
            data,
            Backprop(horizon=1.0, stride=args.stride, max_steps=100, target_loss=recorded_loss(lagged)),
            callback=lambda i, loss: log(f"backprop step {i + 1}: {loss:.6g}"),
        )
        bp_time = time.perf_counter() - t0
        reached = recorded_loss(direct) <= recorded_loss(lagged)
        log(
            f"backprop: loss {recorded_loss(direct):.6g} in {bp_time:.1f} s ({len(direct.history) - 1} steps); "
            f"{'reached' if reached else 'did not reach'} the EM-free loss"
        )
        t0 = time.perf_counter()
        newton = fit_lagged(
            system,
            data,
            Lagged(horizon=1.0, stride=args.stride, max_iterations=30, state_sensitivities=True),
            callback=lambda i, loss: log(f"Gauss-Newton iteration {i + 1}: {loss:.6g}"),
        )
        gn_time = time.perf_counter() - t0
        gn_reach = next((t for t, loss in newton.history if loss <= recorded_loss(lagged)), None)
        log(
            f"Gauss-Newton (state sensitivities): loss {recorded_loss(newton):.6g} in {gn_time:.1f} s "
            f"({len(newton.history) - 1} iterations); EM-free loss reached after {gn_reach} s"
        )
        result["timing"] = {
            "gauss_newton_loss": recorded_loss(newton),
            "gauss_newton_seconds": gn_time,
            "gauss_newton_seconds_to_em_free_loss": gn_reach,
            "gauss_newton_history": [list(h) for h in newton.history],
            "horizon_s": 1.0,
            "em_free_loss": recorded_loss(lagged),
            "em_free_seconds": em_time,
            "em_free_history": [list(h) for h in lagged.history],
            "backprop_loss": recorded_loss(direct),
            "backprop_seconds": bp_time,
            "backprop_reached_em_free_loss": bool(reached),
            "backprop_history": [list(h) for h in direct.history],
        }
    write_json(out / "helicopter_learning.json", result)
    log(f"wrote {out / 'helicopter_learning.json'}")


if __name__ == "__main__":
    main()
