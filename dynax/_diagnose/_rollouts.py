"""Open-loop rollouts of a model from measured states, on windows of a record (vmapped)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._data._trajectory import Trajectory
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


def horizon_errors(system, trajectory: Trajectory, horizons_s, *, max_windows: int = 200, method=FixedGrid()):
    """Multi-start open-loop errors at each horizon: the raw material of error-against-horizon.

    **Returns:** `(steps, starts, errors, diverged)` with `errors` of shape
    `(window, max_step + 1, n_measured)`.
    """
    dt = trajectory.dt
    steps = np.maximum(np.round(np.asarray(horizons_s, float) / dt).astype(int), 1)
    n_steps = int(steps.max())
    n_starts = len(trajectory) - n_steps
    if n_starts < 1:
        raise ValueError(
            f"the record of {trajectory.duration:g} s is too short for a {max(horizons_s):g} s horizon"
        )
    stride = max(1, int(np.ceil(n_starts / max_windows)))
    starts = jnp.arange(0, n_starts, stride)
    errors, diverged = _jit_window_rollouts(system, trajectory.ts, trajectory.xs, trajectory.us, starts, n_steps, method)
    return steps, starts, errors, diverged


def position_rmse(errors, steps, position_index):
    """RMSE over windows and position states at each horizon step (inf when a window diverged)."""
    at = np.asarray(errors)[:, steps][:, :, position_index]
    bad = ~np.isfinite(at).all(axis=(1, 2))
    rmse = np.sqrt(np.mean(at[~bad] ** 2, axis=(0, 2))) if (~bad).any() else np.full(len(steps), np.inf)
    return np.where(bad.any(), np.inf, rmse) if bad.mean() > 0.05 else rmse
