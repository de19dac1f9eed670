"""`dynax fit quadrotor` and `dynax evaluate --steps` on a real NanoBench flight, and their refusals."""

import gzip
import json

import numpy as np
import pytest

from dynax._cli._main import main

from .test_flight_data import NANOBENCH_MAP, STAR

MAP = ",".join(f"{k}={v}" for k, v in NANOBENCH_MAP.items())
GROUPS = ("position", "velocity", "attitude", "body_rate")

pytestmark = pytest.mark.skipif(not STAR.exists(), reason="the NanoBench flights are not in ../shared/datasets")


@pytest.fixture(scope="module")
def short_flight(tmp_path_factory):
    """The first 9 s of a flight: 3 s on the floor, then 6 s of flight."""
    path = tmp_path_factory.mktemp("nanobench") / "star_9s.csv.gz"
    with gzip.open(STAR, "rt") as f:
        lines = [next(f) for _ in range(901)]
    with gzip.open(path, "wt") as f:
        f.writelines(lines)
    return path


def test_fit_then_evaluate_a_real_flight(short_flight, tmp_path, capsys):
    model = tmp_path / "model.json"
    assert main(["fit", "quadrotor", str(short_flight), "--map", MAP, "--model", "nominal", "--criterion", "one-step",
                 "--out", str(model)]) == 0
    printed = capsys.readouterr().out
    assert "ground segment from t = 0.00" in printed  # the take-off is noted and left out
    obj = json.loads(model.read_text())
    assert obj["system"] == "quadrotor" and obj["family"] == "nominal" and obj["criterion"] == "one-step"
    assert "dw/(vbat m1)^2" in obj["parameters"]
    metrics = tmp_path / "metrics.json"
    assert main(["evaluate", str(model), str(short_flight), "--map", MAP, "--steps", "1,10", "--metric", "mae",
                 "--out", str(metrics)]) == 0
    out = json.loads(metrics.read_text())
    assert out["steps"] == [1, 10] and set(out["model"]["mae"]) == set(GROUPS) and "rmse" not in out["model"]
    for group in GROUPS:
        values = np.array(out["model"]["mae"][group])
        assert values.shape == (2,) and np.all(values >= 0) and values[1] > values[0]
        assert np.isfinite(out["constant_velocity"]["cumulative_mae"][group])
    # On its own flight the fitted thrust predicts velocity 0.1 s ahead better than holding it.
    assert out["model"]["mae"]["velocity"][1] < out["constant_velocity"]["mae"]["velocity"][1]


def test_fit_refuses_a_missing_column_and_writes_nothing(short_flight, tmp_path, capsys):
    model = tmp_path / "model.json"
    bad = MAP.replace("m3=motor_motor_m3", "m3=motor_speed_3")
    assert main(["fit", "quadrotor", str(short_flight), "--map", bad, "--out", str(model)]) == 2
    err = capsys.readouterr().err
    assert "motor_speed_3" in err and "star_9s.csv.gz" in err
    assert not model.exists()


def test_usage_errors(short_flight, tmp_path, capsys):
    model = tmp_path / "model.json"
    assert main(["fit", "helicopter", str(short_flight), "--model", "nominal", "--out", str(model)]) == 2
    assert "helicopter" in capsys.readouterr().err
    assert main(["fit", "quadrotor", str(short_flight), "--map", MAP, "--model", "acceleration",
                 "--criterion", "frequency", "--out", str(model)]) == 2
    assert "helicopter's linear model" in capsys.readouterr().err
    assert not model.exists()
    model.write_text(json.dumps({"system": "quadrotor", "model": "acceleration", "features": ["m1"], "mask": [[1]] * 6,
                                 "weights": [[0.0]] * 6, "input_scale": [1, 1, 1, 1, 1], "gravity": -9.81}))
    metrics = tmp_path / "metrics.json"
    assert main(["evaluate", str(model), str(short_flight), "--map", MAP, "--steps", "0,10", "--out", str(metrics)]) == 2
    assert "--steps" in capsys.readouterr().err
    assert not metrics.exists()
