"""The one-step residuals on an arm whose motion is fast for the residuals' 0.1 s filter window.

The truth is a 5 cm double pendulum (links and masses scaled from the nominal arm: natural frequency about
15 rad/s) integrated by scipy's DOP853 (`tests.hidden_cases`), not by dynax. Read through a cubic fit of the states
and a cubic smoothing of the model's accelerations, the true model left a residual the probe explained by 33 %
(p = 0.003): a fast arm without any missing effect was called `unexplained`.
"""

import jax.numpy as jnp
import numpy as np
import pytest

from dynax import DoublePendulum, Trajectory
from dynax.internal import acceleration_residuals, structure_test
from tests import hidden_cases

SCALE = 0.05  # link length [m] and mass [kg] of each link, against the nominal arm's 1 m and 1 kg


def _records(seed=3, duration=30.0, train_s=20.0):
    # Base parameters scale as m l^2 (inertias), m l (gravity), and the damping as m l^1.5 (the same damping ratio).
    powers = np.array([3, 3, 3, 2, 2, 2.5, 2.5])
    theta = np.asarray(hidden_cases.THETA) * SCALE**powers
    case = hidden_cases.Case("small-arm", "double_pendulum", None, None, 0.0, "", "refit", seed)
    rhs, _ = hidden_cases.arm_rhs(theta, case, (0, 1))
    n = round(duration / hidden_cases.DT) + 1
    ts = np.arange(n) * hidden_cases.DT
    us = hidden_cases.multisine(n, 2, seed, 1.0) * 1.5 * SCALE**2
    xs = hidden_cases.integrate(rhs, np.zeros(4), ts, us)
    xs = xs + np.array([1e-3, 1e-3, 1e-2, 1e-2]) * np.random.default_rng(seed).standard_normal(xs.shape)
    k = round(train_s / hidden_cases.DT) + 1

    def record(a, b):
        return Trajectory(
            jnp.asarray(ts[a:b]), jnp.asarray(xs[a:b]), jnp.asarray(us[a:b]),
            ("q1", "q2", "dq1", "dq2"), ("tau1", "tau2"), "double_pendulum", "small arm",
        )  # fmt: skip

    truth = DoublePendulum(**{f"theta{i + 1}": float(v) for i, v in enumerate(theta)})
    return truth, record(0, k), record(k, n)


@pytest.fixture(scope="module")
def small_arm():
    return _records()


def test_the_true_model_of_a_fast_arm_leaves_no_structure(small_arm):
    truth, train, held_out = small_arm
    residuals, _, predicted, _ = acceleration_residuals(truth, held_out)
    # Its motion is fast for the window: accelerations of tens of rad/s^2 at 15-20 rad/s.
    assert np.sqrt(np.mean(predicted**2)) > 40.0
    # What is left is the velocities' noise through the filter, not the filter's bias (4 % of the accelerations
    # before), and the probe finds nothing in it.
    assert np.sqrt(np.mean(residuals**2)) < 0.02 * np.sqrt(np.mean(predicted**2))
    assert not structure_test(truth, train, held_out).significant


def test_a_missing_damping_on_the_fast_arm_is_structure(small_arm):
    truth, train, held_out = small_arm
    # The model without the arm's joint damping (theta6, theta7: 0.1 scaled): a missing effect the probe must see.
    undamped = DoublePendulum(**{**{f"theta{i + 1}": float(getattr(truth, f"theta{i + 1}")) for i in range(5)},
                                 "theta6": 0.0, "theta7": 0.0})  # fmt: skip
    found = structure_test(undamped, train, held_out)
    assert found.significant and found.r2 > 0.3
