"""`dynax fit quadrotor` and `dynax evaluate --steps` on a real NanoBench flight, and their refusals."""

import gzip
import json

import numpy as np
import pytest

from dynax.internal import cli_main as main

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
    assert (
        main(
            [
                "fit",
                "quadrotor",
                str(short_flight),
                "--map",
                MAP,
                "--model",
                "nominal",
                "--criterion",
                "one-step",
                "--out",
                str(model),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "ground segment from t = 0.00" in printed  # the take-off is noted and left out
    obj = json.loads(model.read_text())
    assert obj["system"] == "quadrotor" and obj["family"] == "nominal" and obj["criterion"] == "one-step"
    assert "dw/(vbat m1)^2" in obj["parameters"]
    metrics = tmp_path / "metrics.json"
    assert (
        main(
            [
                "evaluate",
                str(model),
                str(short_flight),
                "--map",
                MAP,
                "--steps",
                "1,10",
                "--metric",
                "mae",
                "--out",
                str(metrics),
            ]
        )
        == 0
    )
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
    assert (
        main(
            [
                "fit",
                "quadrotor",
                str(short_flight),
                "--map",
                MAP,
                "--model",
                "acceleration",
                "--criterion",
                "frequency",
                "--out",
                str(model),
            ]
        )
        == 2
    )
    assert "helicopter's linear model" in capsys.readouterr().err
    assert not model.exists()
    model.write_text(
        json.dumps(
            {
                "system": "quadrotor",
                "model": "acceleration",
                "features": ["m1"],
                "mask": [[1]] * 6,
                "weights": [[0.0]] * 6,
                "input_scale": [1, 1, 1, 1, 1],
                "gravity": -9.81,
            }
        )
    )
    metrics = tmp_path / "metrics.json"
    assert (
        main(["evaluate", str(model), str(short_flight), "--map", MAP, "--steps", "0,10", "--out", str(metrics)]) == 2
    )
    assert "--steps" in capsys.readouterr().err
    # The helicopter's options would be ignored for a quadrotor (every start is scored, at --steps): refused, named.
    for extra, named in (
        (["--stride", "5"], "--stride"),
        (["--horizons", "0.5"], "--horizons"),
        (["--steps", "1,,10"], "--steps"),
    ):
        argv = ["evaluate", str(model), str(short_flight), "--map", MAP, *extra, "--out", str(metrics)]
        assert main(argv) == 2
        assert named in capsys.readouterr().err
    assert not metrics.exists()


def test_fit_ridge_reaches_the_criterion_and_shrinks_the_map(short_flight, tmp_path, capsys):
    """`--ridge` is the criterion's Tikhonov term: a large one pulls the one-step weights towards zero (the
    motor features of a flight near hover are nearly collinear, so the default fit's weights are large and
    cancel); a negative ridge, or one with a criterion that has none, is refused before anything is written."""

    def fit(*extra):
        out = tmp_path / f"model{len(extra)}.json"
        argv = ["fit", "quadrotor", str(short_flight), "--map", MAP, "--criterion", "one-step", "--out", str(out)]
        assert main([*argv, *extra]) == 0
        return np.asarray(json.loads(out.read_text())["weights"])

    plain, ridged = fit(), fit("--ridge", "1e-2")
    capsys.readouterr()
    assert np.linalg.norm(ridged) < 0.5 * np.linalg.norm(plain)
    model = tmp_path / "refused.json"
    for extra in (["--ridge", "-1"], ["--ridge", "1e-3", "--criterion", "backprop"]):
        argv = ["fit", "quadrotor", str(short_flight), "--map", MAP, "--out", str(model), *extra]
        assert main(argv) == 2
        assert "--ridge" in capsys.readouterr().err
        assert not model.exists()


@pytest.mark.heavy  # two fits and evaluations compiled for a second input layout: 25 s of CPU
def test_another_drone_needs_only_a_map(tmp_path, capsys):
    """Logs of another vehicle (the rigid body of test_quadrotor_model, rotor speeds in rad/s, no
    battery voltage, columns named its own way): the same command with a --map, no code change."""
    from .test_quadrotor_model import _flight

    flights = [_flight(seed) for seed in (11, 12)]
    paths = []
    for k, f in enumerate(flights):
        table = np.column_stack([np.asarray(f.ts) + 100.0, np.asarray(f.xs), np.asarray(f.us[:, :4]) * (2500 / 4e4)])
        names = [
            "time",
            "px",
            "py",
            "pz",
            "q_w",
            "q_x",
            "q_y",
            "q_z",
            "vel_x",
            "vel_y",
            "vel_z",
            "gyro_x",
            "gyro_y",
            "gyro_z",
            "omega1",
            "omega2",
            "omega3",
            "omega4",
        ]
        path = tmp_path / f"other_{k}.csv"
        np.savetxt(path, table, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
        paths.append(str(path))
    other_map = (
        "t=time,x=px,y=py,z=pz,qw=q_w,qx=q_x,qy=q_y,qz=q_z,vx=vel_x,vy=vel_y,vz=vel_z,p=gyro_x,q=gyro_y,"
        "r=gyro_z,m1=omega1,m2=omega2,m3=omega3,m4=omega4"
    )
    model = tmp_path / "model.json"
    assert main(["fit", "quadrotor", *paths, "--map", other_map, "--model", "nominal", "--out", str(model)]) == 0
    obj = json.loads(model.read_text())
    assert "dw/m1^2" in obj["parameters"] and obj["input_scale"][0] == pytest.approx(2500, rel=0.1)
    metrics = tmp_path / "metrics.json"
    assert main(["evaluate", str(model), *paths, "--map", other_map, "--steps", "1,10", "--out", str(metrics)]) == 0
    out = json.loads(metrics.read_text())
    # The nominal model is this vehicle's own structure: far ahead of holding the velocity.
    assert out["model"]["mae"]["velocity"][1] < 0.01 * out["constant_velocity"]["mae"]["velocity"][1]


def test_flights_whose_motors_are_in_different_units_are_refused_together(tmp_path, capsys):
    # one flight's motors in percent of the 16-bit range among flights logged in counts: one motor map fitted
    # to all three predicted none of them, with exit status 0
    from tests.cli.hostile_cases import write_table
    from tests.quadrotor.synthetic_flight import quadrotor_flight

    paths = []
    for seed, factor in ((1, 1.0), (2, 1.0), (3, 100.0 / 65535.0)):
        f = quadrotor_flight(6.0, seed=seed)
        table = np.column_stack([np.asarray(f.ts), np.asarray(f.xs), factor * np.asarray(f.us)])
        paths.append(str(write_table(tmp_path / f"flight{seed}.csv", ("t", *f.state_names, *f.input_names), table)))
    argv = ["fit", "quadrotor", "--model", "nominal", "--criterion", "one-step", "--out", str(tmp_path / "m.json")]
    assert main([*argv[:2], *paths, *argv[2:]]) == 2
    err = capsys.readouterr().err
    assert "flight3.csv" in err and "column 'm1'" in err and "another unit" in err
    assert main([*argv[:2], *paths[:2], *argv[2:]]) == 0
