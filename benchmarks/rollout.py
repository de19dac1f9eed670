"""Batched acrobot rollouts: dynax against MuJoCo, gymnasium and a hand-written RK4 scan.

1,024 acrobot rollouts of 1,000 classical RK4 steps at dt = 0.01 s in float32, each with its own
control sequence (what a sampling-based controller or a parameter sweep does), run side by side:

- `dynax.simulate(..., method=FixedGrid(RK4, substeps=1))` vmapped over the batch, on one XLA
  CPU device and with the batch sharded over all host devices (`jax.sharding`);
- a hand-written RK4 step inside `lax.scan` on the same `Acrobot().vector_field`: the practical
  XLA limit for this model (once with the constant dt folded in, once reading dt from the grid
  as `simulate` must, since it accepts irregular sampling);
- MuJoCo's `mujoco.rollout.rollout` on `benchmarks/acrobot.xml` (the same acrobot, checked by
  `tests/benchmarks/test_acrobot_mjcf.py`), RK4, float64 (MuJoCo has no float32 mode);
- gymnasium's `Acrobot-v1` in a plain `env.step` loop (one step = one RK4 step of 0.2 s of its
  own acrobot model, plus observation and reward).

It also times the gradient of a 1,000-step rollout loss with respect to the system parameters
and the initial states, relative to the forward pass, with the compiled peak memory.

XLA runs one jitted computation on one CPU core; to use more cores the batch is sharded over
several host "devices". Their number is fixed when JAX starts, so this script (the caller, never
the library) sets `XLA_FLAGS=--xla_force_host_platform_device_count=N` before importing jax.
On a GPU machine the script runs unchanged: the same sharding spreads the batch over the GPUs, and
the device's name (`jax.devices()[0].device_kind`) is printed and stored with the numbers (CPU-only
runs say so). MuJoCo and gymnasium always run on the host CPU.

    python benchmarks/rollout.py [--devices 2] [--batch 1024] [--steps 1000] [--json FILE]
"""

import argparse
import os
import pathlib
import resource
import sys
import time


def _arguments():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--devices", type=int, default=2, help="host CPU devices to shard over (default 2)")
    parser.add_argument("--batch", type=int, default=1024, help="rollouts (default 1024)")
    parser.add_argument("--steps", type=int, default=1000, help="RK4 steps per rollout (default 1000)")
    parser.add_argument("--dt", type=float, default=0.01, help="step size [s] (default 0.01)")
    parser.add_argument("--reps", type=int, default=5, help="timed repetitions; the best is reported (default 5)")
    parser.add_argument("--gym-steps", type=int, default=20_000, help="gymnasium env.step calls (default 20000)")
    parser.add_argument("--skip-gradient", action="store_true", help="leave out the gradient timing")
    parser.add_argument("--json", type=pathlib.Path, help="also write the results to this JSON file")
    return parser.parse_args()


ARGS = _arguments() if __name__ == "__main__" else None
if ARGS is not None and ARGS.devices > 1:
    # Must happen before jax is imported; appended so other XLA flags of the caller survive.
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={ARGS.devices}"
    ).strip()

import json  # noqa: E402

from _device import describe, device_info  # noqa: E402
import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jax.sharding import NamedSharding, PartitionSpec  # noqa: E402
import numpy as np  # noqa: E402

try:
    import dynax
except ImportError:  # run from a checkout without installing it
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
    import dynax

MJCF = pathlib.Path(__file__).resolve().parent / "acrobot.xml"


def _problem(batch, steps, dt, seed=0):
    """Initial states and per-rollout control sequences (float64, numpy)."""
    rng = np.random.default_rng(seed)
    x0 = np.concatenate([rng.uniform(-1.0, 1.0, (batch, 2)), rng.uniform(-1.0, 1.0, (batch, 2))], axis=1)
    t = dt * np.arange(steps + 1)
    amplitude = rng.uniform(0.5, 2.0, (batch, 1))
    frequency = rng.uniform(0.2, 2.0, (batch, 1))
    us = amplitude * np.sin(2 * np.pi * frequency * t[None]) + 0.1 * rng.standard_normal((batch, steps + 1))
    return x0, us[..., None], t


def _best_time(fn, *args, reps):
    """Best and median wall time, and best process CPU time, of `reps` calls after a warm-up call.

    On a shared machine the wall time includes waiting for a core; the CPU time (all threads of
    this process) does not, so work per CPU-second is the load-independent measure of cost.
    """
    jax.block_until_ready(fn(*args))
    walls, cpus = [], []
    for _ in range(reps):
        wall, cpu = time.perf_counter(), time.process_time()
        jax.block_until_ready(fn(*args))
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return min(walls), float(np.median(walls)), min(cpus)


def _compile(fn, *args):
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    return compiled, time.perf_counter() - start


def _row(results, name, timing, n_steps, **extra):
    seconds, median, cpu = timing
    results[name] = dict(
        seconds=seconds,
        median_seconds=median,
        cpu_seconds=cpu,
        steps_per_s=n_steps / seconds,
        steps_per_cpu_s=n_steps / cpu,
        **extra,
    )
    parts = [f"{k}={v:.2f}s" if k.endswith("_s") else f"{k}={v}" for k, v in extra.items()]
    print(
        f"  {name:38s} {seconds * 1e3:9.1f} {median * 1e3:9.1f} {n_steps / seconds / 1e6:9.2f}"
        f" {cpu * 1e3:9.1f} {n_steps / cpu / 1e6:9.2f}  {'  '.join(parts)}"
    )


HEADER = f"  {'':38s} {'best ms':>9s} {'median ms':>9s} {'M step/s':>9s} {'CPU ms':>9s} {'M st/CPUs':>9s}"


def rollout_programs(system, ts, dt):
    """The three batched rollout programs compared here, `(x0, us) -> xs`: `dynax.simulate` with
    `FixedGrid(RK4())`, a hand-written RK4 `lax.scan` with `dt` a compile-time constant, and the same
    scan reading the step size from the grid `ts` (also used by `rollout_profile.py`)."""
    method = dynax.FixedGrid(dynax.RK4(), substeps=1)

    def dynax_rollouts(x0, us):
        simulate = lambda x, u: dynax.simulate(system, x, ts, u, method=method, throw=False).xs  # noqa: E731
        return jax.vmap(simulate)(x0, us)

    def vector_field(x, u):
        return system.vector_field(0.0, x, u)

    def rk4(x, u, h):
        k1 = vector_field(x, u)
        k2 = vector_field(x + h / 2 * k1, u)
        k3 = vector_field(x + h / 2 * k2, u)
        k4 = vector_field(x + h * k3, u)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def hand_rollouts(x0, us):
        def rollout(x, u_seq):
            def step(x, u):
                x = rk4(x, u, dt)  # dt a compile-time constant
                return x, x

            return jax.lax.scan(step, x, u_seq[:-1])[1]

        return jax.vmap(rollout)(x0, us)

    def hand_grid_rollouts(x0, us):
        def rollout(x, u_seq):
            def step(x, inputs):
                u, h = inputs
                x = rk4(x, u, h)  # dt read from the sample grid
                return x, x

            return jax.lax.scan(step, x, (u_seq[:-1], jnp.diff(ts)))[1]

        return jax.vmap(rollout)(x0, us)

    return dynax_rollouts, hand_rollouts, hand_grid_rollouts


def bench_jax(args, x0, us, ts, results):
    dtype = jnp.float32
    system = jax.tree.map(lambda p: jnp.asarray(p, dtype), dynax.Acrobot())
    x0_32, us_32 = jnp.asarray(x0, dtype), jnp.asarray(us, dtype)
    n_steps = args.batch * args.steps
    dynax_rollouts, hand_rollouts, hand_grid_rollouts = rollout_programs(system, jnp.asarray(ts, dtype), args.dt)

    print(f"\nJAX {jax.__version__} ({jax.devices()[0].device_kind}, {jax.device_count()} device(s)), float32:")
    print(HEADER)
    compiled = {}
    for name, fn in [
        ("dynax simulate, 1 device", dynax_rollouts),
        ("hand-written RK4 scan, 1 device", hand_rollouts),
        ("hand-written, dt from grid, 1 device", hand_grid_rollouts),
    ]:
        compiled[name], compile_s = _compile(fn, x0_32, us_32)
        _row(results, name, _best_time(compiled[name], x0_32, us_32, reps=args.reps), n_steps, compile_s=compile_s)

    n_dev = jax.device_count()
    if n_dev > 1:
        if args.batch % n_dev:
            raise SystemExit(f"--batch {args.batch} must be divisible by the device count {n_dev}")
        # Auto (GSPMD) sharding: the compiler propagates the batch split through the rollout.
        mesh = jax.make_mesh((n_dev,), ("batch",), axis_types=(jax.sharding.AxisType.Auto,))
        batch_sharding = NamedSharding(mesh, PartitionSpec("batch"))
        x0_s, us_s = jax.device_put(x0_32, batch_sharding), jax.device_put(us_32, batch_sharding)
        for name, fn in [
            (f"dynax simulate, {n_dev} devices", dynax_rollouts),
            (f"hand-written RK4 scan, {n_dev} devices", hand_rollouts),
        ]:
            start = time.perf_counter()
            sharded = jax.jit(fn, in_shardings=batch_sharding, out_shardings=batch_sharding).lower(x0_s, us_s).compile()
            compile_s = time.perf_counter() - start
            _row(results, name, _best_time(sharded, x0_s, us_s, reps=args.reps), n_steps, compile_s=compile_s)
            compiled[name] = sharded

    xs_dynax = np.asarray(compiled["dynax simulate, 1 device"](x0_32, us_32))
    if n_dev > 1:
        # The sharded run computes the same rollouts, each on one device.
        xs_sharded = compiled[f"dynax simulate, {n_dev} devices"](x0_s, us_s)
        assert len(xs_sharded.sharding.device_set) == n_dev
        results["sharded_max_difference"] = float(np.max(np.abs(np.asarray(xs_sharded) - xs_dynax)))
        print(f"  sharded vs 1-device rollouts: max |difference| {results['sharded_max_difference']:.1e}")
    xs_hand = np.asarray(compiled["hand-written RK4 scan, 1 device"](x0_32, us_32))
    return system, xs_dynax, xs_hand


def bench_gradient(args, system, x0, us, ts, results):
    """Cost of d(rollout MSE)/d(parameters, x0) relative to the loss alone, and peak memory.

    The same for the hand-written scan, with and without `jax.checkpoint` on its step, to tell
    what reverse mode through a 1,000-step scan costs in XLA from what dynax adds.
    """
    dtype = jnp.float32
    ts32, x0_32, us_32 = jnp.asarray(ts, dtype), jnp.asarray(x0, dtype), jnp.asarray(us, dtype)
    method = dynax.FixedGrid(dynax.RK4(), substeps=1)

    def dynax_rollouts(system, x0):
        simulate = lambda x, u: dynax.simulate(system, x, ts32, u, method=method, throw=False).xs[1:]  # noqa: E731
        return jax.vmap(simulate)(x0, us_32)

    def hand_rollouts(system, x0, checkpoint=False):
        def rk4(x, u):
            f = lambda x: system.vector_field(0.0, x, u)  # noqa: E731
            h = args.dt
            k1 = f(x)
            k2 = f(x + h / 2 * k1)
            k3 = f(x + h / 2 * k2)
            k4 = f(x + h * k3)
            return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

        def step(x, u):
            x = rk4(x, u)
            return x, x

        step = jax.checkpoint(step) if checkpoint else step
        return jax.vmap(lambda x, u_seq: jax.lax.scan(step, x, u_seq[:-1])[1])(x0, us_32)

    target = jax.jit(dynax_rollouts)(system, x0_32)
    perturbed = eqx.tree_at(lambda s: (s.theta1, s.theta6), system, (system.theta1 * 1.05, system.theta6 * 1.5))
    print(f"\nGradient of a {args.steps}-step rollout MSE w.r.t. theta1..theta7 and x0, batch {args.batch}, float32:")
    print(HEADER)
    reps = min(args.reps, 3)
    n_steps = args.batch * args.steps
    entries = {}
    for label, rollouts in [
        ("dynax", dynax_rollouts),
        ("hand-written", hand_rollouts),
        ("hand-written + jax.checkpoint", lambda s, x: hand_rollouts(s, x, checkpoint=True)),
    ]:

        def loss(system, x0, rollouts=rollouts):
            return jnp.mean((rollouts(system, x0) - target) ** 2)

        fwd, fwd_compile = _compile(loss, perturbed, x0_32)
        bwd, bwd_compile = _compile(jax.grad(loss, argnums=(0, 1)), perturbed, x0_32)
        fwd_t = _best_time(fwd, perturbed, x0_32, reps=reps)
        bwd_t = _best_time(bwd, perturbed, x0_32, reps=reps)
        g_system, g_x0 = bwd(perturbed, x0_32)
        assert all(np.all(np.isfinite(np.asarray(v))) for v in jax.tree.leaves((g_system, g_x0)))
        memory = [c.memory_analysis() for c in (fwd, bwd)]
        memory = [None if m is None else m.temp_size_in_bytes / 2**20 for m in memory]
        _row(results, f"{label}: loss", fwd_t, n_steps, compile_s=fwd_compile, temp_MiB=_fmt(memory[0]))
        _row(results, f"{label}: jax.grad", bwd_t, n_steps, compile_s=bwd_compile, temp_MiB=_fmt(memory[1]))
        entries[label] = dict(
            ratio_cpu=bwd_t[2] / fwd_t[2],
            ratio_wall=bwd_t[0] / fwd_t[0],
            forward_temp_MiB=memory[0],
            gradient_temp_MiB=memory[1],
        )
    for label, entry in entries.items():
        print(
            f"  {label:32s} gradient / forward: {entry['ratio_cpu']:.2f}x CPU time ({entry['ratio_wall']:.2f}x wall);"
            f" compiled temporaries {_fmt(entry['forward_temp_MiB'])} -> {_fmt(entry['gradient_temp_MiB'])} MiB"
        )
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"  target <= 4x; the trajectory itself is {n_steps * 16 / 2**20:.1f} MiB; process max RSS {rss:.0f} MiB")
    results["gradient"] = dict(entries, max_rss_MiB=rss)


def _fmt(value):
    return "n/a" if value is None else f"{value:.1f}"


def bench_mujoco(args, x0, us, results):
    import mujoco
    from mujoco import rollout

    model = mujoco.MjModel.from_xml_path(str(MJCF))
    model.opt.timestep = args.dt
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    data = mujoco.MjData(model)
    state0 = np.empty((args.batch, mujoco.mj_stateSize(model, spec)))
    for i, x in enumerate(x0):
        data.qpos[:], data.qvel[:] = x[:2], x[2:]
        mujoco.mj_getState(model, data, state0[i], spec)
    control = np.ascontiguousarray(us[:, :-1])
    n_steps = args.batch * args.steps
    print(f"\nMuJoCo {mujoco.__version__} mujoco.rollout, RK4, float64:")
    print(HEADER)
    out = None
    for nthread in (1, 2):
        datas = [mujoco.MjData(model) for _ in range(nthread)]
        state = np.empty((args.batch, args.steps, state0.shape[1]))
        walls, cpus = [], []
        for _ in range(max(2, args.reps // 2)):
            wall, cpu = time.perf_counter(), time.process_time()
            rollout.rollout(model, datas, state0, control, state=state)
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
        _row(results, f"mujoco.rollout, nthread={nthread}", (min(walls), float(np.median(walls)), min(cpus)), n_steps)
        out = state
    return out[:, :, 1:5]  # FULLPHYSICS state = [time, qpos, qvel, ...]


def bench_gymnasium(args, results):
    import gymnasium

    env = gymnasium.make("Acrobot-v1")
    env.reset(seed=0)
    actions = np.random.default_rng(0).integers(0, 3, args.gym_steps)
    wall, cpu = time.perf_counter(), time.process_time()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(f"\ngymnasium {gymnasium.__version__} Acrobot-v1, plain env.step loop (one step = one RK4 step of dt 0.2 s):")
    print(HEADER)
    _row(results, "gymnasium Acrobot-v1 env.step", (wall, wall, cpu), args.gym_steps)


def main(args):
    print(
        f"{args.batch} acrobot rollouts x {args.steps} RK4 steps (dt = {args.dt} s); best of {args.reps}; "
        f"{os.cpu_count()} CPU cores, load average {os.getloadavg()[0]:.1f}"
    )
    print(describe(device_info()))
    x0, us, ts = _problem(args.batch, args.steps, args.dt)
    results = {}
    load_start = os.getloadavg()[0]
    system, xs_dynax, xs_hand = bench_jax(args, x0, us, ts, results)
    xs_mujoco = bench_mujoco(args, x0, us, results)
    bench_gymnasium(args, results)
    if not args.skip_gradient:
        bench_gradient(args, system, x0, us, ts, results)

    # Same computation? Compare the first second (float32 rounding grows along chaotic rollouts).
    k = min(100, args.steps)
    agreement = dict(
        dynax_vs_mujoco_1s=float(np.max(np.abs(xs_dynax[:, k] - xs_mujoco[:, k - 1]))),
        dynax_vs_hand_1s=float(np.max(np.abs(xs_dynax[:, k] - xs_hand[:, k - 1]))),
    )
    results["agreement"] = agreement

    def rate(name, per="steps_per_s"):
        return results[name][per]

    n_dev = jax.device_count()
    d1, mj2, mj1 = "dynax simulate, 1 device", "mujoco.rollout, nthread=2", "mujoco.rollout, nthread=1"
    hand, hand_grid = "hand-written RK4 scan, 1 device", "hand-written, dt from grid, 1 device"
    gym = "gymnasium Acrobot-v1 env.step"
    ratios = {
        "dynax 1 device / MuJoCo 2 threads (wall; target >= 20)": rate(d1) / rate(mj2),
        "dynax 1 device / hand-written scan (wall; target >= 0.9)": rate(d1) / rate(hand),
        "dynax 1 device / gymnasium step loop (wall)": rate(d1) / rate(gym),
        "dynax / MuJoCo, per CPU-second": rate(d1, "steps_per_cpu_s") / rate(mj1, "steps_per_cpu_s"),
        "dynax / hand-written scan, per CPU-second": rate(d1, "steps_per_cpu_s") / rate(hand, "steps_per_cpu_s"),
        "dynax / hand-written with grid dt, per CPU-s": rate(d1, "steps_per_cpu_s")
        / rate(hand_grid, "steps_per_cpu_s"),
    }
    if n_dev > 1:
        dn = f"dynax simulate, {n_dev} devices"
        ratios[f"dynax {n_dev} devices / MuJoCo 2 threads (wall; target >= 30)"] = rate(dn) / rate(mj2)
        ratios[f"dynax {n_dev} devices / 1 device (wall)"] = rate(dn) / rate(d1)
        ratios["MuJoCo 2 threads / 1 thread (wall)"] = rate(mj2) / rate(mj1)
    results["ratios"] = ratios
    print("\nRatios of throughput (wall ratios need an otherwise idle machine; CPU-second ratios do not):")
    for name, value in ratios.items():
        print(f"  {name:58s} {value:8.2f}x")
    print(
        f"\nAgreement after 1 s (max |x| difference): dynax vs MuJoCo (float32 vs float64) "
        f"{agreement['dynax_vs_mujoco_1s']:.1e}, dynax vs hand-written {agreement['dynax_vs_hand_1s']:.1e}"
    )
    print(f"Load average {load_start:.1f} at the start, {os.getloadavg()[0]:.1f} at the end ({os.cpu_count()} cores).")
    if args.json is not None:
        meta = dict(
            batch=args.batch,
            steps=args.steps,
            dt=args.dt,
            reps=args.reps,
            devices=n_dev,
            cpu_count=os.cpu_count(),
            jax=jax.__version__,
            device=device_info(),
            load_average_start=load_start,
            load_average_end=os.getloadavg()[0],
            date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        )
        args.json.write_text(json.dumps(dict(meta=meta, results=results), indent=2))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main(ARGS)
