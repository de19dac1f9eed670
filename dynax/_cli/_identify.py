"""`dynax identify SYSTEM DATA... [--validation DATA...] --out FILE.json`: fit a system's parameters to measured
records.

With no recipe flags every filter setting is chosen from the data, the estimate is constrained to
the physically consistent set, two-link arms on noisy (real) data are refined by the output-error
fit, and the model is validated open loop on held-out data; all of it goes into the JSON.
"""

import argparse
import dataclasses
import time
import warnings

from .._errors import UsageError
from ._common import (
    add_data_options,
    add_exclude_option,
    add_time_option,
    add_velocity_option,
    data_options,
    finite_seconds,
    load_records,
    min_fit_samples,
    output_file,
)
from ._notes import current, with_warnings
from ._output import write_json

_SYSTEMS = ("acrobot", "double_pendulum", "linear_axis", "helicopter")
_LEAST_SQUARES = {
    "acrobot": ("energy", "power", "dynamic"),
    "double_pendulum": ("energy", "power", "dynamic"),
    "linear_axis": ("dynamic",),
    "helicopter": (),
}


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
    parser.add_argument("data", nargs="+", help="CSV, NPZ or MAT file(s) with t, the states and the inputs")
    parser.add_argument(
        "--validation",
        nargs="+",
        default=None,
        metavar="DATA",
        help="held-out file(s) for the open-loop validation (default: the last 20 %% of each DATA "
        "file is held out and not fitted)",
    )
    parser.add_argument(
        "--holdout",
        type=float,
        default=None,
        metavar="FRACTION",
        help="fraction of each DATA file held out when no --validation is given (default 0.2; "
        "0 fits everything and reports no validation)",
    )
    parser.add_argument(
        "--method",
        choices=("energy", "power", "dynamic", "simulation"),
        default="dynamic",
        help="identification model (default dynamic)",
    )
    parser.add_argument(
        "--friction",
        choices=("viscous", "coulomb"),
        default=None,
        help="friction model (default: coulomb for linear_axis, viscous otherwise)",
    )
    add_data_options(parser)
    add_time_option(parser)
    add_exclude_option(parser)
    add_velocity_option(parser)
    parser.add_argument(
        "--lowpass",
        default="auto",
        metavar="HZ|auto|none",
        help="zero-phase Butterworth cut-off [Hz] applied before differentiating (dynamic), to the "
        "equations (power) or to the states (energy); dynamic default 'auto' (the velocities' "
        "signal band, from their spectra), power and energy default none",
    )
    parser.add_argument(
        "--order", default="auto", metavar="N|auto", help="dynamic model: order of one filter pass (default auto)"
    )
    parser.add_argument(
        "--decimate",
        default="auto",
        metavar="N|auto",
        help="parallel decimation of the equations (dynamic default auto, power default 1)",
    )
    parser.add_argument(
        "--trim",
        default="auto",
        metavar="N|auto",
        help="samples dropped at each end (dynamic default auto, power default 1)",
    )
    parser.add_argument(
        "--consistency",
        choices=("constrain", "check", "off"),
        default="constrain",
        help="physical consistency: fit over the consistent set when needed (default), only check and warn, or off",
    )
    parser.add_argument(
        "--refine",
        choices=("auto", "yes", "no"),
        default="auto",
        help="output-error refinement after least squares (default auto: two-link arms on noisy data)",
    )
    parser.add_argument(
        "--inputs",
        choices=("held", "sampled"),
        default="held",
        help="dynamic model: inputs as a zero-order hold (default) or as sampled measurements",
    )
    parser.add_argument(
        "--offsets",
        choices=("auto", "forces", "angles", "none"),
        default="auto",
        help="dynamic model: what each record may be off by: one force offset per record and driven joint "
        "(forces), one zero per record and angle (angles, double_pendulum), none, or auto (default: with the "
        "filter settings chosen from the data, force offsets, or on double_pendulum the angle zeros where they "
        "fit the records clearly better; none with an explicit --lowpass)",
    )
    parser.add_argument(
        "--static-friction",
        action="store_true",
        help="dynamic model: add Stiction (a static friction level) at each joint that rests under load "
        "(default: the rests are found and reported, the model keeps its friction law of the speed)",
    )
    parser.add_argument(
        "--window", type=int, default=10, metavar="N", help="energy model: samples per window (default 10)"
    )
    parser.add_argument(
        "--segment",
        type=float,
        default=1.0,
        metavar="SECONDS",
        help="simulation method: multiple-shooting segment length (default 1 s)",
    )
    parser.add_argument("--out", required=True, help="output JSON file")
    parser.set_defaults(run=run)


def _setting(value, flag, *, kind=int, minimum=0, allow_none=False):
    """`auto`, `none` (where allowed) or a number >= `minimum`, else a UsageError naming the flag."""
    text = str(value).strip().lower()
    if text == "auto":
        return "auto"
    if allow_none and text == "none":
        return None
    try:
        number = kind(text)
    except ValueError:
        raise UsageError(f"{flag} must be a number{', none' if allow_none else ''} or auto, got {value!r}") from None
    if not number >= minimum or (kind is float and not number > 0):
        raise UsageError(f"{flag} must be {'positive' if kind is float else f'at least {minimum}'}, got {value}")
    return number


def with_static_friction(method, args):
    """`method` with the static level on where `--static-friction` asks (the dynamic model only)."""
    if not args.static_friction:
        return method
    if args.method != "dynamic":
        raise UsageError(f"--static-friction applies to --method dynamic, not {args.method}")
    return dataclasses.replace(method, static_friction=True)


_OFFSETS = {"auto": "auto", "forces": True, "angles": "angles", "none": False}  # --offsets as `Dynamic(offsets=...)`


def _method(args):
    from .._identify import Dynamic, Energy, Power, SimulationFit

    lowpass = _setting(args.lowpass, "--lowpass", kind=float, allow_none=True)
    order = _setting(args.order, "--order", minimum=1)
    decimate = _setting(args.decimate, "--decimate", minimum=1)
    trim = _setting(args.trim, "--trim", minimum=0)
    if args.window < 1:
        raise UsageError(f"--window must be at least 1 sample, got {args.window}")
    finite_seconds(args.segment, "--segment")
    if args.method == "dynamic":
        assert order is not None and trim is not None and decimate is not None  # `none` is refused for these three
        return Dynamic(
            lowpass_hz=lowpass,
            lowpass_order=order,
            trim=trim,
            decimate=decimate,
            inputs=args.inputs,
            offsets=_OFFSETS[args.offsets],
        )
    if args.offsets != "auto":
        raise UsageError(f"--offsets applies to --method dynamic, not {args.method}")
    plain = lambda value, default: default if value == "auto" else value  # noqa: E731
    if args.method == "power":
        return Power(
            lowpass_hz=plain(lowpass, None),
            lowpass_order=plain(order, 4),
            trim=plain(trim, 1),
            decimate=plain(decimate, 1),
        )
    if args.method == "energy":
        return Energy(window=args.window, lowpass_hz=plain(lowpass, None), lowpass_order=plain(order, 4))
    return SimulationFit(segment_s=args.segment)


def method_from_args(args):
    """The identification method that parsed `dynax identify` arguments choose: `--method` with its filter
    settings and `--offsets`, and the static level where `--static-friction` asks. Raises `UsageError` for a
    setting out of range or a flag that does not apply to the method."""
    return with_static_friction(_method(args), args)


def _system(name):
    from .._model import Acrobot, DoublePendulum, LinearAxis

    if name == "helicopter":
        from .._model._helicopter import Helicopter

        return Helicopter()
    return {"acrobot": Acrobot, "double_pendulum": DoublePendulum, "linear_axis": LinearAxis}[name]()


def run(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)  # identification in float64; the library leaves config alone

    from .._data import DataWarning
    from .._identify import identify, Validate
    from .._identify._least_squares import describe_poorly_determined
    from .._identify._result import StageKind

    allowed = _LEAST_SQUARES[args.system] + ("simulation",)
    if args.method not in allowed:
        raise UsageError(f"--method {args.method} is not available for {args.system}; choose one of {list(allowed)}")
    friction = args.friction or ("coulomb" if args.system == "linear_axis" else "viscous")
    if args.system == "helicopter" and args.friction is not None:
        raise UsageError("--friction does not apply to the helicopter")
    method = method_from_args(args)
    data_options(args)  # a malformed --map, --scale or --offset is refused before any work
    out = output_file(args.out, "parameters.json")
    if args.holdout is not None and not 0 <= args.holdout < 1:
        raise UsageError(f"--holdout must be in [0, 1), got {args.holdout}")
    if args.holdout is not None and args.validation:
        raise UsageError("give either --validation files or --holdout, not both")
    start = time.perf_counter()
    data, validation, _ = load_records(args, args.system, min_samples=min_fit_samples())  # its notes: printed, kept
    refine = {"auto": "auto", "yes": True, "no": False}[args.refine]
    if refine is True and args.system not in ("acrobot", "double_pendulum"):
        raise UsageError(f"--refine yes is for acrobot and double_pendulum; use --method simulation for {args.system}")
    with warnings.catch_warnings():  # the records' faults were refused or printed by `load_records`
        warnings.simplefilter("ignore", DataWarning)
        result = identify(
            _system(args.system),
            data,
            method,
            friction=friction,
            consistency=args.consistency,
            refine=refine,
            validation=Validate(validation, holdout="auto" if args.holdout is None else args.holdout),
        )
    report = result.to_json()
    if args.system == "helicopter":
        report.pop("friction")
    said, lines = current(), []

    def say(line: str, kind: str | None = None) -> None:
        """A line of the summary; with `kind`, a note the JSON's `warnings` keeps too."""
        lines.append(line)
        if kind is not None:
            said.add(kind, line.strip().removeprefix("WARNING: ").removeprefix("NOTE: "))

    say(
        f"{args.system}, {report['method']} model, {report['n_samples']} samples: "
        f"condition number {report['condition_number']:.3g}, relative equation error {float(result.relative_error):.3%}"
    )
    between = report.get("record_std_errors") or {}
    for name, value in report["parameters"].items():
        std = report["std_errors"].get(name)
        say(
            f"  {name:>8s} = {value:.6g}"
            + (f" +- {std:.2g}" if std is not None else "")
            + (f" (leaving one record out: +- {between[name]:.2g})" if name in between else "")
        )
    least_squares, output_error = result.stage(StageKind.LEAST_SQUARES), result.stage(StageKind.OUTPUT_ERROR)
    serial = None if least_squares is None else least_squares.serial_correlation
    if serial and output_error is None:
        ratios = serial["inflation"].values()
        say(
            f"  standard errors robust to the equations' correlation in time (over {serial['bandwidth_steps']:.0f} "
            f"time steps): {min(ratios):.2g} to {max(ratios):.2g} times those counting every equation as independent"
        )
    for settings in result.settings:
        if settings.get("chosen_from_data"):
            say(f"  settings ({settings.get('record') or 'record'}): {settings['reason']}")
    consistency = result.consistency
    if consistency is not None:
        if consistency.violated:
            say("  physically INCONSISTENT: " + "; ".join(consistency.violated), "inconsistent")
        enforced = () if least_squares is None else least_squares.consistency.active
        if enforced:
            say("  consistency constraint active (the plain least-squares estimate broke: " + "; ".join(enforced) + ")")
        elif not consistency.violated:
            say("  physically consistent")
    if result.poorly_determined:
        cells = describe_poorly_determined(result.poorly_determined)
        say(
            f"  WARNING: the data determine these parameters poorly (relative standard error): {cells}; "
            "record more motion in every joint before trusting them, or look for what the model misses",
            "poorly_determined",
        )
    if result.jointly_determined:
        cells = "; ".join(jointly_determined_cell(n, j, report) for n, j in result.jointly_determined.items())
        say(
            "  NOTE: determined mostly jointly (the standard error over 10 times what it would be with every other "
            "parameter known: most of the error is shared, and a combination of the correlated parameters is known "
            f"better than each alone): {cells}",
            "jointly_determined",
        )
    if output_error is not None and result.record_std_errors is None and len(data) < 3:
        own = args.validation is None  # without --validation, the held-out part is the records' own tail
        say(
            f"  NOTE: fitted on {len(data)} record{'s' if len(data) > 1 else ''}: the standard errors "
            + ("and the validation come" if own else "come")
            + " from within the records, and cannot show what changes from one recording to the next "
            "(friction, sensor offsets, motion a record does not contain). Give three records or more for errors "
            "between records" + (", and a record of its own to --validation" if own else ""),
            "few_records",
        )
    disagree = None if output_error is None else output_error.records_disagree
    if disagree:
        cells = ", ".join(f"{n} ({r:.1f}x)" for n, r in disagree.items())
        say(
            f"  NOTE: the records disagree more than their noise explains: leaving one record out moves {cells} "
            "by that many times their standard error from within the records; read the leave-one-record-out "
            "errors as their uncertainty",
            "records_disagree",
        )
    for check in (result.record_offsets, result.record_friction):
        if check is not None and check.differ():
            say(f"  {check.note()}", "records_differ")  # differ(): a note
    fitted_offsets = None if least_squares is None else least_squares.offsets
    if fitted_offsets:
        cells = "; ".join(
            f"{record} " + ", ".join(f"{joint} {value:+.3g}" for joint, value in zip(fitted_offsets["joints"], row))
            for record, row in zip(fitted_offsets["records"], fitted_offsets["values"])
        )
        say(f"  force offsets fitted per record (not part of the model): {cells}")
    if result.angle_zeros is not None:
        say("  " + result.angle_zeros.note())
    if result.static_friction is not None and result.static_friction.stretches:  # said where a record rests
        say("  friction at rest: " + result.static_friction.note)
    timing = None if output_error is None else output_error.solution.statistics.input_latency_s
    if timing is not None:
        latency = 1e3 * timing
        say(
            f"  input timing (fitted in the refinement): the inputs act {abs(latency):.2f} ms "
            f"{'after' if latency >= 0 else 'before'} their samples (0 ms: sampled without delay; "
            "half the record's interval after: held as recorded)"
        )
    for stage in result.stages:
        if stage.validation is not None:
            for line in stage.validation.summary(str(stage.kind)).splitlines():
                say("  " + line)
    concentrated = None if result.validation is None else result.validation.note()
    if concentrated:
        say("  NOTE: " + concentrated, "validation_concentrated")
    worse = _refinement_validates_worse(least_squares, output_error)
    if worse:
        say(
            f"  NOTE: the least-squares stage predicts the {worse} better than the refined model at every "
            "horizon; the refined model is the one written (`--refine no` returns the least-squares model)",
            "refinement_validates_worse",
        )
    if result.validation is None:
        say("  no held-out validation (nothing held out)", "no_validation")
    write_json(out, with_warnings(report))
    print("\n".join(lines))
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0


def _refinement_validates_worse(least_squares, output_error) -> str | None:
    """The held-out source where the output-error stage's open-loop error is above the least-squares
    stage's at every horizon; `None` otherwise (or when either stage has no validation)."""
    ls, oe = (None if s is None else s.validation for s in (least_squares, output_error))
    if ls is None or oe is None or ls.rmse is None or oe.rmse is None or not len(ls.rmse):
        return None
    if all(o > l for o, l in zip(oe.rmse, ls.rmse)):
        return oe.source
    return None


def jointly_determined_cell(name, joint, report) -> str:
    """One parameter of the jointly-determined NOTE: `theta1 (108x, +- 39 %) with Ir2 (-0.99), ...`;
    an estimate its error reaches past zero (one at a bound, e.g. a friction) is given as value and
    error, since a relative error of millions of per cent says nothing."""
    std, value = report["std_errors"].get(name), report["parameters"][name]
    if std is None:
        alone = ""
    elif value and std < abs(value):
        alone = f", +- {100 * std / abs(value):.2g} %"
    else:
        alone = f", {value:.3g} +- {std:.2g}"
    partners = ", ".join(f"{p} ({c:+.2f})" for p, c in zip(joint["with"], joint["correlations"]))
    return f"{name} ({joint['inflation']:.0f}x{alone}) with {partners or 'several others'}"
