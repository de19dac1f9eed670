"""Drake's Spong controller: the control law term by term, and swing-up from Drake's own test start."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import dynax
from dynax.control import (
    is_upright,
    random_starts,
    simulate_closed_loop,
    SmoothActivation,
    SpongController,
    swing_up_time,
    SwingUpTask,
    upright_error,
)
from tests.typecheck import standing_aside

DRAKE_TEST_START = jnp.array([0.1, -0.1, 0.0, 0.02])


def _drake_reference_torque(x, k_e=5.0, k_p=50.0, k_d=5.0, threshold=1000.0):
    """A line-by-line numpy transcription of Drake's AcrobotSpongController::CalcControlTorque."""
    m1, m2, l1, lc1, lc2, Ic1, Ic2, b1, b2, g = 1.0, 1.0, 1.0, 0.5, 1.0, 0.083, 0.33, 0.1, 0.1, 9.81
    th1, th2, th1d, th2d = x
    I1, I2 = Ic1 + m1 * lc1**2, Ic2 + m2 * lc2**2
    m2l1lc2 = m2 * l1 * lc2
    c2, s1, s2, s12 = np.cos(th2), np.sin(th1), np.sin(th2), np.sin(th1 + th2)
    M = np.array([[I1 + I2 + m2 * l1**2 + 2 * m2l1lc2 * c2, I2 + m2l1lc2 * c2], [I2 + m2l1lc2 * c2, I2]])
    bias = np.array(
        [
            -2 * m2l1lc2 * s2 * th2d * th1d
            - m2l1lc2 * s2 * th2d**2
            + g * m1 * lc1 * s1
            + g * m2 * (l1 * s1 + lc2 * s12)
            + b1 * th1d,
            m2l1lc2 * s2 * th1d**2 + g * m2 * lc2 * s12 + b2 * th2d,
        ]
    )

    # LQR about upright, linearised by finite differences of the same dynamics.
    def f(state, u):
        q1, q2, v1, v2 = state
        c2_, s1_, s2_, s12_ = np.cos(q2), np.sin(q1), np.sin(q2), np.sin(q1 + q2)
        M_ = np.array([[I1 + I2 + m2 * l1**2 + 2 * m2l1lc2 * c2_, I2 + m2l1lc2 * c2_], [I2 + m2l1lc2 * c2_, I2]])
        h = np.array(
            [
                -2 * m2l1lc2 * s2_ * v2 * v1
                - m2l1lc2 * s2_ * v2**2
                + g * m1 * lc1 * s1_
                + g * m2 * (l1 * s1_ + lc2 * s12_)
                + b1 * v1,
                m2l1lc2 * s2_ * v1**2 + g * m2 * lc2 * s12_ + b2 * v2,
            ]
        )
        return np.concatenate([[v1, v2], np.linalg.solve(M_, np.array([0.0, u]) - h)])

    x0 = np.array([np.pi, 0, 0, 0])
    eps = 1e-6
    A = np.stack([(f(x0 + eps * e, 0) - f(x0 - eps * e, 0)) / (2 * eps) for e in np.eye(4)], axis=1)
    B = ((f(x0, eps) - f(x0, -eps)) / (2 * eps))[:, None]
    Q, R = np.diag([10.0, 10, 1, 1]), np.eye(1)
    S = scipy.linalg.solve_continuous_are(A, B, Q, R)
    K = np.linalg.solve(R, B.T @ S)
    xw = np.array(x, dtype=float)
    xw[0] = np.mod(xw[0], 2 * np.pi)
    xw[1] = np.mod(xw[1] + np.pi, 2 * np.pi) - np.pi
    cost = (xw - x0) @ S @ (xw - x0)
    if cost < threshold:
        u = (K @ (x0 - xw))[0]
    else:
        Minv = np.linalg.inv(M)
        PE = -m1 * g * lc1 * np.cos(th1) - m2 * g * (l1 * np.cos(th1) + lc2 * np.cos(th1 + th2))
        KE = 0.5 * np.array([th1d, th2d]) @ M @ np.array([th1d, th2d])
        E_desired = (m1 * lc1 + m2 * (l1 + lc2)) * g
        u_e = -k_e * (PE + KE - E_desired) * th2d
        y = -k_p * th2 - k_d * th2d
        a3, a2 = Minv[1, 1], Minv[0, 1]
        u = u_e + (a2 * bias[0] + y) / a3 + bias[1]
    return float(np.clip(u, -20, 20)), cost


@pytest.fixture(scope="module")
def controller():
    return SpongController()


def test_torque_matches_drake_transcription(controller):
    rng = np.random.default_rng(0)
    states = np.concatenate(
        [
            np.column_stack(
                [rng.uniform(-np.pi, np.pi, 40), rng.uniform(-np.pi, np.pi, 40), rng.normal(0, 1, (40, 2))]
            ),
            np.column_stack([np.pi + rng.normal(0, 0.05, 20), rng.normal(0, 0.05, 20), rng.normal(0, 0.2, (20, 2))]),
            np.column_stack(
                [np.pi + 2 * np.pi + rng.normal(0, 0.05, 5), rng.normal(0, 0.05, 5) - 2 * np.pi, np.zeros((5, 2))]
            ),
        ]
    )
    torques = jax.jit(jax.vmap(lambda x: controller(0.0, x)))(jnp.asarray(states))[:, 0]
    reference = [_drake_reference_torque(x) for x in states]
    expected = np.array([u for u, _ in reference])
    costs = np.array([c for _, c in reference])
    assert (costs < 1000).sum() >= 20 and (costs >= 1000).sum() >= 20  # both branches exercised
    np.testing.assert_allclose(torques, expected, rtol=1e-6, atol=1e-6)
    assert np.all(np.abs(torques) <= 20.0)


def test_drake_test_start_is_upright_by_10_s(controller):
    # Drake's run_swing_up: from (0.1, -0.1, 0, 0.02) the acrobot is within 0.01 rad and 0.1 rad/s
    # of upright after 10 s of simulation.
    ts = jnp.arange(1001) * 0.01
    loop = jax.jit(simulate_closed_loop, static_argnums=())(dynax.Acrobot(), controller, DRAKE_TEST_START, ts)
    final = upright_error(loop.xs[-1])
    assert np.all(np.abs(final[:2]) < 1e-2) and np.all(np.abs(final[2:]) < 0.1)
    time, success = swing_up_time(loop.ts, loop.xs)
    assert success and 2.0 < time < 10.0
    assert jnp.all(jnp.abs(loop.us) <= 20.0)
    assert not jnp.isfinite(loop.diverged_at)


def test_with_params_and_switching(controller):
    assert np.allclose(controller.params, [5.0, 50.0, 5.0, 1000.0])
    tuned = controller.with_params(jnp.array([1.0, 2.0, 3.0, 4.0]))
    assert np.allclose(tuned.params, [1.0, 2.0, 3.0, 4.0])
    near_upright = jnp.array([jnp.pi + 0.01, 0.0, 0.0, 0.0])
    assert controller.balance.cost_to_go(near_upright) < 1000
    np.testing.assert_allclose(controller(0.0, near_upright), controller.balance(0.0, near_upright))
    # A zero threshold never balances: the swing-up law acts everywhere.
    never = controller.with_params(jnp.array([5.0, 50.0, 5.0, 0.0]))
    np.testing.assert_allclose(never(0.0, near_upright)[0], jnp.clip(never.swing_up_torque(near_upright), -20, 20))
    with standing_aside(), pytest.raises(ValueError, match="`params`"):  # a wrong shape on purpose
        controller.with_params(jnp.ones(3))


def test_smooth_activation_approaches_threshold_and_is_differentiable(controller):
    sharp = eqx.tree_at(lambda c: c.switching, controller, SmoothActivation(temperature=1e-3))
    rng = np.random.default_rng(1)
    states = jnp.asarray(
        np.column_stack([np.pi + rng.normal(0, 0.3, 30), rng.normal(0, 0.3, 30), rng.normal(0, 0.5, (30, 2))])
    )

    @eqx.filter_jit
    def torques(c):
        return jax.vmap(lambda x: c(0.0, x))(states)

    hard, soft = torques(controller), torques(sharp)
    costs = jax.vmap(controller.balance.cost_to_go)(states)
    away = jnp.abs(jnp.log(costs / 1000.0)) > 0.05  # not on the switching surface
    np.testing.assert_allclose(soft[away], hard[away], rtol=1e-6, atol=1e-6)
    smooth = eqx.tree_at(lambda c: c.switching, controller, SmoothActivation())
    d_phi = eqx.filter_jit(jax.grad(lambda c: c(0.0, states[0])[0]))(smooth).phi
    assert jnp.isfinite(d_phi) and d_phi != 0


def test_closed_loop_with_zero_controller_matches_simulate():
    system = dynax.Acrobot()
    ts = jnp.arange(201) * 0.01
    x0 = jnp.array([0.5, -0.3, 0.0, 0.1])
    loop = simulate_closed_loop(system, lambda t, x: jnp.zeros(1), x0, ts)
    open_loop = dynax.simulate(system, x0, ts)
    np.testing.assert_allclose(loop.xs, open_loop.xs, rtol=1e-12, atol=1e-12)
    assert loop.us.shape == (201, 1)


def test_closed_loop_reports_divergence_and_checks_shapes():
    system = dynax.Acrobot()
    ts = jnp.arange(101) * 0.01
    loop = simulate_closed_loop(system, lambda t, x: jnp.array([1e9]), jnp.zeros(4), ts, divergence_bound=1e3)
    assert jnp.isfinite(loop.diverged_at) and jnp.all(jnp.isnan(loop.xs[-1]))
    with pytest.raises(ValueError, match="`x0`"):
        simulate_closed_loop(system, lambda t, x: jnp.zeros(1), jnp.zeros(3), ts)


def test_swing_up_time_definition():
    ts = jnp.arange(5) * 1.0
    up = jnp.array([jnp.pi, 0.0, 0.0, 0.0])
    down = jnp.zeros(4)
    # Upright briefly at t=1, then away, then upright from t=3 to the end: settled at 3 s.
    xs = jnp.stack([down, up, down, up, up + jnp.array([2 * jnp.pi, -2 * jnp.pi, 0, 0])])
    time, success = swing_up_time(ts, xs)
    assert success and time == 3.0
    time, success = swing_up_time(ts, xs.at[-1].set(down))
    assert not success and time == 4.0  # failure counts as the episode length
    assert bool(is_upright(up)) and not bool(is_upright(up + jnp.array([0, 0, 0.2, 0])))


def test_task_reward_prefers_drake_gains_over_a_weak_pump():
    task = SwingUpTask(dynax.Acrobot(), SpongController(), duration=10.0, control_rate=50.0)
    starts = random_starts(jax.random.PRNGKey(0), 8)
    evaluate = eqx.filter_jit(task.evaluate)
    drake = evaluate(jnp.array([5.0, 50.0, 5.0, 1000.0]), starts)
    weak = evaluate(jnp.array([0.3, 50.0, 5.0, 1000.0]), starts)
    assert drake["reward"] > weak["reward"]
    assert drake["success_rate"] > weak["success_rate"]
    assert weak["mean_time_s"] == 10.0  # a too-weak energy pump never gets up
    assert jnp.all(jnp.abs(starts[:, :2]) <= 0.5) and jnp.all(starts[:, 2:] == 0)


def test_spong_controller_gives_zero_torque_at_the_hanging_rest():
    # Energy pumping ~ dq2, PFL ~ (q2, dq2) and the bias forces vanish at rest: the arm never moves.
    controller = SpongController()
    x_rest = jnp.zeros(4)
    assert float(controller(0.0, x_rest)[0]) == 0.0
    loop = simulate_closed_loop(controller.system, controller, x_rest, jnp.linspace(0.0, 0.5, 26))
    assert float(jnp.max(jnp.abs(loop.xs))) == 0.0
    # ... while a small offset does give torque (the test can fail).
    assert abs(float(controller(0.0, jnp.array([0.0, 0.05, 0.0, 0.0]))[0])) > 0.1
