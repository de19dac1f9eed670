"""The two-link arm against independently written Spong equations in physical parameters."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax.internal import DRAKE_DEFAULTS
from tests.reference import arm_reference, spong_reference


def test_drake_default_base_parameters():
    theta = dynax.Acrobot().base_parameters
    expected = dict(theta1=1.333, theta2=1.33, theta3=1.0, theta4=14.715, theta5=9.81, theta6=0.1, theta7=0.1)
    for k, v in expected.items():
        assert float(theta[k]) == pytest.approx(v, rel=1e-12), k


@pytest.mark.parametrize("seed", range(3))
def test_vector_field_matches_reference_equations(seed):
    rng = np.random.default_rng(seed)
    physical = {k: v * rng.uniform(0.5, 1.5) for k, v in DRAKE_DEFAULTS.items()}
    physical.pop("g")
    acrobot = dynax.Acrobot.from_physical(**physical)
    pendulum = dynax.DoublePendulum.from_physical(**physical)
    for _ in range(5):
        x = rng.normal(size=4) * 2
        tau = rng.normal(size=2)
        ref = spong_reference({**physical, "g": 9.81}, x, tau)
        np.testing.assert_allclose(
            pendulum.vector_field(0.0, jnp.asarray(x), jnp.asarray(tau)), ref, rtol=1e-10, atol=1e-10
        )
        ref_acro = spong_reference({**physical, "g": 9.81}, x, np.array([0.0, tau[1]]))
        np.testing.assert_allclose(
            acrobot.vector_field(0.0, jnp.asarray(x), jnp.asarray(tau[1:])), ref_acro, rtol=1e-10, atol=1e-10
        )


def test_the_rig_with_friction_and_rotor_inertia_matches_the_base_parameter_reference():
    # The DFKI rig's model as the identification tests make their data (Coulomb friction at both joints,
    # the elbow motor's rotor inertia) against the same arm written out with numpy in base parameters
    # (tests/reference.py), at states that cross the friction's smoothing band.
    rng = np.random.default_rng(7)
    theta = dict(theta1=0.0536, theta2=0.0533, theta3=0.0362, theta4=2.365, theta5=1.777, theta6=0.01, theta7=0.02)
    model = dynax.Extended(
        dynax.DoublePendulum.from_base_parameters(theta),
        (dynax.CoulombFriction(0, 0.15), dynax.CoulombFriction(1, 0.12), dynax.RotorInertia(1, 0.0042)),
    )
    for scale in (3.0, 0.01):
        x = np.concatenate([rng.uniform(-np.pi, np.pi, 2), scale * rng.normal(size=2)])
        tau = rng.normal(size=2)
        ref = arm_reference(list(theta.values()), x, tau, (0.15, 0.12), 0.01, (0.0, 0.0042))
        np.testing.assert_allclose(
            model.vector_field(0.0, jnp.asarray(x), jnp.asarray(tau)), ref, rtol=1e-10, atol=1e-10
        )


def test_energy_is_linear_in_base_parameters():
    x = jnp.array([0.3, -1.2, 0.7, 2.0])
    base = dynax.Acrobot().base_parameters

    def energy(theta):
        return dynax.Acrobot(**dict(zip(list(base)[:5], theta)), theta6=0.1, theta7=0.1).energy(x)

    theta = jnp.stack([base[k] for k in list(base)[:5]])
    hessian = jax.hessian(energy)(theta)
    np.testing.assert_allclose(hessian, 0.0, atol=1e-12)
    np.testing.assert_allclose(jax.grad(energy)(theta) @ theta, energy(theta), rtol=1e-12)


def test_bad_parameters_are_named():
    with pytest.raises(ValueError, match="unknown parameter.*'m3'"):
        dynax.Acrobot.from_physical(m3=1.0)
    with pytest.raises(ValueError, match="`theta2` must be a scalar"):
        dynax.Acrobot(theta2=jnp.ones(3))


def test_linear_axis_matches_emps_model():
    axis = dynax.LinearAxis()
    dq, force = 0.2, 150.0
    acc = axis.vector_field(0.0, jnp.array([0.0, dq]), jnp.array([force]))[1]
    expected = (force - 203.5034 * dq - 20.3935 * np.tanh(dq / 1e-3) + 3.1648) / 95.1089
    assert float(acc) == pytest.approx(expected, rel=1e-12)


def test_pivot_inertias_give_the_same_base_parameters():
    centre = dynax.Acrobot.from_physical(m2=0.8, lc2=0.9, Ic2=0.2)
    pivot = dynax.Acrobot.from_physical(m2=0.8, lc2=0.9, I2=0.2 + 0.8 * 0.9**2, I1=0.083 + 0.25)
    for k, v in centre.base_parameters.items():
        assert float(pivot.base_parameters[k]) == pytest.approx(float(v), rel=1e-12), k
    with pytest.raises(ValueError, match="give each link's inertia once"):
        dynax.Acrobot.from_physical(Ic1=0.1, I1=0.2)
