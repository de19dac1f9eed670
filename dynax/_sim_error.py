"""`simulation_error`: open-loop prediction error against horizon, started from many samples of a record."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from ._data._trajectory import Trajectory
from ._distributed import global_array, leading_sharding, replicate
from ._errors import DataError
from ._model._system import AbstractSystem
from ._simulate import FixedGrid, simulate
from ._solvers import RK4


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
    - `window_mse`: shape `(window, horizon)`, each window's squared error at each horizon, averaged
      over the `states` (NaN where the window diverged): what `rmse` pools, per window.
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
    window_mse: Float[Array, "window horizon"]

    def to_json(self) -> dict:
        """The contract's `sim_error` object: `{"horizons_s": [...], "rmse": [...]}`."""
        return {"horizons_s": [float(h) for h in self.horizons_s], "rmse": [float(r) for r in self.rmse]}


class InputStates(AbstractSystem):
    r"""The internal states of a model's input terms (a lag's output, a delay's filter) as a system of their own.

    $\dot z = g(z, u)$ from `Extended.applied_input`: driven by the recorded input alone, so they
    can be integrated along an input history with `simulate` before the measured states are known.
    """

    model: AbstractSystem

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(self.model.state_names[self.model.system.n_states :])

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(self.model.input_names)

    def vector_field(self, t, z, u):
        return self.model.applied_input(u, z)[1]


# The input-term states change slowly next to the sample rate (lags and delays of tens of
# milliseconds at 100 Hz and above); two RK4 steps per sample interval are far below noise. The
# "lax" scan keeps the whole rollout forward-mode differentiable.
HISTORY_GRID = FixedGrid(solver=RK4(scan_kind="lax"), substeps=2)


def complete_state(system, x_measured, u0, ts_before=None, us_before=None, history_method=HISTORY_GRID):
    """The model's full initial state from a measured one.

    Models with internal states (an input lag or delay, see `Extended`) complete it with
    `initial_state(x, u0)`: internal states at rest under the input in force. With an input history
    (`ts_before`, `us_before`: the samples up to and including the start), the internal states
    start at rest under its first input and are integrated along it (`simulate` on `InputStates`),
    so a window starts with the internal state the inputs before it imply. Otherwise internal
    states beyond the measured ones start at zero.
    """
    initial_state = getattr(system, "initial_state", None)
    if initial_state is None:
        return jnp.zeros(system.n_states, x_measured.dtype).at[: x_measured.shape[0]].set(x_measured)
    if ts_before is None or system.n_states == x_measured.shape[0]:
        return initial_state(x_measured, u0)
    n = x_measured.shape[0]
    z0 = initial_state(x_measured, us_before[0])[n:]
    z = simulate(InputStates(system), z0, ts_before, us_before, method=history_method, throw=False).xs[-1]
    return jnp.concatenate([x_measured, z.astype(x_measured.dtype)])


def window_rollout(
    system, ts, xs, us, ts_before=None, us_before=None, *, method=FixedGrid(), history_method=HISTORY_GRID
):
    """One open-loop rollout of `system` from the measured state `xs[0]` under the inputs `us`.

    **Arguments:** `ts (step,)`, `xs (step, n_measured)`, `us (step, m)` one window of a record;
    `ts_before`, `us_before` optionally the input history before it (ending at the window's start),
    which drives the internal states of input terms (see `complete_state`); `method` the
    integration strategy of `simulate`.

    **Returns:** `(errors, diverged)`: `system.state_error(simulated, measured)` for the measured
    states, shape `(step, n_measured)` (NaN past a divergence), and whether the rollout diverged.
    """
    n_measured = xs.shape[-1]
    x0 = complete_state(system, xs[0], us[0], ts_before, us_before, history_method)
    sim = simulate(system, x0, ts, us, method=method, throw=False)
    return system.state_error(sim.xs[:, :n_measured], xs), sim.diverged


def window_rollouts(
    system, ts, xs, us, ts_before=None, us_before=None, *, method=FixedGrid(), history_method=HISTORY_GRID
):
    """`window_rollout` on stacked windows (`ts (window, step)`, `xs (window, step, n)`, ...), one `vmap`.

    The one windowed rollout of dynax: `simulation_error` slices its windows from a record and
    calls it, `diagnose` fits and judges candidate models through it.

    **Returns:** `(errors (window, step, n_measured), diverged (window,))`.
    """
    if ts_before is None:
        one = lambda t, x, u: window_rollout(system, t, x, u, method=method)  # noqa: E731
        return jax.vmap(one)(ts, xs, us)
    one = lambda t, x, u, tb, ub: window_rollout(
        system,
        t,
        x,
        u,
        tb,
        ub,
        method=method,  # noqa: E731
        history_method=history_method,
    )
    return jax.vmap(one)(ts, xs, us, ts_before, us_before)


@eqx.filter_jit
def rollouts_from_starts(system, ts, xs, us, starts, n_steps, method):
    """`window_rollouts` on the windows of `n_steps` steps that start at the samples `starts` of one record."""

    def cut(a):
        return jax.vmap(lambda k: jax.lax.dynamic_slice_in_dim(a, k, n_steps + 1))(starts)

    return window_rollouts(system, cut(ts), cut(xs), cut(us), method=method)


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
        window_mse=jnp.mean(at[:, :, idx] ** 2, axis=2),
    )


def _sharded_window_errors(system, trajectory, starts, n_steps, method):
    """`rollouts_from_starts` with the windows split across every device (of every process), then gathered."""
    n_windows = starts.shape[0]
    n_devices = jax.device_count()
    if n_devices < 2:
        return rollouts_from_starts(system, trajectory.ts, trajectory.xs, trajectory.us, starts, n_steps, method)
    padded = -(-n_windows // n_devices) * n_devices
    host_starts = np.asarray(starts)
    host_starts = np.concatenate([host_starts, np.full(padded - n_windows, host_starts[-1])])
    sharded = global_array(host_starts, leading_sharding(padded))
    errors, diverged = rollouts_from_starts(
        system, trajectory.ts, trajectory.xs, trajectory.us, sharded, n_steps, method
    )
    errors, diverged = replicate((errors, diverged))
    return errors[:n_windows], diverged[:n_windows]
