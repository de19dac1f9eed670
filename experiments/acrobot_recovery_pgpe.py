"""Tune the from-rest controller's feedback by PGPE over randomised plants, noise, delays and pulses.

    python experiments/acrobot_recovery_pgpe.py [--policy P.npz] [--generations 16] [--population 16]

The reference of the saved controller stays; PGPE (`dynax.control.PGPE`, the population `vmap`ped)
tunes the feedback around it: the balancing LQR's weights, the cost-to-go threshold below which it
acts, Spong's energy-shaping recovery gains and the time-varying LQR's weights (12 numbers, searched
in logarithms), starting from `SwingUpDesign()`'s defaults. Each candidate is scored on a batch of training episodes
drawn afresh every generation from the six families of the rules (a model parameter off by up to 25 %, velocity and
torque noise, a slow motor, a measurement delay, and random torque pulses drawn with another seed
than the benchmark's), by a smooth success: $\\exp(-\\|e / tol\\|^2)$ of the final error. The mean of
the search is scored by the exact rules (performance and robustness) at the end and saved when it
is at least as good on both; results in `experiments/results/leaderboard/recovery_pgpe/`.
"""

import argparse
import json
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
import dynax
from dynax import control
from dynax.control import balance_lqr, tvlqr
from dynax.internal import leaderboard_rollout

OUT = pathlib.Path(__file__).resolve().parent / "results" / "leaderboard" / "recovery_pgpe"
POLICY = pathlib.Path(__file__).resolve().parent / "results" / "leaderboard" / "acrobot_policy.npz"


def training_bank(n_pulses=200, seed=7):
    """Training episodes: the rules' families with the pulses drawn from another seed than the benchmark's."""
    rules = control.LeaderboardRules(seed=seed, n_sizes=11, repetitions=2, pulse_runs=n_pulses)
    return control.robustness_cases(rules)


def unpack(theta, base, plant, dt):
    q_bal = jnp.exp(theta[0:4])
    r_bal = jnp.exp(theta[4])
    threshold = jnp.exp(theta[5])
    swing = jnp.exp(theta[6:9])
    q_track = jnp.exp(theta[9:11])
    r_track = jnp.exp(theta[11])
    k_bal, s_bal = balance_lqr(plant, q_bal, r_bal, dt)
    qt = jnp.stack([q_track[0], q_track[0], q_track[1], q_track[1]])
    gains = tvlqr(plant, base.x_ref, base.u_ref, qt, r_track, s_bal, dt)
    return eqx.tree_at(
        lambda c: (c.k_balance, c.s_balance, c.threshold, c.swing_up, c.gains),
        base,
        (k_bal, s_bal, threshold, swing, gains),
    )


def initial_theta(design):
    return np.log(
        np.concatenate(
            [
                design.q_balance,
                [design.r_balance, design.threshold],
                design.swing_up,
                [design.q_track[0], design.q_track[2], design.r_track],
            ]
        )
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--policy", default=str(POLICY))
    parser.add_argument("--generations", type=int, default=16)
    parser.add_argument("--population", type=int, default=16)
    parser.add_argument("--episodes", type=int, default=24, help="training episodes per generation")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sigma", type=float, default=0.3, help="initial exploration width (in logarithms)")
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rules = control.LeaderboardRules()
    plant = control.LeaderboardPlant.nominal()
    base = dynax.control.load_controller(args.policy).to_benchmark()
    design = control.SwingUpDesign()
    bank = training_bank()
    # half the episodes from the pulse runs (the weakest family), half from the other families
    pulse_idx = np.flatnonzero(bank.family == 5)
    other_idx = np.flatnonzero(bank.family != 5)
    tol = jnp.asarray(rules.tolerance)
    x0 = jnp.zeros(4)

    def episodes(key):
        k1, k2 = jax.random.split(key)
        n = args.episodes // 2
        i = jnp.concatenate(
            [
                jax.random.choice(k1, jnp.asarray(pulse_idx), (n,), replace=False),
                jax.random.choice(k2, jnp.asarray(other_idx), (args.episodes - n,), replace=False),
            ]
        )
        return jax.tree.map(lambda a: a[i], bank.cases)

    def reward(theta, cases):
        c = unpack(theta, base, plant, rules.dt)
        final = jax.vmap(
            lambda case: leaderboard_rollout(c, case, x0, rules.dt, rules.n_steps, rules.max_delay_steps, False)[0]
        )(cases)
        e1 = jnp.mod(final[:, 0], 2 * jnp.pi) - jnp.pi
        e2 = jnp.mod(final[:, 1] + jnp.pi, 2 * jnp.pi) - jnp.pi
        err = jnp.stack([e1, e2, final[:, 2], final[:, 3]], axis=1) / tol
        err = jnp.where(jnp.isfinite(err), err, 10.0)
        return jnp.mean(jnp.exp(-jnp.sum(err**2, axis=1)))

    pgpe = control.PGPE(args.population, init_sigma=args.sigma, optimizer=__import__("optax").adam(0.1))

    @eqx.filter_jit
    def generation(state, key):
        k_ask, k_ep = jax.random.split(key)
        params, noise = pgpe.ask(state, k_ask)
        cases = episodes(k_ep)
        rewards = jax.vmap(lambda p: reward(p, cases))(params)
        return pgpe.tell(state, noise, rewards), jnp.mean(rewards), jnp.max(rewards)

    theta0 = jnp.asarray(initial_theta(design))
    state = pgpe.init(theta0)
    key = jax.random.key(args.seed)
    history = []
    start = time.perf_counter()
    for g in range(args.generations):
        key, sub = jax.random.split(key)
        state, mean_r, max_r = generation(state, sub)
        history.append(
            {
                "generation": g,
                "mean_reward": float(mean_r),
                "max_reward": float(max_r),
                "seconds": time.perf_counter() - start,
            }
        )
        print(
            f"generation {g}: mean reward {float(mean_r):.3f}, best {float(max_r):.3f} "
            f"[{time.perf_counter() - start:.0f} s]",
            flush=True,
        )
    tuning_s = time.perf_counter() - start
    theta = pgpe.mean_params(state)
    tuned = unpack(theta, base, plant, rules.dt)
    results = {
        "tuning_s": tuning_s,
        "history": history,
        "settings": vars(args),
        "initial": np.exp(np.asarray(theta0)).tolist(),
        "theta": dict(
            zip(
                ["q1", "q2", "dq1", "dq2", "r", "threshold", "k_e", "k_p", "k_d", "q_track", "dq_track", "r_track"],
                np.exp(np.asarray(theta)).tolist(),
            )
        ),
    }
    for name, c in (("before", base), ("after", tuned)):
        perf = control.performance(c)
        rob = control.robustness(c)
        results[name] = {"performance": float(perf.score), "robustness": rob.score, "families": rob.table()}
        print(name, results[name], flush=True)
    tuned.save(out / "tuned_policy.npz")
    (out / "pgpe.json").write_text(json.dumps(results, indent=2, default=float))
    print(f"wrote {out}", flush=True)


if __name__ == "__main__":
    main()
