"""`dynax fit helicopter` and `dynax evaluate`, as in the contract."""

import json

import numpy as np
import pytest

from dynax import Helicopter, save_trajectory
from dynax.internal import cli_main
from dynax.synthetic import generate_helicopter_flight

GROUPS = ("velocity", "angular_rate", "position", "orientation")


@pytest.fixture(scope="module")
def flight_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("heli") / "hover.csv"
    save_trajectory(generate_helicopter_flight("hover", 12.0, seed=3, truth=Helicopter()), path)
    return path


def test_fit_then_evaluate(flight_csv, tmp_path, capsys):
    model = tmp_path / "model.json"
    assert (
        cli_main(
            [
                "fit",
                "helicopter",
                str(flight_csv),
                "--model",
                "acceleration",
                "--criterion",
                "one-step",
                "--out",
                str(model),
            ]
        )
        == 0
    )
    obj = json.loads(model.read_text())
    assert obj["system"] == "helicopter" and obj["model"] == "acceleration" and obj["criterion"] == "one-step"
    # Data flown by the Tempest model itself: the fitted roll damping is the Tempest's.
    assert obj["parameters"]["dp/p"] == pytest.approx(-12.78, rel=0.01)

    metrics = tmp_path / "metrics.json"
    assert (
        cli_main(
            [
                "evaluate",
                str(model),
                str(flight_csv),
                "--horizons",
                "0,0.1,0.5",
                "--stride",
                "10",
                "--out",
                str(metrics),
            ]
        )
        == 0
    )
    out = json.loads(metrics.read_text())
    assert out["horizons_s"] == [0.0, 0.1, 0.5]
    assert set(out["mse"]) == set(GROUPS)
    for group in GROUPS:
        values = np.array(out["mse"][group])
        assert values.shape == (3,) and values[0] < 1e-20 and np.all(values >= 0)
    assert out["mse"]["velocity"][2] < 1e-2  # the (nearly) true model predicts its own flight
    assert "velocity" in capsys.readouterr().out


@pytest.mark.slow
def test_fit_lagged_linear_from_the_cli(flight_csv, tmp_path):
    model = tmp_path / "model.json"
    assert (
        cli_main(
            [
                "fit",
                "helicopter",
                str(flight_csv),
                "--model",
                "linear",
                "--criterion",
                "lagged",
                "--horizon",
                "0.2",
                "--stride",
                "20",
                "--out",
                str(model),
            ]
        )
        == 0
    )
    obj = json.loads(model.read_text())
    assert obj["model"] == "linear" and obj["horizon_s"] == 0.2
    assert len(obj["weights"]) == 6 and len(obj["weights"][0]) == len(obj["features"])


def test_frequency_criterion_needs_the_linear_model(flight_csv, tmp_path, capsys):
    model = tmp_path / "model.json"
    assert cli_main(["fit", "helicopter", str(flight_csv), "--criterion", "frequency", "--out", str(model)]) == 2
    assert "linear" in capsys.readouterr().err
    assert not model.exists()


def test_bad_data_is_refused_with_nothing_written(flight_csv, tmp_path, capsys):
    lines = flight_csv.read_text().splitlines()
    header = lines[0].split(",")
    drop = header.index("u4")
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(",".join(c for i, c in enumerate(l.split(",")) if i != drop) for l in lines[:50]) + "\n")
    model = tmp_path / "model.json"
    assert cli_main(["fit", "helicopter", str(bad), "--out", str(model)]) == 2
    assert "u4" in capsys.readouterr().err
    assert not model.exists()


def test_evaluate_refuses_a_malformed_model(flight_csv, tmp_path, capsys):
    model = tmp_path / "model.json"
    model.write_text(json.dumps({"system": "helicopter", "model": "acceleration"}))
    metrics = tmp_path / "metrics.json"
    assert cli_main(["evaluate", str(model), str(flight_csv), "--out", str(metrics)]) == 2
    assert "features" in capsys.readouterr().err
    assert not metrics.exists()
    assert cli_main(["evaluate", str(model), str(flight_csv), "--horizons", "1,-2", "--out", str(metrics)]) == 2


def test_frequency_fit_reports_its_identification_statistics(flight_csv, tmp_path):
    model = tmp_path / "linear.json"
    assert (
        cli_main(
            ["fit", "helicopter", str(flight_csv), "--model", "linear", "--criterion", "frequency", "--out", str(model)]
        )
        == 0
    )
    obj = json.loads(model.read_text())
    stats = obj["identification"]
    assert obj["criterion"] == "frequency" and stats["eliminated"] == []
    # Every identified weight has a Cramer-Rao bound and an insensitivity (12 s of data give wide ones).
    assert set(stats["cramer_rao_percent"]) == set(stats["insensitivity_percent"]) >= {"dp/u1", "dq/u2", "dr/u3"}
    # (null where a weight is not determined at all)
    bounds = [v for v in stats["cramer_rao_percent"].values() if v is not None]
    assert len(bounds) >= 3 and all(np.isfinite(v) and v > 0 for v in bounds)
