"""The many-start collocation experiment's transcription: a rollout of the benchmark's own 2 ms steps
has zero defects in it, and its costs are the score's surrogate computed apart."""

import importlib.util
import pathlib

import jax
import jax.numpy as jnp
import numpy as np

import dynax
from dynax import control

ROOT = pathlib.Path(__file__).resolve().parents[2]
POLICY = ROOT / "experiments" / "results" / "leaderboard" / "acrobot_policy.npz"


def _experiment():
    spec = importlib.util.spec_from_file_location(
        "acrobot_collocation_starts", ROOT / "experiments" / "acrobot_collocation_starts.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_shooting_trajectory_has_zero_defects_and_the_surrogates_costs():
    jax.config.update("jax_enable_x64", True)
    from dynax.internal import knot_matrix, open_loop_rollout, score_surrogate

    m = _experiment()
    saved = dynax.control.load_controller(POLICY)
    plant = control.LeaderboardPlant.nominal()
    n = saved.u_ref.shape[0] // 10
    # torque knots 20 ms apart, zero at both ends; the 2 ms rollout of their interpolation
    rng = np.random.default_rng(0)
    knots = np.concatenate([[0.0], saved.u_ref[10::10][: n - 1] + 0.1 * rng.normal(size=n - 1), [0.0]])
    us = knot_matrix(10 * n, 0.002, 0.02, n) @ jnp.asarray(knots)
    x_end, xs = open_loop_rollout(plant, us, 0.002)
    x_knots = jnp.concatenate([xs[::10], x_end[None]])
    costs, defects = m.costs_of(plant, x_knots, jnp.asarray(knots), sub=0.002)
    assert float(jnp.max(jnp.abs(defects))) < 1e-10
    # the same costs from the shooting's surrogate (another code path: knots on the tanh scale)
    w = jnp.arctanh(jnp.asarray(knots[1:]) / 6.0)
    design = control.SwingUpDesign(horizon=0.02 * n)
    _, expected = score_surrogate(plant, w, knot_matrix(10 * n, 0.002, 0.02, n), 0.002, design)
    np.testing.assert_allclose(np.asarray(costs), np.asarray(expected), rtol=1e-9)
    # and a coarse 10 ms transcription of the same trajectory does not close
    _, coarse = m.costs_of(plant, x_knots, jnp.asarray(knots), sub=0.01)
    assert float(jnp.max(jnp.abs(coarse))) > 1e-6
