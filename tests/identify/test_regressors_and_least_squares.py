"""The regressors are the models they claim to be, and least squares says what the data leave undetermined."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import CoulombFriction, Extended, IdentifiabilityError, RotorInertia
from dynax.internal import (
    dynamic_regressor,
    energy_regressor,
    friction_power_regressor,
    least_squares,
    parameter_names,
    parameter_vector,
    with_friction,
)


@pytest.fixture(scope="module")
def states():
    rng = np.random.default_rng(0)
    xs = jnp.asarray(rng.uniform(-2, 2, size=(50, 4)))
    ddq = jnp.asarray(rng.uniform(-5, 5, size=(50, 2)))
    return xs, ddq


def test_dynamic_regressor_times_parameters_is_the_inverse_dynamics(states):
    xs, ddq = states
    system = dynax.DoublePendulum.from_physical(
        m1=0.6, m2=0.4, l1=0.3, lc1=0.2, lc2=0.25, Ic1=0.01, Ic2=0.02, b1=0.05, b2=0.02
    )
    theta = parameter_vector(system)
    ys = dynamic_regressor(dynax.DoublePendulum(), xs, ddq)  # parameter values of the model are irrelevant
    tau = jax.vmap(lambda x, a: system.mass_matrix(x[:2]) @ a + system.bias_force(x[:2], x[2:]))(xs, ddq)
    assert ys.shape == (50, 2, 7)
    np.testing.assert_allclose(ys @ theta, tau, rtol=1e-12, atol=1e-12)
    # and the forward dynamics agree: the acceleration the vector field gives reproduces tau = 0 rows.
    accel = jax.vmap(lambda x: system.vector_field(0.0, x, jnp.zeros(2))[2:])(xs)
    np.testing.assert_allclose(dynamic_regressor(system, xs, accel) @ theta, 0.0, atol=1e-10)


def test_extended_terms_enter_the_regressor_with_their_names(states):
    xs, ddq = states
    system = Extended(dynax.DoublePendulum(), (RotorInertia(1, 0.05), CoulombFriction(0, 0.2)))
    names = parameter_names(system, "coulomb")
    assert names == ("theta1", "theta2", "theta3", "theta4", "theta5", "theta6", "theta7", "Ir2", "fc1", "fc2")
    full = with_friction(system, "coulomb")
    theta = parameter_vector(full, "coulomb")
    ys = dynamic_regressor(full, xs, ddq, "coulomb")
    # M ddq + h - extension forces = B u, with the vector field's own accelerations
    us = jnp.asarray(np.random.default_rng(1).normal(size=(50, 2)))
    accel = jax.vmap(lambda x, u: full.vector_field(0.0, x, u)[2:])(xs, us)
    np.testing.assert_allclose(dynamic_regressor(full, xs, accel, "coulomb") @ theta, us, rtol=1e-9, atol=1e-9)
    assert ys.shape == (50, 2, 10)


def test_energy_regressor_is_the_energy_and_friction_power_is_the_dissipation(states):
    xs, _ = states
    system = dynax.Acrobot.from_physical(m1=1.3, lc2=0.8, b1=0.2, b2=0.05)
    theta = parameter_vector(system)
    w = energy_regressor(system, xs)
    np.testing.assert_allclose(w @ theta, jax.vmap(system.energy)(xs), rtol=1e-12)
    assert np.all(w[:, 5:] == 0)  # friction stores no energy
    f = friction_power_regressor(system, xs)
    np.testing.assert_allclose(f @ theta, 0.2 * xs[:, 2] ** 2 + 0.05 * xs[:, 3] ** 2, rtol=1e-12)


def test_least_squares_matches_numpy_and_textbook_standard_errors():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(200, 3)) * np.array([1.0, 100.0, 0.01])
    theta = np.array([1.0, -2.0, 3.0])
    y = a @ theta + 0.1 * rng.normal(size=200)
    fit = least_squares(a, y, names=("a", "b", "c"))
    ref, res, *_ = np.linalg.lstsq(a, y, rcond=None)
    np.testing.assert_allclose(fit.value, ref, rtol=1e-10)
    sigma2 = res[0] / (200 - 3)
    np.testing.assert_allclose(fit.std_errors, np.sqrt(np.diag(sigma2 * np.linalg.inv(a.T @ a))), rtol=1e-8)
    assert (
        int(fit.statistics.rank) == 3 and float(fit.statistics.condition_number) < 2
    )  # column scaling removes the units


def test_rank_deficiency_names_the_unidentified_combination():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(100, 2))
    a = np.column_stack([x[:, 0], x[:, 1], x[:, 0] + 2 * x[:, 1], x[:, 0] * 0])
    with pytest.raises(IdentifiabilityError) as info:
        least_squares(a, x[:, 0], names=("m", "b", "c", "d"))
    assert info.value.rank == 2
    assert info.value.unidentified == ("m + 2 b - c", "d")
    assert "d" in str(info.value) and "rank 2 of 4" in str(info.value)


def test_float32_least_squares_is_as_accurate_as_numpy_lstsq():
    # Two columns that differ by 1e-3 of their scale: the normal equations square the condition
    # number (1e3 -> 1e6, at float32's resolution) and lose the difference; factoring A keeps it.
    rng = np.random.default_rng(0)
    m = 2000
    base = rng.normal(size=m)
    a = np.stack([base, base + 1e-3 * rng.normal(size=m), rng.normal(size=m)], axis=1)
    theta = np.array([1.0, -2.0, 0.5])
    y = a @ theta + 1e-6 * rng.normal(size=m)
    a32, y32 = a.astype(np.float32), y.astype(np.float32)
    reference = np.linalg.lstsq(a32, y32, rcond=None)[0]
    fit = least_squares(jnp.asarray(a32), jnp.asarray(y32))
    assert fit.value.dtype == jnp.float32
    error_numpy = np.max(np.abs(reference - theta))
    error_dynax = np.max(np.abs(np.asarray(fit.value, dtype=float) - theta))
    # numpy's float32 lstsq gets the two nearly collinear coefficients to about 1e-3 here; dynax must
    # do as well (within a factor 3), where the normal equations would be off by order one
    assert error_dynax < 3 * max(error_numpy, 1e-4), (error_dynax, error_numpy)
    gram = np.linalg.solve((a32.T @ a32).astype(np.float32), (a32.T @ y32).astype(np.float32))
    assert np.max(np.abs(gram - theta)) > 10 * error_dynax  # the test can tell the two apart


@pytest.mark.parametrize("rows", [5, 700, 70_000])
def test_tall_skinny_qr_is_householder_qr_up_to_row_signs(rows):
    # 5 rows: one plain QR; 700: one level of blocks and a remainder; 70,000: two levels.
    from dynax.internal import tsqr_r

    rng = np.random.default_rng(4)
    a = rng.normal(size=(rows, 6)) * np.array([1.0, 1e3, 1e-3, 1.0, 1.0, 1.0])
    r = np.asarray(tsqr_r(jnp.asarray(a)))
    reference = np.linalg.qr(a, mode="r")
    assert r.shape == reference.shape
    np.testing.assert_allclose(np.abs(r), np.abs(reference), rtol=1e-9, atol=1e-9 * np.abs(reference).max())
    np.testing.assert_allclose(r.T @ r, a.T @ a, rtol=1e-9, atol=1e-9 * np.abs(a.T @ a).max())


def test_least_squares_on_many_rows_matches_scipy_lstsq():
    import scipy.linalg

    rng = np.random.default_rng(5)
    a = rng.normal(size=(50_001, 7)) * np.logspace(-2, 2, 7)
    y = a @ np.arange(1.0, 8.0) + rng.normal(size=50_001)
    fit = least_squares(a, y)
    np.testing.assert_allclose(fit.value, scipy.linalg.lstsq(a, y)[0], rtol=1e-10)
    residual = a @ np.asarray(fit.value) - y
    np.testing.assert_allclose(float(fit.statistics.residual_rms), np.sqrt(np.mean(residual**2)), rtol=1e-10)


def test_weighted_rank_deficient_residual_is_that_of_the_returned_estimate():
    """The residual norm comes from the QR factor (rho and the directions dropped from the rank), not
    from another pass over the rows: against the residual of the returned estimate itself, and the
    minimum-norm estimate against numpy's pseudo-inverse in the same column scaling."""
    rng = np.random.default_rng(11)
    a = rng.normal(size=(3_001, 5)) * np.array([1.0, 10.0, 0.1, 1.0, 1.0])
    a[:, 4] = 2.0 * a[:, 0] - a[:, 3]  # a null direction: rank 4 of 5
    y = a @ np.array([1.0, 0.2, -3.0, 0.5, 0.0]) + 0.1 * rng.normal(size=3_001)
    w = rng.uniform(0.5, 2.0, size=3_001)
    fit = least_squares(a, y, weights=w, allow_rank_deficient=True)
    assert int(fit.statistics.rank) == 4
    residual = np.sqrt(w) * (a @ np.asarray(fit.value) - y)
    np.testing.assert_allclose(float(fit.statistics.residual_rms), np.sqrt(np.mean(residual**2)), rtol=1e-9)
    aw = np.sqrt(w)[:, None] * a
    d = np.linalg.norm(aw, axis=0)
    reference = np.linalg.pinv(aw / d, rcond=1e-7) @ (np.sqrt(w) * y) / d
    np.testing.assert_allclose(fit.value, reference, rtol=1e-8, atol=1e-10)


def test_rank_deficient_fit_gives_an_infinite_error_only_to_parameters_the_null_space_touches():
    # Column 4 repeats column 1: theta1 and theta4 are known only as their sum, theta2 and theta3 as
    # well as without the repeat. Their errors must be those of the fit that drops the repeat (not
    # infinite for all, not zero where the pseudo-inverse would put it), the tied pair's infinite.
    rng = np.random.default_rng(3)
    a = rng.normal(size=(500, 3)) * np.array([1.0, 5.0, 0.2])
    y = a @ np.array([1.0, -0.4, 2.0]) + 0.05 * rng.normal(size=500)
    tied = least_squares(np.column_stack([a, a[:, 0]]), y, allow_rank_deficient=True)
    alone = least_squares(a, y)
    assert int(tied.statistics.rank) == 3 and tied.unidentified == ("p0 - p3",)
    std = np.asarray(tied.std_errors)
    assert np.isinf(std[0]) and np.isinf(std[3])
    np.testing.assert_allclose(std[1:3], np.asarray(alone.std_errors)[1:3], rtol=1e-8)
    # nothing moves at all: no parameter has an error
    assert np.all(
        np.isinf(np.asarray(least_squares(np.zeros((50, 2)), np.ones(50), allow_rank_deficient=True).std_errors))
    )


def test_jointly_determined_names_the_parameters_a_regression_separates_only_through_a_small_difference():
    # Four regressors, the third almost the sum of the first two: the textbook variance inflation factor
    # 1 / (1 - R^2), from regressing each column on the others, is what the covariance's correlations give,
    # and the three entangled columns are named with each other, the independent fourth is not.
    from dynax.internal import jointly_determined

    rng = np.random.default_rng(3)
    a, b, d = rng.normal(size=(3, 500))
    x = np.stack([a, b, a + b + 0.02 * rng.normal(size=500), d], axis=1)
    covariance = 0.1**2 * np.linalg.inv(x.T @ x)
    names = ("p1", "p2", "p3", "p4")
    joint = jointly_determined(names, covariance)
    assert set(joint) == {"p1", "p2", "p3"}, joint
    assert set(joint["p3"]["with"]) == {"p1", "p2"}
    for i, name in enumerate(names[:3]):
        others = np.delete(x, i, axis=1)
        fit = others @ np.linalg.lstsq(others, x[:, i], rcond=None)[0]
        r2 = 1 - np.sum((x[:, i] - fit) ** 2) / np.sum((x[:, i] - x[:, i].mean()) ** 2)
        np.testing.assert_allclose(joint[name]["inflation"], np.sqrt(1 / (1 - r2)), rtol=0.02)
    # An undefined variance (an unidentified parameter) is left out, not propagated.
    covariance[3, :] = covariance[:, 3] = np.nan
    assert set(jointly_determined(names, covariance)) == {"p1", "p2", "p3"}
