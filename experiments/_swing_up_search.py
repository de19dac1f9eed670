"""What the acrobot reference searches share (`acrobot_global_search.py`, `acrobot_collocation_starts.py`): each
feasible reference made exact and scored by the leaderboard's rules, the best few's robustness, the best saved, and
the best swing-up drawn."""

import json
import time

import numpy as np

from dynax import control


def score_references(plant, feasible, reference_of, top, out, t0):
    """Score each of `feasible` (dicts with `horizon`, `start`, `surrogate_score`) by the exact rules: `reference_of(f)`
    gives its elbow torques on the rules' grid and its `SwingUpDesign`; `end_upright` makes it end at rest, and the
    default feedback is designed around it. Adds `exact` and `controller` to each scored one, the robustness of the
    best `top`, saves the best as `out/best_policy.npz`; returns the scored ones, best first."""
    scored = []
    for f in feasible:
        us, design = reference_of(f)
        xs, us = control.end_upright(plant, us, design)
        if not np.all(np.isfinite(np.asarray(xs))):
            continue
        controller = control.design_swing_up(plant, design, reference=(xs, us))
        f["exact"] = control.performance(controller).as_dict()
        f["controller"] = controller
        scored.append(f)
        print(
            f"  horizon {f['horizon']:.1f} s start {f['start']}: surrogate {f['surrogate_score']:.3f}, exact "
            f"{f['exact']['score']:.3f} {json.dumps({k: round(v, 4) for k, v in f['exact'].items()})} "
            f"[{time.perf_counter() - t0:.0f} s]",
            flush=True,
        )
    scored.sort(key=lambda f: -f["exact"]["score"])
    for f in scored[:top]:
        rob = control.robustness(f["controller"])
        f["robustness"] = dict(score=rob.score, families=rob.table(), seconds=rob.seconds)
        print(
            f"  horizon {f['horizon']:.1f} s start {f['start']}: performance {f['exact']['score']:.3f}, "
            f"robustness {rob.score:.3f} {np.round(rob.family_scores * 100, 1).tolist()} "
            f"[{time.perf_counter() - t0:.0f} s]",
            flush=True,
        )
    if scored:
        scored[0]["controller"].save(out / "best_policy.npz")
    return scored


def plot_best(ax_angles, ax_torque, best):
    """The best reference's closed-loop swing-up: the angles and the elbow torque to a second past its horizon."""
    rollout = control.simulate_leaderboard(best["controller"])
    t = np.asarray(rollout.ts)
    keep = t <= best["horizon"] + 1.0
    ax_angles.plot(t[keep], np.asarray(rollout.xs)[keep, 0], label="q1")
    ax_angles.plot(t[keep], np.asarray(rollout.xs)[keep, 1], label="q2")
    ax_angles.set(xlabel="t [s]", ylabel="rad", title=f"best: exact score {best['exact']['score']:.3f}")
    ax_angles.legend(fontsize=8)
    ax_torque.plot(t[:-1][keep[:-1]], np.asarray(rollout.us)[keep[:-1]])
    ax_torque.set(xlabel="t [s]", ylabel="elbow torque [N m]")
