"""A measured velocity column that lags its position: what it does to the identified parameters, and how well
`dynax.internal.velocity_lag` (the `lag` data check) tells it from clean records.

Records are made apart from dynax's model code (`tests.reference.arm_reference`, the two-link arm written out
with numpy, integrated by scipy's DOP853 on the recorded, possibly jittered, time stamps) and driven at the elbow
by a random multisine; encoder noise is added to the angles and white noise to the velocities. Faults: the
velocity shifted by whole samples, passed through a causal first-order low-pass (a driver's filter), or replaced
by the backward difference of the noisy angle (what a driver logs).

    python experiments/velocity_lag.py [--quick] [--seeds 10] [--out experiments/results/velocity_lag.json]

Prints (1) the bias of `identify` (default `Dynamic`, Python API, the check's warning ignored) on a clean 100 Hz
record and on each fault, and with the velocities estimated from the angles instead (`velocities="positions"`);
(2) the check on clean records (100 Hz to 1 kHz, three noise levels, uniform or jittered time, seeds): how often
it fires (false alarms), and the largest |lag| / std error and phase it read; (3) how often it fires on each fault;
(4) the six DFKI runs' logged velocities (their backward differences, exactly).

`--controls` instead runs the check on records that other studies use as clean: the calibration battery's
arm and axis cases (`tests/hidden_cases.py`, DOP853 with hidden effects, an input dead time among them) and the
demo's 14 seeds, and writes `velocity_lag_controls.json` beside `--out`. `--edges` instead places the start of
a lag that begins part way (`velocity_lag_edges.json`).
"""

import argparse
import json
import pathlib
import sys
import warnings

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
TRUTH = (1.333, 1.33, 1.0, 14.715, 9.81, 0.1, 0.1)
NAMES = ("theta1", "theta2", "theta3", "theta4", "theta5", "theta6", "theta7")
NOISE = {"none": (0.0, 0.0), "encoder": (1e-4, 0.01), "noisy": (1e-3, 0.1)}  # (angle rad, velocity rad/s) std


def arm_record(rate_hz, seed, duration=10.0, jitter=0.0, noise="encoder"):
    """`(ts, xs, tau2)`: the arm under a random elbow multisine, sampled at `rate_hz` (steps jittered by
    `jitter` times the interval, uniformly), with `NOISE[noise]` added."""
    from scipy.integrate import solve_ivp

    from tests.reference import arm_reference

    rng = np.random.default_rng(seed)
    freqs, phases = rng.uniform(0.2, 2.0, 6), rng.uniform(0, 2 * np.pi, 6)

    def drive(t):
        return 3.0 * float(np.sum(np.sin(2 * np.pi * freqs * t + phases))) / np.sqrt(6)

    dt = 1.0 / rate_hz
    steps = dt * (1.0 + jitter * rng.uniform(-1.0, 1.0, int(duration * rate_hz)))
    ts = np.concatenate([[0.0], np.cumsum(steps)])
    sol = solve_ivp(
        lambda t, x: arm_reference(TRUTH, x, (0.0, drive(t))),
        (0.0, ts[-1]),
        [0.2, 0.0, 0.0, 0.0],
        t_eval=ts,
        method="DOP853",
        rtol=1e-10,
        atol=1e-11,
    )
    xs = sol.y.T.copy()
    sq, sv = NOISE[noise]
    xs[:, :2] += sq * rng.standard_normal((len(ts), 2))
    xs[:, 2:] += sv * rng.standard_normal((len(ts), 2))
    return ts, xs, np.array([drive(t) for t in ts])


def shifted(ts, xs, k):
    out = xs.copy()
    out[k:, 2:] = xs[:-k, 2:]
    out[:k, 2:] = xs[0, 2:]
    return out


def low_passed(ts, xs, tau):
    out = xs.copy()
    for c in (2, 3):
        y = xs[0, c]
        for i in range(len(ts)):
            a = (ts[i] - ts[i - 1]) / (tau + ts[i] - ts[i - 1]) if i else 1.0
            y += a * (xs[i, c] - y)
            out[i, c] = y
    return out


def backward(ts, xs):
    out = xs.copy()
    out[1:, 2:] = np.diff(xs[:, :2], axis=0) / np.diff(ts)[:, None]
    out[0, 2:] = out[1, 2:]
    return out


FAULTS = {
    "shift 1 sample": lambda ts, xs: shifted(ts, xs, 1),
    "shift 2 samples": lambda ts, xs: shifted(ts, xs, 2),
    "shift 5 samples": lambda ts, xs: shifted(ts, xs, 5),
    "low-pass 5 ms": lambda ts, xs: low_passed(ts, xs, 0.005),
    "low-pass 10 ms": lambda ts, xs: low_passed(ts, xs, 0.010),
    "low-pass 30 ms": lambda ts, xs: low_passed(ts, xs, 0.030),
    "backward difference": backward,
}


def trajectory(ts, xs, tau, source="run.csv"):
    import dynax

    return dynax.Trajectory(ts, xs, tau[:, None], ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot", source)


def lag_findings(ts, xs, tau):
    import dynax

    check = dynax.check_records([trajectory(ts, xs, tau)], estimated=())
    return [f for f in check.findings if f.kind == "lag"]


def biases(seed=0):
    """Percent error of each identified parameter on a clean 100 Hz record and on each fault, with the logged
    velocities and with them estimated from the angles."""
    import dynax

    ts, xs, tau = arm_record(100.0, seed, duration=8.0, noise="none")
    rows = {}
    for name, fault in {"clean": lambda t, x: x, **FAULTS}.items():
        record = trajectory(ts, fault(ts, xs), tau)
        central = np.column_stack([xs[:, :2], np.gradient(xs[:, :2], ts, axis=0)])
        for how, r in (("logged", record), ("estimated", trajectory(ts, central, tau))):
            if how == "estimated" and name != "clean" and name != "shift 1 sample":
                continue  # the estimate does not read the velocity column: one row shows it
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fit = dynax.identify(dynax.Acrobot(), [r])
            theta = [fit.parameters[n] for n in NAMES]
            rows[f"{name} ({how})"] = [round(100 * (float(p) / t - 1), 1) for p, t in zip(theta, TRUTH)]
            print(
                f"{name:>22} ({how:>9}): "
                + " ".join(f"{n}={v:+6.1f}%" for n, v in zip(NAMES, rows[f"{name} ({how})"])),
                flush=True,
            )
    return rows


def calibration(rates, seeds, jitters):
    from dynax.internal import velocity_lag

    clean = []
    faulted = {k: {rate: {"refuse": 0, "warn": 0, "records": 0} for rate in rates} for k in FAULTS}
    for rate in rates:
        for noise in NOISE:
            for jitter in jitters:
                for seed in seeds:
                    ts, xs, tau = arm_record(rate, seed, jitter=jitter, noise=noise)
                    found = lag_findings(ts, xs, tau)
                    reads = [velocity_lag(ts, xs[:, j], xs[:, j + 2]) for j in (0, 1)]
                    clean.append(
                        {
                            "rate_hz": rate,
                            "noise": noise,
                            "jitter": jitter,
                            "seed": seed,
                            "fired": len(found),
                            "z": max(abs(r.lag) / r.std_error for r in reads if r is not None),
                            "phase": max(abs(r.lag) * r.frequency for r in reads if r is not None),
                        }
                    )
                    for name, fault in FAULTS.items():
                        severities = {str(f.severity) for f in lag_findings(ts, fault(ts, xs), tau)}
                        tally = faulted[name][rate]
                        tally["records"] += 1
                        tally["refuse"] += "refuse" in severities
                        tally["warn"] += severities == {"warn"}
    fired = sum(r["fired"] > 0 for r in clean)
    print(f"\nclean records: {fired} of {len(clean)} fire (rates {rates} Hz, noise {list(NOISE)}, jitter {jitters})")
    for rate in rates:
        sub = [r for r in clean if r["rate_hz"] == rate]
        print(
            f"  {rate:6g} Hz: largest |lag|/std error {max(r['z'] for r in sub):.2f}, largest phase "
            f"{max(r['phase'] for r in sub):.4f} rad"
        )
    print("faults: records refused / warned / of, at " + ", ".join(f"{r:g}" for r in rates) + " Hz")
    for name, by_rate in faulted.items():
        cells = [f"{t['refuse']}/{t['warn']}/{t['records']}" for t in by_rate.values()]
        print(f"  {name:>20}: " + "  ".join(f"{c:>9}" for c in cells))
    return {"clean": clean, "faulted": {k: {f"{r:g}": t for r, t in v.items()} for k, v in faulted.items()}}


def dfki():
    import dynax
    from dynax.internal import velocity_lag

    folder = REPO.parent / "shared" / "datasets" / "dfki_double_pendulum" / "sys_id"
    mapping = dict(
        t="time", q1="pos_meas1", q2="pos_meas2", dq1="vel_meas1", dq2="vel_meas2", tau1="tau_meas1", tau2="tau_meas2"
    )
    rows = []
    for path in sorted(folder.glob("trajectory_*.csv")):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            record = dynax.load_trajectory(path, "double_pendulum", mapping=mapping)
        ts, xs = np.asarray(record.ts), np.asarray(record.xs)
        for j in (0, 1):
            r = velocity_lag(ts, xs[:, j], xs[:, j + 2])
            rows.append(
                {
                    "run": path.stem,
                    "column": f"dq{j + 1}",
                    "lag_ms": round(1e3 * r.lag, 4),
                    "std_error_ms": round(1e3 * r.std_error, 4),
                    "interval_ms": round(1e3 * float(np.median(np.diff(ts))), 3),
                    "phase_rad": round(r.lag * r.frequency, 4),
                    "warned": [str(w.message)[:200] for w in caught if f"column 'dq{j + 1}'" in str(w.message)],
                }
            )
            print(rows[-1], flush=True)
    return rows


def controls(out):
    """Lag findings on the hidden-effect battery's arm and axis records and on the demo's records."""
    import dynax
    from dynax.synthetic import demo_data, hidden_effect
    from tests import hidden_cases

    rows = []
    for case in hidden_cases.CASES:
        if case.system in ("helicopter", "quadrotor"):  # the arms' and the axis' encoder records only
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            train, validation = hidden_cases.records(case)
        found = [f.describe() for f in dynax.check_records([train], [validation]).findings if f.kind == "lag"]
        rows.append({"record": f"hidden:{case.name}", "lag_findings": found})
    for seed in range(14):
        _, train, validation = demo_data(hidden_effect(seed), seed=seed)
        found = [f.describe() for f in dynax.check_records([train], [validation]).findings if f.kind == "lag"]
        rows.append({"record": f"demo:{seed}", "lag_findings": found})
    for kind in ("hidden", "demo"):
        sub = [r for r in rows if r["record"].startswith(kind)]
        print(f"{kind}: {sum(bool(r['lag_findings']) for r in sub)} of {len(sub)} records raise a lag finding")
    out.write_text(json.dumps(rows, indent=1) + "\n")


def edges(out, draws=60):
    """Where the check places the start of a lag that begins part way: the arm's record (8 s, encoder noise) at
    100 and 500 Hz, its velocities 10 ms late from a time drawn uniformly in 2 to 5 s; the distance from the
    start the finding names to the true one, signed (the 0.5 s stretches alone place it to their edges); and the
    rows the DFKI runs' lag warnings name."""
    rng = np.random.default_rng(7)
    found = {}
    for rate in (100.0, 500.0):
        errors, missed = [], 0
        for _ in range(draws):
            seed, start_s = int(rng.integers(0, 10_000)), float(rng.uniform(2.0, 5.0))
            ts, xs, tau = arm_record(rate, seed, duration=8.0)
            k, start = round(0.01 * rate), int(start_s * rate)
            late = xs.copy()
            late[start:, 2:] = xs[start - k : len(ts) - k, 2:]
            lags = [f for f in lag_findings(ts, late, tau) if f.column == "dq1"]
            if not lags:
                missed += 1
                continue
            errors.append(float(lags[0].times[0] - ts[start]))
        e = np.asarray(errors)
        found[f"{rate:g} Hz"] = {
            "placed": len(e),
            "not_read_as_a_lag": missed,
            "median_abs_s": float(np.median(np.abs(e))),
            "p90_abs_s": float(np.percentile(np.abs(e), 90)),
            "latest_s": float(e.max()),  # placed after the true start: lagged samples left out of the span
            "earliest_s": float(e.min()),  # placed before it (where the motion is too still to tell)
            "within_0.05_s": int(np.sum(np.abs(e) <= 0.05)),
        }
        print(f"{rate:g} Hz: {found[f'{rate:g} Hz']}", flush=True)
    # the DFKI runs' velocities lag throughout (backward differences): the rows each warning names
    found["dfki"] = [{"run": r["run"], "column": r["column"], "warned": r["warned"]} for r in dfki()]
    pathlib.Path(out).write_text(json.dumps(found, indent=1) + "\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="two seeds, no jitter, no bias table")
    parser.add_argument("--controls", action="store_true", help="the battery's and the demo's records only")
    parser.add_argument("--edges", action="store_true", help="where a lag that starts part way is placed, only")
    parser.add_argument("--seeds", type=int, default=10, help="records per rate, noise level and jitter")
    parser.add_argument("--out", default=str(REPO / "experiments" / "results" / "velocity_lag.json"))
    args = parser.parse_args()
    sys.path.insert(0, str(REPO))
    import jax

    jax.config.update("jax_enable_x64", True)
    if args.controls:
        return controls(pathlib.Path(args.out).with_name("velocity_lag_controls.json"))
    if args.edges:
        return edges(pathlib.Path(args.out).with_name("velocity_lag_edges.json"))
    out = {}
    if not args.quick:
        out["bias_percent"] = biases()
    seeds = range(2) if args.quick else range(args.seeds)
    out["calibration"] = calibration([100.0, 250.0, 500.0, 1000.0], list(seeds), [0.0] if args.quick else [0.0, 0.5])
    out["dfki"] = dfki()
    pathlib.Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    pathlib.Path(args.out).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
