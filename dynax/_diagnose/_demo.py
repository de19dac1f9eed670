"""The demo's main job: hide an effect in acrobot data, then diagnose it end to end."""

import pathlib
import time

from .._data._trajectory import Trajectory
from .._model._extensions import Extended
from .._model._two_link import Acrobot
from .._progress import ProgressBar
from ._diagnose import diagnose, Refit
from ._report import write_report
from ._synthetic import synthetic_trajectory

# The rig the data comes from differs a little from the datasheet model the user starts with.
DEMO_TRUTH_PHYSICAL = dict(m1=1.05, m2=0.97, lc2=1.02, Ic2=0.32)


def demo_data(term, *, seed: int, train_s: float = 20.0, validation_s: float = 10.0):
    """Training and validation records of the demo's truth acrobot with `term` hidden.

    One run of `train_s + validation_s` seconds at 100 Hz under a random multisine elbow torque,
    with measurement noise; the first `train_s` seconds train, the rest is held out.
    """
    truth = Extended(Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL), (term,))
    run = synthetic_trajectory(truth, duration=train_s + validation_s, dt=0.01, amplitude=2.0, seed=seed,
                               system_name="acrobot")
    k = int(round(train_s / 0.01)) + 1
    train = Trajectory(run.ts[:k], run.xs[:k], run.us[:k], run.state_names, run.input_names, "acrobot", "train.csv")
    validation = Trajectory(run.ts[k:], run.xs[k:], run.us[k:], run.state_names, run.input_names, "acrobot", "validation.csv")
    return truth, train, validation


def run_demo(term, *, seed: int, out: pathlib.Path, save_trajectory, write_json, summary) -> str:
    """Generate the data, diagnose the nominal acrobot against it, write the report; return the terminal summary."""
    out = pathlib.Path(out)
    start = time.perf_counter()
    truth, train, validation = demo_data(term, seed=seed)
    save_trajectory(train, out / "train.csv")
    save_trajectory(validation, out / "validation.csv")
    with ProgressBar(None, "diagnose", unit="stage") as bar:  # stderr; a log without a terminal; --quiet: nothing
        report = diagnose(Acrobot(), train, validation, mode=Refit(), system_name="acrobot",
                          progress=lambda line: bar.say(f"[{time.perf_counter() - start:5.1f} s] {line}"))
    write_report(report, out, validation, write_json=write_json)
    hidden = f"{term.label(truth.system)}, {term.parameter_name(truth.system)} = {float(term.coefficient):.4g}"
    return f"Hidden in the data: {hidden} (and base parameters that differ from the nominal model's).\n" + summary(report)
