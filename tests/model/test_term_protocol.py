"""Terms say which systems they act on through the system protocol, not through concrete classes."""

from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

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
    LinearAxis,
    RotorInertia,
    Wind,
)
from dynax.control import SpongController
import dynax.internal


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


@pytest.mark.parametrize("system", [DoublePendulum(), LinearAxis(), Extended(Acrobot(), (CoulombFriction(1, 0.1),))])
def test_spong_controller_needs_an_acrobot(system):
    with pytest.raises(ValueError, match="SpongController: `system` must be an Acrobot"):
        SpongController(system)
