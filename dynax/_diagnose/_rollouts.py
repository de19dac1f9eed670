"""Open-loop rollouts of a model from measured states, on windows of a record (vmapped)."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._model._extensions import Extended
from .._simulate import FixedGrid, simulate


def full_initial_state(system, x_measured, u0):
    """The model's initial state from a measured one: internal states of an `Extended` model at rest."""
    if isinstance(system, Extended):
        return system.initial_state(x_measured, u0)
    return x_measured


def window_rollouts(
    system, ts: Float[Array, " time"], xs: Float[Array, "time n"], us: Float[Array, "time m"],
    starts: Int[Array, " window"], n_steps: int, method=FixedGrid(),
) -> tuple[Float[Array, "window step n"], Array]:
    """Simulate `system` from the measured state at each start for `n_steps` samples.

    **Returns:** `(errors, diverged)`: simulated minus measured states of shape
    `(window, n_steps + 1, n_measured)` (NaN past a divergence) and a bool per window.
    """
    n_measured = xs.shape[1]

    def one(k):
        t = jax.lax.dynamic_slice_in_dim(ts, k, n_steps + 1)
        u = jax.lax.dynamic_slice_in_dim(us, k, n_steps + 1)
        x = jax.lax.dynamic_slice_in_dim(xs, k, n_steps + 1)
        sim = simulate(system, full_initial_state(system, x[0], u[0]), t, u, method=method, throw=False)
        return sim.xs[:, :n_measured] - x, sim.diverged

    return jax.vmap(one)(starts)


_jit_window_rollouts = eqx.filter_jit(window_rollouts)
