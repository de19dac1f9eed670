"""Frame conventions of the `Helicopter` (NED, body-to-world quaternion) and the Tempest model."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dynax import AccelerationModel, Helicopter, LinearVelocityModel
from dynax.internal import (
    euler_from_quaternion,
    hover_state,
    quaternion_angle,
    quaternion_from_euler,
    TEMPEST_COEFFICIENTS,
    vehicle_rollout,
)
from dynax.synthetic import HelicopterTruth

DT = 0.01


def _free(gravity=9.81):
    """A helicopter with no aerodynamic forces: rigid-body kinematics and gravity only."""
    body = AccelerationModel(weights=jnp.zeros((6, 17)), gravity=gravity)
    return Helicopter(body)


def _roll_out(system, x0, seconds):
    n = int(round(seconds / DT))
    return vehicle_rollout(system, jnp.asarray(x0), jnp.zeros((n, 4)), DT)


def test_pure_roll_rotates_right_wing_down():
    p = 1.0
    x0 = hover_state().at[10].set(p)
    xs = _roll_out(_free(gravity=0.0), x0, 1.0)
    roll, pitch, yaw = euler_from_quaternion(xs[-1, 3:7])
    assert roll == pytest.approx(p * 1.0, abs=1e-6)
    assert abs(pitch) < 1e-9 and abs(yaw) < 1e-9
    # The body y axis (right wing) points partly down (+z in NED) after a positive roll.
    quat = xs[-1, 3:7]
    np.testing.assert_allclose(quat, [np.cos(0.5), np.sin(0.5), 0, 0], atol=1e-6)


def test_pure_yaw_keeps_world_velocity():
    """Yawing at rate r while moving forward: the body velocity turns, the world velocity does not."""
    r = np.pi / 2
    x0 = hover_state().at[12].set(r).at[7].set(1.0)
    xs = _roll_out(_free(gravity=0.0), x0, 1.0)
    _, _, yaw = euler_from_quaternion(xs[-1, 3:7])
    assert yaw == pytest.approx(np.pi / 2, abs=1e-6)  # nose turned from north to east
    np.testing.assert_allclose(xs[-1, 7:10], [0.0, -1.0, 0.0], atol=1e-6)  # the old heading is now to the left
    np.testing.assert_allclose(xs[-1, 0:3], [1.0, 0.0, 0.0], atol=1e-6)  # moved 1 m north in a straight line


@pytest.mark.parametrize("roll", [0.0, np.pi / 2, np.pi])
def test_free_fall_is_down_in_the_world_whatever_the_attitude(roll):
    x0 = hover_state().at[3:7].set(quaternion_from_euler(roll, 0.0, 0.3))
    t = 1.0
    xs = _roll_out(_free(), x0, t)
    np.testing.assert_allclose(xs[-1, 0:3], [0.0, 0.0, 0.5 * 9.81 * t**2], atol=1e-6)
    # In the body frame the velocity is gravity rotated in: g t along body z when level, body y when rolled 90 deg.
    expected = {0.0: [0, 0, 9.81], np.pi / 2: [0, 9.81, 0], np.pi: [0, 0, -9.81]}[roll]
    np.testing.assert_allclose(xs[-1, 7:10], expected, atol=1e-6)


def test_tempest_model_coefficients_in_vector_field():
    c = TEMPEST_COEFFICIENTS
    heli = Helicopter()
    x = hover_state().at[7:13].set(jnp.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0]))
    dx = heli.vector_field(0.0, hover_state(), jnp.array([1.0, 1.0, 1.0, 1.0]))
    np.testing.assert_allclose(dx[10:13], [c["C1"], c["C2"], c["C3"]])
    np.testing.assert_allclose(dx[7:10], [0.0, c["Dv"], 9.81 + c["C4"]])
    dx = heli.vector_field(0.0, x, jnp.zeros(4))
    # omega x v vanishes for parallel (1,1,1) vectors, so only the linear terms and gravity remain.
    np.testing.assert_allclose(dx[7:10], [c["Ax"], c["Ay"] + c["Dv"], c["Az"] + 9.81])
    np.testing.assert_allclose(dx[10:13], [c["Bx"], c["By"], c["Bz"]])


def test_linear_model_is_gravity_linearised_at_hover():
    heli = Helicopter(LinearVelocityModel())
    x = hover_state().at[3:7].set(quaternion_from_euler(0.01, 0.0, 0.0))
    dx = heli.vector_field(0.0, x, jnp.array([0.0, 0.0, 0.0, 0.0]))
    acc = Helicopter().vector_field(0.0, x, jnp.zeros(4))
    np.testing.assert_allclose(dx[7:10], acc[7:10], atol=1e-3)


def test_quaternion_angle_is_sign_invariant_and_exact():
    a = quaternion_from_euler(0.1, -0.2, 0.3)
    b = quaternion_from_euler(0.1, -0.2, 0.3 + 0.25)
    assert quaternion_angle(a, b) == pytest.approx(0.25, abs=1e-9)
    assert quaternion_angle(a, -b) == pytest.approx(0.25, abs=1e-9)
    assert quaternion_angle(a, a) == pytest.approx(0.0, abs=1e-7)


@pytest.mark.wrong_types
def test_bad_body_model_is_refused():
    with pytest.raises(ValueError, match="body_model"):
        Helicopter(body_model="tempest")
    with pytest.raises(ValueError, match="weights"):
        AccelerationModel(weights=jnp.zeros((6, 3)))


def test_vector_field_vmaps_and_differentiates():
    heli = Helicopter()
    xs = jnp.stack([hover_state(), hover_state().at[10].set(0.5)])
    out = jax.vmap(lambda x: heli.vector_field(0.0, x, jnp.zeros(4)))(xs)
    assert out.shape == (2, 13)
    g = jax.grad(lambda h: h.vector_field(0.0, xs[1], jnp.zeros(4))[10])(heli)
    assert float(g.body_model.weights[3, 3]) == pytest.approx(0.5)  # d(pdot)/d(Bx) = p


def _quasi_steady_derivatives(truth, collective, h=1e-5):
    """Hover derivatives without autodiff and without the Schur complement: perturb one body velocity
    or input by +-h, let the flapping settle (solve its equations for zero flapping rate with scipy),
    and difference the body accelerations."""
    from scipy.optimize import fsolve

    field = jax.jit(lambda x, u: truth.vector_field(0.0, x, u))
    x0 = np.zeros(truth.n_states)
    x0[3] = 1.0
    u0 = np.zeros(7)
    u0[3] = collective

    def settled_body_rates(dx, du):
        def flapping_rates(flap):
            return np.asarray(field(jnp.asarray(np.r_[(x0 + dx)[:13], flap]), jnp.asarray(u0 + du)))[13:]

        flap = fsolve(flapping_rates, np.zeros(truth.n_states - 13), xtol=1e-10)
        return np.asarray(field(jnp.asarray(np.r_[(x0 + dx)[:13], flap]), jnp.asarray(u0 + du)))[7:13]

    a, b = np.zeros((6, 6)), np.zeros((6, 4))
    for j in range(6):
        e = np.zeros(truth.n_states)
        e[7 + j] = h
        a[:, j] = (settled_body_rates(e, 0 * u0) - settled_body_rates(-e, 0 * u0)) / (2 * h)
    for j in range(4):
        e = np.zeros(7)
        e[j] = h
        b[:, j] = (settled_body_rates(0 * x0, e) - settled_body_rates(0 * x0, -e)) / (2 * h)
    return a, b


def test_truth_hover_derivatives_match_a_quasi_steady_finite_difference():
    """`hover_derivatives` (autodiff and a Schur complement) against settling the flapping and
    differencing the accelerations; and the physics the docs describe: damped rates, the cyclic
    and pedal control powers of the Tempest's signs, and flap-back speed stability ($L_v < 0$, $M_u > 0$)."""
    from dynax.synthetic import FlightController

    truth = HelicopterTruth()
    a, b = (np.asarray(m) for m in truth.hover_derivatives())
    a_fd, b_fd = _quasi_steady_derivatives(truth, FlightController().hover_collective)
    # central differences at h = 1e-5 on accelerations of order 10-100: truncation ~ h^2, rounding ~ 1e-16 / h
    np.testing.assert_allclose(a, a_fd, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(b, b_fd, rtol=1e-6, atol=1e-6)
    u, v, w, p, q, r = range(6)
    assert a[p, p] < 0 and a[q, q] < 0 and a[r, r] < 0 and a[w, w] < 0
    assert b[p, 0] > 0 and b[q, 1] < 0 and b[r, 2] > 0 and b[w, 3] < 0  # as the Tempest's C1..C4
    assert a[p, v] < 0 and a[q, u] > 0
