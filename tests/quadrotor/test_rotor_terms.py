"""Battery sag and ground effect: the terms scale the rotors' forces and moments, nothing else.

The hidden-effect tests (slow: about two minutes each on two cores) hide each in synthetic flights made
without dynax's model code (`synthetic_flight.quadrotor_flight`: the voltage's square law and Cheeseman and
Bennett's ground effect written out, scipy DOP853 under a geometric controller) and require the diagnosis
to name it; a flight with a steady voltage low over the floor has neither.
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
    initial_quadrotor,
    RotorDrag,
    Selection,
)
from dynax.internal import body_frame_system, quadrotor_candidates

from .synthetic_flight import quadrotor_flight


def _body(battery_inputs=True):
    flight = quadrotor_flight(1.0, seed=0, noise=False, vbat=battery_inputs)
    quad = initial_quadrotor("nominal", [flight], battery=False)
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
    np.testing.assert_allclose(diff[7:], 1e-3 / (0.3 - 0.1 + 0.02) ** 2 * rotors, rtol=1e-10, atol=1e-12)
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


def _diagnosis(train, validation, battery=None):
    quad = initial_quadrotor("nominal", [train], battery=battery)
    return diagnose(
        quad, train, validation, selection=Selection(max_terms=1, discovery=False), progress=False
    ).to_json()


def _named_first(j, cause):
    assert j["findings"], (j["verdict"], j["candidates"][:3])
    first = j["findings"][0]
    assert first["cause"] == cause, j["findings"]
    assert j["gain"] > 0.2 and first["p_value"] < 0.01
    return first


@pytest.mark.slow
@pytest.mark.xfail(
    reason="known shortfall: in a closed-loop flight the command rises as the voltage falls, and the one-step "
    "motor map (m_i^2, m_i) fitted on the training flights absorbs the square law: with the voltage falling "
    "4.2 to 3.5 V over each 15 s flight the nominal's held-out 0.5 s error is 12 mm and battery_sag gains "
    "under 1 %; with training at 4.2-4.0 V and the held-out flight at 3.8-3.6 V the coefficient cannot be "
    "fitted from the training flights (verdict inconclusive). Needs the motor map refitted with the term.",
    strict=True,
)
def test_hidden_battery_sag_is_named_where_the_motor_map_ignores_the_voltage():
    # The voltage falls from 4.2 to 3.5 V over each flight: thrust per command falls by a third.
    train = quadrotor_flight(15.0, seed=5, sag=(4.2, 3.5))
    validation = quadrotor_flight(15.0, seed=105, sag=(4.1, 3.5))
    first = _named_first(_diagnosis(train, validation, battery=False), "battery_sag")
    assert 1.4 < first["coefficient"] < 2.6  # the square law: s = 2 to first order
    # A motor map that reads the voltage (the default where the flights log it) has the sag already.
    j = _diagnosis(train, validation)
    assert "battery_sag" not in [f["cause"] for f in j["findings"]], j["findings"]


@pytest.mark.slow
@pytest.mark.xfail(
    reason="known shortfall: with the floor given at its true height, ground_effect screens first and gains "
    "17 % at 0.5 s on a held-out 15 s flight 2 to 18 cm over the floor (rotors of 8 cm radius, one training "
    "flight high and one low), but the paired test on one held-out flight does not reach the 1 % level "
    "(p = 0.04 with the floor at the lowest height)",
    strict=True,
)
def test_hidden_ground_effect_is_named_low_over_the_floor():
    # Rotors of 8 cm radius flown 2 to 18 cm over the floor: up to a fifth more thrust at the lowest point.
    train = [quadrotor_flight(15.0, seed=6, ground=0.08), quadrotor_flight(15.0, seed=16, altitude=0.1, ground=0.08)]
    validation = quadrotor_flight(15.0, seed=106, altitude=0.1, ground=0.08)
    quad = initial_quadrotor("nominal", train)
    body = body_frame_system(quad, train[0].input_names)
    candidates = quadrotor_candidates(body, floor=0.0)  # the floor's height, as the user knows it
    j = diagnose(
        quad,
        train,
        validation,
        selection=Selection(max_terms=1, discovery=False),
        progress=False,
        candidates=candidates,
    )
    first = _named_first(j.to_json(), "ground_effect")
    # Cheeseman and Bennett's R^2/16 to first order; the fitted floor and rotor height differ from the truth's.
    assert 0.3 * 0.08**2 / 16 < first["coefficient"] < 3 * 0.08**2 / 16


@pytest.mark.slow
def test_a_steady_battery_low_over_the_floor_names_neither():
    train = quadrotor_flight(15.0, seed=7, altitude=0.15, vbat=True)
    validation = quadrotor_flight(15.0, seed=107, altitude=0.15, vbat=True)
    quad = initial_quadrotor("nominal", [train])
    candidates = quadrotor_candidates(body_frame_system(quad, train.input_names), floor=0.0)
    j = diagnose(
        quad,
        train,
        validation,
        selection=Selection(max_terms=1, discovery=False),
        progress=False,
        candidates=candidates,
    )
    j = j.to_json()
    assert not {"battery_sag", "ground_effect"} & {f["cause"] for f in j["findings"]}, j["findings"]
