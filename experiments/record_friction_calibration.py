"""How often `record_friction` flags records that share one friction, and how often it sees a difference.

    python experiments/record_friction_calibration.py --out experiments/results/record_friction_calibration

`record_friction` (`dynax/_identify/_record_friction.py`) compares the records' Coulomb friction
against the spread between the two halves of each record, by a one-way analysis of variance. This
script measures its error rates on synthetic data: `--sets` sets of four 6 s records of the DFKI
rig's model (base parameters, rotor inertia and friction of `tests/identify/test_identify_defaults`),
each under its own random multisine torque (0.5 N m rms, 0.2 to 2.5 Hz), sampled at 2 ms with the
rig's noise (0.15 rad/s on the velocities, 0.02 N m on the torques, 1e-4 rad on the encoders).

- **null**: every record with the elbow friction 0.12 N m; the share of sets flagged at the 1 %
  level is the false-alarm rate (1 % if the test is calibrated).
- **different**: elbow friction 0.12, 0.14, 0.10 and 0.13 N m; the share flagged is the power.

Each set is tested with each record cut into `--parts` parts (`record_friction(..., parts=K)`;
2 is the halves `record_offsets` uses, 4 `record_friction`'s default: more parts give more degrees
of freedom within the records, but each part's estimate is noisier). The equations are those of `identify`'s
least-squares stage (every setting chosen from the data). Writes `OUT/calibration.json`. About 20 s on 2 CPU cores for
36 sets, 100 s for 200.
"""

import argparse
import json
import pathlib

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax import Trajectory  # noqa: E402
from dynax.internal import (
    record_friction,  # noqa: E402
    stacked_equations,  # noqa: E402
)

RIG = dict(theta1=0.0536, theta2=0.0533, theta3=0.0362, theta4=2.365, theta5=1.777, theta6=0.01, theta7=0.01)
FC1, IR2 = 0.15, 0.0042
CASES = {"null": (0.12, 0.12, 0.12, 0.12), "different": (0.12, 0.14, 0.10, 0.13)}


def record(fc2: float, seed: int) -> Trajectory:
    truth = dynax.Extended(
        dynax.DoublePendulum.from_base_parameters(RIG),
        (dynax.CoulombFriction(0, FC1), dynax.CoulombFriction(1, fc2), dynax.RotorInertia(1, IR2)),
    )
    clean = dynax.synthetic.synthetic_trajectory(
        truth,
        duration=6.0,
        dt=0.002,
        seed=seed,
        excitation=dynax.synthetic.Multisine(amplitude=0.5, band_hz=(0.2, 2.5)),
        noise=(1e-4, 1e-4, 0.15, 0.15),
    )
    torque_noise = 0.02 * np.random.default_rng(seed).normal(size=clean.us.shape)
    return Trajectory(clean.ts, clean.xs, clean.us + jnp.asarray(torque_noise), clean.state_names, clean.input_names)


def p_value(a, y, counts, names, parts: int) -> float:
    """`record_friction`'s p-value for the elbow with `parts` parts per record."""
    return float(record_friction(a, y, counts, names, ("fc2",), parts=parts).p_value[0])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--sets", type=int, default=12)
    parser.add_argument("--parts", default="2,3,4,6", help="parts per record to compare (2: the halves)")
    args = parser.parse_args(argv)
    parts = [int(k) for k in args.parts.split(",")]
    out = {
        "alpha": 0.01,
        "parts": parts,
        "cases": {k: list(v) for k, v in CASES.items()},
        "p_values": {},
        "flagged": {},
    }
    for case, frictions in CASES.items():
        rows = []
        for s in range(args.sets):
            records = [record(fc2, 1000 + 10 * s + k) for k, fc2 in enumerate(frictions)]
            _, a, y, _, names, _, _, _, counts, _ = stacked_equations(
                dynax.DoublePendulum(), records, dynax.Dynamic(), "coulomb", None, None
            )
            rows.append([p_value(a, y, counts, list(names), k) for k in parts])
            print(f"{case} set {s}: " + " ".join(f"{k} parts p = {p:.3g}" for k, p in zip(parts, rows[-1])), flush=True)
        out["p_values"][case] = rows
        out["flagged"][case] = {str(k): int(sum(r[j] < 0.01 for r in rows)) for j, k in enumerate(parts)}
        print(
            f"{case}: flagged at the 1 % level, of {args.sets} sets: "
            + ", ".join(f"{k} parts {out['flagged'][case][str(k)]}" for k in parts),
            flush=True,
        )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "calibration.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.out / 'calibration.json'}")


if __name__ == "__main__":
    main()
