"""One process of the two-process test (and the single-process reference): a PGPE search, an
evaluation of one population outside `jit`, a sweep of two PGPE runs, and a `simulation_error`
sweep, saved to an `.npz`.

    python _worker.py OUT.npz                      # one process, one CPU device
    DYNAX_TEST_HOST_DEVICES=2 python _worker.py OUT.npz   # one process, two CPU devices
    python _worker.py OUT.npz PORT N_PROC RANK     # one of N_PROC processes (jax.distributed)
"""

import os
import sys

os.environ["JAX_PLATFORMS"] = "cpu"
# One CPU device per process, or as many as DYNAX_TEST_HOST_DEVICES asks (one process, several devices).
os.environ["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={os.environ.get('DYNAX_TEST_HOST_DEVICES', '1')}"

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import dynax  # noqa: E402

if len(sys.argv) > 2:
    port, n_processes, rank = sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    dynax.initialize_distributed(f"localhost:{port}", n_processes, rank, initialization_timeout=120)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from dynax import Trajectory  # noqa: E402


def main(out):
    ts = jnp.linspace(0.0, 1.0, 21)

    def objective(params, key):
        # The joints' damping is the policy: reward how close to rest a swing from a random start
        # ends (a real rollout, so that every device's share is a different simulation).
        arm = eqx.tree_at(lambda s: (s.theta6, s.theta7), dynax.DoublePendulum(), (params[0], params[1]))
        x0 = jnp.array([0.5, -0.3, 0.0, 0.0]) + 0.1 * jax.random.normal(key, (4,))
        sim = dynax.simulate(arm, x0, ts, jnp.zeros((ts.shape[0], 2)), throw=False)
        return -jnp.sum(sim.xs[-1] ** 2)

    pgpe = dynax.control.PGPE(population_size=8, init_sigma=0.3)
    state, history = dynax.control.run_pgpe(
        pgpe, objective, jnp.array([0.2, 0.1]), jax.random.key(0), 2, progress=False
    )
    population = pgpe.ask(state, jax.random.key(1))[0]
    rewards = dynax.control.evaluate_population(objective, population, jax.random.split(jax.random.key(2), 8))
    # Two runs of one generation with population 4: the runs are split across the devices.
    sweep, _ = dynax.control.sweep_pgpe(
        dynax.control.PGPE(population_size=4, init_sigma=0.3),
        objective,
        jnp.array([0.2, 0.1]),
        jax.random.split(jax.random.key(3), 2),
        1,
        progress=False,
    )

    # A record of an acrobot under a varying torque, replayed through a model with the wrong
    # damping: the errors are not zero, and 9 windows do not divide among 2 devices (padding).
    true = eqx.tree_at(lambda s: s.theta7, dynax.Acrobot(), 0.3)
    t_rec = jnp.arange(120) * 0.01
    u_rec = jnp.sin(3 * t_rec)[:, None]
    xs = dynax.simulate(true, jnp.array([0.3, 0.1, 0.0, 0.0]), t_rec, u_rec).xs
    record = Trajectory(t_rec, xs, u_rec, true.state_names, true.input_names, "acrobot")
    error = dynax.simulation_error(dynax.Acrobot(), record, (0.1, 0.2), stride=12)

    np.savez(
        out,
        mean=np.asarray(state.mean),
        sigma=np.asarray(state.sigma),
        best=np.asarray(state.best_reward),
        history_reward=np.asarray(history.reward),
        rewards=np.asarray(rewards),
        sweep_mean=np.asarray(sweep.mean),
        rmse=np.asarray(error.rmse),
        errors=np.asarray(error.errors),
        n_windows=error.n_windows,
        process_count=jax.process_count(),
        device_count=jax.device_count(),
    )


if __name__ == "__main__":
    main(sys.argv[1])
