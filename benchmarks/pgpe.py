"""One PGPE generation on the acrobot swing-up: dynax vs evosax vs sharded dynax vs numpy.

    XLA_FLAGS=--xla_force_host_platform_device_count=2 python benchmarks/pgpe.py [--out FILE.json]

A generation is: sample a population of 256 around Drake's Spong parameters, run every
member's 20 s episode at 100 Hz with the Spong controller in the loop (Tsit5, 2 steps per
control interval, float32), and update the search distribution. Timed side by side in one
process:

- `dynax`: `PGPE.ask` + `evaluate_population` + `PGPE.tell`, one jitted function, one device;
- `evosax`: evosax's PGPE with the same rollout function, one device;
- `dynax_sharded`: as `dynax`, the population split across all devices with `jax.sharding`;
- `numpy`: the same generation in numpy, vectorised over the population (the way a scipy-based
  study would run it), with the same integrator and controller.

The JAX contenders are timed interleaved, `--repeats` rounds after a warm-up (compilation
excluded); median and minimum are reported. Without the XLA flag there is one CPU device and the
sharded row is skipped.
"""

import argparse
import json
import os
import sys
import time

from _device import describe, device_info
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import dynax
from dynax.control import (
    CentredRank,
    clipup,
    DRAKE_SPONG_PARAMETERS,
    evaluate_population,
    PGPE,
    random_starts,
    SpongController,
    SwingUpTask,
)

POPULATION = 256
DURATION = 20.0
RATE = 100.0


def f32(tree):
    return jax.tree.map(lambda a: a.astype(jnp.float32) if eqx.is_inexact_array(a) else a, tree)


# ---------------------------------------------------------------- numpy reference


class NumpySwingUp:
    """The Spong controller and the acrobot in numpy, vectorised over a population (float32)."""

    def __init__(self, controller: SpongController, plant: dynax.Acrobot, dtype=np.float32):
        p = {k: np.asarray(v, dtype) for k, v in plant.base_parameters.items()}
        c = {k: np.asarray(v, dtype) for k, v in controller.system.base_parameters.items()}
        self.p, self.c, self.dtype = p, c, dtype
        self.gain = np.asarray(controller.balance.gain, dtype)[0]
        self.s = np.asarray(controller.balance.cost_to_go_matrix, dtype)
        self.limit = dtype(controller.torque_limit)

    @staticmethod
    def _mass_bias(p, q1, q2, dq1, dq2):
        c2, s1, s2, s12 = np.cos(q2), np.sin(q1), np.sin(q2), np.sin(q1 + q2)
        m11 = p["theta1"] + p["theta2"] + 2 * p["theta3"] * c2
        m12 = p["theta2"] + p["theta3"] * c2
        m22 = p["theta2"] + 0 * c2
        h1 = (
            -2 * p["theta3"] * s2 * dq2 * dq1
            - p["theta3"] * s2 * dq2**2
            + p["theta4"] * s1
            + p["theta5"] * s12
            + p["theta6"] * dq1
        )
        h2 = p["theta3"] * s2 * dq1**2 + p["theta5"] * s12 + p["theta7"] * dq2
        return m11, m12, m22, h1, h2

    def control(self, x, params):
        q1, q2, dq1, dq2 = x
        k_e, k_p, k_d, phi = params.T
        e = np.stack([np.mod(q1 - np.pi + np.pi, 2 * np.pi) - np.pi, np.mod(q2 + np.pi, 2 * np.pi) - np.pi, dq1, dq2])
        cost = np.einsum("ip,ij,jp->p", e, self.s, e)
        u_lqr = -self.gain @ e
        m11, m12, m22, h1, h2 = self._mass_bias(self.c, q1, q2, dq1, dq2)
        det = m11 * m22 - m12 * m12
        a2, a3 = -m12 / det, m11 / det
        energy = (
            0.5 * (m11 * dq1**2 + 2 * m12 * dq1 * dq2 + m22 * dq2**2)
            - self.c["theta4"] * np.cos(q1)
            - self.c["theta5"] * np.cos(q1 + q2)
        )
        u_e = -k_e * (energy - (self.c["theta4"] + self.c["theta5"])) * dq2
        y = -k_p * q2 - k_d * dq2
        u_p = (a2 * h1 + y) / a3 + h2
        u = np.where(cost < phi, u_lqr, u_e + u_p)
        return np.clip(u, -self.limit, self.limit)

    def vector_field(self, x, u):
        q1, q2, dq1, dq2 = x
        m11, m12, m22, h1, h2 = self._mass_bias(self.p, q1, q2, dq1, dq2)
        det = m11 * m22 - m12 * m12
        r1, r2 = -h1, u - h2
        return np.stack([dq1, dq2, (m22 * r1 - m12 * r2) / det, (m11 * r2 - m12 * r1) / det])

    # Tsit5 tableau (Tsitouras 2011), as diffrax's Tsit5.
    _A = [
        [],
        [0.161],
        [-0.008480655492356989, 0.335480655492357],
        [2.897153057105493, -6.359448489975075, 4.3622954328695815],
        [5.325864828439257, -11.748883564062828, 7.4955393428898365, -0.09249506636175525],
        [5.86145544294642, -12.92096931784711, 8.159367898576159, -0.071584973281401, -0.028269050394068383],
    ]
    _B = [0.09646076681806523, 0.01, 0.4798896504144996, 1.379008574103742, -3.290069515436081, 2.324710524099774]

    def step(self, x, u, h):
        ks = []
        for row in self._A:
            xi = x + h * sum(a * k for a, k in zip(row, ks)) if row else x
            ks.append(self.vector_field(xi, u))
        return x + h * sum(b * k for b, k in zip(self._B, ks))

    def rewards(self, params, x0, duration=DURATION):
        """Episode rewards (`swing_up_reward`) of a population `params (P, 4)` from starts `x0 (P, 4)`."""
        dt = self.dtype(1.0 / RATE)
        steps = int(round(duration * RATE))
        x = x0.T.astype(self.dtype)
        total = np.zeros(params.shape[0], self.dtype)
        for _ in range(steps):
            u = self.control(x, params)
            total += self._cost(x, u)
            for _ in range(2):
                x = self.step(x, u, dt / 2)
        u = self.control(x, params)
        total += self._cost(x, u)
        return -total / (steps + 1)

    @staticmethod
    def _cost(x, u):
        e1 = np.mod(x[0] - np.pi + np.pi, 2 * np.pi) - np.pi
        e2 = np.mod(x[1] + np.pi, 2 * np.pi) - np.pi
        height = (1 - np.cos(e1)) + (1 - np.cos(e1 + e2))
        cost = height + 0.01 * (x[2] ** 2 + x[3] ** 2) + 1e-4 * u**2
        return np.where(np.isfinite(cost), np.minimum(cost, 8.0), 8.0)


def numpy_generation(sim, mean, sigma, scales, rng):
    """One PGPE generation in numpy (symmetric sampling, centred ranks, plain gradient step)."""
    pairs = POPULATION // 2
    noise = sigma * rng.standard_normal((pairs, 4)).astype(np.float32)
    z = np.concatenate([mean + noise, mean - noise])
    x0 = np.zeros((pairs, 4), np.float32)
    x0[:, :2] = rng.uniform(-0.5, 0.5, (pairs, 2))
    rewards = sim.rewards(z * scales, np.concatenate([x0, x0]))
    ranks = np.argsort(np.argsort(rewards)) / (POPULATION - 1) - 0.5
    grad = (ranks[:pairs] - ranks[pairs:]) @ noise / pairs
    return mean + 0.02 * grad / (np.linalg.norm(grad) + 1e-12), rewards


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--numpy-repeats", type=int, default=1)
    parser.add_argument("--out", default=None, help="write the timings as JSON here")
    args = parser.parse_args(argv)

    devices = jax.devices()
    print(
        f"devices: {len(devices)} x {devices[0].device_kind}; XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}", flush=True
    )
    print(describe(device_info()), flush=True)
    jax.config.update("jax_enable_x64", True)
    controller = f32(SpongController())  # LQR in float64, then float32
    plant = f32(dynax.Acrobot())
    task = SwingUpTask(plant, controller, duration=DURATION, control_rate=RATE)
    scales = jnp.asarray(DRAKE_SPONG_PARAMETERS, jnp.float32)
    start = scales
    pgpe = PGPE(
        population_size=POPULATION,
        scales=scales,
        init_sigma=0.1,
        optimizer=clipup(0.02, max_speed=0.04),
        fitness_shaping=CentredRank(),
    )
    state = pgpe.init(start)
    pairs = POPULATION // 2

    def dynax_generation(state, key, shard):
        k_ask, k_ep = jax.random.split(key)
        population, noise = pgpe.ask(state, k_ask)
        pair_keys = jax.random.split(k_ep, pairs)
        rewards = evaluate_population(task, population, jnp.concatenate([pair_keys, pair_keys]), shard=shard)
        return pgpe.tell(state, noise, rewards), rewards

    key = jax.random.PRNGKey(0)
    results = {
        "population": POPULATION,
        "episode_s": DURATION,
        "control_hz": RATE,
        "devices": len(devices),
        "device": device_info(),
    }
    single = eqx.filter_jit(lambda s, k: dynax_generation(s, k, False))

    from evosax.algorithms import PGPE as EvosaxPGPE
    from evosax.core.optimizer import clipup as evosax_clipup

    # Same settings as dynax's: ClipUp with step 0.02 and max speed 0.04, centred ranks, sigma 0.1.
    es = EvosaxPGPE(
        population_size=POPULATION,
        solution=jnp.zeros(4, jnp.float32),
        optimizer=evosax_clipup(learning_rate=0.02, max_velocity=0.04),
    )
    es_params = es.default_params.replace(std_init=0.1)
    es_state = es.init(key, start / scales, es_params)

    @jax.jit
    def evosax_generation(es_state, key):
        k_ask, k_ep, k_tell = jax.random.split(key, 3)
        population, es_state = es.ask(k_ask, es_state, es_params)
        pair_keys = jax.random.split(k_ep, pairs)
        rewards = jax.vmap(task)(population * scales, jnp.concatenate([pair_keys, pair_keys]))
        es_state, _ = es.tell(k_tell, population, -rewards, es_state, es_params)
        return es_state, rewards

    contenders = {"dynax": lambda: single(state, key), "evosax": lambda: evosax_generation(es_state, key)}
    if len(devices) > 1:
        sharded = eqx.filter_jit(lambda s, k: dynax_generation(s, k, True))
        _, rewards = sharded(state, key)
        results["sharded_devices"] = len(rewards.sharding.device_set)
        contenders["dynax_sharded"] = lambda: sharded(state, key)
    else:
        print("dynax, sharded: skipped (one device; set XLA_FLAGS=--xla_force_host_platform_device_count=2)")
    # Interleave the contenders so that a change in machine load affects them alike; report the
    # median and the minimum (the least-disturbed run) of each.
    for fn in contenders.values():
        jax.block_until_ready(fn())  # compile
    times = {name: [] for name in contenders}
    for _ in range(args.repeats):
        for name, fn in contenders.items():
            t0 = time.perf_counter()
            jax.block_until_ready(fn())
            times[name].append(time.perf_counter() - t0)
    for name, ts in times.items():
        results[f"{name}_s"] = float(np.median(ts))
        results[f"{name}_min_s"] = float(np.min(ts))
        results[f"{name}_all_s"] = ts
        print(
            f"{name:14s} {results[f'{name}_s']:.3f} s / generation (median), {results[f'{name}_min_s']:.3f} s (min)",
            flush=True,
        )
    if "dynax_sharded" in times:
        results["sharding_speedup"] = results["dynax_s"] / results["dynax_sharded_s"]
        results["sharding_speedup_min"] = results["dynax_min_s"] / results["dynax_sharded_min_s"]
        print(
            f"sharding speedup: {results['sharding_speedup']:.2f}x (median), {results['sharding_speedup_min']:.2f}x "
            "(min)"
        )

    sim = NumpySwingUp(controller, plant)
    rng = np.random.default_rng(0)
    mean = np.asarray(start / scales)
    times = []
    for _ in range(args.numpy_repeats):
        t0 = time.perf_counter()
        _, numpy_rewards = numpy_generation(sim, mean, 0.1, np.asarray(scales), rng)
        times.append(time.perf_counter() - t0)
    results["numpy_s"] = float(np.median(times))
    results["numpy_over_dynax"] = results["numpy_s"] / results["dynax_s"]
    results["numpy_over_dynax_min"] = results["numpy_s"] / results["dynax_min_s"]
    results["evosax_over_dynax"] = results["evosax_s"] / results["dynax_s"]
    print(f"numpy          {results['numpy_s']:.3f} s / generation ({results['numpy_over_dynax']:.1f}x dynax's median)")
    # Cross-check: numpy and dynax give the same episode rewards for the same members and starts,
    # over 1 s episodes (longer swing-ups are chaotic, so float32 rounding differences grow).
    x0 = random_starts(jax.random.PRNGKey(5), 8, dtype=jnp.float32)
    params = jnp.tile(start, (8, 1)) * (1 + 0.05 * jax.random.normal(jax.random.PRNGKey(6), (8, 4)))
    short = SwingUpTask(plant, controller, duration=1.0, control_rate=RATE)
    via_jax = jax.jit(jax.vmap(lambda p, x: dynax.control.swing_up_reward(short.rollout(p, x))))(params, x0)
    via_numpy = sim.rewards(np.asarray(params), np.asarray(x0), duration=1.0)
    results["numpy_vs_dynax_reward_max_abs_diff"] = float(np.max(np.abs(np.asarray(via_jax) - via_numpy)))
    print(
        "reward agreement numpy vs dynax (8 episodes of 1 s): max |diff| = "
        f"{results['numpy_vs_dynax_reward_max_abs_diff']:.2e}"
    )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
