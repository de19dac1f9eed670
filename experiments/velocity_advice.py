"""Is `--velocities positions` (the `lag` check's advice) better than the logged velocities on coarse encoders
at high rates? Records made apart from dynax (`experiments/velocity_lag.arm_record`: the arm by scipy's DOP853,
10 s, no noise), the angles rounded to encoder counts, the velocity logged as the backward difference of the
counts (`backward`, the DFKI rig's way), as a driver's causal first-order filter of that difference (`filter`),
or as the exact velocity through such a filter (`tachometer`: measured apart from the counts); a filter's lag
makes a phase error of 0.006 rad at the motion's frequency, just over the warning. Each record is written to CSV
and read by `load_trajectory` as logged and with `velocities="positions"`; `identify` (defaults, `Dynamic`)
fits both.

    python experiments/velocity_advice.py [--seeds 2] [--first-seed 0] [--rates 100,500,1000]
        [--bits 12,14,16,exact] [--kinds backward,filter] [--out experiments/results/velocity_advice.json]
    python experiments/velocity_advice.py --table RESULTS.json [...]   # the markdown table of one or more runs

A run writes its rows as it goes (`filter` is skipped at 100 Hz, where the backward difference alone is refused);
`--table` merges runs and prints, per rate, encoder and logged velocity, the root mean square over seeds of each
parameter's percent error with the logged velocities and with `--velocities positions`, the largest error in the
fit's own standard errors, and the largest amount, in the larger of the two fits' standard errors, by which the
switch made a parameter's error grow.
"""

import argparse
import json
import pathlib
import sys
import tempfile
import warnings

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
NAMES = ("theta1", "theta2", "theta3", "theta4", "theta5", "theta6", "theta7")


def logged(ts, q, kind, phase_target=0.006, frequency=None, exact=None):
    """The velocity column a driver logs: the backward difference of the counts ("backward"), or that passed
    through a causal first-order filter whose lag (with the difference's half sample) makes a phase error
    `phase_target` at `frequency` (rad/s) ("filter"), or the exact velocity `exact` through a filter of that
    phase error (a "tachometer": measured apart from the counts, without their noise)."""
    v = np.empty_like(q)
    v[1:] = np.diff(q, axis=0) / np.diff(ts)[:, None]
    v[0] = v[1]
    if kind == "backward":
        return v
    dt = float(np.median(np.diff(ts)))
    tau = max(phase_target / frequency - dt / 2, 0.0)
    if kind == "tachometer":
        v, tau = exact.copy(), phase_target / frequency
    out = v.copy()
    for i in range(1, len(ts)):
        a = (ts[i] - ts[i - 1]) / (tau + ts[i] - ts[i - 1])
        out[i] = out[i - 1] + a * (v[i] - out[i - 1])
    return out


def quantized(q, bits):
    if bits is None:
        return q
    step = 2 * np.pi / 2**bits
    return np.round(q / step) * step


def fit(path, velocities):
    import dynax

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        record = dynax.load_trajectory(path, "acrobot", velocities=velocities)
        result = dynax.identify(dynax.Acrobot(), [record])
    return record, result, [str(w.message)[:160] for w in caught]


def table(paths):
    rows = [r for p in paths for r in json.loads(pathlib.Path(p).read_text())]
    cells = {}
    for r in rows:
        cells.setdefault((r["rate_hz"], str(r["bits"]), r["kind"]), []).append(r)
    print(
        "| rate | encoder | logged | seeds | check | velocities | "
        + " | ".join(NAMES)
        + " | largest error, SE | worst growth, SE |"
    )
    print("|---" * (8 + len(NAMES)) + "|")
    for (rate, bits, kind), sub in sorted(cells.items(), key=lambda c: (c[0][0], c[0][1], c[0][2])):
        check = sorted({f.split(":")[0].split("/")[1] for r in sub for f in r["findings"] if f.startswith("lag")})
        growth = max(  # each parameter's error grown by the switch, in the larger of the two fits' standard errors
            (abs(p) - abs(m)) / max(abs(m / zm) if zm else 0.0, abs(p / zp) if zp else 0.0, 1e-12)
            for r in sub
            for m, zm, p, zp in zip(
                r["measured"]["percent"],
                r["measured"]["in_errors"],
                r["positions"]["percent"],
                r["positions"]["in_errors"],
            )
        )
        for how, label in (("measured", "logged"), ("positions", "positions")):
            rms = np.sqrt(np.mean(np.square([r[how]["percent"] for r in sub]), axis=0))
            first = f"| {rate:g} Hz | {bits} | {kind} | {len(sub)} | {'/'.join(check) or 'none'} |"
            head = first if how == "measured" else "| | | | | |"
            worst = max(abs(z) for r in sub for z in r[how]["in_errors"])
            tail = f" | {worst:.1f} | {growth:+.1f} |" if how == "positions" else f" | {worst:.1f} | |"
            print(head + f" {label} | " + " | ".join(f"{v:.1f}" for v in rms) + tail)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--rates", default="100,500,1000")
    parser.add_argument("--bits", default="12,14,16,exact")
    parser.add_argument("--kinds", default="backward,filter")
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--table", nargs="+", help="print the table of these result files, and run nothing")
    parser.add_argument("--out", default=str(REPO / "experiments" / "results" / "velocity_advice.json"))
    args = parser.parse_args()
    if args.table:
        return table(args.table)
    sys.path.insert(0, str(REPO))
    import jax

    jax.config.update("jax_enable_x64", True)
    import dynax
    from dynax.internal import choose_filter, velocity_lag
    from experiments.velocity_lag import arm_record, TRUTH

    rows = []
    out = pathlib.Path(args.out)
    tmp = pathlib.Path(tempfile.mkdtemp())
    for rate in [float(r) for r in args.rates.split(",")]:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            ts, xs, tau = arm_record(rate, seed, duration=args.duration, noise="none")
            freq = velocity_lag(ts, xs[:, 0], xs[:, 2]).frequency
            for bits in [None if b == "exact" else int(b) for b in args.bits.split(",")]:
                q = quantized(xs[:, :2], bits)
                for kind in args.kinds.split(","):
                    if kind == "filter" and rate == 100.0:
                        continue  # the backward difference alone is past the warning (0.024 rad) at 100 Hz
                    v = logged(ts, q, kind, frequency=freq, exact=xs[:, 2:])
                    path = tmp / f"r{rate:g}_s{seed}_b{bits}_{kind}.csv"
                    data = np.column_stack([ts, q, v, np.zeros_like(tau), tau])
                    np.savetxt(path, data, delimiter=",", header="t,q1,q2,dq1,dq2,tau1,tau2", comments="")
                    row = {"rate_hz": rate, "seed": seed, "bits": bits or "exact", "kind": kind}
                    for how in ("measured", "positions"):
                        record, result, said = fit(path, how)
                        p, se = result.parameters, result.standard_errors
                        row[how] = {
                            "percent": [round(100 * (float(p[n]) / t - 1), 2) for n, t in zip(NAMES, TRUTH)],
                            "in_errors": [round((float(p[n]) - t) / float(se[n]), 2) for n, t in zip(NAMES, TRUTH)],
                            "filter": str(choose_filter(record))[:200],
                        }
                        if how == "measured":
                            check = dynax.check_records([record], estimated=())
                            row["findings"] = [f"{f.kind}/{f.severity}: {f.describe()[:120]}" for f in check.findings]
                    rows.append(row)
                    print(json.dumps(row), flush=True)
                    out.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
