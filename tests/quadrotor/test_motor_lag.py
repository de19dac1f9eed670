"""The motors' shared first-order lag (`MotorLag`): every rotor follows its command with one time constant.

The term is checked against the nominal body driven by the commands passed through the lag in closed form (an
independent reference: for the held-before-zero commands below, scipy's DOP853 on the body and the four lag
states written out in numpy), against four single-input lags (the bookkeeping of a term on several inputs), and
the hidden-effect test hides a 40 ms lag on every motor of another drone, simulated outside dynax
(`other_drone`: 1.5 kg, motor speeds logged in RPM), and requires the diagnosis to name it and tell it from its
look-alike, the motors' shared dead time (`MotorDelay`), and to find nothing on the same flights without it.

On the Crazyflie-sized flights of `synthetic_flight.quadrotor_flight(..., lag=("all", 0.04))` the two are not told
apart: two 15 s flights establish the pair (the lag's p = 3e-5) but name the dead time (49 ms, 39 %) with
`confidence: low`; two 25 s flights end `none`. The stiff attitude loop of a 30 g vehicle turns a 40 ms lag into
little more than a latency.
"""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from dynax import Extended, InputLag
from dynax.internal import cli_main, MotorLag, quadrotor_candidates

from .test_motor_delay import random_body


def _commands(t):
    """Motor commands that step at 0.1 s and then swing slowly (held at their start value before 0 s)."""
    t = np.maximum(np.asarray(t), 0.0)
    step = 0.08 * (t >= 0.1)
    return np.stack([1.0 + (step + 0.05 * np.sin(3.0 * t)) * (1 + 0.3 * k) * (-1) ** k for k in range(4)], axis=-1)


def test_the_motors_follow_their_commands_through_the_lag():
    jax.config.update("jax_enable_x64", True)
    body, tau = random_body(), 0.04
    x0 = np.array([0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.1, -0.1, 0.0, 0.05, -0.05, 0.02])
    ts = np.linspace(0.0, 0.5, 51)
    model = Extended(body, (MotorLag(time_constant=tau),))
    field = jax.jit(lambda x, u: model.vector_field(0.0, x, u))
    nominal = jax.jit(lambda x, u: body.vector_field(0.0, x, u))
    options = dict(t_eval=ts, method="DOP853", rtol=1e-10, atol=1e-12, max_step=0.005)

    z0 = np.asarray(model.initial_state(jnp.asarray(x0), jnp.asarray(_commands(0.0))))
    ours = solve_ivp(lambda t, x: np.asarray(field(jnp.asarray(x), jnp.asarray(_commands(t)))), (0, 0.5), z0, **options)

    def reference(t, s):  # the rigid body under the four rotors' lag states, written out here
        x, a = s[:13], s[13:]
        return np.concatenate([np.asarray(nominal(jnp.asarray(x), jnp.asarray(a))), (_commands(t) - a) / tau])

    theirs = solve_ivp(reference, (0, 0.5), np.concatenate([x0, _commands(0.0)]), **options)
    unlagged = solve_ivp(
        lambda t, x: np.asarray(nominal(jnp.asarray(x), jnp.asarray(_commands(t)))), (0, 0.5), x0, **options
    )
    error = np.abs(ours.y[:13] - theirs.y[:13])[7:].max()
    effect = np.abs(unlagged.y - theirs.y[:13])[7:].max()
    assert effect > 1e-3 and error < 1e-6 * effect + 1e-9, (error, effect)


def test_one_lag_on_every_motor_is_four_single_input_lags():
    body = random_body()
    shared = Extended(body, (MotorLag(time_constant=0.03),))
    single = Extended(body, tuple(InputLag(i, 0.03) for i in range(4)))
    x = jnp.concatenate([jnp.full(13, 0.1).at[3].set(1.0), jnp.linspace(0.9, 1.1, 4)])
    u = jnp.asarray([1.02, 0.98, 1.01, 0.99])
    np.testing.assert_allclose(shared.vector_field(0.0, x, u), single.vector_field(0.0, x, u), rtol=1e-12)
    assert shared.labels == ("motor_lag@motors",) and set(shared.parameters) == {"lag_motors"}
    assert shared.state_names[13:] == ("m1_motor_lag", "m2_motor_lag", "m3_motor_lag", "m4_motor_lag")
    np.testing.assert_allclose(  # at zero time constant the commands pass straight through
        Extended(body, (MotorLag(),)).vector_field(0.0, x, u)[:13], body.vector_field(0.0, x[:13], u), rtol=1e-12
    )


def test_the_motor_lag_refuses_what_it_cannot_be_and_is_a_quadrotor_candidate():
    with pytest.raises(ValueError, match="distinct"):
        MotorLag((1, 1))
    with pytest.raises(ValueError, match="time"):
        MotorLag(time_constant=-0.01)
    with pytest.raises(ValueError, match="inputs"):
        Extended(random_body(), (MotorLag((0, 1, 2, 7)),))
    (lag,) = [t for t in quadrotor_candidates(random_body()) if t.cause == "motor_lag"]
    assert lag.inputs == (0, 1, 2, 3)


def _other_drone_flights(folder, **effects):
    """Two training and two held-out flights of `other_drone` (25 s each: circle, figure-eight; lissajous, star)."""
    from .other_drone import flight_csv

    paths = [
        str(flight_csv(folder / f"{kind}.csv", kind, speed, seed, **effects))
        for kind, speed, seed in (("circle", 2.5, 1), ("eight", 2.5, 2), ("lissajous", 2.5, 3), ("star", 2.0, 4))
    ]
    return paths[:2], paths[2:]


def _diagnosed(folder, train, validation):
    from .other_drone import MAP

    out = folder / "diagnosis"
    argv = ["diagnose", "quadrotor", *train, "--validation", *validation, "--map", MAP, "--out", str(out), "--quiet"]
    assert cli_main(argv) == 0
    return json.loads((out / "report.json").read_text())


@pytest.mark.slow  # four 25 s flights of a scipy simulator and a diagnosis: minutes on two cores
def test_a_hidden_lag_on_every_motor_of_another_drone_is_named_and_told_from_a_dead_time(tmp_path):
    j = _diagnosed(tmp_path, *_other_drone_flights(tmp_path, lag=0.04))
    assert j["verdict"] == "explained" and j["findings"], (j["verdict"], j["candidates"][:4])
    first = j["findings"][0]
    assert (first["cause"], first["where"]) == ("motor_lag", "motors"), j["findings"]
    assert abs(first["coefficient"] - 0.04) < 0.004 and first["confidence"] == "high"
    assert j["gain"] > 0.5


@pytest.mark.slow
def test_the_same_drone_without_an_effect_gets_no_finding(tmp_path):
    j = _diagnosed(tmp_path, *_other_drone_flights(tmp_path))
    assert not j["findings"] and j["verdict"] in ("none", "inconclusive"), (j["verdict"], j["findings"])
