"""Independent reference implementations used by several tests."""

import numpy as np


def spong_reference(p, x, tau):
    """Drake's AcrobotPlant equations written out in physical parameters (numpy)."""
    m1, m2, l1, lc1, lc2, Ic1, Ic2, b1, b2, g = (p[k] for k in ("m1", "m2", "l1", "lc1", "lc2", "Ic1", "Ic2", "b1", "b2", "g"))
    q1, q2, dq1, dq2 = x
    I1, I2 = Ic1 + m1 * lc1**2, Ic2 + m2 * lc2**2
    c2, s1, s2, s12 = np.cos(q2), np.sin(q1), np.sin(q2), np.sin(q1 + q2)
    m12 = I2 + m2 * l1 * lc2 * c2
    M = np.array([[I1 + I2 + m2 * l1**2 + 2 * m2 * l1 * lc2 * c2, m12], [m12, I2]])
    C = np.array([[-2 * m2 * l1 * lc2 * s2 * dq2, -m2 * l1 * lc2 * s2 * dq2], [m2 * l1 * lc2 * s2 * dq1, 0]])
    tau_g = np.array([-m1 * g * lc1 * s1 - m2 * g * (l1 * s1 + lc2 * s12), -m2 * g * lc2 * s12])
    ddq = np.linalg.solve(M, tau + tau_g - C @ np.array([dq1, dq2]) - np.array([b1 * dq1, b2 * dq2]))
    return np.concatenate([[dq1, dq2], ddq])
