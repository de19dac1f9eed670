"""Where the static level costs DFKI runs that never rest: which joint, which part of the friction law, which windows.

    DYNAX_SHARED=/work/shared python experiments/dfki_stiction_motion.py \\
        --fits experiments/results/dfki_stiction_dissipative/results.json --folds 01,05 \\
        --out experiments/results/dfki_stiction_motion

Not a fit: each LORO fold's refined model (`dfki_stiction.py --parts loro`, read from `--fits`) simulated on its
held-out run, which never rests, with its `Stiction` terms

- removed (`without`), as fitted (`fitted`), at one joint only (`q1 only`, `q2 only`);
- with the slip part alone (`slip only`: the Stribeck excess over the Coulomb level in motion, no stick band) or
  the stick band alone (`stick only`: the held force in the band, no excess in motion).

Per variant the position RMSE at 0.1, 0.25 and 0.5 s, pooled and per joint; for the fitted terms, the windows
that carry the change at 0.5 s (start, change of the window's mean squared error, per joint) and the share of the
change the ten largest carry.

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
from dfki_default_identification import load, model_of  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402

HORIZONS = (0.1, 0.25, 0.5)


class SlipOnly(dynax.Stiction):
    """The Stribeck excess in motion, no stick band."""

    def weight(self, dq):
        return jnp.zeros_like(dq)


class StickOnly(dynax.Stiction):
    """The stick band, no excess in motion."""

    def slip_force(self, dq, coulomb):
        return jnp.zeros_like(dq)


def variants(entry) -> dict[str, dynax.AbstractSystem]:
    base = model_of(entry["parameters"])
    levels = {int(k[2:]) - 1: v for k, v in entry["stiction_terms"].items()}

    def model(kind=dynax.Stiction, joints=tuple(levels)):
        terms = tuple(kind(j, levels[j]["fs"], velocity_scale=levels[j]["band"]) for j in joints)
        return dynax.Extended(base.system, base.terms + terms)

    return {
        "without": base,
        "fitted": model(),
        "q1 only": model(joints=(0,)),
        "q2 only": model(joints=(1,)),
        "slip only": model(SlipOnly),
        "stick only": model(StickOnly),
    }


def fold(held: str, entry: dict) -> dict:
    record = load(held)
    out, errors = {}, {}
    for name, model in variants(entry).items():
        errors[name] = {
            s: dynax.simulation_error(model, record, HORIZONS, states=s) for s in (("q1", "q2"), ("q1",), ("q2",))
        }
        out[name] = {"+".join(s): [float(v) for v in e.rmse] for s, e in errors[name].items()}
        print(
            f"held out {held}, {name}: "
            + "; ".join(f"{k} " + " ".join(f"{v:.5f}" for v in r) for k, r in out[name].items()),
            flush=True,
        )
    ts = np.asarray(record.ts)
    starts = np.asarray(errors["fitted"][("q1", "q2")].starts)
    change = {
        s: np.asarray(errors["fitted"][s].window_mse)[:, 2] - np.asarray(errors["without"][s].window_mse)[:, 2]
        for s in (("q1", "q2"), ("q1",), ("q2",))
    }
    pooled = change[("q1", "q2")]
    top = np.argsort(-np.abs(pooled))[:10]
    out["windows_0.5s"] = {
        "change_sum": {"+".join(s): float(c.sum()) for s, c in change.items()},
        "top10_share": float(pooled[top].sum() / pooled.sum()),
        "worse": int((pooled > 0).sum()),
        "better": int((pooled < 0).sum()),
        "top": [
            {
                "start_s": float(ts[starts[k]]),
                "q1+q2": float(pooled[k]),
                "q1": float(change[("q1",)][k]),
                "q2": float(change[("q2",)][k]),
            }
            for k in top
        ],
    }
    print(f"held out {held}: {json.dumps(out['windows_0.5s'])}", flush=True)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--fits", required=True, type=pathlib.Path, help="a dfki_stiction.py results.json")
    parser.add_argument("--folds", default="01,05")
    parser.add_argument("--out", required=True, type=pathlib.Path)
    args = parser.parse_args(argv)
    fits = json.loads(args.fits.read_text())["loro"]
    args.out.mkdir(parents=True, exist_ok=True)
    results = {"fits": str(args.fits), "horizons_s": list(HORIZONS), "folds": {}}
    for held in args.folds.split(","):
        results["folds"][held] = fold(held, fits[held])
        (args.out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.out / 'results.json'}", flush=True)


if __name__ == "__main__":
    main()
