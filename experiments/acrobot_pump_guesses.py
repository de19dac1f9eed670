"""Collocation from pumping initial guesses: q1 swinging with growing amplitude to upright after
`pumps` half-swings, the elbow folding against it; then shooting, end correction, exact score.

    python experiments/acrobot_pump_guesses.py [--horizons 2.0 2.4] [--pumps 2 3 4]
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
from dynax.internal import (
    collocation_reference,
    end_upright_residuals,
    knot_matrix,
    open_loop_rollout,
    reference_search,
)

OUT = pathlib.Path(__file__).resolve().parent / "results" / "leaderboard" / "pump_guesses"


def pump_guess(n_knots, spacing, pumps, elbow, sign, growth, rng):
    s = np.linspace(0.0, 1.0, n_knots + 1)[1:]
    q1 = sign * np.pi * s**growth * np.cos(np.pi * pumps * (1 - s))
    q2 = -elbow * np.sin(np.pi * pumps * (1 - s)) * np.sin(np.pi * s) * sign
    x = np.stack([q1, q2, np.gradient(q1, spacing), np.gradient(q2, spacing)], axis=1)
    return np.concatenate([x.ravel(), 0.3 * rng.normal(size=n_knots)])


def design_reference(plant, design, guesses):
    n_knots = round(design.horizon / design.knot_spacing)
    coarse_steps = round(design.horizon / design.coarse_dt)
    fine_steps = round(design.horizon / design.dt)
    coarse = knot_matrix(coarse_steps, design.coarse_dt, design.knot_spacing, n_knots)
    fine = knot_matrix(fine_steps, design.dt, design.knot_spacing, n_knots)
    z = collocation_reference(plant, jnp.asarray(guesses), design, n_knots, design.iterations)
    w, cost, err = reference_search(
        plant, z[:, 4 * n_knots :], coarse, design.coarse_dt, design, design.shooting_iterations, 1.0
    )
    refs = []
    for j in np.argsort(np.asarray(jnp.where(err < 1e-3, cost, cost + 100 + err))):
        if float(err[j]) > 1e-2:
            continue
        wb = w[j : j + 1]
        if design.refine_iterations:
            wb, _, _ = reference_search(plant, wb, fine, design.dt, design, design.refine_iterations, 1.0)
        w_end = end_upright_residuals(plant, wb[0], fine, design.dt, design.torque_limit)
        us = fine @ jnp.concatenate([jnp.zeros(1), design.torque_limit * jnp.tanh(w_end)])
        _, xs = open_loop_rollout(plant, us, design.dt)
        refs.append((int(j), xs, us))
    return refs


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--horizons", type=float, nargs="+", default=[2.0, 2.4])
    parser.add_argument("--pumps", type=int, nargs="+", default=[2, 3, 4])
    parser.add_argument("--keep", type=int, default=3)
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plant = control.LeaderboardPlant.nominal()
    rng = np.random.default_rng(0)
    records, best = [], None
    t0 = time.perf_counter()
    for horizon in args.horizons:
        design = control.SwingUpDesign(horizon=horizon)
        n_knots = round(horizon / design.knot_spacing)
        guesses, labels = [], []
        for pumps in args.pumps:
            for sign in (1.0, -1.0):
                for elbow in (0.8, 1.6):
                    guesses.append(pump_guess(n_knots, design.knot_spacing, pumps, elbow, sign, 2.0, rng))
                    labels.append({"horizon": horizon, "pumps": pumps, "sign": sign, "elbow": elbow})
        refs = design_reference(plant, design, np.stack(guesses))
        print(
            f"horizon {horizon}: {len(refs)} feasible of {len(guesses)} [{time.perf_counter() - t0:.0f} s]", flush=True
        )
        for j, xs, us in refs[: args.keep]:
            c = control.design_swing_up(plant, design, reference=(xs, us))
            perf = control.performance(c)
            rec = dict(
                labels[j], score=float(perf.score), costs=[float(v) for v in perf.costs], final_q2=float(xs[-1, 1])
            )
            records.append(rec)
            print(f"  {rec} [{time.perf_counter() - t0:.0f} s]", flush=True)
            if best is None or rec["score"] > best[0]["score"]:
                best = (rec, c)
                c.save(out / "best_policy.npz")
        (out / "search.json").write_text(
            json.dumps({"best": best and best[0], "candidates": records, "seconds": time.perf_counter() - t0}, indent=2)
        )


if __name__ == "__main__":
    main()
