"""The swing-up's direct collocation: its transcription against plain RK4 rollouts of the benchmark's own 2 ms
steps (made apart, by `open_loop_rollout`), its banded Jacobian against JAX's, and one short stage solved to
zero defects; the whole default search to a leaderboard score above 0.70 (slow)."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
import pytest

from dynax import control
from dynax.internal import (
    collocate,
    collocation_costs,
    defect_jacobian,
    knot_matrix,
    open_loop_rollout,
    score_surrogate,
    Transcription,
)

H, DT, N = 0.02, 0.002, 8


def _shooting(seed=0):
    """Random smooth knot torques (zero at both ends) and the 2 ms RK4 rollout's states at the knots."""
    rng = np.random.default_rng(seed)
    knots = np.concatenate([[0.0], rng.uniform(-4.0, 4.0, N - 1), [0.0]])
    us = knot_matrix(10 * N, DT, H, N) @ jnp.asarray(knots)
    x_end, xs = open_loop_rollout(control.LeaderboardPlant.nominal(), us, DT)
    return jnp.concatenate([xs[::10], x_end[None]]), jnp.asarray(knots), us


def test_a_shooting_trajectory_has_zero_defects_and_the_surrogates_costs():
    plant = control.LeaderboardPlant.nominal()
    x_knots, knots, _ = _shooting()
    costs, defects = collocation_costs(plant, x_knots, knots, H, DT)
    assert float(jnp.max(jnp.abs(defects))) < 1e-12
    w = jnp.arctanh(knots[1:] / 6.0)  # the shooting's surrogate: another code path, knots on the tanh scale
    _, expected = score_surrogate(plant, w, knot_matrix(10 * N, DT, H, N), DT, control.SwingUpDesign(horizon=H * N))
    np.testing.assert_allclose(np.asarray(costs), np.asarray(expected), rtol=1e-9)
    _, coarse = collocation_costs(plant, x_knots, knots, H, 0.01)  # a 10 ms transcription does not close
    assert float(jnp.max(jnp.abs(coarse))) > 1e-6


def test_the_banded_defect_jacobian_is_jaxs():
    plant = control.LeaderboardPlant.nominal()
    x_knots, knots, _ = _shooting(1)
    tr = Transcription(N, H, 6.0, x_knots[-1])
    z = tr.pack(x_knots, knots) + 0.05 * jnp.asarray(np.random.default_rng(2).normal(size=5 * (N - 1)))

    def defects(z):
        return collocation_costs(plant, *tr.unpack(z), H, 0.01)[1].ravel()

    np.testing.assert_allclose(
        np.asarray(defect_jacobian(plant, z, tr, 0.01)), np.asarray(jax.jacfwd(defects)(z)), atol=1e-12
    )


def test_a_collocation_stage_ends_on_a_plain_rk4_rollout():
    """From a perturbed shooting trajectory, one short stage and its Gauss-Newton projection give knots
    whose plain 2 ms RK4 rollout passes through the collocation's states and reaches the fixed end."""
    plant = control.LeaderboardPlant.nominal()
    x_knots, knots, _ = _shooting(3)
    tr = Transcription(N, H, 6.0, x_knots[-1])
    rng = np.random.default_rng(4)
    z0 = jnp.stack([tr.pack(x_knots, knots) + s * jnp.asarray(rng.normal(size=5 * (N - 1))) for s in (0.02, 0.1)])
    stage = control.CollocationStage(sub_dt=DT, learning_rate=1e-3, rounds=2, inner=20)
    z, surrogate, costs, defect = collocate(plant, z0, tr, stage)
    assert np.all(np.asarray(defect) < 1e-10)
    for i in range(2):
        xs_c, u_c = tr.unpack(z[i])
        us = knot_matrix(10 * N, DT, H, N) @ u_c
        x_end, xs = open_loop_rollout(plant, us, DT)
        np.testing.assert_allclose(np.asarray(xs[::10]), np.asarray(xs_c[:-1]), atol=1e-9)
        np.testing.assert_allclose(np.asarray(x_end), np.asarray(x_knots[-1]), atol=1e-9)
        w = jnp.arctanh(u_c[1:] / 6.0)
        s, expected = score_surrogate(plant, w, knot_matrix(10 * N, DT, H, N), DT, control.SwingUpDesign())
        np.testing.assert_allclose(np.asarray(costs[i]), np.asarray(expected), rtol=1e-8)
        np.testing.assert_allclose(float(surrogate[i]), float(s), rtol=1e-8)


def test_pumping_starts_are_the_grid_and_start_at_rest():
    plant = control.LeaderboardPlant.nominal()
    starts = control.PumpingStarts()
    z, labels = starts.guesses(plant, 75, H, 6.0)
    assert z.shape == (16, 5 * 74) and len({tuple(sorted(d.items())) for d in labels}) == 16
    tr = Transcription(75)
    xs, u = tr.unpack(jnp.asarray(z[0]))
    assert float(jnp.max(jnp.abs(xs[0]))) == 0.0 and float(u[0]) == 0.0 and float(u[-1]) == 0.0
    assert float(jnp.max(jnp.abs(u))) <= 0.95 * 6.0 + 1e-12
    assert control.PumpingStarts(number=3).guesses(plant, 75, H, 6.0)[0].shape[0] == 3
    with pytest.raises(ValueError, match="knot spacing"):
        control.search_reference(plant, control.ReferenceSearch(horizon=1.51))


@pytest.mark.slow
def test_the_default_search_beats_the_published_leaderboard():
    """The whole default search (about 7 min on 2 busy cores): performance above every published entry."""
    controller = control.design_swing_up()
    assert control.performance(controller).score >= 0.70


def test_cli_refuses_a_horizon_off_the_knot_grid(tmp_path, capsys):
    from dynax.internal import cli_main

    assert cli_main(["control", "acrobot", "--out", str(tmp_path / "p.npz"), "--horizon", "1.51"]) == 2
    assert "--horizon" in capsys.readouterr().err and not (tmp_path / "p.npz").exists()
