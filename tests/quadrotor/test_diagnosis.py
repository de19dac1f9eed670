"""The quadrotor's diagnosis: the multirotor causes' physics, then hidden effects in synthetic flights.

The flights are not made by dynax's models: `synthetic_flight.quadrotor_flight` integrates a rigid body with the
effect written out (scipy DOP853) under a geometric controller at 100 Hz. `diagnose` starts from a `Quadrotor` of
zero weights (`Quadrotor.from_flights("nominal")`, no geometry given), fits the rigid body, and must name the
hidden cause first with a significant held-out gain; on an effect-free flight it must claim nothing. The default
suite runs the Crazyflie's rotor drag and a dead time's place on the shortlist (the heavy mark: a few minutes on
two cores); twice that drag, body bias, motor lag, the effect-free control and the CLI are slow. A motor's gain is
hidden the way it happens: the model is fitted on flights of the healthy vehicle, a propeller is chipped
afterwards, and the later flights are diagnosed against the trusted model (`Known()`); a map refitted on the later
flights would carry the gain itself (slow too, 10 s flights: about 100 s of CPU each, 25 s with the compiled code
in the suite's cache).
"""

import json

import jax.numpy as jnp
import numpy as np
import pytest

from dynax import (
    BodyBias,
    diagnose,
    Extended,
    fit_quadrotor,
    Helicopter,
    Known,
    Quadrotor,
    RotorDrag,
    Selection,
)
from dynax.internal import PlanarRotorDrag

from .synthetic_flight import quadrotor_flight


def _diagnose(seed, duration=15.0, **effects):
    train = quadrotor_flight(duration, seed=seed, **effects)
    validation = quadrotor_flight(duration, seed=seed + 100, **effects)
    quad = Quadrotor.from_flights("nominal", [train])
    return diagnose(
        quad, train, validation, selection=Selection(max_terms=1, discovery=False), progress=False
    ).to_json()


def _assert_named_first(j, cause, places):
    assert j["system"] == "quadrotor"
    assert j["findings"], (j["verdict"], j["candidates"])
    first = j["findings"][0]
    assert (first["cause"], first["where"]) in {(cause, w) for w in places}, j["findings"]
    assert j["gain"] > 0.2 and first["p_value"] < 0.01
    h = j["nominal"]["sim_error"]["horizons_s"].index(j["reference_horizon_s"])
    assert j["extended"]["sim_error"]["rmse"][h] < j["nominal"]["sim_error"]["rmse"][h]
    # A physical effect helps at every time scale: the report scores the held-out flights per group and has no
    # note that the named term predicts some group worse one step ahead.
    assert set(j["flight_error"]["models"]) >= {"constant velocity", "nominal"} and j["flight_error"]["note"] is None
    return first


# --- the term ----------------------------------------------------------------------------------


def test_rotor_drag_is_linear_body_frame_drag_on_its_axis():
    heli = Helicopter()
    u = jnp.asarray([0.1, -0.2, 0.05, 0.3])
    x = jnp.asarray([0.0, 0, 0, np.cos(0.3), 0, 0, np.sin(0.3), 1.5, -0.7, 0.4, 0.1, 0.2, -0.3])
    for axis, nu in enumerate((1.5, -0.7, 0.4)):
        diff = (Extended(heli, (RotorDrag(axis, 0.35),)).vector_field(0.0, x, u) - heli.vector_field(0.0, x, u))[7:]
        np.testing.assert_allclose(diff, -0.35 * nu * np.eye(6)[axis], atol=1e-12)
    model = Extended(heli, (RotorDrag(0, 0.3), RotorDrag(1, 0.2), BodyBias(3, 0.1)))
    assert model.labels == ("rotor_drag@u", "rotor_drag@v", "body_bias@p")
    assert set(model.parameters) == {"drag_u", "drag_v", "bias_p"}
    for axis, rate in zip((3, 4, 5), (0.1, 0.2, -0.3)):  # on the rates: the rotors' damping of rotation
        diff = (Extended(heli, (RotorDrag(axis, 2.0),)).vector_field(0.0, x, u) - heli.vector_field(0.0, x, u))[7:]
        np.testing.assert_allclose(diff, -2.0 * rate * np.eye(6)[axis], atol=1e-12)
    with pytest.raises(ValueError, match="axis"):
        RotorDrag(6)


def test_the_rotor_planes_drag_is_one_coefficient_on_u_and_v():
    heli = Helicopter()
    u = jnp.asarray([0.1, -0.2, 0.05, 0.3])
    x = jnp.asarray([0.0, 0, 0, np.cos(0.3), 0, 0, np.sin(0.3), 1.5, -0.7, 0.4, 0.1, 0.2, -0.3])
    model = Extended(heli, (PlanarRotorDrag(0.35),))
    diff = (model.vector_field(0.0, x, u) - heli.vector_field(0.0, x, u))[7:]
    np.testing.assert_allclose(diff, [-0.35 * 1.5, 0.35 * 0.7, 0, 0, 0, 0], atol=1e-12)
    assert model.labels == ("rotor_drag@u+v",) and set(model.parameters) == {"drag_uv"}


def test_synthetic_flight_is_bounded_and_the_drag_changes_it():
    calm = quadrotor_flight(3.0, seed=0, noise=False)
    dragged = quadrotor_flight(3.0, seed=0, noise=False, drag=(0.4, 0.4, 0.1))
    for f in (calm, dragged):
        assert np.all(np.isfinite(np.asarray(f.xs))) and np.abs(np.asarray(f.xs)[:, :3]).max() < 3.0
    assert np.abs(np.asarray(dragged.us) - np.asarray(calm.us)).max() > 30  # the controller works against it


def test_synthetic_flight_with_a_weak_motor_commands_it_harder():
    # The controller does not know: to hold the same thrust, motor 2's command rises by 1 / sqrt(0.85) on average
    # (thrust is k kf w^2), the others' hardly move.
    calm = np.asarray(quadrotor_flight(3.0, seed=0, noise=False).us).mean(axis=0)
    weak = np.asarray(quadrotor_flight(3.0, seed=0, noise=False, gain=(1, 0.85)).us).mean(axis=0)
    np.testing.assert_allclose(weak / calm, [1.0, 1 / np.sqrt(0.85), 1.0, 1.0], rtol=0.01)


# --- hidden effects ----------------------------------------------------------------------------


@pytest.mark.slow  # twice the Crazyflie's drag (the heavy test below): its easier case, about 4 minutes
def test_hidden_rotor_drag_is_named():
    # A drag the same on both axes of the rotor plane, as an X quadrotor's: named there as one cause.
    j = _diagnose(1, drag=(0.4, 0.4, 0.1))
    first = _assert_named_first(j, "rotor_drag", ("u+v",))
    assert first["coefficient"] == pytest.approx(0.4, rel=0.2)
    json.dumps(j)


@pytest.mark.heavy
def test_a_crazyflies_rotor_drag_is_named_in_the_rotor_plane():
    # The Crazyflie 2.0's own drag (Foerster 2015: 0.2 1/s on u and v, 0.22 on w for a 30 g vehicle): on a path
    # that flies forwards and sideways alike each horizontal axis alone gains a few percent (the calibration
    # battery's row: 6-7 %, `none`), the rotor plane's drag as one cause gains what the two together do.
    j = _diagnose(5, drag=(0.2, 0.2, 0.22))
    first = _assert_named_first(j, "rotor_drag", ("u+v",))
    assert first["coefficient"] == pytest.approx(0.2, rel=0.25)


@pytest.mark.slow
def test_hidden_body_bias_is_named():
    j = _diagnose(2, bias=(0, 0.5))  # 0.5 m/s^2 along the body x axis: a tilted thrust axis
    first = _assert_named_first(j, "body_bias", ("u",))
    assert first["coefficient"] == pytest.approx(0.5, rel=0.2)


@pytest.mark.slow  # a 30 s flight to fit and four held out: about ten minutes on two loaded cores
def test_hidden_motor_lag_is_named_at_its_motor():
    # Motor 3 follows its command with an 80 ms lag. The held one-step motor map is refitted through each lag
    # candidate at its one-step optimum (else it takes up part of the lag), and the lag's gain varies with how
    # much motor 3's command moves: on one 30 s held-out flight it is inconclusive (p = 0.0012 at a 56 % gain) and
    # the report asks for about 110 s of such flight, so four are held out.
    lag = (2, 0.08)
    train = quadrotor_flight(30.0, seed=3, lag=lag)
    validation = [quadrotor_flight(30.0, seed=seed, lag=lag) for seed in (103, 203, 303, 403)]
    quad = Quadrotor.from_flights("nominal", [train])
    j = diagnose(quad, train, validation, selection=Selection(max_terms=1, discovery=False), progress=False).to_json()
    first = _assert_named_first(j, "input_lag", ("m3",))
    assert first["coefficient"] == pytest.approx(0.08, rel=0.1)


class _Shortlisted(Exception):
    """Raised by `_first_refit` at the first round's refit: the shortlist is known, the fits are not needed."""


def _first_refit(train, validation) -> str:
    """The diagnosis's progress up to the first round's line naming the candidates refitted (the shortlist)."""
    lines = []

    def say(line):
        lines.append(line)
        if "simulation-error refit of the nominal model with" in line:
            raise _Shortlisted

    quad = Quadrotor.from_flights("nominal", [train])
    with pytest.raises(_Shortlisted):
        diagnose(quad, train, validation, selection=Selection(max_terms=1, discovery=False), progress=say)
    return "\n".join(lines)


@pytest.mark.slow  # about 80 s; the suite hides the Crazyflie's rotor drag
def test_a_dead_time_the_held_map_hides_reaches_the_shortlist():
    # 40 ms from every logged command to its rotor, on the calibration battery's 10 s flights (its row
    # `quadrotor-motor_delay@motors-0.04-dead_time`: these seeds). Screened against the held one-step motor map,
    # which has taken up part of the delay, `motor_delay@motors` gains -5.6 % and was left off the shortlist (the
    # verdict `none`); the map refitted one step through it at 40 ms fits one step better by far more than chance
    # (likelihood ratio 223 against a bar of 13), and that test is its place on the shortlist.
    said = _first_refit(quadrotor_flight(10.0, seed=5040, delay=0.04), quadrotor_flight(10.0, seed=5045, delay=0.04))
    assert "motor_delay@motors" in said.splitlines()[-1], said


@pytest.mark.slow
def test_effect_free_flights_claim_nothing():
    j = _diagnose(4)
    assert j["findings"] == [], j["findings"]
    assert j["verdict"] in ("none", "unexplained")  # no named cause; what the residual probe says is its own


def _after_a_chipped_propeller(seed, duration=10.0, **effects):
    """The diagnosis of a later flight (and one held out) against the model fitted on a flight of the healthy
    vehicle (one step, `fit_quadrotor`), trusted as it is (`Known()`); `effects` are the later flights'."""
    healthy = quadrotor_flight(duration, seed=seed)
    trusted = fit_quadrotor(Quadrotor.from_flights("nominal", [healthy]), healthy, progress=False).model
    train = quadrotor_flight(duration, seed=seed + 1, **effects)
    validation = quadrotor_flight(duration, seed=seed + 101, **effects)
    return diagnose(
        trusted, train, validation, mode=Known(), selection=Selection(max_terms=1, discovery=False), progress=False
    ).to_json()


@pytest.mark.slow
def test_a_motor_that_lost_thrust_after_the_fit_is_named_at_its_motor():
    # Motor 2's thrust and yaw moment per command fall to 0.85 of the others' (a chipped propeller). The trusted map
    # is quadratic in the command and `InputGain` scales the command, so the gain to find is sqrt(0.85) = 0.922.
    # Measured: 0.922 at a held-out gain of 90 % (0.15 s), p = 7e-16 (cross-fitted).
    j = _after_a_chipped_propeller(20, gain=(1, 0.85))
    first = _assert_named_first(j, "input_gain", ("m2",))
    assert 1.0 - first["coefficient"] == pytest.approx(1.0 - np.sqrt(0.85), rel=0.2)


@pytest.mark.slow
def test_the_healthy_vehicle_against_its_trusted_model_claims_nothing():
    j = _after_a_chipped_propeller(20)
    assert j["findings"] == [], j["findings"]
    assert j["verdict"] in ("none", "unexplained")


def _on_the_pad_first(flight, seconds=0.5):
    """The flight's log with `seconds` on the floor before it (motors off, level, at rest), as a real log
    starts: the loader takes the floor's height from there (without it, the flight's lowest point)."""
    from dynax import Trajectory

    n, dt = int(round(seconds / flight.dt)), flight.dt
    xs, us = np.asarray(flight.xs), np.asarray(flight.us)
    pad = np.zeros((n, xs.shape[1]))
    pad[:, :2], pad[:, 3] = xs[0, :2], 1.0
    return Trajectory(
        np.arange(n + len(xs)) * dt,
        np.concatenate([pad, xs]),
        np.concatenate([np.zeros((n, us.shape[1])), us]),
        flight.state_names,
        flight.input_names,
        "quadrotor",
        flight.source,
    )


@pytest.mark.slow
def test_cli_diagnose_quadrotor_names_rotor_drag(tmp_path, capsys):
    from dynax import save_trajectory
    from dynax.internal import cli_main

    save_trajectory(_on_the_pad_first(quadrotor_flight(15.0, seed=1, drag=(0.4, 0.4, 0.1))), tmp_path / "train.csv")
    save_trajectory(_on_the_pad_first(quadrotor_flight(15.0, seed=101, drag=(0.4, 0.4, 0.1))), tmp_path / "val.csv")
    out = tmp_path / "report"
    code = cli_main(
        [
            "diagnose",
            "quadrotor",
            str(tmp_path / "train.csv"),
            "--validation",
            str(tmp_path / "val.csv"),
            "--max-terms",
            "1",
            "--no-discovery",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    j = json.loads((out / "report.json").read_text())
    assert j["system"] == "quadrotor" and j["findings"][0]["cause"] == "rotor_drag"
    scores = json.loads((out / "flight_error.json").read_text())
    assert scores == j["flight_error"]  # the report's scores, written as they are
    groups = scores["models"]
    assert groups["extended"]["mae"]["velocity"][-1] < groups["nominal"]["mae"]["velocity"][-1]
    # A physical drag helps at every time scale: no note that the term spoils the next sample.
    assert scores["note"] is None and not any(note.startswith("One step ahead") for note in j["notes"])
    printed = capsys.readouterr().out
    assert "rotor_drag" in printed and "held-out error per group" in printed
