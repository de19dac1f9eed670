"""Independent reference implementations used by several tests.

The acrobot here is Drake's `AcrobotPlant` written out in physical parameters with numpy and integrated
by scipy's DOP853: it shares no code with dynax's base-parameter model or its diffrax integrators, so
data made with it test identification against a different implementation and a different integrator.
"""

import numpy as np
from scipy.integrate import solve_ivp

DRAKE = dict(m1=1.0, m2=1.0, l1=1.0, lc1=0.5, lc2=1.0, Ic1=0.083, Ic2=0.33, b1=0.1, b2=0.1, g=9.81)  # Drake's defaults


def spong_reference(p, x, tau, coulomb=(0.0, 0.0), rotor=(0.0, 0.0)):
    """Drake's AcrobotPlant equations written out in physical parameters (numpy), with optional Coulomb
    friction `coulomb = (fc1, fc2)` (joint torque $-f_c\\,\\mathrm{sign}(\\dot q)$) and reflected rotor
    inertias `rotor = (Ir1, Ir2)` added to the mass matrix's diagonal."""
    m1, m2, l1, lc1, lc2, Ic1, Ic2, b1, b2, g = (
        p[k] for k in ("m1", "m2", "l1", "lc1", "lc2", "Ic1", "Ic2", "b1", "b2", "g")
    )
    q1, q2, dq1, dq2 = x
    I1, I2 = Ic1 + m1 * lc1**2, Ic2 + m2 * lc2**2
    c2, s1, s2, s12 = np.cos(q2), np.sin(q1), np.sin(q2), np.sin(q1 + q2)
    m12 = I2 + m2 * l1 * lc2 * c2
    M = np.array([[I1 + I2 + m2 * l1**2 + 2 * m2 * l1 * lc2 * c2 + rotor[0], m12], [m12, I2 + rotor[1]]])
    C = np.array([[-2 * m2 * l1 * lc2 * s2 * dq2, -m2 * l1 * lc2 * s2 * dq2], [m2 * l1 * lc2 * s2 * dq1, 0]])
    tau_g = np.array([-m1 * g * lc1 * s1 - m2 * g * (l1 * s1 + lc2 * s12), -m2 * g * lc2 * s12])
    friction = np.array([b1 * dq1 + coulomb[0] * np.sign(dq1), b2 * dq2 + coulomb[1] * np.sign(dq2)])
    ddq = np.linalg.solve(M, tau + tau_g - C @ np.array([dq1, dq2]) - friction)
    return np.concatenate([[dq1, dq2], ddq])


def scipy_acrobot(x0, ts, us, p=DRAKE, coulomb=(0.0, 0.0), rotor=(0.0, 0.0), rtol=1e-11, atol=1e-12):
    """The acrobot (elbow torque `us[:, 0]`) by DOP853, restarted at each sample (zero-order hold)."""
    x = np.asarray(x0, dtype=float)
    out = [x]
    for k in range(len(ts) - 1):
        tau = np.array([0.0, float(us[k][0])])
        sol = solve_ivp(
            lambda t, y: spong_reference(p, y, tau, coulomb, rotor),
            (float(ts[k]), float(ts[k + 1])),
            x,
            method="DOP853",
            rtol=rtol,
            atol=atol,
        )
        x = sol.y[:, -1]
        out.append(x)
    return np.asarray(out)


def arm_reference(theta, x, tau, coulomb=(0.0, 0.0), velocity_scale=0.01, rotor=(0.0, 0.0)):
    r"""A two-link arm hanging from its shoulder (the DFKI rig's double pendulum, both joints driven) in
    base parameters `theta = (theta1, ..., theta7)` ($\theta_1 = I_1 + m_2 l_1^2$, $\theta_2 = I_2$,
    $\theta_3 = m_2 l_1 l_{c2}$, $\theta_4 = g(m_1 l_{c1} + m_2 l_1)$, $\theta_5 = g m_2 l_{c2}$, viscous
    $\theta_6, \theta_7$), written out with numpy from the Lagrangian: a smoothed Coulomb friction
    $-f_c \tanh(\dot q / v_s)$ at each joint and reflected rotor inertias `rotor` on the mass matrix's
    diagonal. For data made apart from dynax's model code (a scalar-input, closed-form 2x2 solve)."""
    t1, t2, t3, t4, t5, t6, t7 = theta
    q1, q2, dq1, dq2 = x
    c2, s2, s1, s12 = np.cos(q2), np.sin(q2), np.sin(q1), np.sin(q1 + q2)
    m11, m12, m22 = t1 + t2 + 2 * t3 * c2 + rotor[0], t2 + t3 * c2, t2 + rotor[1]
    h1 = (
        tau[0]
        + t3 * s2 * (2 * dq1 * dq2 + dq2**2)
        - t4 * s1
        - t5 * s12
        - t6 * dq1
        - coulomb[0] * np.tanh(dq1 / velocity_scale)
    )
    h2 = tau[1] - t3 * s2 * dq1**2 - t5 * s12 - t7 * dq2 - coulomb[1] * np.tanh(dq2 / velocity_scale)
    det = m11 * m22 - m12 * m12
    return np.array([dq1, dq2, (m22 * h1 - m12 * h2) / det, (m11 * h2 - m12 * h1) / det])


def arm_run(theta, duration, rate_hz, drive, x0=(0.2, 0.0, 0.0, 0.0), rtol=1e-10, atol=1e-11):
    """`(ts, xs, taus)`: `arm_reference` under the torques `drive(t)` (a pair), integrated by scipy's DOP853 and
    sampled at `rate_hz` for `duration` seconds from `x0`; `taus` is `drive` at the sample times."""
    ts = np.arange(0.0, duration + 0.5 / rate_hz, 1.0 / rate_hz)
    sol = solve_ivp(
        lambda t, x: arm_reference(theta, x, drive(t)),
        (0.0, ts[-1]),
        list(x0),
        t_eval=ts,
        method="DOP853",
        rtol=rtol,
        atol=atol,
    )
    return ts, sol.y.T, np.array([drive(t) for t in ts])


def _arm_pieces(theta, x, tau, fc, fs, vst, direction):
    """Mass matrix and the generalised force of the arm with each joint's friction as the Stribeck curve
    $-[f_c + (f_s - f_c) e^{-(\\dot q/v_{st})^2}]\\,s$ in the direction `s` it slips (0 where it sticks)."""
    t1, t2, t3, t4, t5, t6, t7 = theta
    q1, q2, dq1, dq2 = x
    c2, s2, s1, s12 = np.cos(q2), np.sin(q2), np.sin(q1), np.sin(q1 + q2)
    mass = np.array([[t1 + t2 + 2 * t3 * c2, t2 + t3 * c2], [t2 + t3 * c2, t2]])
    force = np.array(
        [
            tau[0] + t3 * s2 * (2 * dq1 * dq2 + dq2**2) - t4 * s1 - t5 * s12 - t6 * dq1,
            tau[1] - t3 * s2 * dq1**2 - t5 * s12 - t7 * dq2,
        ]
    )
    for j, v in enumerate((dq1, dq2)):
        force[j] -= (fc[j] + (fs[j] - fc[j]) * np.exp(-((v / vst) ** 2))) * direction[j]
    return mass, force


def _arm_stuck(mass, force, stuck):
    """Accelerations and the stuck joints' friction forces: solves $M\\ddot q = F + \\sum_{j \\in S} e_j f_j$
    with $\\ddot q_j = 0$ for the stuck joints $S$."""
    n = len(force)
    free = [j for j in range(n) if j not in stuck]
    a = np.zeros((n, n))
    a[:, : len(free)] = mass[:, free]
    for k, j in enumerate(stuck):
        a[j, len(free) + k] = -1.0
    z = np.linalg.solve(a, force)
    ddq = np.zeros(n)
    ddq[free] = z[: len(free)]
    return ddq, dict(zip(stuck, z[len(free) :]))


def stick_slip_arm(
    theta,
    x0,
    ts,
    us,
    fc=(0.0, 0.0),
    fs=(0.0, 0.0),
    vst=0.05,
    rtol=1e-10,
    atol=1e-12,
    dwell=None,
    slip_distance=0.005,
    hold_time=0.01,
    memory0=(1.0, 1.0),
):
    r"""The two-link arm of `arm_reference` (both joints driven, `us` of shape `(time, 2)`, zero-order hold) with
    stick-slip friction made by an event-based integrator (Karnopp's switch, integrated exactly): a joint
    at rest sticks (speed held at exactly 0) while the friction it needs stays within $\pm f_s$; it breaks
    away when it would need more, and slips with the Stribeck friction
    $-[f_c + (f_s - f_c) e^{-(\dot q / v_{st})^2}]\operatorname{sign}(\dot q)$ until its speed crosses zero,
    where it sticks again if the friction can hold it. scipy's DOP853 between events (`solve_ivp` events on
    each slipping joint's speed and each stuck joint's needed friction). Shares no code with dynax's models.

    With `dwell` (rising static friction) each joint carries a memory of rest $m$ (from `memory0`): it grows as
    $\dot m = (1 - m) / T_d$ while the joint is stuck and falls as
    $\dot m = -|\dot q|\,m / (d_s + |\dot q|\,\tau_h)$ while it slips (over a slip of `slip_distance` $d_s$, no
    faster than `hold_time` $\tau_h$), and the static level is $f_c + m (f_s - f_c)$, in the breakaway test and in
    the Stribeck curve.

    Returns the states `(time, 4)` (`(time, 6)` with a `dwell`: the memories after the speeds) and a boolean
    `(time, 2)` of the joints stuck at each sample."""
    fc, fs_full = np.asarray(fc, float), np.asarray(fs, float)
    n = 2
    x = np.asarray(x0, dtype=float).copy()
    if dwell is not None:
        x = np.concatenate([x, np.asarray(memory0, float)])

    def level(y):
        """The static level: with a dwell, as far as the memory of rest has built it."""
        return fs_full if dwell is None else fc + y[4:] * (fs_full - fc)

    def classify(x, tau, stuck, direction):
        """Which joints at zero speed stick, and the slip direction of the others (from the needed force)."""
        stuck = list(stuck)
        fs = level(x)
        for _ in range(2 * n):
            changed = False
            mass, force = _arm_pieces(theta, x[:4], tau, fc, fs, vst, direction)
            _, held = _arm_stuck(mass, force, stuck)
            for j, f in held.items():
                if abs(f) > fs[j] * (1 + 1e-9):
                    stuck.remove(j)
                    direction[j] = -np.sign(f)
                    changed = True
                    break
            if changed:
                continue
            for j in range(n):
                if j not in stuck and x[2 + j] == 0.0:
                    trial = [*stuck, j]
                    d = direction.copy()
                    d[j] = 0.0
                    mass, force = _arm_pieces(theta, x[:4], tau, fc, fs, vst, d)
                    _, held = _arm_stuck(mass, force, trial)
                    if abs(held[j]) <= fs[j]:
                        stuck, direction, changed = trial, d, True
                        break
                    direction[j] = -np.sign(held[j])
            if not changed:
                break
        for j in stuck:
            direction[j] = 0.0
        return sorted(stuck), direction

    stuck = []
    direction = np.sign(x[2:4]).astype(float)
    for j in range(n):
        if x[2 + j] == 0.0:
            direction[j] = 0.0
    out, stuck_out = [x.copy()], []
    for k in range(len(ts) - 1):
        tau = np.asarray(us[k], float)
        t, t_end = float(ts[k]), float(ts[k + 1])
        stuck, direction = classify(x, tau, stuck, direction)
        stuck_out.append([j in stuck for j in range(n)])
        for _ in range(1000):
            if t >= t_end:
                break

            def rhs(_, y, stuck=tuple(stuck), direction=direction.copy()):
                mass, force = _arm_pieces(theta, y[:4], tau, fc, level(y), vst, direction)
                ddq, _ = _arm_stuck(mass, force, list(stuck))
                dq = y[2:4].copy()
                dq[list(stuck)] = 0.0
                if dwell is None:
                    return np.concatenate([dq, ddq])
                m = y[4:]
                wear = np.abs(dq) / (slip_distance + np.abs(dq) * hold_time)
                dm = np.where([j in stuck for j in range(n)], (1.0 - m) / dwell, -wear * m)
                return np.concatenate([dq, ddq, dm])

            events = []
            for j in range(n):
                if j in stuck:

                    def breakaway(_, y, j=j, stuck=tuple(stuck), direction=direction.copy()):
                        fs = level(y)
                        mass, force = _arm_pieces(theta, y[:4], tau, fc, fs, vst, direction)
                        return fs[j] - abs(_arm_stuck(mass, force, list(stuck))[1][j])

                    events.append(breakaway)
                else:

                    def reversal(_, y, j=j):
                        return y[2 + j]

                    events.append(reversal)
            for e in events:
                e.terminal = True
            sol = solve_ivp(rhs, (t, t_end), x, method="DOP853", rtol=rtol, atol=atol, events=events)
            x = sol.y[:, -1].copy()
            t = float(sol.t[-1])
            if sol.status == 1:  # an event: re-classify at the event's state
                for j, te in enumerate(sol.t_events):
                    if len(te) and j not in stuck:
                        x[2 + j] = 0.0
                stuck, direction = classify(x, tau, stuck, direction)
                # step a hair past the event, so that it does not fire again at once
                if t < t_end:
                    rhs_now = rhs(t, x, tuple(stuck), direction.copy())
                    h = min(1e-9, t_end - t)
                    x = x + h * rhs_now
                    t += h
        for j in stuck:
            x[2 + j] = 0.0
        out.append(x.copy())
    stuck_out.append([j in stuck for j in range(n)])
    return np.asarray(out), np.asarray(stuck_out)


def ar1_runs(rng, runs: int, windows: int, phi: float, mean: float, burn_in: int = 50):
    """Paired window differences of `runs` held-out runs of `windows` windows each: `mean` plus an AR(1) of
    coefficient `phi` and unit innovations, started at zero `burn_in` windows before the first kept one. Returns
    `(d, run_index)` as `paired_block_test` takes them. Its long-run variance is $1/(1-\\phi)^2$."""
    import scipy.signal

    e = rng.normal(0.0, 1.0, (runs, windows + burn_in))
    e[:, 0] = 0.0  # the series starts at zero
    x = scipy.signal.lfilter([1.0], [1.0, -phi], e, axis=1)
    return (mean + x[:, burn_in:]).ravel(), np.repeat(np.arange(runs), windows)
