"""`dynax fit helicopter DATA --model M --criterion C [--horizon S] --out MODEL.json`: vehicle learning.

`dynax fit` is the vehicle spelling of `identify`: the helicopter's record, or a quadrotor's flights
(`_quadrotor.py`), fitted whole by `identify` with the vehicle criterion (`fit_everything`)."""

import argparse
import math
import sys
import time

from .._errors import DataError, UsageError
from ._common import add_data_options, data_options, finite_seconds, min_fit_samples, MIN_RESIDUAL_DOF, output_file
from ._notes import current, with_warnings
from ._output import write_json

_MODELS = ("acceleration", "linear")
AUTO_WINDOWS = 600  # start times the lagged and backprop criteria use by default (--stride auto)
_CRITERIA = ("one-step", "frequency", "lagged", "backprop")


def register(subparsers):
    parser = subparsers.add_parser(
        "fit",
        help="learn a vehicle dynamics model (helicopter, quadrotor) from flight data",
        description=(
            "Learn the body-frame model of a helicopter from the record DATA (Abbeel, Ganapathi and Ng 2005) "
            "and write it to --out. Models: acceleration (body accelerations linear in a few features, gravity "
            "and frame rotation from physics) or linear (next velocities linear in state and inputs). Criteria: "
            "one-step least squares, frequency (CIFER-style, linear model only), lagged (EM-free minimisation "
            "of the H-step prediction error) and backprop (the same loss by gradients through the rollouts)."
        ),
    )
    parser.add_argument("system", choices=("helicopter", "quadrotor"), help="the vehicle")
    parser.add_argument(
        "data",
        nargs="+",
        help="CSV, CSV.GZ or NPZ file(s) with the contract's columns: helicopter t, x..r, u1..u4 (one "
        "file); quadrotor t, x..r, m1..m4 and optional vbat (one or more flights; ground "
        "segments and glitches are found, noted and left out)",
    )
    parser.add_argument(
        "--model",
        choices=(*_MODELS, "nominal"),
        default=None,
        help="body model (default acceleration); quadrotor also nominal (the rigid body)",
    )
    parser.add_argument(
        "--no-battery",
        action="store_true",
        help="quadrotor: do not scale the motor features by vbat (default: scaled when vbat is given)",
    )
    parser.add_argument(
        "--criterion",
        choices=_CRITERIA,
        default="one-step",
        help="learning criterion (default one-step); frequency: helicopter linear model only",
    )
    parser.add_argument(
        "--horizon",
        type=float,
        default=1.0,
        metavar="SECONDS",
        help="lagged and backprop: prediction horizon H (default 1 s)",
    )
    parser.add_argument(
        "--features",
        choices=("tempest", "rich"),
        default="tempest",
        help="acceleration model: the Tempest features (default) or a richer set",
    )
    parser.add_argument(
        "--stride",
        type=_stride,
        default="auto",
        metavar="N|auto",
        help="lagged and backprop: use every N-th start time. Each start costs one H-second "
        "rollout (and its gradient) per loss evaluation, so the fit's time grows with the "
        f"number of starts. Default auto: every start up to {AUTO_WINDOWS} starts, otherwise "
        f"the stride that keeps about {AUTO_WINDOWS} (every 10th on 60 s at 100 Hz with H = 1 s: "
        "windows 0.1 s apart overlap by 90 %%, and the loss over them is within 1 %% of the loss "
        "over every start); 1 uses every start (ten times the work on that record)",
    )
    parser.add_argument(
        "--max-iterations",
        type=int,
        default=None,
        metavar="N",
        help="lagged: EM-free iterations (default 20); backprop: L-BFGS steps (default 100). Both "
        "also stop when an iteration lowers the loss by less than a relative 1e-4 (lagged) or "
        "1e-7 (backprop); a bar on stderr shows each iteration's loss. With all defaults, backprop on 60 s "
        "of aerobatic flight at 100 Hz stops after 57 steps, about one CPU-minute for the whole "
        "command",
    )
    parser.add_argument(
        "--ridge",
        type=float,
        default=None,
        metavar="R",
        help="one-step and lagged: the Tikhonov term on the normal equations, relative to their trace "
        "(default 1e-10). On flights near hover, whose motor features are nearly collinear, a larger one "
        "keeps the map smooth (1e-3 on the NanoBench flights, chosen by cross-validation over their shapes)",
    )
    add_data_options(parser)
    parser.add_argument(
        "--exclude",
        default=None,
        metavar="T0:T1",
        help="cut a stretch of time [s] at the head or tail of the record before fitting (8.8: cuts from 8.8 s on)",
    )
    parser.add_argument("--out", required=True, help="output model file (JSON)")
    parser.set_defaults(run=run)


def load_helicopter_data(path, mapping=None, scale=None, offset=None, *, min_samples=3, exclude=None):
    """Load helicopter data; check the quaternion; resample jittered sampling to its median interval (and say so).

    Gaps and near-duplicate time stamps are refused by the loader, so resampling only evens out
    jitter; it never interpolates across a missing stretch.
    """
    import sys
    import warnings

    import jax.numpy as jnp
    import numpy as np

    from .._data import check_records, exclude_stretches, load_trajectory, parse_exclude, resample, Sampling
    from .._data._flight_kinematics import check_unit_quaternions

    with warnings.catch_warnings():  # checked below, on what --exclude leaves
        warnings.simplefilter("ignore")
        data = load_trajectory(
            path,
            "helicopter",
            mapping=mapping,
            scale=scale,
            offset=offset,
            sampling=Sampling(min_samples=min_samples),
            check=False,
        )
    spans = [(t0, t1) for _, t0, t1 in parse_exclude(exclude)]
    if spans:
        pieces = exclude_stretches(data, spans)
        if len(pieces) != 1:
            raise UsageError(
                f"--exclude leaves {len(pieces)} pieces of {path}; a vehicle model is fitted to one "
                "contiguous record: cut only its head or tail, or split the file"
            )
        data = pieces[0]
        if len(data) < min_samples:
            raise DataError(f"has {len(data)} samples after --exclude; at least {min_samples} are needed", path=path)
    check_unit_quaternions(np.asarray(data.xs[:, 3:7]), path, mapping)
    check = check_records([data])
    check.raise_refusals()
    said = current()
    for finding in check.warnings:
        said.finding(finding)
    if not data.is_uniform:
        dt = data.dt
        data = resample(data, dt)
        said.note(
            "resampled",
            f"{path} is irregularly sampled; resampled to its median interval {dt:.6g} s",
            file=path,
            stream=sys.stdout,
        )
    xs = jnp.asarray(data.xs)
    xs = xs.at[:, 3:7].set(xs[:, 3:7] / jnp.linalg.norm(xs[:, 3:7], axis=1, keepdims=True))
    return type(data)(data.ts, xs, data.us, data.state_names, data.input_names, data.system, data.source)


def required_samples(system, criterion: str, horizon_s: float, dt: float) -> tuple[int, str]:
    """The fewest samples a fit can be trusted with, and why: each body axis's one-step regression
    needs `min_fit_samples` for its free weights; lagged and backprop, one horizon more."""
    import numpy as np

    free = int(np.max(np.sum(np.asarray(system.body_model.mask, dtype=bool), axis=1)))
    need = min_fit_samples(free, trim=1)
    why = f"{free} free weights per axis and {MIN_RESIDUAL_DOF} residual degrees of freedom"
    if criterion in ("lagged", "backprop"):
        steps = int(round(horizon_s / dt))
        need, why = need + steps, why + f", plus the {steps} samples the horizon {horizon_s:g} s spans"
    return need, why


def fit_everything(system, records, criterion):
    """`identify` of a vehicle on all of `records` with a vehicle `criterion` (nothing held out: `dynax
    evaluate` scores held-out flights), the data's faults already printed by the loader: its `Solution`."""
    from .._identify import FitSettings
    from .._identify._vehicle._fit import fit_all

    return fit_all(system, records, criterion, FitSettings(), warn_data=False)


def _stride(text: str):
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number or 'auto', got {text!r}") from None


def check_iterative_options(args) -> None:
    """`--horizon`, `--stride` and `--max-iterations` of `dynax fit`, checked alike for every vehicle."""
    finite_seconds(args.horizon, "--horizon")
    if args.stride != "auto" and args.stride < 1:
        raise UsageError(f"--stride must be at least 1 or 'auto', got {args.stride}")
    if args.max_iterations is not None and args.max_iterations < 1:
        raise UsageError(f"--max-iterations must be at least 1, got {args.max_iterations}")


def vehicle_criterion(args, stride: int, ridge: dict):
    """The criterion `--criterion` names, with `--horizon`, the `stride`, `--max-iterations` and the `ridge`
    keyword (`ridge_option`)."""
    from .._identify._vehicle import Backprop, FrequencyDomain, Lagged, OneStep

    limit = (
        {}
        if args.max_iterations is None
        else {"lagged": {"max_iterations": args.max_iterations}, "backprop": {"max_steps": args.max_iterations}}.get(
            args.criterion, {}
        )
    )
    return {
        "one-step": lambda: OneStep(**ridge),
        "frequency": lambda: FrequencyDomain(),
        "lagged": lambda: Lagged(horizon=args.horizon, stride=stride, **limit, **ridge),
        "backprop": lambda: Backprop(horizon=args.horizon, stride=stride, **limit),
    }[args.criterion]()


def ridge_option(args) -> dict:
    """`--ridge` as the criterion's keyword (none where not given), checked: a finite number, not negative, and
    only with a criterion that reads it."""
    if args.ridge is None:
        return {}
    if not (math.isfinite(args.ridge) and args.ridge >= 0):
        raise UsageError(f"--ridge must be a finite number, at least 0, got {args.ridge}")
    if args.criterion not in ("one-step", "lagged"):
        raise UsageError(f"--ridge applies to --criterion one-step and lagged, not {args.criterion}")
    return {"ridge": args.ridge}


def run(args: argparse.Namespace) -> int:
    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)  # learning in float64; the library leaves config alone

    from .._identify._vehicle import (
        auto_stride,
        initial_helicopter,
        model_to_json,
        recorded_loss,
    )

    if args.system == "quadrotor":
        from ._quadrotor import run_fit

        return run_fit(args)
    if len(args.data) != 1:
        raise UsageError(f"dynax fit helicopter takes one data file, got {len(args.data)}")
    args.data = args.data[0]
    args.model = args.model or "acceleration"
    if args.model not in _MODELS:
        raise UsageError(f"--model {args.model} is not a helicopter model; expected one of {list(_MODELS)}")

    if args.criterion == "frequency" and args.model != "linear":
        raise UsageError("--criterion frequency fits the linear model only; use --model linear")
    check_iterative_options(args)
    ridge = ridge_option(args)
    out = output_file(args.out, "model.json")
    mapping, scale, offset = data_options(args)
    start = time.perf_counter()
    data = load_helicopter_data(args.data, mapping, scale, offset, exclude=args.exclude)
    system = initial_helicopter(args.model, args.features)
    n_needed, why = required_samples(system, args.criterion, args.horizon, data.dt)
    if len(data) < n_needed:
        raise DataError(
            f"has {len(data)} samples; the {args.model} model with the {args.criterion} criterion needs "
            f"at least {n_needed} ({why})",
            path=args.data,
        )
    stride, n_steps = args.stride, max(int(round(args.horizon / data.dt)), 1)
    if stride == "auto":
        stride = auto_stride(len(data), n_steps, AUTO_WINDOWS)
    criterion = vehicle_criterion(args, stride, ridge)
    if args.criterion in ("lagged", "backprop") and stride > 1:
        current().note(
            "stride",
            f"one start time in {stride}, {-(-(len(data) - n_steps) // stride)} windows of {args.horizon:g} s "
            "(--stride 1 for every start)",
            stream=sys.stdout,
        )
    fit = fit_everything(system, data, criterion)  # a bar per iteration with the loss on stderr (see --quiet)
    horizon = args.horizon if args.criterion in ("lagged", "backprop") else None
    weights = np.asarray(fit.model.body_model.weights)
    loss = recorded_loss(fit)
    if not (np.all(np.isfinite(weights)) and np.isfinite(loss)):
        print(
            f"dynax fit: error: the fit failed numerically (loss {loss}, {np.sum(~np.isfinite(weights))} "
            "non-finite weights); nothing written",
            file=sys.stderr,
        )
        return 1
    write_json(out, with_warnings(model_to_json(fit, horizon_s=horizon)))
    print(f"helicopter, {args.model} model, {args.criterion} criterion, {len(data)} samples: loss {loss:.6g}")
    for name, value in fit.model.body_model.parameters.items():
        print(f"  {name:>10s} = {float(value):.6g}")
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0
