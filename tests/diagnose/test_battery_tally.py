"""The calibration battery's tally (`experiments/calibration_battery.py`, `summary`): the secondary reading that
counts the best candidate an `inconclusive` verdict names counts it only where it is the hidden cause at its place,
and only for `inconclusive` (a `none` names nothing); and in refit mode what the record can show is the truth's gain
over the refitted arm, not over the effect-free truth."""

import importlib.util
import pathlib

SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "experiments" / "calibration_battery.py"


def _battery():
    spec = importlib.util.spec_from_file_location("calibration_battery", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _row(name, verdict, named_first, best=None, expected="battery_sag@vbat", truth_gain=0.5, **extra):
    power = None if best is None else {"best_candidate": dict(zip(("cause", "where"), best.split("@")))}
    return {
        "name": name,
        "expected": expected,
        "verdict": verdict,
        "named_first": named_first,
        "right_verdict": verdict == "explained" and named_first,
        "false_claim": False,
        "extra": False,
        "near": False,
        "best_gain": 0.5,
        "none_with_gain": False,
        "power": power,
        "truth_gain": truth_gain,
        **extra,
    }


def test_an_inconclusive_counts_only_where_its_best_candidate_is_the_hidden_cause():
    rows = [
        _row("found", "explained", True),
        _row("inconclusive, right best", "inconclusive", False, best="battery_sag@vbat"),
        _row("inconclusive, wrong best", "inconclusive", False, best="rotor_drag@u"),
        _row("none, right best", "none", False, best="battery_sag@vbat"),
        _row("invisible, inconclusive right", "inconclusive", False, best="battery_sag@vbat", truth_gain=0.1),
    ]
    s = _battery().summary(rows)
    assert s["named_first"] == 1 / 5
    assert s["named_first_or_inconclusive_best"] == 3 / 5
    # Over the effects the record can show (truth gains 25 % or more): 2 of 4.
    assert s["named_first_or_inconclusive_best_where_truth_gains_25"] == 2 / 4


def test_in_refit_mode_the_truth_is_scored_over_the_refitted_arm():
    rows = [
        _row("found", "explained", True),
        # The truth gains 99 % over the effect-free truth, 9 % once the refit has absorbed what it can.
        _row("absorbed by the refit", "none", False, truth_gain=0.99, truth_gain_refit=0.09),
        # A refit that leaves most of the effect: it counts as one the record can show.
        _row("left by the refit", "none", False, truth_gain=0.99, truth_gain_refit=0.6),
        # Known mode (no refit gain): the truth's own gain decides.
        _row("known", "none", False, truth_gain=0.99, truth_gain_refit=None),
        _row("known, too small", "none", False, truth_gain=0.05, truth_gain_refit=None),
    ]
    s = _battery().summary(rows)
    assert s["effects_truth_below_practical"] == ["absorbed by the refit", "known, too small"]
    assert s["named_first_where_truth_gains_25"] == 1 / 3
    assert s["right_verdict_truth_aware"] == 3 / 5
