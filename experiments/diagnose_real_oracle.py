"""Was there a gain for refit mode to find? The lab's model against the refitted rigid-body model on held-out runs.

For each split of `diagnose_real_splits.py`, refit mode's nominal model (theta1..theta5 refitted on the
training runs, model 3.1's zero friction kept: `Refit()`'s default since 2026-11-25; theta1..theta7
before) and the DFKI lab's `model_3.0` (rotor inertia, Coulomb and viscous friction at both
joints; fitted by the lab on all six runs, so in-sample everywhere) are simulated on the held-out runs
from the same windows and start states (velocities from the encoder positions, as `diagnose` takes
them), and their open-loop position RMSE compared at several horizons.

    python experiments/diagnose_real_oracle.py ../shared/datasets experiments/results/diagnose_real_splits [S1,S2,S3,S4]

Writes `OUT/oracle.json`.
"""

import json
import pathlib
import sys

import jax

jax.config.update("jax_enable_x64", True)

import dynax  # noqa: E402
from dynax import diagnose, Refit, Selection  # noqa: E402
from dynax.internal import with_velocities_from_positions  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from dfki_simulation import lab_model, read_parameters  # noqa: E402
from diagnose_real_splits import load, nominal_model_3_1, SPLITS  # noqa: E402

HORIZONS = (0.1, 0.15, 0.2, 0.25, 0.3, 0.5)

if __name__ == "__main__":
    data, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    splits = sys.argv[3].split(",") if len(sys.argv) > 3 else list(SPLITS)
    lab = lab_model(read_parameters("model_3.0"), with_friction_and_rotor=True)
    results = []
    for name in splits:
        train_runs, val_runs = SPLITS[name]
        report = diagnose(
            nominal_model_3_1(),
            [load(data, r) for r in train_runs],
            [load(data, r) for r in val_runs],
            mode=Refit(),
            progress=False,
            selection=Selection(discovery=False),
        )
        for run in val_runs:
            record = with_velocities_from_positions(load(data, run))[0]
            refit = dynax.simulation_error(report.nominal_model, record, HORIZONS, stride=10).rmse
            ours = dynax.simulation_error(lab, record, HORIZONS, stride=10).rmse
            row = {
                "split": name,
                "held_out": run,
                "reference_horizon_s": report.reference_horizon_s,
                "horizons_s": list(HORIZONS),
                "refit_rmse": [float(v) for v in refit],
                "lab_rmse": [float(v) for v in ours],
                "lab_gain_over_refit": [float(1 - a / b) for a, b in zip(ours, refit)],
            }
            print(json.dumps(row), flush=True)
            results.append(row)
    out.mkdir(parents=True, exist_ok=True)
    (out / "oracle.json").write_text(json.dumps(results, indent=1))
