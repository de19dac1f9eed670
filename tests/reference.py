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
