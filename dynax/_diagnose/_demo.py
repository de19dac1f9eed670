"""The demo's main job: hide an effect in acrobot data, then show what the nominal simulation gets wrong."""

import pathlib

import numpy as np

from .._model._extensions import Extended
from .._model._two_link import Acrobot
from ._figures import plot_error_vs_horizon, plot_measured_vs_simulated
from ._rollouts import horizon_errors, position_rmse
from ._synthetic import synthetic_trajectory

DEMO_HORIZONS_S = (0.1, 0.25, 0.5, 1.0, 2.0)
# The rig the data comes from differs a little from the datasheet model the user starts with.
DEMO_TRUTH_PHYSICAL = dict(m1=1.05, m2=0.97, lc2=1.02, Ic2=0.32)


def demo_data(term, *, seed: int, train_s: float = 20.0, validation_s: float = 10.0):
    """Training and validation records of the demo's truth acrobot with `term` hidden in it."""
    truth = Extended(Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL), (term,))
    kwargs = dict(dt=0.01, amplitude=2.0, system_name="acrobot")
    train = synthetic_trajectory(truth, duration=train_s, seed=2 * seed + 1, source="train.csv", **kwargs)
    validation = synthetic_trajectory(truth, duration=validation_s, seed=2 * seed + 2, source="validation.csv", **kwargs)
    return truth, train, validation


def run_demo(term, *, seed: int, out: pathlib.Path, save_trajectory, write_json) -> str:
    """Generate the data, simulate the nominal model against it, write the outputs; return the summary."""
    out = pathlib.Path(out)
    truth, train, validation = demo_data(term, seed=seed)
    save_trajectory(train, out / "train.csv")
    save_trajectory(validation, out / "validation.csv")
    nominal = Acrobot()
    steps, _, errors, _ = horizon_errors(nominal, validation, DEMO_HORIZONS_S)
    rmse = position_rmse(errors, steps, [0, 1])
    write_json(
        out / "sim_error.json",
        {"system": "acrobot", "model": "nominal", "data": "validation.csv",
         "sim_error": {"horizons_s": list(DEMO_HORIZONS_S), "rmse": rmse}},
    )
    plot_measured_vs_simulated(validation, {"nominal": nominal}, out / "measured_vs_simulated.png")
    plot_error_vs_horizon({"nominal": (DEMO_HORIZONS_S, rmse)}, out / "sim_error.png")
    lines = ["What the nominal simulation gets wrong (held-out data, position RMSE [rad]):"]
    lines += [f"  {h:5.2f} s: {r:.4f}" for h, r in zip(DEMO_HORIZONS_S, rmse)]
    return "\n".join(lines)
