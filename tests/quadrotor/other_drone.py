"""Another drone, simulated outside dynax: a 1.5 kg X quadrotor logging its motor speeds in RPM.

An independent 6-DOF simulator (numpy and scipy's DOP853 at rtol 1e-10, no dynax code), written as an outside
probe of "another drone's logs given only a `--map`": a vehicle fifty times the Crazyflie's mass of
`synthetic_flight.py`, its own motor numbering and column names (`MAP`), logs stamped from t = 1000 s, ground
segments at both ends (motors off, then idling), and a geometric controller with a band-limited torque dither.

Vehicle: 1.5 kg X-frame, arm 0.225 m (rotor at 45 deg), J = diag(0.029, 0.029, 0.055) kg m^2.
Body frame x forward, y left, z up. World z up. Quaternion body->world, Hamilton, scalar first.
Motor numbering (my own, not Crazyflie's):
  m1 front-left  (+x,+y) spins CCW (seen from above)  -> reaction yaw torque -km w^2
  m2 rear-left   (-x,+y) spins CW                       -> +km w^2
  m3 rear-right  (-x,-y) spins CCW                      -> -km w^2
  m4 front-right (+x,-y) spins CW                       -> +km w^2
Thrust per rotor kf w^2 (w in rad/s), hover ~ 700 rad/s (~6700 RPM). Logged inputs: RPM.
Controller: geometric (Lee-style) position + attitude, updated once per log sample, motor commands
held (zero-order hold) between samples. Small dither on the torque commands for excitation.
Hidden effects (truth only): drag (body-frame linear drag, 1/s, per mass), lag (first-order motor
lag, s
the LOGGED value is then the command), gain (motor index, factor on its thrust and yaw torque).
"""

import numpy as np
from scipy.integrate import solve_ivp

M = 1.5
G = 9.81
ARM = 0.225
J = np.diag([0.029, 0.029, 0.055])
JINV = np.linalg.inv(J)
W_HOVER = 700.0
KF = M * G / 4 / W_HOVER**2
KM = 0.016 * KF
W_MAX = 1300.0
W_MIN_FLY = 150.0
a = ARM / np.sqrt(2)
POS = np.array([[a, a], [-a, a], [-a, -a], [a, -a]])  # x, y of rotors 1..4
SPIN = np.array([-1.0, 1.0, -1.0, 1.0])  # yaw torque sign per unit km w^2
# [F, tx, ty, tz] = MIX @ f  (f: rotor thrusts)
MIX = np.vstack([np.ones(4), POS[:, 1], -POS[:, 0], SPIN * KM / KF])
MIXINV = np.linalg.inv(MIX)
RPM = 60 / (2 * np.pi)


def qmul(p, q):
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def qrot(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rot2q(R):
    tr = np.trace(R)
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    else:
        i = np.argmax(np.diag(R))
        if i == 0:
            s = np.sqrt(1 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
            q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
        elif i == 1:
            s = np.sqrt(1 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
            q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
        else:
            s = np.sqrt(1 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
            q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    return q / np.linalg.norm(q)


def shape(kind, t, speed):
    """Offset from the centre (m) of a smooth 3-D path."""
    if kind == "circle":
        R = 1.5
        w = speed / R
        return np.array([R * np.cos(w * t) - R, R * np.sin(w * t), 0.3 * np.sin(0.5 * w * t)])
    if kind == "flatcircle":
        R = 1.5
        w = speed / R
        return np.array([R * np.cos(w * t) - R, R * np.sin(w * t), 0.0])
    if kind == "eight":
        R = 1.6
        w = speed / (1.3 * R)
        return np.array([R * np.sin(w * t), 0.6 * R * np.sin(2 * w * t), 0.25 * np.sin(w * t)])
    if kind == "lissajous":
        w = speed / 1.6
        return np.array([1.2 * np.sin(w * t), 1.0 * np.sin(1.5 * w * t + 0.5), 0.4 * np.sin(0.75 * w * t)])
    if kind == "helix":
        R = 1.2
        w = speed / R
        return np.array([R * np.cos(w * t) - R, R * np.sin(w * t), 0.6 * (1 - np.cos(0.25 * w * t))])
    if kind == "star":
        # rounded star: radius modulated at 5 lobes
        w = speed / 1.7
        r = 1.2 + 0.35 * np.cos(5 * 0.4 * w * t)
        return np.array([r * np.cos(0.4 * w * t) - 1.55, r * np.sin(0.4 * w * t), 0.3 * np.sin(0.8 * w * t)])
    raise ValueError(kind)


def smooth(s):  # 0..1 C2 blend
    s = np.clip(s, 0, 1)
    return s**3 * (10 - 15 * s + 6 * s * s)


class Reference:
    def __init__(self, kind, speed, t_takeoff, t_fly, t_land, hover_z=1.2, yaw_amp=0.4):
        self.kind, self.speed = kind, speed
        self.t0, self.t1, self.t2 = t_takeoff, t_fly, t_land
        self.z = hover_z
        self.yaw_amp = yaw_amp

    def pos(self, t):
        T_up = 2.5
        z_climb = self.z * smooth((t - self.t0) / T_up)
        z_down = self.z * smooth((t - self.t2) / 3.0)
        blend = smooth((t - (self.t0 + T_up)) / 3.0) * (1 - smooth((t - (self.t2 - 3.5)) / 3.0))
        tt = max(t - (self.t0 + T_up), 0.0)
        off = blend * shape(self.kind, tt, self.speed) if blend > 0 else np.zeros(3)
        p = (
            np.array([0.0, 0.0, z_climb - z_down - 0.05 * (t > self.t2 + 3.0) * smooth((t - self.t2 - 3.0) / 0.5)])
            + off
        )
        yaw = self.yaw_amp * blend * np.sin(0.3 * tt)
        return p, yaw

    def derivs(self, t, h=1e-3):
        p0, y0 = self.pos(t)
        pp, _ = self.pos(t + h)
        pm, _ = self.pos(t - h)
        v = (pp - pm) / (2 * h)
        acc = (pp - 2 * p0 + pm) / h**2
        return p0, v, acc, y0


def vee(S):
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def controller(state, ref, t, dither):
    p, v, q, w = state[0:3], state[3:6], state[6:10], state[10:13]
    pr, vr, ar, yaw = ref.derivs(t)
    R = qrot(q)
    acc = -4.0 * (p - pr) - 3.5 * (v - vr) + ar + np.array([0, 0, G])
    F = M * acc @ R[:, 2]
    b3 = acc / np.linalg.norm(acc)
    b1c = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    b2 = np.cross(b3, b1c)
    b2 /= np.linalg.norm(b2)
    b1 = np.cross(b2, b3)
    Rd = np.column_stack([b1, b2, b3])
    eR = 0.5 * vee(Rd.T @ R - R.T @ Rd)
    wn = np.array([14.0, 14.0, 6.0])
    zeta = 0.8
    KR = np.diag(J) * wn**2
    Kw = np.diag(J) * 2 * zeta * wn
    tau = -KR * eR - Kw * w + np.cross(w, J @ w) + dither
    f = MIXINV @ np.concatenate([[F], tau])
    wcmd = np.sqrt(np.clip(f, 0, None) / KF)
    return np.clip(wcmd, W_MIN_FLY, W_MAX)


def rhs(t, s, wcmd, eff):
    _p, v, q, w, om = s[0:3], s[3:6], s[6:10], s[10:13], s[13:17]
    R = qrot(q)
    lagv = eff["lagv"]
    has = lagv > 0
    mot = np.where(has, om, wcmd)
    domega = np.where(has, (wcmd - om) / np.where(has, lagv, 1.0), 0.0)
    f = KF * mot**2
    f = f * eff["gains"]
    FT = f.sum()
    tau = np.array([POS[:, 1] @ f, -POS[:, 0] @ f, (SPIN * KM / KF) @ f])
    vb = R.T @ v
    Fb = np.array([0, 0, FT]) - M * eff["drag"] * vb
    dv = R @ Fb / M - np.array([0, 0, G])
    dw = JINV @ (tau - np.cross(w, J @ w))
    dq = 0.5 * qmul(q, np.concatenate([[0.0], w]))
    return np.concatenate([v, dv, dq, dw, domega])


def simulate(
    kind,
    speed,
    seed,
    rate=100.0,
    duration=40.0,
    drag=(0, 0, 0),
    lag=0.0,
    gain=None,
    rest_off=1.0,
    rest_idle=0.7,
    lag_motor=None,
    hover_z=1.2,
):
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    t_takeoff = rest_off + rest_idle
    t_land = duration - 4.5
    ref = Reference(kind, speed, t_takeoff, t_takeoff + 2.5, t_land, hover_z=hover_z)
    lagv = np.full(4, float(lag)) if lag_motor is None else np.where(np.arange(4) == lag_motor - 1, float(lag), 0.0)
    eff = {"drag": np.asarray(drag, float), "lag": lag, "lagv": lagv, "gains": np.ones(4)}
    if gain is not None:
        eff["gains"][gain[0] - 1] = gain[1]
    n = int(round(duration * rate))
    s = np.zeros(17)
    s[6] = 1.0
    # dither: band-limited torque noise (N m), logged through the commands
    nd = n + 10
    white = rng.standard_normal((nd, 3))
    from scipy.signal import butter, lfilter

    bb, aa = butter(2, min(0.99, 8.0 / (rate / 2)))
    dith = lfilter(bb, aa, white, axis=0) * np.array([0.25, 0.25, 0.06]) * 3
    X = np.zeros((n, 13))
    U = np.zeros((n, 4))
    T = np.arange(n) * dt
    idle = 0.25 * W_HOVER
    for k in range(n):
        t = T[k]
        X[k] = s[:13]
        if t < rest_off or t >= t_land + 3.6:
            wcmd = np.zeros(4)
        elif t < t_takeoff:
            wcmd = np.full(4, idle)
        else:
            wcmd = controller(s, ref, t, dith[k] if t_takeoff + 3 < t < t_land - 1 else 0.0)
            if t >= t_land + 3.2:
                wcmd = np.full(4, idle)
        U[k] = wcmd
        on_ground = s[2] <= 1e-9
        if on_ground and KF * np.sum(wcmd**2) * eff["gains"].mean() < M * G * 1.0:
            # resting on the floor: nothing moves (motors still spin up/down with the lag)
            s[13:17] = np.where(lagv > 0, wcmd + (s[13:17] - wcmd) * np.exp(-dt / np.where(lagv > 0, lagv, 1.0)), wcmd)
            s[:3] = [s[0], s[1], 0.0]
            s[3:6] = 0
            s[10:13] = 0
            continue
        sol = solve_ivp(rhs, (t, t + dt), s, method="DOP853", rtol=1e-10, atol=1e-10, args=(wcmd, eff))
        s = sol.y[:, -1]
        s[6:10] /= np.linalg.norm(s[6:10])
        if s[2] < 0:  # touched the floor
            s[2] = 0.0
            s[3:6] = 0.0
            s[10:13] = 0.0
            # level it
            R = qrot(s[6:10])
            yaw = np.arctan2(R[1, 0], R[0, 0])
            s[6:10] = [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
    return T, X, U


def noisy(T, X, U, seed, pos_sd=1e-3, vel_sd=5e-3, att_sd=1e-3, rate_sd=0.01, rpm_sd=3.0, t0=1000.0):
    rng = np.random.default_rng(seed + 7777)
    n = len(T)
    Xn = X.copy()
    Xn[:, 0:3] += rng.normal(0, pos_sd, (n, 3))
    Xn[:, 3:6] += rng.normal(0, vel_sd, (n, 3))
    for k in range(n):
        e = rng.normal(0, att_sd, 3)
        ang = np.linalg.norm(e)
        dq = np.concatenate([[np.cos(ang / 2)], np.sin(ang / 2) * e / max(ang, 1e-12)])
        Xn[k, 6:10] = qmul(Xn[k, 6:10], dq)
    Xn[:, 10:13] += rng.normal(0, rate_sd, (n, 3))
    rpm = U * RPM
    rpm = np.where(rpm > 0, rpm + rng.normal(0, rpm_sd, rpm.shape), 0.0)
    return T + t0, Xn, rpm


COLS = [
    "time",
    "pos_x",
    "pos_y",
    "pos_z",
    "att_w",
    "att_x",
    "att_y",
    "att_z",
    "vel_x",
    "vel_y",
    "vel_z",
    "gyro_x",
    "gyro_y",
    "gyro_z",
    "rpm1",
    "rpm2",
    "rpm3",
    "rpm4",
]
MAP = (
    "t=time,x=pos_x,y=pos_y,z=pos_z,qw=att_w,qx=att_x,qy=att_y,qz=att_z,vx=vel_x,vy=vel_y,vz=vel_z,"
    "p=gyro_x,q=gyro_y,r=gyro_z,m1=rpm1,m2=rpm2,m3=rpm3,m4=rpm4"
)


def write(path, T, X, U):
    # state order is p, v, q, w; the file's is p, q, v, w
    table = np.column_stack([T, X[:, 0:3], X[:, 6:10], X[:, 3:6], X[:, 10:13], U])
    np.savetxt(path, table, delimiter=",", header=",".join(COLS), comments="", fmt="%.10g")


def flight_csv(path, kind, speed, seed, duration=25.0, **effects):
    """Fly one path (`simulate`), add the sensors' noise (`noisy`) and write it as CSV (`write`): `path`."""
    T, X, U = simulate(kind, speed, seed, duration=duration, **effects)
    write(path, *noisy(T, X, U, seed))
    return path
