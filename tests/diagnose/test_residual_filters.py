"""The one-step residuals on an arm whose motion is fast for the residuals' 0.1 s filter window.

The truth is a 5 cm double pendulum (links and masses scaled from the nominal arm: natural frequency about
15 rad/s) integrated by scipy's DOP853 (`tests.hidden_cases`), not by dynax. Read through a cubic fit of the states
and a cubic smoothing of the model's accelerations, the true model left a residual the probe explained by 33 %
(p = 0.003): a fast arm without any missing effect was called `unexplained`.
"""

import numpy as np
import pytest

from dynax import DoublePendulum
from dynax.internal import acceleration_residuals, structure_test
from tests import hidden_cases

SCALE = 0.05  # link length [m] and mass [kg] of each link, against the nominal arm's 1 m and 1 kg


@pytest.fixture(scope="module")
def small_arm():
    theta, train, held_out, _ = hidden_cases.scaled_arm(SCALE)
    truth = DoublePendulum(**{f"theta{i + 1}": float(v) for i, v in enumerate(theta)})
    return truth, train, held_out


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
