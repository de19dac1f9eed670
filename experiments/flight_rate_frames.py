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

`--loads` runs every faulted copy through `dynax.load_flight` instead and sorts its answers: the same 16
flights, both rates, turned to 0, 90 and 180 degrees, written as `.npz` files of the logged columns with one
fault each: the two frame faults above (192 cases), and the per-axis faults a log carries (288): the yaw
rate's sign flipped, the columns of p and q swapped, the rates in deg/s; the turned clean copies (96) and the
32 flights as logged (their times, states, inputs, usable masks and notes hashed, to compare checkouts).
Each answer is: the right fix alone, a refusal naming two readings with the right one among them, a wrong
fix alone, a refusal naming no fix, or a silent load. `--code CHECKOUT` judges another checkout's dynax (the
code before a change), `--only NAME` some flights:

    nice -n 5 python experiments/flight_rate_frames.py --loads [--code CHECKOUT] [--out FILE]

Writes `FILE` (default `OUT/loads.json`) and prints the counts.
"""

import argparse
import gzip
import hashlib
import pathlib
import sys
import tempfile
import warnings

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
DEGREES = 180.0 / np.pi

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


def misfit_table(out):
    from dynax.internal import write_json

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


def _read_csv(path):
    with gzip.open(path, "rt") as f:
        names = f.readline().strip().split(",")
    return dict(zip(names, np.loadtxt(path, delimiter=",", skiprows=1, unpack=True)))


def _faulted(raw, mapping, degrees, fault):
    """The logged columns of `raw` that `mapping` reads, the world turned by `degrees` about z, with `fault`."""
    cols = {n: raw[mapping.get(n, n)].copy() for n in ("t", "x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz")}
    cols |= {n: raw[mapping.get(n, n)].copy() for n in ("p", "q", "r", "m1", "m2", "m3", "m4", "vbat")}
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    for a, b in (("x", "y"), ("vx", "vy")):
        cols[a], cols[b] = c * cols[a] - s * cols[b], s * cols[a] + c * cols[b]
    q = np.stack([cols[n] for n in ("qw", "qx", "qy", "qz")], axis=1)
    q = _turned(q, np.radians(degrees))
    rates = np.stack([cols[n] for n in ("p", "q", "r")], axis=1)
    if fault == "world-to-body quaternion":
        q = q * np.array([1.0, -1, -1, -1])
    elif fault == "rates in world axes":
        rates = np.einsum("nij,nj->ni", _rotation(q / np.linalg.norm(q, axis=1, keepdims=True)), rates)
    elif fault == "yaw rate sign flipped":
        rates = rates * np.array([1.0, 1.0, -1.0])
    elif fault == "p and q swapped":
        rates = rates[:, [1, 0, 2]]
    elif fault == "rates in deg/s":
        rates = rates * DEGREES
    cols |= dict(zip(("qw", "qx", "qy", "qz"), q.T)) | dict(zip(("p", "q", "r"), rates.T))
    return {mapping.get(n, n): v for n, v in cols.items()}


# The fix each fault needs, as `advice` names it.
RIGHT = {
    "world-to-body quaternion": "conjugate",
    "rates in world axes": "world axes",
    "yaw rate sign flipped": "r=-1",
    "p and q swapped": "swap p,q",
    "rates in deg/s": "deg/s",
}
FAULTS = ("clean", *RIGHT)


def advice(message: str, mapping) -> list[str]:
    """The fixes a refusal names, in its order: `conjugate`, `world axes`, `deg/s`, a sign (`r=-1`, `p=-1,q=-1`),
    a swap (`swap p,q`: the per-axis check's question, or a `--map` that exchanges the rate columns), or a swap
    with signs (`swap p,q; q=-1`)."""
    found = []
    for k, part in enumerate(message.split("`")):
        if k % 2 and part.startswith("--"):
            found.append(_fix(part, mapping))
        elif not k % 2 and "omega_body = R(q)^T omega_world" in part:
            found.append("world axes")
        elif not k % 2 and ("are the columns of p and q swapped?" in part or "columns of q and p swapped?" in part):
            found.append("swap p,q")
    return found


def _fix(flags: str, mapping) -> str:
    """The fix that the flags `--map ... --scale ...` of a refusal make."""
    moved, factors = [], {}
    for flag, body in zip(flags.split()[::2], flags.split()[1::2]):
        pairs = dict(a.split("=", 1) for a in body.split(","))
        if flag == "--map":
            moved = sorted(k for k, v in pairs.items() if v != mapping.get(k, k))
        else:
            factors = {k: float(v) for k, v in pairs.items()}
    if set(factors) == {"qx", "qy", "qz"} and all(v == -1 for v in factors.values()):
        return "conjugate"
    if factors and all(abs(v * DEGREES - 1) < 1e-3 for v in factors.values()):
        return "deg/s"
    signs = ",".join(f"{k}={v:g}" for k, v in factors.items())
    return "; ".join(([f"swap {','.join(moved)}"] if moved else []) + ([signs] if signs else []))


def outcome(fault, error, mapping) -> str:
    if error is None:
        return "loads" if fault == "clean" else "silent load"
    if fault == "clean":
        return "refused clean"
    named = advice(error, mapping)
    right = RIGHT[fault]
    if not named:
        return "refused, no fix"
    if len(named) == 1:
        return "right fix" if named[0] == right else "wrong fix"
    return "tie, right one named" if right in named else "tie, right one missing"


def _digest(trajectory, notes) -> str:
    h = hashlib.sha256()
    for a in (trajectory.ts, trajectory.xs, trajectory.us, notes.usable):
        h.update(np.ascontiguousarray(np.asarray(a)).tobytes())
    h.update("\n".join(notes.describe()).encode())
    return h.hexdigest()[:16]


def readings(file, mapping):
    """The misfits of the readings `check_rate_frame` weighs, on the run `load_flight` checks: the body frame,
    world axes, a world-to-body quaternion, and the signed order of the rate columns that fits best
    (`dynax.internal.signed_reading_misfits`; absent from a checkout without it)."""
    import dynax.internal as internal

    if not hasattr(internal, "signed_reading_misfits"):
        return None
    data = dynax.load_trajectory(file, "quadrotor", mapping=mapping, check=False)
    first, last = motors_running_run(data)
    ts = np.asarray(data.ts, dtype=float)[first : last + 1]
    xs = np.asarray(data.xs, dtype=float)[first : last + 1]
    q = xs[:, 3:7] / np.linalg.norm(xs[:, 3:7], axis=1, keepdims=True)
    frames = rate_frame_misfits(ts - ts[0], q, xs[:, 10:13].T)
    signed = internal.signed_reading_misfits(ts - ts[0], q, xs[:, 10:13].T)
    if frames is None or signed is None:
        return None
    best = min(signed, key=signed.__getitem__)
    return frames | {
        "best signed": signed[best],
        "best signed reading": internal.signed_reading_fix(best)[0],
        "r flipped": signed[((0, 1, 2), (0, 0, 1))],
        "p, q swapped": signed[((1, 0, 2), (0, 0, 0))],
    }


def loads(args):
    warnings.simplefilter("ignore", dynax.DataWarning)
    rows = []
    paths = [p for p in sorted(DATA.glob("*.csv.gz")) if not args.only or args.only in p.name]
    with tempfile.TemporaryDirectory() as tmp:
        for path in paths:
            raw = _read_csv(path)
            for label, mapping in (("motion capture", NANOBENCH_MAP), ("gyro", GYRO_MAP)):
                try:
                    digest = _digest(*dynax.load_flight(path, mapping=mapping))
                except dynax.DataError as e:
                    digest = f"refused: {e}"
                rows.append(
                    {
                        "flight": path.name,
                        "rates": label,
                        "heading": "logged",
                        "fault": "clean",
                        "outcome": "refused clean" if digest.startswith("refused") else "loads",
                        "digest": digest,
                    }
                )
                for degrees in (0, 90, 180):
                    for fault in FAULTS:
                        if fault == "clean" and degrees == 0:
                            continue
                        file = pathlib.Path(tmp) / f"{path.name[:-7]}_{degrees}.npz"
                        np.savez(file, **_faulted(raw, mapping, degrees, fault))
                        try:
                            dynax.load_flight(file, mapping=mapping)
                            error = None
                        except dynax.DataError as e:
                            error = str(e)
                        row = {
                            "flight": path.name,
                            "rates": label,
                            "heading": degrees,
                            "fault": fault,
                            "outcome": outcome(fault, error, mapping),
                            "error": error,
                            "readings": readings(file, mapping),
                        }
                        rows.append(row)
                        print(f"{path.name[:-7]:26s} {label:14s} {degrees:3d} {fault:26s} {row['outcome']}", flush=True)
    write_json(pathlib.Path(args.out), rows)
    counts = {}
    for row in rows:
        group = (
            "clean as logged"
            if row["heading"] == "logged"
            else "clean, turned"
            if row["fault"] == "clean"
            else (
                "frame faults"
                if row["fault"] in ("world-to-body quaternion", "rates in world axes")
                else "per-axis faults"
            )
        )
        counts.setdefault(group, {}).setdefault(row["outcome"], 0)
        counts[group][row["outcome"]] += 1
    for group, found in counts.items():
        print(f"{group}: " + ", ".join(f"{k} {v}" for k, v in sorted(found.items())))
    print(f"written to {args.out}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="experiments/results/flight_rate_frames")
    parser.add_argument("--loads", action="store_true", help="every faulted copy through load_flight")
    parser.add_argument("--code", default=str(HERE.parent), help="checkout whose dynax is judged")
    parser.add_argument("--out", dest="file", default=None, help="--loads: results file (default OUT/loads.json)")
    parser.add_argument("--only", default=None, help="--loads: flights whose name holds this")
    args = parser.parse_args()
    sys.path.insert(0, str(pathlib.Path(args.code).resolve()))
    sys.path.insert(1, str(HERE))
    from nanobench_heldout import DATA, NANOBENCH_MAP

    import dynax
    from dynax.internal import motors_running_run, rate_frame_misfits, write_json

    GYRO_MAP = NANOBENCH_MAP | {"p": "imu_gyro_x", "q": "imu_gyro_y", "r": "imu_gyro_z"}
    print(f"judging dynax from {pathlib.Path(dynax.__file__).parent}", file=sys.stderr)
    if args.loads:
        args.out = args.file or str(pathlib.Path(args.out) / "loads.json")
        loads(args)
    else:
        misfit_table(pathlib.Path(args.out))
