"""Where dynax's leave-one-run-out models lose to the lab's on the DFKI runs, and whether the runs agree on the
friction.

    python experiments/dfki_record_friction.py --out experiments/results/dfki_record_friction

Two measurements, about 3 minutes on 2 CPU cores:

1. **Which parameters carry the gap.** For each fold of
   `experiments/results/dfki_default_identification/results.json` (dynax's default identification
   fitted without the held-out run), the held-out run is simulated open loop (200 start samples,
   position RMSE at 0.1 / 0.25 / 0.5 s, as there) with dynax's model, with the lab's `model_3.0`, and
   with dynax's model with one group of its parameters replaced by the lab's (the lab's mapped into
   dynax's base parameters exactly, `dfki_default_identification.lab_model`). A group whose swap alone
   brings dynax's error to the lab's is where the two models differ on that run. The swaps read the
   held-out run's error, so they are a diagnosis, not a fit anyone could make without the run.
2. **Do the runs agree on the Coulomb friction?** `dynax.internal.record_friction` on the inverse-dynamics
   equations of `identify`'s least-squares stage (every setting chosen from the data), on all six runs
   and on each fold's five training runs: each run's Coulomb coefficients, from the whole run and from each of its four
   parts, and an analysis of variance of the runs against their four parts (see `dynax.internal.record_friction`).

Writes `OUT/record_friction.json` and `OUT/record_friction.png`.

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets.
"""

import argparse
import json
import pathlib

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
# The script's folder is on sys.path.
from dfki_default_identification import HORIZONS, lab_parameters, load, model_of, RUNS
from dfki_simulation import read_parameters  # noqa: E402
from dfki_torque_offsets import LORO  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax import held_out_error  # noqa: E402
import dynax.internal  # noqa: E402
from dynax.internal import compare_records  # noqa: E402

GROUPS = {
    "inertia (theta1, theta2, theta3, Ir2)": ("theta1", "theta2", "theta3", "Ir2"),
    "gravity (theta4, theta5)": ("theta4", "theta5"),
    "viscous friction (theta6, theta7)": ("theta6", "theta7"),
    "Coulomb friction (fc1, fc2)": ("fc1", "fc2"),
    "shoulder Coulomb fc1": ("fc1",),
    "elbow Coulomb fc2": ("fc2",),
    "all friction": ("theta6", "theta7", "fc1", "fc2"),
    "elbow rotor Ir2": ("Ir2",),
}


def friction_json(found) -> dict | None:
    return None if found is None else found.to_json()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    args = parser.parse_args(argv)
    folds = json.loads(LORO.read_text())["runs"]
    lab = lab_parameters(read_parameters("model_3.0"))
    records = {r: load(r) for r in RUNS}
    out = {"horizons_s": list(HORIZONS), "lab_parameters": lab, "folds": {}}

    _, everything = compare_records(dynax.DoublePendulum(), [records[r] for r in RUNS])
    out["all_runs"] = friction_json(everything)
    print("all six runs: " + (everything.note() or "the runs agree on the Coulomb friction"), flush=True)

    for run in RUNS:
        fold = folds[run]
        ours = fold["parameters"]
        swapped = {}
        for name, keys in GROUPS.items():
            mixed = dict(ours, **{k: lab[k] for k in keys})
            swapped[name] = list(held_out_error(model_of(mixed), [records[run]], HORIZONS).rmse)
        _, training = compare_records(dynax.DoublePendulum(), [records[r] for r in RUNS if r != run])
        out["folds"][run] = {
            "dynax": fold["dynax"],
            "lab_model_3.0": fold["lab_model_3.0"],
            "dynax_with_the_labs": swapped,
            "training_record_friction": friction_json(training),
        }
        print(
            f"held out {run}: dynax "
            + " ".join(f"{v:.4f}" for v in fold["dynax"])
            + " | lab "
            + " ".join(f"{v:.4f}" for v in fold["lab_model_3.0"]),
            flush=True,
        )
        for name, rmse in swapped.items():
            print(f"    with the lab's {name:40s} " + " ".join(f"{v:.4f}" for v in rmse), flush=True)
        if training is not None:
            print(
                "    training runs' Coulomb friction: "
                + "; ".join(
                    f"{c} " + ", ".join(f"{v:.3f}" for v in training.values[:, k]) + f" (p = {training.p_value[k]:.2g})"
                    for k, c in enumerate(training.columns)
                ),
                flush=True,
            )

    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "record_friction.json").write_text(json.dumps(out, indent=2) + "\n")

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    if everything is not None:
        x = np.arange(len(RUNS))
        for k, (ax, column) in enumerate(zip(axes, everything.columns)):
            n_parts = everything.parts.shape[1]
            width = 0.8 / n_parts
            for h in range(n_parts):
                ax.bar(
                    x + (h - (n_parts - 1) / 2) * width,
                    everything.parts[:, h, k],
                    width,
                    color=f"C{h}",
                    label=f"part {h + 1} of {n_parts} of the run",
                )
            ax.plot(x, everything.values[:, k], "kD", label="the run's value")
            ax.axhline(everything.shared[k], color="k", lw=1, label="one value for all runs")
            ax.axhline(lab[column], color="r", ls="--", lw=1, label="lab model_3.0 (output error)")
            ax.set_xticks(x, [f"run {r}" for r in RUNS])
            ax.set(
                ylabel=f"{column} [N m]",
                title=f"{column}: F = {everything.f_statistic[k]:.3g}, p = {everything.p_value[k]:.2g}",
            )
        axes[0].legend(fontsize=8)
    fig.suptitle(
        "DFKI double pendulum: Coulomb friction per run, least-squares equations (DFKI RIC Underactuated Robotics Lab)"
    )
    fig.tight_layout()
    fig.savefig(args.out / "record_friction.png", dpi=110)
    print(f"wrote {args.out / 'record_friction.json'} and {args.out / 'record_friction.png'}")


if __name__ == "__main__":
    main()
