"""Fit %, residual tests, AIC/FPE and cross-validation, on models of known structure fitted to noisy data."""

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

import dynax
import dynax.internal


def _arx_data(n=3000, seed=0):
    """y_t = 1.5 y_{t-1} - 0.7 y_{t-2} + u_{t-1} + 0.5 u_{t-2} + e_t, u white: a second-order system."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=n)
    e = 0.1 * rng.normal(size=n)
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + u[t - 1] + 0.5 * u[t - 2] + e[t]
    return u, y


def _arx_residuals(u, y, na, nb, start=None):
    """One-step prediction errors of a least-squares ARX(na, nb) fit (numpy, independent of dynax)."""
    k = start or max(na, nb)
    rows = [np.concatenate([y[t - na : t][::-1], u[t - nb : t][::-1]]) for t in range(k, len(y))]
    phi, target = np.array(rows), y[k:]
    theta = np.linalg.lstsq(phi, target, rcond=None)[0]
    return target - phi @ theta, u[k:], na + nb


def test_nrmse_fit_is_matlabs_compare_percentage():
    ts = np.linspace(0, 10, 2001)
    y = np.sin(ts)[:, None] * np.array([1.0, 2.0])
    assert np.allclose(dynax.nrmse_fit(y, y), 100.0)
    assert np.allclose(dynax.nrmse_fit(y, np.broadcast_to(y.mean(axis=0), y.shape)), 0.0)
    noise = 0.1 * np.random.default_rng(0).normal(size=y.shape)
    fit = dynax.nrmse_fit(y, y + noise)
    # ||noise|| / ||y - mean|| ~ 0.1 / rms(y): rms of a sine is amplitude / sqrt(2)
    expected = 100 * (1 - 0.1 / (np.array([1.0, 2.0]) / np.sqrt(2)))
    np.testing.assert_allclose(fit, expected, atol=1.0)
    with pytest.raises(ValueError, match="differ in shape"):
        dynax.nrmse_fit(y, y[:-1])
    with pytest.raises(ValueError, match="constant"):
        dynax.nrmse_fit(np.ones(10), np.zeros(10))
    with pytest.raises(ValueError, match="non-finite value at row 3"):
        dynax.nrmse_fit(y[:, 0], np.where(np.arange(len(ts)) == 3, np.nan, y[:, 0]))


def test_whiteness_test_tells_the_right_order_from_an_underfit_one():
    u, y = _arx_data()
    right, _, _ = _arx_residuals(u, y, 2, 2)
    wrong, _, _ = _arx_residuals(u, y, 1, 1)
    assert dynax.whiteness_test(right).white.all()
    test = dynax.whiteness_test(wrong)
    assert not test.white.any()
    assert np.any(np.abs(test.autocorrelation) > test.bound)
    assert test.bound == pytest.approx(scipy.stats.norm.ppf(0.995) / np.sqrt(len(wrong)))


def test_false_alarm_rates_match_the_confidence():
    # white residuals, independent of a coloured input: 5 % rejections expected at 95 % confidence;
    # a binomial(400, 0.05) stays within 2..8.5 % with probability > 0.99
    rng = np.random.default_rng(1)
    white, independent = [], []
    for _ in range(400):
        e = rng.normal(size=500)
        u = np.convolve(rng.normal(size=520), np.ones(20) / 20, mode="valid")[:500]  # low-pass input
        white.append(dynax.whiteness_test(e, max_lag=10, confidence=0.95).white[0])
        independent.append(dynax.cross_correlation_test(e, u, max_lag=10, confidence=0.95).independent[0, 0])
    assert 0.02 <= 1 - np.mean(white) <= 0.085
    assert 0.02 <= 1 - np.mean(independent) <= 0.085


def test_cross_correlation_finds_a_missing_input_term_at_its_lag():
    u, y = _arx_data()
    right, u_right, _ = _arx_residuals(u, y, 2, 2)
    missing, u_missing, _ = _arx_residuals(u, y, 2, 1)  # leaves out the u_{t-2} term
    assert dynax.cross_correlation_test(right, u_right).independent.all()
    test = dynax.cross_correlation_test(missing, u_missing)
    assert not test.independent.all() and test.p_value[0, 0] < 1e-6
    assert np.any(np.abs(test.cross_correlation) > test.bound[..., None])
    peak = test.lags[np.argmax(np.abs(test.cross_correlation[0, 0]))]
    assert peak == 2  # the input two samples back still acts
    with pytest.raises(ValueError, match="`inputs` has 10 samples"):
        dynax.cross_correlation_test(right, u_right[:10])


def test_aic_is_the_gaussian_likelihood_penalty_and_picks_the_true_order():
    u, y = _arx_data(seed=2)
    e, _, d = _arx_residuals(u, y, 2, 2)
    # AIC = -2 log L + 2 d at the Gaussian MLE of the variance (independent: scipy's log density)
    loglik = scipy.stats.norm.logpdf(e, scale=np.sqrt(np.mean(e**2))).sum()
    assert dynax.aic(e, d) == pytest.approx(-2 * loglik + 2 * d, rel=1e-10)
    v = np.mean(e**2)
    assert dynax.fpe(e, d) == pytest.approx(v * (1 + d / len(e)) / (1 - d / len(e)), rel=1e-12)
    # ARX orders 1..4 on the same samples: both criteria are smallest at (or, with a negligible
    # margin, just above) the true order 2, and a clear loss for under-fitting.
    scores = {}
    for order in (1, 2, 3, 4):
        res, _, d = _arx_residuals(u, y, order, order, start=4)  # the same samples for every order
        scores[order] = (dynax.aic(res, d), dynax.fpe(res, d))
    assert min(scores, key=lambda k: scores[k][0]) in (2, 3)
    assert scores[1][0] > scores[2][0] + 100
    assert scores[1][1] > scores[2][1]


def test_kfold_and_leave_one_out_cross_validation_with_identify():
    # A linear axis identified on folds of one record, scored by fit % on the held-out block.
    axis = dynax.LinearAxis(mass=2.0, viscous=3.0, coulomb=0.0, offset=0.0)
    ts = np.arange(0, 6.0, 0.002)
    force = 5 * np.sin(2 * ts) + 3 * np.sin(7.3 * ts)
    sim = dynax.simulate(axis, jnp.zeros(2), ts, force[:, None])
    run = dynax.Trajectory(jnp.asarray(ts), sim.xs, jnp.asarray(force[:, None]), ("q", "dq"), ("force",), "linear_axis")
    folds = dynax.kfold_splits(run, 3)
    assert [len(v) for _, v in folds] == [1000, 1000, 1000]
    assert sum(len(t) for t in folds[1][0]) == 2000 and len(folds[0][0]) == 1

    def fit(train):
        return dynax.identify(axis, train, dynax.Dynamic()).system

    def score(model, validation):
        return float(
            dynax.nrmse_fit(
                validation.xs[:, 1], dynax.simulate(model, validation.x0, validation.ts, validation.us).xs[:, 1]
            )[0]
        )

    scores = dynax.cross_validate(fit, score, folds)
    assert scores.shape == (3,) and np.all(scores > 95)
    parts = [run.slice(0, 1500), run.slice(1500, None)]
    loo = dynax.cross_validate(fit, score, dynax.leave_one_out_splits(parts))
    assert loo.shape == (2,) and np.all(loo > 95)
    with pytest.raises(dynax.UsageError, match="need 2 <= k"):
        dynax.kfold_splits(run, 1)
    with pytest.raises(dynax.UsageError, match="at least 2 experiments"):
        dynax.leave_one_out_splits(parts[:1])


def test_horizon_fit_is_compare_with_a_k_step_prediction():
    # independent check: each window simulated on its own with dynax.simulate
    ts = np.arange(0, 3.0, 0.01)
    us = (0.5 * np.sin(2 * ts) + 0.3 * np.sin(5.1 * ts))[:, None]
    truth = dynax.Acrobot()
    xs = dynax.simulate(truth, jnp.array([0.4, -0.2, 0.0, 0.0]), ts, us).xs
    run = dynax.Trajectory(jnp.asarray(ts), xs, jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot")
    assert all(v > 99.9 for v in dynax.internal.horizon_fit(truth, run, 0.2, max_windows=8).values())
    wrong = dynax.Acrobot(theta4=truth.theta4 * 1.2)
    fits = dynax.internal.horizon_fit(wrong, run, 0.2, states=["q1"], max_windows=8)
    error = dynax.simulation_error(wrong, run, (0.2,), max_windows=8)
    measured, predicted = [], []
    for k in np.asarray(error.starts):
        window = dynax.simulate(wrong, xs[k], ts[k : k + 21], us[k : k + 21])
        measured.append(float(xs[k + 20, 0]))
        predicted.append(float(window.xs[-1, 0]))
    expected = float(dynax.nrmse_fit(np.array(measured), np.array(predicted))[0])
    assert fits["q1"] == pytest.approx(expected, abs=1e-6) and expected < 99
    with pytest.raises(ValueError, match="not states"):
        dynax.internal.horizon_fit(wrong, run, 0.2, states=["x"])
