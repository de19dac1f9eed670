"""`refine_by_simulation`'s wrappers (`ConsistentSystem`, `TimedInputs`) start a model's internal states as the model
itself does: along the record before a segment (`complete_state` with a history), not at rest at its first state.

`identify` refines a two-link arm with `Stiction` and a dwell time where its records rest under load; the memory of
rest is an internal state. The reference is the bare model's own start along the same history.
"""

import jax.numpy as jnp
import numpy as np

import dynax
from dynax.internal import (
    complete_state,
    consistent_parametrisation,
    ConsistentSystem,
    parameter_names,
    parameter_vector,
    TimedInputs,
)


def test_the_refinements_wrappers_start_the_memory_of_rest_along_the_record():
    model = dynax.Extended(  # pyright: ignore[reportCallIssue]
        dynax.DoublePendulum(),
        (
            dynax.CoulombFriction(0, 0.1),
            dynax.CoulombFriction(1, 0.08),
            dynax.Stiction(1, 0.15, dwell_time=0.1),
            dynax.RotorInertia(1, 0.0),
        ),
    )
    names = parameter_names(model, "coulomb")
    start = jnp.asarray(parameter_vector(model, "coulomb"))
    parametrisation = consistent_parametrisation(model, names, jnp.maximum(jnp.abs(start), 1e-3))
    phi = parametrisation.phi(start)
    consistent = ConsistentSystem(phi, model, parametrisation, names)  # pyright: ignore[reportCallIssue]
    timed = TimedInputs(consistent, jnp.zeros((), jnp.result_type(consistent.phi)))  # pyright: ignore[reportCallIssue]
    # Half a second of history: the elbow swings, then rests for its last 50 ms (the memory builds to about
    # 1 - exp(-0.05 / 0.1) = 39 % of its level; `initial_state` of the resting end would say 100 %).
    dt = 0.01
    tb = np.arange(-50, 1) * dt
    q2 = np.where(tb < -0.05, 0.3 * np.sin(2 * np.pi * tb), 0.3 * np.sin(2 * np.pi * -0.05))
    dq2 = np.where(tb < -0.05, 0.6 * np.pi * np.cos(2 * np.pi * tb), 0.0)
    xb = np.stack([0.2 * np.sin(np.pi * tb), q2, 0.2 * np.pi * np.cos(np.pi * tb), dq2], axis=1)
    ub = np.stack([0.5 * np.sin(3 * tb), 0.1 * np.cos(5 * tb)], axis=1)
    tb, xb, ub = (jnp.asarray(a) for a in (tb, xb, ub))
    stencil = jnp.tile(ub, (1, 2 * timed.reach + 1))  # the inputs `with_neighbour_inputs` gives, all alike
    reference = complete_state(consistent.model, xb[-1], ub[-1], tb, ub, xs_before=xb)
    memory = float(reference[-1])
    assert 0.2 < memory < 0.6, memory  # built along the rest, not at rest's full level
    for wrapper, us in ((consistent, ub), (timed, stencil)):
        np.testing.assert_allclose(complete_state(wrapper, xb[-1], us[-1], tb, us, xs_before=xb), reference, rtol=1e-6)
    # Without the history both start at `initial_state` of the resting state: the full level.
    assert float(complete_state(consistent, xb[-1], ub[-1])[-1]) > 0.9
