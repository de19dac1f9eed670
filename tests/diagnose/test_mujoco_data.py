"""Hidden effects in data another simulator made: MuJoCo's double pendulum (`tests/mujoco_rig.py`) with the
DFKI rig's sensor noise, diagnosed against dynax's rigid arm with the right size and viscous friction. The
effect is MuJoCo's, not a dynax term: a dry friction that sticks (`frictionloss`, a constraint), a motor's
armature. Two 12 s training runs and two 12 s held-out runs, as a user with four recordings would split them.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import diagnose, Refit, Trajectory
from tests import mujoco_rig

pytestmark = pytest.mark.heavy  # end-to-end runs of a minute or more


BASE = ("theta1", "theta2", "theta3", "theta4", "theta5", "theta6", "theta7")


def _diagnose(effect: dict, scale: float):
    pytest.importorskip("mujoco")
    arm = {**mujoco_rig.RIG, "a2": 0.0, "f1": 0.0, "f2": 0.0, **effect}
    records = []
    for seed in (0, 1, 7, 8):
        ts, xs, us, _ = mujoco_rig.record(arm, 12.0, seed, scale=scale)
        records.append(
            Trajectory(jnp.asarray(ts), jnp.asarray(xs), jnp.asarray(us), mujoco_rig.STATES, mujoco_rig.INPUTS)
        )
    truth = mujoco_rig.base_parameters(arm)
    nominal = dynax.DoublePendulum.from_base_parameters({n: truth[n] for n in BASE})
    report = diagnose(nominal, records[:2], records[2:], mode=Refit())
    return report.to_json(), records


@pytest.mark.slow  # about 90 s; the quick suite keeps the MuJoCo rotor-inertia case
def test_a_dry_friction_that_sticks_is_named_coulomb_friction_with_its_size():
    report, _ = _diagnose({"f2": 0.10}, scale=0.6)
    assert report["verdict"] == "explained", (report["verdict"], report["findings"])
    first = report["findings"][0]
    assert (first["cause"], first["where"]) == ("coulomb_friction", "q2"), report["findings"]
    assert abs(first["coefficient"] - 0.10) < 0.01, first  # measured 0.1009
    # Its standard error is honest: the truth within 4 of it (measured 1.9; the Gauss-Newton one, which
    # counts a window's correlated residuals as independent, was 0.00005 N m, 19 of them away) ...
    assert abs(first["coefficient"] - 0.10) < 4 * first["std_error"], first
    # ... and small enough to mean something.
    assert first["std_error"] < 0.01, first
    assert report["gain"] > 0.5


@pytest.mark.slow  # about 90 s; the quick suite keeps the verdicts' effect-free control
def test_no_effect_claims_no_cause():
    """Nothing named; `none`, or `inconclusive` only for want of power, never for a candidate of practical size.
    Measured: no candidate gains 3 % on the typical window, and the two 12 s held-out runs (20 s of windows) let
    the test see 25.5 % in mean squared window error with 80 % power (noncentral t on the test's few degrees of
    freedom), just over the 25 % that matters: `inconclusive`, asking for 21 s."""
    report, _ = _diagnose({}, scale=0.6)
    assert report["findings"] == [], report["findings"]
    assert report["verdict"] in ("none", "inconclusive"), report["verdict"]
    power = report["test"]["power"]
    assert power["best_candidate"]["gain_typical"] < power["min_practical_gain"], power
    if report["verdict"] == "inconclusive":
        assert power["detectable_gain"] > power["min_practical_gain"], power


@pytest.mark.slow  # about 2 min; the quick suite keeps hidden effects in DOP853 records (test_verdicts.py)
def test_rotor_inertia_is_found_on_an_arm_that_turns_over():
    # At this amplitude the arm goes over the top: its angles wind up over several turns. Their spread,
    # against which the reference horizon is chosen, is taken on the circle; the unwrapped angles'
    # standard deviation (up to 6 rad here) chose a 1 s horizon, over which this chaotic arm's windows
    # drift apart so unevenly that the held-out test had no power (p = 0.026 for a 99.8 % gain: `none`).
    report, records = _diagnose({"a2": 0.0036}, scale=1.0)
    q = np.concatenate([np.asarray(r.xs[:, :2]) for r in records[:2]])
    assert np.max(np.ptp(q, axis=0)) > 2 * np.pi  # the arm turns over
    assert report["reference_horizon_s"] <= 0.5, report["horizon"]
    assert report["verdict"] == "explained", (report["verdict"], report["candidates"][:2])
    first = report["findings"][0]
    assert (first["cause"], first["where"]) == ("rotor_inertia", "q2"), report["findings"]
    assert abs(first["coefficient"] / 0.0036 - 1) < 0.1, first  # measured 0.00358
    assert abs(first["coefficient"] - 0.0036) < 4 * first["std_error"] < 0.0036, first  # measured 0.7 of them
