"""Battery sag and ground effect: the terms scale the rotors' forces and moments, nothing else.

The hidden-effect tests (slow: several minutes each on two cores) hide each in synthetic flights made
without dynax's model code (`synthetic_flight.quadrotor_flight`: the voltage's square law and Cheeseman and
Bennett's ground effect written out, scipy DOP853 under a geometric controller) and require the diagnosis,
with the thrust map refitted with each candidate, to name it; a flight with a steady voltage low over the
floor has neither.
"""

import jax.numpy as jnp
import numpy as np
import pytest

from dynax import (
    BatterySag,
    BodyBias,
    diagnose,
    Extended,
    GroundEffect,
    Helicopter,
    Quadrotor,
    Refit,
    RotorDrag,
    Selection,
)
from dynax.internal import (
    body_frame_system,
    moment_parameters,
    quadrotor_candidates,
    quadrotor_refit_names,
    thrust_parameters,
)

from .synthetic_flight import quadrotor_flight


def _body(battery_inputs=True):
    flight = quadrotor_flight(1.0, seed=0, noise=False, vbat=battery_inputs)
    quad = Quadrotor.from_flights("nominal", [flight], battery=False)
    weights = jnp.asarray(np.random.default_rng(0).normal(size=quad.body_model.weights.shape))
    quad = quad.with_body_model(type(quad.body_model)(weights, quad.body_model.feature_names, quad.body_model.mask))
    return body_frame_system(quad, flight.input_names)


def test_the_terms_scale_the_rotor_part_of_the_body_model_only():
    body = _body()
    x = jnp.asarray([0.1, -0.2, 0.3, np.cos(0.2), 0.1, 0.0, np.sin(0.2), 0.5, -0.3, 0.2, 0.1, 0.2, -0.3])
    u = jnp.asarray([1.1, 0.9, 1.05, 0.95, 0.97])  # motors and vbat, as the model scales them
    idle = u.at[:4].set(0.0)
    rotors = (body.vector_field(0.0, x, u) - body.vector_field(0.0, x, idle))[7:]
    assert float(jnp.abs(rotors).max()) > 0.1
    sag = Extended(body, (BatterySag(2.0),)).vector_field(0.0, x, u) - body.vector_field(0.0, x, u)
    np.testing.assert_allclose(sag[7:], 2.0 * (0.97 - 1.0) * rotors, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(sag[:7], 0.0, atol=1e-12)  # the kinematics are unchanged
    ground = Extended(body, (GroundEffect(1e-3, floor=0.1, rotor_height=0.02),))
    diff = ground.vector_field(0.0, x, u) - body.vector_field(0.0, x, u)
    ratio = 1e-3 / (0.3 - 0.1 + 0.02) ** 2  # Cheeseman and Bennett: thrust / (1 - (R / 4z)^2), c = R^2 / 16
    np.testing.assert_allclose(diff[7:], ratio / (1 - ratio) * rotors, rtol=1e-10, atol=1e-12)
    # With the motors off there is nothing to scale: gravity and the rigid body stay as they are.
    for term in (BatterySag(2.0), GroundEffect(1e-3)):
        np.testing.assert_allclose(
            Extended(body, (term,)).vector_field(0.0, x, idle), body.vector_field(0.0, x, idle), atol=1e-12
        )
    model = Extended(body, (BatterySag(), GroundEffect(), RotorDrag(0), BodyBias(3)))
    assert model.labels == ("battery_sag@vbat", "ground_effect@z", "rotor_drag@u", "body_bias@p")
    assert set(model.parameters) == {"sag_vbat", "ground_z", "drag_u", "bias_p"}


def test_the_terms_refuse_systems_they_cannot_act_on():
    with pytest.raises(ValueError, match="vbat"):
        Extended(_body(battery_inputs=False), (BatterySag(),))
    with pytest.raises(ValueError, match="m1..m4"):
        Extended(Helicopter(), (GroundEffect(),))
    with pytest.raises(ValueError, match="rotor_height"):
        GroundEffect(rotor_height=0.0)


def test_battery_sag_is_a_candidate_only_where_the_flights_log_vbat_and_ground_effect_where_the_floor_is_given():
    with_vbat = {t.cause for t in quadrotor_candidates(_body(True))}
    without = {t.cause for t in quadrotor_candidates(_body(False))}
    assert "battery_sag" in with_vbat and "battery_sag" not in without
    assert "ground_effect" not in with_vbat | without  # flight segments do not show where the floor is
    (ground,) = [t for t in quadrotor_candidates(_body(False), floor=0.05) if t.cause == "ground_effect"]
    assert float(ground.floor) == 0.05


def test_thrust_parameters_are_the_thrust_axis_motor_weights():
    flight = quadrotor_flight(0.5, seed=0, noise=False, vbat=True)
    for battery, squared in ((False, "dw/m1^2"), (True, "dw/(vbat m1)^2")):
        for family in ("nominal", "acceleration"):
            names = thrust_parameters(Quadrotor.from_flights(family, [flight], battery=battery))
            assert len(names) == 8 and squared in names and all(n.startswith("dw/") for n in names)
            assert "dw/w sum(m)" not in names  # rotor drag, not the thrust map


def test_moment_parameters_are_the_moment_axes_motor_weights_and_the_command_line_expands_both_groups():
    flight = quadrotor_flight(0.5, seed=0, noise=False, vbat=True)
    for battery, squared in ((False, "dq/m1^2"), (True, "dq/(vbat m1)^2")):
        for family in ("nominal", "acceleration"):
            names = moment_parameters(Quadrotor.from_flights(family, [flight], battery=battery))
            assert len(names) == 24 and squared in names and {n[:3] for n in names} == {"dp/", "dq/", "dr/"}, names
            # neither the gyroscopic products nor the acceleration model's rate damping: the commands' map only
            assert not {"dp/qr", "dq/pr", "dr/pq", "dp/p", "dq/q", "dr/r"} & set(names)
    quad = Quadrotor.from_flights("nominal", [flight])
    assert quadrotor_refit_names(quad, "thrust, moments") == thrust_parameters(quad) + moment_parameters(quad)
    assert quadrotor_refit_names(quad, "moments,dw/m1^2") == moment_parameters(quad) + ("dw/m1^2",)
    assert quadrotor_refit_names(quad, "") is None


def _diagnosis(train, validation, battery=None, floor=None):
    """`diagnose` with the thrust map refitted with each candidate (`thrust_parameters`): the held one-step
    map takes up most of a thrust-per-command change (see `dynax._diagnose._quadrotor`)."""
    quad = Quadrotor.from_flights("nominal", train, battery=battery)
    body = body_frame_system(quad, train[0].input_names)
    return diagnose(
        quad,
        train,
        validation,
        mode=Refit(parameters=thrust_parameters(quad)),
        selection=Selection(max_terms=1, discovery=False),
        progress=False,
        candidates=quadrotor_candidates(body, floor=floor),
    ).to_json()


def _named_first(j, cause, min_gain=0.2):
    assert j["findings"], (j["verdict"], j["candidates"][:3])
    first = j["findings"][0]
    assert first["cause"] == cause, j["findings"]
    assert j["gain"] > min_gain and first["p_value"] < 0.01
    return first


@pytest.mark.slow
def test_hidden_battery_sag_is_named_where_the_motor_map_ignores_the_voltage():
    # Flights at different charges, as a pack is flown down over a session: thrust per command falls by a
    # quarter from 4.2 to 3.5 V (rotor speed follows command times voltage). Within one flight the voltage
    # and the command level drift together and a map of the commands alone takes up the sag; across
    # flights at different charges it cannot.
    # One 20 s held-out flight leaves it `inconclusive` (gain 39 %, p = 0.0011 against a bar of 0.00043), and the
    # report asks for 28 to 44 s of such flight: two are held out.
    train = [quadrotor_flight(15.0, seed=5, sag=(4.2, 3.9)), quadrotor_flight(15.0, seed=15, sag=(3.8, 3.5))]
    validation = [quadrotor_flight(20.0, seed=s, sag=(4.1, 3.6)) for s in (105, 205)]
    first = _named_first(_diagnosis(train, validation, battery=False), "battery_sag")
    assert 1.4 < first["coefficient"] < 2.6  # the square law: s = 2 to first order
    # A motor map that reads the voltage (the default where the flights log it) has the sag already.
    j = _diagnosis(train, validation)
    assert "battery_sag" not in [f["cause"] for f in j["findings"]], j["findings"]


@pytest.mark.slow
def test_hidden_ground_effect_is_named_low_over_the_floor():
    # Rotors of 8 cm radius flown 1.4 to 13 cm over the floor: up to half again the thrust at the lowest point.
    # The one-step thrust map takes up most of it: the map is refitted with each candidate. The training
    # flights must hold the effect (with one of them at 1 m the term refits at its size but gains a fifth,
    # p = 0.001, not named), and two held-out flights: it acts at their low points only.
    train = [quadrotor_flight(15.0, seed=s, altitude=0.07, ground=0.08) for s in (6, 16)]
    validation = [quadrotor_flight(15.0, seed=s, altitude=0.07, ground=0.08) for s in (106, 126)]
    # It acts at the flights' low points only: the held-out score by group gains 15 %.
    first = _named_first(_diagnosis(train, validation, floor=0.0), "ground_effect", min_gain=0.1)  # the floor as known
    # Cheeseman and Bennett's R^2/16.
    assert 0.5 * 0.08**2 / 16 < first["coefficient"] < 2 * 0.08**2 / 16


@pytest.mark.slow
def test_a_steady_battery_low_over_the_floor_names_neither():
    # The control of the two above: the same low flight and the same diagnosis (the floor given, the thrust
    # map refitted with each candidate), with neither effect in the flight.
    train = quadrotor_flight(15.0, seed=7, altitude=0.15, vbat=True)
    validation = quadrotor_flight(15.0, seed=107, altitude=0.15, vbat=True)
    j = _diagnosis([train], [validation], battery=False, floor=0.0)
    assert not {"battery_sag", "ground_effect"} & {f["cause"] for f in j["findings"]}, j["findings"]


@pytest.mark.slow  # a diagnosis with its simulation-error refits: 4 to 11 minutes on two shared cores
def test_cli_diagnose_quadrotor_refits_the_thrust_map_with_each_candidate(tmp_path, capsys):
    # Short flights at two charges (the sag hidden, vbat logged) through `dynax diagnose quadrotor --refit
    # thrust`: the report says the named weights were refitted with each candidate; a name that is no
    # parameter of the model is refused with exit 2 before anything is written.
    import json

    from dynax import save_trajectory
    from dynax.internal import cli_main

    save_trajectory(quadrotor_flight(5.0, seed=8, sag=(4.2, 4.0)), tmp_path / "train.csv")
    save_trajectory(quadrotor_flight(5.0, seed=108, sag=(3.7, 3.5)), tmp_path / "val.csv")
    common = ["diagnose", "quadrotor", str(tmp_path / "train.csv"), "--validation", str(tmp_path / "val.csv")]
    assert cli_main([*common, "--refit", "dw/no_such_weight", "--out", str(tmp_path / "bad")]) == 2
    assert "dw/no_such_weight" in capsys.readouterr().err and not (tmp_path / "bad").exists()
    out = tmp_path / "report"
    quick = ["--max-terms", "1", "--no-discovery", "--no-cross-fit"]
    assert cli_main([*common, "--refit", "thrust", *quick, "--out", str(out)]) == 0
    j = json.loads((out / "report.json").read_text())
    assert j["system"] == "quadrotor" and j["mode"] == "refit"
    assert any("the named ones refitted by simulation error with each candidate" in n for n in j["notes"]), j["notes"]
    assert (out / "flight_error.json").exists()
