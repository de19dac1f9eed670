"""`simulation_error`: open-loop prediction error against horizon, started from many samples of a record."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._data._trajectory import Trajectory
from ._distributed import _global_array, _leading_sharding, _replicate
from ._errors import DataError
from ._model._system import AbstractSystem
from ._simulate import FixedGrid, simulate


class SimulationError(eqx.Module):
    """Open-loop simulation error against horizon (the result of `simulation_error`).

    **Fields:**

    - `horizons_s`: the horizons [s].
    - `rmse`: root-mean-square error at each horizon over the `states` it was computed for and
      over all start times (`inf` at a horizon where some window diverged).
    - `rmse_per_state`: shape `(horizon, n_measured_states)`, per state column.
    - `states`: the names the headline `rmse` pools.
    - `state_names`: the names of the columns of `rmse_per_state`.
    - `n_windows`: number of start times.
    - `diverged_fraction`: fraction of windows whose rollout diverged.
    - `errors`: the raw errors, shape `(window, step, n_measured_states)` (simulated minus measured).
    - `starts`: the start indices of the windows.
    """

    horizons_s: Float[Array, " horizon"]
    rmse: Float[Array, " horizon"]
    rmse_per_state: Float[Array, "horizon n_states"]
    states: tuple[str, ...] = eqx.field(static=True)
    state_names: tuple[str, ...] = eqx.field(static=True)
    n_windows: int = eqx.field(static=True)
    diverged_fraction: Float[Array, ""]
    errors: Float[Array, "window step n_states"]
    starts: Array

    def to_json(self) -> dict:
        """The contract's `sim_error` object: `{"horizons_s": [...], "rmse": [...]}`."""
        return {"horizons_s": [float(h) for h in self.horizons_s], "rmse": [float(r) for r in self.rmse]}


def _complete_state(system, x_measured, u0):
    """The model's full initial state from a measured one.

    Models with internal states (an input lag or delay, see `Extended`) complete it with
    `initial_state(x, u0)`: internal states at rest under the input in force. Otherwise internal
    states beyond the measured ones start at zero.
    """
    initial_state = getattr(system, "initial_state", None)
    if initial_state is not None:
        return initial_state(x_measured, u0)
    return jnp.zeros(system.n_states, x_measured.dtype).at[: x_measured.shape[0]].set(x_measured)


@eqx.filter_jit
def _window_errors(system, ts, xs, us, starts, n_steps, method):
    n_measured = xs.shape[1]

    def one(k):
        t = jax.lax.dynamic_slice_in_dim(ts, k, n_steps + 1)
        u = jax.lax.dynamic_slice_in_dim(us, k, n_steps + 1)
        x = jax.lax.dynamic_slice_in_dim(xs, k, n_steps + 1)
        x0 = _complete_state(system, x[0], u[0])
        sim = simulate(system, x0, t, u, method=method, throw=False)
        return sim.xs[:, :n_measured] - x, sim.diverged

    return jax.vmap(one)(starts)


def simulation_error(
    system: AbstractSystem,
    trajectory: Trajectory,
    horizons_s=(0.5, 1.0, 2.0),
    *,
    stride: int | None = None,
    max_windows: int = 200,
    states: tuple[str, ...] | None = None,
    method=FixedGrid(),
) -> SimulationError:
    r"""Open-loop simulation error of `system` against measured `trajectory`, against horizon.

    From each start sample $k$ (every `stride` samples) the model is simulated from the measured
    state $x_k$ under the recorded inputs, and compared with the measured states $H$ seconds later.
    The rollouts run as one `vmap`ped, jit-compiled computation. Horizons are converted to a number
    of samples with the median sample interval (irregular grids are integrated as recorded).

    **Arguments:**

    - `system`: the model. Internal states beyond the measured ones (an input lag or delay) start
      at rest under the input in force (`Extended.initial_state`), or at zero for other systems.
    - `trajectory`: the measured record (its `state_names` must be the system's first states).
    - `horizons_s`: horizons [s].
    - `stride`: samples between start times; default spreads at most `max_windows` windows over
      the record.
    - `states`: the state names the headline `rmse` pools; default the positions (names not
      starting with `d`, e.g. `q1, q2` for the acrobot: RMSE in rad).
    - `method`: the integration strategy passed to `simulate`.

    With several devices the windows are split across them (padded to a multiple of their
    number); in a multi-process run (`dynax.initialize_distributed`) across every process's
    devices, each process computing its share and getting every window's errors back.

    **Returns:** a `SimulationError`.
    """
    names = trajectory.state_names
    if tuple(system.state_names[: len(names)]) != tuple(names):
        raise ValueError(
            f"simulation_error: the trajectory's states {names} are not the first states of "
            f"{type(system).__name__} {system.state_names}"
        )
    horizons = np.asarray(horizons_s, dtype=float)
    dt = trajectory.dt
    steps = np.maximum(np.round(horizons / dt).astype(int), 1)
    n_steps = int(steps.max())
    n = len(trajectory)
    if n < n_steps + 1:
        raise DataError(
            f"has {n} samples, too few for a {horizons.max():g} s horizon at {dt:g} s sampling "
            f"(need at least {n_steps + 1})",
            path=trajectory.source or None,
        )
    n_starts = n - n_steps
    if stride is None:
        stride = max(1, int(np.ceil(n_starts / max_windows)))
    starts = jnp.arange(0, n_starts, stride)
    errors, diverged = _sharded_window_errors(system, trajectory, starts, n_steps, method)
    at = errors[:, steps, :]  # (window, horizon, state)
    if states is None:
        states = tuple(s for s in names if not s.startswith("d"))
    idx = jnp.array([names.index(s) for s in states])
    per_state = jnp.sqrt(jnp.nanmean(at**2, axis=0))
    pooled = jnp.sqrt(jnp.nanmean(at[:, :, idx] ** 2, axis=(0, 2)))
    pooled = jnp.where(jnp.any(diverged), jnp.inf, pooled)
    return SimulationError(
        horizons_s=jnp.asarray(horizons),
        rmse=pooled,
        rmse_per_state=per_state,
        states=tuple(states),
        state_names=tuple(names),
        n_windows=int(starts.shape[0]),
        diverged_fraction=jnp.mean(diverged.astype(errors.dtype)),
        errors=errors,
        starts=starts,
    )


def _sharded_window_errors(system, trajectory, starts, n_steps, method):
    """`_window_errors` with the windows split across every device (of every process), then gathered."""
    n_windows = starts.shape[0]
    n_devices = jax.device_count()
    if n_devices < 2:
        return _window_errors(system, trajectory.ts, trajectory.xs, trajectory.us, starts, n_steps, method)
    padded = -(-n_windows // n_devices) * n_devices
    host_starts = np.asarray(starts)
    host_starts = np.concatenate([host_starts, np.full(padded - n_windows, host_starts[-1])])
    sharded = _global_array(host_starts, _leading_sharding(padded))
    errors, diverged = _window_errors(system, trajectory.ts, trajectory.xs, trajectory.us, sharded, n_steps, method)
    errors, diverged = _replicate((errors, diverged))
    return errors[:n_windows], diverged[:n_windows]
