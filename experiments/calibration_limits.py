"""What the calibration battery's misses are worth on their records: independent bounds, computed outside dynax.

For each case the battery's diagnosis gets wrong, or got wrong before a change, this asks whether *any* method could
name it from its record, with numpy RK4 on the written-out laws (`tests.hidden_cases`):

- `horizon`: the helicopter's body-frame quadratic drags: the truth's own held-out gain (`truth_gain`) at longer
  reference horizons, and the diagnosis run at a 1 s reference horizon (`Horizons(reference_s=1.0)`) on the drags and
  the two effect-free helicopter controls: does a longer horizon, where the drag's velocity error has grown, let the
  test see it?
- `refit`: the rotor inertias at a two-link arm's elbow in refit mode: the truth's gain over the effect-free arm
  refitted to it (`refit_truth_gain`, an equation-error refit) beside its gain over the unrefitted one (`truth_gain`).
- `lookalike`: the dead times: the truth's gain over the first-order lag closest to it on the held-out windows
  (`look_alike_gain`): can the record tell a dead time from a lag at all?

    nice -n 5 python experiments/calibration_limits.py [OUT] [--part horizon|refit|lookalike]

OUT defaults to `experiments/results/calibration_limits`; `OUT/limits.json` gets one entry per part run (the others
kept), with the wall time.
"""

import json
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from tests.hidden_cases import CASES, look_alike_gain, outcome, records, refit_truth_gain, truth_gain

BY_NAME = {c.name: c for c in CASES}
DRAGS = [c.name for c in CASES if c.cause == "quadratic_drag"]
HELI_CONTROLS = [c.name for c in CASES if c.system == "helicopter" and c.cause is None]
ROTORS = [c.name for c in CASES if c.cause == "rotor_inertia" and c.mode == "refit"]
DEAD_TIMES = [c.name for c in CASES if c.cause == "input_delay" and c.system == "linear_axis"]
STRIDE_S = 0.1  # window starts 0.1 s apart (the diagnosis's are 0.05 s): the bounds' cost halved, their value not


def say(*parts):
    print(*parts, flush=True)


def horizon_part():
    import dynax
    import dynax.internal

    gains = {}
    for name in DRAGS:
        gains[name] = {}
        for h in (0.45, 1.0, 2.0):
            gains[name][h] = truth_gain(BY_NAME[name], h, STRIDE_S)
            say(name, f"truth gain at {h:g} s: {gains[name][h]:.3f}")
    nominal = dynax.Helicopter()
    candidates = tuple(
        t for t in dynax.default_candidates(nominal) if isinstance(t, dynax.internal.AbstractVehicleTerm)
    )
    at_1s = {}
    for name in DRAGS + HELI_CONTROLS:
        case = BY_NAME[name]
        train, held_out = records(case)
        j = dynax.diagnose(
            nominal,
            train,
            held_out,
            mode=dynax.Known(),
            selection=dynax.Selection(max_terms=2),
            candidates=candidates,
            horizons=dynax.Horizons(horizons_s=(0.25, 0.5, 1.0), reference_s=1.0),
            progress=False,
        ).to_json()
        o = outcome(case, j)
        best = (o["power"] or {}).get("best_candidate") or {}
        at_1s[name] = {
            "verdict": o["verdict"],
            "findings": o["findings"],
            "best_candidate": o["best_candidate"],
            "best_gain": o["best_gain"],
            "best_p_value": best.get("p_value"),
            "stopped_by": best.get("stopped_by"),
        }
        say(name, "at 1 s:", at_1s[name])
    return {"truth_gain_by_horizon_s": gains, "diagnosis_at_1s": at_1s}


def refit_part():
    out = {}
    for name in ROTORS:
        case = BY_NAME[name]
        out[name] = {
            "truth_gain": truth_gain(case, 0.45, STRIDE_S),
            "refit_truth_gain": refit_truth_gain(case, 0.45, STRIDE_S),
        }
        say(name, out[name])
    return out


def lookalike_part():
    out = {}
    for name in DEAD_TIMES:
        gain, tau = look_alike_gain(BY_NAME[name], 0.45, STRIDE_S)
        out[name] = {"gain_over_closest_lag": gain, "closest_lag_s": tau}
        say(name, out[name])
    return out


PARTS = {"horizon": horizon_part, "refit": refit_part, "lookalike": lookalike_part}


def main():
    args = sys.argv[1:]
    parts = list(PARTS)
    if "--part" in args:
        i = args.index("--part")
        parts = [args[i + 1]]
        del args[i : i + 2]
    out = pathlib.Path(args[0] if args else "experiments/results/calibration_limits")
    out.mkdir(parents=True, exist_ok=True)
    path = out / "limits.json"
    result = json.loads(path.read_text()) if path.exists() else {}
    for part in parts:
        t0 = time.perf_counter()
        result[part] = {"stride_s": STRIDE_S, **PARTS[part](), "wall_s": time.perf_counter() - t0}
        path.write_text(json.dumps(result, indent=1))
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
