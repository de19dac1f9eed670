"""`identify`'s static level on synthetic stick-slip records, with the output-error refinement.

    python experiments/stick_slip_identification.py --out experiments/results/stick_slip_identification

The records are the hidden-effect battery's stick-slip cases (`tests/hidden_cases.py`: Karnopp's switch
integrated by scipy's DOP853 with events, outside dynax's model code, with the encoders' noise of 1 mrad
and 0.01 rad/s): a static level of 0.5 N m at the elbow and no Coulomb level, under held, drifting torques
that rest the elbow under load and break it away (`stiction@q2`), and the same truth swung by a multisine,
which never rests (`swinging`); a static level of 0.8 N m at the shoulder instead (`shoulder`, the
battery's `stiction@q1`); and a sticking Coulomb friction of 0.5 N m at the elbow, static and sliding level
alike (`coulomb`, the battery's `coulomb_friction@q2-0.5-sticking_coulomb`). `identify` runs with its
defaults and the static level on (`Dynamic(static_friction=True)`, `friction="coulomb"`, the
refinement where the velocities are noisy) on all of the data (`holdout=0`). Reported: the level read from
the rests (and its kind), the band, the refined level, each against the truth, and each still stretch under a
torque with the friction its measured motion leaves (`moves`: it gives no level); on the swinging records,
that no `Stiction` is added and the parameters equal those of the same fit without the rest search.

Writes `OUT/results.json`.
"""

import argparse
import dataclasses
import json
import pathlib
import sys
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax.internal import rest_search_off  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from tests.hidden_cases import CASES, records  # noqa: E402


def case(name):
    (found,) = [c for c in CASES if c.name == name]
    return found


def fit(data, **kwargs):
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = dynax.identify(
            dynax.DoublePendulum(),
            data,
            dynax.Dynamic(static_friction=True),
            friction="coulomb",
            validation=dynax.Validate(holdout=0),
            **kwargs,
        )
    return result, time.perf_counter() - start


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument(
        "--parts",
        default="stick,swinging",
        help="stick: the stick-slip records; shoulder: the same at the shoulder; coulomb: a sticking Coulomb "
        "friction at the elbow; swinging: no rest",
    )
    args = parser.parse_args(argv)
    parts = args.parts.split(",")
    args.out.mkdir(parents=True, exist_ok=True)
    stick = case("double_pendulum-stiction@q2-0.5-stick-slip")
    swinging = dataclasses.replace(stick, name="double_pendulum-stiction@q2-0.5-swinging", law="stick-slip swinging")
    out = {"truth": {"joint": "q2", "fs": stick.size, "fc": 0.0}}
    if "stick" in parts:
        stick_slip(stick, out, "stick_slip")
    if "shoulder" in parts:
        shoulder = case("double_pendulum-stiction@q1-0.8-stick-slip")
        out["truth_shoulder"] = {"joint": "q1", "fs": shoulder.size, "fc": 0.0}
        stick_slip(shoulder, out, "shoulder")
    if "coulomb" in parts:
        coulomb = case("double_pendulum-coulomb_friction@q2-0.5-sticking_coulomb")
        out["truth_coulomb"] = {"joint": "q2", "fs": coulomb.size, "fc": coulomb.size}
        stick_slip(coulomb, out, "coulomb")
    if "swinging" in parts:
        no_rest(swinging, out)
    (args.out / "results.json").write_text(json.dumps(out, indent=2) + "\n")


def stick_slip(stick, out, key):
    result, seconds = fit(list(records(stick)))
    joints = result.static_friction.joints
    truth = {"q1": 0, "q2": 1}[stick.where]
    out[key] = {
        "fit_seconds": seconds,
        "refined": len(result.stages) > 1,
        "joints": [j.to_json() for j in joints],
        "level_error": {j.name: j.level / stick.size - 1 for j in joints if j.joint == truth},
        "refined_error": {
            j.name: j.refined / stick.size - 1 for j in joints if j.joint == truth and j.refined is not None
        },
        "stretches": [
            {k: v for k, v in s.to_json().items() if k not in ("held_position", "speed_noise")}
            for s in result.static_friction.stretches
            if s.held != 0.0
        ],
        "note": result.static_friction.note,
    }
    print(f"{key} ({seconds:.0f} s): {result.static_friction.note}; refined {out[key]['refined_error']}")


def no_rest(swinging, out):
    data = list(records(swinging))
    result, seconds = fit(data)
    terms = [t for t in getattr(result.system, "terms", ()) if isinstance(t, dynax.Stiction)]
    with rest_search_off():
        before, _ = fit(data)
    out["swinging"] = {
        "fit_seconds": seconds,
        "stiction_terms": len(terms),
        "note": result.static_friction.note,
        "parameters_identical": bool(np.array_equal(np.asarray(result.estimate), np.asarray(before.estimate))),
    }
    print(
        f"swinging ({seconds:.0f} s): {len(terms)} Stiction terms; identical: {out['swinging']['parameters_identical']}"
    )


if __name__ == "__main__":
    main()
