"""The DFKI runs simulated with the input timing `identify` fitted, for dynax's models and the lab's.

    python experiments/dfki_input_timing.py --out experiments/results/dfki_input_timing

`identify`'s output-error refinement fits, with the model, the time by which the recorded torques act
after their samples (`stages["output_error"]["input_timing"]`): on the DFKI runs about 2 ms *before*
them, where the contract's zero-order hold applies each sample over the following interval. If that
latency belongs to the recordings (a driver's filter, the bus cycle) and not to dynax's fit, applying
it to a held-out run must help the lab's `model_3.0` too, which was fitted without it. For each
leave-one-run-out fold of `experiments/results/dfki_default_identification/results.json`, the
held-out run's torque is read `latency` later (linear interpolation: the torque held over
`[t_k, t_k+1)` is the recording at `t_k + dt/2 - latency`) and both models are simulated open loop
from the same 200 start samples as there; position RMSE at 0.1, 0.25 and 0.5 s. Writes
`timing.json`. About 30 s.

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets.
"""

import argparse
import json
import pathlib

import jax

jax.config.update("jax_enable_x64", True)

from dfki_default_identification import HORIZONS, lab_model, load  # noqa: E402  (the script's folder is on sys.path)
from dfki_simulation import read_parameters  # noqa: E402
from dfki_torque_offsets import LORO, loro_model  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax import held_out_error  # noqa: E402


def read_later(record: dynax.Trajectory, latency: float) -> dynax.Trajectory:
    """`record` whose input held over each interval is the recording at the interval's middle less `latency`."""
    ts, us = np.asarray(record.ts), np.asarray(record.us)
    middle = ts + 0.5 * float(np.median(np.diff(ts))) - latency
    timed = np.stack([np.interp(middle, ts, us[:, j]) for j in range(us.shape[1])], axis=1)
    return dynax.Trajectory(
        record.ts, record.xs, jnp.asarray(timed), record.state_names, record.input_names, record.system, record.source
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    args = parser.parse_args(argv)
    folds = json.loads(LORO.read_text())["runs"]
    lab = lab_model(read_parameters("model_3.0"))
    out = {"horizons_s": list(HORIZONS), "runs": {}}
    for run, fold in sorted(folds.items()):
        latency = fold["input_timing"]["latency_s"]
        record = load(run)
        timed = read_later(record, latency)
        entry = {
            "latency_s": latency,
            "dynax_recorded": [
                float(v) for v in held_out_error(loro_model(fold["parameters"]), [record], HORIZONS).rmse
            ],
            "dynax_timed": [float(v) for v in held_out_error(loro_model(fold["parameters"]), [timed], HORIZONS).rmse],
            "lab_recorded": [float(v) for v in held_out_error(lab, [record], HORIZONS).rmse],
            "lab_timed": [float(v) for v in held_out_error(lab, [timed], HORIZONS).rmse],
        }
        out["runs"][run] = entry
        print(
            f"run {run}: latency {1e3 * latency:+.1f} ms | "
            + " | ".join(
                f"{k} " + "/".join(f"{v:.4f}" for v in entry[k])
                for k in ("dynax_recorded", "dynax_timed", "lab_recorded", "lab_timed")
            ),
            flush=True,
        )
    helped = sum(t < r for e in out["runs"].values() for t, r in zip(e["lab_timed"], e["lab_recorded"]))
    print(f"the fitted timing lowers the lab model's error in {helped} of {3 * len(out['runs'])} cells")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "timing.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.out / 'timing.json'}")


if __name__ == "__main__":
    main()
