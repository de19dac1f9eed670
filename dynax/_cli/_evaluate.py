"""`dynax evaluate MODEL.json DATA --horizons 0.1,0.5,1,2 --out METRICS.json`: held-out prediction error."""

import argparse
import math
import sys
import time

from .._errors import DataError, UsageError
from ._common import add_data_options, data_options, output_file, read_json_object
from ._notes import current, with_warnings
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
    parser.add_argument("model", help="model file written by `dynax fit helicopter` or `dynax fit quadrotor`")
    parser.add_argument(
        "data", nargs="+", help="CSV, CSV.GZ or NPZ file(s) with the contract's columns (helicopter: one)"
    )
    parser.add_argument(
        "--horizons",
        default=None,
        help="helicopter: comma-separated horizons in seconds (default 0.1,0.5,1,2)",
    )
    parser.add_argument(
        "--steps",
        default=None,
        help="quadrotor: comma-separated horizons in samples (default 1,10,50): MAE and RMSE per group "
        "(position m, velocity m/s, attitude rad, body rate rad/s) and the cumulative MAE over "
        "1..max, beside the constant-velocity baseline",
    )
    parser.add_argument("--metric", default="mae,rmse", help="quadrotor: mae, rmse or mae,rmse (default both)")
    parser.add_argument(
        "--stride",
        type=int,
        default=None,
        metavar="N",
        help="helicopter: use every N-th start sample (default 1: every; a quadrotor is scored from every sample)",
    )
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


def check_model_file(obj: dict, path) -> None:
    """Refuse a model file that `dynax fit` could not have written: a feature list that does not
    belong to its `model` kind (a hand-edited kind) or weights that are not finite numbers."""
    import numpy as np

    from .._model._helicopter import ACCELERATION_FEATURE_NAMES, LINEAR_FEATURE_NAMES

    kind, features = obj.get("model"), obj.get("features")
    if not isinstance(features, list) or not all(isinstance(f, str) for f in features):
        raise DataError("'features' must be a list of feature names", path=path)
    if kind == "linear" and tuple(features) != LINEAR_FEATURE_NAMES:
        raise DataError(
            f"'model' is 'linear' but the features {features} are not the linear model's {list(LINEAR_FEATURE_NAMES)}",
            path=path,
        )
    if kind == "acceleration" and not set(features) <= set(ACCELERATION_FEATURE_NAMES):
        raise DataError(
            f"'model' is 'acceleration' but the features {sorted(set(features) - set(ACCELERATION_FEATURE_NAMES))} "
            "are not acceleration-model features",
            path=path,
        )
    try:
        weights = np.asarray(obj.get("weights"), dtype=float)
    except (TypeError, ValueError):
        raise DataError("'weights' must be a 6 x n_features array of numbers", path=path) from None
    if weights.shape != (6, len(features)):
        raise DataError(
            f"'weights' has shape {weights.shape}; 6 x {len(features)} (axes x features) expected", path=path
        )
    bad = np.argwhere(~np.isfinite(weights))
    if bad.size:
        axis, j = bad[0]
        raise DataError(f"weight [{axis}][{j}] (feature '{features[j]}') is not a finite number", path=path)
    if kind == "acceleration" and "gravity" in obj:
        gravity = obj["gravity"]
        if isinstance(gravity, bool) or not isinstance(gravity, (int, float)) or not 0 < gravity < 1e3:
            raise DataError(
                f"'gravity' is {gravity!r}: a physical gravity is a positive acceleration in m/s^2 (9.81 on Earth)",
                path=path,
                column="gravity",
            )


def _refuse_a_flight_log(args, model_obj, mapping) -> None:
    """Name the mismatch where a helicopter model is given a quadrotor flight log (the file reads with the
    quadrotor's columns): the missing helicopter column alone would send the user to `--map`."""
    import warnings

    from .._data import load_trajectory

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            load_trajectory(args.data, "quadrotor", mapping=mapping, check=False)
    except (DataError, UsageError):
        return
    raise DataError(
        f"is a {model_obj.get('system', 'helicopter')} model, and {args.data} is a quadrotor flight log (it has "
        "the quadrotor's columns): evaluate a quadrotor model on it (`dynax fit quadrotor`), or this model on "
        "its own system's data",
        path=args.model,
    )


def run(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)

    from .._identify._vehicle import model_from_json, prediction_error
    from ._fit import load_helicopter_data

    model_obj = read_json_object(args.model, "a model file written by `dynax fit`")
    if model_obj.get("system") == "quadrotor":  # the field's protocol: every start sample, horizons in samples
        for option, value in (("--horizons", args.horizons), ("--stride", args.stride)):
            if value is not None:
                raise UsageError(
                    f"{option} applies to helicopter models; a quadrotor model is scored from every start sample "
                    "at --steps (samples, default 1,10,50)"
                )
        from .._data._motor_order import MotorSignature
        from .._identify._vehicle._quadrotor import quadrotor_from_json
        from ._quadrotor import run_evaluate

        reference = MotorSignature.from_json(model_obj.get("motor_signature"), args.model)
        return run_evaluate(args, quadrotor_from_json(model_obj, path=args.model), reference)
    if args.steps is not None:
        raise UsageError("--steps applies to quadrotor models; a helicopter model takes --horizons (seconds)")
    if len(args.data) != 1:
        raise UsageError(f"evaluating a helicopter model takes one data file, got {len(args.data)}")
    args.data = args.data[0]
    horizons = _horizons("0.1,0.5,1,2" if args.horizons is None else args.horizons)
    args.stride = 1 if args.stride is None else args.stride
    if args.stride < 1:
        raise UsageError(f"--stride must be at least 1, got {args.stride}")
    out = output_file(args.out, "metrics.json")
    mapping, scale, offset = data_options(args)
    start = time.perf_counter()
    check_model_file(model_obj, args.model)
    system = model_from_json(model_obj, path=args.model)
    try:
        data = load_helicopter_data(args.data, mapping, scale, offset)
    except DataError:
        _refuse_a_flight_log(args, model_obj, mapping)
        raise
    n_needed = int(round(max(horizons) / data.dt)) + 1
    if len(data) < n_needed + 1:
        raise DataError(
            f"has {len(data)} samples; the horizon {max(horizons)} s needs at least {n_needed + 1}", path=args.data
        )
    mse = prediction_error(system, data, horizons, stride=args.stride)
    diverged = [float(v) for v in mse.pop("diverged_fraction")]
    # A diverged rollout has no finite error: its horizon's mse is null, with the reason beside it.
    metrics = {
        "horizons_s": horizons,
        "mse": {
            name: [float(v) if math.isfinite(v) else None for v in map(float, values)] for name, values in mse.items()
        },
    }
    if any(diverged):
        metrics["diverged_fraction"] = diverged
        metrics["status"] = ["diverged" if d else "ok" for d in diverged]
        current().note(
            "diverged",
            f"{max(diverged):.1%} of the rollouts diverged; the mean squared error at those horizons is "
            "infinite, written as null with status 'diverged'",
            stream=sys.stdout,
        )
    write_json(out, with_warnings(metrics))
    print(f"helicopter model {args.model} on {args.data}: mean squared open-loop prediction error")
    print("  horizon [s]  " + "  ".join(f"{h:>10g}" for h in horizons))
    for name, values in metrics["mse"].items():
        print(f"  {name:>12s} " + "  ".join(f"{v:>10.4g}" if v is not None else f"{'diverged':>10s}" for v in values))
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0
