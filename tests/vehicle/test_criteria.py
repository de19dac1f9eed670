"""The learning criteria: coefficient recovery (noise-free and noisy), EM-free prediction on a new flight, backprop
gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dynax import AccelerationModel, Backprop, fit_vehicle, FrequencyDomain, Helicopter, Lagged, LinearVelocityModel
from dynax.internal import (
    fit_backprop,
    fit_frequency,
    fit_lagged,
    fit_one_step,
    frequency_responses,
    HOVER_DERIVATIVES,
    lagged_loss,
    lagged_loss_gradient_norm,
    lagged_loss_of,
    normal_equations,
    recorded_loss,
    TEMPEST_COEFFICIENTS,
    TEMPEST_FEATURES,
    window_starts,
    with_theta,
)
from dynax.synthetic import generate_helicopter_flight

TEMPEST_NAMES = {
    "du/u": "Ax",
    "dv/v": "Ay",
    "dw/w": "Az",
    "dp/p": "Bx",
    "dq/q": "By",
    "dr/r": "Bz",
    "dp/u1": "C1",
    "dq/u2": "C2",
    "dr/u3": "C3",
    "dw/u4": "C4",
    "dv/1": "Dv",
}


@pytest.fixture(scope="module")
def tempest_data():
    """Hover flight of the Tempest acceleration model itself (noise-free, still air)."""
    return generate_helicopter_flight("hover", 20.0, seed=5, truth=Helicopter(), measurement_noise=False)


@pytest.fixture(scope="module")
def truth_data():
    """Hover flight of the higher-fidelity truth simulator (the acceleration model is not exact)."""
    return generate_helicopter_flight("hover", 20.0, seed=6)


def _zero_tempest():
    return Helicopter(AccelerationModel.with_features(TEMPEST_FEATURES))


def _check_tempest(system, rtol):
    for name, value in system.body_model.parameters.items():
        expected = TEMPEST_COEFFICIENTS[TEMPEST_NAMES[name]]
        assert float(value) == pytest.approx(expected, rel=rtol), name


def test_one_step_recovers_the_tempest_coefficients(tempest_data):
    # From all-zero weights; the data came from the model itself, so only the quadrature of the
    # one-step regression (trapezoidal over 10 ms, against the 4-substep RK4 of the generator) remains.
    fit = fit_one_step(_zero_tempest(), tempest_data)
    _check_tempest(fit.model, rtol=0.01)


@pytest.mark.slow
def test_lagged_keeps_the_true_coefficients(tempest_data):
    start = fit_one_step(_zero_tempest(), tempest_data).model
    fit = fit_lagged(start, tempest_data, Lagged(horizon=0.3, stride=5, max_iterations=2))
    _check_tempest(fit.model, rtol=0.01)
    assert recorded_loss(fit) < 1e-6


@pytest.fixture(scope="module")
def em_free_fit(truth_data):
    start = fit_one_step(_zero_tempest(), truth_data).model
    return start, fit_lagged(start, truth_data, Lagged(horizon=0.2, stride=10, max_iterations=3))


@pytest.fixture(scope="module")
def held_out_flight():
    """Another hover flight of the truth simulator (new excitation, gusts and noise)."""
    return generate_helicopter_flight("hover", 12.0, seed=8)


def test_em_free_fit_predicts_a_new_flight_better_than_one_step(truth_data, held_out_flight, em_free_fit):
    """The EM-free iteration accepts only steps that lower its training loss, so a lower training loss
    proves nothing; the 0.2 s prediction error on a flight it never saw is what it is for. And the loss
    it reports is the lagged loss of the model it returns, recomputed here."""
    start, fit = em_free_fit
    assert recorded_loss(fit) == pytest.approx(lagged_loss_of(fit.model, truth_data, 0.2, stride=10), rel=1e-10)
    before = lagged_loss_of(start, held_out_flight, 0.2, stride=10)
    after = lagged_loss_of(fit.model, held_out_flight, 0.2, stride=10)
    # the held-out loss averages about 100 overlapping 0.2 s windows; the training gain (19 %) is
    # several times the window-to-window scatter of such a mean, so most of it must carry over
    assert after < 0.9 * before, (before, after)


@pytest.fixture(scope="module")
def noisy_tempest_data():
    """The Tempest model flown by the generator (RK4, 4 substeps) with the recorder's measurement noise."""
    return generate_helicopter_flight("hover", 20.0, seed=5, truth=Helicopter())


def test_one_step_on_a_noisy_flight_is_within_the_noise(noisy_tempest_data):
    r"""Rate damping and control power from the noisy flight against the true Tempest values, with a
    tolerance from the known noise: 4 standard errors of the same on-axis regression written out in
    numpy ($\dot p \approx (p_{k+1} - p_k)/\Delta t$ on the interval's mean rate and held input), plus
    the 1 % the noise-free fit is held to (and which covers the errors-in-variables bias, 0.3 % here).
    The rate noise $n_k$ (0.01 rad/s, white) enters each equation as $e_k = a n_{k+1} - b n_k$ with
    $a, b = 1/\Delta t \mp B/2$, so the equation errors are correlated and the standard errors are
    the sandwich $(X^T X)^{-1} X^T \Sigma X (X^T X)^{-1}$ with that tridiagonal $\Sigma$."""
    fit = fit_one_step(_zero_tempest(), noisy_tempest_data)
    fitted = fit.model.body_model.parameters
    xs, us, dt, sigma = np.asarray(noisy_tempest_data.xs), np.asarray(noisy_tempest_data.us), 0.01, 0.01
    for column, channel, names in ((10, 0, ("dp/p", "dp/u1")), (11, 1, ("dq/q", "dq/u2")), (12, 2, ("dr/r", "dr/u3"))):
        x = np.stack([(xs[1:, column] + xs[:-1, column]) / 2, us[:-1, channel]], axis=1)
        damping = TEMPEST_COEFFICIENTS[TEMPEST_NAMES[names[0]]]
        a, b = 1 / dt - damping / 2, 1 / dt + damping / 2
        sigma_x = sigma**2 * ((a * a + b * b) * x - a * b * (np.r_[x[1:], 0 * x[:1]] + np.r_[0 * x[:1], x[:-1]]))
        inverse = np.linalg.inv(x.T @ x)
        std_errors = np.sqrt(np.diag(inverse @ (x.T @ sigma_x) @ inverse))
        for name, std_error in zip(names, std_errors):
            true = TEMPEST_COEFFICIENTS[TEMPEST_NAMES[name]]
            assert abs(float(fitted[name]) - true) < 4 * std_error + 0.01 * abs(true), (
                name,
                float(fitted[name]),
                true,
                std_error,
            )


@pytest.mark.slow  # about 30 s
def test_state_sensitivities_reach_a_stationary_point_of_the_lagged_loss(truth_data, em_free_fit):
    # Gauss-Newton on the true loss (the EM-free least squares with the rollout's full Jacobian):
    # at its result the true loss's gradient, J^T W r, vanishes, and the loss is no higher than
    # the paper's EM-free iteration, which holds the predicted states fixed.
    start, em_free = em_free_fit
    criterion = Lagged(horizon=0.2, stride=10, max_iterations=6, state_sensitivities=True)
    fit = fit_lagged(start, truth_data, criterion)
    assert recorded_loss(fit) <= recorded_loss(em_free)
    starts = window_starts(truth_data, 20, 10)

    def stationarity(system):  # |J^T W r| through the Gauss-Newton normal equations
        ata, atb, _ = normal_equations(system, truth_data, starts, 20, jnp.ones(6), True, 128, True)
        return float(jnp.linalg.norm(ata @ system.body_model.parameter_vector() - atb))

    assert stationarity(fit.model) < 1e-3 * stationarity(start)
    # The same by reverse-mode autodiff of the loss itself, independent of the normal equations.
    gradient_norm = lambda system: lagged_loss_gradient_norm(system, truth_data, 0.2, stride=10)  # noqa: E731
    assert gradient_norm(fit.model) < 1e-3 * gradient_norm(start)


def test_backprop_gradient_matches_finite_differences(truth_data):
    system = fit_one_step(_zero_tempest(), truth_data).model
    starts = jnp.arange(0, 500, 100)
    theta = system.body_model.parameter_vector()

    def loss(th, segment):
        return lagged_loss(with_theta(system, th), truth_data, 8, starts=starts, checkpoint_segment=segment)

    # Checkpointed (3 segments of 3 steps, the last padded) gradient against central differences,
    # all through one compiled value-and-gradient.
    value_and_grad = jax.jit(jax.value_and_grad(lambda th: loss(th, None)))
    _, grad = value_and_grad(theta)
    for i in (0, 5, 8):  # du/u, dp/p, dq/u2
        h = 1e-5 * max(1.0, abs(float(theta[i])))
        e = jnp.zeros_like(theta).at[i].set(h)
        fd = (value_and_grad(theta + e)[0] - value_and_grad(theta - e)[0]) / (2 * h)
        assert float(grad[i]) == pytest.approx(float(fd), rel=1e-5, abs=1e-10)


@pytest.mark.slow
def test_backprop_reaches_the_lagged_loss(truth_data):
    start = fit_one_step(_zero_tempest(), truth_data).model
    lagged = fit_lagged(start, truth_data, Lagged(horizon=0.3, stride=10, max_iterations=6))
    direct = fit_backprop(start, truth_data, Backprop(horizon=0.3, stride=10, max_steps=40))
    newton = fit_lagged(start, truth_data, Lagged(horizon=0.3, stride=10, max_iterations=6, state_sensitivities=True))
    assert recorded_loss(direct) < lagged.history[0][1]
    # Backprop and Gauss-Newton on the true loss find the same minimum (0.100083 here).
    assert recorded_loss(newton) == pytest.approx(recorded_loss(direct), rel=1e-4)
    # At this small scale (Tempest features, H = 0.3 s) the EM-free fixed point is 0.4 % above it; with
    # the rich features and H = 1 s of the experiment the gap is 7 % (hover) to 12 % (aerobatic).
    assert recorded_loss(lagged) <= 1.05 * min(recorded_loss(direct), recorded_loss(newton))


def test_measured_frequency_response_matches_the_model(tempest_data):
    """Welch multi-input estimate of the roll-rate response to u1 against C1 / (j w - Bx) e^{-j w dt/2}."""
    c = TEMPEST_COEFFICIENTS
    freqs, responses, coherence = frequency_responses(tempest_data, segment_s=2.5)
    for f in (0.8, 2.0):
        k = int(np.argmin(np.abs(freqs - f)))
        w = 2 * np.pi * freqs[k]
        expected = c["C1"] / (1j * w - c["Bx"]) * np.exp(-1j * w * 0.005)
        assert coherence[k, 3, 0] > 0.9
        assert abs(responses[k, 3, 0] - expected) < 0.1 * abs(expected)


@pytest.mark.slow
def test_frequency_domain_recovers_the_rate_dynamics():
    linear = Helicopter(LinearVelocityModel())
    data = generate_helicopter_flight("hover", 40.0, seed=7, truth=linear)
    # Equation-error fit only (max_steps=0) keeps the default suite fast; the on-axis rate and
    # collective dynamics are what closed-loop frequency responses identify well (the off-axis
    # terms are weakly determined, as in CIFER practice).
    fit = fit_frequency(linear, data, FrequencyDomain(segment_s=5.0, max_steps=0))
    p = fit.model.body_model.parameters
    true = linear.body_model.parameters
    for name in ("dp/p", "dp/u1", "dq/q", "dq/u2", "dr/r", "dr/u3", "dw/u4"):
        assert float(p[name]) == pytest.approx(float(true[name]), rel=0.15), name


def test_frequency_domain_refuses_the_acceleration_model(truth_data):
    with pytest.raises(ValueError, match="linear model only"):
        fit_vehicle(Helicopter(), truth_data, FrequencyDomain())


@pytest.mark.slow  # about 70 s
def test_frequency_structure_reduction_drops_what_the_responses_do_not_determine():
    """CIFER's elimination (insensitivity > 10 %, Cramer-Rao > 20 %) on data from the linear model itself:
    two derivatives the model does not have are dropped, the on-axis ones are kept and recovered."""
    linear = Helicopter(LinearVelocityModel())
    data = generate_helicopter_flight("hover", 40.0, seed=7, truth=linear)
    structure = dict(HOVER_DERIVATIVES)
    structure["p"] += ("w",)
    structure["q"] += ("w",)
    fit = fit_frequency(linear, data, FrequencyDomain(structure=structure, eliminate=True))
    assert "dp/w" in fit.statistics.eliminated and "dq/w" in fit.statistics.eliminated
    kept = {
        name: (value, cramer_rao, insensitivity) for name, value, cramer_rao, insensitivity in fit.statistics.accuracy
    }
    assert not set(kept) & set(fit.statistics.eliminated)
    true = linear.body_model.parameters
    for name in ("dp/p", "dp/u1", "dq/q", "dq/u2", "dr/r", "dr/u3", "dw/u4", "du/pitch", "dv/roll"):
        value, cramer_rao, insensitivity = kept[name]
        assert value == pytest.approx(float(true[name]), rel=0.15), name
        assert cramer_rao <= 20.0 and insensitivity <= 10.0, name
    # Eliminated weights are zero in the fitted model.
    fitted = fit.model.body_model.parameters
    assert all(float(fitted[name]) == 0.0 for name in fit.statistics.eliminated)


def test_frequency_elimination_thresholds_must_be_positive(truth_data):
    with pytest.raises(ValueError, match="max_cramer_rao and max_insensitivity must be positive"):
        fit_frequency(Helicopter(LinearVelocityModel()), truth_data, FrequencyDomain(max_cramer_rao=0.0))
