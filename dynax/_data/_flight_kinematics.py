r"""Flight logs whose columns contradict each other: a velocity that is not its position's derivative, a
body rate that is not its attitude's, a vertical axis that points down.

Another drone's log, mapped onto the contract's `quadrotor` columns, can load and fit without a
word while meaning something else: rates in deg/s (PX4 and Betaflight logs), velocities in mm/s, a
gyro axis counted the other way, two columns swapped, a north-east-down frame where the contract's
is z up. Each makes every model fitted to it wrong, and nothing downstream names the cause. The
record states each quantity twice, so `load_flight` compares the two:

- each world velocity `vx, vy, vz` with the derivative of its position `x, y, z` (the arm's test,
  `dynax._data._velocities`: block means against secant slopes, refused beyond 20 % of a gain of 1
  where significant, with the unit, sign or swap the gain matches);
- each body rate `p, q, r` with the derivative of the attitude: the body-frame rotation vector of
  each sample's quaternion step, $\phi_i = 2\log(q_i^{-1} \otimes q_{i+1})$ (for a body-to-world
  quaternion, $q_{i+1} = q_i \otimes \exp(\tfrac12\omega\,\Delta t)$), summed into three angles
  whose derivatives are exactly the body rates, tested as a velocity against its angle. A gyro
  read against motion capture agrees less well than a velocity with its position (on the NanoBench
  flights its gain is 0.12-0.93, lowest about the axes that barely turn: noise in the attitude's
  steps attenuates it, and the gyro lags), so only a fault of another size is refused: the opposite
  sign, a factor of 2 or more (degrees per second), or the rate of another axis (swapped columns);
- the vertical: the contract's z is up, so with the motors running the vehicle is above where it
  rests with them off. A record that flies mostly *below* its motors-off height has its z axis
  down (north-east-down or forward-right-down logs), and its attitude, rates and gravity are
  then in another frame too: it is refused with the heights, not rescaled.

Only a fault that holds for the whole record is refused with a `scale` to fix it (a unit, a sign or
a swap): a gain that is wrong in some stretches only is no unit (see `gain_holds_everywhere` in
`dynax._data._velocities`).
"""

import numpy as np

from .._errors import DataError
from ._velocities import BLOCK_S, check_velocities, MIN_BLOCKS, SIGNIFICANCE, STRETCHES, velocity_gain

_AXES = ("p", "q", "r")
_ANGLE_AXIS = ("body x", "body y", "body z")
MAX_RATE_FACTOR = 2.0  # a body rate's gain on its attitude's beyond this (or its inverse) is a unit or a swap
DEGREES = 180.0 / np.pi
_OPPOSITE_SIGN = "the opposite sign (a gyro axis counted the other way: forward-right-down against forward-left-up?)"
MIN_FLIGHT_SHARE = 0.5  # the share of motors-running samples below the motors-off height that reads as z down


def attitude_angles(quats: np.ndarray) -> np.ndarray:
    """The cumulative body-frame rotation of a body-to-world quaternion series `(n, 4)` as `(qw, qx, qy,
    qz)`: `(n, 3)` angles [rad] whose derivatives are the body rates `p, q, r` (the first row zero).

    Each step $q_i^{-1} \\otimes q_{i+1}$ is turned into its rotation vector; the quaternions' signs
    are made continuous first ($q$ and $-q$ are one attitude)."""
    q = np.asarray(quats, dtype=float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    a, b = q[:-1], q[1:]
    b = np.where(np.sum(a * b, axis=1, keepdims=True) < 0, -b, b)
    aw, av, bw, bv = a[:, :1], a[:, 1:], b[:, :1], b[:, 1:]
    w = aw * bw + np.sum(av * bv, axis=1, keepdims=True)  # conj(a) (x) b
    v = aw * bv - bw * av - np.cross(av, bv)
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    angle = 2.0 * np.arctan2(norm, w)
    step = np.where(norm > 0, v * angle / np.where(norm > 0, norm, 1.0), 2.0 * v)
    return np.concatenate([np.zeros((1, 3)), np.cumsum(step, axis=0)])


def check_flight_kinematics(ts, values: dict, *, path=None, columns=None, scale=None) -> None:
    """Refuse a flight record whose columns contradict each other (see the module notes).

    **Arguments:**

    - `ts`: sample times; `values`: column arrays by contract name (`x, y, z, qw..qz, vx..vz, p, q, r`).
    - `path`, `columns` (contract name -> file column), `scale` (the factors already applied): named
      in the error and folded into the `scale` it suggests, as `check_velocities` does.

    **Raises:** `DataError` naming the file and the column: the velocity or rate that is not its
    position's or attitude's derivative (its gain, the unit, sign or swap that gain matches, and the
    `scale` that fixes it).
    """
    ts = np.asarray(ts, dtype=float)
    columns = dict(columns or {})
    check_velocities(ts, values, {"vx": "x", "vy": "y", "vz": "z"}, path=path, columns=columns, scale=scale)
    quats = np.stack([np.asarray(values[c], dtype=float) for c in ("qw", "qx", "qy", "qz")], axis=1)
    angles = attitude_angles(quats)
    scale = scale or {}
    faults = {}  # rate -> (what is wrong, the factor that fixes it)
    for k, rate in enumerate(_AXES):
        found = _rate_fault(ts, angles, k, np.asarray(values[rate], dtype=float), path, columns)
        if found is not None:
            faults[rate] = found
    if faults:
        first, (what, _, _) = next(iter(faults.items()))
        rest = list(faults)[1:]
        if rest:
            what = what + [f"so are {', '.join(rest)} (gains {', '.join(f'{faults[r][2]:.4g}' for r in rest)})"]
        fix = {r: factor * float(scale.get(r, 1.0)) for r, (_, factor, _) in faults.items()}
        as_dict = ", ".join(f"'{r}': {f:.6g}" for r, f in fix.items())
        as_flag = ",".join(f"{r}={f:.6g}" for r, f in fix.items())
        what.append(f"scale {'it' if len(fix) == 1 else 'them'} (`scale={{{as_dict}}}`, `--scale {as_flag}`)")
        raise DataError("; ".join(what), path=path, column=columns.get(first, first))


def _rate_fault(ts, angles, k, rate, path, columns) -> tuple[list[str], float, float] | None:
    """What is wrong with body rate `k`, the factor that fixes it, and its gain, where it is the
    attitude's derivative with the wrong sign or in other units; `None` where nothing is (see the module
    notes: only faults of that size, which hold for the whole record). **Raises:** `DataError` where
    it is another axis's rate."""
    name = _AXES[k]
    found = velocity_gain(ts, angles[:, k], rate)
    if found is None:
        return None
    gain, std, corr = found
    # A gyro against motion capture reads low where the axis barely turns (noise in the attitude's
    # steps attenuates the gain) or lags: gains of 0.12-0.93 are seen on real flights. Only a sign, a unit
    # (a factor of 2 or more) or another axis is a column fault.
    if abs(gain) <= MAX_RATE_FACTOR and (gain > 0 or abs(gain) < SIGNIFICANCE * std):
        if abs(gain) >= 1 / MAX_RATE_FACTOR:
            return None
        others = [j for j in range(3) if j != k]
        follows = [
            j
            for j in others
            if (m := velocity_gain(ts, angles[:, j], rate)) and 1 / MAX_RATE_FACTOR <= m[0] <= MAX_RATE_FACTOR
        ]
        if not follows:
            return None
        other = _AXES[follows[0]]
        raise DataError(
            f"it is not the body rate about {_ANGLE_AXIS[k]} (gain {gain:.3g} +- {std:.2g} on the attitude's "
            f"rate of change about that axis) but about {_ANGLE_AXIS[follows[0]]}: are the columns of {name} and "
            f"{other} swapped?",
            path=path,
            column=columns.get(name, name),
        )
    if abs(gain) <= SIGNIFICANCE * std:
        return None
    what = [
        f"it is not the attitude's rate of change about {_ANGLE_AXIS[k]} (from qw, qx, qy, qz): over "
        f"{BLOCK_S * 1e3:g} ms blocks its mean is {gain:.4g} +- {std:.2g} times that rate (correlation {corr:.2f})"
    ]
    if not _fault_holds_everywhere(ts, angles[:, k], rate, gain):
        return None  # wrong in some stretches only: no unit, no scale is right
    if gain < 0:
        what.append(f"it has {_OPPOSITE_SIGN}")
        factor = -1.0
    elif 0.3 * DEGREES <= gain <= 1.2 * DEGREES:  # a gyro's gain is 0.12-0.93 of the attitude's (above)
        what.append("it reads as degrees per second (the contract's rates are in rad/s)")
        factor = 1.0 / DEGREES
    else:
        factor = 1.0 / gain
    return what, factor, gain


def _fault_holds_everywhere(ts, angle, rate, gain: float) -> bool:
    """Whether the rate's fault (the opposite sign, or a gain above `MAX_RATE_FACTOR`) is seen in each of
    `STRETCHES` stretches that move: the rates' gains vary between stretches more than a velocity's
    (above), so the fault, not the gain to 20 %, must hold."""
    bounds = np.linspace(0, len(ts), STRETCHES + 1).astype(int)
    seen = 0
    for a, b in zip(bounds[:-1], bounds[1:]):
        found = velocity_gain(ts[a:b], angle[a:b], rate[a:b]) if b - a > 4 * MIN_BLOCKS else None
        if found is None or not abs(found[0]) > SIGNIFICANCE * found[1]:
            continue  # too short or too still to tell
        seen += 1
        if (found[0] < 0) != (gain < 0) or (gain > 0 and found[0] <= MAX_RATE_FACTOR):
            return False
    return seen > 0


def check_vertical(ts, z, off, path=None, columns=None) -> None:
    """Refuse a record that flies below its motors-off height (`off`: per sample, every motor off): its
    z axis points down. **Raises:** `DataError` naming the file, the z column and the first such row."""
    columns = columns or {}
    running = ~off
    if not off.any() or running.sum() < 10:
        return  # no rest to compare with, or no flight
    rests = np.flatnonzero(off)
    nearest = rests[np.clip(np.searchsorted(rests, np.flatnonzero(running)), 0, len(rests) - 1)]
    below = z[running] - z[nearest]
    spread = float(np.ptp(z))
    if spread <= 0:
        return
    # below its rest by more than a tenth of the record's height range, for most of the flight
    down = below < -0.1 * spread
    if down.mean() > MIN_FLIGHT_SHARE:
        first = int(np.flatnonzero(running)[np.argmax(down)])
        raise DataError(
            f"the vehicle flies below where it rests with its motors off ({down.mean():.0%} of the samples with "
            f"the motors running, by up to {-below.min():.3g} in z's units, first at t = {ts[first] - ts[0]:.2f} s): "
            "the z axis points down (a north-east-down or forward-right-down log?); the contract's frame has z up, "
            "so convert the position, velocity, attitude and body rates to a z-up frame (east-north-up, "
            "forward-left-up) before loading",
            path=path,
            column=columns.get("z", "z"),
            row=first + 1,
        )
