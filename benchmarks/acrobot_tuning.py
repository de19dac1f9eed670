"""How long `dynax control acrobot` takes to tune a swing-up from scratch, and how the result scores.

    python benchmarks/acrobot_tuning.py [--out benchmarks/results/acrobot_tuning.json] [--policy P.npz]
        [-- extra arguments for `dynax control acrobot`]

Runs the command a user runs, `python -m dynax control acrobot --out POLICY` (the default
search, nothing carried over from a saved controller), as a child process, and records:

- `wall_s`: its wall-clock time, imports and compilation included;
- `cpu_s`: its CPU time (user + system, `resource.getrusage(RUSAGE_CHILDREN)`): on a shared
  machine, what two free cores would need at most, as the search is mostly one busy thread;
- `load_average`: the 1-minute load average sampled every 10 s during the run (min, mean, max),
  and `uptime` before and after;
- the saved controller's scores by the leaderboard's rules (`dynax.control.performance` and
  `robustness`, the per-family table) and the time that evaluation takes.

The tuning's own output (its stages, with times) is passed through to the terminal.
"""

import argparse
import json
import os
import pathlib
import resource
import subprocess
import sys
import threading
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def _uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()
    except OSError:
        return ""


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=pathlib.Path, default=RESULTS / "acrobot_tuning.json")
    parser.add_argument("--policy", type=pathlib.Path, default=RESULTS / "acrobot_tuning_policy.npz")
    parser.add_argument("extra", nargs="*", help="further arguments for `dynax control acrobot`")
    args = parser.parse_args(argv)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "dynax", "control", "acrobot", "--out", str(args.policy), *args.extra]
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    print(" ".join(command[1:]), "|", _uptime(), flush=True)

    loads, done = [], threading.Event()

    def sample():
        while not done.wait(10.0):
            loads.append(os.getloadavg()[0])

    sampler = threading.Thread(target=sample, daemon=True)
    before, t0 = _uptime(), time.perf_counter()
    sampler.start()
    child = subprocess.run(command, env=env, cwd=ROOT, check=False)
    wall = time.perf_counter() - t0
    done.set()
    after = _uptime()
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    if child.returncode != 0:
        raise SystemExit(f"`{' '.join(command)}` failed with exit status {child.returncode}")
    loads = loads or [os.getloadavg()[0]]
    result = dict(
        command="python -m dynax control acrobot --out POLICY " + " ".join(args.extra),
        cpu_count=os.cpu_count(),
        wall_s=wall,
        cpu_s=usage.ru_utime + usage.ru_stime,
        max_rss_mb=usage.ru_maxrss / 1024,
        load_average=dict(min=min(loads), mean=sum(loads) / len(loads), max=max(loads), samples=len(loads)),
        uptime_before=before,
        uptime_after=after,
    )
    print(f"tuned in {wall:.0f} s wall, {result['cpu_s']:.0f} s CPU; load average {result['load_average']}", flush=True)

    import jax

    jax.config.update("jax_enable_x64", True)
    sys.path.insert(0, str(ROOT))
    from dynax import control

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _device import device_info

    controller = control.load_controller(args.policy).to_benchmark()
    t1 = time.perf_counter()
    perf = control.performance(controller)
    rob = control.robustness(controller)
    result |= dict(
        device=device_info(),
        performance=perf.as_dict(),
        robustness=dict(score=rob.score, families=rob.table()),
        evaluation_s=time.perf_counter() - t1,
        targets=dict(performance=0.70, robustness=0.80, minutes=15),
    )
    args.out.write_text(json.dumps(result, indent=2))
    table = ", ".join(f"{k} {100 * v:.1f} %" for k, v in rob.table().items())
    print(f"performance {perf.score:.3f}, robustness {rob.score:.3f} ({table})")
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
