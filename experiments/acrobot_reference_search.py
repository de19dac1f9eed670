"""Search swing-up references from rest against the leaderboard's own performance score.

    python experiments/acrobot_reference_search.py [--horizons 1.6 2.0 2.5 3.0] [--seeds 0 1]
        [--elbow-ranges inf 2.8] [--polish 0]

For each horizon, elbow range and seed: `dynax.control.optimise_swing_up` (collocation from several
guesses, single shooting, the exact end at upright), the default feedback around it
(`design_swing_up(reference=...)`), and the exact score (`dynax.control.performance`). With
`--polish N`, each reference is then polished by N Adam steps on its torque knots against the
score's own smooth costs, `tanh(pi c / n)` of the energy, torque cost, torque smoothness (the
standard deviation of the step-to-step torque changes over the whole 10 s episode) and velocity
cost, gradients through the RK4 rollout, with the terminal penalty at full weight, and re-ended
upright (`end_upright`). Every candidate's score goes to `search.json` under `--out`
(`experiments/results/leaderboard/reference_search/` by default), the best controller to
`best_policy.npz` there.
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
from dynax.internal import knot_matrix, open_loop_rollout

OUT = pathlib.Path(__file__).resolve().parent / "results" / "leaderboard" / "reference_search"
NORM = np.array(control.LeaderboardRules().normalisation)


def smooth_costs(plant, w, interp, dt, spacing, limit, n_episode):
    knots = jnp.concatenate([jnp.zeros(1, w.dtype), limit * jnp.tanh(w), jnp.zeros(1, w.dtype)])
    us = interp @ knots
    x_final, xs = open_loop_rollout(plant, us, dt)
    q2 = jnp.concatenate([xs[:, 1], x_final[1:2]])
    energy = jnp.sum(jnp.abs(jnp.diff(q2) * us))
    torque = jnp.sum(us**2) * dt
    velocity = jnp.sum(xs[:, 2:] ** 2) * dt
    # the fine-step changes of a piecewise-linear profile: (dk)*dt_fine/spacing, spacing/dt_fine of them
    fine = 0.002
    smooth = jnp.sqrt(jnp.sum(jnp.diff(knots) ** 2) * fine / spacing / n_episode + 1e-12)
    costs = jnp.stack([energy, torque, smooth, velocity]) / jnp.asarray(NORM[1:])
    err = jnp.stack([2 * jnp.cos(x_final[0] / 2), 2 * jnp.sin(x_final[1] / 2), 0.3 * x_final[2], 0.3 * x_final[3]])
    return jnp.mean(jnp.tanh(jnp.pi * costs)), err


@eqx.filter_jit
def search(plant, w0, interp, dt, spacing, iterations, ramp, lr=0.02, limit=6.0, n_episode=4999, start_weight=0.1):
    opt = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(lr))

    def one(w0):
        def loss(w, weight):
            c, err = smooth_costs(plant, w, interp, dt, spacing, limit, n_episode)
            return c + weight * jnp.sum(err**2)

        def it(carry, i):
            w, s = carry
            weight = jnp.minimum(300.0, start_weight * ramp**i)
            g = jax.grad(loss)(w, weight)
            u, s = opt.update(g, s)
            return (w + u, s), None

        (w, _), _ = jax.lax.scan(it, (w0, opt.init(w0)), jnp.arange(iterations))
        c, err = smooth_costs(plant, w, interp, dt, spacing, limit, n_episode)
        return w, c, jnp.sum(err**2)

    return jax.vmap(one)(w0)


def polish(plant, xs, us, spacing, coarse_dt, iterations):
    """Adam on the knots of a feasible reference against the score's own smooth costs (full terminal weight)."""
    per_knot = round(spacing / 0.002)
    n_steps = us.shape[0]
    n_seg = n_steps // per_knot
    knots = np.asarray(us)[per_knot : n_seg * per_knot : per_knot]  # interior knots
    w0 = jnp.asarray(np.arctanh(np.clip(knots / 6.0, -0.999, 0.999)))[None]
    coarse_steps = round(n_steps * 0.002 / coarse_dt)
    interp = knot_matrix(coarse_steps, coarse_dt, spacing, n_seg)
    w, _cost, _err = search(plant, w0, interp, coarse_dt, spacing, iterations, 1.0, lr=0.003, start_weight=300.0)
    fine = np.asarray(knot_matrix(n_steps, 0.002, spacing, n_seg))
    return jnp.asarray(fine @ np.concatenate([[0.0], 6.0 * np.tanh(np.asarray(w[0])), [0.0]]))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--horizons", type=float, nargs="+", default=[1.6, 2.0, 2.5, 3.0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--elbow-ranges", type=float, nargs="+", default=[float("inf"), 2.8])
    parser.add_argument("--polish", type=int, default=0, help="Adam iterations on the exact smooth costs (0: none)")
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plant = control.LeaderboardPlant.nominal()
    records, best = [], None
    start_all = time.perf_counter()

    def score(xs, us, design, label):
        nonlocal best
        c = control.design_swing_up(plant, design, reference=(xs, us))
        perf = control.performance(c)
        rec = dict(label, score=float(perf.score), costs=[float(v) for v in perf.costs])
        records.append(rec)
        print(
            f"  {label}: score {rec['score']:.3f} costs {np.round(rec['costs'], 4)} "
            f"[{time.perf_counter() - start_all:.0f} s]",
            flush=True,
        )
        if best is None or rec["score"] > best[0]["score"]:
            best = (rec, c)
            c.save(out / "best_policy.npz")

    for horizon in args.horizons:
        for elbow in args.elbow_ranges:
            for seed in args.seeds:
                design = control.SwingUpDesign(horizon=horizon, seed=seed, elbow_range=elbow)
                xs, us = control.optimise_swing_up(plant, design)
                label = {"horizon": horizon, "elbow_range": elbow, "seed": seed, "polished": False}
                score(xs, us, design, label)
                if args.polish:
                    us2 = polish(plant, xs, us, design.knot_spacing, design.coarse_dt, args.polish)
                    xs2, us2 = control.end_upright(plant, us2, design)
                    if np.all(np.isfinite(np.asarray(xs2))):
                        score(xs2, us2, design, dict(label, polished=True))
                (out / "search.json").write_text(
                    json.dumps(
                        {
                            "best": best[0],
                            "candidates": records,
                            "seconds": time.perf_counter() - start_all,
                            "settings": vars(args),
                        },
                        indent=2,
                        default=float,
                    )
                )
    print(f"best {best[0]} in {time.perf_counter() - start_all:.0f} s; wrote {out}", flush=True)


if __name__ == "__main__":
    main()
