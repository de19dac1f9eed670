"""The simulator-accuracy experiment runs end to end in --quick mode and writes what the issue asks for."""

import json
import math
import pathlib
import subprocess
import sys

import pytest

SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "experiments" / "helicopter_accuracy.py"
METHODS = ("linear one-step", "linear frequency", "linear lagged", "acceleration one-step", "acceleration lagged")
GROUPS = ("velocity", "angular_rate", "position", "orientation")


@pytest.mark.slow
def test_quick_accuracy_experiment(tmp_path):
    result = subprocess.run(
        [sys.executable, str(SCRIPT), "--quick", "--out", str(tmp_path / "out"), "--data-out", str(tmp_path / "data")],
        capture_output=True,
        text=True,
        timeout=1200,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    results = json.loads((tmp_path / "out" / "accuracy.json").read_text())["results"]
    assert set(results) == {"hover", "aerobatic"}
    for kind, entry in results.items():
        assert entry["horizons_s"][0] == 0.0 and entry["horizons_s"][-1] == pytest.approx(2.0)
        assert set(entry["mse"]) == set(METHODS)
        for method in METHODS:
            assert set(entry["mse"][method]) == set(GROUPS)
            assert entry["mse"][method]["velocity"][0] == 0.0
        # The lagged fits improve the training loss over the one-step fit, and the direct minimum is
        # at or below the EM-free loss.
        check = entry["em_free_check"]
        assert check["em_free_loss"] < check["one_step_loss"]
        assert check["direct_minimum"] <= check["em_free_loss"] and math.isfinite(check["relative_gap"])
        assert (tmp_path / "data" / f"{kind}_train.csv").exists()
    assert (tmp_path / "out" / "accuracy.png").stat().st_size > 10_000
