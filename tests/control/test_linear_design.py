"""python-control's shape: lqr(A, B, Q, R) -> (K, S, E), dlqr, lqe, ctrb, obsv, against scipy and by definition."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import dynax
from tests.typecheck import standing_aside


def _problem(seed, n=4, m=2):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n))
    b = rng.normal(size=(n, m))
    c = rng.normal(size=(n, n))
    q = c @ c.T / n + 0.1 * np.eye(n)
    d = rng.normal(size=(m, m))
    return a, b, q, d @ d.T + np.eye(m)


@pytest.mark.parametrize("seed", [0, 1])
def test_lqr_matrix_form_matches_scipy(seed):
    a, b, q, r = _problem(seed)
    k, s, e = dynax.control.lqr(a, b, q, r)
    s_ref = scipy.linalg.solve_continuous_are(a, b, q, r)
    k_ref = np.linalg.solve(r, b.T @ s_ref)
    np.testing.assert_allclose(s, s_ref, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(k, k_ref, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(
        np.sort_complex(np.asarray(e)), np.sort_complex(np.linalg.eigvals(a - b @ k_ref)), rtol=1e-7
    )
    assert np.all(np.real(e) < 0)  # the closed loop is stable


def test_lqr_system_form_still_returns_a_controller():
    controller = dynax.control.lqr(dynax.Acrobot(), jnp.array([jnp.pi, 0, 0, 0]), jnp.zeros(1), jnp.ones(4), 1.0)
    assert isinstance(controller, dynax.control.LQR)
    with pytest.raises(ValueError, match="cost `r` is missing"):
        dynax.control.lqr(dynax.Acrobot(), jnp.array([jnp.pi, 0, 0, 0]), jnp.zeros(1), jnp.ones(4))
    with pytest.raises(ValueError, match="matrix form is lqr"):
        dynax.control.lqr(np.eye(2), np.ones((2, 1)), np.eye(2), np.eye(1), np.eye(1))


def test_dlqr_matches_scipy():
    a, b, q, r = _problem(2)
    a = a / (1.2 * np.max(np.abs(np.linalg.eigvals(a))))  # any A works; a moderate one keeps it readable
    k, s, e = dynax.control.dlqr(a, b, q, r)
    s_ref = scipy.linalg.solve_discrete_are(a, b, q, r)
    k_ref = np.linalg.solve(r + b.T @ s_ref @ b, b.T @ s_ref @ a)
    np.testing.assert_allclose(s, s_ref, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(k, k_ref, rtol=1e-8, atol=1e-10)
    assert np.all(np.abs(e) < 1)


def test_lqe_is_the_kalman_bucy_gain():
    a, _, _, _ = _problem(3)
    rng = np.random.default_rng(3)
    g = rng.normal(size=(4, 2))
    c = rng.normal(size=(2, 4))
    qn, rn = np.diag([1.0, 0.5]), np.diag([0.1, 0.2])
    gain, p, e = dynax.control.lqe(a, g, c, qn, rn)
    # P solves A P + P A' - P C' RN^-1 C P + G QN G' = 0 (scipy's CARE of the dual problem).
    p_ref = scipy.linalg.solve_continuous_are(a.T, c.T, g @ qn @ g.T, rn)
    np.testing.assert_allclose(p, p_ref, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(gain, p_ref @ c.T @ np.linalg.inv(rn), rtol=1e-8, atol=1e-10)
    assert np.all(np.real(e) < 0)  # the estimation error decays


def test_lqe_filters_a_noisy_simulation_better_than_open_loop():
    # A lightly damped oscillator with process noise, measured in position: the steady-state Kalman
    # gain's estimate must beat the open-loop model's (a statistical property, not a formula).
    dt, n = 1e-3, 20000
    a = np.array([[0.0, 1.0], [-4.0, -0.2]])
    g = np.array([[0.0], [1.0]])
    c = np.array([[1.0, 0.0]])
    qn, rn = np.array([[1.0]]), np.array([[1e-3]])
    gain, _, _ = dynax.control.lqe(a, g, c, qn, rn)
    gain = np.asarray(gain)
    rng = np.random.default_rng(0)
    x = np.zeros(2)
    x_filter = np.zeros(2)
    x_open = np.zeros(2)
    err_filter = err_open = 0.0
    for _ in range(n):
        x = x + dt * (a @ x) + g[:, 0] * rng.normal() * np.sqrt(qn[0, 0] * dt)
        y = c @ x + rng.normal() * np.sqrt(rn[0, 0] / dt)
        x_filter = x_filter + dt * (a @ x_filter + gain @ (y - c @ x_filter))
        x_open = x_open + dt * (a @ x_open)
        err_filter += np.sum((x - x_filter) ** 2)
        err_open += np.sum((x - x_open) ** 2)
    assert err_filter < 0.2 * err_open


def test_ctrb_and_obsv_detect_an_uncontrollable_mode():
    a = np.diag([-1.0, -2.0, -3.0])
    b_full = np.ones((3, 1))
    b_missing = np.array([[1.0], [1.0], [0.0]])  # the third mode is never excited
    assert np.linalg.matrix_rank(np.asarray(dynax.control.ctrb(a, b_full))) == 3
    assert np.linalg.matrix_rank(np.asarray(dynax.control.ctrb(a, b_missing))) == 2
    c = b_missing.T
    np.testing.assert_allclose(dynax.control.obsv(a, c), np.asarray(dynax.control.ctrb(a.T, c.T)).T)  # duality
    assert dynax.control.ctrb(a, np.ones((3, 2))).shape == (3, 6) and dynax.control.obsv(a, np.ones((2, 3))).shape == (
        6,
        3,
    )
    with standing_aside(), pytest.raises(ValueError, match="`b` must have shape"):  # a wrong shape on purpose
        dynax.control.ctrb(a, np.ones((2, 1)))


def test_lqr_gain_is_differentiable_and_jittable():
    a, b, q, r = _problem(4)
    direction = np.random.default_rng(4).normal(size=a.shape)

    def gain_sum(scale):
        return jnp.sum(dynax.control.lqr(jnp.asarray(a) + scale * direction, b, q, r)[0])

    grad = jax.grad(gain_sum)(0.0)
    h = 1e-6
    fd = (gain_sum(h) - gain_sum(-h)) / (2 * h)
    np.testing.assert_allclose(grad, fd, rtol=1e-5)
    k_jit = jax.jit(lambda a: dynax.control.lqr(a, b, q, r)[0])(a)
    np.testing.assert_allclose(k_jit, dynax.control.lqr(a, b, q, r)[0], rtol=1e-10)
