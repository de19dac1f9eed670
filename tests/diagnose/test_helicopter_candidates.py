"""Helicopter candidates: per-axis quadratic drag, world-fixed wind, body-fixed bias.

First the physics of each term (cheap: vector-field evaluations), then hidden-effect tests: a
`Helicopter` (the Tempest acceleration model) with a hidden wind, body bias or quadratic drag flies
in closed loop with heading sweeps, and `diagnose` must name the cause, its place and a positive
gain. The default suite diagnoses with the vehicle candidates in `Known` mode on 20 s flights,
all sharing one compilation, with the no-effect control; the full library in refit mode and the CLI
are marked slow. Input lags are screened in the default suite with the full library.
"""

import json

import jax.numpy as jnp
import numpy as np
import pytest

from dynax import (
    Acrobot,
    BodyBias,
    BodyQuadraticDrag,
    default_candidates,
    diagnose,
    Extended,
    Helicopter,
    Horizons,
    Known,
    Refit,
    Selection,
    Wind,
)
from dynax.internal import AbstractVehicleTerm, hover_state, TEMPEST_COEFFICIENTS
from dynax.synthetic import FlightController, FlightPlan, helicopter_flight

pytestmark = pytest.mark.heavy  # end-to-end runs of a minute or more


U = jnp.asarray([0.1, -0.2, 0.05, 0.3])


def _state(yaw=0.0, body=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)):
    return hover_state(yaw=yaw).at[7:13].set(jnp.asarray(body, float))


def _body_accel(system, x):
    return np.asarray(system.vector_field(0.0, x, U))[7:13]


# --- physics of each term -----------------------------------------------------------------------


def test_terms_at_neutral_values_are_the_nominal_helicopter():
    heli = Helicopter()
    terms = tuple(t for t in default_candidates(heli) if isinstance(t, AbstractVehicleTerm))
    assert {t.cause for t in terms} == {"quadratic_drag", "wind", "body_bias"}
    x = _state(yaw=0.7, body=(1.0, -0.5, 0.3, 0.2, -0.1, 0.4))
    np.testing.assert_allclose(Extended(heli, terms).vector_field(0.0, x, U), heli.vector_field(0.0, x, U), atol=1e-12)


@pytest.mark.parametrize("speed", [2.0, -3.0])
def test_quadratic_drag_opposes_motion_on_its_axis_only(speed):
    heli = Helicopter()
    x = _state(body=(speed, 0.5, -0.4, 0.0, 0.0, 0.0))
    diff = _body_accel(Extended(heli, (BodyQuadraticDrag(0, 0.2),)), x) - _body_accel(heli, x)
    np.testing.assert_allclose(diff, [-0.2 * abs(speed) * speed, 0, 0, 0, 0, 0], atol=1e-12)
    assert diff[0] * speed < 0  # it opposes the motion


def test_body_bias_is_fixed_in_the_body_frame():
    heli = Helicopter()
    for yaw in (0.0, 1.2, -2.5):
        x = _state(yaw=yaw, body=(0.5, 0.0, 0.0, 0.0, 0.0, 0.0))
        for axis in range(6):
            diff = _body_accel(Extended(heli, (BodyBias(axis, 0.7),)), x) - _body_accel(heli, x)
            np.testing.assert_allclose(diff, 0.7 * np.eye(6)[axis], atol=1e-12)


def test_wind_is_fixed_in_the_world_frame_and_acts_through_air_relative_velocity():
    heli = Helicopter()
    c = TEMPEST_COEFFICIENTS
    wind_north = Extended(heli, (Wind(0, 3.0),))
    # Heading north, the wind is a headwind... on the body u axis: drag on u - 3.
    diff = _body_accel(wind_north, _state(yaw=0.0)) - _body_accel(heli, _state(yaw=0.0))
    np.testing.assert_allclose(diff, [c["Ax"] * -3.0, 0, 0, 0, 0, 0], atol=1e-12)
    # Heading east, the same wind comes from the left: it acts on the body v axis (right = south).
    east = _state(yaw=np.pi / 2)
    diff = _body_accel(wind_north, east) - _body_accel(heli, east)
    np.testing.assert_allclose(diff, [0, c["Ay"] * 3.0, 0, 0, 0, 0], atol=1e-9)
    # Moving with the air (ground velocity = wind), there is no aerodynamic force: as in still air at rest.
    drift = _state(yaw=np.pi / 2, body=(0.0, -3.0, 0.0, 0.0, 0.0, 0.0))
    moving, still = wind_north.vector_field(0.0, drift, U), heli.vector_field(0.0, _state(yaw=np.pi / 2), U)
    np.testing.assert_allclose(moving[7:], still[7:], atol=1e-9)
    np.testing.assert_allclose(moving[:3], [3.0, 0.0, 0.0], atol=1e-9)  # it drifts north with the wind
    # Quadratic drag also sees the air-relative velocity.
    both = Extended(heli, (Wind(0, 3.0), BodyQuadraticDrag(0, 0.2)))
    diff = _body_accel(both, _state()) - _body_accel(wind_north, _state())
    np.testing.assert_allclose(diff, [0.2 * 9.0, 0, 0, 0, 0, 0], atol=1e-12)


def test_vehicle_terms_names_and_checks():
    heli = Helicopter()
    model = Extended(heli, (Wind(0, 2.0), Wind(1, -1.0), BodyBias(5, 0.1), BodyQuadraticDrag(2, 0.3)))
    assert model.labels == ("wind@world", "wind@world", "body_bias@r", "quadratic_drag@w")
    assert set(model.parameters) == {"wind_n", "wind_e", "bias_r", "cd_w"}
    with pytest.raises(ValueError, match="not a Helicopter"):
        Extended(Acrobot(), (Wind(0, 1.0),))
    with pytest.raises(ValueError, match="given twice"):
        Extended(heli, (Wind(0, 1.0), Wind(0, 2.0)))
    with pytest.raises(ValueError, match="axis"):
        BodyQuadraticDrag(3)
    with pytest.raises(ValueError, match="axis"):
        BodyBias(6)


def test_a_hidden_wind_makes_a_different_flight():
    """The composed model is a system: it flies, and the wind pushes it (the controller leans into it)."""
    calm = helicopter_flight(Helicopter(), duration=4.0, seed=3, noise=False)
    windy = helicopter_flight(Extended(Helicopter(), (Wind(0, 4.0),)), duration=4.0, seed=3, noise=False)
    assert np.all(np.isfinite(np.asarray(windy.xs)))
    assert np.abs(np.asarray(windy.xs) - np.asarray(calm.xs)).max() > 0.1


# --- hidden effects ----------------------------------------------------------------------------

VEHICLE_CANDIDATES = tuple(t for t in default_candidates(Helicopter()) if isinstance(t, AbstractVehicleTerm))


def _diagnose_hidden(terms, seed, *, fast=False, mode=Known(), candidates=VEHICLE_CANDIDATES, duration=20.0):
    truth = Extended(Helicopter(), tuple(terms))
    # Fast flight (waypoints tens of metres apart, up to 6-7 m/s) for drag; gentle hover otherwise.
    kw = dict(plan=FlightPlan(spread=20.0), controller=FlightController(max_position_error=12.0)) if fast else {}
    train = helicopter_flight(truth, duration=duration, seed=seed, **kw)
    validation = helicopter_flight(truth, duration=duration, seed=seed + 100, **kw)
    return diagnose(
        Helicopter(),
        train,
        validation,
        mode=mode,
        candidates=candidates,
        selection=Selection(max_terms=2),
        horizons=Horizons(horizons_s=(0.25, 0.5, 1.0)),
    ).to_json()


def _assert_found(j, cause, where):
    assert j["verdict"] == "explained", (j["verdict"], j["findings"], j["structure"])
    assert (j["findings"][0]["cause"], j["findings"][0]["where"]) == (cause, where), j["findings"]
    assert j["gain"] > 0.2 and j["findings"][0]["gain"] > 0.2
    h = j["nominal"]["sim_error"]["horizons_s"].index(j["reference_horizon_s"])
    assert j["extended"]["sim_error"]["rmse"][h] < j["nominal"]["sim_error"]["rmse"][h]


@pytest.fixture(scope="module")
def wind_report():
    return _diagnose_hidden((Wind(0, 3.5), Wind(1, -2.0)), seed=1)


@pytest.fixture(scope="module")
def bias_report():
    return _diagnose_hidden((BodyBias(0, 0.8),), seed=2)


def test_hidden_wind_is_named_wind_not_body_bias(wind_report):
    j = wind_report
    _assert_found(j, "wind", "world")
    # One finding for the wind, though its two components were found in two rounds.
    assert [f["cause"] for f in j["findings"]] == ["wind"] and j["extended"]["terms"] == ["wind@world"]
    wind = j["findings"][0]
    found = wind["components"]
    assert found.keys() == {"wind_n", "wind_e"}
    assert found["wind_n"] == pytest.approx(3.5, rel=0.15) and found["wind_e"] == pytest.approx(-2.0, rel=0.15)
    assert wind["coefficient"] == pytest.approx(np.hypot(found["wind_n"], found["wind_e"]))
    assert wind["parameter"] == "wind_speed" and 0 < wind["std_error"] < 0.2 * wind["coefficient"]
    assert set(j["extended"]["parameters"]) >= {"wind_n", "wind_e"}
    assert j["findings"][0]["confidence"] == "high"  # told apart from a body bias
    json.dumps(j)


def test_hidden_body_bias_is_named_body_bias_not_wind(bias_report):
    j = bias_report
    _assert_found(j, "body_bias", "u")
    assert all(f["cause"] != "wind" for f in j["findings"])
    assert j["findings"][0]["coefficient"] == pytest.approx(0.8, rel=0.15)
    assert j["findings"][0]["confidence"] == "high"
    assert any(a["cause"] == "wind" for a in j["findings"][0]["look_alikes"])


@pytest.mark.slow  # about 45 s; the suite hides a wind and a body bias in the helicopter
def test_hidden_quadratic_drag_on_u_is_named():
    # Drag acts only in the fast segments, so the window differences vary from segment to segment: on the 20 s
    # held-out flight alone the test missed it (gain 91 %, p = 0.006 at 0.95 s against Benjamini-Hochberg's 0.01/12
    # for the best of 12 candidates). The candidate horizons now stop where the training flight can still be
    # cross-fitted by blocks, and its windows join the test.
    j = _diagnose_hidden((BodyQuadraticDrag(0, 0.08),), seed=3, fast=True)
    _assert_found(j, "quadratic_drag", "u")
    assert j["findings"][0]["coefficient"] == pytest.approx(0.08, rel=0.1)
    assert j["reference_horizon_s"] <= 20.0 / 24 and j["test"]["cross_fitting"], (j["reference_horizon_s"], j["test"])


def test_no_hidden_effect_gives_none():
    j = _diagnose_hidden((), seed=4)
    assert j["verdict"] == "none", (j["findings"], j["structure"])
    assert j["findings"] == []


@pytest.mark.slow
@pytest.mark.parametrize(
    "terms,cause,where,seed",
    [
        ((Wind(0, -3.0),), "wind", "world", 5),
        ((BodyBias(1, -0.8),), "body_bias", "v", 6),
        ((BodyQuadraticDrag(0, 0.1),), "quadratic_drag", "u", 7),
    ],
)
def test_hidden_effects_with_the_full_library_in_refit_mode(terms, cause, where, seed):
    """The whole vocabulary (inputs too) and the Tempest weights refitted; a bias on v is the model's own Dv."""
    j = _diagnose_hidden(terms, seed, fast=cause == "quadratic_drag", mode=Refit(), candidates=None)
    if (cause, where) == ("body_bias", "v"):
        assert any((c["cause"], c["where"]) == ("body_bias", "v") for c in j["not_identifiable"])
        assert all((f["cause"], f["where"]) != ("body_bias", "v") for f in j["findings"])
        assert j["nominal"]["parameters"]["dv/1"] == pytest.approx(TEMPEST_COEFFICIENTS["Dv"] - 0.8, abs=0.1)
    else:
        _assert_found(j, cause, where)


@pytest.mark.slow
def test_cli_diagnose_helicopter_names_a_hidden_wind(tmp_path, capsys):
    from dynax import save_trajectory
    from dynax.internal import cli_main

    truth = Extended(Helicopter(), (Wind(0, 3.0),))
    save_trajectory(helicopter_flight(truth, duration=20.0, seed=8), tmp_path / "flight1.csv")
    save_trajectory(helicopter_flight(truth, duration=20.0, seed=108), tmp_path / "flight2.csv")
    out = tmp_path / "report"
    code = cli_main(
        [
            "diagnose",
            "helicopter",
            str(tmp_path / "flight1.csv"),
            "--validation",
            str(tmp_path / "flight2.csv"),
            "--max-terms",
            "2",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    j = json.loads((out / "report.json").read_text())
    assert j["system"] == "helicopter"
    assert (j["findings"][0]["cause"], j["findings"][0]["where"]) == ("wind", "world")
    assert j["gain"] > 0.2
    assert "dv/1" in j["nominal"]["parameters"]  # the Tempest weights were refitted
    assert (out / "report.md").exists() and (out / "sim_error.png").exists()
    assert "wind" in capsys.readouterr().out


# --- input lags: screened at finite sizes (issue 10, item 7) ----------------------------------------


def _round_one_screening(truth):
    """`diagnose`'s first-round screening of the full vocabulary on 40 s of aggressive flight, 20 s held out:
    the problem `diagnose` prepares, screened as its first round does."""
    from dynax.internal import first_screening, prepare_problem

    kw = dict(plan=FlightPlan(spread=20.0), controller=FlightController(max_position_error=12.0))
    train = helicopter_flight(truth, duration=40.0, seed=11, **kw)
    validation = helicopter_flight(truth, duration=20.0, seed=111, **kw)
    problem = prepare_problem(Helicopter(), train, validation, None, Refit(), Horizons(), Selection(max_terms=2))
    return first_screening(problem)


@pytest.mark.slow  # about 50 s; the quick suite keeps the hidden wind and body bias
def test_a_collective_lag_screens_first_with_its_size():
    """A 0.15 s lag on u4: the controller moves the collective at a few hertz, far outside the first-order
    (omega tau << 1) range in which a lag is -tau df/du du/dt. Screened only at first order, it ranked
    below a constant vertical bias and was not refitted in the first round; at finite sizes it leads,
    with a start value near its size."""
    from dynax import InputLag

    seen = _round_one_screening(Extended(Helicopter(), (InputLag(3, 0.15),)))
    ranked = sorted(seen, key=lambda label: -seen[label][0])
    assert ranked[0] == "input_lag@u4", [(k, seen[k]) for k in ranked[:5]]
    assert "input_delay@u4" in ranked[:3]  # its look-alike, for the refit to tell apart
    gain, start = seen["input_lag@u4"]
    assert gain > 1.3 * seen["body_bias@w"][0]  # 0.13 against 0.08 (first order: 0.003)
    assert 0.08 < start < 0.3
