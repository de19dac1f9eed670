"""`dynax identify SYSTEM DATA --out FILE.json`: fit a system's parameters to a measured record."""

import argparse
import time

from .._errors import UsageError
from ._common import add_data_options, data_options, min_fit_samples, output_file
from ._output import write_json

_SYSTEMS = ("acrobot", "double_pendulum", "linear_axis", "helicopter")
_LEAST_SQUARES = {"acrobot": ("energy", "power", "dynamic"), "double_pendulum": ("energy", "power", "dynamic"),
                  "linear_axis": ("dynamic",), "helicopter": ()}


def register(subparsers):
    parser = subparsers.add_parser(
        "identify",
        help="fit the parameters of a system to measured data",
        description=(
            "Fit the parameters of SYSTEM to the record DATA and write them, with standard errors and the "
            "condition number, to --out. Methods: energy, power, dynamic (least squares, acrobot and "
            "double_pendulum; dynamic also linear_axis) and simulation (output-error fit, every system)."
        ),
    )
    parser.add_argument("system", choices=_SYSTEMS, help="the system (its data columns are in the contract)")
    parser.add_argument("data", help="CSV, NPZ or MAT file with t, the states and the inputs")
    parser.add_argument("--method", choices=("energy", "power", "dynamic", "simulation"), default="dynamic",
                        help="identification model (default dynamic)")
    parser.add_argument("--friction", choices=("viscous", "coulomb"), default=None,
                        help="friction model (default: coulomb for linear_axis, viscous otherwise)")
    add_data_options(parser)
    parser.add_argument("--lowpass", type=float, default=None, metavar="HZ",
                        help="zero-phase Butterworth cut-off [Hz] applied before differentiating (dynamic), to the "
                             "equations (power) or to the states (energy); default none")
    parser.add_argument("--decimate", type=int, default=1, metavar="N",
                        help="parallel decimation of the equations (dynamic, power; default 1)")
    parser.add_argument("--trim", type=int, default=None, metavar="N",
                        help="samples dropped at each end (dynamic, power; default 1)")
    parser.add_argument("--inputs", choices=("held", "sampled"), default="held",
                        help="dynamic model: inputs as a zero-order hold (default) or as sampled measurements")
    parser.add_argument("--window", type=int, default=10, metavar="N", help="energy model: samples per window (default 10)")
    parser.add_argument("--segment", type=float, default=1.0, metavar="SECONDS",
                        help="simulation method: multiple-shooting segment length (default 1 s)")
    parser.add_argument("--out", required=True, help="output JSON file")
    parser.set_defaults(run=run)


def _method(args):
    from .._identify import Dynamic, Energy, Power, SimulationFit

    if args.decimate < 1:
        raise UsageError(f"--decimate must be at least 1, got {args.decimate}")
    if args.trim is not None and args.trim < 0:
        raise UsageError(f"--trim must be non-negative, got {args.trim}")
    if args.lowpass is not None and not args.lowpass > 0:
        raise UsageError(f"--lowpass must be a positive frequency in Hz, got {args.lowpass}")
    if args.window < 1:
        raise UsageError(f"--window must be at least 1 sample, got {args.window}")
    if not args.segment > 0:
        raise UsageError(f"--segment must be positive, got {args.segment}")
    trim = 1 if args.trim is None else args.trim
    if args.method == "dynamic":
        return Dynamic(lowpass_hz=args.lowpass, trim=trim, decimate=args.decimate, inputs=args.inputs)
    if args.method == "power":
        return Power(lowpass_hz=args.lowpass, trim=trim, decimate=args.decimate)
    if args.method == "energy":
        return Energy(window=args.window, lowpass_hz=args.lowpass)
    return SimulationFit(segment_s=args.segment)


def _system(name):
    from .._model import Acrobot, DoublePendulum, LinearAxis

    if name == "helicopter":
        from .._model._helicopter import Helicopter

        return Helicopter()
    return {"acrobot": Acrobot, "double_pendulum": DoublePendulum, "linear_axis": LinearAxis}[name]()


def run(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)  # identification in float64; the library leaves config alone

    from .._data import load_trajectory
    from .._identify import identify

    allowed = _LEAST_SQUARES[args.system] + ("simulation",)
    if args.method not in allowed:
        raise UsageError(f"--method {args.method} is not available for {args.system}; choose one of {list(allowed)}")
    friction = args.friction or ("coulomb" if args.system == "linear_axis" else "viscous")
    if args.system == "helicopter" and args.friction is not None:
        raise UsageError("--friction does not apply to the helicopter")
    method = _method(args)
    mapping, scale = data_options(args)
    out = output_file(args.out, "parameters.json")
    start = time.perf_counter()
    data = load_trajectory(args.data, args.system, mapping=mapping, scale=scale, min_samples=min_fit_samples())
    result = identify(_system(args.system), data, method, friction=friction)
    report = result.to_json()
    if args.system == "helicopter":
        report.pop("friction")
    write_json(out, report)
    print(
        f"{args.system}, {report['method']} model, {report['n_samples']} samples: "
        f"condition number {report['condition_number']:.3g}, relative error {float(result.relative_error):.3%}"
    )
    for name, value in report["parameters"].items():
        std = report["std_errors"].get(name)
        print(f"  {name:>8s} = {value:.6g}" + (f" +- {std:.2g}" if std is not None else ""))
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0
