"""The predictability horizon and the cross-validated residual probe, on data made without them."""

import jax
import numpy as np
import pytest

import dynax
from dynax.internal import (
    cross_validated_ridge,
    folds_by_run,
    horizon_errors,
    position_spread,
    predictability_horizon,
    relative_position_error,
    window_simulation_errors,
)


def test_horizon_is_the_last_before_the_error_first_exceeds_the_fraction():
    dt = 0.01
    steps = np.arange(201) * dt
    # An error that grows exponentially (a chaotic pendulum): 1 % of the spread at 0, doubling every 0.2 s.
    relative = 0.01 * 2 ** (steps / 0.2)
    h = predictability_horizon(relative, dt, np.arange(0.1, 2.0001, 0.05), fraction=0.25)
    # 0.01 * 2^(t / 0.2) = 0.25 at t = 0.2 log2(25) = 0.929 s: the last candidate below is 0.9 s.
    assert h.seconds == pytest.approx(0.9)
    assert "training runs" in h.rule and h.fraction == 0.25
    assert h.to_json()["seconds"] == pytest.approx(0.9)


def test_horizon_ignores_a_dip_after_the_error_has_grown():
    dt = 0.05
    relative = np.array([0.0, 0.1, 0.2, 0.3, 0.2, 0.1, 0.1])  # grows past 25 %, then dips (a periodic motion)
    h = predictability_horizon(relative, dt, [0.05, 0.1, 0.15, 0.2, 0.25, 0.3], fraction=0.25)
    assert h.seconds == pytest.approx(0.1)


def test_horizon_falls_back_to_the_shortest_candidate_and_says_so():
    h = predictability_horizon(np.full(50, 0.9), 0.01, [0.1, 0.2], fraction=0.25)
    assert h.seconds == pytest.approx(0.1) and "already" in h.rule
    with pytest.raises(ValueError, match="fraction"):
        predictability_horizon(np.zeros(5), 0.01, [0.01], fraction=1.5)


def test_relative_position_error_is_rmse_over_spread():
    rng = np.random.default_rng(0)
    errors = rng.normal(size=(400, 3, 2)) * np.array([2.0, 0.5])  # positions 0 (spread 4) and state 1 (not a position)
    rel = relative_position_error(errors, [0], np.array([4.0]))
    assert rel == pytest.approx(np.full(3, 0.5), rel=0.1)
    errors[0, 1, 0] = np.nan  # one window of 400 diverged: still counted on the finite ones
    assert np.isfinite(relative_position_error(errors, [0], np.array([4.0]))).all()


def test_probe_ridge_is_strong_when_structure_does_not_transfer_across_runs():
    rng = np.random.default_rng(1)
    sizes = [300, 300, 300]
    x = rng.normal(size=(900, 1))
    # Residuals depend on the feature with a slope that changes sign from run to run: nothing transfers.
    slope = np.repeat([2.0, -2.0, 2.0], 300)[:, None]
    Phi = np.concatenate([x, np.ones((900, 1))], axis=1)
    R = slope * x + 0.1 * rng.normal(size=(900, 1))
    strength, scores = cross_validated_ridge(Phi, R, sizes)
    assert strength >= 1.0  # shrunk towards zero: the held-out R^2 does not go far below zero
    # A slope that is the same in every run transfers: a weak ridge wins and the CV R^2 is high.
    R = 2.0 * x + 0.1 * rng.normal(size=(900, 1))
    strength, scores = cross_validated_ridge(Phi, R, sizes)
    assert strength <= 1e-2 and scores[strength] > 0.9


def test_folds_by_run():
    assert [f.tolist() for f in folds_by_run([2, 3])] == [[0, 1], [2, 3, 4]]
    assert len(folds_by_run([9])) == 3


def test_an_angle_that_turns_over_has_a_bounded_spread():
    rng = np.random.default_rng(0)
    still = rng.normal(0.3, 0.4, 2000)
    winding = still + np.linspace(0.0, 40.0, 2000)  # six turns
    metres = 3.0 * still + np.linspace(0.0, 40.0, 2000)
    spread = position_spread(np.stack([still, winding, metres], axis=1), [True, True, False])
    assert spread[0] == pytest.approx(np.std(still))  # within half a turn of its mean: the standard deviation
    assert np.std(winding) > 10 and spread[1] <= np.pi / np.sqrt(3) + 1e-9  # a uniform angle's, at most
    assert spread[2] == pytest.approx(np.std(metres))  # a linear position: as it is
    # An extended model answers for its system's angles.
    extended = dynax.Extended(dynax.DoublePendulum(), (dynax.RotorInertia(1, 0.001),))
    assert extended.angle_indices == (0, 1) and dynax.Extended(dynax.LinearAxis(), ()).angle_indices == ()


def test_horizon_errors_are_window_simulation_errors():
    """The fit window's and the reference horizon's rollouts through one padded program: the windows and numbers of
    `window_simulation_errors`, bit for bit, for a model with weakly typed parameters (made from Python floats) and
    for a strongly typed one (as a fit leaves it)."""
    record = dynax.synthetic.synthetic_trajectory(
        dynax.Acrobot(), duration=3.0, dt=0.01, excitation=dynax.synthetic.Multisine(amplitude=2.0), seed=3
    )
    strong = jax.tree.map(lambda a: jax.device_put(np.asarray(a)) if isinstance(a, jax.Array) else a, dynax.Acrobot())
    for model in (dynax.Acrobot(), strong):
        for longest in (1.0, 0.55):
            candidates = np.round(np.arange(0.1, longest + 1e-9, 0.05), 6)
            expected = np.asarray(window_simulation_errors(model, record, candidates, stride=5))
            np.testing.assert_array_equal(horizon_errors(model, record, candidates, 5, 0.01), expected)
