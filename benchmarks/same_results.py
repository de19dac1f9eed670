"""Do two trees of dynax give the same results? The byte-for-byte check behind a change made for speed alone.

Runs, in the tree on `PYTHONPATH`, the workloads of `identify.py` and `diagnose.py` and the CLI's demo, and
writes every result's JSON (`to_json()`, and the demo's `report.json`) into one file, floats at full
precision:

- `identify.py`'s 100,000 samples of acrobot data by `Dynamic(lowpass_hz=None)`, `Power()` and `Energy()`
  (its settings: no refinement, no held-out part, no consistency check);
- `identify` with its defaults on `diagnose.py`'s 40 s acrobot file (Coulomb friction hidden at the elbow);
- `diagnose` with its defaults on that file and on the second file of the same size;
- `dynax demo --seed 0` (the report it writes).

Run it once per tree, then compare:

    PYTHONPATH=<tree> python benchmarks/same_results.py --out before.json
    PYTHONPATH=<tree> python benchmarks/same_results.py --out after.json
    python benchmarks/same_results.py --compare before.json after.json

`--compare` prints every path where the two differ (with `--tolerance`, only differences larger than that,
relative) and exits with status 1 if any does. Entries that would time a run (`timings`, `wall_s`, `cpu_s`,
`elapsed_s`, `*_seconds`) are left out of the comparison (these results hold none today).
"""

import argparse
import json
import math
import os
import pathlib
import subprocess
import sys
import tempfile

TIMING_KEYS = ("timings", "wall_s", "cpu_s", "elapsed_s")


def _records(folder: pathlib.Path):
    from dynax import Acrobot, CoulombFriction, Extended, load_trajectory, save_trajectory
    from dynax.synthetic import DEMO_TRUTH_PHYSICAL, Multisine, synthetic_trajectory

    truth = Extended(Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL), (CoulombFriction(1, 0.25),))
    out = []
    for seed in (0, 1):
        record = synthetic_trajectory(
            truth, duration=40.0, dt=0.01, excitation=Multisine(amplitude=2.0), seed=seed, system_name="acrobot"
        )
        path = folder / f"acrobot_40s_{seed}.csv"
        save_trajectory(record, path)
        out.append(load_trajectory(path, "acrobot"))
    return out


def _identify_data():
    import jax.numpy as jnp
    import numpy as np

    import dynax

    n, dt = 100_000, 0.01
    ts = dt * np.arange(n)
    rng = np.random.default_rng(0)
    us = np.repeat(rng.uniform(-2, 2, size=n // 50 + 1), 50)[:n, None]
    xs = dynax.simulate(dynax.Acrobot(), jnp.array([0.2, 0.0, 0.0, 0.0]), jnp.asarray(ts), jnp.asarray(us)).xs
    return dynax.Trajectory(jnp.asarray(ts), xs, jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot")


def run(out: pathlib.Path) -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    import dynax

    results = {}
    data = _identify_data()
    for name, method in (
        ("dynamic", dynax.Dynamic(lowpass_hz=None)),
        ("power", dynax.Power()),
        ("energy", dynax.Energy()),
    ):
        fit = dynax.identify(
            dynax.Acrobot(), data, method, refine=False, validation=dynax.Validate(holdout=0), consistency="off"
        )
        results[f"identify.py/{name}"] = fit.to_json()
        print(f"identify.py/{name} done", flush=True)
    with tempfile.TemporaryDirectory() as folder:
        first, other = _records(pathlib.Path(folder))
        results["identify/defaults"] = dynax.identify(dynax.Acrobot(), first).to_json()
        print("identify/defaults done", flush=True)
        for label, record in (("first", first), ("other", other)):
            results[f"diagnose/{label}"] = dynax.diagnose(dynax.Acrobot(), record).to_json()
            print(f"diagnose/{label} done", flush=True)
        # the records' paths name the temporary folder: written as where it is in every tree
        results = json.loads(json.dumps(results).replace(str(folder), "<records>"))
    with tempfile.TemporaryDirectory() as folder:
        demo = pathlib.Path(folder) / "demo"
        env = dict(os.environ, DYNAX_NO_CACHE="1")
        subprocess.run(
            [sys.executable, "-m", "dynax", "demo", "--seed", "0", "--out", str(demo), "-q"], check=True, env=env
        )
        results["demo/report.json"] = json.loads((demo / "report.json").read_text())
    print("demo done", flush=True)
    out.write_text(json.dumps(results, indent=1, sort_keys=True, allow_nan=True) + "\n")
    print(f"wrote {out}")


def _differences(a, b, path, tolerance, found):
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if key in TIMING_KEYS or key.endswith("_seconds"):
                continue
            if key not in a or key not in b:
                found.append(f"{path}/{key}: only in {'after' if key not in a else 'before'}")
            else:
                _differences(a[key], b[key], f"{path}/{key}", tolerance, found)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            found.append(f"{path}: {len(a)} entries against {len(b)}")
        for i, (x, y) in enumerate(zip(a, b)):
            _differences(x, y, f"{path}[{i}]", tolerance, found)
    elif isinstance(a, float) and isinstance(b, float) and tolerance > 0:
        same = (math.isnan(a) and math.isnan(b)) or abs(a - b) <= tolerance * max(abs(a), abs(b))
        if not same:
            found.append(f"{path}: {a!r} against {b!r}")
    elif a != b and not (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)):
        found.append(f"{path}: {a!r} against {b!r}")


def compare(before: pathlib.Path, after: pathlib.Path, tolerance: float) -> int:
    a, b = json.loads(before.read_text()), json.loads(after.read_text())
    found: list[str] = []
    _differences(a, b, "", tolerance, found)
    for line in found:
        print(line)
    print(
        f"{len(found)} difference(s) over {len(a)} results"
        + (f" (relative tolerance {tolerance:g})" if tolerance else "")
    )
    return 1 if found else 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path)
    parser.add_argument("--compare", nargs=2, type=pathlib.Path, metavar=("BEFORE", "AFTER"))
    parser.add_argument("--tolerance", type=float, default=0.0)
    args = parser.parse_args()
    if args.compare:
        sys.exit(compare(*args.compare, args.tolerance))
    if args.out is None:
        parser.error("--out or --compare")
    run(args.out)


if __name__ == "__main__":
    main()
