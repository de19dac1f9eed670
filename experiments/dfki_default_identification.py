"""Leave-one-run-out identification of the DFKI double pendulum with default settings, against the lab's model.

    python experiments/dfki_default_identification.py --out experiments/results/dfki_default_identification

(`--record-weights motion` for the previous default, each record weighted by its motion alone)

(or folds in parallel: `--runs 00,01,02 --out A`, `--runs 03,05,12 --out B`, then `--merge A B --out ...`)

`--variant 5ms|10ms|half|noise` fits the training runs recorded otherwise (as
`diagnose_real_splits.py --variant` makes them: resampled at 5 or 10 ms; at 5 ms and cut to their
first half; at 5 ms with white noise of 0.3 rad/s on the velocities and 0.03 N m on the torques
added) and still validates on the held-out run as recorded, so that the table compares with the
default one: a check that the defaults follow the data, not one format of it. Results in
`experiments/results/dfki_identify_variants/VARIANT/`. `--variant encoders` reads the training runs
as encoder angles alone (the mapping without `dq1`, `dq2`: `load_trajectory` estimates them by
backward differences) at their median interval.

`--band-from positions` takes each record's filter band from its angles' spectra (the ratio of
signal to white noise a differentiator keeps) instead of its velocities' (docs/data.md, "Why not
the band of the angles themselves"): `--runs 00,03,05 --band-from positions --out OUT`.

`--velocities positions` reads every run's velocities from its angles (`load_trajectory(velocities=
"positions")`, as `dynax identify --velocities positions` does) instead of the logged columns, which lag
the angles by half a 2 ms interval (the `lag` data check); each fold is scored from both kinds of start
state, for dynax's fit and for the lab's model (`by_start_velocities` in `results.json`):
`--runs 03 --velocities positions --out OUT`.

`--stagger K` cuts the records into segments K times, each cut a 1/K segment after the last
(identify's default is 4; `--stagger 1` gives the single cut used before).

`--segment-band-hz F` sets the band edge that the refinement's segment length is one period of
(default: the widest band `choose_filter` reads off the training runs), to see how much the
segmentation alone moves a fold (docs/devdocs/dfki_loro.md, "The count of cells is within what the
fit's own settings move"): `--runs 01 --segment-band-hz 5.5 --out OUT`.

For each of the six `sys_id` runs: fit `identify(DoublePendulum(), other_five_runs, Dynamic(),
friction="coulomb", validation=[this_run])` with no recipe (every setting chosen from the data),
and simulate the held-out run open loop from 200 start samples; compare the position RMSE at 0.1,
0.25 and 0.5 s with the lab's `model_3.0` on the same windows. Writes `results.json` and
`loro.png`. Runs are resampled at their median interval (2 ms; run 12: 1.6 ms).

Each cell also gets the paired test `diagnose` uses (`paired_block_test`: the flat-top HAC over the
overlapping windows, Student's t) on the per-window log ratio of the two models' squared errors,
one-sided each way (`paired_test` in `results.json`): whether dynax is significantly better or
worse than the lab there, or whether the windows cannot tell them apart.

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets.
"""

import argparse
import dataclasses
import json
import math
import pathlib
import time
from typing import ClassVar

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
from dfki_simulation import DFKI, MAPPING, read_parameters  # noqa: E402  (the script's folder is on sys.path)
import diagnose_real_splits  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax import AbstractJointTerm, held_out_error  # noqa: E402
from dynax.internal import (  # noqa: E402
    DEFAULT_RECORD_WEIGHTS,
    filter_rule,
    log_ratio_differences,
    noise_floor_and_band,
    paired_block_test,
    RECORD_WEIGHTS,
    refinement_method,
    refinement_options,
    RefinementStatistics,
    trim_and_decimation,
)

RUNS = ("00", "01", "02", "03", "05", "12")
HORIZONS = (0.1, 0.25, 0.5)


def lab_parameters(p: dict[str, float]) -> dict[str, float]:
    """The lab's equations in dynax's base parameters, rotor inertia with its coupling exactly.

    Their M11 = I1 + I2 + l1^2 m2 + 2 l1 m2 r2 cos q2 + (gr^2 + 1) Ir, M12 = I2 + l1 m2 r2 cos q2 - gr Ir,
    M22 = I2 + gr^2 Ir are dynax's M with theta1 = I1 + l1^2 m2 + (gr^2 + gr + 1) Ir,
    theta2 = I2 - gr Ir and RotorInertia(1) = Ir2 = (gr^2 + gr) Ir. Friction b dq + cf atan(100 dq): viscous
    b, Coulomb fc = cf pi/2 of tanh(100 dq) (same saturation; the slope at rest differs by pi/2).
    """
    gr, ir, g = p["gr"], p["Ir"], p["g"]
    return dict(
        theta1=p["I1"] + p["l1"] ** 2 * p["m2"] + (gr**2 + gr + 1) * ir,
        theta2=p["I2"] - gr * ir,
        theta3=p["l1"] * p["m2"] * p["r2"],
        theta4=g * (p["m1"] * p["r1"] + p["m2"] * p["l1"]),
        theta5=g * p["m2"] * p["r2"],
        theta6=p["b1"],
        theta7=p["b2"],
        fc1=p["cf1"] * math.pi / 2,
        fc2=p["cf2"] * math.pi / 2,
        Ir2=(gr**2 + gr) * ir,
    )


def model_of(p: dict[str, float]) -> dynax.AbstractSystem:
    """The double pendulum of base parameters `theta1..theta7`, Coulomb friction `fc1`, `fc2` and
    elbow rotor inertia `Ir2` (what `identify` returns here, as a dict)."""
    rigid = dynax.DoublePendulum.from_base_parameters({k: p[k] for k in (f"theta{i}" for i in range(1, 8))})
    return dynax.Extended(
        rigid, (dynax.CoulombFriction(0, p["fc1"]), dynax.CoulombFriction(1, p["fc2"]), dynax.RotorInertia(1, p["Ir2"]))
    )


def lab_model(p: dict[str, float]) -> dynax.AbstractSystem:
    """The lab's `model_3.0` (its `model_parameters.yml` as a dict) as a dynax model (`lab_parameters`)."""
    return model_of(lab_parameters(p))


class ArctanFriction(AbstractJointTerm):
    r"""The lab's own friction law at one joint, $-c_f \arctan(100 \dot q_j)$ (its `cf1`, `cf2`), written
    out for the comparison only: `lab_model` maps it to dynax's `CoulombFriction` with the same
    saturation, which at every speed is the stronger (at 0.1 rad/s, $c_f \pi/2$ against
    $1.471\,c_f$)."""

    joint: int = eqx.field(static=True)
    coefficient: jax.Array
    cause: ClassVar[str] = "coulomb_friction"
    prefix: ClassVar[str] = "cf"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1

    def __init__(self, joint: int, cf: float):
        self.joint = joint
        self.coefficient = jnp.asarray(cf, float)

    def force(self, q, dq):
        return -self.coefficient * jnp.arctan(100.0 * dq)


def lab_model_as_written(p: dict[str, float]) -> dynax.AbstractSystem:
    """`model_3.0` with its friction as the lab writes it (`ArctanFriction`), not mapped to a tanh:
    `lab_model` with its two `CoulombFriction` terms replaced."""
    mapped = lab_model(p)
    return dynax.Extended(mapped.system, (ArctanFriction(0, p["cf1"]), ArctanFriction(1, p["cf2"]), mapped.terms[2]))


INPUTS = ["hold", "hold"]  # --inputs, --score-inputs: how `load` resamples the training and held-out runs' inputs


def load(run: str, variant: str = "native", velocities: str = "measured", held_out: bool = True) -> dynax.Trajectory:
    """One run at its median interval (`native`), or changed as `diagnose_real_splits.load` says; `velocities`
    as `load_trajectory` takes it (`"positions"`: estimated from the angles, not the logged columns)."""
    if variant not in ("native", "encoders"):
        return diagnose_real_splits.load(DFKI.parent, run, variant)
    mapping = MAPPING if variant == "native" else {k: v for k, v in MAPPING.items() if not k.startswith("dq")}
    raw = dynax.load_trajectory(
        DFKI / "sys_id" / f"trajectory_{run}.csv", "double_pendulum", mapping=mapping, velocities=velocities
    )
    return dynax.resample(raw, raw.dt, inputs=INPUTS[not held_out])


def cell_tests(model, lab, record, horizons) -> list[dict]:
    """Per horizon, the paired test of dynax's held-out window errors against the lab's on the same windows.

    `d` is `log_ratio_differences(lab, dynax)` of each window's mean squared position error (positive:
    dynax better); `ratio` is $e^{-\\bar d/2}$, dynax's error over the lab's as a geometric mean over
    windows; `p_better` and `p_worse` are the one-sided p-values of `paired_block_test` on `d` and
    `-d` (windows `overlap` = horizon over stride share data)."""
    mine, theirs = (dynax.simulation_error(m, record, horizons) for m in (model, lab))
    stride_s = float((mine.starts[1] - mine.starts[0]) * record.dt)
    out = []
    for k, h in enumerate(horizons):
        d = log_ratio_differences(np.asarray(theirs.window_mse[:, k]), np.asarray(mine.window_mse[:, k]))
        runs, overlap = np.zeros(d.size, int), math.ceil(h / stride_s - 1e-9)
        better, worse = paired_block_test(d, runs, overlap), paired_block_test(-d, runs, overlap)
        out.append(
            {
                "horizon_s": h,
                "ratio": float(np.exp(-better.mean / 2)),
                "mean_log_ratio": better.mean,
                "std_error": better.std_error,
                "df": better.df,
                "p_better": better.p_value,
                "p_worse": worse.p_value,
            }
        )
    return out


def band_from_positions(trajectory, choice, *, snr=100.0):
    """A `filter_rule`: each record's band read from its angles' spectra instead of its velocities' (the widest
    angle band, with the trim and decimation that go with it), where the velocities' rule filters at all."""
    if choice.cutoff_hz is None:
        return choice
    fs = 1.0 / trajectory.dt
    n = len(trajectory.state_names) // 2
    bands = {
        name: noise_floor_and_band(np.asarray(trajectory.xs[:, k]), fs, snr=snr)[1]
        for k, name in enumerate(trajectory.state_names[n:])
    }
    band = max(bands.values())
    trim, decimate = trim_and_decimation(fs, band, len(trajectory))
    return dataclasses.replace(
        choice,
        cutoff_hz=band,
        trim=trim,
        decimate=decimate,
        band_hz=bands,
        reason=f"band from the angles' spectra: {band:.3g} Hz",
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--runs", default=",".join(RUNS), help="held-out runs to evaluate (default all six)")
    parser.add_argument(
        "--merge",
        nargs="+",
        type=pathlib.Path,
        default=(),
        metavar="DIR",
        help="fit nothing: merge the results.json of earlier runs (e.g. folds run in parallel)",
    )
    parser.add_argument(
        "--record-weights",
        choices=RECORD_WEIGHTS,
        default=DEFAULT_RECORD_WEIGHTS,
        help="weights of the records in the output-error refinement (default: %(default)s)",
    )
    parser.add_argument(
        "--variant",
        choices=("native", "encoders") + diagnose_real_splits.VARIANTS[:1] + diagnose_real_splits.VARIANTS[2:],
        default="native",
        help="how the training runs are recorded (the held-out run stays native)",
    )
    parser.add_argument(
        "--segment-band-hz",
        type=float,
        default=None,
        metavar="F",
        help="segments of 1/F s in the refinement instead of one period of the widest band's edge",
    )
    parser.add_argument(
        "--stagger",
        type=int,
        default=None,
        metavar="K",
        help="fit K staggered cuts of the records into segments (SimulationFit.stagger; default "
        "identify's, 4; 1 for the single cut of the table before 2026-11-26's afternoon)",
    )
    parser.add_argument(
        "--offsets",
        choices=("auto", "force", "angles"),
        default="auto",
        help="Dynamic(offsets=...): auto (identify's default: angle zeros or force offsets per record, "
        "whichever explains the runs clearly better), force (force offsets, the default before "
        "2026-11-27) or angles",
    )
    parser.add_argument(
        "--band-from",
        choices=("velocities", "positions"),
        default="velocities",
        help="the spectra the filter band is read from (default: %(default)s, identify's)",
    )
    parser.add_argument(
        "--velocities",
        choices=("measured", "positions"),
        default="measured",
        help="the velocities of every run, training and held out: the logged columns (measured, the default) "
        "or estimated from the angles (load_trajectory(velocities='positions'), `dynax identify --velocities "
        "positions`); each fold is also scored from both kinds of start state (`by_start_velocities`)",
    )
    parser.add_argument(
        "--inputs",
        choices=("hold", "average", "linear"),
        default="hold",
        help="how each run's inputs are put on its uniform grid (experiments/input_resampling.py; default: "
        "%(default)s, dynax.resample's)",
    )
    parser.add_argument(
        "--score-inputs",
        choices=("hold", "average", "linear"),
        default=None,
        help="how the held-out run's inputs are resampled for scoring (default: as --inputs): `--inputs average "
        "--score-inputs hold` scores a fit to averaged inputs on today's held-out records",
    )
    args = parser.parse_args(argv)
    INPUTS[:] = [args.inputs if args.score_inputs is None else args.score_inputs, args.inputs]
    with filter_rule(band_from_positions if args.band_from == "positions" else None):
        with refinement_options(record_weights=args.record_weights):
            fit_folds(args)


def refinement(train, method, args):
    """identify's default refinement of `train` (`"auto"`), with `--segment-band-hz` and `--stagger` applied."""
    if args.segment_band_hz is None and args.stagger is None:
        return "auto"
    default = refinement_method("auto", dynax.DoublePendulum(), method, train)
    if default is None:
        return False
    if args.segment_band_hz is not None:
        default = dataclasses.replace(default, segment_s=1.0 / args.segment_band_hz)
    if args.stagger is not None:
        default = dataclasses.replace(default, stagger=args.stagger)
    return default


def fit_folds(args):
    results = {"horizons_s": list(HORIZONS), "runs": {}}
    for part in args.merge:
        results["runs"].update(json.loads((part / "results.json").read_text())["runs"])
    held_out = [] if args.merge else args.runs.split(",")
    runs = {r: load(r, velocities=args.velocities) for r in RUNS} if held_out else {}
    training = {r: load(r, args.variant, args.velocities, held_out=False) for r in RUNS} if held_out else {}
    # The held-out runs both ways: the windows' start states from the logged velocities or from the angles.
    starts = {v: {r: load(r, velocities=v) for r in held_out} for v in ("measured", "positions")}
    lab = lab_model(read_parameters("model_3.0")) if held_out else None
    for held in held_out:
        train = [training[r] for r in RUNS if r != held]
        start = time.perf_counter()
        offsets = {"auto": "auto", "force": True, "angles": "angles"}[args.offsets]
        method = dynax.Dynamic(offsets=offsets)
        result = dynax.identify(
            dynax.DoublePendulum(),
            train,
            method,
            friction="coulomb",
            refine=refinement(train, method, args),
            validation=dynax.Validate([runs[held]], horizons_s=HORIZONS),
        )
        refined = result.stages[-1].solution.statistics  # the output-error refinement's
        assert isinstance(refined, RefinementStatistics)
        seconds = time.perf_counter() - start
        lab_error = held_out_error(lab, [runs[held]], HORIZONS)
        paired = cell_tests(result.system, lab, runs[held], HORIZONS)
        stages = result.to_json()["stages"]
        by_start = {
            v: {
                "dynax": list(held_out_error(result.system, [starts[v][held]], HORIZONS).rmse),
                "lab_model_3.0": list(held_out_error(lab, [starts[v][held]], HORIZONS).rmse),
            }
            for v in starts
        }
        entry = {
            "velocities": args.velocities,
            "by_start_velocities": by_start,
            "fit_seconds": seconds,
            "dynax": list(result.validation.rmse),
            "dynax_least_squares": stages["least_squares"]["validation"]["rmse"],
            "lab_model_3.0": list(lab_error.rmse),
            "paired_test": paired,
            "parameters": result.parameters,
            "least_squares_parameters": stages["least_squares"]["parameters"],
            "consistency": result.consistency.to_json(),
            "least_squares_consistency": stages["least_squares"]["consistency"],
            "relative_equation_error": {k: v["relative_equation_error"] for k, v in stages.items()},
            "record_weights_mode": args.record_weights,
            "variant": args.variant,
            "segment_s": stages["output_error"].get("segment_s"),
            "stagger": args.stagger,
            "training_runs": [r for r in RUNS if r != held],
            "record_weights": list(refined.record_weights),
            "record_residual_scale": list(refined.record_sigma),
            "reweights": refined.reweights,
            "input_timing": stages["output_error"].get("input_timing"),
            "offsets": args.offsets,
            "angle_zeros": None if result.angle_zeros is None else result.angle_zeros.to_json(),
            "settings": [
                {k: s[k] for k in ("lowpass_hz", "lowpass_order", "trim", "decimate")} for s in result.settings
            ],
        }
        results["runs"][held] = entry
        print(
            f"held out {held} ({seconds:.0f} s): dynax "
            + " ".join(f"{v:.3f}" for v in entry["dynax"])
            + " | least squares "
            + " ".join(f"{v:.3f}" for v in entry["dynax_least_squares"])
            + " | lab "
            + " ".join(f"{v:.3f}" for v in entry["lab_model_3.0"])
            + " | p worse/better "
            + " ".join(f"{c['p_worse']:.2g}/{c['p_better']:.2g}" for c in paired)
            + "".join(
                f" | starts {v}: dynax "
                + " ".join(f"{x:.4f}" for x in by_start[v]["dynax"])
                + " lab "
                + " ".join(f"{x:.4f}" for x in by_start[v]["lab_model_3.0"])
                for v in by_start
            )
            + f" | consistent {entry['consistency']['consistent']}"
            + " | weights "
            + " ".join(f"{w:.2f}" for w in entry["record_weights"])
            + " | residual scale "
            + " ".join(f"{v:.1f}" for v in entry["record_residual_scale"])
            + f" | {entry['reweights']} refits"
            + (
                ""
                if entry["input_timing"] is None
                else f" | input latency {1e3 * entry['input_timing']['latency_s']:.2f} ms"
            ),
            flush=True,
        )
    # The lab's model with its own arctan friction: cheap, independent of the fits, so filled in for
    # merged folds made before it was added too.
    written = lab_model_as_written(read_parameters("model_3.0"))
    for run, entry in results["runs"].items():
        if "lab_model_3.0_arctan" not in entry:
            record = runs[run] if run in runs else load(run)
            entry["lab_model_3.0_arctan"] = list(held_out_error(written, [record], HORIZONS).rmse)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.json").write_text(json.dumps(results, indent=2) + "\n")

    held_runs = sorted(results["runs"])
    fig, axes = plt.subplots(1, len(HORIZONS), figsize=(5 * len(HORIZONS), 4))
    x = np.arange(len(held_runs))
    for ax, (k, h) in zip(axes, enumerate(HORIZONS)):
        for offset, (key, label) in zip(
            (-0.27, 0.0, 0.27),
            (
                ("dynax", "dynax (default)"),
                ("dynax_least_squares", "dynax least-squares stage"),
                ("lab_model_3.0", "lab model_3.0"),
            ),
        ):
            ax.bar(x + offset, [results["runs"][r][key][k] for r in held_runs], 0.27, label=label)
        ax.set_xticks(x, [f"run {r}" for r in held_runs])
        ax.set(yscale="log", ylabel="position RMSE [rad]", title=f"held-out run, {h:g} s open loop")
    axes[0].legend(fontsize=8)
    fig.suptitle("DFKI double pendulum, leave one run out (DFKI RIC Underactuated Robotics Lab)")
    fig.tight_layout()
    fig.savefig(args.out / "loro.png", dpi=110)
    print(f"wrote {args.out / 'results.json'} and {args.out / 'loro.png'}")


if __name__ == "__main__":
    main()
