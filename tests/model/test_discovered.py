"""The `Discovered` term: a sparse formula of typed features, composing with `Extended` like a named term."""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dynax import AbstractJointTerm, Acrobot, Extended, JointSpring, LinearAxis, QuadraticDrag
from dynax.internal import Discovered, Feature


class _Cogging(AbstractJointTerm):
    """A test-local position-periodic force A sin(2 pi q / p + phase), written independently of `Feature`."""

    joint: int = eqx.field(static=True)
    coefficient: jax.Array
    period: float = eqx.field(static=True)
    phase: float = eqx.field(static=True)
    cause: ClassVar[str] = "cogging"
    prefix: ClassVar[str] = "A"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def force(self, q, dq):
        return self.coefficient * jnp.sin(2 * jnp.pi * q / self.period + self.phase)


def _random_states(n, k, seed=0):
    rng = np.random.default_rng(seed)
    return jnp.asarray(rng.uniform(-2, 2, (n, k))), jnp.asarray(rng.normal(size=(n, 1)))


def test_a_discovered_linear_term_in_q2_is_a_joint_spring():
    spring = Extended(Acrobot(), (JointSpring(1, 1.49),))
    found = Extended(Acrobot(), (Discovered(1, (Feature("position", 1),), [-1.49]),))
    xs, us = _random_states(32, 4)
    f = jax.vmap(lambda x, u: found.vector_field(0.0, x, u))(xs, us)
    g = jax.vmap(lambda x, u: spring.vector_field(0.0, x, u))(xs, us)
    np.testing.assert_allclose(f, g, rtol=1e-12, atol=1e-12)


def test_a_discovered_periodic_pair_is_a_phase_shifted_periodic_force():
    amplitude, period, phase = 7.0, 0.05, 0.7
    truth = Extended(LinearAxis(), (_Cogging(0, jnp.asarray(amplitude), period, phase),))
    # A sin(w q + phi) = A cos(phi) sin(w q) + A sin(phi) cos(w q)
    pair = (Feature("periodic_sin", 0, period=period), Feature("periodic_cos", 0, period=period))
    found = Extended(LinearAxis(), (Discovered(0, pair, [amplitude * np.cos(phase), amplitude * np.sin(phase)]),))
    xs, us = _random_states(32, 2, seed=1)
    f = jax.vmap(lambda x, u: found.vector_field(0.0, x, u))(xs, us)
    g = jax.vmap(lambda x, u: truth.vector_field(0.0, x, u))(xs, us)
    np.testing.assert_allclose(f, g, rtol=1e-10, atol=1e-10)


def test_discovered_features_match_the_named_forms_they_stand_for():
    drag = Extended(Acrobot(), (QuadraticDrag(0, 0.3),))
    found = Extended(Acrobot(), (Discovered(0, (Feature("abs_velocity", 0),), [-0.3]),))
    xs, us = _random_states(16, 4, seed=2)
    np.testing.assert_allclose(
        jax.vmap(lambda x, u: found.vector_field(0.0, x, u))(xs, us),
        jax.vmap(lambda x, u: drag.vector_field(0.0, x, u))(xs, us),
        rtol=1e-12,
        atol=1e-12,
    )


def test_a_discovered_input_product_reads_the_applied_input():
    term = Discovered(1, (Feature("input_position", 1, input=0),), [0.5])
    x, u = jnp.asarray([0.1, 0.4, 0.0, 0.0]), jnp.asarray([2.0])
    assert np.isclose(float(term.joint_force(x[:2], x[2:], u)), 0.5 * 2.0 * 0.4)


def test_discovered_term_renders_its_formula_and_parameters():
    system = Acrobot()
    term = Discovered(1, (Feature("position", 1), Feature("sin", 0)), [-1.49, 0.2])
    assert term.formula(system) == "tau_q2 += -1.49*q2 + 0.2*sin(q1)"
    assert "M^-1" in term.acceleration_formula(system)
    model = Extended(system, (term,))
    assert model.labels == ("discovered@q2[q2 + sin(q1)]",)
    assert set(model.parameters) == {"c_q2[q2]", "c_q2[sin(q1)]"}
    assert LinearAxis().state_names[0] in Discovered(
        0, (Feature("periodic_sin", 0, period=0.05),), [1.0]
    ).acceleration_formula(LinearAxis())


def test_discovered_term_refuses_bad_construction():
    with pytest.raises(ValueError, match="coefficients"):
        Discovered(1, (Feature("position", 1),), [1.0, 2.0])
    with pytest.raises(ValueError, match="features"):
        Discovered(1, (), [])
    with pytest.raises(ValueError, match="kind"):
        Feature("spline", 0)
    with pytest.raises(ValueError, match="period"):
        Feature("periodic_sin", 0, period=0.0)
