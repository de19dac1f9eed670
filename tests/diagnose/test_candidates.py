"""The candidate library and the structural identifiability test."""

import jax.numpy as jnp
import numpy as np

from dynax import Acrobot, DoublePendulum
from dynax._diagnose._candidates import default_candidates, look_alikes, structurally_absorbed
from dynax._diagnose._fit import Family, nominal_parameter_names
from dynax._model._extensions import Extended


def _family(system):
    candidates = default_candidates(system)
    names = nominal_parameter_names(system)
    n = len(candidates)
    return Family(
        Extended(system, candidates), names, jnp.ones(len(names)), jnp.ones(len(names)), jnp.ones(n), jnp.zeros(n),
        jnp.asarray([t.neutral for t in candidates], float), jnp.ones(system.n_states),
    )


def _absorbed(system, refit):
    family = _family(system)
    return {t.label(system) for t, a in zip(family.model.terms, structurally_absorbed(family, refit)) if a}


def test_the_library_covers_the_contract_vocabulary():
    labels = {t.label(Acrobot()) for t in default_candidates(Acrobot())}
    for cause in ("coulomb_friction", "viscous_friction", "quadratic_drag", "rotor_inertia"):
        assert {f"{cause}@q1", f"{cause}@q2"} <= labels
    for cause in ("input_delay", "input_lag", "input_gain", "input_offset"):
        assert f"{cause}@tau2" in labels


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
        "viscous_friction@q2", "quadratic_drag@q2"}
    assert {candidates[k].label(system) for k in look_alikes(system, delay, candidates)} == {"input_lag@tau2"}
