"""The calibration battery's quadrotor cases (`tests.hidden_flights`): the truth's own gain rolls the generator's
law out as the flight was flown, and a right answer is scored as every case's.

The truth's gain is only as good as its rollout: on flights without noise, the windows it starts from the recorded
state under the logged commands must land on the recorded states (the generator integrates each sample by scipy's
DOP853; the rollout by RK4), with each effect as the generator wrote it, and the effect-free rollout must not."""

import dataclasses

import numpy as np
import pytest

from tests import hidden_flights as hf
from tests.hidden_cases import CASES, outcome
from tests.quadrotor import synthetic_flight as sf


@pytest.mark.parametrize(
    ("effects", "altitude"),
    [
        ({"drag": (0.2, 0.2, 0.22)}, 1.0),
        ({"bias": (3, 5.0)}, 1.0),
        ({"delay": 0.04}, 1.0),
        ({"gain": (1, 0.85)}, 1.0),
        ({"sag": (4.2, 3.5)}, 1.0),
        ({"ground": 0.0225}, 0.03),
    ],
)
def test_the_truths_rollout_is_the_flight_and_the_effect_free_one_is_not(effects, altitude):
    flight = sf.quadrotor_flight(2.0, seed=3, noise=False, altitude=altitude, **effects)
    xs, commands = np.asarray(flight.xs), np.asarray(flight.us)[:, :4] / sf.NANO.unit
    truth = dict(effects)
    late = int(round(truth.pop("delay", 0.0) / 0.01))
    v0, v1 = truth.pop("sag", (sf.V_REF, sf.V_REF))
    battery = ((v0 + (v1 - v0) * np.arange(len(xs)) / (len(xs) - 1)) / sf.V_REF) ** 2
    n = 30
    for k in (10, 70, 150):
        target = xs[k + 1 : k + n + 1]
        sim = hf._rollout(xs[k], commands[k - late : k - late + n], 0, truth, battery[k : k + n], commands[k], n)
        free = hf._rollout(xs[k], commands[k : k + n], 0, {}, np.ones(n), commands[k], n)
        assert np.abs(sim - target).max() < 1e-6
        assert np.abs(free - target)[:, 7:].max() > 1e-3


def test_a_rotor_drag_named_on_any_body_axis_is_the_hidden_one():
    (case,) = [c for c in CASES if c.system == "quadrotor" and c.cause == "rotor_drag"]
    report = {
        "verdict": "explained",
        "findings": [{"cause": "rotor_drag", "where": "v"}, {"cause": "rotor_drag", "where": "u"}],
        "candidates": [],
        "gain": 0.5,
        "structure": {"extended": {"r2": 0.0, "p_value": 0.5}},
        "test": {},
    }
    row = outcome(case, report)
    assert row["named_first"] and row["right_verdict"] and not row["extra"]
    report["findings"].append({"cause": "rotor_drag", "where": "q"})  # the rates' damping was not hidden
    assert outcome(case, report)["extra"]
    report["findings"] = [{"cause": "rotor_drag", "where": "u+v"}]  # the rotor plane's drag, both axes as one
    row = outcome(case, report)
    assert row["named_first"] and row["right_verdict"] and not row["extra"]
    report["findings"] = [{"cause": "rotor_drag", "where": "u+p"}]  # one place of two is not the hidden effect
    assert not outcome(case, report)["named_first"]


def test_every_quadrotor_case_flies_its_plan():
    quads = [c for c in CASES if c.system == "quadrotor"]
    assert {c.cause for c in quads} == {
        None,
        "rotor_drag",
        "body_bias",
        "motor_delay",
        "input_lag",
        "input_gain",
        "battery_sag",
        "ground_effect",
    }
    for case in quads:
        p = hf.plan(case)
        assert p["train"] and p["validation"]
        assert (p["healthy"] is not None) == (case.mode == "known")
        if case.cause == "battery_sag" or case.law == "steady vbat":
            assert p["battery"] is False and p["thrust"]  # the sag to be found, with the thrust map refitted
            assert len({kw.get("sag") for kw in p["train"] + p["validation"]}) in (1, 3)
        if case.cause == "ground_effect" or case.law == "over the floor":
            assert p["floor"] == 0.0 and p["thrust"]


@pytest.mark.heavy
def test_a_motor_lag_under_the_one_step_bar_is_refitted_from_its_one_step_optimum():
    # The battery's 80 ms lag of one motor flown from another seed: the map refitted one step through the lag fits
    # best at 80 ms, by a likelihood ratio under the bar that would shortlist it. Screened first anyway, it was refitted
    # from the default start against the held map, which had taken up part of the lag, and stopped at 24 ms with a
    # 5 % gain: `none`, where the truth gains 62 % (`hf.truth_gains`). From the one-step optimum it is refitted near
    # its size and gains what the truth gains; with 20 s held out the test may still want more flight.
    case = dataclasses.replace({c.name: c for c in CASES}["quadrotor-input_lag@m3-0.08-first_order"], seed=566)
    found = outcome(case, hf.diagnose_flights(case).to_json())
    assert found["verdict"] in ("explained", "inconclusive"), found
    assert found["best_candidate"] == "input_lag@m3" and 0.064 <= found["best_coefficient"] <= 0.096, found
    assert found["best_gain"] > 0.4, found
    assert not found["findings"] or found["named_first"], found  # nothing named, or the lag first
