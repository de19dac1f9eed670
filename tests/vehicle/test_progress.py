"""`fit_vehicle` and `dynax fit` show a bar per iteration with the loss, on stderr, and only when asked or on a
terminal."""

import pytest

from dynax import fit_vehicle, Helicopter, Lagged, save_trajectory
from dynax.internal import cli_main, initial_helicopter, recorded_loss
from dynax.synthetic import generate_helicopter_flight


@pytest.fixture(scope="module")
def flight():
    return generate_helicopter_flight("hover", 4.0, seed=5, truth=Helicopter())


def test_lagged_fit_reports_each_iteration_with_its_loss(flight, capsys):
    seen = []
    criterion = Lagged(horizon=0.1, stride=25, max_iterations=2)
    fit = fit_vehicle(
        initial_helicopter("linear"), flight, criterion, callback=lambda i, loss: seen.append(loss), progress=True
    )
    err = capsys.readouterr().err
    assert "lagged fit" in err and f"loss={seen[-1]:.4g}" in err and f"{len(seen)}/2" in err
    assert recorded_loss(fit) == seen[-1]
    fit_vehicle(initial_helicopter("linear"), flight, criterion)  # stderr is not a terminal: no bar
    assert capsys.readouterr().err == ""


def test_cli_fit_progress(flight, tmp_path, capsys):
    path = tmp_path / "flight.csv"
    save_trajectory(flight, path)
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
        "--stride",
        "25",
        "--out",
        str(tmp_path / "m.json"),
    ]
    assert cli_main(command + ["--progress"]) == 0  # (--quiet's plumbing: tests/cli/test_packaging.py)
    err = capsys.readouterr().err
    assert "lagged fit" in err and "loss=" in err
