"""`dynax demo`: the main job on the embedded default, an acrobot with an effect hidden in its data."""

import argparse
import dataclasses
import pathlib
import time

from .._errors import UsageError
from .._synthetic import hidden_effect
from ._notes import current
from ._output import staged_directory, write_json

MAX_SEED = 2**32 - 1  # the random generators' seeds are unsigned 32-bit integers


def register(subparsers):
    parser = subparsers.add_parser(
        "demo",
        help="generate acrobot data with a hidden effect and diagnose it",
        description=(
            "Generate measured data for an acrobot with an effect hidden in it (chosen by --seed), "
            "simulate the nominal model against it, diagnose what it gets wrong, and write the report."
        ),
    )
    parser.add_argument("--out", default="dynax-demo", help="output directory (default dynax-demo/)")
    parser.add_argument("--seed", type=int, default=0, help="chooses the hidden effect and its size (default 0)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)  # the CLI identifies in float64; the library does not change config

    if not 0 <= args.seed <= MAX_SEED:
        raise UsageError(f"--seed must be an integer from 0 to {MAX_SEED}, got {args.seed}")
    start = time.perf_counter()
    out = pathlib.Path(args.out)
    with staged_directory(out) as stage:
        text = run_demo(hidden_effect(args.seed), seed=args.seed, out=stage)
    print(text)
    print(f"wrote {out}/ in {time.perf_counter() - start:.0f} s")
    return 0


def run_demo(term, *, seed: int, out: pathlib.Path) -> str:
    """Generate the data, diagnose the nominal acrobot against it, write the report; return the terminal summary."""
    from .._data._io import save_trajectory
    from .._diagnose import diagnose, Refit, write_report
    from .._model._two_link import Acrobot
    from .._progress import ProgressBar
    from .._synthetic import demo_data
    from ._diagnose import summary

    out = pathlib.Path(out)
    start = time.perf_counter()
    truth, train, validation = demo_data(term, seed=seed)
    save_trajectory(train, out / "train.csv")
    save_trajectory(validation, out / "validation.csv")
    with ProgressBar(None, "diagnose", unit="stage") as bar:  # stderr; a log without a terminal; --quiet: nothing
        report = diagnose(
            Acrobot(),
            train,
            validation,
            mode=Refit(),
            progress=lambda line: bar.say(f"[{time.perf_counter() - start:5.1f} s] {line}"),
        )
    report = dataclasses.replace(report, warnings=current().to_json())  # report.json's `warnings`
    write_report(report, out, validation, write_json=write_json)
    hidden = f"{term.label(truth.system)}, {term.parameter_name(truth.system)} = {float(term.coefficient):.4g}"
    return f"Hidden in the data: {hidden} (and base parameters that differ from the nominal model's).\n" + summary(
        report
    )
