"""Time jitter's bias on the identified parameters, the dampings first, at realistic sizes.

Two faults of a logger's clock. *Sampled unevenly, stamped uniformly*: sample k is taken at
`k h + e_k` but written at `k h` (a real-time loop that wakes late, logging its nominal time): nothing in the
file shows it. *Sampled uniformly, stamped unevenly*: the reverse (the stamp read from a clock after a
variable delay): the stamps' spread shows it. And, as a control, *both*: sampled unevenly and stamped
truly (the stamps right, the sampling uneven; the spread shows it too). `e_k` is uniform in +-J
(independent samples), J = 0.1, 0.3, 1 ms, at 100, 500 and 1000 Hz.

Records are made apart from dynax's model code (`tests.reference.arm_reference`, DOP853 at rtol 1e-10; the
acrobot under a random elbow multisine, 8 s, no noise: the bias alone), evaluated at the true sample
times, and `identify` (`Dynamic`, refined by the output-error fit as a noisy record is by default) fits
each. Prints each parameter's percent error against the truth, next to the same seed without jitter.

    python experiments/time_jitter.py [--seeds 0,1,2] [--rates 100,500,1000] [--how sampled,stamped,both]
        [--out FILE.json]
    python experiments/time_jitter.py --dfki   # the DFKI runs' held-input ages after resampling
"""

import argparse
import json
import pathlib
import sys
import warnings

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
TRUTH = np.array([1.333, 1.33, 1.0, 14.715, 9.81, 0.1, 0.1])
NAMES = tuple(f"theta{i}" for i in range(1, 8))


def jittered_record(rate_hz, seed, jitter_s, how, duration=8.0):
    """`(stamps, xs, tau2)`: the arm sampled at `k h + e_k` and stamped `k h` (`how="sampled"`), sampled at `k h`
    and stamped `k h + e_k` (`"stamped"`), or sampled and stamped at `k h + e_k` (`"both"`: uneven sampling,
    truly stamped), `e_k` uniform in +-`jitter_s`."""
    from scipy.integrate import solve_ivp

    from tests.reference import arm_reference

    rng = np.random.default_rng(seed)
    freqs, phases = rng.uniform(0.2, 2.0, 6), rng.uniform(0, 2 * np.pi, 6)

    def drive(t):
        return 3.0 * float(np.sum(np.sin(2 * np.pi * freqs * t + phases))) / np.sqrt(6)

    grid = np.arange(0.0, duration + 0.5 / rate_hz, 1.0 / rate_hz)
    e = jitter_s * np.random.default_rng(seed + 1000).uniform(-1.0, 1.0, len(grid))
    e[0] = 0.0
    taken = grid if how == "stamped" else grid + e
    stamps = grid if how == "sampled" else grid + e
    sol = solve_ivp(
        lambda t, x: arm_reference(tuple(TRUTH), x, (0.0, drive(t))),
        (0.0, taken[-1] + 1e-3),
        [0.2, 0.0, 0.0, 0.0],
        t_eval=taken,
        method="DOP853",
        rtol=1e-10,
        atol=1e-11,
    )
    # the torque the logger writes with each sample: the command at the sample's true time
    return stamps, sol.y.T, np.array([drive(t) for t in taken])


def errors(ts, xs, tau):
    import dynax

    record = dynax.Trajectory(ts, xs, tau[:, None], ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot", "run.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # refined always: the default refines a record that carries noise (every real one), and jitter reads as
        # noise, so that `refine="auto"` would compare a refined jittered fit with an unrefined clean one
        fit = dynax.identify(dynax.Acrobot(), [record], refine=True)
    return [100.0 * (float(fit.parameters[n]) / t - 1.0) for n, t in zip(NAMES, TRUTH)]


def dfki_input_ages():
    """On each DFKI run, the age of the input `dynax.resample` holds at each point of the grid it resamples
    onto (the record's first stamp plus whole median intervals: the run's stamps are 2 ms but for a few gaps),
    in intervals: 0 where the grid meets a stamp; and the share of grid points whose held input is not the
    sample nearest in time. Read from `resample` itself."""
    import dynax

    sys.path.insert(0, str(REPO))
    from tests.conftest import DFKI_MAPPING

    folder = REPO.parent / "shared" / "datasets" / "dfki_double_pendulum" / "sys_id"
    rows = {}
    for n in ("00", "01", "02", "03", "05", "12"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            record = dynax.load_trajectory(folder / f"trajectory_{n}.csv", "double_pendulum", mapping=DFKI_MAPPING)
        ts = np.asarray(record.ts)
        # a ramp as the input: the held value is the stamp of the sample held, so its age is read off exactly
        ramp = dynax.Trajectory(ts, record.xs, np.column_stack([ts, ts]), record.state_names, record.input_names)
        uniform = dynax.resample(ramp, record.dt)
        grid, held = np.asarray(uniform.ts), np.asarray(uniform.us)[:, 0]
        age = (grid - held) / record.dt
        rows[n] = {
            "median_age_intervals": round(float(np.median(age)), 3),
            "p90_age_intervals": round(float(np.percentile(age, 90)), 3),
            "share_not_nearest": round(float(np.mean(age > 0.5)), 3),
        }
        print(f"run {n}: {rows[n]}", flush=True)
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2", help="comma-separated seeds")
    parser.add_argument("--rates", default="100,500,1000")
    parser.add_argument("--how", default="sampled,stamped,both", help="which faults (comma-separated)")
    parser.add_argument("--dfki", action="store_true", help="the DFKI runs' held-input ages after resampling, only")
    parser.add_argument("--out", default=str(REPO / "experiments" / "results" / "time_jitter.json"))
    args = parser.parse_args()
    sys.path.insert(0, str(REPO))
    import jax

    jax.config.update("jax_enable_x64", True)
    if args.dfki:
        out = pathlib.Path(args.out).with_name("time_jitter_dfki.json")
        out.write_text(json.dumps(dfki_input_ages(), indent=1) + "\n")
        return
    rows = []
    for rate in map(float, args.rates.split(",")):
        for seed in map(int, args.seeds.split(",")):
            base = errors(*jittered_record(rate, seed, 0.0, "sampled"))
            rows.append({"rate_hz": rate, "seed": seed, "jitter_ms": 0.0, "how": "none", "error_percent": base})
            print(f"{rate:6.0f} Hz seed {seed} no jitter         : " + " ".join(f"{v:+6.1f}" for v in base), flush=True)
            for how in args.how.split(","):
                for jitter_ms in (0.1, 0.3, 1.0):
                    if jitter_ms * 1e-3 * rate >= 0.5:
                        continue  # a jitter of half an interval or more reorders samples
                    err = errors(*jittered_record(rate, seed, jitter_ms * 1e-3, how))
                    rows.append(
                        {"rate_hz": rate, "seed": seed, "jitter_ms": jitter_ms, "how": how, "error_percent": err}
                    )
                    print(
                        f"{rate:6.0f} Hz seed {seed} {how:>7} +-{jitter_ms:3.1f} ms: "
                        + " ".join(f"{v:+6.1f}" for v in err)
                        + "   (theta6, theta7 moved "
                        + f"{err[5] - base[5]:+.1f}, {err[6] - base[6]:+.1f} points)",
                        flush=True,
                    )
    pathlib.Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    pathlib.Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
