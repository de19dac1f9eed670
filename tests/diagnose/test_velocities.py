"""Velocities from the encoder positions where the measured ones are noisy (`Selection(velocities="auto")`).

The truth is simulated without noise and the same run recorded with noise, so the estimate is scored
against the true velocities, not against what the rule itself computes."""

import jax.numpy as jnp
import numpy as np

from dynax import Acrobot, CoulombFriction, Extended
from dynax.internal import with_velocities_from_positions
from dynax.synthetic import Multisine, synthetic_trajectory

TRUTH = Extended(Acrobot(), (CoulombFriction(1, 0.2),))


def _run(noise):
    return synthetic_trajectory(
        TRUTH, duration=20.0, dt=0.005, seed=3, excitation=Multisine(amplitude=2.0), noise=noise
    )


def _rms(a):
    return float(jnp.sqrt(jnp.mean(a**2)))


def test_a_driver_grade_velocity_is_replaced_by_a_better_one_from_the_positions():
    clean = _run((0.0, 0.0, 0.0, 0.0))
    noisy = _run((1e-4, 1e-4, 0.15, 0.15))  # encoder-grade positions, the DFKI driver's velocity noise
    out, choice, replaced = with_velocities_from_positions(noisy)
    assert replaced == ("dq1", "dq2") and choice.cutoff_hz is not None
    measured = _rms(noisy.xs[:, 2:] - clean.xs[:, 2:])
    fitted = _rms(out.xs[:, 2:] - clean.xs[:, 2:])
    assert 0.1 < measured < 0.2
    assert fitted < 0.4 * measured, (fitted, measured)
    np.testing.assert_array_equal(out.xs[:, :2], noisy.xs[:, :2])  # positions untouched


def test_nearly_clean_velocities_are_kept_as_measured():
    # With 0.01 rad/s of noise the fit's bias (Coulomb friction's kinks, the torque steps) exceeds the noise it would
    # remove.
    slightly = _run((1e-3, 1e-3, 1e-2, 1e-2))
    out, _, replaced = with_velocities_from_positions(slightly)
    assert replaced == ()
    assert out is slightly
