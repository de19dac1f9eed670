"""The RealAIGym acrobot leaderboard: design a swing-up from the hanging rest and score it by the rules.

    python experiments/acrobot_leaderboard.py                      # design, score, figures (minutes)
    python experiments/acrobot_leaderboard.py --policy P.npz       # score a saved controller only

Writes `experiments/results/leaderboard/`: `results.json` (the performance costs and score, the
robustness per family and its score, timings), `acrobot_policy.npz` (the controller, for
`dynax.control.load_controller`), `robustness.png` (success against each perturbation's size),
`swing_up.png` (the nominal episode), and the trade-off of the controller's prediction lead
(performance against robustness, same reference). The experiment owns no algorithm: the benchmark is
`dynax.control.performance` / `robustness`, the design `dynax.control.design_swing_up`.
"""

import argparse
import json
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
import dynax
from dynax import control
from dynax.internal import estimator_view

OUT = pathlib.Path(__file__).resolve().parent / "results" / "leaderboard"
PUBLISHED = {  # leaderboards v2, best published entry per family (robustness), and the top scores
    "model": 0.676,
    "velocity_noise": 0.286,
    "torque_noise": 1.0,
    "torque_response": 1.0,
    "delay": 0.905,
    "perturbations": 0.78,
}


def figures(rob, rollout, out):
    curves = rob.curves()
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    ax = axes[0, 0]
    for name in control.MODEL_PARAMETERS:
        sizes, ok = curves[f"model:{name}"]
        rel = np.linspace(-1, 1, len(sizes))
        ax.plot(rel, ok + 0.02 * control.MODEL_PARAMETERS.index(name), ".-", label=name)
    ax.set_title(f"model ({100 * rob.family_scores[0]:.0f} %)")
    ax.set_xlabel("position in the parameter's range (-1 .. 1)")
    ax.legend(fontsize=6, ncol=2)
    for ax, fam in zip(axes.ravel()[1:], list(control.Family)[1:]):
        sizes, ok = curves[fam.value]
        kind = "bar" if fam is control.Family.PERTURBATIONS else "line"
        if kind == "bar":
            ax.bar(sizes, ok)
            ax.set_xlabel("run")
        else:
            ax.plot(sizes, ok, "o-")
            ax.set_xlabel(
                {
                    "velocity_noise": "sigma [rad/s]",
                    "torque_noise": "sigma [N m]",
                    "torque_response": "k",
                    "delay": "delay [s]",
                }[fam.value]
            )
        score = rob.family_scores[list(control.Family).index(fam)]
        ax.set_title(f"{fam.value} ({100 * score:.0f} %)")
        ax.set_ylim(-0.05, 1.1)
    for ax in axes.ravel():
        ax.set_ylabel("success")
    fig.suptitle(f"robustness {rob.score:.3f} (published best per family: {PUBLISHED})", fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "robustness.png", dpi=110)
    plt.close(fig)
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    axes[0].plot(rollout.ts, rollout.xs[:, :2])
    axes[0].axhline(np.pi, color="k", lw=0.5)
    axes[0].set_ylabel("q [rad]")
    axes[0].legend(["q1", "q2"])
    axes[1].plot(rollout.ts[:-1], rollout.us)
    axes[1].set_ylabel("elbow torque [N m]")
    axes[1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(out / "swing_up.png", dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--policy", default=None, help="score this saved controller instead of designing one")
    parser.add_argument(
        "--reference",
        default=None,
        help="design the feedback (TVLQR, LQR, lead) with the default SwingUpDesign around the "
        "reference of this saved controller instead of searching for a reference",
    )
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    timings = {}
    if args.policy:
        controller = dynax.control.load_controller(args.policy).to_benchmark()
        design = None
    else:
        design = control.SwingUpDesign()
        reference = None
        if args.reference:
            saved = dynax.control.load_controller(args.reference)
            reference = (jax.numpy.asarray(saved.x_ref), jax.numpy.asarray(saved.u_ref))
        print(
            "designing the swing-up (collocation, shooting, TVLQR) ..."
            if reference is None
            else f"designing the feedback around the reference of {args.reference} ...",
            flush=True,
        )
        start = time.perf_counter()
        controller = control.design_swing_up(design=design, reference=reference)
        timings["design_s"] = time.perf_counter() - start
        controller.save(out / "acrobot_policy.npz")
        print(f"  {timings['design_s']:.0f} s", flush=True)
    start = time.perf_counter()
    rollout = control.simulate_leaderboard(controller)
    perf = control.performance_costs(rollout, control.LeaderboardPlant.nominal())
    timings["performance_s"] = time.perf_counter() - start
    print("performance", perf.as_dict(), flush=True)
    print("robustness (722 rollouts, one compiled call) ...", flush=True)
    rob = control.robustness(controller)
    timings["robustness_s"] = rob.seconds
    start = time.perf_counter()
    again = control.robustness(controller)  # compiled: the evaluation alone
    timings["robustness_warm_s"] = again.seconds
    assert np.array_equal(again.success, rob.success)
    print("robustness", rob.score, rob.table(), timings, flush=True)
    figures(rob, rollout, out)
    print("the prediction lead against delay: performance and robustness for other leads ...", flush=True)
    import equinox as eqx
    import jax.numpy as jnp

    leads = []
    for lead in (0.0, 0.01, 0.015, 0.02, 0.03):
        c = eqx.tree_at(lambda c: c.lead, controller, jnp.asarray(lead))
        if controller.x_track is not None:  # the reference as the estimate with this lead sees it
            view = estimator_view(
                controller.plant, controller.x_ref, controller.u_ref, lead, controller.dt, controller.velocity_source
            )
            c = eqx.tree_at(lambda c: c.x_track, c, view)
        p, r = control.performance(c), control.robustness(c)
        leads.append({"lead": lead, "performance": float(p.score), "robustness": r.score, "families": r.table()})
        print(f"  lead {lead:.3f} s: performance {float(p.score):.3f}, robustness {r.score:.3f}", flush=True)
    results = {
        "performance": perf.as_dict(),
        "robustness": {"score": rob.score, "families": rob.table(), "published_best": PUBLISHED},
        "timings": timings,
        "lead_tradeoff": leads,
        "design": None if design is None else {k: getattr(design, k) for k in design.__dataclass_fields__},
        "reference_from": args.reference or args.policy,
        "rules": {k: getattr(control.LeaderboardRules(), k) for k in control.LeaderboardRules.__dataclass_fields__},
    }
    (out / "results.json").write_text(json.dumps(results, indent=2, default=float))
    print(f"wrote {out}", flush=True)


if __name__ == "__main__":
    main()
