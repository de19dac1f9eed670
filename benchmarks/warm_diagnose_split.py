"""Where a warm `diagnose` call spends its CPU time, by stage: the batch fits, the cross-fitted fold fits, the
equation-error and output-error screenings, and the rest.

The workload is `benchmarks/diagnose.py`'s (a 40 s, 100 Hz acrobot file with Coulomb friction hidden at the
elbow; the full candidate library; the last 30 % held out). A first call compiles; then a second call on the
same file and a call on another file of the same size each run under `cProfile` with a CPU-time clock (user +
system of every thread). A stage's time is the cumulative time of the function that runs it (`_fit_batch`:
the batch fits and their held-out rollouts; `_cross_fit`: the fold fits and the cross-fitted rollouts;
`screen`: the one-step screening; `rollout_screen`: the output-error screening), and "compiled" is the time
inside compiled calls made through `equinox.filter_jit` (the fits, rollouts, screening sensitivities). The
profiler inflates the Python work a little; the calls' CPU time is printed as measured under it.

The script runs on the tree before the vocabulary redesign too (`PYTHONPATH` at that tree; its spelling of the
API is tried second), so that the two trees' warm calls can be split alike:

    python benchmarks/warm_diagnose_split.py [--out DIR] [--plain] [--reports FILE]

Writes `DIR/warm_diagnose_split.json` when `--out` is given; prints the table. `--plain` times the calls without
the profiler (no split); `--reports FILE` writes the three calls' reports (`Report.to_json()`) to compare trees
or settings (e.g. the process pinned to one core with `taskset -c 0`, which sizes XLA's thread pool to one).
"""

import argparse
import cProfile
import json
import os
import pathlib
import pstats
import subprocess
import tempfile
import time
from typing import Any

import jax

jax.config.update("jax_enable_x64", True)

import dynax  # noqa: E402

# label -> (file, function) whose cumulative time is the stage's.
STAGES = {
    "batch fits + held-out rollouts (_fit_batch)": ("_forward.py", "_fit_batch"),
    "fold fits + cross-fitted rollouts (_cross_fit)": ("_forward.py", "_cross_fit"),
    "equation-error screening (screen)": ("_screening.py", "screen"),
    "output-error screening (rollout_screen)": ("_rollout_screening.py", "rollout_screen"),
}
COMPILED = ("_jit.py", "_call")


def records():
    """`benchmarks/diagnose.py`'s two files, written as contract CSVs and read back (this tree's spelling)."""
    try:
        from dynax import CoulombFriction, Extended, load_trajectory, save_trajectory
        from dynax.synthetic import DEMO_TRUTH_PHYSICAL, Multisine, synthetic_trajectory

        excitation: dict[str, Any] = {"excitation": Multisine(amplitude=2.0)}
    except ImportError:  # the tree before the redesign, which exported these from private modules only
        from dynax._data import load_trajectory, save_trajectory  # type: ignore[no-redef]  # private: old tree
        from dynax._model._extensions import CoulombFriction, Extended  # type: ignore[no-redef]  # private: old tree
        from dynax.synthetic import DEMO_TRUTH_PHYSICAL, synthetic_trajectory

        excitation = {"amplitude": 2.0}
    truth = Extended(dynax.Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL), (CoulombFriction(1, 0.25),))
    out = []
    with tempfile.TemporaryDirectory() as folder:
        for seed in (0, 1):
            record = synthetic_trajectory(truth, duration=40.0, dt=0.01, seed=seed, system_name="acrobot", **excitation)
            path = pathlib.Path(folder) / f"acrobot_40s_{seed}.csv"
            save_trajectory(record, path)
            out.append(load_trajectory(path, "acrobot"))
    return out


def _diagnose():
    """This tree's `diagnose(system, data)`."""
    if hasattr(dynax, "diagnose"):
        return lambda data: dynax.diagnose(dynax.Acrobot(), data)
    from dynax._diagnose import diagnose  # private: the tree before the redesign

    return lambda data: diagnose(dynax.Acrobot(), data, system_name="acrobot")  # pyright: ignore[reportCallIssue]


def split(stats: pstats.Stats) -> dict[str, float]:
    """CPU seconds of each stage (`STAGES`) and of the compiled calls."""
    table = stats.stats  # type: ignore[attr-defined]  # pstats' documented dictionary of (cc, nc, tt, ct, callers)
    out = dict.fromkeys(STAGES, 0.0)
    out["compiled calls (equinox.filter_jit)"] = 0.0
    for (filename, _, name), (_, _, tt, ct, _) in table.items():
        for label, key in STAGES.items():
            if (pathlib.Path(filename).name, name) == key:
                out[label] += ct
        if (pathlib.Path(filename).name, name) == COMPILED:
            out["compiled calls (equinox.filter_jit)"] += tt
    return out


def main():
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--out", default=None)
    parser.add_argument("--plain", action="store_true", help="time the calls without the profiler")
    parser.add_argument("--reports", default=None, help="write the three calls' reports (JSON) here")
    args = parser.parse_args()
    run = _diagnose()
    first, other = records()
    start = time.process_time()
    reports = {"first call (with compilation)": run(first).to_json()}
    result = {
        "first call cpu_s": time.process_time() - start,
        "profiled": not args.plain,
        "cores this process may use": len(os.sched_getaffinity(0)),
        "calls": {},
    }
    for label, record in (("second call (compiled)", first), ("another file of the same size", other)):
        profile = cProfile.Profile(time.process_time)
        cpu, wall = time.process_time(), time.perf_counter()
        reports[label] = (run(record) if args.plain else profile.runcall(run, record)).to_json()
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        if args.plain:
            result["calls"][label] = {"cpu_s": cpu, "wall_s": wall}
            print(f"{label}: {cpu:.2f} s CPU, {wall:.2f} s wall")
            continue
        parts = split(pstats.Stats(profile))
        staged = sum(v for k, v in parts.items() if k in STAGES)
        parts["the rest"] = cpu - staged
        result["calls"][label] = {"cpu_s": cpu, "wall_s": wall, "split_cpu_s": parts}
        print(f"{label}: {cpu:.2f} s CPU, {wall:.2f} s wall (under the profiler)")
        for key, seconds in parts.items():
            print(f"  {key:50s} {seconds:6.2f} s CPU ({seconds / cpu:4.0%})")
    if args.reports:
        pathlib.Path(args.reports).write_text(json.dumps(reports, indent=1, default=str) + "\n")
    if args.out:
        tree = pathlib.Path(dynax.__file__).resolve().parents[1]
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=tree, capture_output=True, text=True).stdout.strip()
        result["tree"] = commit or str(tree)
        out = pathlib.Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "warm_diagnose_split.json").write_text(json.dumps(result, indent=1) + "\n")
        print(f"wrote {out / 'warm_diagnose_split.json'}")


if __name__ == "__main__":
    main()
