"""Every benchmark before and after the vocabulary redesign, side by side: after/before time ratios.

Both trees are exported from git (`git archive`) into a temporary folder, and each benchmark script
of `benchmarks/` that exists in both runs from its own tree (its spelling of the API is that tree's;
the workload is the same) in a fresh subprocess with `PYTHONPATH` at that tree, the same Python and
the same arguments. The runs alternate before/after, the order flipping every round (ABBA), so a
machine whose load drifts loads both sides alike; the ratio of each pair is what is reported, with
its spread over the rounds.

Measured for every run: the subprocess's wall time and CPU time (user + system, children included):
the *cold* cost, import and compilation included. From the JSON each benchmark writes, every time it
reports (warm calls, compile times, first calls) is paired by name; rows timing code that is not
dynax's (numpy, scipy, MuJoCo, gymnasium, evosax, hand-written scans, bare diffrax) are kept apart
as *controls*: their ratio shows how far the machine alone moves a ratio. Every other number in the
JSON (estimates, losses, rewards, memory) is compared too, and differences are listed.

Run (about an hour on the 2-core machine):

    nice -n 5 python benchmarks/redesign_ab.py --before ba17e60 --after HEAD [--rounds 3] [--only a,b]

Writes `benchmarks/results/redesign_ab/results.json` and `ratios.png`.
"""

import argparse
import json
import math
import os
import pathlib
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "redesign_ab"

# name -> (arguments, rounds at most); `{json}` is the file (or folder) the script writes into.
# Sizes are cut where the cost is in a reference that is not dynax (MuJoCo, gymnasium, scipy's
# DOP853), the same on both sides.
BENCHMARKS = {
    "identify": (["--repeats", "3", "--out", "{json}/identify.json"], 3),
    "eager_simulate": (["--reps", "5", "--json", "{json}/eager_simulate.json"], 3),
    "pgpe": (["--repeats", "3", "--out", "{json}/pgpe.json"], 3),
    "levenberg_marquardt": (["--solvers", "dynax", "--json", "{json}/levenberg_marquardt.json"], 3),
    "diagnose": (["--out", "{json}"], 3),
    "rollout": (
        ["--devices", "2", "--batch", "256", "--reps", "3", "--gym-steps", "2000", "--json", "{json}/rollout.json"],
        3,
    ),
    "simulate_paths": (["--references", "1", "--reps", "3", "--json", "{json}/simulate_paths.json"], 2),
    "helicopter_learning": (["--out", "{json}"], 2),
}
NOT_RUN = {
    "acrobot_tuning": "not in the tree before",
    "quadrotor_fit": "not in the tree before",
    "leaderboard": "not in the tree before",
    "rollout_profile": "prints only (no JSON); its programs are rollout.py's",
    "warm_profile": "prints only (no JSON); its workload is identify.py's",
    "crossfit_profile": "prints only (no JSON); its workload is diagnose.py's",
    "same_results": "compares results, times nothing; not in the tree before",
    "scaling": "several jax.distributed processes: its scaling needs an idle machine; PGPE itself is in pgpe",
}
# Times a script prints but does not write (levenberg_marquardt.py writes its JSON only beside optimistix's run).
LOG_TIMES = {
    "levenberg_marquardt": re.compile(
        r"(?P<solver>\w+)\s+identify cold\s+(?P<cold_s>[\d.]+) s \(fits\s+(?P<cold_fits_s>[\d.]+)\), "
        r"warm\s+(?P<warm_s>[\d.]+) s \(fits\s+(?P<warm_fits_s>[\d.]+)\)"
    ),
}
COLD = re.compile(r"first|compile_s|cold|with compilation")  # not "second call (compiled)"
CONTROL_WORDS = ("numpy", "scipy", "mujoco", "gymnasium", "evosax", "hand-written", "bare", "diffeqsolve")
TIME_SUFFIXES = ("_s", "_ms", "seconds")
NOT_TIMES = ("target_s", "horizon_s", "episode_s", "duration_s")
NOT_VALUES = ("ratio", "speedup", "over", "per_s", "per_cpu", "rss", "efficiency", "load", "count", "cores", "history")


def export(commit, folder):
    """The tree of `commit` under `folder`, with `shared/` beside it (the DFKI data's path)."""
    folder.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(REPO), "archive", commit], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    sha = subprocess.run(["git", "-C", str(REPO), "rev-parse", commit], check=True, capture_output=True, text=True)
    return sha.stdout.strip()


def flatten(tree, prefix=""):
    """Numeric leaves of a JSON tree by path; lists of dicts by index, lists of numbers skipped."""
    out = {}
    if isinstance(tree, dict):
        for key, value in tree.items():
            out.update(flatten(value, f"{prefix}/{key}" if prefix else str(key)))
    elif isinstance(tree, list) and tree and all(isinstance(v, dict) for v in tree):
        for i, value in enumerate(tree):
            label = value.get("call", value.get("horizon_s", i))
            out.update(flatten(value, f"{prefix}[{label}]"))
    elif isinstance(tree, bool):
        out[prefix] = float(tree)
    elif isinstance(tree, int | float):
        out[prefix] = float(tree)
    return out


def normalise(path):
    """The same row under both trees' names (`dynax.control.x` was `dynax.x` before)."""
    return path.replace("dynax.control.", "dynax.")


def kind(path):
    """'time' (with 'cold'/'warm' and 'control'/'dynax') or 'value'."""
    key = path.rsplit("/", 1)[-1]
    timed = key.endswith(TIME_SUFFIXES) or "_seconds_" in key  # gauss_newton_seconds_to_em_free_loss
    if timed and key not in NOT_TIMES and "per_" not in key:  # not a rate (steps_per_cpu_s)
        phase = "cold" if COLD.search(path) else "warm"
        owner = "control" if any(w in path.lower() for w in CONTROL_WORDS) else "dynax"
        return f"time:{phase}:{owner}"
    if any(w in key.lower() for w in NOT_VALUES) or "date" in key or "/ratios/" in path:
        return None
    return "value"


def run_one(tree, name, arguments, scratch, log):
    folder = scratch / f"{name}-{tree.name}-{time.time_ns()}"
    folder.mkdir()
    argv = [a.replace("{json}", str(folder)) for a in arguments]
    env = dict(os.environ, PYTHONPATH=str(tree), JAX_PLATFORMS="cpu")
    env.pop("XLA_FLAGS", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    with open(log, "w") as stream:
        done = subprocess.run(
            [sys.executable, str(tree / "benchmarks" / f"{name}.py"), *argv],
            cwd=tree,
            env=env,
            stdout=stream,
            stderr=subprocess.STDOUT,
            timeout=1800,
        )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        raise RuntimeError(f"{name} in {tree} exited {done.returncode}; see {log}")
    leaves = {}
    for file in sorted(folder.glob("*.json")):
        leaves.update(flatten(json.loads(file.read_text())))
    shutil.rmtree(folder)
    if name in LOG_TIMES and not leaves:
        for match in LOG_TIMES[name].finditer(log.read_text()):
            fields = match.groupdict()
            solver = fields.pop("solver")
            leaves.update({f"solvers/{solver}/{k}": float(v) for k, v in fields.items()})
    leaves = {normalise(k): v for k, v in leaves.items()}
    leaves["process/wall_s (cold)"] = wall
    leaves["process/cpu_s (cold)"] = cpu
    return {"wall_s": wall, "cpu_s": cpu, "load_average": os.getloadavg(), "leaves": leaves}


def summarise(runs):
    """Per metric: the after/before ratio of each round, median and spread; values compared."""
    metrics, values = {}, {}
    rounds = sorted({r["round"] for r in runs})
    for rnd in rounds:
        pair = {r["tree"]: r["leaves"] for r in runs if r["round"] == rnd}
        if set(pair) != {"before", "after"}:
            continue
        for path in sorted(set(pair["before"]) & set(pair["after"])):
            b, a = pair["before"][path], pair["after"][path]
            what = "time:cold:dynax" if path.startswith("process/") else kind(path)
            if what is None:
                continue
            if what == "value":
                scale = max(abs(b), abs(a), 1e-300)
                values[path] = max(values.get(path, 0.0), abs(a - b) / scale)
            elif b > 0 and a > 0:
                entry = metrics.setdefault(path, {"kind": what, "before": [], "after": [], "ratios": []})
                entry["before"].append(b)
                entry["after"].append(a)
                entry["ratios"].append(a / b)
    for entry in metrics.values():
        r = np.asarray(entry["ratios"])
        entry.update(
            ratio_median=float(np.median(r)),
            ratio_min=float(r.min()),
            ratio_max=float(r.max()),
            ratio_of_medians=float(np.median(entry["after"]) / np.median(entry["before"])),
        )
    return metrics, values


def resummarise(result, logs):
    """Recompute every benchmark's kinds and headline from its stored pairs (after a change of the
    classification), and add the times a script only printed, from the runs' logs."""
    for name, entry in result["benchmarks"].items():
        metrics = entry["metrics"]
        for path, metric in list(metrics.items()):
            metric["kind"] = "time:cold:dynax" if path.startswith("process/") else kind(path)
            if not (metric["kind"] or "").startswith("time"):
                del metrics[path]
        entry["values_differing"] = {p: d for p, d in entry["values_differing"].items() if kind(p) == "value"}
        if name in LOG_TIMES:
            pairs = {}
            for run in entry["runs"]:
                text = (logs / f"{name}.{run['tree']}.{run['round']}.log").read_text()
                for match in LOG_TIMES[name].finditer(text):
                    fields = match.groupdict()
                    solver = fields.pop("solver")
                    for key, value in fields.items():
                        by_round = pairs.setdefault(f"solvers/{solver}/{key}", {})
                        by_round.setdefault(run["round"], {})[run["tree"]] = float(value)
            for path, rounds in pairs.items():
                full = [r for r in sorted(rounds) if set(rounds[r]) == {"before", "after"}]
                if full:
                    b = [rounds[r]["before"] for r in full]
                    a = [rounds[r]["after"] for r in full]
                    ratios = np.asarray(a) / np.asarray(b)
                    metrics[path] = {
                        "kind": kind(path),
                        "before": b,
                        "after": a,
                        "ratios": ratios.tolist(),
                        "ratio_median": float(np.median(ratios)),
                        "ratio_min": float(ratios.min()),
                        "ratio_max": float(ratios.max()),
                        "ratio_of_medians": float(np.median(a) / np.median(b)),
                    }
        entry["headline"] = headline(metrics)


def geomean(xs):
    return float(math.exp(np.mean(np.log(xs)))) if xs else float("nan")


def headline(metrics):
    """Per benchmark: process wall and CPU ratios, and the geometric means of dynax's and the controls' rows."""
    out = {}
    for group, wanted in (
        ("process wall (cold)", lambda p, m: p == "process/wall_s (cold)"),
        ("process CPU (cold)", lambda p, m: p == "process/cpu_s (cold)"),
        ("dynax, warm", lambda p, m: m["kind"] == "time:warm:dynax"),
        ("dynax, warm CPU", lambda p, m: m["kind"] == "time:warm:dynax" and "cpu" in p.lower()),
        ("dynax, compile / first call", lambda p, m: m["kind"] == "time:cold:dynax" and not p.startswith("process")),
        ("controls (not dynax)", lambda p, m: m["kind"].endswith("control")),
    ):
        chosen = [m for p, m in metrics.items() if wanted(p, m)]
        if chosen:
            per_round = np.asarray([m["ratios"] for m in chosen if len(m["ratios"]) == len(chosen[0]["ratios"])])
            rounds = [geomean(list(per_round[:, k])) for k in range(per_round.shape[1])]
            out[group] = {
                "ratio": geomean([m["ratio_median"] for m in chosen]),
                "round_min": min(rounds),
                "round_max": max(rounds),
                "rows": len(chosen),
            }
    if "dynax, warm" in out and "controls (not dynax)" in out:  # the machine's share taken out
        out["dynax, warm / controls"] = {
            k: out["dynax, warm"][k] / out["controls (not dynax)"][k] if k != "rows" else out["dynax, warm"][k]
            for k in ("ratio", "round_min", "round_max", "rows")
        }
    return out


def plot(summary, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = ["process wall (cold)", "process CPU (cold)", "dynax, warm", "controls (not dynax)"]
    names = list(summary)
    fig, ax = plt.subplots(figsize=(11, 4.5))
    width = 0.8 / len(groups)
    for g, group in enumerate(groups):
        xs, ys, lo, hi = [], [], [], []
        for i, name in enumerate(names):
            h = summary[name]["headline"].get(group)
            if h:
                xs.append(i + (g - (len(groups) - 1) / 2) * width)
                ys.append(h["ratio"])
                lo.append(max(h["ratio"] - h["round_min"], 0))
                hi.append(max(h["round_max"] - h["ratio"], 0))
        ax.bar(xs, ys, width, yerr=[lo, hi], capsize=2, label=group)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.axhspan(0.95, 1.05, color="0.9", zorder=0)
    ax.set_xticks(range(len(names)), names, rotation=20, ha="right")
    ax.set_ylabel("after / before (time; < 1 is faster)")
    pairs = sorted({len(summary[n]["runs"]) // 2 for n in names})
    spread = "one pair each, no spread" if pairs == [1] else f"{pairs[0]}-{pairs[-1]} ABBA pairs; bars: spread"
    ax.set_title(f"Vocabulary redesign: every benchmark after / before ({spread})")
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", default="ba17e60", help="commit before the redesign (default ba17e60)")
    parser.add_argument("--after", default="HEAD", help="commit after it (default HEAD)")
    parser.add_argument("--rounds", type=int, default=3, help="ABBA rounds at most (each benchmark has its own cap)")
    parser.add_argument("--only", default=None, help="comma-separated benchmark names")
    parser.add_argument("--out", type=pathlib.Path, default=OUT)
    parser.add_argument("--first", choices=("before", "after"), default="before", help="the side run first in round 0")
    parser.add_argument(
        "--set", action="append", default=[], metavar="NAME=ARGS", help="replace a benchmark's arguments"
    )
    parser.add_argument("--keep", action="store_true", help="keep the other benchmarks' entries of results.json")
    parser.add_argument(
        "--resummarise", action="store_true", help="only recompute results.json's summaries and figure from its pairs"
    )
    args = parser.parse_args()
    for item in args.set:
        name, _, rest = item.partition("=")
        BENCHMARKS[name] = (rest.split(), BENCHMARKS[name][1])
    names = args.only.split(",") if args.only else list(BENCHMARKS)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.resummarise:
        result = json.loads((args.out / "results.json").read_text())
        resummarise(result, args.out / "logs")
        (args.out / "results.json").write_text(json.dumps(result, indent=1) + "\n")
        report(result)
        plot(result["benchmarks"], args.out / "ratios.png")
        return
    scratch = pathlib.Path(tempfile.mkdtemp(prefix="redesign_ab-"))
    (scratch / "shared").symlink_to(REPO.parent / "shared" if (REPO.parent / "shared").exists() else "/work/shared")
    trees = {"before": scratch / "before", "after": scratch / "after"}
    commits = {side: export(getattr(args, side), trees[side]) for side in trees}
    logs = args.out / "logs"
    logs.mkdir(exist_ok=True)
    print(f"before {commits['before'][:9]}, after {commits['after'][:9]}; scratch {scratch}", flush=True)
    result = {
        "command": "nice -n 5 python benchmarks/redesign_ab.py " + " ".join(sys.argv[1:]),
        "commits": commits,
        "python": sys.version.split()[0],
        "cpu_count": os.cpu_count(),
        "niceness": os.nice(0),
        "start": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "load_average_start": os.getloadavg(),
        "arguments": {n: BENCHMARKS[n][0] for n in names},
        "not_run": NOT_RUN,
        "benchmarks": {},
    }
    previous = args.out / "results.json"
    if args.keep and previous.exists():
        kept = json.loads(previous.read_text())
        result["benchmarks"] = {n: e for n, e in kept["benchmarks"].items() if n not in names}
        result["arguments"] = {**kept.get("arguments", {}), **result["arguments"]}
        result["earlier_invocations"] = kept.get("earlier_invocations", []) + [
            {k: kept.get(k) for k in ("command", "commits", "start", "end", "load_average_1min_range")}
        ]
    runs = {n: [] for n in names}
    for rnd in range(args.rounds):
        order = ("before", "after") if (rnd % 2 == 0) == (args.first == "before") else ("after", "before")
        for name in names:
            if rnd >= BENCHMARKS[name][1]:
                continue
            for side in order:
                log = logs / f"{name}.{side}.{rnd}.log"
                run = run_one(trees[side], name, BENCHMARKS[name][0], scratch, log)
                runs[name].append(dict(run, tree=side, round=rnd))
                print(
                    f"[{time.strftime('%H:%M:%S')}] round {rnd} {name:20s} {side:6s} {run['wall_s']:7.1f} s wall "
                    f"{run['cpu_s']:7.1f} s CPU  load {run['load_average'][0]:.1f}",
                    flush=True,
                )
            metrics, values = summarise(runs[name])
            result["benchmarks"][name] = {
                "headline": headline(metrics),
                "metrics": metrics,
                "values_differing": {p: d for p, d in values.items() if d > 1e-9},
                "values_compared": len(values),
                "runs": [{k: v for k, v in r.items() if k != "leaves"} for r in runs[name]],
            }
            result["end"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
            result["load_average_end"] = os.getloadavg()
            loads = [r["load_average"][0] for rs in runs.values() for r in rs] or [0.0]
            result["load_average_1min_range"] = [min(loads), max(loads)]
            (args.out / "results.json").write_text(json.dumps(result, indent=1) + "\n")
    report(result)
    plot(result["benchmarks"], args.out / "ratios.png")
    shutil.rmtree(scratch)


def report(result):
    print("\nafter / before (median over rounds; [min, max] of the rounds' geometric means):")
    for name, entry in result["benchmarks"].items():
        cells = "; ".join(
            f"{g} {h['ratio']:.3f} [{h['round_min']:.3f}, {h['round_max']:.3f}]" for g, h in entry["headline"].items()
        )
        print(f"  {name:20s} {cells}")
        for path, diff in entry["values_differing"].items():
            print(f"      value differs: {path} (relative {diff:.1e})")
    groups = (
        "process CPU (cold)",
        "process wall (cold)",
        "dynax, warm CPU",
        "dynax, warm",
        "controls (not dynax)",
        "dynax, warm / controls",
        "dynax, compile / first call",
    )
    print("\n| benchmark | pairs | " + " | ".join(groups) + " |")
    print("|---|---:|" + "---:|" * len(groups))
    for name, entry in result["benchmarks"].items():
        h = entry["headline"]
        cells = [
            f"{h[g]['ratio']:.2f}"
            + (f" ({h[g]['round_min']:.2f}-{h[g]['round_max']:.2f})" if h[g]["round_min"] != h[g]["round_max"] else "")
            if g in h
            else "-"
            for g in groups
        ]
        print(f"| `{name}` | {len(entry['runs']) // 2} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
