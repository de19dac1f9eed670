"""`dynax evaluate MODEL.json DATA --horizons 0.1,0.5,1,2 --out METRICS.json`: held-out prediction error."""

import argparse
import json
import math
import time

from .._errors import DataError, UsageError
from ._common import add_data_options, data_options, output_file
from ._output import write_json


def register(subparsers):
    parser = subparsers.add_parser(
        "evaluate",
        help="open-loop prediction error of a learned vehicle model on (held-out) data",
        description=(
            "Roll the model in MODEL (written by `dynax fit`) out open loop from every sample of DATA under the "
            "recorded inputs and write the mean squared prediction error per state group (velocity, "
            "angular_rate, position, orientation) at each horizon to --out."
        ),
    )
    parser.add_argument("model", help="model file written by `dynax fit helicopter`")
    parser.add_argument("data", help="CSV or NPZ file with the contract's helicopter columns")
    parser.add_argument("--horizons", default="0.1,0.5,1,2", help="comma-separated horizons in seconds (default 0.1,0.5,1,2)")
    parser.add_argument("--stride", type=int, default=1, metavar="N", help="use every N-th start sample (default 1: every)")
    add_data_options(parser)
    parser.add_argument("--out", required=True, help="output metrics file (JSON)")
    parser.set_defaults(run=run)


def _horizons(text):
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise UsageError(f"--horizons must be comma-separated seconds, got {text!r}") from None
    if not values or any(not math.isfinite(v) or v < 0 for v in values):
        raise UsageError(f"--horizons must be non-negative finite seconds, got {text!r}")
    return values


def run(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)

    from .._identify._vehicle import model_from_json, prediction_error
    from ._fit import load_helicopter_data

    horizons = _horizons(args.horizons)
    if args.stride < 1:
        raise UsageError(f"--stride must be at least 1, got {args.stride}")
    out = output_file(args.out, "metrics.json")
    mapping, scale = data_options(args)
    start = time.perf_counter()
    try:
        with open(args.model) as f:
            model_obj = json.load(f)
    except FileNotFoundError:
        raise DataError("no such file", path=args.model) from None
    except json.JSONDecodeError as e:
        raise DataError(f"is not valid JSON ({e})", path=args.model) from None
    system = model_from_json(model_obj, path=args.model)
    data = load_helicopter_data(args.data, mapping, scale)
    n_needed = int(round(max(horizons) / data.dt)) + 1
    if len(data) < n_needed + 1:
        raise DataError(f"has {len(data)} samples; the horizon {max(horizons)} s needs at least {n_needed + 1}",
                        path=args.data)
    mse = prediction_error(system, data, horizons, stride=args.stride)
    diverged = [float(v) for v in mse.pop("diverged_fraction")]
    metrics = {"horizons_s": horizons, "mse": {name: [float(v) for v in values] for name, values in mse.items()}}
    if any(diverged):
        metrics["diverged_fraction"] = diverged
        print(f"note: {max(diverged):.1%} of the rollouts diverged; their error counts as infinite")
    write_json(out, metrics)
    print(f"helicopter model {args.model} on {args.data}: mean squared open-loop prediction error")
    print("  horizon [s]  " + "  ".join(f"{h:>10g}" for h in horizons))
    for name, values in metrics["mse"].items():
        print(f"  {name:>12s} " + "  ".join(f"{v:>10.4g}" for v in values))
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0
