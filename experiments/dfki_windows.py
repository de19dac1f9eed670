"""Which windows carry the open-loop error on the DFKI runs, and what holds the swing-up run's pendulum upright.

    python experiments/dfki_windows.py --out experiments/results/dfki_windows

Under a minute on 2 CPU cores. Three measurements, for each fold of
`experiments/results/dfki_default_identification/results.json` (dynax's default identification fitted
without the held-out run) against the lab's `model_3.0`:

1. **Where the error is.** Each held-out run is simulated open loop from 200 start samples (as in that
   table); `held_out_error` gives the RMSE, the median window error and the windows that carry the RMSE
   (`SimulationError.concentrated`). On run 12 the windows are also pooled by phase: started while the
   torques pump energy in (before 3 s), and from the last swing on (3 s and after: the pendulum
   reaches the top at about 4.2 s and rests there to the end).
2. **What holds it there.** Over the rest at the top (4.75 s to the end, both joints slower than the
   driver's velocity noise), the mean measured torque against the gravity torque the lab's model
   computes at the measured configuration: what the torque holds that gravity does not.
3. **Another start state.** The windows start from the measured state, the driver's noisy velocity
   included (about 0.1 rad/s where the pendulum rests). Started instead from the
   velocities of a local cubic fit of the encoder positions where that estimate is the better one
   (`with_velocities_from_positions`, what `diagnose` does by default), both models are compared
   again on every run: does the verdict hang on the start state?
4. **A what-if, not a fit.** Both models with a static friction (a Stribeck term: the friction rises
   from the Coulomb value to `fs` below about 0.05 rad/s) at the torques held at the top, read
   off run 12 itself. No training run rests (at most 6 % of their samples are below 0.1 rad/s, all
   of them reversals), so no fit on them could find it; it says what part of run 12's error the
   models' missing friction at rest makes.

Writes `OUT/windows.json` and `OUT/windows.png` (run 12's window error at 0.5 s against start time,
both models, under its positions).

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets.
"""

import argparse
import json
import pathlib
from typing import ClassVar

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
# The script's folder is on sys.path.
from dfki_default_identification import HORIZONS, lab_parameters, load, model_of, RUNS
from dfki_simulation import read_parameters  # noqa: E402
from dfki_torque_offsets import LORO  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax import AbstractJointTerm, held_out_error  # noqa: E402
from dynax.internal import float_scalar, with_velocities_from_positions  # noqa: E402

PHASE_S = 3.0  # run 12: energy pumped in before; the last swing, the top and the rest after
BALANCE_S = 4.75  # run 12: held at the top from here to the end
STRIBECK_VELOCITY = 0.05  # rad/s, below the driver's velocity noise at rest (about 0.1 rad/s)


class StaticFriction(AbstractJointTerm):
    """The friction at rest above the Coulomb value: $-(f_s - f_c) e^{-(\\dot q / v_s)^2} \\tanh(\\dot q / 0.01)$
    (a Stribeck curve; Armstrong-Hélouvry, Dupont and Canudas de Wit 1994). For this what-if only."""

    joint: int = eqx.field(static=True)
    coefficient: jax.Array
    cause: ClassVar[str] = "static_friction"
    prefix: ClassVar[str] = "fs"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1

    def __init__(self, joint, excess):
        self.joint = joint
        self.coefficient = float_scalar(excess)

    def force(self, q, dq):
        return -self.coefficient * jnp.exp(-((dq / STRIBECK_VELOCITY) ** 2)) * jnp.tanh(dq / 0.01)


def phases(error, record) -> dict:
    """RMSE per horizon over run 12's windows (`error`, its `simulation_error`) started before `PHASE_S` and from it
    on."""
    squared = np.asarray(error.window_mse)
    t0 = np.asarray(record.ts)[np.asarray(error.starts)]
    return {
        name: [float(v) for v in np.sqrt(squared[mask].mean(axis=0))]
        for name, mask in (("before", t0 < PHASE_S), ("after", t0 >= PHASE_S))
    }


def held_torque(model, record) -> dict:
    """Mean measured torque over the rest at the top, the gravity torque at the measured configuration, and
    the torque left that gravity does not explain (per joint, N m)."""
    ts, xs, us = (np.asarray(a) for a in (record.ts, record.xs, record.us))
    rest = ts >= BALANCE_S
    gravity = np.asarray(jax.vmap(lambda q: model.system.bias_force(q, jnp.zeros(2)))(jnp.asarray(xs[rest, :2])))
    measured = us[rest].mean(axis=0)
    return {
        "measured": measured.tolist(),
        "gravity": gravity.mean(axis=0).tolist(),
        "held": (measured - gravity.mean(axis=0)).tolist(),
        "speed_rms": np.sqrt((xs[rest, 2:] ** 2).mean(axis=0)).tolist(),
        "from_s": BALANCE_S,
        "to_s": float(ts[-1]),
    }


def with_static_friction(p: dict, fs) -> dynax.AbstractSystem:
    model = model_of(p)
    excess = [max(f - p[f"fc{j + 1}"], 0.0) for j, f in enumerate(fs)]
    return dynax.Extended(model.system, model.terms + tuple(StaticFriction(j, e) for j, e in enumerate(excess)))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    args = parser.parse_args(argv)
    folds = json.loads(LORO.read_text())["runs"]
    lab_p = lab_parameters(read_parameters("model_3.0"))
    lab = model_of(lab_p)
    out = {"horizons_s": list(HORIZONS), "runs": {}}
    records = {run: load(run) for run in RUNS}
    for run, record in records.items():
        smoothed, _, replaced = with_velocities_from_positions(record)
        entry = {}
        for name, model in (("dynax", model_of(folds[run]["parameters"])), ("lab", lab)):
            found = held_out_error(model, [record], HORIZONS)
            entry[name] = {
                "rmse": list(found.rmse),
                "median": list(found.median),
                "concentrated": found.concentrated.get(f"trajectory_{run}.csv", []),
                "rmse_velocities_from_positions": list(held_out_error(model, [smoothed], HORIZONS).rmse),
            }
        entry["velocities_from_positions"] = list(replaced)
        out["runs"][run] = entry
        print(
            f"run {run}: "
            + " | ".join(
                f"{k} RMSE {' '.join(f'{v:.4f}' for v in e['rmse'])} median {' '.join(f'{v:.4f}' for v in e['median'])}"
                + "".join(
                    f" [{c['horizon_s']:g} s: half from {c['windows']}/{c['of']} windows at "
                    f"{c['from_s']:.2f}-{c['to_s']:.2f} s]"
                    for c in e["concentrated"]
                )
                for k, e in entry.items()
                if k in ("dynax", "lab")
            ),
            flush=True,
        )
    cells = [
        (d <= b, d / b)
        for r in RUNS
        for d, b in zip(
            out["runs"][r]["dynax"]["rmse_velocities_from_positions"],
            out["runs"][r]["lab"]["rmse_velocities_from_positions"],
        )
    ]
    out["velocities_from_positions"] = {
        "cells_at_or_below_lab": sum(c for c, _ in cells),
        "geometric_mean_ratio": float(np.exp(np.mean(np.log([q for _, q in cells])))),
    }
    for run in RUNS:
        e = out["runs"][run]
        print(
            f"run {run}, started from velocities of the positions "
            f"({', '.join(e['velocities_from_positions']) or 'none replaced'}): "
            + " | ".join(
                f"{k} {' '.join(f'{v:.4f}' for v in e[k]['rmse_velocities_from_positions'])}" for k in ("dynax", "lab")
            )
        )
    print(
        f"started from velocities of the positions: dynax at or below the lab in "
        f"{out['velocities_from_positions']['cells_at_or_below_lab']} of {len(cells)} cells, geometric mean ratio "
        f"{out['velocities_from_positions']['geometric_mean_ratio']:.4f}"
    )

    swing_up = records["12"]
    dynax_12 = model_of(folds["12"]["parameters"])
    windows_12 = {
        "dynax": dynax.simulation_error(dynax_12, swing_up, HORIZONS),
        "lab": dynax.simulation_error(lab, swing_up, HORIZONS),
    }
    held = held_torque(lab, swing_up)
    fs = [abs(v) for v in held["held"]]
    what_if = {
        name: {
            "static_friction": fs,
            "rmse": [float(v) for v in dynax.simulation_error(with_static_friction(p, fs), swing_up, HORIZONS).rmse],
        }
        for name, p in (("dynax", folds["12"]["parameters"]), ("lab", lab_p))
    }
    one_window = {}
    k = int(np.searchsorted(np.asarray(swing_up.ts), 5.0))
    n = int(round(HORIZONS[-1] / swing_up.dt)) + 1
    for friction, scale in (("none", 0.0), ("at the held torques", 1.0), ("at twice the held torques", 2.0)):
        model = lab if scale == 0.0 else with_static_friction(lab_p, [scale * f for f in fs])
        for start, x0 in (("measured", swing_up.xs[k]), ("at rest", swing_up.xs[k].at[2:].set(0.0))):
            xs = np.asarray(dynax.simulate(model, x0, swing_up.ts[k : k + n], swing_up.us[k : k + n]).xs)
            one_window[f"{start} start, static friction {friction}"] = float(
                np.sqrt(np.mean((xs[-1, :2] - np.asarray(swing_up.xs[k + n - 1, :2])) ** 2))
            )
    out["run_12"] = {
        "one_window_from_5s": {"start_velocity": np.asarray(swing_up.xs[k, 2:]).tolist(), "error": one_window},
        "phases": {name: phases(error, swing_up) for name, error in windows_12.items()},
        "phase_s": PHASE_S,
        "balancing": held,
        "with_static_friction": what_if,
        "stribeck_velocity": STRIBECK_VELOCITY,
    }
    for name, p in out["run_12"]["phases"].items():
        print(
            f"run 12, {name}: windows before {PHASE_S:g} s "
            + " ".join(f"{v:.4f}" for v in p["before"])
            + f" | from {PHASE_S:g} s on "
            + " ".join(f"{v:.4f}" for v in p["after"])
        )
    print(
        "run 12 at rest at the top: torque measured "
        + " ".join(f"{v:+.3f}" for v in held["measured"])
        + " N m, gravity "
        + " ".join(f"{v:+.3f}" for v in held["gravity"])
        + " N m, speed rms "
        + " ".join(f"{v:.3f}" for v in held["speed_rms"])
        + " rad/s"
    )
    for name, w in what_if.items():
        print(
            f"run 12 with static friction {fs[0]:.3f}, {fs[1]:.3f} N m ({name}): "
            + " ".join(f"{v:.4f}" for v in w["rmse"])
        )

    print(
        f"one window from 5.0 s, lab's model, error at {HORIZONS[-1]:g} s (measured start velocity "
        + " ".join(f"{v:+.3f}" for v in out["run_12"]["one_window_from_5s"]["start_velocity"])
        + " rad/s):"
    )
    for name, value in one_window.items():
        print(f"  {name}: {value:.4f} rad")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "windows.json").write_text(json.dumps(out, indent=2) + "\n")
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name, error in (("dynax (fitted without run 12)", windows_12["dynax"]), ("lab model_3.0", windows_12["lab"])):
        t0 = np.asarray(swing_up.ts)[np.asarray(error.starts)]
        bottom.semilogy(t0, np.sqrt(np.asarray(error.window_mse)[:, -1]), ".", label=name)
    bottom.axvline(PHASE_S, color="0.5", ls="--")
    bottom.set(xlabel="window start [s]", ylabel=f"position error at {HORIZONS[-1]:g} s [rad]")
    bottom.legend(fontsize=8)
    top.plot(np.asarray(swing_up.ts), np.asarray(swing_up.xs)[:, :2], lw=1)
    top.legend(["q1", "q2"], fontsize=8)
    top.set(ylabel="position [rad]", title="DFKI run 12: open-loop error of each window, under the motion")
    fig.tight_layout()
    fig.savefig(args.out / "windows.png", dpi=110)
    print(f"wrote {args.out / 'windows.json'} and {args.out / 'windows.png'}")


if __name__ == "__main__":
    main()
