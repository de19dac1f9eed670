"""`dynax fit`'s defaults for the lagged and backprop criteria: about 600 start times, an iteration cap."""

import json

import pytest

from dynax import Helicopter, save_trajectory
from dynax.internal import cli_main
from dynax.synthetic import generate_helicopter_flight


@pytest.mark.slow  # about 20 s
def test_auto_stride_and_iteration_cap(tmp_path, capsys):
    flight = generate_helicopter_flight("hover", 8.0, seed=5, truth=Helicopter())  # 800 samples
    path = tmp_path / "flight.csv"
    save_trajectory(flight, path)
    out = tmp_path / "model.json"
    command = [
        "fit",
        "helicopter",
        str(path),
        "--model",
        "linear",
        "--criterion",
        "lagged",
        "--horizon",
        "0.1",
        "--max-iterations",
        "1",
        "--out",
        str(out),
    ]
    assert cli_main(command) == 0
    printed = capsys.readouterr().out
    # 790 start times for a 10-sample horizon: every second one keeps 395 <= 600 (every one would be 790)
    assert "one start time in 2, 395 windows of 0.1 s" in printed
    assert json.loads(out.read_text())["criterion"] == "lagged"
    assert cli_main(command + ["--stride", "1"]) == 0
    assert "start time in" not in capsys.readouterr().out
    assert cli_main(command[:-2] + ["--stride", "0", "--out", str(out)]) == 2
    assert "--stride" in capsys.readouterr().err
