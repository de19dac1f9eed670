"""Tune the acrobot swing-up on a plant identified from data, score it on the true plant.

    python experiments/acrobot_identified_tuning.py [--seconds 30] [--noise 0.002] [--rounds 30] [--out DIR]

The seed's question on the leaderboard: what does tuning on dynax's own identification cost against
tuning on the true plant? The true plant is the benchmark's nominal with model errors of the kind and
size the robustness rules apply (`TRUE_CHANGES`: the first link's centre of mass and both inertias off
by 10 to 15 %, the second link's centre of mass by 10 %, viscous friction at both joints; no Coulomb
friction, which the viscous model below cannot represent). One record from rest: 2 ms samples of RK4
under a random multisine elbow torque (0.2 to 3 Hz, 2.5 N m peak), positions and velocities with
Gaussian noise (`--noise` rad, ten times that in rad/s). `dynax.identify(Acrobot(), record,
friction="viscous", refine=False)` gives the seven base parameters; with the lengths and masses
as the controller's model has them (the base parameters fix only their combinations), they become a
`LeaderboardPlant`. Then `design_swing_up` (the default search and feedback, `dynax control acrobot`)
on three models: the identified plant, the true plant, the nominal plant (what the leaderboard
controller assumes); each scored on the true plant by the rules (performance; robustness with the
perturbations applied around the true plant).

Writes `results.json` under `--out` (`experiments/results/leaderboard/identified_tuning/`).
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
import equinox as eqx

import dynax
from dynax import control
from dynax.internal import open_loop_rollout

OUT = pathlib.Path(__file__).resolve().parent / "results" / "leaderboard" / "identified_tuning"
NOMINAL = control.LeaderboardPlant.nominal()
TRUE_CHANGES = dict(
    r1=float(NOMINAL.r1) * 1.15,
    r2=float(NOMINAL.r2) * 1.10,
    I1=float(NOMINAL.I1) * 0.85,
    I2=float(NOMINAL.I2) * 1.10,
    b1=0.02,
    b2=0.05,
)


def record(plant, seconds, noise, rng, dt=0.002):
    """One excitation record of `plant` from rest: a multisine elbow torque, noisy states."""
    t = np.arange(int(round(seconds / dt))) * dt
    freqs = rng.uniform(0.2, 3.0, 8)
    phases = rng.uniform(0, 2 * np.pi, 8)
    u = np.sum(np.sin(2 * np.pi * freqs[:, None] * t[None] + phases[:, None]), axis=0)
    u = 2.5 * u / np.max(np.abs(u)) * np.minimum(1.0, t / 0.5)  # a half-second ramp from rest
    x_end, xs = open_loop_rollout(plant, jnp.asarray(u), dt)
    xs = np.asarray(xs) + rng.normal(size=xs.shape) * np.array([noise, noise, 10 * noise, 10 * noise])
    return dynax.Trajectory(t, xs, u[:, None], ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot")


def plant_from_base(theta, like=NOMINAL):
    """A `LeaderboardPlant` with the identified base parameters and `like`'s lengths and masses.

    theta1 = I1 + m2 l1^2, theta2 = I2, theta3 = m2 l1 r2, theta4 = g (m1 r1 + m2 l1), theta5 = g m2 r2,
    theta6 = b1, theta7 = b2. theta3 and theta5 both give m2 r2: the gravity one (theta5) sets r2, and
    the coupling's estimate is reported beside it."""
    m1, m2, l1, g = (float(getattr(like, k)) for k in ("m1", "m2", "l1", "g"))
    changes = dict(
        I1=theta["theta1"] - m2 * l1**2,
        I2=theta["theta2"],
        r2=theta["theta5"] / (g * m2),
        r1=(theta["theta4"] / g - m2 * l1) / m1,
        b1=theta["theta6"],
        b2=theta["theta7"],
    )
    return eqx.tree_at(
        lambda p: tuple(getattr(p, k) for k in changes), like, tuple(jnp.asarray(v, float) for v in changes.values())
    ), theta["theta3"] / (m2 * l1)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--noise", type=float, default=0.002, help="position noise [rad] (velocities: ten times, rad/s)")
    ap.add_argument("--rounds", type=int, default=None, help="augmented-Lagrangian rounds per stage (default 30)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=pathlib.Path, default=OUT)
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    true = control.LeaderboardPlant.nominal(**TRUE_CHANGES)
    data = record(true, args.seconds, args.noise, np.random.default_rng(args.seed))
    fit = dynax.identify(dynax.Acrobot(), data, friction="viscous", refine=False)
    theta = {k: float(v) for k, v in fit.system.base_parameters.items()}
    identified, r2_coupling = plant_from_base(theta)
    true_theta = {k: float(v) for k, v in plant_base(true).items()}
    print(f"identified in {time.perf_counter() - t0:.0f} s:", flush=True)
    for k in theta:
        print(f"  {k}: {theta[k]:.5g} (true {true_theta[k]:.5g}, {100 * (theta[k] / true_theta[k] - 1):+.2f} %)")
    search = control.ReferenceSearch()
    if args.rounds is not None:
        stages = tuple(eqx.tree_at(lambda st: st.rounds, st, args.rounds) for st in search.stages)
        search = eqx.tree_at(lambda s: s.stages, search, stages)
    results = dict(
        command="python experiments/acrobot_identified_tuning.py " + " ".join(sys.argv[1:] if argv is None else argv),
        true_changes=TRUE_CHANGES,
        theta_identified=theta,
        theta_true=true_theta,
        r2_from_coupling=r2_coupling,
        plants={},
    )
    for name, model in (("identified", identified), ("true", true), ("nominal", NOMINAL)):
        print(f"tuning on the {name} plant ...", flush=True)
        start = time.perf_counter()
        controller = control.design_swing_up(model, search=search)
        tuned = time.perf_counter() - start
        perf_model = control.performance(controller, plant=model)
        perf = control.performance(controller, plant=true)
        rob = control.robustness(controller, plant=true)
        controller.save(args.out / f"policy_{name}.npz")
        results["plants"][name] = dict(
            model={k: float(getattr(model, k)) for k in ("r1", "r2", "I1", "I2", "b1", "b2")},
            tuning_s=tuned,
            performance_on_its_model=perf_model.as_dict(),
            performance_on_true=perf.as_dict(),
            robustness_on_true=dict(score=rob.score, families=rob.table()),
        )
        print(
            f"  {name}: tuned in {tuned:.0f} s; performance on its model {perf_model.score:.3f}, on the true plant "
            f"{perf.score:.3f}; robustness on the true plant {rob.score:.3f} "
            f"{np.round(rob.family_scores * 100, 1).tolist()} [{time.perf_counter() - t0:.0f} s]",
            flush=True,
        )
        (args.out / "results.json").write_text(json.dumps(results, indent=2))
    print(f"wrote {args.out}")
    return results


def plant_base(p):
    """The seven base parameters of a `LeaderboardPlant` without rotor inertia."""
    m1, m2, l1, r1, r2, g = (float(getattr(p, k)) for k in ("m1", "m2", "l1", "r1", "r2", "g"))
    return dict(
        theta1=float(p.I1) + m2 * l1**2,
        theta2=float(p.I2),
        theta3=m2 * l1 * r2,
        theta4=g * (m1 * r1 + m2 * l1),
        theta5=g * m2 * r2,
        theta6=float(p.b1),
        theta7=float(p.b2),
    )


if __name__ == "__main__":
    main()
