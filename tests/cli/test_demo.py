"""`dynax demo` hides an effect in acrobot data and writes what the nominal simulation gets wrong."""

import json

import numpy as np
import pytest

from dynax.synthetic import hidden_effect
from dynax._cli._main import main
from dynax._data import load_trajectory


def test_seed_chooses_a_hidden_effect_of_the_vocabulary():
    causes = {hidden_effect(seed).cause for seed in range(7)}
    assert causes == {"coulomb_friction", "rotor_inertia", "input_delay", "quadratic_drag", "input_lag", "input_offset"}
    assert hidden_effect(3) == hidden_effect(3)  # reproducible


@pytest.mark.slow
def test_demo_writes_data_report_and_figures(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--seed", "0"]) == 0
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
    assert main(["demo", "--out", str(tmp_path / "x"), "--seed", "-1"]) == 2
    assert "--seed" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
