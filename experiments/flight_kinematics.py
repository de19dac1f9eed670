"""How well each NanoBench flight's columns agree with each other: the gains behind `load_flight`'s check.

For every flight, read with its motion-capture rates and with its IMU gyro, the gain (and standard
error) of each velocity on its position's derivative and of each body rate on the attitude's, and
the thrust's two slopes (horizontal acceleration on the lean of body z, vertical acceleration on the
motors' thrust), over the longest run with the motors running, as `load_flight` reads them
(`dynax.internal`'s `attitude_angles`, `thrust_frame_slopes`, `velocity_gain`); then faults injected
into a copy of the star flight, and whether each is refused.

    nice -n 5 python experiments/flight_kinematics.py [OUT]

Writes `OUT/gains.json` (default `experiments/results/flight_kinematics`) and prints the table.
"""

import csv
import gzip
import pathlib
import sys
import tempfile
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax.internal import (  # noqa: E402
    attitude_angles,
    motors_running_run,
    thrust_frame_slopes,
    velocity_gain,
    write_json,
)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_heldout import DATA, NANOBENCH_MAP  # noqa: E402

GYRO_MAP = NANOBENCH_MAP | {"p": "imu_gyro_x", "q": "imu_gyro_y", "r": "imu_gyro_z"}
COLUMNS = ("vx", "vy", "vz", "p", "q", "r")


def gains(path, mapping):
    trajectory, _ = dynax.load_flight(path, mapping=mapping)
    us = np.asarray(trajectory.us[:, :4], dtype=float)
    first, last = motors_running_run(trajectory)  # the stretch `load_flight` checks
    a, b = first, last + 1
    ts = np.asarray(trajectory.ts, dtype=float)[a:b]
    xs = np.asarray(trajectory.xs, dtype=float)[a:b]
    angles = attitude_angles(xs[:, 3:7])
    positions = (xs[:, 0], xs[:, 1], xs[:, 2], angles[:, 0], angles[:, 1], angles[:, 2])
    out = {}
    for k, name in enumerate(COLUMNS):
        found = velocity_gain(ts, positions[k], xs[:, 7 + k])
        out[name] = None if found is None else {"gain": found[0], "std_error": found[1], "correlation": found[2]}
    values = {n: xs[:, i] for i, n in enumerate(trajectory.state_names)}
    c, c_std, k, k_std = thrust_frame_slopes(ts, values, us[a:b])
    out["thrust"] = {"lean_gain": c, "lean_gain_std_error": c_std, "vertical_t": k / k_std}
    return out


FAULTS = {
    "rates in deg/s": lambda t, c: t[:, [c("wx_vicon"), c("wy_vicon"), c("wz_vicon")]] * (180 / np.pi),
    "yaw rate sign": lambda t, c: -t[:, [c("wz_vicon")]],
    "roll and pitch rates swapped": lambda t, c: t[:, [c("wy_vicon"), c("wx_vicon")]],
    "velocity in mm/s": lambda t, c: t[:, [c("vx"), c("vy"), c("vz")]] * 1000,
    "vx and vy swapped": lambda t, c: t[:, [c("vy"), c("vx")]],
    "z down": lambda t, c: -t[:, [c("pz"), c("vz")]],
    "world-to-body quaternion": lambda t, c: -t[:, [c("qx"), c("qy"), c("qz")]],
}
FAULT_COLUMNS = {
    "rates in deg/s": ("wx_vicon", "wy_vicon", "wz_vicon"),
    "yaw rate sign": ("wz_vicon",),
    "roll and pitch rates swapped": ("wx_vicon", "wy_vicon"),
    "velocity in mm/s": ("vx", "vy", "vz"),
    "vx and vy swapped": ("vx", "vy"),
    "z down": ("pz", "vz"),
    "world-to-body quaternion": ("qx", "qy", "qz"),
}


def faults():
    source = DATA / "B8_star_fast_rep1.csv.gz"
    with gzip.open(source, "rt") as f:
        rows = list(csv.reader(f))
    header, table = rows[0], np.array(rows[1:], float)
    out = {}
    for name, fault in FAULTS.items():
        bad = table.copy()
        bad[:, [header.index(c) for c in FAULT_COLUMNS[name]]] = fault(table, header.index)
        with tempfile.TemporaryDirectory() as folder:
            path = pathlib.Path(folder) / "faulty.csv"
            with open(path, "w", newline="") as f:
                csv.writer(f).writerows([header, *bad.tolist()])
            try:
                dynax.load_flight(path, mapping=NANOBENCH_MAP)
                out[name] = "loaded (not caught)"
            except dynax.DataError as e:
                out[name] = str(e).split(": ", 1)[1]
        print(f"{name}: {out[name][:160]}", flush=True)
    return out


def main():
    out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "experiments/results/flight_kinematics")
    warnings.simplefilter("ignore", dynax.DataWarning)
    table = {}
    for path in sorted(DATA.glob("*.csv.gz")):
        for label, mapping in (("motion capture", NANOBENCH_MAP), ("gyro", GYRO_MAP)):
            found = gains(path, mapping)
            table.setdefault(path.name, {})[label] = found
            cells = " ".join(f"{name} {found[name]['gain']:.3f}" if found[name] else f"{name} -" for name in COLUMNS)
            cells += " | lean gain {lean_gain:.2f} m/s^2, vertical t {vertical_t:.1f}".format(**found["thrust"])
            print(f"{path.name:34s} {label:14s} {cells}", flush=True)
    write_json(out / "gains.json", {"flights": table, "faults_in_star_fast": faults()})
    print(f"written to {out / 'gains.json'}")


if __name__ == "__main__":
    main()
