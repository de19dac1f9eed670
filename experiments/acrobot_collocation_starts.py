"""Many-start direct collocation of the acrobot's swing-up from rest against the leaderboard's whole score.

    python experiments/acrobot_collocation_starts.py [--horizons 1.0 1.2 1.4 1.6] [--starts 32]
        [--rounds 30] [--inner 200] [--lr 0.01] [--keep 6] [--polish 0] [--top 3] [--seed 0] [--skip 0]
        [--refine POLICY --sigma 0.05] [--lead 0.02] [--out DIR]

Asks what the score-optimal swing-up looks like, from many starts rather than one basin. The
reference: elbow torque knots 20 ms apart, piecewise linear, zero at the start and at the end
(`6 tanh(w)` within the limit). Per horizon, `--starts` initial guesses in one `vmap`: the
shoulder turned to +pi or -pi with 0 to 2 back-swings of random size, the elbow swung 1 to 4
half-periods with a random amplitude either way, the elbow torque of the guessed motion (its
own equation of motion) as the first torques. With `--refine POLICY`: that controller's
reference stretched to each horizon, and perturbations of its torques.

1. **Direct collocation** (states at the knots and the torques free, the end fixed upright at
   rest): the defects of the RK4 steps of `--sub-dt` (10 ms; 2 ms: the benchmark's own) per knot
   interval (the shooting's discretisation, so a collocation with zero defects is a shooting
   trajectory), by an
   augmented Lagrangian (`--rounds` multiplier updates, `--inner` Adam steps each, the penalty
   growing by 1.25 per round, the step size decaying from `--lr` to 10 % of it), then 20
   minimum-norm Gauss-Newton steps onto zero defects (full where they lower the defects, else a
   tenth). The objective is the score's own mean of `tanh(pi c / n)` over the five costs
   (`dynax.internal.score_surrogate`'s definitions: the swing-up time as the time the
   end effector spends below the line, a sigmoid of its height).
2. The best `--keep` collocations per horizon (by the surrogate, defects below 0.05) are kept
   as they are, or, with `--polish N`, seed the single-shooting search on the hand-over
   constraint (`dynax.internal.polish_on_constraint`: Gauss-Newton onto it, then N projected
   Adam steps).
3. Feasible references are re-ended upright at the control period (`dynax.control.end_upright`),
   get the default feedback (`design_swing_up(reference=...)`, lead `--lead`) and are scored by
   the exact rules; the best `--top` also for robustness.

`dynax.control.ReferenceSearch` (what `dynax control acrobot` runs) folds the four runs of this
script that found the 1.5 s reference into one call ([the dev notes](../docs/devdocs/control_notes.md)).

Results: `search.json`, `search.png`, `best_policy.npz` under `--out`
(`experiments/results/leaderboard/collocation_starts/` by default).
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
import optax

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from dynax import control
from dynax.internal import collocation_costs, knot_matrix, polish_on_constraint
from experiments._swing_up_search import plot_best, score_references

OUT = pathlib.Path(__file__).resolve().parent / "results" / "leaderboard" / "collocation_starts"
RULES = control.LeaderboardRules()
NORM = jnp.asarray(RULES.normalisation)
H = 0.02  # knot spacing
SUB = 0.01  # RK4 step of the search
LIMIT = 6.0
SCALE = jnp.array([1.0, 1.0, 0.3, 0.3])  # defects in rad and rad/s


def _unpack(z, n, sign):
    xs = jnp.concatenate(
        [
            jnp.zeros((1, 4), z.dtype),
            z[: 4 * (n - 1)].reshape(n - 1, 4),
            jnp.stack([sign * jnp.pi, 0.0, 0.0, 0.0])[None].astype(z.dtype),
        ]
    )
    u = jnp.concatenate([jnp.zeros(1, z.dtype), LIMIT * jnp.tanh(z[4 * (n - 1) :]), jnp.zeros(1, z.dtype)])
    return xs, u


def costs_of(plant, xs, u, sub=SUB, sharpness=0.01):
    """The five smooth costs of a collocated trajectory (`score_surrogate`'s definitions) and its defects."""
    return collocation_costs(plant, xs, u, H, sub, RULES, sharpness)


@eqx.filter_jit
def collocate(plant, z0, signs, n, rounds, inner, lr, sub=SUB):
    """Augmented-Lagrangian collocation from each start (one `vmap`)."""
    opt = optax.adam(optax.exponential_decay(lr, rounds * inner, 0.1))

    def one(z0, sign):
        def lagrangian(z, lam, rho):
            xs, u = _unpack(z, n, sign)
            c, d = costs_of(plant, xs, u, sub)
            f = jnp.mean(jnp.tanh(jnp.pi * c / NORM))
            return f + jnp.sum(lam * d) + 0.5 * rho * jnp.sum(d**2)

        def outer(carry, r):
            z, lam, s = carry
            rho = 10.0 * 1.25**r

            def step(carry, _):
                z, s = carry
                g = jax.grad(lagrangian)(z, lam, rho)
                upd, s = opt.update(g, s)
                return (z + upd, s), None

            (z, s), _ = jax.lax.scan(step, (z, s), None, length=inner)
            xs, u = _unpack(z, n, sign)
            _, d = costs_of(plant, xs, u, sub)
            return (z, lam + rho * d, s), jnp.max(jnp.abs(d))

        (z, _, _), hist = jax.lax.scan(outer, (z0, jnp.zeros((n, 4), z0.dtype), opt.init(z0)), jnp.arange(rounds))

        def defects(z):
            xs, u = _unpack(z, n, sign)
            return costs_of(plant, xs, u, sub)[1].ravel()

        def project(z, _):  # minimum-norm Gauss-Newton steps onto zero defects
            d, j = defects(z), jax.jacfwd(defects)(z)
            step = j.T @ jnp.linalg.solve(j @ j.T + 1e-10 * jnp.eye(d.shape[0]), d)
            full, short = z - step, z - 0.1 * step
            better = jnp.sum(defects(full) ** 2) < jnp.sum(d**2)  # a full step when it helps, else a short one
            z_new = jnp.where(better, full, short)
            return jnp.where(jnp.all(jnp.isfinite(z_new)), z_new, z), None

        z, _ = jax.lax.scan(project, z, None, length=20)
        xs, u = _unpack(z, n, sign)
        c, d = costs_of(plant, xs, u, sub)
        return z, c, jnp.mean(jnp.tanh(jnp.pi * c / NORM)), jnp.max(jnp.abs(d)), hist

    return jax.vmap(one)(z0, signs)


def initial_guesses(plant, rng, n_starts, n):
    """Shoulder to +-pi with back-swings, elbow swings either way; the elbow torque of the guessed motion."""
    s = np.arange(n + 1) / n
    zs, signs, labels = [], [], []
    for i in range(n_starts):
        sign = 1.0 if i % 2 == 0 else -1.0
        back = rng.integers(0, 3)
        pumps = rng.integers(1, 5)
        a_back = rng.uniform(0.2, 1.2) * (back > 0)
        a_elbow = rng.uniform(0.5, 2.5) * rng.choice([-1.0, 1.0])
        ramp = s**2 * (3 - 2 * s)
        q1 = sign * (np.pi * ramp - a_back * np.sin(np.pi * max(back, 1) * s))
        q2 = a_elbow * np.sin(np.pi * pumps * s) * np.sin(np.pi * s) ** 0.5
        t = s * n * H
        v1, v2 = np.gradient(q1, t), np.gradient(q2, t)
        a1, a2 = np.gradient(v1, t), np.gradient(v2, t)
        x = np.stack([q1, q2, v1, v2], axis=1)
        x[-1] = [sign * np.pi, 0, 0, 0]
        # the elbow's own equation: tau2 = m01 a1 + m11 a2 + h v1^2 + m2 g r2 sin(q1 + q2)
        m01 = plant.I2 + plant.m2 * plant.l1 * plant.r2 * np.cos(q2)
        tau = (
            m01 * a1
            + plant.I2 * a2
            + plant.m2 * plant.l1 * plant.r2 * np.sin(q2) * v1**2
            + plant.m2 * plant.g * plant.r2 * np.sin(q1 + q2)
        )
        tau = np.clip(np.asarray(tau, float)[1:n], -0.95 * LIMIT, 0.95 * LIMIT)
        zs.append(np.concatenate([x[1:n].ravel(), np.arctanh(tau / LIMIT)]))
        signs.append(sign)
        labels.append(dict(sign=sign, back_swings=int(back), elbow_half_periods=int(pumps), elbow=float(a_elbow)))
    return jnp.asarray(np.stack(zs)), jnp.asarray(signs), labels


def refine_guesses(path, rng, n_starts, n, sigma):
    """A saved controller's reference stretched to `n` knots, and `n_starts - 1` perturbations of its torques."""
    saved = control.load_controller(path)
    xs, us = saved.x_ref, saved.u_ref
    t_old = np.arange(len(us)) / len(us)
    s = np.arange(n + 1) / n
    stretch = len(us) * RULES.dt / (n * H)
    x = np.stack([np.interp(s, t_old, xs[:, i]) * (1.0 if i < 2 else stretch) for i in range(4)], axis=1)
    u = np.interp(s, t_old, us)
    sign = float(np.sign(xs[-1, 0]))
    x[-1] = [sign * np.pi, 0, 0, 0]
    w = np.arctanh(np.clip(u[1:n] / LIMIT, -0.99, 0.99))
    zs = [np.concatenate([x[1:n].ravel(), w + sigma * (i > 0) * rng.normal(size=w.shape)]) for i in range(n_starts)]
    labels = [dict(refined=str(path), perturbation=sigma * (i > 0)) for i in range(n_starts)]
    return jnp.asarray(np.stack(zs)), jnp.asarray([sign] * n_starts), labels


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--horizons", type=float, nargs="+", default=[1.0, 1.2, 1.4, 1.6])
    ap.add_argument("--starts", type=int, default=32, help="collocation starts per horizon")
    ap.add_argument("--rounds", type=int, default=30, help="augmented-Lagrangian multiplier updates")
    ap.add_argument("--inner", type=int, default=200, help="Adam steps per round")
    ap.add_argument("--lr", type=float, default=0.01)
    ap.add_argument("--keep", type=int, default=6, help="collocations per horizon polished by shooting")
    ap.add_argument("--polish", type=int, default=0, help="projected Adam steps on the hand-over constraint (0: none)")
    ap.add_argument("--lead", type=float, default=0.02, help="the controller's lead [s]")
    ap.add_argument("--top", type=int, default=3, help="how many of the best are scored for robustness")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--skip", type=int, default=0, help="discard this many starts first (a later horizon's starts of a run)"
    )
    ap.add_argument(
        "--refine",
        type=pathlib.Path,
        default=None,
        help="start from this saved controller's reference (stretched to each horizon) and perturbations of it",
    )
    ap.add_argument("--sigma", type=float, default=0.05, help="--refine's perturbations of the torques (tanh scale)")
    ap.add_argument(
        "--sub-dt", type=float, default=SUB, help="RK4 step within the knot intervals [s] (0.002: the benchmark's)"
    )
    ap.add_argument("--out", type=pathlib.Path, default=OUT)
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    plant = control.LeaderboardPlant.nominal()
    rng = np.random.default_rng(args.seed)
    if args.skip:  # the generator's draws do not depend on the horizon
        initial_guesses(plant, rng, args.skip, 10)
    design = control.SwingUpDesign(polish_feasibility=80, polish_iterations=args.polish)
    t0 = time.perf_counter()
    found = []
    print(
        f"{args.starts} collocation starts per horizon {args.horizons}: {args.rounds} x {args.inner} Adam steps; "
        f"the best {args.keep} per horizon polished ({args.polish} steps)",
        flush=True,
    )
    for horizon in args.horizons:
        n = int(round(horizon / H))
        if args.refine is None:
            z0, signs, labels = initial_guesses(plant, rng, args.starts, n)
        else:
            z0, signs, labels = refine_guesses(args.refine, rng, args.starts, n, args.sigma)
        z, c, f, dmax, hist = collocate(plant, z0, signs, n, args.rounds, args.inner, args.lr, args.sub_dt)
        c, f, dmax = np.asarray(c), np.asarray(f), np.asarray(dmax)
        ok = dmax < 0.05
        order = np.argsort(np.where(ok, f, np.inf))
        print(
            f"  horizon {horizon:.1f} s: collocation {int(ok.sum())}/{args.starts} with defects < 0.05; best surrogate "
            f"scores {np.round(1 - f[order[:5]], 3).tolist()} [{time.perf_counter() - t0:.0f} s]",
            flush=True,
        )
        for j in order[:3]:
            print(f"    start {j} {labels[j]}: costs {np.round(c[j], 3).tolist()}, defect {dmax[j]:.1e}", flush=True)
        keep = [int(j) for j in order[: args.keep] if ok[j]]
        if not keep:
            continue
        # shooting from the collocations' torques: w for knots 1..n (the last is driven to zero)
        u = np.asarray(jax.vmap(lambda zz, sg: _unpack(zz, n, sg)[1])(z[np.array(keep)], signs[np.array(keep)]))
        w0 = jnp.asarray(np.arctanh(np.clip(u[:, 1:] / LIMIT, -0.999999, 0.999999)))
        interp = knot_matrix(int(round(horizon / args.sub_dt)), args.sub_dt, H, n)
        if args.polish:
            w, feas, end, score, pc = polish_on_constraint(plant, w0, interp, args.sub_dt, design)
        else:  # the collocations as they are (exact shooting trajectories when their defects are zero)
            w = w0
            feas = end = jnp.asarray(dmax[np.array(keep)] ** 2)
            score, pc = jnp.asarray(f[np.array(keep)]), jnp.asarray(c[np.array(keep)])
        end, score = np.asarray(end), np.asarray(score)
        for i, j in enumerate(keep):
            found.append(
                dict(
                    horizon=horizon,
                    start=j,
                    guess=labels[j],
                    collocation_surrogate=float(1 - f[j]),
                    collocation_costs=c[j].tolist(),
                    collocation_defect=float(dmax[j]),
                    after_feasibility=float(feas[i]),
                    end_residual=float(end[i]),
                    surrogate_score=float(1 - score[i]),
                    smooth_costs=np.asarray(pc[i]).tolist(),
                    w=np.asarray(w[i]),
                )
            )
        print(
            f"    shooting: {int((end < 1e-4).sum())}/{len(keep)} on the constraint, surrogate scores "
            f"{np.round(np.where(end < 1e-4, 1 - score, np.nan), 3).tolist()} [{time.perf_counter() - t0:.0f} s]",
            flush=True,
        )
    feasible = sorted([f for f in found if f["end_residual"] < 1e-4], key=lambda f: -f["surrogate_score"])
    print(f"{len(feasible)} feasible; each scored by the exact rules", flush=True)

    def reference_of(f):
        n, n_fine = int(round(f["horizon"] / H)), int(round(f["horizon"] / RULES.dt))
        knots = jnp.concatenate([jnp.zeros(1), LIMIT * jnp.tanh(jnp.asarray(f["w"]))])
        return knot_matrix(n_fine, RULES.dt, H, n) @ knots, control.SwingUpDesign(horizon=f["horizon"], lead=args.lead)

    scored = score_references(plant, feasible, reference_of, args.top, args.out, t0)

    def record(f):
        out = {k: v for k, v in f.items() if k not in ("w", "controller")}
        return out | {"knots": np.asarray(LIMIT * np.tanh(f["w"])).tolist()}

    summary = dict(
        command="python experiments/acrobot_collocation_starts.py " + " ".join(sys.argv[1:] if argv is None else argv),
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
        ax[0].scatter(f["horizon"] - 0.02, f["collocation_surrogate"], c="C0", s=10)
        if f["end_residual"] < 1e-4:
            ax[0].scatter(f["horizon"], f["surrogate_score"], c="C2", s=10)
        if "exact" in f:
            ax[0].scatter(f["horizon"] + 0.02, f["exact"]["score"], c="C1", s=14, marker="x")
    ax[0].axhline(0.601, ls="-.", c="C3", lw=0.8, label="saved policy before (0.601)")
    ax[0].axhline(0.655, ls="--", c="k", lw=0.8, label="best published (0.655)")
    ax[0].axhline(0.70, ls=":", c="k", lw=0.8, label="target (0.70)")
    ax[0].set(xlabel="horizon [s]", ylabel="score", title="collocation (blue), shooting (green), exact (x)")
    ax[0].legend(fontsize=8)
    if scored:
        plot_best(ax[1], ax[2], scored[0])
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
