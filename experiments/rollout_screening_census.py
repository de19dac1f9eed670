"""How often the output-error screening changes the first round's shortlist on the calibration battery's cases.

The diagnosis screens every candidate by equation error (one-step residuals), then by the first Gauss-Newton step of
its simulation-error refit, and gives up to a quarter of the shortlist to candidates the second ranks above
shortlisted ones (`dynax.internal.with_rollout_evidence`). This script runs each battery case
(`tests/hidden_cases.py`, made by scipy's DOP853 outside dynax's model code) only up to the first round's refit and
records which candidates joined the shortlist that way, and whether the hidden cause was on the shortlist before and
after. A promotion that pushes the hidden cause off the shortlist would show here; later rounds are not covered.

    nice -n 5 python experiments/rollout_screening_census.py [OUT] [--every K] [--budget-s S]

OUT defaults to `experiments/results/rollout_screening_census`; writes `OUT/census.json` after each case.
"""

import argparse
import json
import pathlib
import re
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

import dynax  # noqa: E402
import dynax.internal  # noqa: E402
from tests import hidden_cases  # noqa: E402


class _FirstRefit(Exception):
    """Raised by the progress callback when the first round's refit begins: the census needs nothing after it."""


def census_case(case):
    """The first round's shortlist of `case` and the candidates the output-error screening put on it."""
    train, held_out = hidden_cases.records(case)
    mode = dynax.Known() if case.mode == "known" else dynax.Refit()
    nominal, kwargs = _nominal(case)
    lines = []

    def say(line):
        lines.append(line)
        if "simulation-error refit of the nominal model" in line:
            raise _FirstRefit

    try:
        dynax.diagnose(
            nominal, train, held_out, mode=mode, selection=dynax.Selection(max_terms=2), progress=say, **kwargs
        )
    except _FirstRefit:
        pass
    pairs = [m.groups() for line in lines if (m := re.search(r"(\S+) joins the shortlist in place of (\S+):", line))]
    promoted = [new for new, _ in pairs]
    refit = next((line for line in lines if "simulation-error refit of the nominal model" in line), "")
    short = refit.split(" with ", 1)[1].replace(" (one batch) ...", "").split(", ") if " with " in refit else []
    expected = None if case.expected is None else f"{case.expected[0]}@{case.expected[1]}"
    before = [dict((new, old) for new, old in pairs).get(s, s) for s in short]
    return {
        "case": case.name,
        "expected": expected,
        "shortlist": short,
        "promoted": promoted,
        "expected_on_shortlist": expected in short if expected else None,
        "expected_promoted": expected in promoted if expected else None,
        "lines": [line for line in lines if "joins the shortlist" in line],
        "shortlist_before_promotion_holds_expected": (expected in before) if expected else None,
    }


def _nominal(case):
    """The nominal model and extra arguments `tests.hidden_cases.diagnose_case` uses for `case`'s system."""
    import jax.numpy as jnp

    if case.system == "acrobot":
        return dynax.Acrobot(), {}
    if case.system == "double_pendulum" and hidden_cases.on_damped_arm(case):
        theta = {f"theta{i + 1}": v for i, v in enumerate(hidden_cases.DAMPED_THETA)}
        return dynax.DoublePendulum.from_base_parameters(theta), {}
    if case.system == "double_pendulum":
        return dynax.DoublePendulum(), {}
    if case.system == "linear_axis":
        axis = hidden_cases.AXIS
        return dynax.LinearAxis(
            mass=jnp.asarray(axis["mass"]),
            viscous=jnp.asarray(axis["viscous"]),
            coulomb=jnp.asarray(0.0),
            offset=jnp.asarray(axis["offset"]),
        ), {}
    heli = dynax.Helicopter()
    terms = tuple(t for t in dynax.default_candidates(heli) if isinstance(t, dynax.internal.AbstractVehicleTerm))
    return heli, {"candidates": terms, "horizons": dynax.Horizons(horizons_s=(0.25, 0.5, 1.0))}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", nargs="?", default="experiments/results/rollout_screening_census")
    parser.add_argument("--every", type=int, default=1, help="every K-th case")
    parser.add_argument("--budget-s", type=float, default=float("inf"), help="stop starting cases after this long")
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "census.json"
    rows = json.loads(path.read_text()) if path.exists() else []
    done = {r["case"] for r in rows}
    start = time.perf_counter()
    single_run = [c for c in hidden_cases.CASES if c.system != "quadrotor"]  # the flights are lists of records
    cases = [c for i, c in enumerate(single_run) if i % args.every == 0 and c.name not in done]
    for i, case in enumerate(cases):
        if time.perf_counter() - start > args.budget_s:
            print(f"budget reached after {i} cases", flush=True)
            break
        t0 = time.perf_counter()
        row = census_case(case)
        row["seconds"] = round(time.perf_counter() - t0, 1)
        rows.append(row)
        path.write_text(json.dumps(rows, indent=1))
        print(
            f"[{time.perf_counter() - start:7.1f} s] {i + 1}/{len(cases)} {case.name}: promoted {row['promoted']}, "
            f"hidden cause on the shortlist: {row['expected_on_shortlist']}",
            flush=True,
        )
    effects = [r for r in rows if r["expected"]]
    summary = {
        "cases": len(rows),
        "with_a_promotion": sum(bool(r["promoted"]) for r in rows),
        "hidden_cause_on_shortlist": sum(bool(r["expected_on_shortlist"]) for r in effects),
        "hidden_cause_pushed_off": sum(
            bool(r["shortlist_before_promotion_holds_expected"]) and not r["expected_on_shortlist"] for r in effects
        ),
        "hidden_cause_promoted": sum(bool(r["expected_promoted"]) for r in effects),
        "effect_cases": len(effects),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
