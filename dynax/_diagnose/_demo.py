"""The demo's main job: hide an effect in acrobot data, then diagnose it end to end."""

import pathlib
import time

from .._model._two_link import Acrobot
from .._synthetic import DEMO_TRUTH_PHYSICAL, demo_data  # noqa: F401 (DEMO_TRUTH_PHYSICAL: the old path)
from .._progress import ProgressBar
from ._diagnose import diagnose, Refit
from ._report import write_report


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
