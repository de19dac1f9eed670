"""Per-run torque offsets and angle zeros on the DFKI double pendulum, and how much of the held-out
simulation error they carry.

    python experiments/dfki_torque_offsets.py --out experiments/results/dfki_torque_offsets

The inverse-dynamics least-squares problem of `identify(DoublePendulum(), runs, Dynamic(),
friction="coulomb")` (every setting chosen from the data, as `identify` chooses it) is solved on all
six `sys_id` runs at once with one nuisance column per run, joint and half of the run: a constant
torque that adds to what that run's recorded torque says (a sensor or current offset), the base
parameters shared; `dynax.internal.record_offsets` does this, and `identify` reports it
as `record_offsets`. An offset of the sensor stays the same within a run, model error need not.

Then each run is simulated open loop (200 start samples, position RMSE at 0.1 / 0.25 / 0.5 s, as
`dfki_default_identification.py` does) with its recorded torques and with its torques less its
offset, for the lab's `model_3.0` and for dynax's leave-one-run-out model of that run (the
parameters in `experiments/results/dfki_default_identification/results.json`, fitted without the
run). The corrected rows use the held-out run's own offset, so they are an oracle: what a model
would gain if the run's offset were known, not something either model can predict.

The same for the runs' angle zeros (`dynax.internal.record_angle_zeros`, one zero per
run and joint fitted with the base parameters, as `identify` fits them by default): the equation
error with them against that with the torque offsets, each half's zeros, and each run simulated
with its angles read from its own zero (positions less the zeros, velocities and torques as
recorded), again an oracle.

Writes `OUT/offsets.json` and `OUT/offsets.png`.
"""

import argparse
import json
import pathlib

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
from dfki_default_identification import HORIZONS, lab_model, load, RUNS  # noqa: E402
from dfki_default_identification import model_of as loro_model
from dfki_simulation import read_parameters  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax import held_out_error  # noqa: E402
import dynax.internal  # noqa: E402
from dynax.internal import (  # noqa: E402
    least_squares,
    record_angle_zeros,
    record_offsets,  # noqa: E402
    stacked_equations,
)
from dynax.internal import shifted as shifted_angles

LORO = pathlib.Path(__file__).parent / "results" / "dfki_default_identification" / "results.json"


def shifted(record, offset):
    us = jnp.asarray(np.asarray(record.us) - np.asarray(offset)[None, :])
    return dynax.Trajectory(
        record.ts, record.xs, us, record.state_names, record.input_names, record.system, record.source
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, type=pathlib.Path)
    args = parser.parse_args(argv)
    records = {r: load(r) for r in RUNS}
    # The least-squares stage `identify` builds (settings chosen from the data), with and without the offsets.
    _, a, y, _, names, _, _, _, counts, _ = stacked_equations(
        dynax.DoublePendulum(), [records[r] for r in RUNS], dynax.Dynamic(offsets=True), "coulomb", None, None
    )
    theta0 = np.asarray(least_squares(a, y, names=names).value)
    found = record_offsets(a, y, counts, ("q1", "q2"))
    error0 = float(np.linalg.norm(np.asarray(a) @ theta0 - np.asarray(y)) / np.linalg.norm(np.asarray(y)))
    print("base parameters, no offsets:   " + " ".join(f"{n}={v:.4g}" for n, v in zip(names, theta0)))
    print("base parameters, run offsets:  " + " ".join(f"{n}={v:.4g}" for n, v in zip(names, found.estimate)))
    print(
        f"relative equation error {error0:.4f} -> {found.relative_error:.4f}; F = "
        + ", ".join(f"{j} {f:.3g} (p = {p:.2g})" for j, f, p in zip(found.joints, found.f_statistic, found.p_value))
    )
    zeros = record_angle_zeros(dynax.DoublePendulum(), [records[r] for r in RUNS], dynax.Dynamic(), "coulomb", None)
    print(
        f"angle zeros: relative equation error {zeros.relative_error:.4f} (torque offsets "
        f"{zeros.force_relative_error:.4f}); {zeros.steps} Gauss-Newton steps"
    )
    lab = lab_model(read_parameters("model_3.0"))
    loro = json.loads(LORO.read_text())["runs"] if LORO.exists() else {}
    table = {}
    for i, run in enumerate(RUNS):
        offset = found.offsets[i]
        entry = {
            "offset": offset.tolist(),
            "offset_halves": found.halves[i].tolist(),
            "angle_zero": zeros.values[i].tolist(),
            "angle_zero_halves": zeros.halves[i].tolist(),
        }
        corrected = shifted_angles(records[run], (0, 1), zeros.values[i])
        models = {"lab_model_3.0": lab}
        if run in loro:
            models["dynax_loro"] = loro_model(loro[run]["parameters"])
        for label, model in models.items():
            entry[label] = {
                "recorded": list(held_out_error(model, [records[run]], HORIZONS).rmse),
                "offset_removed": list(held_out_error(model, [shifted(records[run], offset)], HORIZONS).rmse),
                "angles_from_own_zero": list(held_out_error(model, [corrected], HORIZONS).rmse),
            }
        table[run] = entry
        h = found.halves[i]
        z = zeros.halves[i]
        line = (
            f"run {run}: offset tau1 {offset[0]:+.3f} N m (halves {h[0, 0]:+.3f} / {h[1, 0]:+.3f}),"
            f" tau2 {offset[1]:+.3f} (halves {h[0, 1]:+.3f} / {h[1, 1]:+.3f}); angle zeros"
            f" q1 {zeros.values[i, 0]:+.4f} rad (halves {z[0, 0]:+.4f} / {z[1, 0]:+.4f}),"
            f" q2 {zeros.values[i, 1]:+.4f} (halves {z[0, 1]:+.4f} / {z[1, 1]:+.4f})"
        )
        for label in models:
            line += (
                f" | {label} "
                + "/".join(f"{v:.4f}" for v in entry[label]["recorded"])
                + " -> "
                + "/".join(f"{v:.4f}" for v in entry[label]["offset_removed"])
                + " (offset) or "
                + "/".join(f"{v:.4f}" for v in entry[label]["angles_from_own_zero"])
                + " (angle zero)"
            )
        print(line, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    result = {
        "horizons_s": list(HORIZONS),
        "names": list(names),
        "theta_without_offsets": theta0.tolist(),
        "theta_with_offsets": found.estimate.tolist(),
        "relative_equation_error": {"without_offsets": error0, "with_offsets": found.relative_error},
        "record_offsets": found.to_json(),
        "angle_zeros": zeros.to_json(),
        "runs": table,
    }
    (args.out / "offsets.json").write_text(json.dumps(result, indent=2) + "\n")

    fig, axes = plt.subplots(1, 3, figsize=(16, 4))
    x = np.arange(len(RUNS))
    ax = axes[0]
    for k, (dx, label) in enumerate(((-0.2, "first half"), (0.2, "second half"))):
        ax.bar(x + dx, [table[r]["offset_halves"][k][0] for r in RUNS], 0.4, label=label)
    ax.set_xticks(x, [f"run {r}" for r in RUNS])
    ax.set(ylabel="offset on the shoulder torque [N m]", title="per-run torque offset (each half of the run)")
    ax.axhline(0, color="k", lw=0.6)
    ax.legend(fontsize=8)
    ax = axes[1]
    for j, joint in enumerate(("q1", "q2")):
        for k, half in enumerate(("first half", "second half")):
            ax.bar(
                x + (2 * j + k - 1.5) * 0.2,
                [table[r]["angle_zero_halves"][k][j] for r in RUNS],
                0.2,
                label=f"{joint}, {half}",
            )
    ax.set_xticks(x, [f"run {r}" for r in RUNS])
    ax.set(ylabel="angle zero [rad]", title="per-run angle zeros (each half of the run)")
    ax.axhline(0, color="k", lw=0.6)
    ax.legend(fontsize=7)
    ax = axes[2]
    for dx, key, sub, label in (
        (-0.35, "lab_model_3.0", "recorded", "lab, as recorded"),
        (-0.25, "lab_model_3.0", "offset_removed", "lab, torque offset removed"),
        (-0.15, "lab_model_3.0", "angles_from_own_zero", "lab, angles from the run's zero"),
        (0.05, "dynax_loro", "recorded", "dynax (run left out), as recorded"),
        (0.15, "dynax_loro", "offset_removed", "dynax, torque offset removed"),
        (0.25, "dynax_loro", "angles_from_own_zero", "dynax, angles from the run's zero"),
    ):
        if all(key in table[r] for r in RUNS):
            ax.bar(x + dx, [table[r][key][sub][-1] for r in RUNS], 0.1, label=label)
    ax.set_xticks(x, [f"run {r}" for r in RUNS])
    ax.set(yscale="log", ylabel=f"position RMSE at {HORIZONS[-1]:g} s [rad]", title="open-loop simulation of each run")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out / "offsets.png", dpi=120)


if __name__ == "__main__":
    main()
