"""Which frame a flight log's body rates and attitude are in: the misfits behind `load_flight`'s
`check_rate_frame`, on the 16 NanoBench flights as logged and with the frame faults a real log carries.

For every flight, read with its motion-capture rates and with its IMU gyro, over the longest run with the
motors running (as `load_flight` checks it), the misfit of the rates `p, q, r` on the attitude's rate of
change read three ways (`dynax.internal.rate_frame_misfits`): the contract's body frame, world axes, and a
world-to-body quaternion. Then the same flights turned to a heading of 0, 90 and 180 degrees (the motion
capture's x axis elsewhere: the position, velocity and attitude rotated about z; the same flight) with
two faults each: the quaternion conjugated (world-to-body logged), and the rates rotated into world axes.
A row says whether `check_rate_frame`'s rule (body misfit above `RATE_FRAME_MISFIT`, the other reading at
most `RATE_FRAME_RATIO` of it) names the fault, and `load_flight`'s answer on the clean flight.

    nice -n 5 python experiments/flight_rate_frames.py [OUT]

Writes `OUT/misfits.json` (default `experiments/results/flight_rate_frames`) and prints the table.
"""

import pathlib
import sys
import warnings

import numpy as np

import dynax
from dynax.internal import motors_running_run, rate_frame_misfits, write_json

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_heldout import DATA, NANOBENCH_MAP  # noqa: E402

GYRO_MAP = NANOBENCH_MAP | {"p": "imu_gyro_x", "q": "imu_gyro_y", "r": "imu_gyro_z"}
# the rule of `check_rate_frame` (dynax._data._flight_kinematics)
FLOOR, RATIO = 0.3, 0.8


def _rotation(q):
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _turned(q, heading):
    """The body-to-world quaternions `q` with the world turned by `heading` [rad] about z (q0 (x) q)."""
    c, s = np.cos(heading / 2), np.sin(heading / 2)
    w, x, y, z = q.T
    return np.stack([c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w], axis=1)


def named(found) -> str:
    """What the rule names: `body` (nothing refused), `world` or `world_to_body`."""
    if found is None or found["body"] <= FLOOR:
        return "body"
    reading = min(("world_to_body", "world"), key=found.__getitem__)
    return reading if found[reading] <= RATIO * found["body"] else "body"


def flight(path, mapping):
    data = dynax.load_trajectory(path, "quadrotor", mapping=mapping, check=False)
    first, last = motors_running_run(data)
    ts = np.asarray(data.ts, dtype=float)[first : last + 1]
    xs = np.asarray(data.xs, dtype=float)[first : last + 1]
    q = xs[:, 3:7] / np.linalg.norm(xs[:, 3:7], axis=1, keepdims=True)
    rates = xs[:, 10:13]
    out = {"clean": rate_frame_misfits(ts - ts[0], q, rates.T)}
    for degrees in (0, 90, 180):
        turned = _turned(q, np.radians(degrees))
        conjugated = turned * np.array([1.0, -1, -1, -1])
        world_rates = np.einsum("nij,nj->ni", _rotation(turned), rates)
        out[f"heading {degrees}: world-to-body quaternion"] = rate_frame_misfits(ts - ts[0], conjugated, rates.T)
        out[f"heading {degrees}: rates in world axes"] = rate_frame_misfits(ts - ts[0], turned, world_rates.T)
        out[f"heading {degrees}: clean"] = rate_frame_misfits(ts - ts[0], turned, rates.T)
    try:
        dynax.load_flight(path, mapping=mapping)
        loads = "loads"
    except dynax.DataError as e:
        loads = f"refused: {e}"
    return out, loads


def main():
    out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "experiments/results/flight_rate_frames")
    warnings.simplefilter("ignore", dynax.DataWarning)
    table = {}
    for path in sorted(DATA.glob("*.csv.gz")):
        for label, mapping in (("motion capture", NANOBENCH_MAP), ("gyro", GYRO_MAP)):
            found, loads = flight(path, mapping)
            row = {k: {"misfits": v, "named": named(v)} for k, v in found.items()}
            row["load_flight"] = loads
            table.setdefault(path.name, {})[label] = row
            clean = found["clean"]
            faults = " ".join(
                f"{k.split(':')[0][8:]}{'W2B' if 'quaternion' in k else 'WR' if 'world axes' in k else 'ok'}"
                f"->{named(v)}"
                for k, v in found.items()
                if k != "clean"
            )
            print(
                f"{path.name:34s} {label:14s} body {clean['body']:.3f} world {clean['world']:.3f} "
                f"w2b {clean['world_to_body']:.3f} | {loads[:40]} | {faults}",
                flush=True,
            )
    write_json(out / "misfits.json", table)
    print(f"written to {out / 'misfits.json'}")


if __name__ == "__main__":
    main()
