"""`dynax diagnose SYSTEM TRAIN... [--validation VAL...] --out DIR`: the discrepancy workflow on measured runs."""

import argparse
import contextlib
import dataclasses
import time
import warnings

from .._errors import UsageError
from ._common import (
    add_data_options,
    add_exclude_option,
    add_time_option,
    data_options,
    finite_seconds,
    load_records,
    read_nominal_parameters,
)
from ._nominal import check_nominal, nominal_from_data, nominal_system, split_term_coefficients
from ._notes import current
from ._output import staged_directory, write_json

_SYSTEMS = ("acrobot", "double_pendulum", "linear_axis", "helicopter", "quadrotor")


def register(subparsers):
    parser = subparsers.add_parser(
        "diagnose",
        help="show what a model's simulation gets wrong, name the cause, extend the model, measure the gain",
        description=(
            "Fit the nominal model of SYSTEM on DATA, show what its simulation gets wrong on held-out data, "
            "name the cause from the library of model extensions, extend the model and measure the gain. "
            "Several training and held-out runs may be given; runs are never concatenated and no window crosses "
            "a run boundary. Writes DIR/report.json (the contract's schema), DIR/report.md and figures DIR/*.png. "
            "Without --validation the last 30% of each training run is held out."
        ),
    )
    parser.add_argument("system", choices=_SYSTEMS, help="the system (its data columns are in the contract)")
    parser.add_argument(
        "data", nargs="+", metavar="DATA", help="training run(s): CSV, NPZ or MAT with t, the states and the inputs"
    )
    parser.add_argument("--validation", nargs="+", default=None, metavar="VAL", help="held-out run(s) (same columns)")
    add_data_options(parser)
    add_time_option(parser)
    add_exclude_option(parser)
    parser.add_argument(
        "--mode",
        choices=("refit", "known"),
        default="refit",
        help="refit the nominal parameters on DATA (default) or trust them (known)",
    )
    parser.add_argument(
        "--nominal",
        default=None,
        metavar="FILE.json",
        help="nominal parameters: a JSON with a 'parameters' object (e.g. the output of dynax identify)",
    )
    parser.add_argument(
        "--refit",
        default=None,
        metavar="NAMES",
        help="comma-separated nominal parameters to refit (default all but the nominal friction, which "
        "the friction candidates test, e.g. theta1..theta5; for linear_axis mass and "
        "offset; for helicopter the Tempest weights, e.g. du/u,dv/1; for quadrotor `thrust`, the thrust "
        "map, with which battery sag and ground effect are tested, and `moments`, the roll, pitch and yaw motor "
        "weights, with which rate damping is)",
    )
    parser.add_argument(
        "--dt",
        type=float,
        default=None,
        metavar="SECONDS",
        help="resample the records to this interval first (default: as recorded)",
    )
    parser.add_argument(
        "--reference-horizon",
        type=float,
        default=None,
        metavar="SECONDS",
        help="horizon at which the gain is judged (default: the predictability horizon of the "
        "nominal model on the training runs, see report.json 'horizon')",
    )
    parser.add_argument("--max-terms", type=int, default=3, help="at most this many causes (default 3)")
    parser.add_argument(
        "--velocities",
        choices=("auto", "measured", "positions"),
        default="auto",
        help="auto (default): where a joint velocity's measurement noise exceeds the bias of a local "
        "cubic fit of the positions, take the velocity from that fit (report.json data.velocities "
        "says which); measured: use the velocities as recorded; positions: leave the files' velocity "
        "columns unread and estimate them from the positions (for a logged velocity that lags its angle)",
    )
    parser.add_argument(
        "--no-discovery",
        action="store_true",
        help="do not search for a term beyond the cause vocabulary when structure is left",
    )
    parser.add_argument(
        "--no-cross-fit",
        action="store_true",
        help="test on the held-out runs alone; by default, with three or more training runs, each "
        "training run is also held out in turn (refitted on the others) and the test pools them",
    )
    parser.add_argument("--out", required=True, help="output directory")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)  # the CLI identifies in float64; the library does not change config

    from .._diagnose import diagnose, Horizons, Known, Refit, Selection, write_report
    from .._diagnose._records import holdout_split

    if args.system == "quadrotor":  # flight logs: ground segments, glitches, the body frame (`_quadrotor.py`)
        from ._quadrotor import run_diagnose

        return run_diagnose(args)
    data_options(args)  # a malformed --map, --scale or --offset is refused before any work
    if args.dt is not None:
        finite_seconds(args.dt, "--dt")
    if args.reference_horizon is not None:
        finite_seconds(args.reference_horizon, "--reference-horizon")
    if args.max_terms < 1:
        raise UsageError(f"--max-terms must be at least 1, got {args.max_terms}")
    parameters, cli_notes = None, []
    if args.nominal is not None:
        parameters = read_nominal_parameters(args.nominal)
        parameters, set_aside = split_term_coefficients(args.system, parameters)
        if set_aside:
            current().note("nominal_terms_set_aside", set_aside, file=args.nominal)
            cli_notes.append(set_aside)
    # Everything that can be refused is read before anything is written. With the parameters known, a record
    # that nothing drives is still a test of them: a zero or constant input is then said, not refused.
    from .._data import DataWarning
    from .._data._sanity import Check

    lenient = (Check.ZERO, Check.CONSTANT) if args.mode == "known" else ()
    train, validation, data_notes = load_records(args, args.system, min_samples=MIN_SAMPLES, lenient=lenient)
    cli_notes += data_notes  # printed and kept for `warnings` by `load_records`; in the report's notes too
    if args.dt is not None:
        train = [_resampled(t, args.dt) for t in train]
        validation = None if validation is None else [_resampled(v, args.dt) for v in validation]
    system = nominal_system(args.system, parameters)
    if args.nominal is not None:
        check_nominal(system, args.nominal)
    if args.nominal is None and args.system != "helicopter":
        # Only what the diagnosis trains on: without --validation, the first part of each record.
        with warnings.catch_warnings():  # the records' faults were refused or printed by `load_records`
            warnings.simplefilter("ignore", DataWarning)
            system, note = nominal_from_data(
                system, train if validation is not None else [holdout_split(t)[0] for t in train]
            )
        current().note("nominal_from_data", note)
        cli_notes.append(note)
    if args.mode == "known":
        mode = Known()
    else:
        names = tuple(n.strip() for n in args.refit.split(",") if n.strip()) if args.refit else None
        mode = Refit(parameters=names)
    with stage_log() as say, warnings.catch_warnings():  # the records' faults: refused or printed above
        warnings.simplefilter("ignore", DataWarning)
        report = diagnose(
            system,
            train,
            validation,
            mode=mode,
            horizons=Horizons(reference_s=args.reference_horizon),
            selection=Selection(
                max_terms=args.max_terms,
                discovery=not args.no_discovery,
                cross_fit=not args.no_cross_fit,
                velocities="auto" if args.velocities == "positions" else args.velocities,
            ),
            progress=say,
        )
    report.notes.extend(cli_notes)
    # the contract's name, whatever the files say; what the run warned of and noted, for report.json's `warnings`
    report = dataclasses.replace(report, system=args.system, warnings=current().to_json())
    held_out = validation if validation is not None else [holdout_split(t)[1] for t in train]
    with staged_directory(args.out) as stage:
        write_report(report, stage, held_out, write_json=write_json)
    print(summary(report))
    print(f"wrote {args.out}/report.json, report.md and figures")
    return 0


MIN_SAMPLES = 50  # the fewest samples of a record diagnose reads (before and after --dt)


def _resampled(trajectory, dt: float):
    """`trajectory` resampled to `dt`, refusing a `--dt` that leaves too few samples of it."""
    from .._data import resample

    n = int((trajectory.duration + 1e-9 * dt) // dt) + 1
    if n < MIN_SAMPLES:
        raise UsageError(
            f"--dt {dt:g} s leaves {n} sample(s) of the {trajectory.duration:.4g} s record "
            f"{trajectory.source}; at least {MIN_SAMPLES} are needed: give --dt at most "
            f"{trajectory.duration / (MIN_SAMPLES - 1):.4g} s (is the interval in seconds?)"
        )
    return resample(trajectory, dt)


@contextlib.contextmanager
def stage_log():
    """`say(line)` for a diagnosis on the command line: a progress bar on stderr with one step per stage and
    per candidate batch, each stage's line (with the elapsed time) written above it; without a terminal the
    lines alone, as a log; nothing under `--quiet` (see `dynax._progress`)."""
    from .._progress import ProgressBar

    start = time.perf_counter()
    with ProgressBar(None, "diagnose", unit="stage") as bar:
        yield lambda line: bar.say(f"[{time.perf_counter() - start:5.1f} s] {line}")


def _tested_gain(j: dict, finding: dict) -> float | None:
    """The held-out gain the paired test judged a finding on (its round's window error over every state, scaled),
    where it differs from the reported position gain: a rate damping can pass on the attitude and rates while the
    position at the reference horizon gains nothing."""
    for r in j.get("rounds", []):
        for c in r.get("candidates", []):
            if c.get("outcome") == "selected" and (c["cause"], c["where"]) == (finding["cause"], finding["where"]):
                gain = c.get("gain")
                return None if gain is None or round(gain, 2) == round(finding["gain"], 2) else float(gain)
    return None


def summary(report) -> str:
    """A few lines for the terminal: what the simulation got wrong, the cause, the gain."""
    j = report.to_json()
    ref = j["reference_horizon_s"]
    h = j["nominal"]["sim_error"]["horizons_s"]
    i = h.index(ref) if ref in h else len(h) - 1
    unit = "m" if j["system"] in ("linear_axis", "helicopter", "quadrotor") else "rad"
    lines = [
        "What the simulation gets wrong: held-out position RMSE of the nominal model "
        + ", ".join(f"{r:.3g} {unit} at {t:g} s" for t, r in zip(h, j["nominal"]["sim_error"]["rmse"]) if r is not None)
        + ".",
    ]
    s = j["structure"]["nominal"]
    if s["significant"]:
        lines.append(
            f"Its one-step residuals have structure ({max(s['r2'], 0):.0%} explained by "
            + ", ".join(f["feature"] for f in s["top_features"][:2])
            + ")."
        )
    if "horizon" in j:
        lines.append(f"Reference horizon {ref:g} s: {j['horizon']['rule']}.")
    lines.append(f"Verdict: {j['verdict']}.")
    if j.get("test", {}).get("detectable_gain") is not None:
        lines.append(
            f"The test would have detected a gain of about {j['test']['detectable_gain']:.0%} in mean squared window "
            f"error at {ref:g} s."
        )
    for f in j["findings"]:
        if f["cause"] == "discovered":
            lines.append(
                f"Discovered (beyond the vocabulary) at {f['where']}: {f['formula']}; gain {f['gain']:.0%}"
                + "".join(f"; {r}" for r in f["readings"])
                + "."
            )
            continue
        components = "".join(f", {n} = {v:.4g}" for n, v in f.get("components", {}).items())
        tested = _tested_gain(j, f)
        lines.append(
            f"Cause: {f['cause']} at {f['where']}, {f['parameter']} = {f['coefficient']:.4g} "
            f"(± {f['std_error']:.2g}{components}); gain {f['gain']:.0%}"
            + (f" ({tested:.0%} in the tested window error over every state)" if tested is not None else "")
            + f"; look-alikes told apart: {f['confidence']}."
        )
    if j["findings"]:
        lines.append(
            f"Gain of the extended model ({', '.join(j['extended']['terms'])}): "
            f"{j['gain']:.0%} less simulation error (position RMSE) at {ref:g} s "
            f"({j['nominal']['sim_error']['rmse'][i]:.3g} -> {j['extended']['sim_error']['rmse'][i]:.3g} {unit})."
        )
    if j["not_identifiable"]:
        lines.append(
            "Not identifiable in this mode: "
            + ", ".join(f"{c['cause']}@{c['where']}" for c in j["not_identifiable"])
            + "."
        )
    if j.get("not_proposed"):
        lines.append(
            "Not proposed (no rest under load in the records): "
            + ", ".join(f"{c['cause']}@{c['where']}" for c in j["not_proposed"])
            + "."
        )
    flights = getattr(report, "flight_error", None)
    if flights is not None:  # a flight diagnosis: the held-out scores per group, and what they note
        lines.append(flights.summary())
        if flights.note is not None:
            lines.append(f"Note: {flights.note}")
    return "\n".join(lines)
