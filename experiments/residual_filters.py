"""The one-step residuals of the *true* model on arms of three sizes: does the probe find structure where there is none?

The truth is the nominal two-link arm (`tests.hidden_cases.THETA`, 1 m and 1 kg links) scaled to links of `scale`
metres and kilograms (inertias as m l^2, gravity as m l, joint damping as m l^1.5), driven at both joints by the
battery's multisine (torques scaled as m l), integrated by scipy's DOP853 (`tests.hidden_cases.integrate`) at
100 Hz with the battery's noise (1e-3 rad, 1e-2 rad/s); 20 s of training, 10 s held out. For each residual window
(samples; the diagnosis uses `sg_window`, 0.1 s) it prints the probe's held-out R^2 and p (`structure_test`) and
the residuals' RMS against the model accelerations'.

    python experiments/residual_filters.py [--scales 1,0.3,0.05] [--windows 7,11,21] [--out DIR]

For another tree of dynax (the "before" column of docs/devdocs/outside_probes.md), run a copy placed in that tree's
`experiments/`: the script puts its own tree first on the path.
"""

import argparse
import json
import pathlib
import sys

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from dynax import DoublePendulum
import dynax._diagnose._residuals as residuals_module  # private: the window every reader looks up, set per row
from dynax.internal import acceleration_residuals, structure_test
from tests import hidden_cases


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scales", default="1,0.3,0.05")
    parser.add_argument("--windows", default="7,11,21")
    parser.add_argument("--out", default="experiments/results/residual_filters")
    args = parser.parse_args()
    rows = []
    chosen = residuals_module.sg_window
    for scale in (float(s) for s in args.scales.split(",")):
        theta, train, held_out, xs = hidden_cases.scaled_arm(scale)
        truth = DoublePendulum(**{f"theta{i + 1}": float(v) for i, v in enumerate(theta)})
        speed = np.sqrt((xs[:, 2:] ** 2).mean())
        for w in (int(s) for s in args.windows.split(",")):
            residuals_module.sg_window = lambda dt, w=w: w  # every reader of the window looks it up here
            try:
                r, _, predicted, _ = acceleration_residuals(truth, held_out)
                found = structure_test(truth, train, held_out)
            finally:
                residuals_module.sg_window = chosen
            row = {
                "scale_m": scale,
                "window": w,
                "rms_speed": float(speed),
                "r2": float(found.r2),
                "p": float(found.p_value),
                "significant": bool(found.significant),
                "residual_rms": float(np.sqrt((r**2).mean())),
                "acceleration_rms": float(np.sqrt((predicted**2).mean())),
            }
            rows.append(row)
            print(
                f"{scale:5.2f} m, window {w:2d}: R^2 {row['r2']:6.3f} (p {row['p']:.2g}), residual RMS "
                f"{row['residual_rms']:.3g} of the accelerations' {row['acceleration_rms']:.3g}",
                flush=True,
            )
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
