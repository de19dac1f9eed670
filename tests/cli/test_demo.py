"""`dynax demo` hides an effect in acrobot data and writes what the nominal simulation gets wrong."""

import json

import numpy as np
import pytest

from dynax import load_trajectory
from dynax.internal import cli_main
from dynax.synthetic import demo_data, DEMO_TRUTH_PHYSICAL, hidden_effect
from tests.reference import DRAKE, scipy_acrobot


def test_seed_chooses_a_hidden_effect_of_the_vocabulary():
    causes = {hidden_effect(seed).cause for seed in range(7)}
    assert causes == {"coulomb_friction", "rotor_inertia", "input_delay", "quadratic_drag", "input_lag", "input_offset"}


@pytest.mark.parametrize("seed", [1, 6], ids=["rotor_inertia", "input_offset"])
def test_the_demo_data_carry_the_seeds_hidden_effect(seed):
    """The training record against Drake's acrobot written out in numpy and integrated by scipy
    (tests/reference.py) with the demo's truth parameters and the seed's effect: equal to the
    measurement noise (1e-3 rad rms), and far from the same reference without the effect."""
    term = hidden_effect(seed)
    _, train, _ = demo_data(term, seed=seed, train_s=3.0, validation_s=0.5)
    physical = {**DRAKE, **DEMO_TRUTH_PHYSICAL}
    us = np.asarray(train.us)
    if term.cause == "rotor_inertia":
        reference = scipy_acrobot(np.zeros(4), np.asarray(train.ts), us, physical, rotor=(0.0, float(term.coefficient)))
    else:
        reference = scipy_acrobot(np.zeros(4), np.asarray(train.ts), us + float(term.coefficient), physical)
    nominal = scipy_acrobot(np.zeros(4), np.asarray(train.ts), us, physical)
    rms = lambda xs: float(np.sqrt(np.mean((np.asarray(train.xs[:, :2]) - xs[:, :2]) ** 2)))  # noqa: E731
    # the rms of 600 draws of N(0, 1e-3) lies within 1e-3 +- 10 % at 3 sigma
    assert rms(reference) < 1.1e-3
    assert rms(nominal) > 10 * rms(reference)


@pytest.mark.slow
def test_demo_writes_data_report_and_figures(tmp_path, capsys):
    out = tmp_path / "demo"
    assert cli_main(["demo", "--out", str(out), "--seed", "0"]) == 0
    train = load_trajectory(out / "train.csv", "acrobot")
    assert len(train) > 1000 and np.isclose(train.dt, 0.01)
    for name in ("validation.csv", "report.json", "report.md", "measured_vs_simulated.png", "sim_error.png"):
        assert (out / name).stat().st_size > 0
    report = json.loads((out / "report.json").read_text())
    hidden = hidden_effect(0)
    assert report["verdict"] == "explained"
    assert (report["findings"][0]["cause"], report["findings"][0]["where"]) == (hidden.cause, "q2")
    assert report["gain"] > 0.2
    summary = capsys.readouterr().out
    assert "gets wrong" in summary and "Cause: coulomb_friction at q2" in summary and "Gain" in summary


def test_demo_refuses_a_negative_seed(tmp_path, capsys):
    assert cli_main(["demo", "--out", str(tmp_path / "x"), "--seed", "-1"]) == 2
    assert "--seed" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
