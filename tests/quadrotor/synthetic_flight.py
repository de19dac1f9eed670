"""Synthetic quadrotor flights made without dynax's model code: a rigid body with the effect written out,
integrated by scipy's DOP853 (rtol 1e-9) under a geometric controller at 100 Hz (zero-order hold), so the
flight stays bounded whatever the hidden effect.

The vehicle (`Vehicle`) is by default a Crazyflie-sized X quadrotor (30 g, 46 mm arms, `NANO`); `PLUS` is
a 0.5 kg '+' quadrotor. Thrust per rotor is `kf w^2` for a normalised rotor command `w` (1 at hover); the
log records the commands in the vehicle's unit (PWM-like counts, or rotor speeds in rad/s). The hidden
effects, each written here independently of dynax:

- `drag=(du, dv, dw)`: rotor drag, a body-frame force -m D nu (nu the body velocity);
- `bias=(axis, b)`: a constant body-frame acceleration (axis 0..2, m/s^2) or angular acceleration
  (axis 3..5, rad/s^2);
- `lag=(motor, tau)`: that motor's rotor command follows the logged one with a first-order lag tau [s]
  (`motor="all"`: every motor's, with one time constant);
- `delay=T`: every rotor receives the logged commands T seconds late (a whole number of samples: the
  command logged at sample k acts from sample k + T / dt);
- `sag=(v0, v1)`: the battery voltage falls linearly from v0 to v1 [V] over the flight, logged as `vbat`
  (with 10 mV noise), and every rotor's thrust and moment per command scale with (vbat / V_REF)^2 (rotor
  speed proportional to command times voltage; `V_REF` = 4 V, one voltage for every flight of the
  vehicle, so that flights at different charges share one physics);
- `gain=(motor, k)`: that motor's thrust and yaw moment per command are k times the others' (a chipped or
  bent propeller, a weak motor): thrust `k kf w^2` for its command `w`; the controller does not know;
- `ground=R`: ground effect of rotors of radius R [m] over a floor at z = 0, thrust times
  1 / (1 - (R / 4 z_r)^2) (Cheeseman and Bennett) at the rotor plane's height z_r = z + 0.02 m; give the
  flight a low `altitude`.
Any flight can log `vbat=True` (a steady 4.0 V with its noise) without the effect.
"""

import dataclasses

import numpy as np
from scipy.integrate import solve_ivp

from dynax import Trajectory

G = 9.81
V_REF = 4.0  # the battery voltage [V] at which the normalised command 1 is the hover thrust


@dataclasses.dataclass(frozen=True)
class Vehicle:
    """A quadrotor's rigid body and rotors: `mass` [kg], principal `inertia` [kg m^2], `arm` (rotor distance
    from the centre [m]), `frame` ("x" or "+"), `km` (yaw moment per newton of thrust [m]) and `unit`
    (what the log records per normalised command: PWM-like counts, or the rotor speed at hover [rad/s])."""

    mass: float = 0.030
    inertia: tuple[float, float, float] = (1.4e-5, 1.4e-5, 2.2e-5)
    arm: float = 0.046
    frame: str = "x"
    km: float = 0.006
    unit: float = 40000.0

    @property
    def kf(self) -> float:
        return self.mass * G / 4  # thrust [N] per rotor at the normalised command 1 (hover)

    @property
    def mix(self) -> np.ndarray:
        """`[T, tx, ty, tz] = mix @ thrusts`, motors numbered as the log's m1..m4."""
        a = self.arm / np.sqrt(2) if self.frame == "x" else self.arm
        positions = (
            np.array([[a, -a], [-a, -a], [-a, a], [a, a]])
            if self.frame == "x"
            else np.array([[a, 0.0], [0.0, -a], [-a, 0.0], [0.0, a]])
        )
        spin = np.array([-1.0, 1.0, -1.0, 1.0])
        return np.vstack([np.ones(4), positions[:, 1], -positions[:, 0], self.km * spin])


#: The Crazyflie-sized X quadrotor the hidden-effect tests fly (PWM-like counts logged).
NANO = Vehicle()
#: A larger '+' quadrotor (0.5 kg, 17 cm arms) whose log records rotor speeds [rad/s], 600 at hover.
PLUS = Vehicle(mass=0.5, inertia=(2.5e-3, 2.5e-3, 4.5e-3), arm=0.17, frame="+", km=0.016, unit=600.0)

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


def _controller(t, s, c, vehicle):
    """Geometric control (Lee, Leok and McClamroch 2010) to the reference: the normalised rotor commands."""
    p, q, v, om = s[:3], s[3:7], s[7:10], s[10:13]
    R = rotation(q)
    pos, vel, acc, yaw = _reference(t, c)
    a_des = acc + 6.0 * (pos - p) + 4.0 * (vel - v) + np.array([0.0, 0.0, G])
    inertia = np.asarray(vehicle.inertia)
    thrust = vehicle.mass * a_des @ R[:, 2]
    b3 = a_des / np.linalg.norm(a_des)
    b2 = np.cross(b3, [np.cos(yaw), np.sin(yaw), 0.0])
    b2 /= np.linalg.norm(b2)
    Rd = np.column_stack([np.cross(b2, b3), b2, b3])
    E = 0.5 * (Rd.T @ R - R.T @ Rd)
    e_r = np.array([E[2, 1], E[0, 2], E[1, 0]])
    torque = inertia * (-150.0 * e_r - 20.0 * om) + np.cross(om, inertia * om)
    kf = vehicle.kf
    thrusts = np.clip(np.linalg.solve(vehicle.mix, np.concatenate([[thrust], torque])), 0.05 * kf, 4.0 * kf)
    return np.sqrt(thrusts / kf)


def lagging(effects) -> np.ndarray:
    """Which of the four rotors lag their commands under `effects` (`lag=(motor, tau)`, `motor` an index or "all")."""
    motor = effects.get("lag", (-1, 0.0))[0]
    return np.ones(4, bool) if motor == "all" else np.arange(4) == motor


def _field(t, s, command, effects, battery, vehicle):
    q, v, om = s[3:7], s[7:10], s[10:13]
    rotor = s[13:17]
    R = rotation(q)
    inertia = np.asarray(vehicle.inertia)
    thrusts = vehicle.kf * rotor**2 * battery
    if "gain" in effects:
        motor, k = effects["gain"]
        thrusts[motor] *= k  # the yaw moment is km times the thrust: it scales with it
    if "ground" in effects:
        z_rotor = max(s[2], 0.0) + 0.02
        thrusts = thrusts / (1.0 - (effects["ground"] / (4.0 * z_rotor)) ** 2)
    wrench = vehicle.mix @ thrusts
    nu = R.T @ v
    f_body = np.array([0.0, 0.0, wrench[0] / vehicle.mass])
    m_body = wrench[1:] / inertia
    if "drag" in effects:
        f_body = f_body - np.asarray(effects["drag"]) * nu
    if "bias" in effects:
        axis, b = effects["bias"]
        (f_body if axis < 3 else m_body)[axis % 3] += b
    dv = R @ f_body - np.array([0.0, 0.0, G])
    dom = m_body - np.cross(om, inertia * om) / inertia
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
        tau, lags = effects["lag"][1], lagging(effects)
        drotor[lags] = (command[lags] - rotor[lags]) / tau
    return np.concatenate([v, dq, dv, dom, drotor])


def quadrotor_flight(
    duration=20.0, seed=0, *, dt=0.01, noise=True, altitude=1.0, vbat=False, vehicle=NANO, **effects
) -> Trajectory:
    """A closed-loop flight of `duration` s sampled every `dt`, as a quadrotor `Trajectory` (inputs in the
    `vehicle`'s unit), around `altitude` [m] (the vertical swing is up to 0.3 m, or 0.8 of a lower altitude)."""
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
    v0, v1 = effects.pop("sag", (V_REF, V_REF))
    volts = v0 + (v1 - v0) * np.arange(n) / max(n - 1, 1)
    late = int(round(effects.pop("delay", 0.0) / dt))
    sent = []  # the commands logged so far; a delayed rotor receives the one logged `late` samples ago
    for k in range(n):
        command = _controller(k * dt, s, c, vehicle)
        sent.append(command)
        received = sent[max(k - late, 0)]
        s[13:17] = np.where(lagging(effects), s[13:17], received)  # the other rotors follow their commands at once
        xs[k], us[k] = s[:13], command
        if k + 1 < n:
            sol = solve_ivp(
                _field,
                (k * dt, (k + 1) * dt),
                s,
                method="DOP853",
                rtol=1e-9,
                atol=1e-11,
                args=(received, effects, (volts[k] / V_REF) ** 2, vehicle),
            )
            s = sol.y[:, -1].copy()
            s[3:7] /= np.linalg.norm(s[3:7])
    if noise:
        xs[:, :3] += 5e-4 * rng.standard_normal((n, 3))
        xs[:, 7:10] += 5e-3 * rng.standard_normal((n, 3))
        xs[:, 10:13] += 2e-2 * rng.standard_normal((n, 3))
    us, names = us * vehicle.unit, INPUT_NAMES
    if vbat or v1 != v0:
        us, names = np.column_stack([us, volts + 0.01 * rng.standard_normal(n)]), (*INPUT_NAMES, "vbat")
    return Trajectory(np.arange(n) * dt, xs, us, STATE_NAMES, names, "quadrotor", f"synthetic seed {seed}")
