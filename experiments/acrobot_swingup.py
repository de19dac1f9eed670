"""Tune Drake's Spong swing-up controller for the acrobot with PGPE, and go past it.

    python experiments/acrobot_swingup.py --out results/acrobot_swingup           # full (< 30 min, 2 cores)
    python experiments/acrobot_swingup.py --out /tmp/swingup --quick              # test-suite sized

Writes `DIR/results.json` and figures `DIR/*.png`:

1. PGPE from Drake's defaults, every episode from one fixed start (Drake's test start), and
   with random starts within +-0.5 rad of rest per joint; several independent runs each.
   `learning_fixed_start.png`, `learning_random_starts.png`: average reward and swing-up time
   against iteration with 95 % bands over runs, on the training start(s) and on held-out
   random starts (the fixed-start runs overfit: better on their one start, not elsewhere).
2. Baselines on the same held-out random starts: Drake's defaults, scipy Nelder-Mead over the
   same four parameters (same episode budget), evosax's PGPE on the same objective.
3. Past the study: a learned soft hand-over (`SmoothActivation`, temperature tuned with the
   gains), gradient-based tuning by backpropagation through the rollouts, the sampled region
   of attraction of the saturated LQR, and the pipeline identify -> tune -> evaluate on a truth
   with a hidden effect (the elbow motor gives 80 % of the commanded torque; perturbed link 2).

The experiment owns no algorithm: everything comes from `dynax` (its control and identification).
"""

import argparse
import json
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402
import numpy as np  # noqa: E402
import optax  # noqa: E402
import scipy.optimize  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import dynax  # noqa: E402
from dynax.control import (
    CentredRank,
    clipup,
    DRAKE_SPONG_PARAMETERS,
    estimate_region_of_attraction,
    PGPE,
    random_starts,
    RegionSampling,
    run_pgpe,
    SmoothActivation,
    SPONG_PARAMETER_NAMES,
    SpongController,
    sweep_pgpe,
    SwingUpTask,
)

DRAKE_TEST_START = (0.1, -0.1, 0.0, 0.02)
SCALES = np.array(DRAKE_SPONG_PARAMETERS)

CONFIGS = {
    "full": dict(
        runs=8,
        iterations=80,
        population=64,
        duration=20.0,
        rate=100.0,
        held_out=256,
        curve_starts=32,
        eval_every=5,
        nm_evals=160,
        nm_starts=32,
        soft_iterations=80,
        grad_steps=40,
        grad_batch=8,
        roa_directions=128,
        pipeline_iterations=60,
        pipeline_runs=4,
        excitation_s=30.0,
    ),
    "quick": dict(
        runs=2,
        iterations=3,
        population=8,
        duration=4.0,
        rate=50.0,
        held_out=8,
        curve_starts=4,
        eval_every=1,
        nm_evals=6,
        nm_starts=2,
        soft_iterations=2,
        grad_steps=2,
        grad_batch=2,
        roa_directions=4,
        pipeline_iterations=2,
        pipeline_runs=1,
        excitation_s=4.0,
    ),
}


def log(message):
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


def f32(tree):
    return jax.tree.map(lambda a: a.astype(jnp.float32) if eqx.is_inexact_array(a) else a, tree)


def ci95(samples, axis=0):
    """Mean and the half-width of a normal 95 % confidence interval of the mean over `axis`."""
    samples = np.asarray(samples, float)
    n = samples.shape[axis]
    mean = samples.mean(axis)
    half = 1.96 * samples.std(axis, ddof=1) / np.sqrt(n) if n > 1 else np.zeros_like(mean)
    return mean, half


def params_dict(params):
    return {name: float(v) for name, v in zip(SPONG_PARAMETER_NAMES, np.asarray(params))}


def summary(evaluation, params=None, **extra):
    out = {
        "success_rate": float(evaluation["success_rate"]),
        "mean_time_s": float(evaluation["mean_time_s"]),
        "reward": float(evaluation["reward"]),
    }
    if params is not None:
        out = {"params": params_dict(params), **out}
    return {**out, **extra}


def pgpe_strategy(cfg, n_params=4, scales=SCALES):
    return PGPE(
        population_size=cfg["population"],
        scales=jnp.asarray(scales, jnp.float32),
        init_sigma=0.1,
        optimizer=clipup(0.02, max_speed=0.04),
        fitness_shaping=CentredRank(),
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--quick", action="store_true", help="tiny sizes for the test suite")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--all",
        action="store_true",
        help="with --quick, also run the parts past the study (ROA, soft hand-over, "
        "gradient tuning, identification pipeline)",
    )
    args = parser.parse_args(argv)
    cfg = CONFIGS["quick" if args.quick else "full"]
    args.out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    key = jax.random.PRNGKey(args.seed)
    k_train, k_held, k_curve, k_nm, k_evosax, k_soft, k_grad, k_roa, k_pipe = jax.random.split(key, 9)

    nominal = dynax.Acrobot()
    template = f32(SpongController(nominal))  # LQR solved in float64, then cast
    plant = f32(nominal)
    drake = jnp.asarray(DRAKE_SPONG_PARAMETERS, jnp.float32)
    fixed_start = jnp.asarray(DRAKE_TEST_START, jnp.float32)
    common = dict(duration=cfg["duration"], control_rate=cfg["rate"])
    task_fixed = SwingUpTask(plant, template, start=fixed_start, **common)
    task_random = SwingUpTask(plant, template, **common)
    held_out = random_starts(k_held, cfg["held_out"], dtype=jnp.float32)
    curve_starts = random_starts(k_curve, cfg["curve_starts"], dtype=jnp.float32)
    evaluate = eqx.filter_jit(lambda task, p, starts: task.evaluate(p, starts))
    evaluate_many = eqx.filter_jit(lambda task, ps, starts: jax.vmap(lambda p: task.evaluate(p, starts))(ps))
    results = {"config": {**cfg, "mode": "quick" if args.quick else "full", "seed": args.seed}}

    # ------------------------------------------------------------------ Drake's defaults
    results["drake_defaults"] = summary(evaluate(task_random, drake, held_out), drake)
    fixed_default = evaluate(task_fixed, drake, fixed_start[None])
    results["drake_defaults"]["fixed_start_time_s"] = float(fixed_default["mean_time_s"])
    log(f"Drake defaults on held-out starts: {results['drake_defaults']}")

    # ------------------------------------------------------------------ PGPE, two regimes
    pgpe = pgpe_strategy(cfg)
    run_keys = jax.random.split(k_train, cfg["runs"])
    checkpoints = np.arange(0, cfg["iterations"] + 1, cfg["eval_every"])
    curves = {}
    for regime, task in (("fixed_start", task_fixed), ("random_starts", task_random)):
        t0 = time.perf_counter()
        states, history = sweep_pgpe(pgpe, task, drake, run_keys, cfg["iterations"])
        jax.block_until_ready(history.reward)
        wall = time.perf_counter() - t0
        final = jax.vmap(pgpe.mean_params)(states)
        log(f"PGPE {regime}: {cfg['runs']} runs x {cfg['iterations']} iterations x {cfg['population']} in {wall:.1f} s")
        # Learning curves of the mean parameters: on the training start(s) and on held-out starts.
        trace = jnp.concatenate([history.mean_params, final[:, None]], axis=1)[:, checkpoints]  # (runs, K, 4)
        flat = trace.reshape(-1, 4)
        on_fixed = evaluate_many(task_fixed, flat, fixed_start[None])
        on_random = evaluate_many(task_random, flat, curve_starts)
        shape = trace.shape[:2]
        curves[regime] = dict(
            iterations=checkpoints.tolist(),
            train_reward=np.asarray(history.reward),  # (runs, iterations) population average
            fixed_reward=np.asarray(on_fixed["reward"]).reshape(shape),
            fixed_time=np.asarray(on_fixed["mean_time_s"]).reshape(shape),
            random_reward=np.asarray(on_random["reward"]).reshape(shape),
            random_time=np.asarray(on_random["mean_time_s"]).reshape(shape),
        )
        # Per-run held-out performance of the final means; the reported parameters are the run that
        # did best on its own training objective (no selection on the held-out starts).
        per_run = evaluate_many(task_random, final, held_out)
        train_score = curves[regime]["fixed_reward" if regime == "fixed_start" else "random_reward"][:, -1]
        chosen = int(np.argmax(train_score))
        sr_mean, sr_half = ci95(per_run["success_rate"])
        t_mean, t_half = ci95(per_run["mean_time_s"])
        results[f"pgpe_{regime}"] = summary(
            jax.tree.map(lambda a: a[chosen], per_run),
            final[chosen],
            fixed_start_time_s=float(curves[regime]["fixed_time"][chosen, -1]),
            chosen_run=chosen,
            runs=dict(
                success_rate=np.asarray(per_run["success_rate"]).tolist(),
                mean_time_s=np.asarray(per_run["mean_time_s"]).tolist(),
                success_rate_mean_ci95=[float(sr_mean), float(sr_half)],
                mean_time_s_mean_ci95=[float(t_mean), float(t_half)],
                params=[params_dict(p) for p in final],
            ),
            wall_time_s=wall,
        )
        log(
            f"PGPE {regime} held-out: {results[f'pgpe_{regime}']['success_rate']:.3f} success, "
            f"{results[f'pgpe_{regime}']['mean_time_s']:.2f} s; over runs {sr_mean:.3f} +- {sr_half:.3f}"
        )
    plot_learning(curves, results, cfg, args.out)

    # ------------------------------------------------------------------ Nelder-Mead (scipy)
    nm_starts = random_starts(k_nm, cfg["nm_starts"], dtype=jnp.float32)
    nm_objective = eqx.filter_jit(
        lambda task, z: task.evaluate(z * jnp.asarray(SCALES, jnp.float32), nm_starts)["reward"]
    )
    nm_objective(task_random, jnp.ones(4, jnp.float32)).block_until_ready()  # compile outside the timing
    t0 = time.perf_counter()
    nm = scipy.optimize.minimize(
        lambda z: -float(nm_objective(task_random, jnp.asarray(z, jnp.float32))),
        np.ones(4),
        method="Nelder-Mead",
        options=dict(maxfev=cfg["nm_evals"], initial_simplex=np.vstack([np.ones(4), np.ones(4) + 0.1 * np.eye(4)])),
    )
    wall = time.perf_counter() - t0
    nm_params = jnp.asarray(nm.x * SCALES, jnp.float32)
    results["nelder_mead"] = summary(
        evaluate(task_random, nm_params, held_out),
        nm_params,
        wall_time_s=wall,
        evaluations=int(nm.nfev),
        episodes=int(nm.nfev) * cfg["nm_starts"],
    )
    log(f"Nelder-Mead: {results['nelder_mead']}")

    # ------------------------------------------------------------------ evosax PGPE, same objective
    results["evosax_pgpe"], results["pgpe_single_run_wall_time_s"] = evosax_baseline(
        cfg, task_random, drake, pgpe, k_evosax, held_out, evaluate
    )
    log(f"evosax PGPE: {results['evosax_pgpe']}")

    # ------------------------------------------------------------------ past the study
    if not args.quick or args.all:
        results["region_of_attraction"] = region_of_attraction(cfg, template, plant, k_roa)
        log(f"sampled region of attraction of the saturated LQR: rho = {results['region_of_attraction']['rho']:.3g}")
        results["soft_handover"] = soft_handover(cfg, template, plant, k_soft, held_out, curve_starts, run_keys)
        log(f"learned soft hand-over: {results['soft_handover']}")
        results["gradient_tuning"] = gradient_tuning(cfg, template, plant, k_grad, held_out, evaluate)
        log(f"gradient tuning through rollouts: {results['gradient_tuning']}")
        results["pipeline"] = pipeline(cfg, k_pipe, held_out, results["pgpe_random_starts"]["params"])
        log(f"identify -> tune -> truth: {results['pipeline']}")

    plot_baselines(results, args.out)
    results["total_wall_time_s"] = time.perf_counter() - t_start
    results["figures"] = sorted(p.name for p in args.out.glob("*.png"))
    with open(args.out / "results.json", "w") as f:
        json.dump(results, f, indent=2)
    log(f"wrote {args.out / 'results.json'} in {results['total_wall_time_s']:.0f} s")
    return 0


def evosax_baseline(cfg, task, start, pgpe, key, held_out, evaluate):
    """evosax's PGPE (centred ranks, ClipUp) on the same objective, against dynax's one run, same sizes."""
    from evosax.algorithms import PGPE as EvosaxPGPE

    scales = jnp.asarray(SCALES, jnp.float32)
    from evosax.core.optimizer import clipup as evosax_clipup

    # Same settings as dynax's: ClipUp with step 0.02 and max speed 0.04, centred ranks, sigma 0.1.
    es = EvosaxPGPE(
        population_size=cfg["population"],
        solution=jnp.zeros(4, jnp.float32),
        optimizer=evosax_clipup(learning_rate=0.02, max_velocity=0.04),
    )
    es_params = es.default_params.replace(std_init=0.1)
    pairs = cfg["population"] // 2

    @jax.jit
    def evosax_run(key):
        state = es.init(key, start / scales, es_params)

        def generation(state, key):
            k_ask, k_ep, k_tell = jax.random.split(key, 3)
            population, state = es.ask(k_ask, state, es_params)
            pair_keys = jax.random.split(k_ep, pairs)
            rewards = jax.vmap(task)(population * scales, jnp.concatenate([pair_keys, pair_keys]))
            state, _ = es.tell(k_tell, population, -rewards, state, es_params)
            return state, jnp.mean(rewards)

        state, rewards = jax.lax.scan(generation, state, jax.random.split(key, cfg["iterations"]))
        return state.mean * scales, rewards

    dynax_run = eqx.filter_jit(lambda k: run_pgpe(pgpe, task, start, k, cfg["iterations"]))
    jax.block_until_ready(evosax_run(key))
    jax.block_until_ready(dynax_run(key))
    t0 = time.perf_counter()
    mean, rewards = jax.block_until_ready(evosax_run(key))
    evosax_wall = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(dynax_run(key))
    dynax_wall = time.perf_counter() - t0
    out = summary(evaluate(task, mean, held_out), mean, wall_time_s=evosax_wall, final_train_reward=float(rewards[-1]))
    return out, dynax_wall


def region_of_attraction(cfg, template, plant, key):
    roa = eqx.filter_jit(estimate_region_of_attraction)(
        plant,
        template.balance,
        key,
        sampling=RegionSampling(n_directions=cfg["roa_directions"], control_rate=cfg["rate"]),
    )
    return {
        "rho": float(roa.rho),
        "levels": np.asarray(roa.levels).tolist(),
        "converged_fraction": np.asarray(roa.converged_fraction).tolist(),
        "drake_threshold": DRAKE_SPONG_PARAMETERS[3],
    }


class _SoftTask(eqx.Module):
    """The swing-up task with five parameters: the four Spong parameters and log10 of the hand-over temperature."""

    task: SwingUpTask

    def controller_task(self, params):
        soft = SmoothActivation(temperature=10.0 ** params[4])
        return eqx.tree_at(lambda t: t.controller.switching, self.task, soft)

    def __call__(self, params, key):
        return self.controller_task(params)(params[:4], key)

    def evaluate(self, params, starts):
        return self.controller_task(params).evaluate(params[:4], starts)


def soft_handover(cfg, template, plant, key, held_out, curve_starts, run_keys):
    """PGPE on random starts with the learned soft hand-over (temperature tuned with the gains)."""
    soft_template = eqx.tree_at(lambda c: c.switching, template, SmoothActivation(temperature=0.3))
    task = _SoftTask(SwingUpTask(plant, soft_template, duration=cfg["duration"], control_rate=cfg["rate"]))
    start = jnp.array([*DRAKE_SPONG_PARAMETERS, np.log10(0.3)], jnp.float32)
    pgpe = pgpe_strategy(cfg, 5, np.array([*SCALES, 1.0]))
    t0 = time.perf_counter()
    states, _ = sweep_pgpe(pgpe, task, start, run_keys, cfg["soft_iterations"])
    final = jax.vmap(pgpe.mean_params)(states)
    wall = time.perf_counter() - t0
    evaluate_runs = eqx.filter_jit(lambda starts: jax.vmap(lambda p: task.evaluate(p, starts))(final))
    per_run = evaluate_runs(held_out)
    sr_mean, sr_half = ci95(per_run["success_rate"])
    t_mean, t_half = ci95(per_run["mean_time_s"])
    best = int(np.argmax(evaluate_runs(curve_starts)["reward"]))  # chosen on training-like starts, not held-out
    return {
        "params": params_dict(final[best, :4]),
        "temperature": float(10.0 ** final[best, 4]),
        "success_rate": float(per_run["success_rate"][best]),
        "mean_time_s": float(per_run["mean_time_s"][best]),
        "success_rate_mean_ci95": [float(sr_mean), float(sr_half)],
        "mean_time_s_mean_ci95": [float(t_mean), float(t_half)],
        "runs_success_rate": np.asarray(per_run["success_rate"]).tolist(),
        "wall_time_s": wall,
    }


def gradient_tuning(cfg, template, plant, key, held_out, evaluate):
    """Adam on the four parameters, backpropagating through the rollouts (soft hand-over so phi has a gradient)."""
    soft_template = eqx.tree_at(lambda c: c.switching, template, SmoothActivation(temperature=0.3))
    task = SwingUpTask(plant, soft_template, duration=cfg["duration"], control_rate=cfg["rate"])
    scales = jnp.asarray(SCALES, jnp.float32)
    optimiser = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(0.02))

    def loss(z, key):
        starts = random_starts(key, cfg["grad_batch"], dtype=jnp.float32)
        return -jnp.mean(jax.vmap(lambda x0: dynax.control.swing_up_reward(task.rollout(z * scales, x0)))(starts))

    @eqx.filter_jit
    def step(z, opt_state, key):
        value, grad = jax.value_and_grad(loss)(z, key)
        grad = jnp.where(jnp.isfinite(grad), grad, 0.0)
        updates, opt_state = optimiser.update(grad, opt_state, z)
        return optax.apply_updates(z, updates), opt_state, value, jnp.linalg.norm(grad)

    z = jnp.ones(4, jnp.float32)
    opt_state = optimiser.init(z)
    losses, norms = [], []
    t0 = time.perf_counter()
    for k in jax.random.split(key, cfg["grad_steps"]):
        z, opt_state, value, norm = step(z, opt_state, k)
        losses.append(float(value))
        norms.append(float(norm))
    wall = time.perf_counter() - t0
    params = z * scales
    return summary(task.evaluate(params, held_out), params, wall_time_s=wall, train_loss=losses, gradient_norm=norms)


def pipeline(cfg, key, held_out, tuned_on_nominal):
    """Identify the acrobot from data with a hidden effect, tune on the identified model, evaluate on the truth."""
    from dynax import identify, Power

    truth_core = dynax.Acrobot.from_physical(m2=1.15, lc2=0.95, b2=0.15)
    # The hidden effect: the elbow motor delivers only 80 % of the commanded torque.
    truth = dynax.Extended(truth_core, (dynax.InputGain(0, 0.8),))
    # Excitation: a multisine elbow torque, recorded at 100 Hz with small sensor noise.
    dt = 0.01
    ts = jnp.arange(int(cfg["excitation_s"] / dt) + 1) * dt
    k_noise, k_phase, k_tune = jax.random.split(key, 3)
    freqs = jnp.array([0.2, 0.45, 0.7, 1.1, 1.6])
    phases = jax.random.uniform(k_phase, freqs.shape) * 2 * jnp.pi
    us = (1.5 * jnp.sin(2 * jnp.pi * freqs[None] * ts[:, None] + phases).sum(1))[:, None]
    sim = dynax.simulate(truth, jnp.array([0.2, -0.3, 0.0, 0.0]), ts, us)
    xs = sim.xs + 1e-4 * jax.random.normal(k_noise, sim.xs.shape)
    record = dynax.Trajectory(ts, xs, us, ("q1", "q2", "dq1", "dq2"), ("tau2",), system="acrobot")
    # A torque gain g is indistinguishable from dividing every base parameter by g: the power
    # model identifies the truth in the units of the commanded torque, which is what the
    # controller needs.
    fit = identify(dynax.Acrobot(), record, Power(), refine=False, validation=dynax.Validate(holdout=0))
    identified_core = fit.system

    truth32 = f32(truth)
    nominal_template = f32(SpongController(dynax.Acrobot()))
    identified_template = f32(SpongController(identified_core))
    common = dict(duration=cfg["duration"], control_rate=cfg["rate"])
    on_truth_nominal = SwingUpTask(truth32, nominal_template, **common)
    on_truth_identified = SwingUpTask(truth32, identified_template, **common)
    tune_task = SwingUpTask(f32(identified_core), identified_template, **common)
    drake = jnp.asarray(DRAKE_SPONG_PARAMETERS, jnp.float32)
    pgpe = pgpe_strategy(cfg)
    keys = jax.random.split(k_tune, cfg["pipeline_runs"])
    states, _ = sweep_pgpe(pgpe, tune_task, drake, keys, cfg["pipeline_iterations"])
    finals = jax.vmap(pgpe.mean_params)(states)
    on_identified = eqx.filter_jit(jax.vmap(lambda p: tune_task.evaluate(p, held_out)))(finals)
    chosen = int(np.argmax(on_identified["reward"]))  # selected on the identified model, not on the truth
    tuned = finals[chosen]
    evaluate = eqx.filter_jit(lambda task, p: task.evaluate(p, held_out))
    nominal_tuned = jnp.asarray([tuned_on_nominal[n] for n in SPONG_PARAMETER_NAMES], jnp.float32)
    return {
        "truth": {"physical": {"m2": 1.15, "lc2": 0.95, "b2": 0.15}, "hidden": "input_gain@tau2", "gain": 0.8},
        "identified": {k: float(v) for k, v in fit.parameters.items()},
        "truth_base_parameters_over_gain": {k: float(v) / 0.8 for k, v in truth_core.base_parameters.items()},
        "drake_defaults_nominal_model_on_truth": summary(evaluate(on_truth_nominal, drake)),
        "pgpe_tuned_on_nominal_on_truth": summary(evaluate(on_truth_nominal, nominal_tuned), nominal_tuned),
        "drake_defaults_identified_model_on_truth": summary(evaluate(on_truth_identified, drake)),
        "pgpe_tuned_on_identified_on_truth": summary(evaluate(on_truth_identified, tuned), tuned),
        "pgpe_tuned_on_identified_on_identified": summary(jax.tree.map(lambda a: a[chosen], on_identified)),
    }


def plot_learning(curves, results, cfg, out):
    titles = {
        "fixed_start": "(a) PGPE, every episode from one fixed start",
        "random_starts": "(b) PGPE, random starts within ±0.5 rad of rest",
    }
    for regime, c in curves.items():
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
        it_all = np.arange(c["train_reward"].shape[1])
        m, h = ci95(c["train_reward"])
        axes[0].plot(it_all, m, color="C0", label="population average (training)")
        axes[0].fill_between(it_all, m - h, m + h, color="C0", alpha=0.25)
        for name, colour, label in (
            ("fixed", "C1", "mean params, fixed start"),
            ("random", "C2", "mean params, held-out random starts"),
        ):
            m, h = ci95(c[f"{name}_reward"])
            axes[0].plot(c["iterations"], m, color=colour, label=label)
            axes[0].fill_between(c["iterations"], m - h, m + h, color=colour, alpha=0.25)
            m, h = ci95(c[f"{name}_time"])
            axes[1].plot(c["iterations"], m, color=colour, label=label)
            axes[1].fill_between(c["iterations"], m - h, m + h, color=colour, alpha=0.25)
        axes[1].axhline(
            results["drake_defaults"]["mean_time_s"], color="k", ls="--", lw=1, label="Drake defaults, held-out"
        )
        axes[0].set(xlabel="PGPE iteration", ylabel="average reward", title=titles[regime])
        axes[1].set(
            xlabel="PGPE iteration",
            ylabel="swing-up time [s] (failure = episode length)",
            title=f"{cfg['runs']} runs, 95 % bands",
        )
        for ax in axes:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / f"learning_{regime}.png", dpi=120)
        plt.close(fig)


def plot_baselines(results, out):
    names = [
        ("drake_defaults", "Drake defaults"),
        ("pgpe_fixed_start", "PGPE fixed start"),
        ("pgpe_random_starts", "PGPE random starts"),
        ("nelder_mead", "Nelder-Mead"),
        ("evosax_pgpe", "evosax PGPE"),
        ("gradient_tuning", "backprop (Adam)"),
    ]
    names = [(k, label) for k, label in names if k in results]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    x = np.arange(len(names))
    axes[0].bar(x, [results[k]["success_rate"] for k, _ in names], color="C0")
    axes[1].bar(x, [results[k]["mean_time_s"] for k, _ in names], color="C1")
    axes[0].set(ylabel="success rate (held-out random starts)", ylim=(0, 1))
    axes[1].set(ylabel="mean swing-up time [s]")
    for ax in axes:
        ax.set_xticks(x, [label for _, label in names], rotation=30, ha="right", fontsize=8)
        ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(out / "baselines.png", dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
