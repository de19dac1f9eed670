"""Simulate the Drake-default model and the DFKI lab's identified models against a DFKI rig run.

    python experiments/dfki_simulation.py --out docs/tutorials/figures [--run 00]

Writes `dfki_simulation.json` (RMSE against horizon per model) and `dfki_simulation.png` (measured
against simulated; error against horizon). Data: DFKI RIC Underactuated Robotics Lab, double_pendulum
design C.0 (BSD-3-Clause), read from ../shared/datasets.
"""

import argparse
import json
import math
import os
import pathlib

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[1]
# `DYNAX_SHARED` names the shared folder where it is not beside the checkout (a git worktree elsewhere).
DFKI = pathlib.Path(os.environ.get("DYNAX_SHARED", REPO.parent / "shared")) / "datasets" / "dfki_double_pendulum"
MAPPING = {
    "t": "time",
    "q1": "pos_meas1",
    "q2": "pos_meas2",
    "dq1": "vel_meas1",
    "dq2": "vel_meas2",
    "tau1": "tau_meas1",
    "tau2": "tau_meas2",
}
HORIZONS = (0.05, 0.1, 0.25, 0.5, 1.0)


def read_parameters(model: str) -> dict[str, float]:
    """The lab's `model_parameters.yml` (flat `key: value` lines)."""
    text = (DFKI / "identified_parameters" / "design_C.0" / model / "model_parameters.yml").read_text()
    return {k.strip(): float(v) for k, v in (line.split(":", 1) for line in text.splitlines() if ":" in line)}


def lab_model(p: dict[str, float], *, with_friction_and_rotor: bool) -> dynax.AbstractSystem:
    """The lab's model in dynax terms: rigid body in base parameters, plus rotor inertia and friction.

    The lab's friction is `b dq + cf atan(100 dq)`, which saturates at `cf pi / 2`: dynax's
    `CoulombFriction` (a tanh with the same 0.01 rad/s scale) gets `fc = cf pi / 2`. Its rotor
    inertia adds `gr^2 Ir + Ir` to M11, `gr^2 Ir` to M22 and `-gr Ir` to M12; dynax's `RotorInertia`
    adds to the diagonal only. The off-diagonal term is about 1 % of M12, yet on the elbow-only run 03 it
    carries most of the prediction: 0.043 rad at 0.25 s without it, 0.025 with it (mapped exactly, as
    `dfki_default_identification.lab_model` does; docs/devdocs/dfki_loro.md).
    """
    rigid = dynax.DoublePendulum.from_physical(
        m1=p["m1"],
        m2=p["m2"],
        l1=p["l1"],
        lc1=p["r1"],
        lc2=p["r2"],
        I1=p["I1"],
        I2=p["I2"],
        b1=p["b1"],
        b2=p["b2"],
        g=p["g"],
    )
    if not with_friction_and_rotor:
        return rigid
    gr, ir = p["gr"], p["Ir"]
    terms = (
        dynax.RotorInertia(joint=0, inertia=gr**2 * ir + ir),
        dynax.RotorInertia(joint=1, inertia=gr**2 * ir),
        dynax.CoulombFriction(joint=0, fc=p["cf1"] * math.pi / 2),
        dynax.CoulombFriction(joint=1, fc=p["cf2"] * math.pi / 2),
    )
    return dynax.Extended(rigid, terms)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--run", default="00", help="trajectory number (00, 01, 02, 03, 05, 12)")
    parser.add_argument("--window", type=float, default=2.0, help="seconds shown in the measured/simulated panel")
    args = parser.parse_args(argv)

    run = dynax.load_trajectory(DFKI / "sys_id" / f"trajectory_{args.run}.csv", "double_pendulum", mapping=MAPPING)
    print(
        f"loaded {run.source}: {len(run)} samples over {run.duration:.2f} s, "
        f"median dt {run.dt * 1e3:.2f} ms ({'uniform' if run.is_uniform else 'irregular, kept as recorded'})"
    )
    models = {
        "Drake defaults": dynax.DoublePendulum(),
        "DFKI model_3.1 (rigid body)": lab_model(read_parameters("model_3.1"), with_friction_and_rotor=False),
        "DFKI model_3.0 (+ friction, rotor)": lab_model(read_parameters("model_3.0"), with_friction_and_rotor=True),
    }
    n_show = int(np.searchsorted(np.asarray(run.ts), float(run.ts[0]) + args.window))
    window = run.slice(0, n_show)
    results, shown = {}, {}
    for name, model in models.items():
        error = dynax.simulation_error(model, run, HORIZONS)
        results[name] = {
            "horizons_s": list(HORIZONS),
            "rmse_rad": [float(r) for r in error.rmse],
            "diverged_fraction": float(error.diverged_fraction),
        }
        print(f"{name:38s} RMSE " + "  ".join(f"{h:g}s: {r:.3g} rad" for h, r in zip(HORIZONS, error.rmse)))
        x0 = jnp.zeros(model.n_states).at[:4].set(window.x0)
        shown[name] = dynax.simulate(model, x0, window.ts, window.us, throw=False).xs[:, :4]

    args.out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    t = np.asarray(window.ts)
    for j, ax in enumerate(axes[:2]):
        ax.plot(t, np.asarray(window.xs[:, j]), "k", lw=2, label="measured")
        for name, xs in shown.items():
            ax.plot(t, np.asarray(xs[:, j]), label=name)
        ax.set(xlabel="t [s]", ylabel=f"q{j + 1} [rad]", title=f"q{j + 1}: measured and simulated from t = 0")
    axes[0].legend(fontsize=8)
    for name, r in results.items():
        axes[2].semilogy(HORIZONS, r["rmse_rad"], "o-", label=name)
    axes[2].set(xlabel="horizon [s]", ylabel="RMSE of q1, q2 [rad]", title="open-loop error against horizon")
    axes[2].legend(fontsize=8)
    fig.suptitle(f"DFKI double pendulum, trajectory_{args.run} (DFKI RIC Underactuated Robotics Lab)")
    fig.tight_layout()
    fig.savefig(args.out / "dfki_simulation.png", dpi=110)
    (args.out / "dfki_simulation.json").write_text(json.dumps({"run": args.run, "models": results}, indent=2) + "\n")
    print(f"wrote {args.out / 'dfki_simulation.png'} and {args.out / 'dfki_simulation.json'}")


if __name__ == "__main__":
    main()
