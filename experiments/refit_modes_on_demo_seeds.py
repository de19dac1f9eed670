"""Refit mode keeping the nominal friction (`Refit()`, since 2026-11-25) against refitting all of theta1..theta7.

For each demo seed in [FIRST, LAST) the demo's acrobot data with its hidden effect (`dynax demo --seed`)
is diagnosed in both ways; a row records the hidden cause and size and, per mode, the verdict, the
findings and the first finding's coefficient. The summary counts the seeds where exactly the hidden
cause was named, the wrong causes, and the coefficients' relative errors.

    python experiments/refit_modes_on_demo_seeds.py 7 35 experiments/results/refit_modes/seeds.json [MODE]

With MODE (`friction_kept` or `all_refitted`) only that mode is run.
"""

import json
import sys

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from dynax import Acrobot, diagnose, Refit  # noqa: E402
from dynax.synthetic import demo_data, hidden_effect  # noqa: E402

ALL = tuple(f"theta{i}" for i in range(1, 8))
MODES = {"friction_kept": Refit(), "all_refitted": Refit(parameters=ALL)}


def summary(rows):
    out = {}
    for mode in MODES:
        right = [r for r in rows if r[mode]["findings"] == [r["hidden"]]]
        errors = [abs(r[mode]["coefficient"] - r["size"]) / r["size"] for r in right]
        out[mode] = {
            "named_exactly_the_hidden_cause": len(right),
            "of": len(rows),
            "wrong_cause_named": sum(any(f != r["hidden"] for f in r[mode]["findings"]) for r in rows),
            "missed": [r["seed"] for r in rows if r[mode]["findings"] != [r["hidden"]]],
            "coefficient_relative_error_median": float(np.median(errors)) if errors else None,
            "coefficient_relative_error_max": float(np.max(errors)) if errors else None,
        }
    return out


if __name__ == "__main__":
    first, last, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    if len(sys.argv) > 4:
        MODES = {sys.argv[4]: MODES[sys.argv[4]]}
    rows = []
    for seed in range(first, last):
        term = hidden_effect(seed)
        truth, train, validation = demo_data(term, seed=seed)
        row = {"seed": seed, "hidden": term.label(truth.system), "size": float(term.coefficient)}
        for name, mode in MODES.items():
            j = diagnose(Acrobot(), train, validation, mode=mode, progress=False).to_json()
            row[name] = {
                "verdict": j["verdict"],
                "findings": [f"{f['cause']}@{f['where']}" for f in j["findings"]],
                "coefficient": j["findings"][0]["coefficient"] if j["findings"] else None,
                "gain": j["gain"],
            }
        print(json.dumps(row), flush=True)
        rows.append(row)
    result = {"rows": rows, "summary": summary(rows)}
    print(json.dumps(result["summary"], indent=1))
    with open(out, "w") as f:
        json.dump(result, f, indent=1)
