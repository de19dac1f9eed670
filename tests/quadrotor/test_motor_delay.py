"""The motors' shared dead time (`MotorDelay`): every motor's command acts the same time late.

The term is checked against the nominal body driven by the commands shifted in time (an independent
reference: the rigid body under the recorded inputs read `T` earlier, scipy's DOP853), against four
single-input delays (the bookkeeping of a term on several inputs), and the hidden-effect tests hide a
40 ms dead time in synthetic flights made without dynax's model code (`synthetic_flight.quadrotor_flight`,
each rotor receiving the command logged four samples before) and require the diagnosis to name it.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from dynax import diagnose, Extended, InputDelay, MotorDelay, Quadrotor, Selection
from dynax.internal import body_frame_system, quadrotor_candidates

from .synthetic_flight import quadrotor_flight


def random_body():
    """A body-frame quadrotor with random motor-map weights (the dynamics of a term are checked, not a fit)."""
    flight = quadrotor_flight(1.0, seed=0, noise=False)
    quad = Quadrotor.from_flights("nominal", [flight], battery=False)
    weights = jnp.asarray(np.random.default_rng(0).normal(size=quad.body_model.weights.shape))
    quad = quad.with_body_model(type(quad.body_model)(weights, quad.body_model.feature_names, quad.body_model.mask))
    return body_frame_system(quad, flight.input_names)


def _commands(t):
    """Slow motor commands (content well below 1 / (2 T), where the Pade delay is accurate), held before 0 s
    (so that the delay's internal states start at rest)."""
    t = np.maximum(np.asarray(t), 0.0)
    return np.stack([1.0 + 0.05 * (1.0 - np.cos(2.0 * t)) * (1 + 0.3 * k) for k in range(4)], axis=-1)


def _dop853(rhs, x0, ts):
    """States at `ts` from `x0` by scipy's DOP853 at tight tolerance (the reference, outside dynax's integrators)."""
    f = lambda t, x: np.asarray(rhs(t, x))  # noqa: E731
    return solve_ivp(f, (ts[0], ts[-1]), x0, t_eval=ts, method="DOP853", rtol=1e-10, atol=1e-12).y.T


def test_the_motors_act_the_delay_late():
    jax.config.update("jax_enable_x64", True)
    body, delay = random_body(), 0.04
    x0 = np.array([0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.1, -0.1, 0.0, 0.05, -0.05, 0.02])
    ts = np.linspace(0.0, 0.6, 61)
    model = Extended(body, (MotorDelay(delay=delay),))
    field = jax.jit(lambda x, u: model.vector_field(0.0, x, u))
    z0 = np.asarray(model.initial_state(jnp.asarray(x0), jnp.asarray(_commands(0.0))))
    ours = _dop853(lambda t, x: field(jnp.asarray(x), jnp.asarray(_commands(t))), z0, ts)[:, :13]
    nominal = jax.jit(lambda x, u: body.vector_field(0.0, x, u))
    shifted = _dop853(lambda t, x: nominal(jnp.asarray(x), jnp.asarray(_commands(t - delay))), x0, ts)
    undelayed = _dop853(lambda t, x: nominal(jnp.asarray(x), jnp.asarray(_commands(t))), x0, ts)
    error = np.abs(ours - shifted)[:, 7:].max()
    effect = np.abs(undelayed - shifted)[:, 7:].max()
    assert effect > 1e-3 and error < 0.01 * effect, (error, effect)


def test_one_delay_on_every_motor_is_four_single_input_delays():
    body = random_body()
    shared = Extended(body, (MotorDelay(delay=0.03),))
    single = Extended(body, tuple(InputDelay(i, 0.03) for i in range(4)))
    assert shared.state_names == single.state_names  # m1_delay1, m1_delay2, ..., m4_delay2
    x = jnp.concatenate([jnp.full(13, 0.1).at[3].set(1.0), jnp.linspace(0.9, 1.1, 8)])
    u = jnp.asarray([1.02, 0.98, 1.01, 0.99])
    np.testing.assert_allclose(shared.vector_field(0.0, x, u), single.vector_field(0.0, x, u), rtol=1e-12)
    assert shared.labels == ("motor_delay@motors",) and set(shared.parameters) == {"delay_motors"}
    np.testing.assert_allclose(  # at zero delay the commands pass straight through
        Extended(body, (MotorDelay(),)).vector_field(0.0, x, u)[:13], body.vector_field(0.0, x[:13], u), rtol=1e-12
    )


def test_the_motor_delay_refuses_inputs_it_cannot_act_on_and_is_a_quadrotor_candidate():
    with pytest.raises(ValueError, match="distinct"):
        MotorDelay((0, 0))
    with pytest.raises(ValueError, match="inputs"):
        Extended(random_body(), (MotorDelay((0, 1, 2, 7)),))
    (delay,) = [t for t in quadrotor_candidates(random_body()) if t.cause == "motor_delay"]
    assert delay.inputs == (0, 1, 2, 3)


@pytest.mark.slow  # two 15 s flights and a diagnosis with the simulation-error refits: minutes on two cores
def test_a_hidden_motor_delay_is_named():
    train = quadrotor_flight(15.0, seed=5, delay=0.04)
    validation = quadrotor_flight(15.0, seed=105, delay=0.04)
    quad = Quadrotor.from_flights("nominal", [train])
    j = diagnose(quad, train, validation, selection=Selection(max_terms=1, discovery=False), progress=False).to_json()
    assert j["findings"], (j["verdict"], j["candidates"][:5])
    first = j["findings"][0]
    assert (first["cause"], first["where"]) == ("motor_delay", "motors"), j["findings"]
    assert 0.025 < first["coefficient"] < 0.055
    assert j["gain"] > 0.2 and first["p_value"] < 0.01
