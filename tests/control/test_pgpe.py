"""PGPE: the ask/tell contract, a known quadratic, the swing-up objective, and sharded populations."""

import os
import subprocess
import sys
import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import dynax
from dynax.control import (
    BaselineNormalisation,
    CentredRank,
    clipup,
    PGPE,
    random_starts,
    run_pgpe,
    SpongController,
    SwingUpTask,
)
from tests.helpers import tree_allclose

TARGET = jnp.array([1.0, -2.0, 3.0, 500.0])
SCALES = jnp.array([1.0, 1.0, 1.0, 100.0])


def quadratic(params, key):
    return -jnp.sum(((params - TARGET) / SCALES) ** 2)


def test_ask_is_symmetric_and_tell_checks_shapes(key):
    pgpe = PGPE(population_size=8, scales=SCALES, init_sigma=0.3)
    state = pgpe.init(jnp.zeros(4))
    population, noise = pgpe.ask(state, key)
    assert population.shape == (8, 4) and noise.shape == (4, 4)
    np.testing.assert_allclose(population[:4] + population[4:], 0.0, atol=1e-12)
    np.testing.assert_allclose(population[:4], noise * SCALES[None], rtol=1e-12)
    with pytest.raises(ValueError, match="`rewards`"):
        pgpe.tell(state, noise, jnp.zeros(7))
    with pytest.raises(ValueError, match="`population_size`"):
        PGPE(population_size=7)


@pytest.mark.parametrize(
    "pgpe",
    [
        PGPE(population_size=32, scales=SCALES, init_sigma=0.5, optimizer=optax.sgd(0.5)),
        PGPE(population_size=32, scales=SCALES, init_sigma=0.5, optimizer=optax.adam(0.1)),
        PGPE(population_size=32, scales=SCALES, init_sigma=0.5, optimizer=clipup(0.15), fitness_shaping=CentredRank()),
    ],
    ids=["paper-sgd", "paper-adam", "rank-clipup"],
)
def test_pgpe_solves_a_quadratic(pgpe, key):
    state, history = jax.jit(lambda k: run_pgpe(pgpe, quadratic, jnp.zeros(4), k, 150))(key)
    # Start: distance^2 = 1 + 4 + 9 + 25 = 39 in normalised units.
    assert quadratic(pgpe.mean_params(state), None) > -0.5
    assert history.reward[-10:].mean() > 0.05 * history.reward[:10].mean()
    # The best reward is a real evaluation: the objective at the recorded best parameters gives it back.
    assert float(quadratic(state.best_params, None)) == pytest.approx(float(state.best_reward), rel=1e-12)
    assert float(history.best_reward[-1]) == float(state.best_reward)


def _paper_update(mean, sigma, best, baseline, noise, rewards, learning_rate, first):
    """One iteration of symmetric-sampling PGPE written out from Sehnke et al. (2010), eqs. for the
    symmetric case with reward normalisation, in numpy (plain SGD on the mean, unit scales)."""
    pairs = len(noise)
    r_plus, r_minus = rewards[:pairs], rewards[pairs:]
    best = max(best, rewards.max())
    baseline = rewards.mean() if first else baseline
    mean_signal = np.array(
        [(a - b) / (2 * best - a - b) if 2 * best - a - b > 0 else 0.0 for a, b in zip(r_plus, r_minus)]
    )
    sigma_signal = ((r_plus + r_minus) / 2 - baseline) / (best - baseline) if best > baseline else np.zeros(pairs)
    new_mean = mean + learning_rate * sum(m * e for m, e in zip(mean_signal, noise)) / pairs
    grad_sigma = sum(r * (e**2 - sigma**2) / sigma for r, e in zip(sigma_signal, noise)) / pairs
    new_sigma = np.maximum(sigma + np.clip(0.1 * grad_sigma, -0.2 * sigma, 0.2 * sigma), 1e-4)
    return new_mean, new_sigma, best, 0.9 * baseline + 0.1 * rewards.mean()


def test_tell_is_the_papers_update(key):
    """Two `ask`/`tell` iterations against the paper's update written out in numpy."""
    pgpe = PGPE(population_size=6, init_sigma=jnp.array([0.3, 0.5, 0.2, 0.4]), optimizer=optax.sgd(0.7))
    start = np.array([0.5, -1.0, 2.0, 0.0])
    state = pgpe.init(jnp.asarray(start))
    mean, sigma, best, baseline, best_params = start, np.array([0.3, 0.5, 0.2, 0.4]), -np.inf, 0.0, start
    for i, k in enumerate(jax.random.split(key, 3)):
        population, noise = pgpe.ask(state, k)
        rewards = np.asarray(jax.vmap(lambda p: -jnp.sum((p - jnp.arange(4.0)) ** 2))(population))
        state = pgpe.tell(state, noise, jnp.asarray(rewards))
        if rewards.max() > best:
            best_params = np.asarray(population[int(np.argmax(rewards))])
        mean, sigma, best, baseline = _paper_update(
            mean, sigma, best, baseline, np.asarray(noise), rewards, 0.7, i == 0
        )
        np.testing.assert_allclose(state.mean, mean, rtol=1e-12)
        np.testing.assert_allclose(state.sigma, sigma, rtol=1e-12)
        np.testing.assert_allclose([state.best_reward, state.baseline], [best, baseline], rtol=1e-12)
        np.testing.assert_allclose(state.best_params, best_params, rtol=1e-12)


def test_sigma_shrinks_near_the_optimum(key):
    pgpe = PGPE(population_size=32, scales=SCALES, init_sigma=1.0, fitness_shaping=BaselineNormalisation())
    state, history = jax.jit(lambda k: run_pgpe(pgpe, quadratic, TARGET, k, 60))(key)
    assert jnp.all(state.sigma < 0.5)


def test_runs_vmap_over_seeds(key):
    pgpe = PGPE(population_size=16, scales=SCALES, init_sigma=0.5, optimizer=optax.adam(0.1))
    keys = jax.random.split(key, 3)
    states, histories = jax.jit(jax.vmap(lambda k: run_pgpe(pgpe, quadratic, jnp.zeros(4), k, 60)))(keys)
    assert histories.reward.shape == (3, 60)
    assert not np.allclose(histories.reward[0], histories.reward[1])  # independent runs
    # a member of the vmapped sweep is the run made alone with its key: state and history alike
    alone = jax.jit(lambda k: run_pgpe(pgpe, quadratic, jnp.zeros(4), k, 60))(keys[1])
    assert tree_allclose(jax.tree.map(lambda x: x[1], (states, histories)), alone, rtol=1e-10, atol=1e-12)
    assert jnp.all(histories.reward[:, -5:].mean(1) > histories.reward[:, :5].mean(1))


def test_pgpe_improves_swing_up_from_a_poor_start():
    """Ten times too weak an energy pump: the acrobot rarely gets up. PGPE on random starts fixes it.

    Three seeds in one vmapped sweep. Every run must raise the mean reward on 32 fresh starts by more
    than 1; the swing-up success on those starts is a threshold event of a chaotic rollout in float32
    (one full-suite run once left a single seed at 0 of 32 while its reward still rose by more than 1),
    so it is asserted over the sweep, not per seed. Until 2026-11-25 this was a non-strict xfail,
    which cannot fail."""
    plant = jax.tree.map(lambda a: jnp.asarray(a, jnp.float32), dynax.Acrobot())
    task = SwingUpTask(plant, SpongController(plant), duration=8.0, control_rate=50.0)
    poor = jnp.array([0.5, 50.0, 5.0, 1000.0], jnp.float32)
    pgpe = PGPE(
        population_size=16,
        scales=jnp.array([5.0, 50.0, 5.0, 1000.0], jnp.float32),
        init_sigma=0.15,
        optimizer=clipup(0.08),
        fitness_shaping=CentredRank(),
    )
    keys = jax.random.split(jax.random.PRNGKey(3), 3)
    states, history = eqx.filter_jit(jax.vmap(lambda k: run_pgpe(pgpe, task, poor, k, 15)))(keys)
    starts = random_starts(jax.random.PRNGKey(123), 32, dtype=jnp.float32)
    evaluate = eqx.filter_jit(task.evaluate)
    before = evaluate(poor, starts)
    after = [evaluate(pgpe.mean_params(jax.tree.map(lambda x: x[i], states)), starts) for i in range(3)]
    assert all(a["reward"] > before["reward"] + 1.0 for a in after), [float(a["reward"]) for a in after]
    assert max(a["success_rate"] for a in after) > before["success_rate"]
    assert jnp.all(history.reward[:, -3:].mean(1) > history.reward[:, :3].mean(1))


SHARDED_SCRIPT = textwrap.dedent(
    """
    import jax, jax.numpy as jnp
    from dynax.control import evaluate_population, PGPE, population_sharding, run_pgpe, sweep_pgpe
    assert jax.device_count() == 2, jax.devices()
    assert population_sharding(8) is not None and population_sharding(7) is None
    target = jnp.arange(4.0)
    objective = lambda p, k: -jnp.sum((p - target) ** 2)
    pgpe = PGPE(population_size=8, init_sigma=0.5)
    keys = jax.random.split(jax.random.PRNGKey(0), 8)
    population = jax.random.normal(jax.random.PRNGKey(1), (8, 4))
    rewards = jax.jit(lambda p, k: evaluate_population(objective, p, k))(population, keys)
    assert len(rewards.sharding.device_set) == 2, rewards.sharding
    sharded = jax.jit(lambda k: run_pgpe(pgpe, objective, jnp.zeros(4), k, 30))(jax.random.PRNGKey(0))
    single = jax.jit(lambda k: run_pgpe(pgpe, objective, jnp.zeros(4), k, 30, shard=False))(jax.random.PRNGKey(0))
    assert jnp.allclose(sharded[1].reward, single[1].reward, rtol=1e-5), (sharded[1].reward, single[1].reward)
    # A sweep over seeds puts whole runs on each device and matches the unsharded vmap.
    keys = jax.random.split(jax.random.PRNGKey(2), 4)
    states, histories = sweep_pgpe(pgpe, objective, jnp.zeros(4), keys, 20)
    assert len(histories.reward.sharding.device_set) == 2, histories.reward.sharding
    _, reference = sweep_pgpe(pgpe, objective, jnp.zeros(4), keys, 20, shard=False)
    assert jnp.allclose(histories.reward, reference.reward, rtol=1e-5)
    assert histories.reward.shape == (4, 20)
    print("ok")
    """
)


def test_population_sharded_across_two_host_devices():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    result = subprocess.run(
        [sys.executable, "-c", SHARDED_SCRIPT], env=env, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.strip().endswith("ok")
