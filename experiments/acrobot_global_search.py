"""A global search for the acrobot's swing-up from rest against the leaderboard's whole score.

    python experiments/acrobot_global_search.py [--from POLICY|none] [--starts 16] [--sigma 0.3]
        [--horizons 2.0] [--feasibility 80] [--iterations 400] [--seed 0] [--keep 16] [--top 3] [--out DIR]

The reference searched: piecewise-linear elbow torque knots 20 ms apart (zero at the start,
`6 tanh(w)` within the limit) from rest to upright at rest with zero torque at the horizon, where
the balancing LQR takes over (the hand-over constraint). The starts, per horizon, all in one
`vmap`: a saved controller's reference stretched to the horizon (`--from`; the saved policy by
default) and random perturbations of its knots whose size grows to `2 --sigma` (basin hopping),
or, with `--from none`, random elbow pumps (random frequencies, phases and growth, plus noise).
From each, `dynax.internal.polish_on_constraint` (what `design_swing_up`'s last search stage runs):

1. **feasibility**: damped Gauss-Newton steps of minimum norm on the knots onto the constraint
   (the end minus the nearest upright rest, the last torque), gradients through the RK4 rollout
   (10 ms steps);
2. **optimisation on the constraint**: Adam on the gradient of the score's smooth surrogate
   (`dynax.internal.score_surrogate`) projected onto the constraint's tangent space, each step
   followed by a Gauss-Newton correction back onto it. The surrogate is the score's own mean of
   `tanh(pi c / n)` over the five costs: the swing-up time as the time the end effector spends
   below the line (a sigmoid of its height), the energy, the torque cost, the torque smoothness
   (the standard deviation of the 2 ms torque changes over the whole 10 s episode) and the
   velocity cost.

The best `--keep` feasible references are re-ended exactly upright at the control period
(`dynax.control.end_upright`), get the default time-varying LQR around them
(`design_swing_up(reference=...)`), and are scored by the exact rules
(`dynax.control.performance`); the best `--top` also by `dynax.control.robustness`. Results:
`search.json`, `search.png` and `best_policy.npz` under `--out`
(`experiments/results/leaderboard/global_search/` by default).
"""

import argparse
import json
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from dynax import control
from dynax.internal import knot_matrix, polish_on_constraint
from experiments._swing_up_search import plot_best, score_references

OUT = pathlib.Path(__file__).resolve().parent / "results" / "leaderboard" / "global_search"
RULES = control.LeaderboardRules()
NORM = jnp.asarray(RULES.normalisation)
FINE = RULES.dt
SPACING = 0.02
LIMIT = 6.0


def _knots(w):
    return jnp.concatenate([jnp.zeros(1, w.dtype), LIMIT * jnp.tanh(w)])


def initial_guesses(rng, n, n_knots, horizon):
    """Smooth random torque profiles: elbow pumps at random frequencies, phases and growth, plus noise."""
    t = np.arange(1, n_knots + 1) * SPACING
    out = []
    for _ in range(n):
        f = rng.uniform(0.7, 2.5)
        growth = rng.uniform(0.0, 2.5)
        amp = rng.uniform(1.5, 5.0)
        u = amp * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) * np.exp(growth * (t / horizon - 1))
        u = u + rng.normal(0, 0.5, n_knots)
        out.append(np.arctanh(np.clip(u / LIMIT, -0.95, 0.95)))
    return np.stack(out)


def seed_knots(path, horizon):
    """A saved controller's reference torque knots (`w`), stretched in time to `horizon`."""
    us = control.load_controller(path).u_ref
    per_knot = int(round(SPACING / FINE))
    knots = np.concatenate([us[per_knot::per_knot], us[-1:]])
    t_old = np.arange(1, len(knots) + 1) / len(knots)
    n_knots = int(round(horizon / SPACING))
    t_new = np.arange(1, n_knots + 1) / n_knots
    return np.arctanh(np.clip(np.interp(t_new, t_old, knots) / LIMIT, -0.999, 0.999))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=16, help="starts per horizon")
    ap.add_argument("--horizons", type=float, nargs="+", default=[2.0])
    ap.add_argument(
        "--from",
        dest="seed_policy",
        type=pathlib.Path,
        default=OUT.parent / "acrobot_policy.npz",
        help="perturb this saved controller's reference (stretched to each horizon); 'none': random starts",
    )
    ap.add_argument("--sigma", type=float, default=0.3, help="the perturbations' size on the knots' tanh scale")
    ap.add_argument("--feasibility", type=int, default=80, help="Gauss-Newton steps from each start")
    ap.add_argument("--iterations", type=int, default=400, help="projected Adam steps on the constraint")
    ap.add_argument("--lr", type=float, default=0.003)
    ap.add_argument("--search-dt", type=float, default=0.01, help="RK4 step of the search [s]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", type=int, default=16, help="how many feasible references are scored exactly")
    ap.add_argument("--top", type=int, default=3, help="how many of the best are scored for robustness")
    ap.add_argument("--out", type=pathlib.Path, default=OUT)
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    plant = control.LeaderboardPlant.nominal()
    design = control.SwingUpDesign(
        polish_feasibility=args.feasibility, polish_iterations=args.iterations, polish_learning_rate=args.lr
    )
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    found = []
    print(
        f"{args.starts} random starts per horizon {args.horizons}: {args.feasibility} Gauss-Newton steps, "
        f"{args.iterations} projected Adam steps, RK4 at {args.search_dt * 1e3:.0f} ms",
        flush=True,
    )
    for horizon in args.horizons:
        n_knots = int(round(horizon / SPACING))
        interp = knot_matrix(int(round(horizon / args.search_dt)), args.search_dt, SPACING, n_knots)
        if str(args.seed_policy) == "none":
            w0 = initial_guesses(rng, args.starts, n_knots, horizon)
        else:  # the seed itself, then perturbations of it whose size grows to 2 sigma
            scale = args.sigma * np.linspace(0.0, 2.0, args.starts)[:, None]
            w0 = seed_knots(args.seed_policy, horizon)[None] + scale * rng.normal(size=(args.starts, n_knots))
        w0 = jnp.asarray(w0)
        w, feasible, end, score, costs = polish_on_constraint(plant, w0, interp, args.search_dt, design)
        end, score = np.asarray(end), np.asarray(score)
        for j in range(args.starts):
            found.append(
                dict(
                    horizon=horizon,
                    start=j,
                    w=np.asarray(w[j]),
                    after_feasibility=float(feasible[j]),
                    end_residual=float(end[j]),
                    surrogate_score=float(1 - score[j]),
                    smooth_costs=np.asarray(costs[j]).tolist(),
                )
            )
        ok = end < 1e-4
        print(
            f"  horizon {horizon:.1f} s: {int(np.sum(np.asarray(feasible) < 1e-4))} feasible after Gauss-Newton, "
            f"{int(ok.sum())} after the search; best surrogate score "
            f"{float(np.max(np.where(ok, 1 - score, -np.inf))):.3f} [{time.perf_counter() - t0:.0f} s]",
            flush=True,
        )
    feasible = sorted([f for f in found if f["end_residual"] < 1e-4], key=lambda f: -f["surrogate_score"])
    print(f"{len(feasible)} feasible; the best {min(args.keep, len(feasible))} scored by the exact rules", flush=True)

    def reference_of(f):
        n_knots, n_fine = int(round(f["horizon"] / SPACING)), int(round(f["horizon"] / FINE))
        us = knot_matrix(n_fine, FINE, SPACING, n_knots) @ _knots(jnp.asarray(f["w"]))
        return us, control.SwingUpDesign(horizon=f["horizon"])

    scored = score_references(plant, feasible[: args.keep], reference_of, args.top, args.out, t0)
    if scored:
        print("best:", json.dumps(scored[0]["exact"]), "robustness", scored[0].get("robustness", {}).get("score"))

    def record(f):
        out = {k: v for k, v in f.items() if k not in ("w", "controller")}
        return out | {"knots": np.asarray(_knots(jnp.asarray(f["w"]))).tolist()}

    summary = dict(
        command="python experiments/acrobot_global_search.py " + " ".join(sys.argv[1:] if argv is None else argv),
        settings={k: (str(v) if isinstance(v, pathlib.Path) else v) for k, v in vars(args).items()},
        seconds=time.perf_counter() - t0,
        feasible=len(feasible),
        best=record(scored[0]) if scored else None,
        found=[record(f) for f in found],
    )
    (args.out / "search.json").write_text(json.dumps(summary, indent=1))
    _figure(args.out / "search.png", found, scored)
    print(f"wrote {args.out} [{time.perf_counter() - t0:.0f} s]")
    return summary


def _figure(path, found, scored):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    for f in found:
        if f["end_residual"] < 1e-4:
            ax[0].scatter(f["horizon"], f["surrogate_score"], c="C0", s=10)
        if "exact" in f:
            ax[0].scatter(f["horizon"] + 0.02, f["exact"]["score"], c="C1", s=14, marker="x")
    ax[0].axhline(0.549, ls="-.", c="C2", lw=0.8, label="SwingUpDesign() (0.549)")
    ax[0].axhline(0.655, ls="--", c="k", lw=0.8, label="best published (0.655)")
    ax[0].axhline(0.70, ls=":", c="k", lw=0.8, label="target (0.70)")
    ax[0].set(xlabel="horizon [s]", ylabel="score", title="feasible starts: surrogate (o), exact (x)")
    ax[0].legend(fontsize=8)
    if scored:
        plot_best(ax[1], ax[2], scored[0])
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
