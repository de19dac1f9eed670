"""A vehicle's window score sees what its record shows (`dynax.internal.flight_state_scale`).

A 0.1 m/s^2 side force (a thrust axis 0.6 degrees off) on a Crazyflie-sized flight changes the held-out position at
0.4 s by about half, and nothing in the attitude or rates. The truth's rollouts, with and without the force, are the
generator's own law by RK4 (`tests.hidden_flights`), not dynax's; dynax gives only the scale. In units of each
state's spread over the flight, the score read a gain of about 1 % (the position's metres against centimetres of
error, the gyro's noise carried open loop in the rates); scaled by the starting model's error per group (position,
attitude, body velocity, rates) it reads the position's and velocity's gains.
"""

import numpy as np

import dynax
import dynax.internal
from tests import hidden_flights as hf
from tests.quadrotor import synthetic_flight as sf

N_REF = 40  # 0.4 s at 100 Hz


def _errors(flight, effects):
    """Open-loop errors `(window, step, state)` of the generator's law (with `effects`) from the measured state every
    0.1 s, in the body-frame states."""
    xs, commands = np.asarray(flight.xs, float), np.asarray(flight.us, float)[:, :4] / sf.NANO.unit
    measured = hf._body_states(xs)
    out = []
    for k in range(0, len(xs) - N_REF, 10):
        u = commands[k : k + N_REF]
        sim = hf._body_states(hf._rollout(xs[k], u, 0, effects, np.ones(N_REF), u[0].copy(), N_REF))
        out.append(sim - measured[k + 1 : k + N_REF + 1])
    return np.asarray(out)


def _gain(with_effect, without, scale):
    score = lambda e: np.mean((e / scale) ** 2)  # noqa: E731 (the mean window score)
    return 1.0 - score(with_effect) / score(without)


def test_a_side_force_shows_in_the_flight_score_not_in_the_spread():
    bias = {"bias": (1, 0.1)}
    train, held = (sf.quadrotor_flight(6.0, seed=s, bias=(1, 0.1)) for s in (21, 22))
    quad = dynax.Quadrotor.from_flights("nominal", [train])
    quad = dynax.fit_quadrotor(quad, train, progress=False).model
    body = dynax.internal.body_frame_system(quad, train.input_names)
    groups = dynax.internal.vehicle_state_groups(body)
    assert groups == ((0, 1, 2), (3, 4, 5, 6), (7, 8, 9), (10, 11, 12))
    records = dynax.internal.body_frame_records(quad, [train])
    scale = dynax.internal.flight_state_scale(body, records, 0.4, 0.01, groups)
    assert scale is not None
    spread = np.asarray(records[0].xs).std(axis=0)
    for g in groups:  # one scale per group
        assert np.ptp(scale[list(g)]) == 0.0
    truth, free = _errors(held, bias), _errors(held, {})
    position = 1 - np.sqrt(np.mean(truth[:, -1, :3] ** 2) / np.mean(free[:, -1, :3] ** 2))
    assert position > 0.3  # what the record shows
    assert _gain(truth, free, spread) < 0.05  # the spread's score hides it (about 1 %)
    assert _gain(truth, free, scale) > 0.2  # the flight score reads it


def test_a_manipulator_and_the_helicopter_keep_the_spread():
    assert dynax.internal.vehicle_state_groups(dynax.Acrobot()) == ()
    assert dynax.internal.vehicle_state_groups(dynax.Helicopter()) == ()
