"""Calibration of the held-out paired test of `diagnose`: its false-claim rate on data with no effect.

Two parts.

1. **Synthetic window differences** (fast; `--part synthetic`). Differences are made as `diagnose`
   makes them: each window averages `overlap` strides of a stationary noise, so neighbouring windows
   share data. The noise processes are AR(1) at the stride level (slowly changing excitation, rho
   0.5-0.97 per stride), ARMA(1,1), AR(1) with Student-t(3) innovations, and pure overlap (white noise). For each
   configuration (overlap, windows per run, runs: those of the tests, the helicopter flights and the
   DFKI records), `--reps` null records are tested; the rate of p below 0.05, 0.01 and
   0.001 is printed with its binomial standard error, for each estimator of `_statistics`:
   `flat_top` (the default), `truncated`, `obm` (overlapping batch means) and `nbm` (the earlier
   non-overlapping batch means). The same records shifted by half the per-window standard deviation
   of the differences give each estimator's power at 1 %, for comparison.

2. **Diagnosis runs with no hidden effect** (slow; `--part diagnosis`). The acrobot demo's truth
   without an effect (`CoulombFriction(1, 0)`), several seeds, refit mode: the verdict must be `none`
   and no candidate may pass; the smallest p-value of each run is printed.

3. **Several training runs, cross-fitted** (slow; `--part diagnosis-runs`). As part 2, but trained
   on three runs (the training parts of the demo runs of three seeds: other excitations, other noise)
   and held out on the first seed's validation part, so that the test pools the held-out run with
   each training run cross-fitted (`diagnose(..., selection=Selection(cross_fit=True))`, the default; two training runs
   are not cross-fitted).

    python experiments/test_calibration.py --part synthetic --reps 600
    python experiments/test_calibration.py --part diagnosis --seeds 40
    python experiments/test_calibration.py --part diagnosis-runs --seeds 40

Results are written to `experiments/results/test_calibration_<part>.json`.
"""

import argparse
import json
import pathlib
import time

import numpy as np
import scipy.signal

from dynax.internal import paired_block_test


def null_windows(rng, n_windows, overlap, process, substeps=5):
    """Overlapping-window averages of a stationary zero-mean noise at `substeps` per stride."""
    n = (n_windows + overlap) * substeps
    kind, param = process
    if kind == "ar1":
        e = scipy.signal.lfilter([1.0], [1.0, -(param ** (1 / substeps))], rng.normal(size=n))
    elif kind == "ar1_t3":
        e = scipy.signal.lfilter([1.0], [1.0, -(param ** (1 / substeps))], rng.standard_t(3, size=n))
    elif kind == "arma":  # ARMA(1,1): AR root param, MA coefficient 0.5, at the substep level
        e = scipy.signal.lfilter([1.0, 0.5], [1.0, -(param ** (1 / substeps))], rng.normal(size=n))
    elif kind == "white":
        e = rng.normal(size=n)
    else:
        raise ValueError(kind)
    e = e[::substeps][: n_windows + overlap]
    return np.convolve(e, np.ones(overlap) / overlap, "valid")[:n_windows]


CONFIGS = [  # (overlap, windows per run, runs): acrobot demo, helicopter 20 s at 0.5 / 1 s, DFKI 6 s records
    (10, 110, 1),
    (10, 110, 2),
    (20, 100, 2),
    (2, 400, 3),
    (10, 380, 1),
    (20, 380, 1),
    (10, 100, 3),
]
METHODS = ("flat_top", "truncated", "obm", "nbm")
PROCESSES = [("white", 0.0), ("ar1", 0.5), ("ar1", 0.9), ("ar1", 0.97), ("arma", 0.9), ("ar1_t3", 0.9)]


def synthetic(reps, seed=0):
    rng = np.random.default_rng(seed)
    rows = []
    for overlap, n_windows, n_runs in CONFIGS:
        runs = np.repeat(np.arange(n_runs), n_windows)
        for process in PROCESSES:
            p = {m: [] for m in METHODS}
            power = {m: [] for m in METHODS}
            # the shift for power: 0.5 of the per-window standard deviation of the differences
            ref = np.concatenate([null_windows(rng, n_windows, overlap, process) for _ in range(50)])
            shift = 0.5 * float(np.std(ref))
            for _ in range(reps):
                d = np.concatenate([null_windows(rng, n_windows, overlap, process) for _ in range(n_runs)])
                for method in p:
                    p[method].append(paired_block_test(d, runs, overlap, method=method).p_value)
                    power[method].append(paired_block_test(d + shift, runs, overlap, method=method).p_value)
            row = dict(
                overlap=overlap, windows=n_windows, runs=n_runs, process=f"{process[0]}({process[1]:g})", reps=reps
            )
            for method in p:
                pv, pw = np.asarray(p[method]), np.asarray(power[method])
                for a in (0.05, 0.01, 0.001):
                    row[f"{method}_rate_{a:g}"] = float(np.mean(pv < a))
                row[f"{method}_power_0.01"] = float(np.mean(pw < 0.01))
            rows.append(row)
            print(
                f"overlap {overlap:2d} n {n_windows:3d} x {n_runs} {row['process']:>11s}: "
                + "  ".join(
                    f"{m}: "
                    + " ".join(f"{row[f'{m}_rate_{a:g}']:.4f}" for a in (0.05, 0.01, 0.001))
                    + f" power@0.01 {row[f'{m}_power_0.01']:.2f}"
                    for m in p
                ),
                flush=True,
            )
    summary = {}
    for m in METHODS:
        for a in (0.05, 0.01, 0.001):
            rates = [r[f"{m}_rate_{a:g}"] for r in rows]
            summary[f"{m}_rate_{a:g}"] = dict(mean=float(np.mean(rates)), max=float(np.max(rates)))
        summary[f"{m}_power_0.01_mean"] = float(np.mean([r[f"{m}_power_0.01"] for r in rows]))
    se = {a: float(np.sqrt(a * (1 - a) / reps)) for a in (0.05, 0.01, 0.001)}
    print(
        "summary (mean / max over configurations; binomial s.e. of one rate:",
        ", ".join(f"{se[a]:.4f} at {a:g}" for a in se),
        ")",
    )
    for k, v in summary.items():
        print(f"  {k}: {v}")
    return dict(rows=rows, summary=summary, binomial_se=se)


def diagnosis(seeds, runs=1):
    import jax

    jax.config.update("jax_enable_x64", True)
    from dynax import Acrobot, CoulombFriction, diagnose, Selection
    from dynax.synthetic import demo_data

    rows = []
    for seed in range(seeds):
        t0 = time.perf_counter()
        _, train, validation = demo_data(CoulombFriction(1, 0.0), seed=1000 + seed)
        if runs > 1:  # more training runs: other seeds' excitations and noise, the same truth
            train = [train] + [
                demo_data(CoulombFriction(1, 0.0), seed=5000 + runs * seed + i)[1] for i in range(1, runs)
            ]
        j = diagnose(Acrobot(), train, validation, selection=Selection(discovery=False)).to_json()
        tested = [c for c in j["candidates"] if c.get("p_value") is not None]
        best = min(tested, key=lambda c: c["p_value"]) if tested else None
        row = dict(
            seed=1000 + seed,
            verdict=j["verdict"],
            findings=[f"{f['cause']}@{f['where']}" for f in j["findings"]],
            smallest_p=float(best["p_value"]) if best else None,
            n_tested=len(j["candidates"]),
            smallest_p_candidate=None
            if best is None
            else {k: best[k] for k in ("cause", "where", "gain", "coefficient", "runs_helped")},
            seconds=round(time.perf_counter() - t0, 1),
        )
        rows.append(row)
        print(row, flush=True)
    claims = sum(bool(r["findings"]) for r in rows)
    print(f"false claims: {claims} of {len(rows)} no-effect diagnoses")
    return dict(rows=rows, false_claims=claims)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=["synthetic", "diagnosis", "diagnosis-runs"], default="synthetic")
    parser.add_argument("--reps", type=int, default=600)
    parser.add_argument("--seeds", type=int, default=6)
    args = parser.parse_args()
    if args.part == "synthetic":
        out = synthetic(args.reps)
    else:
        out = diagnosis(args.seeds, runs=3 if args.part == "diagnosis-runs" else 1)
    path = pathlib.Path(__file__).parent / "results" / f"test_calibration_{args.part}.json"
    path.parent.mkdir(exist_ok=True)
    path.write_text(json.dumps(out, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
