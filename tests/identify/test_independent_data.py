"""Identification on data that dynax did not make: Drake's acrobot written out in physical parameters
(numpy) and integrated by scipy's DOP853 at rtol 1e-11, with measurement noise and with an effect the
fitted model lacks. The tests in `test_identify.py` fit data from the same model class and integrator;
these check that the estimate is right for reasons other than agreeing with itself.

Tolerances come from the noise, not from the observed errors:

- noise-free, the only error is the methods' numerical differentiation or quadrature of sampled data,
  $O((h\\omega)^2)$ with $h$ = 5 ms and the multisine's top frequency $\\omega$ = 5.1 rad/s: $7\\cdot 10^{-4}$;
- with noise, the estimate must lie within 4 of its own standard errors (a 4-sigma event has probability
  6e-5 per parameter), inflated where the method low-pass filters its equations: filtered residuals are
  correlated, and a band of $f_c$ Hz sampled at $f_s$ carries only $2 f_c / f_s$ of the samples'
  independent information, so the standard errors, which assume white residuals, are low by
  $\\sqrt{f_s / (2 f_c)}$ (Bartlett's effective sample size);
- and the standard errors themselves must be small (under 1 % for the inertial and gravity parameters),
  or the previous bound would say nothing.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import Dynamic, Energy, identify, Power, SimulationFit, Trajectory
from tests.reference import scipy_acrobot

TRUE = dynax.Acrobot()  # Drake's parameters, the same physical acrobot as tests.reference.DRAKE
THETA = np.array([float(v) for v in TRUE.base_parameters.values()])
FS = 200.0
TS = np.arange(0.0, 10.0, 1 / FS)
FREQS = np.array([0.7, 1.9, 3.3, 5.1])  # rad/s
US = sum(a * np.sin(f * TS + k) for k, (a, f) in enumerate(zip([2.0, 1.5, 1.0, 0.5], FREQS)))[:, None]
X0 = [0.2, 0.0, 0.0, 0.0]
# A 16-bit encoder (2 pi / 2^16 = 1e-4 rad), its velocity estimate and a torque sensor, 1-sigma.
NOISE = np.array([1e-4, 1e-4, 1e-3, 1e-3])
TORQUE_NOISE = 1e-3
DISCRETISATION = (FREQS.max() / FS) ** 2 + 1e-4  # (h omega)^2, plus the friction terms' weaker excitation


def _trajectory(xs, us):
    return Trajectory(jnp.asarray(TS), jnp.asarray(xs), jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",))


@pytest.fixture(scope="module")
def scipy_states():
    return scipy_acrobot(X0, TS, US)


@pytest.fixture(scope="module")
def noisy(scipy_states):
    rng = np.random.default_rng(11)
    return _trajectory(
        scipy_states + NOISE * rng.normal(size=scipy_states.shape), US + TORQUE_NOISE * rng.normal(size=US.shape)
    )


def _relative(result):
    return np.abs(np.asarray(result.estimate[:7]) - THETA) / THETA


@pytest.mark.parametrize("method", [Dynamic(), Power(), Energy()], ids=["dynamic", "power", "energy"])
def test_least_squares_on_scipy_data(scipy_states, method):
    result = identify(
        dynax.Acrobot(theta1=5.0),
        _trajectory(scipy_states, US),
        method,
        refine=False,
        validation=dynax.Validate(holdout=0),
    )
    relative = _relative(result)
    assert np.all(relative[:5] < DISCRETISATION), relative
    assert np.all(relative[5:] < 10 * DISCRETISATION), relative  # the friction columns are 10x less excited


@pytest.mark.parametrize(
    "method, filter_hz",
    [(Dynamic(), "auto"), (Power(lowpass_hz=4.0), 4.0), (Energy(), None)],
    ids=["dynamic", "power-filtered", "energy"],
)
def test_least_squares_error_is_within_its_standard_errors_under_noise(noisy, method, filter_hz):
    result = identify(TRUE, noisy, method, refine=False, validation=dynax.Validate(holdout=0))
    if filter_hz == "auto":  # Dynamic chooses its low-pass from the spectra and reports it
        filter_hz = result.settings[0]["lowpass_hz"]
    inflation = 1.0 if filter_hz is None else max(1.0, np.sqrt(FS / (2 * filter_hz)))
    error = np.abs(np.asarray(result.estimate) - THETA)
    std_errors = np.asarray(result.std_errors)
    assert np.all(std_errors[:5] < 0.01 * THETA[:5]), std_errors / THETA
    assert np.all(error < 4 * inflation * std_errors + DISCRETISATION * THETA), error / std_errors


@pytest.fixture(scope="module")
def coulomb_data():
    """The scipy acrobot with Coulomb friction of 0.05 N m at both joints (2.6 % of the rms torque)."""
    return _trajectory(scipy_acrobot(X0, TS, US, coulomb=(0.05, 0.05)), US)


@pytest.mark.parametrize("method", [Dynamic(), Power(), Energy()], ids=["dynamic", "power", "energy"])
def test_least_squares_with_an_effect_the_model_lacks(coulomb_data, method):
    # With the Coulomb columns the structure is right again: friction and base parameters recovered.
    right = identify(TRUE, coulomb_data, method, refine=False, validation=dynax.Validate(holdout=0), friction="coulomb")
    assert right.names[-2:] == ("fc1", "fc2")
    np.testing.assert_allclose([right.parameters["fc1"], right.parameters["fc2"]], 0.05, rtol=0.05)
    assert np.all(_relative(right)[:5] < DISCRETISATION)
    # Without them the viscous terms absorb what they can and the rest is equation error. The
    # inertial and gravity parameters, excited far more than friction, are biased by no more than the
    # share of the equations the model cannot explain (its relative equation error).
    wrong = identify(TRUE, coulomb_data, method, refine=False, validation=dynax.Validate(holdout=0))
    unexplained = float(wrong.relative_error)
    assert unexplained > 10 * float(right.relative_error)
    assert np.all(_relative(wrong)[:5] < unexplained), (_relative(wrong), unexplained)


@pytest.mark.slow  # about 30 s alone (80 s on a loaded machine), nearly all compiling Levenberg-Marquardt
def test_simulation_fit_on_noisy_scipy_data(scipy_states):
    """Output error on 1 s of states measured with 1e-3 rad and 1e-2 rad/s white noise: the maximum-
    likelihood fit for that noise, so its standard errors are honest and the 4-sigma bound applies."""
    rng = np.random.default_rng(12)
    noise = np.array([1e-3, 1e-3, 1e-2, 1e-2])
    data = _trajectory(scipy_states + noise * rng.normal(size=scipy_states.shape), US).slice(0, 201)
    start = dynax.Acrobot.from_base_parameters({k: 1.1 * float(v) for k, v in TRUE.base_parameters.items()})
    result = identify(
        start, data, SimulationFit(segment_s=0.25, max_steps=30), refine=False, validation=dynax.Validate(holdout=0)
    )
    error = np.abs(np.asarray(result.estimate) - THETA)
    std_errors = np.asarray(result.std_errors)
    assert np.all(std_errors[:5] < 0.02 * THETA[:5]), std_errors / THETA
    assert np.all(error < 4 * std_errors), error / std_errors
