"""`simulation_error`: open-loop prediction error against horizon, started from many samples of a record."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from .._data._trajectory import Trajectory
from .._distributed import global_array, leading_sharding, replicate
from .._errors import DataError, UsageError
from .._model._system import AbstractSystem
from ._simulate import FixedGrid, simulate
from ._solvers import RK4

HorizonValues = Float[Array | np.ndarray, " horizon"]
PerState = Float[Array | np.ndarray, "horizon n_states"]


def _cells(horizons_s, values) -> str:
    return ", ".join(f"{h:g} s: {float(v):.4g}" for h, v in zip(horizons_s, values))


class SimulationError(eqx.Module):
    r"""Open-loop prediction error against horizon: the one type for every such score in dynax.

    A model is rolled out from measured states under the recorded inputs and compared with the
    measurements a horizon later, from many start samples (windows). `simulation_error` returns
    one for a record, `held_out_error` for held-out records (what `identify` validates with),
    `flight_error` per state group for flight records, and `diagnose` one per model in its
    `Report` (the contract's `sim_error`). Fields a use does not fill are `None` (or empty).

    **Fields:**

    - `horizons_s`: the horizons [s].
    - `n_windows`: the number of start samples scored (over every record).
    - `diverged_fraction`: the fraction of them whose rollout diverged.
    - `rmse`: root-mean-square error at each horizon, pooled over the windows and the `states`
      (`inf` at a horizon where a window diverged); `None` where the columns have different
      units (a flight's state groups).
    - `states`: the state names `rmse` pools.
    - `state_names`: the names of the columns of `rmse_per_state` and `mae_per_state`: states,
      or a flight's state groups (`position`, `velocity`, `attitude`, `body_rate`).
    - `rmse_per_state`: shape `(horizon, n_states)`, per column.
    - `steps`, `dt`: the horizons in samples and the sample interval [s].

    One record (`simulation_error`):

    - `errors`: the raw errors, shape `(window, step, n_measured_states)` (simulated minus measured).
    - `starts`: the start indices of the windows.
    - `window_mse`: shape `(window, horizon)`, each window's squared error at each horizon, averaged
      over the `states` (NaN where the window diverged): what `rmse` pools, per window.

    Held-out records (`held_out_error`):

    - `source`: `"validation records"` or `"held-out end of each record (last X %)"`.
    - `rmse_per_record`: record name -> RMSE per horizon.
    - `diverged_per_record`: record name -> fraction of windows whose rollout diverged.
    - `median`: per horizon, the median over every window of every record of the window's
      root-mean-square error (a typical window, where `rmse` weighs the worst), over the windows
      that did not diverge.
    - `concentrated`: record name -> one entry per horizon at which the record's RMSE is more than
      `CONCENTRATED` times its median window error: `horizon_s`, `rmse`, `median`, `windows` (the
      fewest windows holding half of the squared error), `of` (the record's windows), `from_s`,
      `to_s` (the first and last of those windows' start times, in the record's time). Records
      whose RMSE no few windows carry are absent.

    Flights (`flight_error`, errors as sizes: the Euclidean norm of the position [m],
    world-velocity [m/s] and body-rate [rad/s] errors, the geodesic angle between the attitudes
    [rad]):

    - `mae_per_state`: shape `(horizon, group)`, the mean error size over start samples;
      `rmse_per_state` their root mean square (`inf` where a rollout diverged).
    - `cumulative_mae`: shape `(group,)`: the MAE averaged over every horizon $h = 1..\max$ steps.
    """

    horizons_s: tuple[float, ...] = eqx.field(static=True)
    n_windows: int = eqx.field(static=True)
    diverged_fraction: float = eqx.field(static=True)
    rmse: HorizonValues | None = None
    states: tuple[str, ...] = eqx.field(static=True, default=())
    state_names: tuple[str, ...] = eqx.field(static=True, default=())
    rmse_per_state: PerState | None = None
    steps: tuple[int, ...] | None = eqx.field(static=True, default=None)
    dt: float | None = eqx.field(static=True, default=None)
    errors: Float[Array, "window step n_states"] | None = None
    starts: Array | None = None
    window_mse: Float[Array, "window horizon"] | None = None
    source: str | None = eqx.field(static=True, default=None)
    rmse_per_record: dict[str, tuple[float, ...]] | None = eqx.field(static=True, default=None)
    diverged_per_record: dict[str, float] | None = eqx.field(static=True, default=None)
    median: HorizonValues | None = None
    concentrated: dict[str, list[dict]] = eqx.field(static=True, default_factory=dict)
    mae_per_state: PerState | None = None
    cumulative_mae: Float[Array | np.ndarray, " n_states"] | None = None

    def table(self, metric: str = "rmse") -> dict[str, list[float]]:
        """`{column: [value at each horizon]}` of `metric` (`rmse` or, for a flight, `mae`)."""
        values = {"mae": self.mae_per_state, "rmse": self.rmse_per_state}[metric]
        if values is None:
            raise ValueError(f"SimulationError.table: no per-state `{metric}` in this result")
        values = np.asarray(values)
        return {g: [float(v) for v in values[:, i]] for i, g in enumerate(self.state_names)}

    def note(self) -> str | None:
        """One sentence per record whose RMSE a few windows carry (`concentrated`); `None` if none."""
        if not self.concentrated:
            return None
        parts = []
        for name, entries in self.concentrated.items():
            cells = "; ".join(
                f"at {e['horizon_s']:g} s half of its squared error comes from {e['windows']} of "
                f"{e['of']} windows, starting {e['from_s']:.2f} to {e['to_s']:.2f} s (RMSE "
                f"{e['rmse']:.3g} against a median window error of {e['median']:.3g})"
                for e in entries
            )
            parts.append(f"{name}: {cells}")
        return (
            "the open-loop RMSE is carried by a few windows, which say more about those stretches "
            "(rest at an unstable equilibrium, a glitch in the data) than about the "
            "record: " + ". ".join(parts)
        )

    def summary(self, label: str = "", metrics: tuple[str, ...] = ("mae", "rmse")) -> str:
        """The error as lines of text for a person: the RMSE at each horizon (held-out records: on
        which data, the median window and each record; a flight: `metrics` per state group and the
        cumulative MAE). `label` names the model or stage."""
        if self.mae_per_state is not None and self.cumulative_mae is not None:
            steps = self.steps or ()
            lines = [
                f"{label + ': ' if label else ''}open-loop error over {self.n_windows} starts at h = "
                + " / ".join(str(s) for s in steps)
                + " steps"
                + (f" ({self.diverged_fraction:.1%} diverged)" if self.diverged_fraction else "")
            ]
            for metric in metrics:
                for i, (group, values) in enumerate(self.table(metric).items()):
                    row = "  ".join(f"{v:6.4f}" for v in values)
                    lines.append(f"  {metric} {group:>10s}  {row}   cum MAE {float(self.cumulative_mae[i]):.4f}")
            return "\n".join(lines)
        rmse = () if self.rmse is None else np.asarray(self.rmse)
        if self.source is None:
            pooled = f" of {', '.join(self.states)}" if self.states else ""
            return (
                f"open-loop RMSE{pooled}{' (' + label + ')' if label else ''}: {_cells(self.horizons_s, rmse)} "
                f"({self.n_windows} windows, {self.diverged_fraction:.0%} diverged)"
            )
        medians = "" if self.median is None else ", ".join(f"{float(m):.4g}" for m in self.median)
        lines = [
            f"open-loop RMSE on {self.source}{' (' + label + ')' if label else ''}: {_cells(self.horizons_s, rmse)}"
            + (f" (median window: {medians})" if medians else "")
        ]
        if self.rmse_per_record is not None and len(self.rmse_per_record) > 1:
            lines += [f"  {name}: {_cells(self.horizons_s, r)}" for name, r in self.rmse_per_record.items()]
        return "\n".join(lines)

    def to_json(self, *, null_diverged: bool = False) -> dict:
        """The contract's `sim_error` object, `{"horizons_s": [...], "rmse": [...]}`; held-out records add
        `per_record`, `diverged_fraction` (per record), `source`, `median` and `concentrated`; a flight's
        scores (`flight_error`, whose `rmse` is empty) add `steps` and the `scores` per state group.
        `null_diverged` writes a non-finite RMSE as `null` (the diagnosis report's `sim_error`)."""
        rmse = [] if self.rmse is None else [float(r) for r in np.asarray(self.rmse)]
        if null_diverged:
            rmse = [r if np.isfinite(r) else None for r in rmse]
        out: dict = {"horizons_s": list(self.horizons_s), "rmse": rmse}
        if self.mae_per_state is not None:
            out.update(steps=list(self.steps or ()), scores=self.scores())
        if self.source is not None:
            out.update(
                per_record={k: list(v) for k, v in (self.rmse_per_record or {}).items()},
                diverged_fraction=self.diverged_per_record,
                source=self.source,
                median=[] if self.median is None else [float(m) for m in np.asarray(self.median)],
                concentrated=self.concentrated,
            )
        return out

    def scores(self, metrics: tuple[str, ...] = ("mae", "rmse")) -> dict:
        """A flight's scores as JSON: `metrics` per state group, `cumulative_mae`, `n_starts`, and
        `diverged_fraction` where a rollout diverged (`dynax evaluate`'s `model` object)."""
        out: dict = {m: self.table(m) for m in metrics}
        cumulative = [] if self.cumulative_mae is None else np.asarray(self.cumulative_mae)
        out["cumulative_mae"] = {g: float(v) for g, v in zip(self.state_names, cumulative)}
        out["n_starts"] = self.n_windows
        if self.diverged_fraction:
            out["diverged_fraction"] = self.diverged_fraction
        return out


def nominal_states(model) -> int:
    """How many of a model's states are nominal (measured), the rest internal: what a wrapper names
    (`nominal_n_states`: `refine_by_simulation`'s `ConsistentSystem` and `TimedInputs`), an `Extended`'s system's,
    else all of a plain system's."""
    n = getattr(model, "nominal_n_states", None)
    if n is not None:
        return n
    inner = getattr(model, "system", None)
    return model.n_states if inner is None else inner.n_states


class InputStates(AbstractSystem):
    r"""The internal states of a model's input terms (a lag's output, a delay's filter) as a system of their own.

    $\dot z = g(z, u)$ from `Extended.applied_input`: driven by the recorded input alone, so they
    can be integrated along an input history with `simulate` before the measured states are known.
    """

    model: AbstractSystem

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(self.model.state_names[nominal_states(self.model) :])

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(self.model.input_names)

    def vector_field(self, t, z, u):
        return self.model.applied_input(u, z)[1]


class AlongStates(InputStates):
    r"""A model's internal states as a system of their own (named as `InputStates` names them), the nominal states
    read from a record (`xs` at `ts`, linear between samples): $\dot z$ of `Extended.vector_field` there.

    Every internal state moves, the input terms' with the recorded input and every other term's
    (`AbstractTerm.hidden_vector_field`, e.g. a lagged speed) with the measured states: the diagnosis's one-step
    residuals integrate them along a record, and its windowed rollouts along the measured states before each
    window (`complete_state`'s `xs_before`).
    """

    ts: Float[Array, " time"]
    xs: Float[Array, "time n_measured"]

    def vector_field(self, t, z, u):
        x = jax.vmap(lambda column: jnp.interp(t, self.ts, column), in_axes=1)(self.xs)
        return self.model.vector_field(t, jnp.concatenate([x, z]), u)[self.xs.shape[1] :]


# The input-term states change slowly next to the sample rate (lags and delays of tens of
# milliseconds at 100 Hz and above); two RK4 steps per sample interval are far below noise. The
# "lax" scan keeps the whole rollout forward-mode differentiable.
HISTORY_GRID = FixedGrid(solver=RK4(scan_kind="lax"), substeps=2)


def complete_state(system, x_measured, u0, ts_before=None, us_before=None, history_method=HISTORY_GRID, xs_before=None):
    """The model's full initial state from a measured one.

    Models with internal states (an input lag or delay, see `Extended`) complete it with
    `initial_state(x, u0)`: internal states at rest under the input in force. With an input history
    (`ts_before`, `us_before`: the samples up to and including the start), the internal states
    start at rest under its first input and are integrated along it (`simulate` on `InputStates`),
    so a window starts with the internal state the inputs before it imply. Otherwise internal
    states beyond the measured ones start at zero. A model with no states beyond the measured ones
    starts from the measured state as it is.

    A term's states that are not an input's (`Extended.state_terms`, e.g. a damping on a lagged speed) move with
    the nominal states, not the input alone. With the measured states of the history too (`xs_before`, at
    `ts_before`), every internal state starts at the history's first sample as `initial_state` puts it there and
    is integrated along the measured states and inputs (`simulate` on `AlongStates`): a window starts with the lag
    the record implies, not at rest at its first state. Such states forget their start over the history (a lag
    over its time constant, `Stiction`'s memory of rest over its dwell time or a slip); without `xs_before` they
    start at `AbstractTerm.initial_hidden` of `x_measured`.
    """
    if system.n_states == x_measured.shape[0]:
        return x_measured
    initial_state = getattr(system, "initial_state", None)
    if initial_state is None:
        return jnp.zeros(system.n_states, x_measured.dtype).at[: x_measured.shape[0]].set(x_measured)
    if ts_before is None:
        return initial_state(x_measured, u0)
    assert us_before is not None, "complete_state: `ts_before` without `us_before`"
    n = x_measured.shape[0]
    if xs_before is not None and getattr(system, "state_terms", ()):
        z0 = initial_state(xs_before[0], us_before[0])[n:]
        along = AlongStates(system, ts_before, xs_before)  # pyright: ignore[reportCallIssue]
        z = simulate(along, z0, ts_before, us_before, method=history_method, throw=False).xs[-1]
        return jnp.concatenate([x_measured, z.astype(x_measured.dtype)])
    z0 = initial_state(x_measured, us_before[0])[n:]
    z = simulate(InputStates(system), z0, ts_before, us_before, method=history_method, throw=False).xs[-1]
    return jnp.concatenate([x_measured, z.astype(x_measured.dtype)])


def window_rollout(
    system,
    ts,
    xs,
    us,
    ts_before=None,
    us_before=None,
    xs_before=None,
    *,
    method=FixedGrid(),
):
    """One open-loop rollout of `system` from the measured state `xs[0]` under the inputs `us`.

    **Arguments:** `ts (step,)`, `xs (step, n_measured)`, `us (step, m)` one window of a record;
    `ts_before`, `us_before` optionally the input history before it (ending at the window's start),
    which drives the internal states of input terms (see `complete_state`) and lets a dead time
    (`InputDelay`) act exactly, as the recorded input shifted in time (`Extended.with_shifted_inputs`),
    instead of through its Padé filter; `xs_before` optionally the measured states there too, along which
    the states of the other terms with states are integrated (`complete_state`, on `HISTORY_GRID`); `method`
    the integration strategy of `simulate`.

    **Returns:** `(errors, diverged)`: `system.state_error(simulated, measured)` for the measured
    states, shape `(step, n_measured)` (NaN past a divergence), and whether the rollout diverged.
    """
    n_measured = xs.shape[-1]
    if us_before is not None and hasattr(system, "with_shifted_inputs"):
        # A dead time shifts the recorded inputs exactly, its history included (`Extended.with_shifted_inputs`).
        n_before = us_before.shape[0]
        dt = (ts[-1] - ts[0]) / (ts.shape[0] - 1)
        system, shifted = system.with_shifted_inputs(jnp.concatenate([us_before[:-1], us]), dt)
        us_before, us = shifted[:n_before], shifted[n_before - 1 :]
    x0 = complete_state(system, xs[0], us[0], ts_before, us_before, HISTORY_GRID, xs_before)
    sim = simulate(system, x0, ts, us, method=method, throw=False)
    return system.state_error(sim.xs[:, :n_measured], xs), sim.diverged


def window_rollouts(
    system,
    ts,
    xs,
    us,
    ts_before=None,
    us_before=None,
    xs_before=None,
    *,
    method=FixedGrid(),
):
    """`window_rollout` on stacked windows (`ts (window, step)`, `xs (window, step, n)`, ...), one `vmap`.

    The one windowed rollout of dynax: `simulation_error` slices its windows from a record and
    calls it, `diagnose` fits and judges candidate models through it. `xs_before (window, before, n)`
    is read only by a model whose terms have states of their own besides the input terms' (`complete_state`).

    **Returns:** `(errors (window, step, n_measured), diverged (window,))`.
    """
    if ts_before is None:
        one = lambda t, x, u: window_rollout(system, t, x, u, method=method)  # noqa: E731
        return jax.vmap(one)(ts, xs, us)
    if xs_before is not None and getattr(system, "state_terms", ()):
        along = lambda t, x, u, tb, ub, xb: window_rollout(system, t, x, u, tb, ub, xb, method=method)  # noqa: E731
        return jax.vmap(along)(ts, xs, us, ts_before, us_before, xs_before)
    one = lambda t, x, u, tb, ub: window_rollout(system, t, x, u, tb, ub, method=method)  # noqa: E731
    return jax.vmap(one)(ts, xs, us, ts_before, us_before)


# The history [s] before each window along which `simulation_error` starts a model's internal states, as the
# diagnosis's windows have it (`make_windows`): a lag forgets all but exp(-0.5 / tau) of the history's start.
HISTORY_S = 0.5


def history_steps(system, n_measured: int, dt: float) -> int:
    """The samples of history `simulation_error` gives each window: `HISTORY_S` of them for a model with internal
    states that `complete_state` can integrate along a record (an `Extended` with a lag, a delay or a term's own
    states), else 0 (the model starts from the measured state as before: the same compiled program)."""
    if system.n_states == n_measured or not hasattr(system, "applied_input"):
        return 0
    return max(1, int(round(HISTORY_S / dt)))


def with_history(ts, xs, us, n_before: int, dt: float):
    """`ts, xs, us` of a record (numpy) with `n_before` samples put before its start: the first state and input
    repeated, at `dt` before its first time (as `make_windows` pads a window's history)."""
    ts, xs, us = np.asarray(ts), np.asarray(xs), np.asarray(us)
    if n_before == 0:
        return ts, xs, us
    first = lambda a: np.repeat(a[:1], n_before, axis=0)  # noqa: E731
    before = ts[0] + dt * np.arange(-n_before, 0, dtype=ts.dtype)
    return np.concatenate([before, ts]), np.concatenate([first(xs), xs]), np.concatenate([first(us), us])


@eqx.filter_jit
def rollouts_from_starts(system, ts, xs, us, starts, n_steps, method, n_before: int = 0):
    """`window_rollouts` on the windows of `n_steps` steps that start at the samples `starts` of one record.

    With `n_before` > 0 the record's arrays carry `n_before` samples of history before its first sample
    (`with_history`) and `starts` count from the record's own first sample: each window gets the `n_before`
    samples before it as `ts_before`, `us_before` and `xs_before` (`window_rollouts`), along which the model's
    internal states start (`complete_state`)."""

    def cut(a, n=n_steps + 1, offset=0):
        return jax.vmap(lambda k: jax.lax.dynamic_slice_in_dim(a, k + offset, n))(starts)

    if n_before == 0:
        return window_rollouts(system, cut(ts), cut(xs), cut(us), method=method)
    window = lambda a: cut(a, offset=n_before)  # noqa: E731
    before = lambda a: cut(a, n_before + 1)  # noqa: E731  # the history ends at the window's first sample
    return window_rollouts(
        system, window(ts), window(xs), window(us), before(ts), before(us), before(xs), method=method
    )


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

    - `system`: the model. Internal states beyond the measured ones (an input lag or delay, a term's
      own states such as a lagged speed or `Stiction`'s memory of rest) start where the record puts
      them: at rest under the input `HISTORY_S` (0.5 s) before the window (`Extended.initial_state`, the
      record's first sample repeated before its start) and integrated along the recorded inputs and
      measured states up to the window's start (`complete_state` with `xs_before`), as the diagnosis's
      windows start them; a dead time shifts the recorded input exactly (`Extended.with_shifted_inputs`).
      A model without internal states starts from the measured state (no history is cut: the same
      compiled program as before); a system with internal states but no `applied_input` (not an
      `Extended`) starts them as its `initial_state` completes the measured state.
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
    horizons, steps, n_starts, stride = _starts(system, trajectory, horizons_s, stride, max_windows)
    dt = trajectory.dt
    starts = jnp.arange(0, n_starts, stride)
    errors, diverged = _sharded_window_errors(system, trajectory, starts, int(steps.max()), method)
    at = errors[:, steps, :]  # (window, horizon, state)
    if states is None:
        states = tuple(s for s in names if not s.startswith("d"))
    idx = jnp.array([names.index(s) for s in states])
    per_state = jnp.sqrt(jnp.nanmean(at**2, axis=0))
    pooled = jnp.sqrt(jnp.nanmean(at[:, :, idx] ** 2, axis=(0, 2)))
    pooled = jnp.where(jnp.any(diverged), jnp.inf, pooled)
    return SimulationError(
        horizons_s=tuple(float(h) for h in horizons),
        n_windows=int(starts.shape[0]),
        diverged_fraction=float(jnp.mean(diverged.astype(errors.dtype))),
        rmse=pooled,
        states=tuple(states),
        state_names=tuple(names),
        rmse_per_state=per_state,
        steps=tuple(int(k) for k in steps),
        dt=float(dt),
        errors=errors,
        starts=starts,
        window_mse=jnp.mean(at[:, :, idx] ** 2, axis=2),
    )


def _starts(system, trajectory, horizons_s, stride, max_windows):
    """`simulation_error`'s windows: `(horizons, steps, n_starts, stride)`, the record checked against them."""
    names = trajectory.state_names
    if tuple(system.state_names[: len(names)]) != tuple(names):
        raise UsageError(
            f"simulation_error: the trajectory's states {names} are not the first states of "
            f"{type(system).__name__} {system.state_names}"
        )
    try:
        horizons = np.asarray(horizons_s, dtype=float)
    except (TypeError, ValueError):
        horizons = np.asarray([np.nan])
    if horizons.ndim != 1 or horizons.size == 0 or not np.all(np.isfinite(horizons)) or np.any(horizons <= 0):
        raise UsageError(
            "simulation_error: `horizons_s` must be a non-empty sequence of positive, finite seconds, "
            f"got {horizons_s!r}"
        )
    if stride is not None and (isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or stride < 1):
        raise UsageError(f"simulation_error: `stride` must be a positive whole number of samples, got {stride!r}")
    stride = None if stride is None else int(stride)
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
    return horizons, steps, n_starts, stride


def window_simulation_errors(
    system: AbstractSystem,
    trajectory: Trajectory,
    horizons_s=(0.5, 1.0, 2.0),
    *,
    stride: int | None = None,
    max_windows: int = 200,
    method=FixedGrid(),
) -> Float[Array, "window step n_measured"]:
    """`simulation_error(...).errors` alone: the windows' simulated-minus-measured states, the same rollouts
    (the same compiled program), without the summaries over windows, each an operation compiled for its shape."""
    _, steps, n_starts, stride = _starts(system, trajectory, horizons_s, stride, max_windows)
    starts = np.arange(0, n_starts, stride)
    return _sharded_window_errors(system, trajectory, starts, int(steps.max()), method)[0]


def _sharded_window_errors(system, trajectory, starts, n_steps, method):
    """`rollouts_from_starts` with the windows split across every device (of every process), then gathered.

    A model with internal states (`history_steps`) gets `HISTORY_S` of the record before each window (the first
    sample repeated before the record's start), along which they start."""
    n_windows = starts.shape[0]
    n_devices = jax.device_count()
    n_before = history_steps(system, len(trajectory.state_names), float(trajectory.dt))
    ts, xs, us = trajectory.ts, trajectory.xs, trajectory.us
    if n_before:
        ts, xs, us = (jax.device_put(a) for a in with_history(ts, xs, us, n_before, float(trajectory.dt)))
    if n_devices < 2:
        return rollouts_from_starts(system, ts, xs, us, starts, n_steps, method, n_before)
    padded = -(-n_windows // n_devices) * n_devices
    host_starts = np.asarray(starts)
    host_starts = np.concatenate([host_starts, np.full(padded - n_windows, host_starts[-1])])
    sharded = global_array(host_starts, leading_sharding(padded))
    errors, diverged = rollouts_from_starts(system, ts, xs, us, sharded, n_steps, method, n_before)
    errors, diverged = replicate((errors, diverged))
    return errors[:n_windows], diverged[:n_windows]
