"""LQR: linearisation by autodiff and the Riccati solvers against scipy, with gradient checks."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import dynax
from dynax.control import discrete_lqr, linearise, lqr, solve_continuous_are, solve_discrete_are, wrap_angle

UPRIGHT = jnp.array([jnp.pi, 0.0, 0.0, 0.0])
Q = np.diag([10.0, 10.0, 1.0, 1.0])
R = np.eye(1)


def _random_problem(seed, n=5, m=2):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n))
    b = rng.normal(size=(n, m))
    c = rng.normal(size=(n, n))
    q = c @ c.T / n + 0.1 * np.eye(n)
    d = rng.normal(size=(m, m))
    r = d @ d.T + np.eye(m)
    return a, b, q, r


def test_linearise_matches_closed_form_acrobot():
    # Upright linearisation of the acrobot: A = [[0, I], [M^-1 dtau_g/dq, -M^-1 D]], B = [0; M^-1 e2].
    system = dynax.Acrobot()
    a, b = linearise(system, UPRIGHT, jnp.zeros(1))
    p = system
    m = np.array(system.mass_matrix(UPRIGHT[:2]))
    minv = np.linalg.inv(m)
    dtau = np.array([[p.theta4 + p.theta5, p.theta5], [p.theta5, p.theta5]])  # d tau_g / dq at (pi, 0)
    damping = np.diag([p.theta6, p.theta7])
    expected_a = np.block([[np.zeros((2, 2)), np.eye(2)], [minv @ dtau, -minv @ damping]])
    expected_b = np.concatenate([np.zeros((2, 1)), minv @ np.array([[0.0], [1.0]])])
    np.testing.assert_allclose(a, expected_a, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b, expected_b, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_care_matches_scipy(seed):
    a, b, q, r = _random_problem(seed)
    x = solve_continuous_are(a, b, q, r)
    expected = scipy.linalg.solve_continuous_are(a, b, q, r)
    np.testing.assert_allclose(x, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize("seed", range(4))
def test_dare_matches_scipy(seed):
    a, b, q, r = _random_problem(seed)
    a = a / (0.9 * np.max(np.abs(np.linalg.eigvals(a))))  # some eigenvalues near the unit circle
    x = solve_discrete_are(a, b, q, r)
    expected = scipy.linalg.solve_discrete_are(a, b, q, r)
    np.testing.assert_allclose(x, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def test_acrobot_lqr_matches_scipy_and_stabilises():
    system = dynax.Acrobot()
    controller = lqr(system, UPRIGHT, jnp.zeros(1), Q, R, angles=(0, 1))
    a, b = (np.asarray(m) for m in linearise(system, UPRIGHT, jnp.zeros(1)))
    s = scipy.linalg.solve_continuous_are(a, b, Q, R)
    np.testing.assert_allclose(controller.cost_to_go_matrix, s, rtol=1e-9)
    np.testing.assert_allclose(controller.gain, np.linalg.solve(R, b.T @ s), rtol=1e-9)
    closed = a - b @ np.asarray(controller.gain)
    assert np.max(np.linalg.eigvals(closed).real) < 0
    # Angles are wrapped: a full turn of the shoulder is still upright.
    np.testing.assert_allclose(controller(0.0, UPRIGHT + jnp.array([2 * jnp.pi, 0, 0, 0])), 0.0, atol=1e-9)


def test_discrete_lqr_matches_scipy():
    system = dynax.Acrobot()
    dt = 0.01
    controller = discrete_lqr(system, UPRIGHT, jnp.zeros(1), Q, R, dt)
    a, b = (np.asarray(m) for m in linearise(system, UPRIGHT, jnp.zeros(1)))
    ad = scipy.linalg.expm(a * dt)
    bd = np.linalg.solve(a, (ad - np.eye(4))) @ b  # A is invertible at the upright point
    s = scipy.linalg.solve_discrete_are(ad, bd, Q, R)
    np.testing.assert_allclose(controller.cost_to_go_matrix, s, rtol=1e-8)
    k = np.linalg.solve(R + bd.T @ s @ bd, bd.T @ s @ ad)
    np.testing.assert_allclose(controller.gain, k, rtol=1e-8)


def _central_difference(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


def test_care_gradient_matches_finite_differences():
    a, b, q, r = _random_problem(7, n=4, m=1)
    direction = np.random.default_rng(1).normal(size=a.shape)
    weights = np.random.default_rng(2).normal(size=a.shape)

    def loss(scale):
        return jnp.sum(weights * solve_continuous_are(a + scale * direction, b, q * (1 + scale), r))

    grad = jax.jit(jax.grad(loss))(0.0)
    assert np.isclose(grad, _central_difference(loss, 0.0, 1e-5), rtol=1e-6)
    # Reverse mode for all four arguments at once agrees with forward mode.
    fwd = jax.jit(jax.jacfwd(lambda r_: solve_continuous_are(a, b, q, r_)))(jnp.asarray(r))
    rev = jax.jit(jax.jacrev(lambda r_: solve_continuous_are(a, b, q, r_)))(jnp.asarray(r))
    np.testing.assert_allclose(fwd, rev, rtol=1e-9, atol=1e-12)


def test_dare_gradient_matches_finite_differences():
    a, b, q, r = _random_problem(3, n=4, m=2)
    direction = np.random.default_rng(4).normal(size=b.shape)

    def loss(scale):
        return jnp.sum(solve_discrete_are(a / 3, b + scale * direction, q, r * (1 + scale)) ** 2)

    assert np.isclose(jax.jit(jax.grad(loss))(0.0), _central_difference(loss, 0.0, 1e-5), rtol=1e-6)


def test_lqr_gain_differentiable_in_model_parameters():
    def gain_sum(theta1):
        return lqr(dynax.Acrobot(theta1=theta1), UPRIGHT, jnp.zeros(1), Q, R).gain.sum()

    theta1 = jnp.asarray(dynax.Acrobot().theta1)
    assert np.isclose(jax.jit(jax.grad(gain_sum))(theta1), _central_difference(gain_sum, theta1, 1e-5), rtol=1e-6)


def test_riccati_solvers_vmap():
    problems = [_random_problem(s, n=3, m=1) for s in range(3)]
    stacked = [np.stack(p) for p in zip(*problems)]
    xs = jax.vmap(solve_continuous_are)(*stacked)
    for x, p in zip(xs, problems):
        np.testing.assert_allclose(x, scipy.linalg.solve_continuous_are(*p), rtol=1e-9)


@pytest.mark.wrong_types
def test_shape_errors_name_the_argument():
    a, b, q, r = _random_problem(0)
    with pytest.raises(ValueError, match="`q`"):
        solve_continuous_are(a, b, q[:2, :2], r)
    with pytest.raises(ValueError, match="`x_eq`"):
        linearise(dynax.Acrobot(), jnp.zeros(3), jnp.zeros(1))


def test_wrap_angle_range():
    angles = jnp.array([-7.0, -jnp.pi, 0.0, jnp.pi, 7.0])
    wrapped = wrap_angle(angles)
    assert jnp.all(wrapped >= -jnp.pi) and jnp.all(wrapped < jnp.pi)
    np.testing.assert_allclose(jnp.cos(wrapped), jnp.cos(angles), atol=1e-12)
