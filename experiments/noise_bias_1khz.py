"""Velocity noise read as negligible that biases the dynamic least squares: an acrobot at 1 kHz.

The record is made outside dynax's model code (scipy's DOP853 on `tests.reference.arm_reference`, the elbow driven
by a 3 N m multisine of 0.2-2 Hz, the shoulder free), `--minutes` long at 1 kHz, with white noise of `--noise` on
the angles and the velocities. It is identified with `Dynamic()`'s defaults (least-squares stage only, no refinement
or validation) and, for comparison, unfiltered (`Dynamic(lowpass_hz=None)`: what the spectra's 1 % rule alone
chose before `dynax._identify._noise_bias`), and each estimate is compared with the truth.

    python experiments/noise_bias_1khz.py [OUT] [--minutes 10] [--noise 1e-4]

Writes `OUT/noise_bias.json` (default `experiments/results/noise_bias_1khz`) and prints the table.
"""

import argparse
import json
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
import dynax
from tests.reference import arm_run

TRUTH = {"theta1": 1.333, "theta2": 1.33, "theta3": 1.0, "theta4": 14.715, "theta5": 9.81, "theta6": 0.1, "theta7": 0.1}


def record(minutes: float, noise: float) -> dynax.Trajectory:
    rng = np.random.default_rng(0)
    freqs, phases = rng.uniform(0.2, 2.0, 6), rng.uniform(0, 2 * np.pi, 6)

    def elbow(t):
        return 3.0 * float(np.sum(np.sin(2 * np.pi * freqs * t + phases))) / np.sqrt(6)

    drive = lambda t: (0.0, elbow(t))  # noqa: E731
    ts, xs, taus = arm_run(tuple(TRUTH.values()), 60.0 * minutes, 1000.0, drive, rtol=1e-9, atol=1e-10)
    xs = xs + noise * rng.standard_normal((len(ts), 4))
    us = taus[:, 1:]
    return dynax.Trajectory(ts, xs, us, ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot", "acrobot-1khz")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="experiments/results/noise_bias_1khz")
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--noise", type=float, default=1e-4)
    args = parser.parse_args()
    print(f"integrating {args.minutes:g} min at 1 kHz (DOP853) ...", flush=True)
    data = record(args.minutes, args.noise)
    rows = {}
    for label, method in (("unfiltered (the 1 % rule alone)", dynax.Dynamic(lowpass_hz=None)), ("defaults", None)):
        start = time.perf_counter()
        result = dynax.identify(
            dynax.Acrobot(),
            data,
            dynax.Dynamic() if method is None else method,
            refine=False,
            validation=dynax.Validate(holdout=0),
        )
        rows[label] = {
            "relative_error": {k: result.parameters[k] / v - 1 for k, v in TRUTH.items()},
            "in_standard_errors": {k: (result.parameters[k] - v) / result.standard_errors[k] for k, v in TRUTH.items()},
            "settings": result.settings[0]["reason"],
            "seconds": time.perf_counter() - start,
        }
        errors = " ".join(f"{k} {e:+.2%}" for k, e in rows[label]["relative_error"].items())
        print(f"{label}: {errors} ({rows[label]['seconds']:.1f} s)\n  {rows[label]['settings'][:160]}", flush=True)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "noise_bias.json").write_text(
        json.dumps({"minutes": args.minutes, "noise": args.noise, "truth": TRUTH, "fits": rows}, indent=1)
    )
    print(f"wrote {out / 'noise_bias.json'}")


if __name__ == "__main__":
    main()
