r"""Flight logs whose columns contradict each other: a velocity that is not its position's derivative, a
body rate that is not its attitude's, a thrust that does not push along body z, up.

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
  flights its gain is 0.16-0.85, lowest about the axes that barely turn: noise in the attitude's
  steps attenuates it, and the gyro lags), so only a fault of another size is refused: the opposite
  sign, a factor of 2 or more (degrees per second), or the rate of another axis (swapped columns);
- the rates' frame and the quaternion's direction (`check_rate_frame`, before the per-axis rates): the
  rates against the attitude's rate of change read as the body frame's, as world axes' and as that of a
  world-to-body quaternion, and as every other order and sign of the rate columns. Away from a heading along
  the world x axis, per-axis gains mistake either fault for a sign or a swap of axes whose `scale` loads a
  record still wrong, and flown level at one heading the two read alike: where they fit about as well, both
  are named and neither advised;
- the thrust: a multirotor's pushes along its body z axis, up, so its horizontal acceleration follows
  the lean of body z and its vertical acceleration rises with the motors' thrust
  (`check_thrust_frame`). A north-east-down log, a forward-right-down body or a world-to-body
  quaternion breaks one of the two; such a frame takes more than a scale to convert, and the error
  says which;
- the up axis: body z's mean direction over the flight points up (`check_up_axis`). A world frame with
  y up (a Y-up motion-capture frame) passes the thrust's checks, since the horizontal acceleration
  still follows the lean, and is refused here.

Only a fault that holds for the whole record is refused with a `scale` to fix it (a unit, a sign or
a swap): a gain that is wrong in some stretches only is no unit (see `gain_holds_everywhere` in
`dynax._data._velocities`), and a fix of the rates is named alone only where the record it makes reads
consistent and no other frame, order or sign of the rates reads nearly as well (`_refuse_unless_consistent`);
a frame that reads as well is named beside it. An order or sign of the rate columns that reads clearly best
is named where no column's gain shows it (`_refuse_other_reading`).
"""

import itertools
from typing import NamedTuple

import numpy as np

from .._errors import DataError
from ._velocities import (
    BLOCK_S,
    block_slopes,
    check_velocities,
    MAX_GAIN_ERROR,
    MIN_BLOCKS,
    SIGNIFICANCE,
    stretch_edges,
    stretch_gains,
    velocity_gain,
)

_AXES = ("p", "q", "r")
_ANGLE_AXIS = ("body x", "body y", "body z")
MAX_RATE_FACTOR = 2.0  # a body rate's gain on its attitude's beyond this (or its inverse) is a unit or a swap
DEGREES = 180.0 / np.pi
_OPPOSITE_SIGN = "the opposite sign (a gyro axis counted the other way: forward-right-down against forward-left-up?)"
STANDARD_GRAVITY = 9.80665


# A body-to-world quaternion further than this from unit norm is not an attitude measurement.
QUATERNION_TOLERANCE = 0.01


def check_unit_quaternions(quats, path, mapping=None) -> np.ndarray:
    """The norms of a record's body-to-world quaternions (rows `qw, qx, qy, qz`); a `DataError` naming the file,
    the column (as `mapping` maps it) and the first row where one is further than `QUATERNION_TOLERANCE` from 1."""
    norms = np.linalg.norm(quats, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1) > QUATERNION_TOLERANCE)
    if bad.size:
        k = int(bad[0])
        raise DataError(
            f"the quaternion (qw, qx, qy, qz) has norm {norms[k]:.6g}, not 1 (tolerance "
            f"{QUATERNION_TOLERANCE:g}; {bad.size} such rows): the contract's attitude is a unit "
            "quaternion",
            path=path,
            column=(mapping or {}).get("qw", "qw"),
            row=k + 1,
        )
    return norms


class _RateRecord(NamedTuple):
    """What the per-axis rate checks weigh and name: the times, the quaternions `(n, 4)` and the rates `(n, 3)`
    as logged, and the file, its columns (contract name -> file column) and the factors already applied."""

    ts: np.ndarray
    quats: np.ndarray
    rates: np.ndarray
    path: object
    columns: dict
    scale: dict


def attitude_angles(quats: np.ndarray, *, world: bool = False) -> np.ndarray:
    """The cumulative body-frame rotation of a body-to-world quaternion series `(n, 4)` as `(qw, qx, qy,
    qz)`: `(n, 3)` angles [rad] whose derivatives are the body rates `p, q, r` (the first row zero).

    Each step $q_i^{-1} \\otimes q_{i+1}$ is turned into its rotation vector; the quaternions' signs
    are made continuous first ($q$ and $-q$ are one attitude). With `world`, the steps are the world
    frame's, $q_{i+1} \\otimes q_i^{-1}$: angles whose derivatives are the angular velocity in world axes,
    $R\\,\\omega$."""
    q = np.asarray(quats, dtype=float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    a, b = q[:-1], q[1:]
    b = np.where(np.sum(a * b, axis=1, keepdims=True) < 0, -b, b)
    aw, av, bw, bv = a[:, :1], a[:, 1:], b[:, :1], b[:, 1:]
    w = aw * bw + np.sum(av * bv, axis=1, keepdims=True)  # conj(a) (x) b, or b (x) conj(a)
    v = aw * bv - bw * av + (1.0 if world else -1.0) * np.cross(av, bv)
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
    rates = np.stack([np.asarray(values[r], dtype=float) for r in _AXES], axis=1)
    scale = scale or {}
    record = _RateRecord(ts, quats, rates, path, columns, scale)
    faults = {}  # rate -> (what is wrong, the factor that fixes it)
    for k, rate in enumerate(_AXES):
        found = _rate_fault(record, angles, k)
        if found is not None:
            faults[rate] = found
    if not faults:
        _refuse_other_reading(record)
    if faults:
        first, (what, _, _) = next(iter(faults.items()))
        fixed = rates * np.array([faults[r][1] if r in faults else 1.0 for r in _AXES])
        fix = {r: factor * float(scale.get(r, 1.0)) for r, (_, factor, _) in faults.items()}
        as_dict = ", ".join(f"'{r}': {f:.6g}" for r, f in fix.items())
        as_flag = ",".join(f"{r}={f:.6g}" for r, f in fix.items())
        scaled = f"scale {'it' if len(fix) == 1 else 'them'} (`scale={{{as_dict}}}`, `--scale {as_flag}`)"
        _refuse_unless_consistent(record, fixed, what, scaled, columns.get(first, first))
        rest = list(faults)[1:]
        if rest:
            what = what + [f"so are {', '.join(rest)} (gains {', '.join(f'{faults[r][2]:.4g}' for r in rest)})"]
        what.append(scaled)
        raise DataError("; ".join(what), path=path, column=columns.get(first, first))


def _rate_fault(record: _RateRecord, angles, k) -> tuple[list[str], float, float] | None:
    """What is wrong with body rate `k` of `record`, the factor that fixes it, and its gain, where it is the
    attitude's derivative (`angles`, `attitude_angles`) with the wrong sign or in other units; `None` where
    nothing is (see the module notes: only faults of that size, which hold for the whole record). **Raises:**
    `DataError` where it is another axis's rate (the swap checked to make the record consistent)."""
    ts, rates, columns = record.ts, record.rates, record.columns
    name, rate = _AXES[k], rates[:, k]
    found = velocity_gain(ts, angles[:, k], rate)
    if found is None:
        return None
    gain, std, corr = found
    # A gyro against motion capture reads low where the axis barely turns (noise in the attitude's
    # steps attenuates the gain) or lags: gains of 0.16-0.85 are seen on real flights. Only a sign, a unit
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
        what = (
            f"it is not the body rate about {_ANGLE_AXIS[k]} (gain {gain:.3g} +- {std:.2g} on the attitude's "
            f"rate of change about that axis) but about {_ANGLE_AXIS[follows[0]]}"
        )
        swapped = rates.copy()
        swapped[:, [k, follows[0]]] = rates[:, [follows[0], k]]
        order = list(range(3))
        order[k], order[follows[0]] = follows[0], k
        remap = signed_reading_fix((tuple(order), (0, 0, 0)), columns, record.scale)[1]
        _refuse_unless_consistent(record, swapped, [what], f"swap them (`{remap}`)", columns.get(name, name))
        raise DataError(
            f"{what}: are the columns of {name} and {other} swapped?", path=record.path, column=columns.get(name, name)
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
    elif 0.1 * DEGREES <= gain <= 1.2 * DEGREES:  # a gyro's gain is 0.16-0.85 of the attitude's (above)
        what.append("it reads as degrees per second (the contract's rates are in rad/s)")
        factor = 1.0 / DEGREES
    else:  # no unit of rates known to dynax: the factor that makes it agree
        factor = 1.0 / gain
    return what, factor, gain


def _refuse_unless_consistent(record: _RateRecord, fixed, what: list[str], fix: str, column) -> None:
    """Refuse, without a fix, a per-axis fix of the rates that would load a record still wrong. `fixed` holds
    `p, q, r` as the fix (a sign, a unit, a swap) makes them; it reads consistent where they miss the attitude's
    body-frame rate of change by `RATE_CONSISTENT_MISFIT` at most and `RATE_FRAME_RATIO` times as closely as every
    other reading: the record as it is with a world-to-body quaternion or rates in world axes
    (`rate_frame_misfits`), and the fixed rates in another order or with other signs (`_signed_misfits`, compared
    on the axes they read otherwise). On a level flight at a heading of 180 degrees a conjugated quaternion and a
    yaw rate of the opposite sign read alike, and a swap of roll and pitch rates reads as both of their signs
    flipped on some paths: a fix is named alone only where the record tells them apart. Returns where the fix
    reads consistent, or where the record is too short or still to tell.

    **Raises:** `DataError` naming `column`, what is wrong (`what`): with the fix (`fix`, words) beside a frame
    that fits within `RATE_FRAME_RATIO` of it, neither advised; else with the order or sign of the columns that
    reads clearly best (`_refuse_other_reading`); else without a fix, naming the reading that fits as well and
    the conventions to check."""
    ts, quats, columns, scale, path = record.ts, record.quats, record.columns, record.scale, record.path
    frames = rate_frame_misfits(ts, quats, record.rates.T)
    misfit = _signed_misfits(ts, attitude_angles(quats), fixed)
    if frames is None or misfit is None:
        return
    own = misfit[[0, 1, 2], [0, 1, 2], 0]  # each axis's misfit with the fix
    after = float(np.mean(own))
    # another order or other signs of the fixed rates, compared on the axes it reads otherwise
    ratios = {
        "a world-to-body quaternion": after / frames["world_to_body"],
        "rates in world axes": after / frames["world"],
    }
    for order in itertools.permutations(range(3)):
        for signs in itertools.product((0, 1), repeat=3):
            moved = [k for k in range(3) if order[k] != k or signs[k]]
            if moved:
                other = float(np.mean([misfit[k, order[k], signs[k]] for k in moved]))
                taken = ", ".join("+-"[signs[k]] + _AXES[order[k]] for k in range(3))
                ratios[f"p, q, r taken as {taken} after that fix"] = float(np.mean(own[moved])) / other
    rival = max(ratios, key=ratios.__getitem__)
    if after <= RATE_CONSISTENT_MISFIT and ratios[rival] <= RATE_FRAME_RATIO:
        return
    frame = {"a world-to-body quaternion": "world_to_body", "rates in world axes": "world"}.get(rival)
    if after <= RATE_CONSISTENT_MISFIT and frame is not None and ratios[rival] * RATE_FRAME_RATIO <= 1.0:
        # a frame of the record as logged fits about as well as the fix, not clearly better: both are named
        raise DataError(
            "; ".join(
                [
                    *what,
                    f"{fix}, or read {_reading_words(frame, columns, scale)}: {_reading_fix(frame, columns, scale)}; "
                    f"the record cannot tell which holds (misfit on the attitude's rate of change {after:.0%} with "
                    f"the fix, {frames[frame]:.0%} so; at one heading, flown nearly level, the two read alike): check "
                    "the logger's documentation of its frames and signs, or give a stretch flown at another heading",
                ]
            ),
            path=path,
            column=column,
        )
    # the record as logged may read clearly best in another order or sign than the fix makes (a roll rate that
    # follows pitch, its gain on roll negative where roll and pitch turn against each other, is no sign fault)
    _refuse_other_reading(record)
    if after > RATE_CONSISTENT_MISFIT:
        why = (
            f"no scale or swap of the rates is right for the whole record: fixed so, p, q, r would still miss "
            f"the attitude's rate of change by {after:.0%} of its size over {BLOCK_S * 1e3:g} ms blocks "
            f"(a consistent record: {RATE_CONSISTENT_MISFIT:.0%} at most)"
        )
    else:
        why = (
            f"no scale or swap of the rates is suggested: read as {rival} the record fits nearly as well or better "
            f"(its misfit on the attitude's rate of change {1 / ratios[rival]:.2f} times that with the fix)"
        )
    raise DataError(
        "; ".join(
            [
                *what,
                why,
                "check the conventions: the quaternion body-to-world, p, q, r the body frame's (x forward, "
                "z up), each column's sign and axis",
            ]
        ),
        path=path,
        column=column,
    )


def _refuse_other_reading(record: _RateRecord) -> None:
    """Refuse rates that another order or sign of their columns reads clearly better than the record as logged
    and every other reading of `rate_readings` (`RATE_FRAME_MISFIT` and `RATE_FRAME_RATIO`, as `check_rate_frame`
    names a frame) and makes read consistent (`RATE_CONSISTENT_MISFIT`), where no column's gain named it: a roll
    rate that follows pitch while roll and pitch move against each other (the star flight's) has a negative gain
    on its own axis that holds in some stretches only. Two readings within `RATE_FRAME_RATIO` of each other are
    both named."""
    path, columns, scale = record.path, record.columns, record.scale
    found = rate_readings(record.ts, record.quats, record.rates.T)
    if found is None or found["body"] <= RATE_FRAME_MISFIT:
        return
    best, second = sorted((k for k in found if k != "body"), key=found.__getitem__)[:2]
    if not isinstance(best, tuple) or not found[best] <= RATE_FRAME_RATIO * found["body"]:
        return
    if not found[best] <= RATE_CONSISTENT_MISFIT:
        return  # no reading makes the record consistent (a spike in one rate sample moves every reading's misfit)
    if found[best] > RATE_FRAME_RATIO * found[second]:
        raise _alike_error(found, best, second, path=path, columns=columns, scale=scale)
    words, fix = signed_reading_fix(best, columns, scale)
    first = _AXES[next(k for k in range(3) if best[0][k] != k or best[1][k])]
    raise DataError(
        f"p, q, r read as {words}: so they miss the attitude's rate of change by {found[best]:.0%} of its size over "
        f"{BLOCK_S * 1e3:g} ms blocks, as logged by {found['body']:.0%}, in any other order, sign or frame by "
        f"{found[second]:.0%} or more; load them so (`{fix}`)",
        path=path,
        column=columns.get(first, first),
    )


def _signed_misfits(ts, angles, rates) -> np.ndarray | None:
    """`(3, 3, 2)`: the misfit (as `_axis_misfit`'s per axis) of body axis `k`'s angle read from rate column `j`
    with sign `+` (0) or `-` (1). `None` for a record too short or still."""
    edges = stretch_edges(ts)
    if len(edges) < MIN_BLOCKS + 1:
        return None
    misfit = np.empty((3, 3, 2))
    for k in range(3):
        for j in range(3):
            slopes, means = block_slopes(ts, angles[:, k], rates[:, j], edges)
            motion = float(np.sqrt(np.mean(slopes**2)))
            if not motion > 0:
                return None
            for i, sign in enumerate((1.0, -1.0)):
                misfit[k, j, i] = float(np.sqrt(np.mean((sign * means - slopes) ** 2))) / motion
    return misfit


def _fault_holds_everywhere(ts, angle, rate, gain: float) -> bool:
    """Whether the rate's fault (the opposite sign, or a gain above `MAX_RATE_FACTOR`) is seen in each of
    `STRETCHES` stretches that move: the rates' gains vary between stretches more than a velocity's
    (above), so the fault, not the gain to 20 %, must hold."""
    seen = 0
    for found in stretch_gains(ts, angle, rate):
        if found is None or not abs(found[0]) > SIGNIFICANCE * found[1]:
            continue  # too short or too still to tell
        seen += 1
        if (found[0] < 0) != (gain < 0) or (gain > 0 and found[0] <= MAX_RATE_FACTOR):
            return False
    return seen > 0


def body_z_in_world(values: dict) -> np.ndarray:
    """The body z axis in world coordinates, $R(q) e_z$, `(n, 3)`, of the body-to-world quaternions `qw..qz`."""
    qw, qx, qy, qz = (np.asarray(values[c], dtype=float) for c in ("qw", "qx", "qy", "qz"))
    return np.stack([2 * (qx * qz + qw * qy), 2 * (qy * qz - qw * qx), 1 - 2 * (qx**2 + qy**2)], axis=1)


def thrust_frame_slopes(ts, values: dict, motors: np.ndarray) -> tuple[float, float, float, float] | None:
    """`(c, c_std, k, k_std)` of `check_thrust_frame`: the horizontal acceleration's gain on the lean of
    body z [m/s^2] and the vertical acceleration's slope on the motors' thrust, with standard errors;
    `None` for a record of fewer than `MIN_BLOCKS` blocks."""
    ts = np.asarray(ts, dtype=float)
    edges = stretch_edges(ts)
    if len(edges) < MIN_BLOCKS + 1:
        return None
    start, stop = edges[:-1], edges[1:]
    velocity = np.stack([np.asarray(values[c], dtype=float) for c in ("vx", "vy", "vz")], axis=1)
    acceleration = (velocity[stop] - velocity[start]) / (ts[stop] - ts[start])[:, None]
    lean = body_z_in_world(values)[:, :2]  # (R e_z) horizontal
    thrust = np.sum(np.asarray(motors, dtype=float) ** 2, axis=1)

    def block_mean(x):
        area = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x[:-1], axis=0)])
        return (area[stop] - area[start]) / (stop - start).reshape((-1,) + (1,) * (x.ndim - 1))

    # Flight only: not the spin-up on the pad (thrust rising, the floor holding the vehicle) nor a motor log
    # that runs away (an input beyond 3x its level, 9x the thrust: `FlightChecks.max_input_ratio`).
    u = block_mean(thrust)
    level = float(np.median(u))
    flying = (u >= 0.5 * level) & (u <= 9.0 * level)
    if flying.sum() < MIN_BLOCKS:
        return None
    c, c_std = _slope(block_mean(lean)[flying].ravel(), acceleration[flying, :2].ravel())
    u, a_z = u[flying], acceleration[flying, 2]
    k, k_std = _slope(u - u.mean(), a_z - a_z.mean())
    return c, c_std, k, k_std


def check_thrust_frame(ts, values: dict, motors: np.ndarray, *, path=None, columns=None) -> None:
    r"""Refuse a flight record whose thrust does not act along the attitude's body z axis, up.

    A multirotor's thrust pushes along its body z axis, so over blocks of `BLOCK_S` its horizontal
    world acceleration (the velocity's change) follows the horizontal components of body z,
    $a_h \approx c\,(R e_z)_h$ with $c \approx T/m \approx g > 0$ (6.5-9.6 m/s$^2$ on the NanoBench
    flights, 1.2-1.5 on the two that fly straight ramps), and its vertical acceleration rises with
    the motors' thrust ($\sum_i m_i^2$; $t$-statistics 0-17 over the blocks in flight, at 0.5 to 9 times
    the median thrust, above 5 on 11 of the 16 flights: where the vehicle barely climbs, as on a ramp
    skimming the pad, the slope is weak, and a z axis down alone is caught on those 11). A north-east-down log with a
    forward-right-down body, or a world-to-body quaternion, turns $c$ negative; a z axis that points
    down turns the vertical slope negative. Either is refused where significant (`SIGNIFICANCE`
    standard errors, and $c$ below $-g/10$).

    **Arguments:** `ts`; `values` (contract name -> column: `qw..qz`, `vx..vz`); `motors` `(n, 4)`;
    `path`, `columns` (contract name -> file column) named in the error.

    **Raises:** `DataError` naming the file and the attitude's or the height's column.
    """
    columns = columns or {}
    found = thrust_frame_slopes(ts, values, motors)
    if found is None:
        return
    c, c_std, k, k_std = found
    if c < -SIGNIFICANCE * c_std and c < -0.1 * STANDARD_GRAVITY:
        raise DataError(
            f"the vehicle accelerates away from where its body z axis leans ({c:.3g} +- {c_std:.2g} m/s^2 of "
            "horizontal acceleration per unit lean, over "
            f"{BLOCK_S * 1e3:g} ms blocks; a multirotor's thrust along body z gives about +g): the attitude is in "
            "another frame, a forward-right-down body in a north-east-down world or a world-to-body quaternion; "
            "the contract's is a body-to-world quaternion with z up (forward-left-up in east-north-up)",
            path=path,
            column=columns.get("qw", "qw"),
        )
    if k < -SIGNIFICANCE * k_std:
        raise DataError(
            f"the vertical acceleration falls as the motors' thrust rises (slope {k / k_std:.3g} standard errors "
            "below zero, over "
            f"{BLOCK_S * 1e3:g} ms blocks): the z axis points down (a north-east-down log?); the contract's frame "
            "has z up, so convert the position, velocity, attitude and body rates to a z-up frame before loading",
            path=path,
            column=columns.get("z", "z"),
        )


MIN_MEAN_UPRIGHT = 0.3  # a flight whose body z axis' mean vertical component is below this is in another frame


def check_up_axis(ts, values: dict, *, path=None, columns=None) -> None:
    r"""Refuse a flight record whose body z axis does not point up on average: a world frame with another up.

    A multirotor holds its thrust axis, body z, near the vertical: its mean direction over a flight,
    $\overline{R e_z}$, has a vertical component $\overline{\cos\theta}$ of 0.9 or more at the tilts
    multirotors fly (under 0.5 only at a sustained tilt past 60 degrees). A log whose world frame has another
    axis up (a Y-up motion-capture frame, the default of OptiTrack's Motive and of Unity) reads the same flight
    with body z horizontal on average; every check of the thrust's direction passes it (the horizontal
    acceleration still follows the lean), the ground segments are read from the wrong axis, and a fit puts
    gravity across the flight. Refused below `MIN_MEAN_UPRIGHT`, naming the world axis body z points along.

    **Arguments:** `ts` (seconds from the record's start); `values` (contract name -> column: `qw..qz`);
    `path`, `columns` (contract name -> file column) named in the error.

    **Raises:** `DataError` naming the file and the attitude's column.
    """
    columns = columns or {}
    body_z = body_z_in_world(values)
    if len(body_z) == 0:
        return
    mean = body_z.mean(axis=0)
    if not mean[2] < MIN_MEAN_UPRIGHT:
        return
    k = int(np.argmax(np.abs(mean)))
    along = ("-" if mean[k] < 0 else "+") + "xyz"[k]
    why = (
        "a world frame whose up is y (a Y-up motion-capture frame, as OptiTrack's Motive and Unity log by default?)"
        if k == 1
        else "a world frame with another axis up"
    )
    raise DataError(
        f"the body z axis points along world {along} on average over the flight from t = {float(ts[0]):.2f} to "
        f"{float(ts[-1]):.2f} s (mean direction {mean[0]:+.2f}, {mean[1]:+.2f}, {mean[2]:+.2f}), not up: a "
        f"multirotor holds its thrust axis near the vertical, so this is {why}; the contract's world frame has z "
        "up, so rotate the position, velocity and attitude to a z-up frame before loading",
        path=path,
        column=columns.get("qw", "qw"),
    )


def _slope(x, y) -> tuple[float, float]:
    """The least-squares slope of `y` on `x` (through the origin) and its standard error."""
    xx = float(x @ x)
    if not xx > 0:
        return 0.0, np.inf
    slope = float(x @ y) / xx
    residual = y - slope * x
    return slope, float(np.sqrt(residual @ residual / max(len(x) - 1, 1) / xx))


# The order loggers write a quaternion in besides the contract's (qw, qx, qy, qz), scalar last (ROS, Eigen's
# coefficients, scipy, NanoBench): `QUATERNION_READINGS[name]` are the indices into the columns read as
# (qw, qx, qy, qz) of its w, x, y and z components.
QUATERNION_READINGS = {"scalar last, (x, y, z, w)": (3, 0, 1, 2)}
_QUATERNION = ("qw", "qx", "qy", "qz")


def _rates_agree(ts, quats, rates) -> int:
    """How many of the body rates `p, q, r` follow the attitude's rate of change about their axes within
    `MAX_RATE_FACTOR` (a gyro's gain on motion capture; see the module notes)."""
    angles = attitude_angles(quats)
    agree = 0
    for k in range(3):
        found = velocity_gain(ts, angles[:, k], rates[k])
        if found is not None and 1 / MAX_RATE_FACTOR <= found[0] <= MAX_RATE_FACTOR:
            agree += 1
    return agree


def check_quaternion_order(ts, values: dict, *, path=None, columns=None) -> None:
    """Refuse a quaternion whose components are read in another order than they were written: a scalar-last
    quaternion `(x, y, z, w)` mapped as the contract's scalar-first `(qw, qx, qy, qz)`. Read so, it is still a
    unit quaternion, but of another attitude, and the body rates stop being its rate of change; read in the
    order it was written, all three are. Refused where the columns' own order leaves a rate that does not
    follow the attitude and another order has all three follow it.

    **Raises:** `DataError` naming the file and the column read as `qw`, the order the quaternion reads in,
    and the `--map` that reads it right.
    """
    columns = columns or {}
    ts = np.asarray(ts, dtype=float)
    quats = np.stack([np.asarray(values[c], dtype=float) for c in _QUATERNION], axis=1)
    rates = [np.asarray(values[c], dtype=float) for c in _AXES]
    if _rates_agree(ts, quats, rates) == 3:
        return
    for order, index in QUATERNION_READINGS.items():
        if _rates_agree(ts, quats[:, index], rates) == 3:
            remap = ",".join(f"{c}={columns.get(_QUATERNION[i], _QUATERNION[i])}" for c, i in zip(_QUATERNION, index))
            raise DataError(
                f"the quaternion reads as {order}: the body rates p, q, r follow its rate of change "
                "only with the components in that order, while the contract's is scalar first (qw, qx, qy, qz); "
                f"map them in the order they were written (`--map {remap}`)",
                path=path,
                column=columns.get("qw", "qw"),
            )


# The body rates' misfit on the attitude's rate of change (`_axis_misfit`) below which the rates are taken as the
# body frame's whatever else fits, and the factor by which another reading must fit better to be named instead.
# On the 16 NanoBench flights, at headings of 0, 90 and 180 degrees, the body frame's misfit is 0.09-0.23 (motion
# capture's rates) and 0.51-0.84 (the gyro), every other reading's at least 0.99 times it; with either fault at 90
# or 180 degrees, or a conjugated quaternion at 0, the matching reading's is at most 0.29 times the body frame's
# with motion capture's rates (80 of 80 named) and 0.80 with the gyro's (74 of 75; the trefoil's conjugated
# quaternion at 180 degrees reads 0.82, and is refused without a fix: `_refuse_unless_consistent`)
# (`experiments/flight_rate_frames.py`). The same factor separates a frame from an order or sign of the rate
# columns: closer than it, both are named. Look-alike pairs (a conjugate and a yaw rate flipped at 180 degrees)
# come as close as 0.96 (the frame the truth) and 1.04 (the columns) with motion capture's rates; with the gyro's
# the wrong one fits up to 1.6 % better (`experiments/flight_rate_frames.py --loads`).
RATE_FRAME_MISFIT = 0.3
RATE_FRAME_RATIO = 0.8
# The body reading's misfit up to which rates that a per-axis fix (a sign, a unit, a swap) changes read consistent
# after it: above the 16 clean NanoBench flights' 0.09-0.84, either rates (`_refuse_unless_consistent`).
RATE_CONSISTENT_MISFIT = 1.0


def rate_frame_misfits(ts, quats, rates) -> dict[str, float] | None:
    """The body rates' misfit (`_misfit`: relative root-mean-square difference of block means from the angles'
    secant slopes, 0 where they agree) on the attitude's rate of change read three ways: `"body"`, the
    contract's (body-frame steps of a body-to-world quaternion); `"world"`, rates logged in world axes (the
    world frame's steps); `"world_to_body"`, a world-to-body quaternion logged as body-to-world (its body rate
    is minus the logged quaternion's world-frame one). `None` for a record too short or still to tell."""
    ts = np.asarray(ts, dtype=float)
    rates = np.stack([np.asarray(r, dtype=float) for r in rates], axis=1)
    world = attitude_angles(quats, world=True)
    body = _axis_misfit(ts, attitude_angles(quats), rates)
    in_world = _axis_misfit(ts, world, rates)
    world_to_body = _axis_misfit(ts, -world, rates)
    if body is None or in_world is None or world_to_body is None:
        return None
    return {"body": body, "world": in_world, "world_to_body": world_to_body}


def signed_reading_misfits(ts, quats, rates) -> dict[tuple[tuple[int, ...], tuple[int, ...]], float] | None:
    """The body rates' misfit (as `rate_frame_misfits`'s `"body"`) with the columns `p, q, r` read in another order
    or with other signs, each a per-axis fault of the log (a sign, a swap): keyed by `(order, signs)`, body axis `k`
    read from column `order[k]` with the sign `-` where `signs[k]` is 1; the record as logged left out. `None`
    for a record too short or still to tell."""
    ts = np.asarray(ts, dtype=float)
    rates = np.stack([np.asarray(r, dtype=float) for r in rates], axis=1)
    misfit = _signed_misfits(ts, attitude_angles(quats), rates)
    if misfit is None:
        return None
    return {
        (order, signs): float(np.mean([misfit[k, order[k], signs[k]] for k in range(3)]))
        for order in itertools.permutations(range(3))
        for signs in itertools.product((0, 1), repeat=3)
        if order != (0, 1, 2) or any(signs)
    }


def signed_reading_fix(reading, columns=None, scale=None) -> tuple[str, str]:
    """What a signed reading `(order, signs)` of `signed_reading_misfits` says of the columns `p, q, r`, and the
    `--map`/`--scale` that loads them so (`columns`: contract name -> file column; `scale`, the factors given)."""
    order, signs = reading
    columns, scale = columns or {}, scale or {}
    moved = [k for k in range(3) if order[k] != k]
    flipped = [_AXES[k] for k in range(3) if signs[k]]
    words = []
    if len(moved) == 2:
        words.append(f"the columns of {_AXES[moved[0]]} and {_AXES[moved[1]]} swapped")
    elif moved:
        words.append(f"p, q, r in the columns of {', '.join(_AXES[order[k]] for k in range(3))}")
    if flipped:
        words.append(f"{', '.join(flipped)} of the opposite sign{'s' if len(flipped) > 1 else ''}")
    flags = []
    if moved:
        flags.append("--map " + ",".join(f"{_AXES[k]}={columns.get(_AXES[order[k]], _AXES[order[k]])}" for k in moved))
    factors = {
        _AXES[k]: (-1.0 if signs[k] else 1.0) * float(scale.get(_AXES[order[k]], 1.0))
        for k in range(3)
        if signs[k] or (order[k] != k and scale.get(_AXES[order[k]], 1.0) != scale.get(_AXES[k], 1.0))
    }
    if factors:
        flags.append("--scale " + ",".join(f"{r}={f:.6g}" for r, f in factors.items()))
    return " and ".join(words), " ".join(flags)


def _axis_misfit(ts, angles, rates) -> float | None:
    """`_misfit` per axis (each relative to its own angle's slopes, so that yaw, which barely turns, counts as
    much as roll and pitch: 0 where they agree, 2 where a rate has the opposite sign), averaged over the three;
    `None` for a record too short or still."""
    edges = stretch_edges(ts)
    if len(edges) < MIN_BLOCKS + 1:
        return None
    out = []
    for k in range(3):
        slopes, means = block_slopes(ts, angles[:, k], rates[:, k], edges)
        motion = float(np.sqrt(np.mean(slopes**2)))
        if not motion > 0:
            return None
        out.append(float(np.sqrt(np.mean((means - slopes) ** 2))) / motion)
    return float(np.mean(out))


def check_rate_frame(ts, values: dict, motors=None, *, path=None, columns=None, scale=None) -> None:
    r"""Refuse body rates and an attitude of another convention than the contract's: a world-to-body quaternion
    (the inverse of the contract's body-to-world one), or rates $p, q, r$ logged in world axes. Either makes the
    rates miss the attitude's body-frame rate of change by more than `RATE_FRAME_MISFIT` of its size, and the
    reading that matches follows it `RATE_FRAME_RATIO` times as closely or better (`rate_frame_misfits`). The
    per-axis check (`check_flight_kinematics`) would name a sign or a swap of axes here, whose `scale` loads a
    record that is still wrong: at a heading of 180 degrees a conjugated quaternion reads as a yaw rate of the
    opposite sign, at 90 degrees as roll and pitch swapped. So the frame is weighed against the order or sign of the
    rate columns that fits best (`signed_reading_misfits`): one `RATE_FRAME_RATIO` times as far off as the other
    or less is named alone (the frame here, the columns by the per-axis check); two closer than that are both
    named and neither advised, unless gravity rules out the attitude as logged (`motors`, `(n, 4)`: the vehicle
    accelerates away from the lean of its body z axis, as `check_thrust_frame` tests; a conjugated quaternion
    does so near a heading of 0 degrees, where it reads as all three rates of the opposite sign). Where the
    vehicle holds its heading near that of the world's x axis and flies level, world axes are body axes and
    nothing is refused (nor much wrong).

    **Raises:** `DataError` naming the file and the column read as `qw` (the quaternion: conjugate it, the
    `scale` given) or `p` (the rates: rotate them into the body frame before loading); for two readings alike,
    both fixes.
    """
    columns, scale = columns or {}, scale or {}
    quats = np.stack([np.asarray(values[c], dtype=float) for c in _QUATERNION], axis=1)
    found = rate_readings(ts, quats, [values[c] for c in _AXES])
    if found is None or found["body"] <= RATE_FRAME_MISFIT:
        return
    reading = min(("world_to_body", "world"), key=found.__getitem__)
    if not found[reading] <= RATE_FRAME_RATIO * found["body"]:
        return
    signed = min((k for k in found if isinstance(k, tuple)), key=found.__getitem__)
    if found[signed] <= RATE_FRAME_RATIO * found[reading]:
        return  # a sign or an order of the rate columns fits clearly better: the per-axis check names it
    if found[reading] > RATE_FRAME_RATIO * found[signed] and not _attitude_against_thrust(ts, values, motors, reading):
        raise _alike_error(found, reading, signed, path=path, columns=columns, scale=scale)
    how = (
        f"p, q, r miss the attitude's rate of change by {found['body']:.0%} of its size over {BLOCK_S * 1e3:g} ms "
        f"blocks, and by {found[reading]:.0%}"
    )
    if reading == "world_to_body":
        raise DataError(
            f"the quaternion is world-to-body, the inverse of the contract's body-to-world attitude: {how} with its "
            f"vector part negated; {_reading_fix(reading, columns, scale)}",
            path=path,
            column=columns.get("qw", "qw"),
        )
    raise DataError(
        f"p, q, r are the angular velocity in world axes, not the body rates: {how} as the world frame's rate of "
        f"change; the contract's rates are the body frame's: {_reading_fix(reading, columns, scale)}",
        path=path,
        column=columns.get("p", "p"),
    )


def _attitude_against_thrust(ts, values, motors, reading) -> bool:
    """Whether gravity rules out every reading that keeps the attitude as logged where `reading` is the
    world-to-body quaternion's: the vehicle accelerates away from the lean of its body z axis
    (`check_thrust_frame`'s test). A conjugated quaternion does so near a heading along the world x axis, where it
    reads as all three rates of the opposite sign; at 180 degrees it leans as the true attitude does, and gravity
    cannot tell (nor is this taken as evidence for the attitude)."""
    if reading != "world_to_body" or motors is None:
        return False
    found = thrust_frame_slopes(ts, values, motors)
    return found is not None and found[0] < -SIGNIFICANCE * found[1] and found[0] < -0.1 * STANDARD_GRAVITY


def rate_readings(ts, quats, rates) -> dict | None:
    """Every reading of the body rates `p, q, r` and the attitude that `check_rate_frame` weighs, with its misfit:
    the contract's (`"body"`), the two other frames (`"world"`, `"world_to_body"`: `rate_frame_misfits`), and each
    other order or sign of the rate columns (keyed by `(order, signs)`: `signed_reading_misfits`). `None` for a
    record too short or still to tell."""
    frames = rate_frame_misfits(ts, quats, rates)
    signed = signed_reading_misfits(ts, quats, rates)
    if frames is None or signed is None:
        return None
    return {**frames, **signed}


def _reading_words(reading, columns, scale) -> str:
    """What a reading of `rate_readings` (not the body frame's) says of the record."""
    if reading == "world_to_body":
        return "the quaternion world-to-body (the inverse of the contract's body-to-world attitude)"
    if reading == "world":
        return "p, q, r the angular velocity in world axes"
    return signed_reading_fix(reading, columns, scale)[0]


def _reading_fix(reading, columns, scale) -> str:
    """The fix that loads the record as `reading` reads it."""
    if reading == "world_to_body":
        fix = {c: -1.0 * float(scale.get(c, 1.0)) for c in _QUATERNION[1:]}
        return (
            f"conjugate it (`scale={{{', '.join(f'{c!r}: {f:g}' for c, f in fix.items())}}}`, "
            f"`--scale {','.join(f'{c}={f:g}' for c, f in fix.items())}`)"
        )
    if reading == "world":
        return "rotate them before loading (omega_body = R(q)^T omega_world)"
    return f"`{signed_reading_fix(reading, columns, scale)[1]}`"


def _alike_error(found, first, second, *, path, columns, scale) -> DataError:
    """The refusal of a record that two readings of `rate_readings` (`first`, `second`) fit within
    `RATE_FRAME_RATIO` of each other: both named with their fixes, neither advised."""
    a, b = sorted((first, second), key=found.__getitem__)
    each = [f"{_reading_words(r, columns, scale)} ({found[r]:.0%}; {_reading_fix(r, columns, scale)})" for r in (a, b)]
    quaternion = "world_to_body" in (a, b)
    return DataError(
        f"p, q, r miss the attitude's rate of change by {found['body']:.0%} of its size over {BLOCK_S * 1e3:g} ms "
        f"blocks; two readings fit about as well, and the record cannot tell which holds: {each[0]}, or {each[1]}; "
        "at one heading, flown nearly level, the two read alike: check the logger's documentation of its frames "
        "and signs, or give a stretch flown at another heading",
        path=path,
        column=columns.get("qw", "qw") if quaternion else columns.get("p", "p"),
    )


def check_position_units(ts, values: dict, motors, *, path=None, columns=None, scale=None) -> None:
    """Refuse a position in millimetres beside a velocity in metres per second. The velocity's comparison
    with the position's change (`check_velocities`) says only that the two differ by a factor of 1000; gravity
    says which is wrong: a multirotor's horizontal acceleration follows the lean of its body z axis at about
    $g$ per unit lean (`thrust_frame_slopes`), so a velocity whose change does that is in m/s.

    **Raises:** `DataError` naming the file and the column read as `x`, and the `scale` of the position.
    """
    columns, scale = columns or {}, scale or {}
    ts = np.asarray(ts, dtype=float)
    gains = [velocity_gain(ts, values[p], values[v]) for v, p in (("vx", "x"), ("vy", "y"), ("vz", "z"))]
    moving = [g[0] for g in gains if g is not None and abs(g[0]) > SIGNIFICANCE * g[1]]
    if not moving or not all(abs(g / 1e-3 - 1) < 0.05 for g in moving):
        return
    slopes = thrust_frame_slopes(ts, values, motors)
    if slopes is None or not 0.1 * STANDARD_GRAVITY < slopes[0] < 3 * STANDARD_GRAVITY:
        return  # the velocity's own unit is not pinned: `check_velocities` names the disagreement
    fix = {c: 1e-3 * float(scale.get(c, 1.0)) for c in ("x", "y", "z")}
    raise DataError(
        f"the position reads as millimetres: vx, vy, vz are {np.median(moving):.4g} times its change per second, "
        f"and their change follows the lean of body z at {slopes[0]:.3g} m/s^2 per unit lean (about g: they are "
        "in m/s); scale the position, not the velocity "
        f"(`scale={{{', '.join(f'{c!r}: {f:g}' for c, f in fix.items())}}}`, "
        f"`--scale {','.join(f'{c}={f:g}' for c, f in fix.items())}`)",
        path=path,
        column=columns.get("x", "x"),
    )


def _rotated(quats, vectors, inverse=False):
    """Each vector rotated by its body-to-world quaternion `(qw, qx, qy, qz)` (by its inverse with `inverse`)."""
    w, x, y, z = (quats[:, i] for i in range(4))
    r = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )
    return np.einsum("nji,nj->ni" if inverse else "nij,nj->ni", r, vectors)


def _misfit(ts, position, velocity) -> float | None:
    """The velocity's block means against the position's secant slopes, over all three axes: the residual's
    root mean square relative to the slopes' (0 where they agree); `None` for a record too short or still."""
    edges = stretch_edges(ts)
    if len(edges) < MIN_BLOCKS + 1:
        return None
    blocks = [block_slopes(ts, position[:, i], velocity[:, i], edges) for i in range(3)]
    slopes, means = (np.stack([b[k] for b in blocks], axis=1) for k in (0, 1))
    motion = float(np.sqrt(np.mean(slopes**2)))
    return float(np.sqrt(np.mean((means - slopes) ** 2))) / motion if motion > 0 else None


def check_velocity_frame(ts, values: dict, *, path=None, columns=None) -> None:
    """Refuse a velocity logged in the body frame where the contract's is the world frame's: `vx, vy, vz`
    miss the position's change by more than `MAX_GAIN_ERROR` of its size, and rotated into the world by the
    attitude they follow it at least twice as closely.

    **Raises:** `DataError` naming the file and the column read as `vx`.
    """
    columns = columns or {}
    ts = np.asarray(ts, dtype=float)
    position = np.stack([np.asarray(values[c], dtype=float) for c in ("x", "y", "z")], axis=1)
    velocity = np.stack([np.asarray(values[c], dtype=float) for c in ("vx", "vy", "vz")], axis=1)
    quats = np.stack([np.asarray(values[c], dtype=float) for c in _QUATERNION], axis=1)
    as_world = _misfit(ts, position, velocity)
    if as_world is None or as_world <= MAX_GAIN_ERROR:
        return
    as_body = _misfit(ts, position, _rotated(quats, velocity))
    if as_body is not None and as_body < 0.5 * as_world:
        raise DataError(
            f"vx, vy, vz are the body frame's velocity: as logged they miss the position's change by {as_world:.0%} "
            f"of its size over {BLOCK_S * 1e3:g} ms blocks, rotated by the attitude into the world frame by "
            f"{as_body:.0%}; the contract's velocity is the world frame's: rotate it before loading "
            "(v_world = R(q) v_body)",
            path=path,
            column=columns.get("vx", "vx"),
        )
