"""Friction at rest on the DFKI double pendulum: the static level `identify` reads, and what it does to held-out errors.

    DYNAX_SHARED=/work/shared python experiments/dfki_stiction.py --out experiments/results/dfki_stiction

(`--parts six,split,loro` chooses the measurements, `whatif` adds a what-if on the 5.25 s split, `paired` a
paired test of each LORO fold's model against the fit without the static level on the same windows,
`bandwhatif` one on each LORO fold's held-out run (the band against the level); `--splits 5.25` the splits;
`--folds 00,01` the LORO folds; each part writes its
results into `OUT/results.json` as it finishes, so a run cut short keeps what it measured.)

Three measurements, all with `identify`'s defaults (`Dynamic()`, `friction="coulomb"`, every setting
chosen from the data), in float64:

1. **six**: the six shared `sys_id` runs (00, 01, 02, 03, 05, 12). Run 12 swings up and rests at the
   top from 4.63 s (q1) and 4.76 s (q2) to its end (`rest_stretches`); the other runs never rest. Fitted
   twice: as `identify` does by default (the last 20 % of each record held out for validation: run 12's
   tail from 4.8 s is then not fitted) and with all of the data fitted (`Validate(holdout=0)`). The static level
   read, the torque held (`experiments/dfki_windows.py` measured 0.155 and -0.175 N m with the lab's
   model over 4.75 s to the end) and the note.
2. **split**: the issue's split, runs 00-05 plus run 12 up to 4.5 s fitted and run 12 from 4.5 s on
   held out (no rest in the fitted part: it starts at 4.63 s), and a split that leaves rest in the
   fitted part (up to 5.25 s, held out from 5.25 s: 0.6 s of rest at q1 and 0.5 s at q2 fitted). Position
   RMSE of open-loop windows at 0.1, 0.25, 0.5 s against the lab's `model_3.0` on the same windows.
3. **loro**: leave one run out, as `experiments/dfki_default_identification.py`, against that script's
   table (`experiments/results/dfki_default_identification/results.json`, the fits before the static
   level): the folds that fit run 12 (held-out 00 to 05) now carry `Stiction`.

Writes `OUT/results.json` and `OUT/stiction.png` (the LORO cells and the splits against the lab).

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets (or `$DYNAX_SHARED/datasets`).
"""

import argparse
import json
import pathlib
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
# The script's folder is on sys.path.
from dfki_default_identification import cell_tests, lab_model, load, model_of, RUNS
from dfki_simulation import read_parameters  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax.internal import rest_stretches  # noqa: E402

HORIZONS = (0.1, 0.25, 0.5)
TODAY = pathlib.Path(__file__).resolve().parent / "results" / "dfki_default_identification" / "results.json"
SPLITS_S = (4.5, 5.25)


def fit(train, **kwargs):
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = dynax.identify(
            dynax.DoublePendulum(),
            train,
            dynax.Dynamic(static_friction=True),
            friction="coulomb",
            validation=dynax.Validate(horizons_s=HORIZONS, **kwargs),
        )
    return result, time.perf_counter() - start


def summary(result, seconds) -> dict:
    out = result.to_json()
    return {
        "fit_seconds": seconds,
        "parameters": result.parameters,
        "static_friction": out.get("static_friction"),
        "validation": out["validation"],
        "stiction_terms": {
            f"fs{t.joint + 1}": {
                "fs": float(t.coefficient),
                "held": float(t.held(result.system.system)),
                "band": float(t.velocity_scale),
                "dwell_s": None if t.dwell_time is None else float(t.dwell_time),
            }
            for t in getattr(result.system, "terms", ())
            if isinstance(t, dynax.Stiction)
        },
    }


def speeds_zeroed_everywhere_at_rest(record: dynax.Trajectory) -> tuple[dynax.Trajectory]:
    """`record` with every speed sample of its joints' rests at zero, whatever its size (the reading of the
    tables before `speeds_zeroed_at_rest` read the record's noise), for the comparison."""
    xs = np.array(record.xs)
    ts = np.asarray(record.ts)
    for s in rest_stretches(record):
        xs[(ts >= s.start_s) & (ts <= s.stop_s), 2 + s.joint] = 0.0
    return (
        dynax.Trajectory(
            record.ts, xs, record.us, record.state_names, record.input_names, record.system, record.source
        ),
    )


def cut(record: dynax.Trajectory, seconds: float):
    k = int(np.searchsorted(np.asarray(record.ts) - float(record.ts[0]), seconds))
    return record.slice(None, k), record.slice(k, None)


def six(runs, results, save):
    data = [runs[r] for r in RUNS]
    for name, kwargs in (("all_fitted", {"holdout": 0}), ("default", {})):
        result, seconds = fit(data, **kwargs)
        results.setdefault("six", {})[name] = summary(result, seconds)
        print(f"six runs, {name} ({seconds:.0f} s): {result.static_friction.note}", flush=True)
        save()


def split(runs, lab, results, save, splits=SPLITS_S):
    for at in splits:
        head, tail = cut(runs["12"], at)
        train = [runs[r] for r in RUNS if r != "12"] + [head]
        result, seconds = fit(train, records=[tail])
        # `identify` validates a model with `Stiction` from windows that start at zero speed where a joint rests
        # within the noise (`start_at_rest`); the lab's model is scored by the same rule on the same windows, and
        # both also from the measured state (the reading of the tables before that rule).
        at_rest = result.validation.source.endswith("within the noise")
        entry = summary(result, seconds) | {
            "split_s": at,
            "dynax": list(result.validation.rmse),
            "dynax_least_squares": result.to_json()["stages"]["least_squares"]["validation"]["rmse"],
            "validated_start_at_rest": at_rest,
            "lab_model_3.0": list(dynax.held_out_error(lab, [tail], HORIZONS, start_at_rest=at_rest).rmse),
            "rest_fitted_s": {s.coordinate: s.duration for s in rest_stretches(head) if s.duration > 0},
        }
        entry["measured_start"] = {
            "dynax": list(dynax.held_out_error(result.system, [tail], HORIZONS).rmse),
            "lab_model_3.0": list(dynax.held_out_error(lab, [tail], HORIZONS).rmse),
        }
        # The former second reading: every sample of the tail's rests at zero speed, whatever its size.
        (settled,) = speeds_zeroed_everywhere_at_rest(tail)
        entry["zero_speed_at_rest"] = {
            "dynax": list(dynax.held_out_error(result.system, [settled], HORIZONS).rmse),
            "lab_model_3.0": list(dynax.held_out_error(lab, [settled], HORIZONS).rmse),
        }
        results.setdefault("split", {})[f"{at:g}"] = entry
        print(
            f"split at {at:g} s ({seconds:.0f} s): dynax "
            + " ".join(f"{v:.4f}" for v in entry["dynax"])
            + " | lab "
            + " ".join(f"{v:.4f}" for v in entry["lab_model_3.0"])
            + f" (start at rest: {at_rest}) | from the measured state: dynax "
            + " ".join(f"{v:.4f}" for v in entry["measured_start"]["dynax"])
            + " lab "
            + " ".join(f"{v:.4f}" for v in entry["measured_start"]["lab_model_3.0"])
            + " | every rest sample at zero speed: dynax "
            + " ".join(f"{v:.4f}" for v in entry["zero_speed_at_rest"]["dynax"])
            + " lab "
            + " ".join(f"{v:.4f}" for v in entry["zero_speed_at_rest"]["lab_model_3.0"])
            + f" | {result.static_friction.note}",
            flush=True,
        )
        save()


def loro(runs, lab, folds, results, save):
    today = json.loads(TODAY.read_text())["runs"]
    for held in folds:
        train = [runs[r] for r in RUNS if r != held]
        result, seconds = fit(train, records=[runs[held]])
        before = today[held]["dynax"]
        entry = summary(result, seconds) | {
            "dynax": list(result.validation.rmse),
            "dynax_before": before,
            "lab_model_3.0": today[held]["lab_model_3.0"],
            "change": [a / b - 1 for a, b in zip(result.validation.rmse, before)],
        }
        results.setdefault("loro", {})[held] = entry
        print(
            f"held out {held} ({seconds:.0f} s): dynax "
            + " ".join(f"{v:.4f}" for v in entry["dynax"])
            + " | before "
            + " ".join(f"{v:.4f}" for v in before)
            + " | change "
            + " ".join(f"{100 * c:+.1f}%" for c in entry["change"])
            + f" | stiction {entry['stiction_terms']}",
            flush=True,
        )
        save()


def whatif(runs, lab, results, save):
    """Not a fit: the model fitted up to 5.25 s with `Stiction` put back at its least-squares levels (times
    1 and 1.5, stick band 0.01 and 0.1 rad/s), on run 12 from 5.25 s; and with its refined levels (times 1 and
    1.5) on the same windows started at zero speed where the tail rests. Read off the held-out data."""
    entry = results["split"]["5.25"]
    base = model_of(entry["parameters"])
    levels = {j["joint"]: j["level"] for j in entry["static_friction"]["joints"]}
    tail = cut(runs["12"], 5.25)[1]
    out = {"refined": list(dynax.held_out_error(base, [tail], HORIZONS).rmse)}
    for scale in (1.0, 1.5):
        for band in (0.01, 0.1):
            terms = tuple(dynax.Stiction(j, scale * f, velocity_scale=band) for j, f in levels.items())
            model = dynax.Extended(base.system, base.terms + terms)
            out[f"{scale:g}x_band_{band:g}"] = list(dynax.held_out_error(model, [tail], HORIZONS).rmse)
    out["lab_model_3.0"] = list(dynax.held_out_error(lab, [tail], HORIZONS).rmse)
    # The same from zero speed where the tail rests, at the refined levels times 1 and 1.5 (band 0.01).
    (settled,) = speeds_zeroed_everywhere_at_rest(tail)
    refined = {int(k[2:]) - 1: v["fs"] for k, v in entry["stiction_terms"].items()}
    for scale in (1.0, 1.5):
        terms = tuple(dynax.Stiction(j, scale * f) for j, f in refined.items())
        model = dynax.Extended(base.system, base.terms + terms)
        out[f"zero_start_refined_{scale:g}x"] = list(dynax.held_out_error(model, [settled], HORIZONS).rmse)
    results["whatif_5.25"] = out
    print("what-if, run 12 from 5.25 s: " + "; ".join(f"{k} {v[0]:.4f}/{v[1]:.3f}/{v[2]:.3f}" for k, v in out.items()))
    save()


def band_whatif(runs, results, save):
    """Not a fit: each LORO fold's refined model on its held-out run without `Stiction`, with it at a 0.01 rad/s
    band, and with it as fitted (the band from the velocity noise at rest): which of the level and the band
    costs a run that never rests."""
    for held, entry in results.get("loro", {}).items():
        if not entry.get("stiction_terms"):
            continue
        base = model_of(entry["parameters"])
        out = {"without": list(dynax.held_out_error(base, [runs[held]], HORIZONS).rmse)}
        for name, band in (("band_0.01", 0.01), ("as_fitted", None)):
            terms = tuple(
                dynax.Stiction(int(k[2:]) - 1, v["fs"], velocity_scale=v["band"] if band is None else band)
                for k, v in entry["stiction_terms"].items()
            )
            model = dynax.Extended(base.system, base.terms + terms)
            out[name] = list(dynax.held_out_error(model, [runs[held]], HORIZONS).rmse)
        results.setdefault("band_whatif", {})[held] = out
        print(
            f"band what-if, held out {held}: "
            + "; ".join(f"{k} {v[0]:.4f}/{v[1]:.4f}/{v[2]:.4f}" for k, v in out.items())
        )
        save()


def stiction_model(entry) -> dynax.AbstractSystem:
    """A fold's refined model rebuilt from its results entry: `model_of` its parameters with its `Stiction` terms."""
    base = model_of(entry["parameters"])
    terms = tuple(
        dynax.Stiction(int(k[2:]) - 1, v["fs"], velocity_scale=v["band"], dwell_time=v.get("dwell_s"))
        for k, v in entry["stiction_terms"].items()
    )
    return dynax.Extended(base.system, base.terms + terms)


def paired(runs, results, save):
    """Not a fit: each LORO fold's model against the fit without the static level (`TODAY`'s parameters) on the
    same held-out windows: `cell_tests`, with `ratio` this model's error over that one's (geometric mean over the
    windows) and `p_worse` the one-sided p-value that it is worse. Also the rebuilt model's RMSE, to check the
    rebuild against the fit's own validation."""
    today = json.loads(TODAY.read_text())["runs"]
    for held, entry in results.get("loro", {}).items():
        model, before = stiction_model(entry), model_of(today[held]["parameters"])
        entry["rebuilt_rmse"] = list(dynax.held_out_error(model, [runs[held]], HORIZONS).rmse)
        entry["against_before"] = cell_tests(model, before, runs[held], HORIZONS)
        print(
            f"held out {held}: rebuilt "
            + " ".join(f"{v:.5f}" for v in entry["rebuilt_rmse"])
            + " | against before: "
            + "; ".join(f"ratio {c['ratio']:.4f} p_worse {c['p_worse']:.3f}" for c in entry["against_before"]),
            flush=True,
        )
        save()


def plot(results, out: pathlib.Path):
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    folds = sorted(results.get("loro", {}))
    x = np.arange(len(folds))
    for k, h in enumerate(HORIZONS):
        change = [100 * results["loro"][f]["change"][k] for f in folds]
        axes[0].bar(x + (k - 1) * 0.27, change, 0.27, label=f"{h:g} s")
    axes[0].axhline(0, color="k", lw=0.5)
    axes[0].set_xticks(x, [f"held-out {f}" for f in folds])
    axes[0].set(ylabel="held-out RMSE change [%]", title="LORO: with the static level against before")
    axes[0].legend(fontsize=8)
    splits = sorted(results.get("split", {}), key=float)
    x = np.arange(len(HORIZONS))
    for i, s in enumerate(splits):
        entry = results["split"][s]
        axes[1].bar(x + (2 * i - 1.5) * 0.2, entry["dynax"], 0.2, label=f"dynax, fit to {s} s")
        axes[1].bar(x + (2 * i - 0.5) * 0.2, entry["lab_model_3.0"], 0.2, label=f"lab model_3.0, from {s} s")
    axes[1].set_xticks(x, [f"{h:g} s" for h in HORIZONS])
    axes[1].set(yscale="log", ylabel="position RMSE [rad]", title="run 12 held out from the split")
    axes[1].legend(fontsize=7)
    fig.suptitle("DFKI double pendulum: friction at rest (DFKI RIC Underactuated Robotics Lab)")
    fig.tight_layout()
    fig.savefig(out / "stiction.png", dpi=110)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--parts", default="six,split,loro")
    parser.add_argument("--folds", default="00,01,02,03,05,12")
    parser.add_argument("--splits", default=",".join(f"{s:g}" for s in SPLITS_S), help="split times [s] of run 12")
    parser.add_argument(
        "--merge", nargs="+", type=pathlib.Path, default=(), metavar="DIR", help="merge the results.json of parts"
    )
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "results.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    for part in args.merge:
        for key, value in json.loads((part / "results.json").read_text()).items():
            results[key] = {**results.get(key, {}), **value} if isinstance(value, dict) else value
    results["horizons_s"] = list(HORIZONS)

    def save():
        path.write_text(json.dumps(results, indent=2) + "\n")

    runs = {r: load(r) for r in RUNS}
    lab = lab_model(read_parameters("model_3.0"))
    parts = args.parts.split(",") if args.parts else []
    save()
    if "six" in parts:
        six(runs, results, save)
    if "split" in parts:
        split(runs, lab, results, save, tuple(float(s) for s in args.splits.split(",")))
    if "whatif" in parts:
        whatif(runs, lab, results, save)
    if "loro" in parts:
        loro(runs, lab, args.folds.split(","), results, save)
    if "paired" in parts:
        paired(runs, results, save)
    if "bandwhatif" in parts:
        band_whatif(runs, results, save)
    plot(results, args.out)
    print(f"wrote {path} and {args.out / 'stiction.png'}", flush=True)


if __name__ == "__main__":
    main()
