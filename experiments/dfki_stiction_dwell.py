"""Rising static friction on the DFKI fits: the static level built by the time at rest (`Stiction(dwell_time=...)`).

    DYNAX_SHARED=/work/shared python experiments/dfki_stiction_dwell.py \\
        --fits experiments/results/dfki_stiction_startband/results.json --out experiments/results/dfki_stiction_dwell

Not a fit: each refined model of `--fits` (`dfki_stiction.py`: the split at 5.25 s and the LORO folds that fit run 12)
simulated on its held-out record with its `Stiction` terms

- removed (`without`), as fitted (`fitted`: the level there at once);
- with a memory of rest that builds over `dwell_time` $T_d$ in the stick band and is worn off by a slip of 5 mrad
  (`dwell_{T_d}`, for $T_d$ = 0.05, 0.1, 0.3, 1 s): a joint that only passes through zero speed at a reversal has
  little of the static level, one that starts at rest has all of it.

Every window starts as `identify` validates a model with `Stiction` (`held_out_error(..., start_at_rest=True)`:
zero speed where a joint rests within its record's noise), the lab's `model_3.0` on the same windows. The LORO runs
never rest, so there the rule changes no window. Position RMSE at 0.1, 0.25 and 0.5 s; for the folds also the
change against the fit without `Stiction` (`experiments/results/dfki_default_identification`).

Writes `OUT/results.json`.

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets (or `$DYNAX_SHARED/datasets`).
"""

import argparse
import json
import pathlib

import jax

jax.config.update("jax_enable_x64", True)

# The script's folder is on sys.path.
from dfki_default_identification import lab_model, load, model_of  # noqa: E402
from dfki_simulation import read_parameters  # noqa: E402
from dfki_stiction import cut, TODAY  # noqa: E402

import dynax  # noqa: E402

HORIZONS = (0.1, 0.25, 0.5)
DWELLS = (0.05, 0.1, 0.3, 1.0)


def variants(entry) -> dict[str, dynax.AbstractSystem]:
    base = model_of(entry["parameters"])
    levels = {int(k[2:]) - 1: v for k, v in entry["stiction_terms"].items()}

    def model(**kwargs):
        terms = tuple(dynax.Stiction(j, v["fs"], velocity_scale=v["band"], **kwargs) for j, v in levels.items())
        return dynax.Extended(base.system, base.terms + terms)

    return {"without": base, "fitted": model()} | {f"dwell_{d:g}": model(dwell_time=d) for d in DWELLS}


def score(models, record, lab=None) -> dict:
    out = {
        name: [float(v) for v in dynax.held_out_error(m, [record], HORIZONS, start_at_rest=True).rmse]
        for name, m in models.items()
    }
    if lab is not None:
        lab_error = dynax.held_out_error(lab, [record], HORIZONS, start_at_rest=True)
        out["lab_model_3.0"] = [float(v) for v in lab_error.rmse]
    for name, r in out.items():
        print(f"  {name}: " + " / ".join(f"{v:.5f}" for v in r), flush=True)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--fits", required=True, type=pathlib.Path, help="a dfki_stiction.py results.json")
    parser.add_argument("--folds", default="01,05,03")
    parser.add_argument("--out", required=True, type=pathlib.Path)
    args = parser.parse_args(argv)
    fits = json.loads(args.fits.read_text())
    today = json.loads(TODAY.read_text())["runs"]
    lab = lab_model(read_parameters("model_3.0"))
    args.out.mkdir(parents=True, exist_ok=True)
    results = {"fits": str(args.fits), "horizons_s": list(HORIZONS), "dwells_s": list(DWELLS), "loro": {}}

    def save():
        (args.out / "results.json").write_text(json.dumps(results, indent=2) + "\n")

    print("split at 5.25 s, run 12 from 5.25 s:", flush=True)
    tail = cut(load("12"), 5.25)[1]
    results["split_5.25"] = score(variants(fits["split"]["5.25"]), tail, lab)
    save()
    for held in args.folds.split(","):
        print(f"held out {held}:", flush=True)
        entry = score(variants(fits["loro"][held]), load(held))
        before = today[held]["dynax"]
        entry["change_percent"] = {
            name: [100.0 * (a / b - 1.0) for a, b in zip(r, before, strict=True)] for name, r in entry.items()
        }
        entry["without_stiction_fit"] = before
        print(
            "  change [%]: "
            + "; ".join(f"{k} " + "/".join(f"{v:+.2f}" for v in c) for k, c in entry["change_percent"].items()),
            flush=True,
        )
        results["loro"][held] = entry
        save()
    print(f"wrote {args.out / 'results.json'}", flush=True)


if __name__ == "__main__":
    main()
