"""Synthetic quadrotor flights made without dynax's model code: a rigid body with the effect written out,
integrated by scipy's DOP853 (rtol 1e-9) under a geometric controller at 100 Hz (zero-order hold), so the
flight stays bounded whatever the hidden effect.

The vehicle is a Crazyflie-sized X quadrotor (30 g, 46 mm arms). Thrust per rotor is `KF w^2` for a
normalised rotor command `w` (1 at hover); the log records the commands as PWM-like counts. The hidden
effects, each written here independently of dynax:

- `drag=(du, dv, dw)`: rotor drag, a body-frame force -m D nu (nu the body velocity);
- `bias=(axis, b)`: a constant body-frame acceleration (axis 0..2, m/s^2) or angular acceleration
  (axis 3..5, rad/s^2);
- `lag=(motor, tau)`: that motor's rotor command follows the logged one with a first-order lag tau [s];
- `sag=(v0, v1)`: the battery voltage falls linearly from v0 to v1 [V] over the flight, logged as `vbat`
  (with 10 mV noise), and every rotor's thrust and moment per command scale with (vbat / v0)^2 (rotor
  speed proportional to command times voltage);
- `ground=R`: ground effect of rotors of radius R [m] over a floor at z = 0, thrust times
  1 / (1 - (R / 4 z_r)^2) (Cheeseman and Bennett) at the rotor plane's height z_r = z + 0.02 m; give the
  flight a low `altitude`.
Any flight can log `vbat=True` (a steady 4.0 V with its noise) without the effect.
"""

import numpy as np
from scipy.integrate import solve_ivp

from dynax import Trajectory

MASS, G = 0.030, 9.81
INERTIA = np.array([1.4e-5, 1.4e-5, 2.2e-5])
ARM = 0.046 / np.sqrt(2)
KF = MASS * G / 4  # thrust [N] at the normalised command 1 (hover)
KM = 0.006  # yaw moment per newton of thrust [m]
PWM = 40000.0  # counts per normalised command in the log
# X frame: motor positions (x, y) and spin directions.
POSITIONS = np.array([[ARM, -ARM], [-ARM, -ARM], [-ARM, ARM], [ARM, ARM]])
SPIN = np.array([-1.0, 1.0, -1.0, 1.0])
MIX = np.vstack([np.ones(4), POSITIONS[:, 1], -POSITIONS[:, 0], KM * SPIN])  # [T, tx, ty, tz] = MIX @ thrusts
UNMIX = np.linalg.inv(MIX)

STATE_NAMES = ("x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "p", "q", "r")
INPUT_NAMES = ("m1", "m2", "m3", "m4")


def rotation(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _reference(t, c):
    """Position, velocity and acceleration of a smooth closed path (sums of sines) and the yaw."""
    a, w, ph = c["amplitude"], c["omega"], c["phase"]
    pos = a * np.sin(w * t + ph)
    vel = a * w * np.cos(w * t + ph)
    acc = -a * w**2 * np.sin(w * t + ph)
    pos = pos + np.array([0.0, 0.0, c["altitude"]])
    yaw = c["yaw"] * np.sin(c["yaw_omega"] * t)
    return pos, vel, acc, yaw


def _controller(t, s, c):
    """Geometric control (Lee, Leok and McClamroch 2010) to the reference: the normalised rotor commands."""
    p, q, v, om = s[:3], s[3:7], s[7:10], s[10:13]
    R = rotation(q)
    pos, vel, acc, yaw = _reference(t, c)
    a_des = acc + 6.0 * (pos - p) + 4.0 * (vel - v) + np.array([0.0, 0.0, G])
    thrust = MASS * a_des @ R[:, 2]
    b3 = a_des / np.linalg.norm(a_des)
    b2 = np.cross(b3, [np.cos(yaw), np.sin(yaw), 0.0])
    b2 /= np.linalg.norm(b2)
    Rd = np.column_stack([np.cross(b2, b3), b2, b3])
    E = 0.5 * (Rd.T @ R - R.T @ Rd)
    e_r = np.array([E[2, 1], E[0, 2], E[1, 0]])
    torque = INERTIA * (-150.0 * e_r - 20.0 * om) + np.cross(om, INERTIA * om)
    thrusts = np.clip(UNMIX @ np.concatenate([[thrust], torque]), 0.05 * KF, 4.0 * KF)
    return np.sqrt(thrusts / KF)


def _field(t, s, command, effects, battery=1.0):
    q, v, om = s[3:7], s[7:10], s[10:13]
    rotor = s[13:17]
    R = rotation(q)
    thrusts = KF * rotor**2 * battery
    if "ground" in effects:
        z_rotor = max(s[2], 0.0) + 0.02
        thrusts = thrusts / (1.0 - (effects["ground"] / (4.0 * z_rotor)) ** 2)
    wrench = MIX @ thrusts
    nu = R.T @ v
    f_body = np.array([0.0, 0.0, wrench[0] / MASS])
    m_body = wrench[1:] / INERTIA
    if "drag" in effects:
        f_body = f_body - np.asarray(effects["drag"]) * nu
    if "bias" in effects:
        axis, b = effects["bias"]
        (f_body if axis < 3 else m_body)[axis % 3] += b
    dv = R @ f_body - np.array([0.0, 0.0, G])
    dom = m_body - np.cross(om, INERTIA * om) / INERTIA
    w, x, y, z = q
    dq = 0.5 * np.array(
        [
            -x * om[0] - y * om[1] - z * om[2],
            w * om[0] + y * om[2] - z * om[1],
            w * om[1] + z * om[0] - x * om[2],
            w * om[2] + x * om[1] - y * om[0],
        ]
    )
    drotor = np.zeros(4)
    if "lag" in effects:
        motor, tau = effects["lag"]
        drotor[motor] = (command[motor] - rotor[motor]) / tau
    return np.concatenate([v, dq, dv, dom, drotor])


def quadrotor_flight(duration=20.0, seed=0, *, dt=0.01, noise=True, altitude=1.0, vbat=False, **effects) -> Trajectory:
    """A closed-loop flight of `duration` s sampled every `dt`, as a quadrotor `Trajectory` (PWM-like inputs),
    around `altitude` [m] (the vertical swing is up to 0.3 m, or 0.8 of a lower altitude)."""
    rng = np.random.default_rng(seed)
    c = {
        "altitude": altitude,
        "amplitude": np.array([1.0, 1.0, min(0.3, 0.8 * altitude)]) * rng.uniform(0.7, 1.0, 3),
        "omega": rng.uniform(0.8, 1.6, 3),
        "phase": rng.uniform(0, 2 * np.pi, 3),
        "yaw": rng.uniform(0.5, 1.0),
        "yaw_omega": rng.uniform(0.2, 0.5),
    }
    pos, vel, _, yaw = _reference(0.0, c)
    s = np.concatenate([pos, [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)], vel, np.zeros(3), np.ones(4)])
    n = int(round(duration / dt)) + 1
    xs, us = np.zeros((n, 13)), np.zeros((n, 4))
    v0, v1 = effects.pop("sag", (4.0, 4.0))
    volts = v0 + (v1 - v0) * np.arange(n) / max(n - 1, 1)
    for k in range(n):
        command = _controller(k * dt, s, c)
        follows = np.arange(4) != effects.get("lag", (-1, 0.0))[0]
        s[13:17] = np.where(follows, command, s[13:17])  # the other rotors follow their commands at once
        xs[k], us[k] = s[:13], command
        if k + 1 < n:
            sol = solve_ivp(
                _field,
                (k * dt, (k + 1) * dt),
                s,
                method="DOP853",
                rtol=1e-9,
                atol=1e-11,
                args=(command, effects, (volts[k] / v0) ** 2),
            )
            s = sol.y[:, -1].copy()
            s[3:7] /= np.linalg.norm(s[3:7])
    if noise:
        xs[:, :3] += 5e-4 * rng.standard_normal((n, 3))
        xs[:, 7:10] += 5e-3 * rng.standard_normal((n, 3))
        xs[:, 10:13] += 2e-2 * rng.standard_normal((n, 3))
    us, names = us * PWM, INPUT_NAMES
    if vbat or v1 != v0:
        us, names = np.column_stack([us, volts + 0.01 * rng.standard_normal(n)]), (*INPUT_NAMES, "vbat")
    return Trajectory(np.arange(n) * dt, xs, us, STATE_NAMES, names, "quadrotor", f"synthetic seed {seed}")
