"""Terms say which systems they act on through the system protocol, not through concrete classes."""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.linalg import expm

import dynax
from dynax import (
    AbstractManipulator,
    Acrobot,
    BodyBias,
    CoulombFriction,
    DoublePendulum,
    Extended,
    Helicopter,
    InputGain,
    InputLag,
    LinearAxis,
    RotorInertia,
    Wind,
)
from dynax.control import SpongController
import dynax.internal
from dynax.internal import AbstractVehicleTerm
from tests.stateful_terms import LaggedDamping


class _Slider(AbstractManipulator):
    """A unit mass on a spring: a manipulator dynax's generic layers have never heard of."""

    state_names: ClassVar[tuple[str, ...]] = ("x", "dx")
    input_names: ClassVar[tuple[str, ...]] = ("f",)
    n_joints: ClassVar[int] = 1

    def mass_matrix(self, q):
        return jnp.eye(1, dtype=q.dtype)

    def bias_force(self, q, dq):
        return 4.0 * q

    def input_matrix(self):
        return jnp.ones((1, 1))


def test_protocol_answers():
    assert Acrobot().joint_names == ("q1", "q2") and Acrobot().body_axes == ()
    assert LinearAxis().joint_names == ("q",)
    assert Helicopter().joint_names == () and Helicopter().body_axes == ("u", "v", "w", "p", "q", "r")
    assert _Slider().joint_names == ("x",)
    # An Extended system is not itself extended further: it has no pieces of its own to act on.
    assert Extended(Acrobot(), (CoulombFriction(1, 0.1),)).joint_names == ()


@pytest.mark.parametrize(
    "system, term, message",
    [
        (Acrobot(), Wind(0, 1.0), "Wind acts on a helicopter's body axes, but Acrobot is not a Helicopter"),
        (
            LinearAxis(),
            BodyBias(3, 0.1),
            "BodyBias acts on a helicopter's body axes, but LinearAxis is not a Helicopter",
        ),
        (Helicopter(), CoulombFriction(0, 0.1), "CoulombFriction acts on a joint, but Helicopter is not a manipulator"),
    ],
)
def test_extended_refuses_a_term_the_system_cannot_take(system, term, message):
    with pytest.raises(ValueError, match="^Extended: " + message):
        Extended(system, (term,))
    with pytest.raises(ValueError, match=message):
        term.check_system(system)


def test_joint_terms_compose_with_any_manipulator():
    # A manipulator defined outside dynax takes joint terms through the protocol alone: Coulomb
    # friction fc tanh(dx / vs) and rotor inertia I_r at its one joint, checked against the equation.
    slider = Extended(_Slider(), (CoulombFriction(0, 0.5), RotorInertia(0, 1.0), InputGain(0, 2.0)))
    assert slider.labels == ("coulomb_friction@x", "rotor_inertia@x", "input_gain@f")
    x, u = jnp.array([0.3, 0.2]), jnp.array([1.5])
    dx = slider.vector_field(0.0, x, u)
    expected = (2.0 * 1.5 - 4.0 * 0.3 - 0.5 * np.tanh(0.2 / 0.01)) / (1.0 + 1.0)
    np.testing.assert_allclose(dx, [0.2, expected], rtol=1e-12)


def test_vehicle_terms_act_on_the_helicopter():
    extended = Extended(Helicopter(), (Wind(1, 2.0), BodyBias(4, 0.3)))
    assert extended.labels == ("wind@world", "body_bias@q")
    x = dynax.internal.hover_state(dtype=jnp.float64)
    u = jnp.array([0.0, 0.0, 0.0, 0.2])
    nominal = Helicopter().vector_field(0.0, x, u)
    dx = extended.vector_field(0.0, x, u)
    # The body bias adds exactly its value to dq; the wind changes the air-relative velocity only.
    assert float(dx[11] - nominal[11]) != 0.0
    no_wind = Extended(Helicopter(), (Wind(1, 0.0), BodyBias(4, 0.3))).vector_field(0.0, x, u)
    np.testing.assert_allclose(no_wind[11] - nominal[11], 0.3, rtol=1e-12)
    np.testing.assert_allclose(no_wind[:7], nominal[:7], rtol=1e-12)


@pytest.mark.wrong_types
@pytest.mark.parametrize("system", [DoublePendulum(), LinearAxis(), Extended(Acrobot(), (CoulombFriction(1, 0.1),))])
def test_spong_controller_needs_an_acrobot(system):
    with pytest.raises(ValueError, match="SpongController: `system` must be an Acrobot"):
        SpongController(system)


class _LaggedBias(AbstractVehicleTerm):
    """A body-axis acceleration $z$ that approaches $c$ as $\\tau \\dot z = c - z$ (for this test only)."""

    axis: int = eqx.field(static=True)
    coefficient: jax.Array
    cause: ClassVar[str] = "lagged_bias"
    prefix: ClassVar[str] = "lb"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def hidden_names(self, system):
        return (f"{self.parameter_name(system)}_now",)

    def hidden_vector_field(self, system, x, a, z):
        return (self.coefficient - z) / 0.5

    def acceleration(self, quat, air, u, z=None):
        assert z is not None
        return jnp.zeros_like(air).at[self.axis].set(z[0])


def test_a_term_with_an_internal_state_of_its_own_simulates_through_extended():
    # The slider (unit mass, spring 4) under a lagged drive force a (InputLag, 0.1 s) and a lagged damping: the linear
    # ODE x'' = a - 4 x - b z, 0.1 a' = u - a, 0.3 z' = x' - z, solved exactly by the matrix exponential.
    b, tau, lag = 0.8, 0.3, 0.1
    model = Extended(_Slider(), (LaggedDamping(0, jnp.asarray(b), tau), InputLag(0, lag)))
    assert model.state_names == ("x", "dx", "f_lag", "bl_x_speed")  # the input terms' states first, then the others'
    x0 = model.initial_state(jnp.array([0.3, -0.5]), jnp.array([0.0]))
    np.testing.assert_allclose(x0, [0.3, -0.5, 0.0, -0.5], rtol=1e-15)
    A = np.array([[0, 1, 0, 0], [-4, 0, 1, -b], [0, 0, -1 / lag, 0], [0, 1 / tau, 0, -1 / tau]])
    B = np.array([0.0, 0.0, 1 / lag, 0.0])
    u = 1.5
    ts = np.linspace(0.0, 3.0, 61)
    # Constant input: x(t) = e^{At} x0 + A^{-1} (e^{At} - I) B u.
    exact = np.stack([expm(A * t) @ x0 + np.linalg.solve(A, (expm(A * t) - np.eye(4)) @ B * u) for t in ts])
    us = np.full((len(ts), 1), u)
    xs = dynax.simulate(model, x0, ts, us, method=dynax.Adaptive(rtol=1e-10, atol=1e-10)).xs
    np.testing.assert_allclose(xs, exact, atol=1e-8)
    # The measured state completes the same way in a windowed rollout's start (its history moves input states only).
    start = dynax.internal.complete_state(model, jnp.array([0.3, -0.5]), jnp.array([0.0]))
    np.testing.assert_array_equal(start, x0)


def test_a_vehicle_term_with_an_internal_state_reads_it():
    model = Extended(Helicopter(), (_LaggedBias(4, jnp.asarray(0.3)),))
    assert model.state_names[-1] == "lb_now"
    x = dynax.internal.hover_state(dtype=jnp.float64)
    u = jnp.array([0.0, 0.0, 0.0, 0.2])
    z = 0.12
    dx = model.vector_field(0.0, jnp.concatenate([x, jnp.array([z])]), u)
    nominal = Helicopter().vector_field(0.0, x, u)
    np.testing.assert_allclose(dx[11] - nominal[11], z, rtol=1e-12)  # the bias acts as far as it has built up
    np.testing.assert_allclose(dx[-1], (0.3 - z) / 0.5, rtol=1e-12)
    np.testing.assert_array_equal(model.initial_state(x, u)[-1], 0.0)  # the default start: zero
