"""`dynax fit quadrotor TRAIN...` and `dynax evaluate MODEL.json DATA... --steps 1,10,50`: flight logs."""

import math
import sys
import time

from .._errors import DataError, UsageError
from ._common import data_options, finite_seconds, output_file
from ._notes import current, with_warnings
from ._output import write_json

QUADROTOR_MODELS = ("nominal", "acceleration", "linear")


def load_flights(
    paths,
    options,
    *,
    min_samples: int,
    needs: str = "",
    training=None,
    numbering=None,
    levels=None,
    reference=None,
):
    """Each file through `load_flight` (`options`: its `mapping`, `scale` and `offset`, as `data_options` reads
    them), its ground segments and glitches noted on stdout; the usable
    runs of at least `min_samples` samples (`needs`: the option that asks for that many, named in the
    refusal), and the notes. A flight given twice is refused, and one that is also a `training` flight
    (`{path: trajectory}` of those loaded before) is no validation. `training`, where given, gains the
    flights loaded here. A flight whose motors are numbered otherwise than `numbering` holds them to (a
    `MotorNumbering`: a model's training flights, or the consensus of the flights it has seen, these among
    them) is refused, and so are flights whose motors or battery are logged in another unit than the others'
    (`levels`, `{path: input_levels}` of the flights loaded before, gains these) or than a model's training
    flights (`reference`: `(levels, name)`)."""

    from .._data._flight import check_input_levels, input_levels, load_flight, usable_segments
    from .._data._motor_order import MotorNumbering
    from .._data._sanity import DataCheck, same_data, shared_stretch_findings

    mapping, scale, offset = options
    runs, notes, seen = [], [], {}
    levels = {} if levels is None else levels
    numbering = MotorNumbering() if numbering is None else numbering
    for path in paths:
        trajectory, found = load_flight(path, mapping=mapping, scale=scale, offset=offset)
        for earlier, other in [*seen.items(), *(training or {}).items()]:
            if same_data(trajectory, other):
                held = earlier not in seen
                raise DataError(
                    f"is the same data as the {'training ' if held else ''}flight {earlier}: "
                    + (
                        "held-out error on the training data is in-sample, no validation; give another flight"
                        if held
                        else "the same flight counted twice doubles its weight and shrinks every standard error by "
                        "about 1.4 (the square root of 2); "
                        "give it once"
                    ),
                    path=path,
                )
            # an excerpt of a flight given beside it (a held-out flight cut from a training one, logs that overlap)
            held = earlier not in seen
            kinds = ("training flight" if held else "flight", "held-out flight" if held else "flight")
            DataCheck(
                tuple(shared_stretch_findings(kinds[0], other, 0, kinds[1], trajectory, exclude=False))
            ).raise_refusals()
        seen[str(path)] = trajectory
        _note_flight(path, found)
        numbering.check(trajectory, found.usable, path, dict(mapping or {}))
        levels[str(path)] = input_levels(trajectory, found.usable)
        kept = usable_segments(trajectory, found, min_samples)
        if not kept:
            longest = max((len(run) for run in usable_segments(trajectory, found, 1)), default=0)
            raise DataError(
                f"has no run of flight of {min_samples} samples or more between its ground segments and glitches "
                f"(the longest has {longest})" + (f", which {needs} needs" if needs else ""),
                path=path,
            )
        runs += kept
        if training is not None:
            training[str(path)] = trajectory
        notes.append(
            {
                "file": str(path),
                "ground_s": [list(g) for g in found.ground],
                "glitches": [g.describe() for g in found.glitches],
                "resampled": found.resampled,
                "estimated": found.estimated,
                "usable_samples": int(found.usable.sum()),
                "samples": len(trajectory),
            }
        )
    numbering.settle()
    given, name = reference or ({}, "")
    check_input_levels(levels, columns=dict(mapping or {}), reference=given, reference_name=name)
    for note in notes:  # what the motor-numbering test could see for each file (nothing: it saw all it could)
        said = numbering.notes.get(note["file"], "")
        if said:
            current().note("motor_numbering", f"{note['file']}: {said}", file=note["file"], stream=sys.stdout)
        note["motor_numbering"] = said or ("checked" if str(note["file"]) in numbering.notes else "not compared")
    return runs, notes


def _note_flight(path, found) -> None:
    """Print (stdout) and keep the ground segments and glitches `load_flight` found in `path` and left out."""
    said = current()
    if found.resampled:
        said.note("resampled", f"{path}: {found.resampled}", file=path, stream=sys.stdout, category="data")
    if found.estimated:
        said.note("estimated", f"{path}: {found.estimated}", file=path, stream=sys.stdout, category="data")
    for line, (t0, t1) in zip(found.describe(), found.ground):
        said.note("ground", f"{path}: {line}", file=path, t0=t0, t1=t1, stream=sys.stdout, category="data")
    for line, g in zip(found.describe()[len(found.ground) :], found.glitches):
        rows = None if g.kind == "gap" else (g.row, g.row + max(g.n_samples, 1) - 1)  # a gap: no rows of its own
        said.note(
            g.kind,
            f"{path}: {line}",
            file=path,
            column=g.column,
            rows=rows,
            t0=g.start,
            t1=g.stop,
            stream=sys.stdout,
            category="data",
        )


def run_fit(args) -> int:
    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)  # learning in float64; the library leaves config alone

    from .._data._motor_order import MotorNumbering
    from .._identify._vehicle._quadrotor import quadrotor_to_json
    from .._model._quadrotor import Quadrotor
    from ._fit import fit_everything

    model = args.model or "acceleration"
    if model not in QUADROTOR_MODELS:
        raise UsageError(f"--model {model} is not a quadrotor model; expected one of {list(QUADROTOR_MODELS)}")
    if args.criterion == "frequency":
        raise UsageError(
            "--criterion frequency identifies the helicopter's linear model only; for a quadrotor use "
            "one-step, lagged or backprop"
        )
    from ._fit import check_iterative_options, ridge_option, vehicle_criterion

    check_iterative_options(args)
    ridge = ridge_option(args)
    out = output_file(args.out, "model.json")
    mapping, scale, offset = data_options(args)
    start = time.perf_counter()
    numbering = MotorNumbering()  # the flights' consensus; written into the model for `evaluate` to hold flights to
    runs, notes = load_flights(
        args.data,
        (mapping, scale, offset),
        min_samples=round(args.horizon * 100) + 2,
        needs=f"--horizon {args.horizon:g}",
        numbering=numbering,
    )
    dt = float(np.median([r.dt for r in runs]))
    n_steps = max(round(args.horizon / dt), 1)
    system = Quadrotor.from_flights(model, runs, battery=False if args.no_battery else None)
    stride = args.stride
    if stride == "auto":
        from .._identify._vehicle import auto_stride
        from ._fit import AUTO_WINDOWS

        stride = auto_stride(sum(len(r) for r in runs), n_steps, AUTO_WINDOWS)
    criterion = vehicle_criterion(args, stride, ridge)
    solution = fit_everything(system, runs, criterion)  # `fit_quadrotor`'s call
    weights = np.asarray(solution.model.body_model.weights)
    loss = float(solution.loss)
    if not (np.all(np.isfinite(weights)) and math.isfinite(loss)):
        print(
            f"dynax fit: error: the fit failed numerically (loss {loss}, {int(np.sum(~np.isfinite(weights)))} "
            "non-finite weights); nothing written",
            file=sys.stderr,
        )
        return 1
    horizon = args.horizon if args.criterion in ("lagged", "backprop") else None
    n_samples = sum(len(r) for r in runs)
    write_json(
        out,
        with_warnings(
            quadrotor_to_json(
                solution.model,
                family=model,
                criterion=args.criterion,
                horizon_s=horizon,
                loss=loss,
                n_samples=n_samples,
                data=notes,
                **_signature_entry(numbering.signature()),
            )
        ),
    )
    print(
        f"quadrotor, {model} model, {args.criterion} criterion, {n_samples} samples in {len(runs)} runs of flight: "
        f"loss {loss:.6g}"
    )
    std = solution.standard_errors()
    for name, value in solution.estimates().items():
        e = std.get(name, float("nan"))
        print(f"  {name:>16s} = {value:.6g}" + (f" +- {e:.2g}" if math.isfinite(e) else ""))
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0


def training_levels(system) -> dict[str, float]:
    """The levels in flight (`dynax._data._flight.input_levels`) of a fitted quadrotor's training flights: its
    `input_scale`, the median of each input in flight (the motors' averaged; the battery's where it uses one).
    A scale of exactly 1, `Quadrotor`'s default for a model built without flights, records no level."""
    scale = [float(s) for s in system.input_scale]
    out = {} if all(s == 1.0 for s in scale[:4]) else {"m1": sum(scale[:4]) / 4}
    if system.uses_battery and len(scale) > 4 and scale[4] != 1.0:
        out["vbat"] = scale[4]
    return out


def _signature_entry(reference) -> dict:
    """The model file's `motor_signature` (the training flights' motors, which `dynax evaluate` and `dynax
    diagnose --nominal` test other flights against), where the flights give one."""
    return {} if reference is None else {"motor_signature": reference.to_json()}


def parse_steps(text: str) -> tuple[int, ...]:
    try:
        steps = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise UsageError(f"--steps must be comma-separated whole numbers of samples, got {text!r}") from None
    if not steps or min(steps) < 1:
        raise UsageError(f"--steps must be positive numbers of samples, got {text!r}")
    return steps


def parse_metrics(text: str) -> tuple[str, ...]:
    metrics = tuple(v.strip() for v in text.split(",") if v.strip())
    bad = [m for m in metrics if m not in ("mae", "rmse")]
    if not metrics or bad:
        raise UsageError(f"--metric must be mae, rmse or mae,rmse, got {text!r}")
    return metrics


def run_evaluate(args, system, reference=None) -> int:
    """The quadrotor branch of `dynax evaluate`: flight scores per group beside constant velocity; `reference`,
    the model's training flights' motor signature, where its file has one."""
    from .._data._motor_order import MotorNumbering
    from .._model._quadrotor import ConstantVelocity
    from .._simulate import flight_error, FLIGHT_UNITS

    steps = parse_steps(args.steps or "1,10,50")
    metrics = parse_metrics(args.metric)
    out = output_file(args.out, "metrics.json")
    mapping, scale, offset = data_options(args)
    start = time.perf_counter()
    runs, notes = load_flights(
        args.data,
        (mapping, scale, offset),
        min_samples=max(steps) + 2,
        needs=f"--steps {max(steps)}",
        numbering=MotorNumbering(reference, f"the training flights of {args.model}"),
        reference=(training_levels(system), f"the training flights of {args.model}"),
    )
    if system.uses_battery and "vbat" not in runs[0].input_names:
        raise DataError(
            "has no vbat column, which the model's features use (map it: --map vbat=COLUMN)", path=args.data[0]
        )
    model_error = flight_error(system, runs, steps)
    baseline = flight_error(ConstantVelocity(), runs, steps)
    result = {
        "steps": list(steps),
        "dt_s": model_error.dt,
        "horizons_s": list(model_error.horizons_s),
        "units": FLIGHT_UNITS,
        "model": model_error.scores(metrics),
        "constant_velocity": baseline.scores(metrics),
        "data": notes,
    }
    write_json(out, with_warnings(result))
    print(f"quadrotor model {args.model} on {len(args.data)} file(s)")
    for name, error in (("model", model_error), ("constant velocity", baseline)):
        print("\n".join("  " + line for line in error.summary(name, metrics).splitlines()))
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0


def run_diagnose(args) -> int:
    """The quadrotor branch of `dynax diagnose`: flights loaded as by `dynax fit quadrotor` (ground segments
    and glitches left out, noted), the diagnosis of the rigid body (`--nominal MODEL.json`: a fitted quadrotor
    model, trusted with `--mode known`), the report and its per-group scores beside constant velocity
    (`Report.flight_error`, also written as `flight_error.json`)."""
    import dataclasses
    import json
    import pathlib
    import warnings

    from .._data import DataWarning
    from .._data._motor_order import MotorNumbering, MotorSignature
    from .._diagnose import diagnose, Horizons, Known, Refit, Selection, write_report
    from .._diagnose._quadrotor import body_frame_records, QUADROTOR_HORIZONS_S, quadrotor_refit_names
    from .._diagnose._records import holdout_split
    from .._identify._vehicle._quadrotor import quadrotor_from_json
    from .._model._quadrotor import Quadrotor
    from ._diagnose import stage_log, summary
    from ._output import staged_directory

    if args.dt is not None:
        raise UsageError(
            "--dt does not apply to quadrotor flights: dynax.load_flight resamples each log to its median interval"
        )
    if args.velocities != "auto":
        raise UsageError("--velocities applies to joint records; a quadrotor's velocities are used as logged")
    if getattr(args, "even_times", False):
        raise UsageError(
            "--even-times does not apply to quadrotor flights: dynax.load_flight resamples each log to its "
            "median interval"
        )
    if getattr(args, "exclude", None):
        raise UsageError(
            "--exclude does not apply to quadrotor flights: dynax.load_flight finds their glitches and "
            "ground segments and leaves them out"
        )
    if args.reference_horizon is not None:
        finite_seconds(args.reference_horizon, "--reference-horizon")
    if args.max_terms < 1:
        raise UsageError(f"--max-terms must be at least 1, got {args.max_terms}")
    if args.mode == "known" and args.nominal is None:
        raise UsageError(
            "--mode known trusts a fitted model: give it with --nominal MODEL.json (dynax fit quadrotor "
            "--model nominal)"
        )
    mapping, scale, offset = data_options(args)
    min_samples = round(max(QUADROTOR_HORIZONS_S) * 100) + 2
    obj = None
    if args.nominal is not None:
        try:
            obj = json.loads(pathlib.Path(args.nominal).read_text())
        except (OSError, ValueError) as e:
            raise DataError(f"cannot read the model file ({e})", path=args.nominal) from None
    # the motors' numbering: the nominal model's training flights' where its file says, else the consensus of
    # the flights given, training and validation together
    reference = MotorSignature.from_json(obj.get("motor_signature"), args.nominal) if isinstance(obj, dict) else None
    loaded: dict = {}
    numbering = MotorNumbering(reference, f"the training flights of {args.nominal}")
    nominal = quadrotor_from_json(obj, path=args.nominal) if obj is not None else None
    levels: dict = {}  # training and validation flights together, or each against the nominal model's
    given = None if nominal is None else (training_levels(nominal), f"the training flights of {args.nominal}")

    def load(paths):  # training, then validation flights: one numbering, one level check, each seen once
        runs, _ = load_flights(
            paths,
            (mapping, scale, offset),
            min_samples=min_samples,
            training=loaded,
            numbering=numbering,
            levels=levels,
            reference=given,
        )
        return runs

    train = load(args.data)
    validation = None if args.validation is None else load(args.validation)
    if nominal is not None:
        system = nominal
    else:
        system = Quadrotor.from_flights("nominal", train)
    if args.mode == "known":
        mode = Known()
    else:
        # `thrust`: the thrust map, refitted with battery sag and ground effect; `moments`: the moment map, with
        # rate damping
        mode = Refit(parameters=quadrotor_refit_names(system, args.refit))
    with stage_log() as say, warnings.catch_warnings():  # the flights' faults were noted by load_flights
        warnings.simplefilter("ignore", DataWarning)
        report = diagnose(
            system,
            train,
            validation,
            mode=mode,
            horizons=Horizons(reference_s=args.reference_horizon),
            selection=Selection(
                max_terms=args.max_terms, discovery=not args.no_discovery, cross_fit=not args.no_cross_fit
            ),
            progress=say,
        )
    held_out = validation if validation is not None else [holdout_split(t)[1] for t in train]
    report = dataclasses.replace(report, warnings=current().to_json())  # report.json's `warnings`
    with staged_directory(args.out) as stage:
        write_report(report, stage, body_frame_records(system, held_out), write_json=write_json)
        if report.flight_error is not None:
            write_json(stage / "flight_error.json", report.flight_error.to_json())  # report.json has the warnings
    print(summary(report))  # with the per-group scores and their note
    print(f"wrote {args.out}/report.json, report.md, flight_error.json and figures", file=sys.stdout)
    return 0
