"""`dynax.internal.applied_inputs`: the commands a quadrotor's rotors act on over each sample interval when they pass
through a motor's lag or a dead time, which the diagnosis refits the held one-step motor map through.

Checked against the closed forms of a first-order lag and a whole-sample dead time driven by a zero-order hold,
written here in numpy."""

import numpy as np

from dynax import InputLag, MotorDelay, Quadrotor
from dynax.internal import applied_inputs, body_frame_system

from .synthetic_flight import quadrotor_flight


def test_a_lag_and_a_dead_time_pass_the_logged_commands_on_as_their_closed_forms():
    flight = quadrotor_flight(2.0, seed=3)
    body = body_frame_system(Quadrotor.from_flights("nominal", [flight]), tuple(flight.input_names))
    us, dt, tau = np.asarray(flight.us), 0.01, 0.08

    lagged = applied_inputs(body, (InputLag(2, tau),), flight)
    # The lag's output over [t_k, t_k + dt] under the held command u_k, from rest at the first command: its mean
    # u_k + (z_k - u_k) tau / dt (1 - exp(-dt / tau)), and z_{k+1} = u_k + (z_k - u_k) exp(-dt / tau).
    z, mean, decay = us[0, 2], np.zeros(len(us)), np.exp(-dt / tau)
    for k, u in enumerate(us[:, 2]):
        mean[k] = u + (z - u) * tau / dt * (1 - decay)
        z = u + (z - u) * decay
    spread = np.ptp(us[:, 2])
    assert spread > 100  # the controller moves motor 3's command: the check has something to see
    np.testing.assert_allclose(lagged[:-1, 2], mean[:-1], atol=1e-3 * spread)
    assert np.abs(lagged[:-1, 2] - us[:-1, 2]).max() > 0.05 * spread  # and the lag changes it
    np.testing.assert_array_equal(lagged[:, [0, 1, 3]], us[:, [0, 1, 3]])  # the other motors as logged

    late = applied_inputs(body, (MotorDelay(delay=3 * dt),), flight)
    np.testing.assert_allclose(late[3:, :4], us[:-3, :4], rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(late[:3, :4], np.broadcast_to(us[0, :4], (3, 4)), rtol=1e-9, atol=1e-6)
