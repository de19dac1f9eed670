"""A flight log without body rates or world velocities (motion capture's poses alone): `load_flight` estimates
them by central differences, says so, and the flight fits; a group of columns half present is still refused."""

import json
import pathlib

import numpy as np
import pytest

import dynax
from dynax.internal import cli_main
from tests.quadrotor.synthetic_flight import quadrotor_flight, rotation

NANOBENCH = pathlib.Path(__file__).resolve().parents[2].parent / "shared" / "datasets" / "nanobench"
STAR = NANOBENCH / "B8_star_fast_rep1.csv.gz"
POSE_MAP = {"x": "px", "y": "py", "z": "pz", **{f"m{i}": f"motor_motor_m{i}" for i in range(1, 5)}}


@pytest.fixture(scope="module")
def flight():
    """A clean closed-loop flight (scipy's DOP853, written outside dynax), turning in yaw as it flies."""
    return quadrotor_flight(12.0, seed=3, noise=False)


def _write(path, flight, columns):
    names = ("t", *flight.state_names, *flight.input_names)
    table = np.column_stack([np.asarray(flight.ts), np.asarray(flight.xs), np.asarray(flight.us)])
    keep = [names.index(c) for c in ("t", *columns)]
    np.savetxt(path, table[:, keep], delimiter=",", header=",".join(names[k] for k in keep), comments="", fmt="%.17g")
    return path


POSES = ("x", "y", "z", "qw", "qx", "qy", "qz", "m1", "m2", "m3", "m4")


def test_a_pose_log_gets_its_rates_and_velocities_estimated_without_lag(flight, tmp_path):
    path = _write(tmp_path / "poses.csv", flight, POSES)
    loaded, notes = dynax.load_flight(path)
    assert "p, q, r from the attitude" in notes.estimated and "vx, vy, vz from x, y, z" in notes.estimated
    true, got = np.asarray(flight.xs), np.asarray(loaded.xs)
    inner = slice(5, -5)  # the ends are one-sided differences
    rms = lambda a: float(np.sqrt(np.mean(a**2)))  # noqa: E731
    for group in (slice(7, 10), slice(10, 13)):  # world velocity, body rates
        error, size = rms(got[inner, group] - true[inner, group]), rms(true[inner, group])
        assert error < 0.01 * size, (group, error, size)
    # The rates are the body frame's: the same rates in world axes differ from them twenty times more.
    world = np.einsum("nij,nj->ni", np.stack([rotation(q) for q in true[:, 3:7]]), true[:, 10:13])
    assert rms(world[inner] - true[inner, 10:13]) > 20 * rms(got[inner, 10:13] - true[inner, 10:13])


def test_a_log_with_its_rates_keeps_them_and_says_nothing(flight, tmp_path):
    path = _write(tmp_path / "full.csv", flight, (*POSES[:7], "vx", "vy", "vz", "p", "q", "r", *POSES[7:]))
    loaded, notes = dynax.load_flight(path)
    assert notes.estimated == ""
    np.testing.assert_allclose(np.asarray(loaded.xs)[:, 10:13], np.asarray(flight.xs)[:, 10:13], atol=1e-12)


def test_one_rate_column_of_three_is_a_misnamed_column_not_a_pose_log(flight, tmp_path):
    path = _write(tmp_path / "two_rates.csv", flight, (*POSES[:7], "vx", "vy", "vz", "p", "q", *POSES[7:]))
    with pytest.raises(dynax.DataError, match="'r': missing column"):
        dynax.load_flight(path)


def test_the_cli_fits_a_pose_log_and_notes_the_estimate(flight, tmp_path, capsys):
    path = _write(tmp_path / "poses.csv", flight, POSES)
    model = tmp_path / "model.json"
    argv = ["fit", "quadrotor", str(path), "--model", "nominal", "--criterion", "one-step", "--out", str(model)]
    assert cli_main(argv) == 0
    assert "estimated by central differences" in capsys.readouterr().out
    warnings = json.loads(model.read_text())["warnings"]
    assert [w["kind"] for w in warnings if w["kind"] == "estimated"] == ["estimated"]


@pytest.mark.skipif(not STAR.exists(), reason="the NanoBench flights are not in ../shared/datasets")
def test_rates_estimated_from_a_real_flights_attitude_follow_its_logged_rates():
    """NanoBench logs body rates beside the attitude (`wx_vicon`, ...); left unread, the estimate follows them."""
    estimated, notes = dynax.load_flight(STAR, mapping=POSE_MAP)
    logged, _ = dynax.load_flight(STAR, mapping={**POSE_MAP, "p": "wx_vicon", "q": "wy_vicon", "r": "wz_vicon"})
    assert "p, q, r" in notes.estimated
    flying = notes.usable
    for k in range(10, 13):
        a, b = np.asarray(estimated.xs)[flying, k], np.asarray(logged.xs)[flying, k]
        assert np.corrcoef(a, b)[0, 1] > 0.9


def test_a_zero_quaternion_in_a_pose_log_is_refused_at_its_row_not_differentiated(flight, tmp_path):
    path = _write(tmp_path / "poses.csv", flight, POSES)
    lines = path.read_text().splitlines()
    row = lines[100].split(",")
    row[4:8] = ["0"] * 4  # qw..qz of data row 100
    lines[100] = ",".join(row)
    path.write_text("\n".join(lines) + "\n")
    for load in (lambda: dynax.load_flight(path), lambda: dynax.load_trajectory(path, "quadrotor")):
        with pytest.raises(dynax.DataError, match="row 100: the quaternion"):
            load()
