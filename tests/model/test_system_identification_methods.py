"""What least-squares identification needs to know per system is a method of the system: the two-link
arm's and the linear axis's against hand-written base-parameter formulas, a system without a linear
model refused by name, and a new system identified by the generic layers through its methods alone."""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax
import dynax.internal
from dynax.internal import min_mass_eigenvalue

THETA = dict(theta1=1.1, theta2=0.7, theta3=0.4, theta4=9.0, theta5=4.5, theta6=0.05, theta7=0.08)


def _acrobot_inverse_dynamics(p, q, dq, ddq):
    """Spong's equations in base parameters, written out."""
    c2, s1, s2, s12 = np.cos(q[1]), np.sin(q[0]), np.sin(q[1]), np.sin(q[0] + q[1])
    t1, t2, t3, t4, t5, t6, t7 = (p[f"theta{i}"] for i in range(1, 8))
    tau1 = (
        (t1 + t2 + 2 * t3 * c2) * ddq[0]
        + (t2 + t3 * c2) * ddq[1]
        - t3 * s2 * (2 * dq[0] * dq[1] + dq[1] ** 2)
        + t4 * s1
        + t5 * s12
        + t6 * dq[0]
    )
    tau2 = (t2 + t3 * c2) * ddq[0] + t2 * ddq[1] + t3 * s2 * dq[0] ** 2 + t5 * s12 + t7 * dq[1]
    return np.array([tau1, tau2])


def test_two_link_methods_are_spongs_base_parameter_model():
    acrobot = dynax.Acrobot.from_base_parameters(THETA)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q, dq, ddq = rng.normal(size=(3, 2)) * 2
        force = acrobot.inverse_dynamics(jnp.asarray(q), jnp.asarray(dq), jnp.asarray(ddq))
        np.testing.assert_allclose(force, _acrobot_inverse_dynamics(THETA, q, dq, ddq), rtol=1e-12, atol=1e-12)
    for friction in ("viscous", "coulomb"):  # Coulomb friction is a joint term, not a base parameter
        assert acrobot.base_parameter_names(friction) == tuple(f"theta{i}" for i in range(1, 8))
    assert acrobot.energy_parameter_names() == ("theta1", "theta2", "theta3", "theta4", "theta5")
    terms = acrobot.coulomb_friction_terms()
    assert [(type(t), t.joint, float(t.coefficient)) for t in terms] == [
        (dynax.CoulombFriction, 0, 0.0),
        (dynax.CoulombFriction, 1, 0.0),
    ]
    assert dynax.internal.parameter_names(acrobot, "coulomb")[-2:] == ("fc1", "fc2")


def test_two_link_consistency_conditions_name_the_broken_base_parameter():
    arm = dynax.DoublePendulum()
    assert arm.base_parameter_conditions({k: float(v) for k, v in arm.base_parameters.items()}) == ()
    names = tuple(THETA)

    def broken(**change):
        return dynax.internal.consistency_conditions(arm, names, np.array([{**THETA, **change}[n] for n in names]))

    assert broken() == ()
    (theta2,) = broken(theta2=-0.1)
    assert theta2.startswith("rigid-body inertia: theta2 = -0.1 must be positive")
    (schur,) = broken(theta3=1.0)  # theta1 theta2 = 0.77 < theta3^2 = 1: M(q) indefinite at q2 = 0
    assert "theta1 * theta2 = 0.77 must be at least theta3^2 = 1" in schur
    (gravity,) = broken(theta5=-4.5)
    assert gravity.startswith("gravity: theta5 = -4.5")
    (friction,) = broken(theta7=-0.01)
    assert friction == "friction: theta7 = -0.01 must be non-negative (viscous, at the elbow)"
    # the sentences check the same bounds the constrained fit reads: every "positive" or "nonnegative"
    # kind is a condition, and a parameter on or inside its bound passes
    for name, kind in arm.base_parameter_kinds().items():
        if kind in ("positive", "nonnegative"):
            (sentence,) = broken(**{name: -1e-3})
            assert sentence.split(": ")[1].startswith(f"{name} = -0.001 must be ")
            assert broken(**{name: 0.0 if kind == "nonnegative" else 0.5 * THETA[name]}) == ()
    kinds = arm.base_parameter_kinds()
    assert kinds["theta1"] == "inertia1" and kinds["theta2"] == kinds["theta4"] == kinds["theta5"] == "positive"


def test_linear_axis_methods_are_the_emps_model_with_the_exact_sign():
    axis = dynax.LinearAxis(
        mass=jnp.asarray(95.0), viscous=jnp.asarray(200.0), coulomb=jnp.asarray(20.0), offset=jnp.asarray(-3.0)
    )
    for dq, ddq, expected in (
        (0.0, 2.0, 95.0 * 2.0 - 3.0),  # at rest the sign is 0, not a smoothed value
        (1e-6, 0.0, 200.0 * 1e-6 + 20.0 - 3.0),  # tanh(1e-6 / 1e-3) would give 0.02, not 20
        (-0.5, 1.0, 95.0 - 100.0 - 20.0 - 3.0),
    ):
        force = axis.inverse_dynamics(jnp.zeros(1), jnp.array([dq]), jnp.array([ddq]))
        np.testing.assert_allclose(force, [expected], rtol=1e-14)
    np.testing.assert_allclose(axis.energy(jnp.array([0.3, -2.0])), 0.5 * 95.0 * 4.0, rtol=1e-14)
    assert axis.base_parameter_names() == ("mass", "viscous", "offset")
    assert axis.base_parameter_names("coulomb") == ("mass", "viscous", "coulomb", "offset")
    assert axis.energy_parameter_names() == ("mass",) and axis.coulomb_friction_terms() == ()
    # written back without `coulomb` (a viscous-friction fit), the Coulomb force is gone
    estimate = dict(mass=90.0, viscous=210.0, offset=1.0)
    fitted = axis.with_base_parameters({n: jnp.asarray(v) for n, v in estimate.items()})
    assert {n: float(v) for n, v in fitted.parameters.items()} == {**estimate, "coulomb": 0.0}
    assert float(axis.with_base_parameters({"coulomb": jnp.asarray(5.0)}).coulomb) == 5.0
    names = ("mass", "viscous", "coulomb", "offset")
    assert dynax.internal.consistency_conditions(axis, names, np.array([-1.0, 200.0, -2.0, -50.0])) == (
        "inertia: mass = -1 must be positive",
        "friction: coulomb = -2 must be non-negative",
    )
    with pytest.raises(dynax.UsageError, match="no joint terms on a LinearAxis"):
        dynax.internal.parameter_names(dynax.Extended(axis, (dynax.CoulombFriction(0, jnp.asarray(1.0)),)))


class Drifter(dynax.AbstractSystem):
    """A system with no linear-in-parameter model: it declares none of the methods."""

    rate: jax.Array = eqx.field(default_factory=lambda: jnp.asarray(1.0))
    state_names: ClassVar[tuple[str, ...]] = ("x",)
    input_names: ClassVar[tuple[str, ...]] = ("u",)

    def vector_field(self, t, x, u):
        return self.rate * u


def test_a_system_without_a_linear_model_is_refused_by_name():
    with pytest.raises(dynax.UsageError, match="got Drifter; use SimulationFit"):
        dynax.internal.parameter_names(Drifter())
    # the hooks are not methods of a system that is not linear in its parameters; asked through
    # `identification_hooks`, they refuse it by name
    assert not isinstance(Drifter(), dynax.internal.AbstractLinearInParameters)
    assert not hasattr(Drifter(), "base_parameter_names")
    hooks = dynax.internal.identification_hooks(Drifter())
    for method in ("base_parameter_names", "energy_parameter_names", "coulomb_friction_terms"):
        with pytest.raises(NotImplementedError, match=f"Drifter.{method}: Drifter declares no model linear"):
            getattr(hooks, method)()
    # no conditions: nothing is bounded, even a name that would be a friction coefficient on an arm
    assert hooks.base_parameter_kinds() == {} and hooks.refinement_terms() is None
    assert dynax.internal.consistency_conditions(Drifter(), ("b1",), np.array([-1.0])) == ()


class Oscillator(dynax.AbstractManipulator, dynax.internal.AbstractLinearInParameters):
    r"""A mass-spring-damper $m \ddot q + c \dot q + k q = u$, linear in `(mass, damping, stiffness)`."""

    mass: jax.Array = eqx.field(default_factory=lambda: jnp.asarray(2.0))
    damping: jax.Array = eqx.field(default_factory=lambda: jnp.asarray(0.3))
    stiffness: jax.Array = eqx.field(default_factory=lambda: jnp.asarray(5.0))
    state_names: ClassVar[tuple[str, ...]] = ("q", "dq")
    input_names: ClassVar[tuple[str, ...]] = ("force",)
    n_joints: ClassVar[int] = 1

    def mass_matrix(self, q):
        return jnp.reshape(self.mass, (1, 1))

    def bias_force(self, q, dq):
        return self.damping * dq + self.stiffness * q

    def input_matrix(self):
        return jnp.ones((1, 1), jnp.result_type(self.mass))

    def energy(self, x):
        return 0.5 * self.mass * x[1] ** 2 + 0.5 * self.stiffness * x[0] ** 2

    def check_least_squares(self, terms=()):
        pass

    def base_parameter_names(self, friction="viscous"):
        return ("mass", "damping", "stiffness")

    def energy_parameter_names(self):
        return ("mass", "stiffness")

    def coulomb_friction_terms(self):
        return (dynax.CoulombFriction(0, jnp.zeros(())),)

    def base_parameter_kinds(self):
        return dict(mass="positive", damping="nonnegative", stiffness="free")

    def base_parameter_conditions(self, parameters):
        return () if parameters["mass"] > 0 else ("inertia: mass must be positive",)


def test_a_new_system_is_identified_through_its_methods_alone():
    osc = Oscillator()
    rng = np.random.default_rng(1)
    xs = jnp.asarray(rng.normal(size=(20, 2)))
    ddq = jnp.asarray(rng.normal(size=(20, 1)))
    q, dq = np.asarray(xs[:, 0]), np.asarray(xs[:, 1])
    assert dynax.internal.parameter_names(osc) == ("mass", "damping", "stiffness")
    assert dynax.internal.parameter_names(osc, "coulomb") == ("mass", "damping", "stiffness", "fc")
    y = dynax.internal.dynamic_regressor(osc, xs, ddq)
    np.testing.assert_allclose(y[:, 0, :], np.stack([ddq[:, 0], dq, q], axis=1), rtol=1e-14)
    w = dynax.internal.energy_regressor(osc, xs)
    np.testing.assert_allclose(w, np.stack([0.5 * dq**2, 0 * q, 0.5 * q**2], axis=1), rtol=1e-14)
    f = dynax.internal.friction_power_regressor(osc, xs)
    np.testing.assert_allclose(f, np.stack([0 * q, dq**2, 0 * q], axis=1), rtol=1e-14, atol=1e-14)
    names = dynax.internal.parameter_names(osc, "coulomb")
    assert dynax.internal.consistency_conditions(osc, names, np.array([-1.0, 0.3, -5.0, -0.1])) == (
        "inertia: mass must be positive",
        "friction: fc = -0.1 must be non-negative",
    )


def test_two_link_mass_check_configurations_find_the_smallest_eigenvalue_over_the_data():
    """The consistency check evaluates M(q) at two configurations only; against the smallest
    eigenvalue over every sample (numpy's eigvalsh), for consistent and inconsistent base parameters,
    with a rotor inertia, and on data that cover only part of the elbow's range."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        theta = {n: v * rng.uniform(0.5, 1.5) for n, v in THETA.items()}
        theta["theta3"] = rng.uniform(-1.2, 1.2)  # |theta3| large: indefinite at some elbow angles
        arm = dynax.DoublePendulum.from_base_parameters(theta)
        system = dynax.Extended(arm, (dynax.RotorInertia(1, jnp.asarray(rng.uniform(0.0, 0.2))),))
        lo, hi = np.sort(rng.uniform(-4.0, 4.0, size=2))
        qs = np.stack([rng.uniform(-3, 3, 500), rng.uniform(lo, hi, 500)], axis=1)
        expected = min(
            np.linalg.eigvalsh(
                np.asarray(arm.mass_matrix(jnp.asarray(q))) + np.diag([0.0, float(system.terms[0].coefficient)])
            )[0]
            for q in qs
        )
        got = min_mass_eigenvalue(system, jnp.asarray(qs))
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
    assert len(arm.mass_check_configurations(jnp.asarray(qs))) == 2


def test_output_error_refinement_terms_are_a_method_of_the_system():
    """`identify`'s refinement adds what the system names (the elbow's rotor inertia); a linear axis
    names none, so `refine=True` on it is refused by name rather than by a class check."""
    arm = dynax.DoublePendulum()
    (term,) = arm.refinement_terms()
    assert isinstance(term, dynax.RotorInertia) and term.joint == 1 and float(term.coefficient) == 0.0
    assert dynax.LinearAxis().refinement_terms() is None
    t = jnp.linspace(0.0, 2.0, 401)
    xs = jnp.stack([0.1 * jnp.sin(3 * t), 0.3 * jnp.cos(3 * t)], axis=1)
    data = dynax.Trajectory(t, xs, jnp.sin(t)[:, None], ("q", "dq"), ("force",), "linear_axis")
    with pytest.raises(dynax.UsageError, match="two-link"):
        dynax.identify(dynax.LinearAxis(), data, dynax.Power(), refine=True, validation=dynax.Validate(holdout=0))
