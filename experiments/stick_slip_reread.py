"""The static level read again with the refined rigid body (issue 48): is the output-error fit good enough to read from?

    python experiments/stick_slip_reread.py --out experiments/results/stick_slip_reread
    python experiments/stick_slip_reread.py --every-rest-out --out experiments/results/stick_slip_reread

`identify` runs as in `experiments/stick_slip_identification.py` (defaults, `Dynamic(static_friction=True)`,
`friction="coulomb"`, refinement on, `holdout=0`) on the battery's records with a rest that ends in a breakaway:
stiction of 0.8 N m at the shoulder (`shoulder`) and a sticking Coulomb friction of 0.5 N m at the elbow
(`coulomb`). The least-squares stage and the refined one are kept, and the rests are read again
(the same `static_friction_rests`, `joint_levels`) with the least-squares rigid body, with the refined one (in the
refinement's terms, rotor inertia at the elbow included, its `Stiction` left out), and with the truth's; each on
the records less the least-squares stage's per-record force offsets (as the refinement sees them, and as the
level is read) and on the records as recorded (the truth has no offsets). Then the parameter groups (inertia,
gravity, damping and Coulomb levels) are swapped one at a time between the truth and each fit, to see which
error moves the reading. Writes `OUT/results.json`.

`--every-rest-out`, a what-if with least squares only: the stage refitted without the rows of every rest (loaded
or not) instead of only the loaded ones, and the level read with it. Writes `OUT/every_rest_out.json`.
"""

import argparse
import contextlib
import json
import pathlib
import sys

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax.internal import (  # noqa: E402
    all_rests_left_out,
    joint_levels,
    parameter_names,
    record_rests,
    records_less_offsets,
    static_friction_rests,
    with_friction,
)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from tests.hidden_cases import CASES, records, truth_theta  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from stick_slip_identification import fit as identify_as_stick_slip  # noqa: E402

CASE_NAMES = {
    "shoulder": "double_pendulum-stiction@q1-0.8-stick-slip",
    "coulomb": "double_pendulum-coulomb_friction@q2-0.5-sticking_coulomb",
}
GROUPS = {
    "inertia": ("theta1", "theta2", "theta3", "Ir2"),
    "gravity": ("theta4", "theta5"),
    "damping and Coulomb": ("theta6", "theta7", "fc1", "fc2"),
}


def read(values: dict, data, rests, covariance=None) -> dict:
    """The level at each joint read with the parameters `values` (absent ones zero) on `data`, in the refinement's
    terms (Coulomb friction, rotor inertia at the elbow)."""
    system = with_friction(dynax.DoublePendulum(), "coulomb")
    system = dynax.Extended(system.system, (*system.terms, dynax.RotorInertia(1)))
    names = parameter_names(system, "coulomb")
    estimate = np.asarray([values.get(n, 0.0) for n in names])
    labels = [pathlib.Path(r.source).name for r in data]
    levels = joint_levels(static_friction_rests(system, names, estimate, covariance, data, rests, labels))
    return {j.name: {"level": j.level, "kind": j.kind, "lower_bound": j.lower_bound} for j in levels}


def reread(part: str) -> dict:
    (case,) = [c for c in CASES if c.name == CASE_NAMES[part]]
    fitted = list(records(case))  # `holdout=0`: every record is fitted, as it is
    result, seconds = identify_as_stick_slip(fitted)
    ls, refined = result.stages[0], result.stages[-1]
    assert ls.kind == dynax.StageKind.LEAST_SQUARES and refined.kind == dynax.StageKind.OUTPUT_ERROR
    rests = record_rests(fitted)
    offsets = ls.offsets  # each record's force offsets at the driven joints, fitted with the parameters
    seen = (
        fitted if offsets is None else records_less_offsets(result.system, fitted, offsets["joints"], offsets["values"])
    )
    fits = {
        "least squares": {n: float(v) for n, v in zip(ls.names, np.asarray(ls.solution.value))},
        "refined": {n: float(v) for n, v in zip(refined.names, np.asarray(refined.solution.value))},
    }
    truth = dict(zip(parameter_names(with_friction(dynax.DoublePendulum(), "coulomb"), "coulomb"), truth_theta(case)))
    truth = {n: float(v) for n, v in truth.items()}
    row = {
        "fit_seconds": seconds,
        "truth": {"fs": case.size, "joint": case.where},
        "returned": {j.name: {"level": j.level, "refined": j.refined} for j in result.static_friction.joints},
        "offsets": {"records": [r.source for r in fitted]}
        | ({"joints": [], "values": None} if offsets is None else {k: offsets[k] for k in ("joints", "values")}),
        "parameters": fits | {"truth": truth},
    }
    read_with = {}
    for name, values in {**fits, "truth": truth}.items():
        for offsets, recs in (("less offsets", seen), ("as recorded", fitted)):
            read_with[f"{name}, {offsets}"] = read(values, recs, rests)
    for name, values in fits.items():
        for group, members in GROUPS.items():
            mixed = {n: truth.get(n, 0.0) if n in members else v for n, v in values.items()}
            read_with[f"{name}, the truth's {group}, less offsets"] = read(mixed, seen, rests)
            mixed = {n: values.get(n, 0.0) if n in members else truth.get(n, 0.0) for n in values}
            read_with[f"truth, the {name} {group}, less offsets"] = read(mixed, seen, rests)
    row["read with"] = read_with
    for key, levels in read_with.items():
        print(part, key, {j: round(v["level"], 4) for j, v in levels.items()}, flush=True)
    return row


def every_rest_out(part: str) -> dict:
    (case,) = [c for c in CASES if c.name == CASE_NAMES[part]]
    data = list(records(case))
    row = {}
    for label, everything in (("loaded rests out", False), ("every rest out", True)):
        with all_rests_left_out() if everything else contextlib.nullcontext():
            result, _ = identify_as_stick_slip(data, refine=False)
        row[label] = {
            "levels": {j.name: {"level": j.level, "kind": j.kind} for j in result.static_friction.joints},
            "rows_left_out": result.static_friction.rows_left_out,
        }
        print(part, label, row[label], flush=True)
    return row


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--parts", default="shoulder,coulomb")
    parser.add_argument("--every-rest-out", action="store_true")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    run, name = (every_rest_out, "every_rest_out.json") if args.every_rest_out else (reread, "results.json")
    out = {}
    for part in args.parts.split(","):
        out[part] = run(part)
        (args.out / name).write_text(json.dumps(out, indent=2, default=str) + "\n")


if __name__ == "__main__":
    main()
