"""`dynax diagnose SYSTEM TRAIN... [--validation VAL...] --out DIR`: the discrepancy workflow on measured runs."""

import argparse
import contextlib
import sys
import time

from .._errors import UsageError
from ._common import add_data_options, data_options, read_nominal_parameters
from ._output import staged_directory, write_json

_SYSTEMS = ("acrobot", "double_pendulum", "linear_axis", "helicopter")


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
    parser.add_argument("data", nargs="+", metavar="DATA",
                        help="training run(s): CSV, NPZ or MAT with t, the states and the inputs")
    parser.add_argument("--validation", nargs="+", default=None, metavar="VAL", help="held-out run(s) (same columns)")
    add_data_options(parser)
    parser.add_argument("--mode", choices=("refit", "known"), default="refit",
                        help="refit the nominal parameters on DATA (default) or trust them (known)")
    parser.add_argument("--nominal", default=None, metavar="FILE.json",
                        help="nominal parameters: a JSON with a 'parameters' object (e.g. the output of dynax identify)")
    parser.add_argument("--refit", default=None, metavar="NAMES",
                        help="comma-separated nominal parameters to refit (default all but the nominal friction, which "
                             "the friction candidates test, e.g. theta1..theta5; for linear_axis mass and "
                             "offset; for helicopter the Tempest weights, e.g. du/u,dv/1)")
    parser.add_argument("--dt", type=float, default=None, metavar="SECONDS",
                        help="resample the records to this interval first (default: as recorded)")
    parser.add_argument("--reference-horizon", type=float, default=None, metavar="SECONDS",
                        help="horizon at which the gain is judged (default: the predictability horizon of the "
                             "nominal model on the training runs, see report.json 'horizon')")
    parser.add_argument("--max-terms", type=int, default=3, help="at most this many causes (default 3)")
    parser.add_argument("--velocities", choices=("auto", "measured"), default="auto",
                        help="auto (default): where a joint velocity's measurement noise exceeds the bias of a local "
                             "cubic fit of the positions, take the velocity from that fit (report.json data.velocities "
                             "says which); measured: use the velocities as recorded")
    parser.add_argument("--no-discovery", action="store_true",
                        help="do not search for a term beyond the cause vocabulary when structure is left")
    parser.add_argument("--out", required=True, help="output directory")
    parser.set_defaults(run=run)


def nominal_system(name: str, parameters: dict | None = None):
    """The nominal model dynax diagnoses for a contract system name, with `parameters` (from `--nominal`) set
    (linear_axis: Coulomb friction and offset 0 unless given)."""
    from .._model import Acrobot, DoublePendulum, LinearAxis

    if name == "helicopter":
        # The Tempest acceleration model; --nominal may give its free weights by name (`du/u`, `dv/1`, ...).
        from .._diagnose._fit import nominal_parameter_names, with_nominal_values
        from .._model._helicopter import Helicopter

        system = Helicopter()
        names = nominal_parameter_names(system)
        unknown = sorted(set(parameters or {}) - set(names))
        if unknown:
            raise UsageError(f"--nominal: {unknown} are not weights of the helicopter's Tempest model {list(names)}")
        import jax.numpy as jnp

        values = dict(zip(names, system.body_model.parameter_vector()))
        values.update({k: float(v) for k, v in (parameters or {}).items()})
        return with_nominal_values(system, names, [jnp.asarray(float(values[n])) for n in names])
    else:
        cls = {"acrobot": Acrobot, "double_pendulum": DoublePendulum, "linear_axis": LinearAxis}[name]
        defaults = {"coulomb": 0.0, "offset": 0.0} if name == "linear_axis" else {}
    import jax.numpy as jnp

    values = {**defaults, **(parameters or {})}
    try:
        return cls(**{k: jnp.asarray(float(v)) for k, v in values.items()})
    except TypeError as e:
        raise UsageError(f"--nominal: parameters {sorted(values)} do not fit {cls.__name__}: {e}") from None


def _split_term_coefficients(system_name: str, parameters: dict) -> tuple[dict, str | None]:
    """`--nominal` parameters that are coefficients of the vocabulary's terms (`fc2`, `Ir2`: what `dynax
    identify --friction coulomb` and its refinement write for a two-link arm) rather than fields of the
    nominal system: set aside, since the nominal model has no such term, with a note saying so; the
    candidates of those causes test them from zero. Other unknown names are left for `nominal_system`
    to refuse."""
    if system_name == "helicopter":
        return parameters, None
    from .._diagnose._candidates import default_candidates

    system = nominal_system(system_name)
    terms = {t.parameter_name(system): t for t in default_candidates(system)}
    aside = {k: v for k, v in parameters.items() if k in terms and not hasattr(system, k)}
    if not aside:
        return parameters, None
    listed = ", ".join(f"{k} = {v:.4g} ({terms[k].cause} at {terms[k].where(system)})" for k, v in aside.items())
    note = (f"--nominal gave {listed}; the nominal model has no such term, so the value was set aside and the "
            f"candidates of that cause test it from zero (the diagnosis may name it again).")
    return {k: v for k, v in parameters.items() if k not in aside}, note


# The defaults describe one machine (Drake's acrobot, the EMPS axis). Least squares on the user's runs
# that puts a size parameter (an inertia, a mass, a gravity term) outside this factor of the default's
# says the data come from another machine.
DEFAULT_SIZE_FACTOR = 2.0


def nominal_from_data(system, train) -> tuple[object, str]:
    """Without `--nominal`: the default model if the training runs agree with its size, else the rigid
    body identified from them.

    Least squares (`identify(system, train, Dynamic(), refine=False, holdout=0)`: filter settings from
    the data, consistency constrained) estimates the base parameters. If every size parameter
    (non-friction base parameters that consistency requires positive: theta1, theta2, theta4, theta5;
    the axis's mass) lies within `DEFAULT_SIZE_FACTOR` of the default's, the default model is kept.
    Otherwise the nominal model is that estimate with its friction set to zero, so that the friction
    candidates test friction (viscous and Coulomb) from zero rather than inherit the least-squares
    viscous coefficient, which absorbs part of a Coulomb friction's effect. Returns the model and a note.
    """
    import jax.numpy as jnp

    from .._identify import Dynamic, identify

    from .._errors import DataError

    try:
        estimate = identify(system, train, Dynamic(), refine=False, holdout=0).parameters
    except DataError as e:  # too little excitation to tell: keep the default, and say so
        return system, f"No --nominal: the default {type(system).__name__} parameters (least squares could not check them: {e})."
    kinds = system.base_parameter_kinds()
    friction = {n for n, (group, _) in system.base_parameter_meanings().items() if group == "friction"}
    size = [n for n, kind in kinds.items() if kind in ("positive", "inertia1") and n not in friction]
    default = {n: float(getattr(system, n)) for n in size}
    ratios = {n: estimate[n] / default[n] for n in size}
    far = {n: r for n, r in ratios.items() if not 1 / DEFAULT_SIZE_FACTOR <= r <= DEFAULT_SIZE_FACTOR}
    listed = ", ".join(f"{n} {estimate[n]:.4g} (default {default[n]:.4g})" for n in size)
    if not far:
        return system, (f"No --nominal: the default {type(system).__name__} parameters, which least squares on the "
                        f"training runs confirms within a factor {DEFAULT_SIZE_FACTOR:g} ({listed}).")
    values = {n: jnp.asarray(v) for n, v in estimate.items() if n in kinds and n not in friction}
    values.update({n: jnp.zeros_like(jnp.asarray(getattr(system, n))) for n in friction})
    nominal = system.with_base_parameters(values)
    worst = max(far, key=lambda n: abs(jnp.log(far[n])))
    return nominal, (f"No --nominal, and the training runs are not the default {type(system).__name__} "
                     f"(least squares: {listed}; {worst} is {far[worst]:.3g} times the default): the nominal model is "
                     "the rigid body identified from the training runs by least squares, with zero friction, which "
                     "the friction candidates test. Pass --nominal to diagnose against a model of your own.")


def run(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)  # the CLI identifies in float64; the library does not change config

    from .._data import load_trajectory, resample
    from .._diagnose import diagnose, Known, Refit, write_report

    mapping, scale = data_options(args)
    if args.dt is not None and not args.dt > 0:
        raise UsageError(f"--dt must be positive, got {args.dt}")
    if args.reference_horizon is not None and not args.reference_horizon > 0:
        raise UsageError(f"--reference-horizon must be positive, got {args.reference_horizon}")
    if args.max_terms < 1:
        raise UsageError(f"--max-terms must be at least 1, got {args.max_terms}")
    parameters, cli_notes = None, []
    if args.nominal is not None:
        parameters = read_nominal_parameters(args.nominal)
        parameters, set_aside = _split_term_coefficients(args.system, parameters)
        if set_aside:
            print(f"note: {set_aside}", file=sys.stderr)
            cli_notes.append(set_aside)
    # Everything that can be refused is read before anything is written.
    train = [load_trajectory(path, args.system, mapping=mapping, scale=scale, min_samples=50) for path in args.data]
    validation = None
    if args.validation is not None:
        validation = [load_trajectory(path, args.system, mapping=mapping, scale=scale, min_samples=50)
                      for path in args.validation]
    if args.dt is not None:
        train = [resample(t, args.dt) for t in train]
        validation = None if validation is None else [resample(v, args.dt) for v in validation]
    system = nominal_system(args.system, parameters)
    if args.nominal is None and args.system != "helicopter":
        system, note = nominal_from_data(system, train)
        print(f"note: {note}", file=sys.stderr)
        cli_notes.append(note)
    if args.mode == "known":
        mode = Known()
    else:
        names = tuple(n.strip() for n in args.refit.split(",") if n.strip()) if args.refit else None
        mode = Refit(parameters=names)
    with stage_log() as say:
        report = diagnose(
            system, train, validation, mode=mode, reference_horizon_s=args.reference_horizon,
            max_terms=args.max_terms, system_name=args.system, discovery=not args.no_discovery,
            velocities=args.velocities, progress=say,
        )
    report.notes.extend(cli_notes)
    held_out = validation if validation is not None else [_held_out(t) for t in train]
    with staged_directory(args.out) as stage:
        write_report(report, stage, held_out, write_json=write_json)
    print(summary(report))
    print(f"wrote {args.out}/report.json, report.md and figures")
    return 0


@contextlib.contextmanager
def stage_log():
    """`say(line)` for a diagnosis on the command line: a progress bar on stderr with one step per stage and
    per candidate batch, each stage's line (with the elapsed time) written above it; without a terminal the
    lines alone, as a log; nothing under `--quiet` (see `dynax._progress`)."""
    from .._progress import ProgressBar

    start = time.perf_counter()
    with ProgressBar(None, "diagnose", unit="stage") as bar:
        yield lambda line: bar.say(f"[{time.perf_counter() - start:5.1f} s] {line}")


def _held_out(train, fraction: float = 0.3):
    from .._data import Trajectory

    k = int(round(len(train) * (1 - fraction)))
    return Trajectory(train.ts[k:], train.xs[k:], train.us[k:], train.state_names, train.input_names, train.system, train.source)


def summary(report) -> str:
    """A few lines for the terminal: what the simulation got wrong, the cause, the gain."""
    j = report.to_json()
    ref = j["reference_horizon_s"]
    h = j["nominal"]["sim_error"]["horizons_s"]
    i = h.index(ref) if ref in h else len(h) - 1
    unit = "m" if j["system"] in ("linear_axis", "helicopter") else "rad"
    lines = [
        "What the simulation gets wrong: held-out position RMSE of the nominal model "
        + ", ".join(f"{r:.3g} {unit} at {t:g} s" for t, r in zip(h, j["nominal"]["sim_error"]["rmse"]) if r is not None) + ".",
    ]
    s = j["structure"]["nominal"]
    if s["significant"]:
        lines.append(f"Its one-step residuals have structure ({max(s['r2'], 0):.0%} explained by "
                     + ", ".join(f["feature"] for f in s["top_features"][:2]) + ").")
    if "horizon" in j:
        lines.append(f"Reference horizon {ref:g} s: {j['horizon']['rule']}.")
    lines.append(f"Verdict: {j['verdict']}.")
    if j.get("test", {}).get("detectable_gain") is not None:
        lines.append(f"The test would have detected a gain of about {j['test']['detectable_gain']:.0%} at {ref:g} s.")
    for f in j["findings"]:
        if f["cause"] == "discovered":
            lines.append(f"Discovered (beyond the vocabulary) at {f['where']}: {f['formula']}; gain {f['gain']:.0%}"
                         + "".join(f"; {r}" for r in f["readings"]) + ".")
            continue
        components = "".join(f", {n} = {v:.4g}" for n, v in f.get("components", {}).items())
        lines.append(f"Cause: {f['cause']} at {f['where']}, {f['parameter']} = {f['coefficient']:.4g} "
                     f"(± {f['std_error']:.2g}{components}); gain {f['gain']:.0%}; look-alikes told apart: {f['confidence']}.")
    if j["findings"]:
        lines.append(f"Gain of the extended model ({', '.join(j['extended']['terms'])}): "
                     f"{j['gain']:.0%} less simulation error at {ref:g} s "
                     f"({j['nominal']['sim_error']['rmse'][i]:.3g} -> {j['extended']['sim_error']['rmse'][i]:.3g} {unit}).")
    if j["not_identifiable"]:
        lines.append("Not identifiable in this mode: " + ", ".join(f"{c['cause']}@{c['where']}" for c in j["not_identifiable"]) + ".")
    return "\n".join(lines)
