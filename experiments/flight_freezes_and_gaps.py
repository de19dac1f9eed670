"""How long honest motion capture repeats a position, and what interpolating a gap costs.

1. On the 16 NanoBench flights: the runs of samples repeating `x, y, z` all three exactly, in flight (the
   usable samples) and on the floor, with the displacement the logged velocity gives over each, beside the
   position's noise (1.4826 times the median absolute step the velocity does not explain, per axis).
2. On a noise-free synthetic flight (tests/quadrotor/synthetic_flight.py: scipy's DOP853), the error of
   linear interpolation across a gap of n intervals against the truth, for n = 2..10, beside the noise
   such a flight logs; and on the NanoBench flights the same interpolation against the recorded samples
   (truth plus noise).

Run: `PYTHONPATH=$PWD python experiments/flight_freezes_and_gaps.py`
"""

import pathlib
import sys

import numpy as np

import dynax

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from experiments.nanobench_heldout import DATA, NANOBENCH_MAP  # noqa: E402
from tests.quadrotor.synthetic_flight import quadrotor_flight  # noqa: E402

GROUPS = {"position [m]": slice(0, 3), "velocity [m/s]": slice(7, 10), "body rates [rad/s]": slice(10, 13)}
SYNTHETIC_NOISE = {"position [m]": 5e-4, "velocity [m/s]": 5e-3, "body rates [rad/s]": 2e-2}


def repeats(position, velocity, dt):
    """`(first, last, displacement)` of each run of samples repeating the one before in all three columns."""
    same = np.concatenate([[False], np.all(position[1:] == position[:-1], axis=1)])
    edges = np.flatnonzero(np.diff(np.concatenate([[0], same.astype(np.int8), [0]])))
    return [
        (a, b - 1, float(np.linalg.norm(velocity[a - 1 : b].sum(axis=0) * dt))) for a, b in zip(edges[::2], edges[1::2])
    ]


def interpolation_error(xs, n, stride=7):
    """Per group, the rms over gap positions of the largest error of linear interpolation across `n` intervals."""
    out = {}
    for name, cols in GROUPS.items():
        worst = []
        for a in range(100, len(xs) - 100 - n, stride):
            inside = np.arange(1, n)[:, None] / n
            guess = xs[a, cols] + inside * (xs[a + n, cols] - xs[a, cols])
            worst.append(np.abs(guess - xs[a + 1 : a + n, cols]).max())
        out[name] = float(np.sqrt(np.mean(np.square(worst))))
    return out


def main():
    print("1. runs of x, y, z repeated exactly (NanoBench)")
    flying, floor, noises, nanobench = [], [], [], []
    for path in sorted(DATA.glob("*.csv.gz")):
        data, notes = dynax.load_flight(path, mapping=NANOBENCH_MAP)
        xs, usable = np.asarray(data.xs, dtype=float), np.asarray(notes.usable)
        position, velocity = xs[:, :3], xs[:, 7:10]
        step = np.diff(position, axis=0) - 0.5 * (velocity[1:] + velocity[:-1]) * data.dt
        noises.append(1.4826 * np.median(np.abs(step[usable[1:]]), axis=0))
        for a, b, moved in repeats(position, velocity, data.dt):
            (flying if usable[a : b + 1].all() else floor).append((path.name, b - a + 1, moved))
        nanobench.append(xs[usable])
    print(f"   in flight: {len(flying)} runs {flying}")
    print(f"   on the floor: {len(floor)} runs {[(f, n, round(m * 1e3, 3)) for f, n, m in floor]} (samples, mm moved)")
    noises = np.array(noises)
    print(f"   position noise per axis: {1e3 * noises.min():.3f} to {1e3 * noises.max():.3f} mm")
    print("2. rms of the largest interpolation error across a gap of n intervals")
    truth = np.asarray(quadrotor_flight(20.0, seed=0, noise=False).xs, dtype=float)
    print("   noise of a synthetic flight: " + ", ".join(f"{k} {v:.1e}" for k, v in SYNTHETIC_NOISE.items()))
    for n in range(2, 11):
        synthetic = interpolation_error(truth, n)
        real = {k: np.mean([interpolation_error(x, n, 23)[k] for x in nanobench]) for k in GROUPS}
        print(
            f"   n = {n:2d}: synthetic "
            + ", ".join(f"{v:.1e}" for v in synthetic.values())
            + "; NanoBench (against the recorded) "
            + ", ".join(f"{v:.1e}" for v in real.values())
        )


if __name__ == "__main__":
    main()
