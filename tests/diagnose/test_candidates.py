"""The candidate library against independent equations, and the structural identifiability test."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dynax import Acrobot, default_candidates, DoublePendulum, Extended, Helicopter
from dynax.internal import Family, look_alikes, nominal_parameter_names, structurally_absorbed, structurally_equivalent
from tests.reference import DRAKE, spong_reference


def _family(system):
    candidates = default_candidates(system)
    names = nominal_parameter_names(system)
    n = len(candidates)
    return Family(
        Extended(system, candidates),
        names,
        jnp.ones(len(names)),
        jnp.ones(len(names)),
        jnp.ones(n),
        jnp.zeros(n),
        jnp.asarray([t.neutral for t in candidates], float),
        jnp.ones(system.n_states),
    )


def _absorbed(system, refit):
    family = _family(system)
    return {t.label(system) for t, a in zip(family.model.terms, structurally_absorbed(family, refit)) if a}


# A non-neutral value per cause, and what it does in Drake's equations written out independently
# (tests/reference.py): a generalised force at the joint, an inertia on the joint's diagonal, or a
# change of the applied elbow torque.
VALUES = {
    "coulomb_friction": 0.3,
    "viscous_friction": 0.2,
    "quadratic_drag": 0.15,
    "rotor_inertia": 0.05,
    "input_gain": 1.3,
    "input_offset": 0.4,
}


def _reference(cause, joint, value, x, tau2):
    force, rotor, tau = np.zeros(2), [0.0, 0.0], tau2
    dq = x[2 + joint] if joint is not None else 0.0
    if cause == "coulomb_friction":
        force[joint] = -value * np.sign(dq)  # |dq| >= 0.5 rad/s here: tanh(dq / 0.01) is 1 to 1e-40
    elif cause == "viscous_friction":
        force[joint] = -value * dq
    elif cause == "quadratic_drag":
        force[joint] = -value * abs(dq) * dq
    elif cause == "rotor_inertia":
        rotor[joint] = value
    elif cause == "input_gain":
        tau = value * tau2
    elif cause == "input_offset":
        tau = tau2 + value
    return spong_reference(DRAKE, x, np.array([0.0, tau]) + force, rotor=rotor)


@pytest.mark.parametrize("x", [np.array([0.4, -1.1, 0.8, -1.5]), np.array([2.0, 0.7, -0.5, 2.5])])
def test_every_joint_and_gain_candidate_acts_as_its_name_says(x):
    system = Acrobot()
    checked = set()
    for term in default_candidates(system):
        if term.cause not in VALUES:
            continue
        value = VALUES[term.cause]
        model = Extended(system, (eqx.tree_at(lambda t: t.coefficient, term, jnp.asarray(value)),))
        dx = model.vector_field(0.0, model.initial_state(jnp.asarray(x), jnp.array([0.7])), jnp.array([0.7]))
        joint = getattr(term, "joint", None)
        np.testing.assert_allclose(
            dx[:4], _reference(term.cause, joint, value, x, 0.7), rtol=1e-10, atol=1e-12, err_msg=term.label(system)
        )
        checked.add(term.label(system))
    assert len(checked) == 10  # four joint causes at each of the two joints, gain and offset at tau2


def test_lag_and_delay_candidates_have_their_transfer_functions():
    r"""The internal-state candidates as linear filters from recorded to applied input,
    $H(j\omega) = C (j\omega - A)^{-1} B + D$, against a first-order lag $1/(1 + j\omega\tau)$ and a dead
    time $e^{-j\omega T}$ (through its (2, 2) Pade approximant, exact to $(\omega T)^5/720$)."""
    system = Acrobot()
    candidates = {t.cause: t for t in default_candidates(system)}
    for cause, value, reference in (
        ("input_lag", 0.1, lambda w: 1 / (1 + 1j * w * 0.1)),
        ("input_delay", 0.05, lambda w: np.exp(-1j * w * 0.05)),
    ):
        term = eqx.tree_at(lambda t: t.coefficient, candidates[cause], jnp.asarray(value))
        u0, z0 = jnp.asarray(0.0), jnp.zeros(term.n_hidden)
        a_z, b_u = jax.jacfwd(term.hidden_derivative, argnums=(1, 0))(u0, z0)
        c_z, d_u = jax.jacfwd(term.applied, argnums=(1, 0))(u0, z0)
        for w in (0.5, 2.0, 6.0):  # rad/s; omega T <= 0.3 for the delay
            h = c_z @ np.linalg.solve(1j * w * np.eye(term.n_hidden) - np.asarray(a_z), np.asarray(b_u)) + d_u
            assert abs(h - reference(w)) < 1e-5, (cause, w, h, reference(w))
        # at rest under a constant input the applied input is the recorded one and nothing moves
        z = term.steady_state(jnp.asarray(0.7))
        assert float(term.applied(jnp.asarray(0.7), z)) == pytest.approx(0.7, abs=1e-12)
        np.testing.assert_allclose(term.hidden_derivative(jnp.asarray(0.7), z), 0.0, atol=1e-12)


def test_refitting_base_parameters_absorbs_exactly_the_expected_causes():
    # Acrobot: viscous friction is theta6/theta7, rotor inertia at the shoulder adds to theta1,
    # and an input gain rescales all seven base parameters.
    expected = {"viscous_friction@q1", "viscous_friction@q2", "rotor_inertia@q1", "input_gain@tau2"}
    assert _absorbed(Acrobot(), np.ones(7)) == expected
    # With both joints driven, one input's gain is no longer a rescaling of the whole model.
    assert "input_gain@tau1" not in _absorbed(DoublePendulum(), np.ones(7))
    # With trusted parameters nothing is absorbed.
    assert _absorbed(Acrobot(), np.zeros(7)) == set()


def test_look_alikes_are_at_the_same_place():
    system = Acrobot()
    candidates = default_candidates(system)
    coulomb_q2 = next(t for t in candidates if t.label(system) == "coulomb_friction@q2")
    delay = next(t for t in candidates if t.label(system) == "input_delay@tau2")
    assert {candidates[k].label(system) for k in look_alikes(system, coulomb_q2, candidates)} == {
        "viscous_friction@q2",
        "quadratic_drag@q2",
    }
    assert {candidates[k].label(system) for k in look_alikes(system, delay, candidates)} == {"input_lag@tau2"}


def test_an_arm_with_two_drives_has_one_shared_dead_time_and_lag():
    """Drives commanded through one chain share its latency: a double pendulum's vocabulary has `motor_delay` and
    `motor_lag` at `motors` beside the per-input terms (look-alikes of each other only); the acrobot, with one
    drive, has neither."""
    system = DoublePendulum()
    candidates = default_candidates(system)
    labels = [t.label(system) for t in candidates]
    assert {"motor_delay@motors", "motor_lag@motors", "input_delay@tau1", "input_delay@tau2"} <= set(labels)
    shared = candidates[labels.index("motor_delay@motors")]
    assert shared.inputs == (0, 1)
    assert {labels[k] for k in look_alikes(system, shared, candidates)} == {"motor_lag@motors"}
    assert not any(t.cause.startswith("motor_") for t in default_candidates(Acrobot()))


def test_gains_on_the_two_motors_are_one_model_when_the_base_parameters_are_refitted():
    """Scaling every torque-side base parameter and both torque gains by one factor leaves the double
    pendulum's motion unchanged (M qdd + ... = G tau), so with the base parameters refitted a gain on tau1
    is a gain on tau2 and only their ratio is determined; no other pair of the vocabulary is. A held
    friction that is not zero would have to scale too: with it held, and with trusted parameters, the two
    are different causes."""

    def pairs(system, refit):
        family = _family(system)
        labels = [t.label(system) for t in family.model.terms]
        among = [k for k, a in enumerate(structurally_absorbed(family, refit)) if not a]
        return {
            frozenset((labels[k], labels[l]))
            for k, ls in structurally_equivalent(family, refit, among).items()
            for l in ls
        }

    gains = {frozenset(("input_gain@tau1", "input_gain@tau2"))}
    assert pairs(DoublePendulum(), np.ones(7)) == gains
    frictionless = eqx.tree_at(lambda s: (s.theta6, s.theta7), DoublePendulum(), (jnp.zeros(()), jnp.zeros(())))
    assert pairs(frictionless, np.asarray([1, 1, 1, 1, 1, 0, 0])) == gains  # refit mode on the DFKI rig's model 3.1
    assert pairs(DoublePendulum(), np.asarray([1, 1, 1, 1, 1, 0, 0])) == set()
    assert pairs(DoublePendulum(), np.zeros(7)) == set()
    # The helicopter's control inputs each drive one body axis (collective: w; cyclics: p, q; pedal: r), so
    # an offset on one is a constant body acceleration on its axis even with every parameter trusted.
    heli = Helicopter()
    assert pairs(heli, np.zeros(len(nominal_parameter_names(heli)))) == {
        frozenset((f"input_offset@u{i}", f"body_bias@{axis}")) for i, axis in zip((1, 2, 3, 4), "pqrw")
    }


def test_the_structural_answers_are_the_same_with_jax_in_float32():
    """With JAX's float64 mode off, the vector field's derivatives carry float32 rounding (some 1e-7 relative),
    which a span test at 1e-7 would read as structure that is not there; the tests read them in float64 on the
    host with a tolerance at least 100 float32 epsilons, and give the float64 answers."""

    def answers():
        family = _family(DoublePendulum())
        labels = [t.label(DoublePendulum()) for t in family.model.terms]
        absorbed = structurally_absorbed(family, np.ones(7))
        among = [k for k, a in enumerate(absorbed) if not a]
        pairs = structurally_equivalent(family, np.ones(7), among)
        return (
            {labels[k] for k in np.flatnonzero(absorbed)},
            {labels[k]: sorted(labels[l] for l in v) for k, v in pairs.items()},
            _absorbed(Acrobot(), np.ones(7)),
        )

    in_float64 = answers()
    with jax.enable_x64(False):
        assert jnp.zeros(()).dtype == jnp.float32
        in_float32 = answers()
    assert in_float32 == in_float64
    assert in_float64[2] == {"viscous_friction@q1", "viscous_friction@q2", "rotor_inertia@q1", "input_gain@tau2"}
