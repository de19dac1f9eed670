"""Strong and weak scaling of PGPE across processes on `jax.distributed` (one CPU core per process).

Each process is pinned to one core (`os.sched_setaffinity`) with XLA's CPU backend on one thread and
one device, and joins the run through `dynax.initialize_distributed` (gloo collectives on
localhost). The work is `run_pgpe` on acrobot rollouts: every generation's population is split
across the processes' devices and the rewards gathered (one all-gather per generation).

- strong scaling: the same population on 1 and on N processes; efficiency `T1 / (N * TN)`.
- weak scaling: N times the population on N processes; efficiency `T1 / TN(N x work)`.

Ideal efficiency is 1.0. The timings are the best of `--repeats` warm runs (after compilation) of
the slowest process, over `--rounds` rounds that alternate the three set-ups. Wall-clock efficiency
needs an otherwise idle machine (the load average is recorded with the numbers); the CPU-time
efficiency (CPU seconds of one process over those of all processes together) measures what the
split itself costs, whatever else the machine runs.

    python benchmarks/scaling.py [--processes 2] [--population 512] [--steps 1000] [--generations 4]
"""

import argparse
import json
import os
import pathlib
import platform
import socket
import subprocess
import sys
import time

REPO = pathlib.Path(__file__).resolve().parents[1]


def worker(args):
    n_cores = os.cpu_count() or 1
    os.sched_setaffinity(0, {args.rank % n_cores})
    os.environ["JAX_PLATFORMS"] = "cpu"
    os.environ["XLA_FLAGS"] = (
        "--xla_force_host_platform_device_count=1 --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
    )
    import jax

    import dynax

    if args.processes > 1:
        dynax.initialize_distributed(f"localhost:{args.port}", args.processes, args.rank, initialization_timeout=300)
    import jax.numpy as jnp

    ts = jnp.arange(args.steps + 1) * 0.01
    arm = dynax.Acrobot()

    def objective(params, key):
        # A whole fixed-step rollout per member from a random start; the reward weighs the final
        # state by the parameters (the work, not the task, is what is measured).
        x0 = jnp.array([0.3, -0.2, 0.0, 0.0]) + 0.1 * jax.random.normal(key, (4,))
        sim = dynax.simulate(arm, x0, ts, jnp.zeros((ts.shape[0], 1)), throw=False)
        return -jnp.sum((sim.xs[-1] * params) ** 2)

    pgpe = dynax.control.PGPE(population_size=args.population, init_sigma=0.2)
    params = jnp.ones(4)

    def run(seed):
        state, _ = dynax.control.run_pgpe(
            pgpe, objective, params, jax.random.key(seed), args.generations, progress=False
        )
        return jax.block_until_ready(state.mean)

    start = time.perf_counter()
    run(0)
    first = time.perf_counter() - start
    times, cpu_times = [], []
    for seed in range(1, args.repeats + 1):
        start, cpu = time.perf_counter(), time.process_time()
        run(seed)
        times.append(time.perf_counter() - start)
        cpu_times.append(time.process_time() - cpu)
    pathlib.Path(f"{args.out}.rank{args.rank}").write_text(
        json.dumps(
            {
                "best_s": min(times),
                "times_s": times,
                "cpu_s": min(cpu_times),
                "first_call_s": first,
                "devices": jax.device_count(),
                "processes": jax.process_count(),
                "device_kind": jax.devices()[0].device_kind,
            }
        )
    )


def _free_port():
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def launch(args, processes, population, tmp):
    out = tmp / f"scaling_{processes}_{population}.json"
    port = _free_port()
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    common = ["--steps", str(args.steps), "--generations", str(args.generations), "--repeats", str(args.repeats)]
    procs = [
        subprocess.Popen(
            [
                sys.executable,
                __file__,
                "--worker",
                "--processes",
                str(processes),
                "--rank",
                str(rank),
                "--port",
                str(port),
                "--population",
                str(population),
                "--out",
                str(out),
                *common,
            ],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for rank in range(processes)
    ]
    try:
        for p in procs:
            text, _ = p.communicate(timeout=args.timeout)
            if p.returncode:
                raise SystemExit(f"a worker failed ({processes} processes):\n{text[-3000:]}")
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    ranks = [json.loads(pathlib.Path(f"{out}.rank{r}").read_text()) for r in range(processes)]
    # The collectives keep the processes in step: the run takes as long as its slowest process; the
    # CPU seconds of all processes together are what the work cost, whatever else the machine runs.
    return dict(
        ranks[0], best_s=max(r["best_s"] for r in ranks), cpu_s=sum(r["cpu_s"] for r in ranks), per_process=ranks
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--processes", type=int, default=2)
    parser.add_argument("--population", type=int, default=512)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--generations", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=2, help="alternating rounds of the three set-ups; best taken")
    parser.add_argument("--timeout", type=float, default=900)
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "scaling.json"))
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--rank", type=int, default=0, help=argparse.SUPPRESS)
    parser.add_argument("--port", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        return worker(args)

    import tempfile

    n = args.processes
    if (os.cpu_count() or 1) < n:
        print(f"note: {n} processes on {os.cpu_count()} cores share cores; the efficiency will show it")
    load_before = os.getloadavg()
    runs = {"one": [], "strong": [], "weak": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        # Rounds alternate the three set-ups, so that a change in the machine's load touches all.
        for _ in range(args.rounds):
            runs["one"].append(launch(args, 1, args.population, tmp))
            runs["strong"].append(launch(args, n, args.population, tmp))
            runs["weak"].append(launch(args, n, n * args.population, tmp))
    load_after = os.getloadavg()
    one, strong, weak = (min(runs[k], key=lambda r: r["best_s"]) for k in ("one", "strong", "weak"))
    one_cpu, strong_cpu, weak_cpu = (min(r["cpu_s"] for r in runs[k]) for k in ("one", "strong", "weak"))
    strong_eff = one["best_s"] / (n * strong["best_s"])
    weak_eff = one["best_s"] / weak["best_s"]
    strong_cpu_eff = one_cpu / strong_cpu
    weak_cpu_eff = n * one_cpu / weak_cpu
    results = {
        "processes": n,
        "population": args.population,
        "steps": args.steps,
        "generations": args.generations,
        "device_kind": one["device_kind"],
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
        "one_process_s": one["best_s"],
        "strong_s": strong["best_s"],
        "weak_s": weak["best_s"],
        "strong_efficiency": strong_eff,
        "weak_efficiency": weak_eff,
        "one_process_cpu_s": one_cpu,
        "strong_cpu_s": strong_cpu,
        "weak_cpu_s": weak_cpu,
        "strong_cpu_efficiency": strong_cpu_eff,
        "weak_cpu_efficiency": weak_cpu_eff,
        "loadavg_before": load_before,
        "loadavg_after": load_after,
        "rounds": args.rounds,
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "runs": runs,
    }
    print(
        f"PGPE, {args.generations} generations of {args.population} acrobot rollouts of {args.steps} steps; "
        f"one CPU core ({one['device_kind']}) per process; load average {load_before[0]:.1f} -> {load_after[0]:.1f}"
    )
    print(f"  1 process:            {one['best_s']:.3f} s")
    print(
        f"  {n} processes, same work: {strong['best_s']:.3f} s -> strong-scaling efficiency {strong_eff:.2f} "
        f"(speed-up {one['best_s'] / strong['best_s']:.2f}x, ideal {n})"
    )
    print(f"  {n} processes, {n}x work:  {weak['best_s']:.3f} s -> weak-scaling efficiency {weak_eff:.2f}")
    print(
        f"  CPU seconds (all processes): {one_cpu:.3f} / {strong_cpu:.3f} / {weak_cpu:.3f} -> CPU efficiency "
        f"strong {strong_cpu_eff:.2f}, weak {weak_cpu_eff:.2f} (the cost of splitting, independent of the load)"
    )
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
