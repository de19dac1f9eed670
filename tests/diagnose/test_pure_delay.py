"""A pure dead time on the elbow torque, made by delaying the torque samples (not by a Pade filter):
dynax must name `input_delay@tau2` with its size and call the verdict `explained`."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dynax import Acrobot, diagnose, Extended, FixedGrid, InputDelay, Refit, simulate, Trajectory
from dynax.internal import acceleration_residuals, exact_delays
from dynax.synthetic import DEMO_TRUTH_PHYSICAL, multisine

DELAY_SAMPLES, DT = 3, 0.01  # 0.03 s


pytestmark = pytest.mark.heavy  # end-to-end runs of a minute or more


def dead_time_run(seed: int, duration: float = 30.0):
    """The truth acrobot driven by the recorded torque three samples late (exact under the zero-order hold)."""
    truth = Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL)
    ts = jnp.arange(int(round(duration / DT)) + 1) * DT
    us = multisine(ts, 1, seed=seed, amplitude=2.0)
    applied = jnp.concatenate([jnp.repeat(us[:1], DELAY_SAMPLES, axis=0), us[:-DELAY_SAMPLES]])
    xs = simulate(truth, jnp.zeros(4), ts, applied, method=FixedGrid(substeps=4)).xs
    noise = jnp.asarray([1e-3, 1e-3, 1e-2, 1e-2])
    xs = xs + noise[None, :] * jax.random.normal(jax.random.PRNGKey(seed + 7919), xs.shape, xs.dtype)
    return Trajectory(ts, xs, us, ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot", "dead_time.csv")


def test_exact_delay_shifts_the_held_input():
    run = dead_time_run(seed=1, duration=2.0)
    model = Extended(Acrobot(), (InputDelay(0, 0.03),))
    evaluated, us, us_before = exact_delays(model, run)
    assert float(evaluated.terms[0].coefficient) == 0.0  # the Pade filter passes the shifted input through
    raw = np.asarray(run.us)[:, 0]
    # At a whole number of samples the interval mean is the mean of the left and right limits.
    assert np.allclose(np.asarray(us)[10:, 0], 0.5 * (raw[7:-3] + raw[6:-4]))
    assert np.allclose(np.asarray(us_before), np.asarray(us))
    # A quarter sample later it moves a quarter of the way: continuous in the delay.
    _, us_later, _ = exact_delays(Extended(Acrobot(), (InputDelay(0, 0.0325),)), run)
    assert np.allclose(np.asarray(us_later)[10:, 0], 0.25 * raw[7:-3] + 0.75 * raw[6:-4])


def test_the_right_delay_leaves_white_residuals_where_the_pade_filter_would_not():
    run = dead_time_run(seed=2, duration=10.0)
    right = Extended(Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL), (InputDelay(0, 0.03),))
    r_exact, *_ = acceleration_residuals(right, run)
    r_none, *_ = acceleration_residuals(right.system, run)
    # With the dead time run exactly, what is left is the noise of the differentiated velocities.
    assert np.sqrt(np.mean(r_exact**2)) < 0.5 * np.sqrt(np.mean(r_none**2))


def test_pure_input_delay_is_named_and_explained():
    run = dead_time_run(seed=24)
    k = 2001
    train = Trajectory(run.ts[:k], run.xs[:k], run.us[:k], run.state_names, run.input_names, "acrobot", "train")
    validation = Trajectory(
        run.ts[k:], run.xs[k:], run.us[k:], run.state_names, run.input_names, "acrobot", "validation"
    )
    report = diagnose(Acrobot(), train, validation, mode=Refit())
    j = report.to_json()
    assert (j["findings"][0]["cause"], j["findings"][0]["where"]) == ("input_delay", "tau2"), j["findings"]
    assert j["findings"][0]["coefficient"] == pytest.approx(0.03, abs=0.006)
    assert j["gain"] > 0.5
    assert j["verdict"] == "explained", (j["structure"], j["notes"])
