r"""`identify(system, data, method=...)`: fit a system's parameters to measured trajectories.

Three linear-in-parameter least-squares models and one output-error fit:

- `Dynamic()`: the inverse-dynamics model $Y(q, \dot q, \ddot q)\,\theta = B u$, both joints' rows
  stacked (never summed); needs $\ddot q$, by central differences of (optionally low-passed)
  velocities.
- `Power()`: the power model $\dot q^\top B u = \frac{d}{dt} H + \dot q^\top F(\dot q)$; no $\ddot q$.
- `Energy()`: the energy model $\int_{t_a}^{t_b} \dot q^\top B u\,dt = H(t_b) - H(t_a) +
  \int_{t_a}^{t_b} \dot q^\top F\,dt$ over windows, by the trapezoid rule; no $\ddot q$.
- `SimulationFit()`: minimise the simulation (output) error through `dynax.simulate`.
"""

import warnings
from collections.abc import Sequence
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._precision import warn_if_float32
from .._data._derivatives import butterworth_filtfilt, central_difference, resample
from .._data._trajectory import Trajectory
from .._errors import DataError, UsageError
from .._fit import Parameters, Solution
from .._simulate import FixedGrid
from .._model._linear_axis import LinearAxis
from .._model._extensions import Extended
from .._model._system import AbstractSystem
from .._model._two_link import Acrobot, DoublePendulum
from ._consistency import (
    check_consistency,
    Consistency,
    consistent_least_squares,
    InconsistentEstimateWarning,
)
from ._defaults import choose_filter, trim_and_decimation
from ._refine import refine_by_simulation
from ._validation import DEFAULT_HORIZONS_S, held_out_error, HeldOutError, split_for_validation
from ._least_squares import least_squares, LeastSquaresFit
from ._offsets import record_labels, record_offsets, RecordOffsets
from ._simulation_fit import fit_simulation_error, SimulationFit
from ._regressors import (
    _positions,
    _split,
    column_kinds,
    dynamic_regressor,
    energy_and_friction_rows,
    Friction,
    generalised_force,
    parameter_names,
    parameter_vector,
    row_dot,
    with_friction,
    with_parameters,
)

_SYSTEM_NAMES = {Acrobot: "acrobot", DoublePendulum: "double_pendulum", LinearAxis: "linear_axis"}


def _uniform(trajectory: Trajectory) -> Trajectory:
    """The record itself if uniformly sampled, else resampled at its median interval."""
    return trajectory if trajectory.is_uniform else resample(trajectory, trajectory.dt)


def _lowpass(trajectory, ys, cutoff_hz, order):
    return butterworth_filtfilt(trajectory.ts, ys, cutoff_hz=cutoff_hz, order=order)


class Dynamic(eqx.Module):
    r"""The inverse-dynamics (dynamic) least-squares model.

    Accelerations are central differences of the velocities, after a zero-phase Butterworth
    low-pass of the states (and of the inputs, with `lowpass_inputs`). Rows near the ends, where
    the filter and the differences are one-sided, are dropped (`trim`), and the rows can be
    decimated. Records that are sampled irregularly are resampled at their median interval before
    filtering (central differences alone work on the recorded grid).

    Every setting defaults to `"auto"`: chosen per record from the spectra of its velocities
    (noise floor and signal band, see `choose_filter`), and reported in
    `Identification.settings`. An explicit value overrides the choice; `lowpass_hz=None` means no
    filter. With an explicit cut-off (your own recipe) the settings left at `"auto"` take their
    classic values: order 4, inputs not filtered, `trim=1`, no decimation.

    **Arguments:**

    - `lowpass_hz`: cut-off of the zero-phase Butterworth filter [Hz], `None` (no filter) or
      `"auto"` (the velocities' signal band).
    - `lowpass_order`: order of one filter pass, or `"auto"` (the smallest order that keeps the
      differentiated noise above the cut-off under 10 % of that inside the band: 4).
    - `lowpass_inputs`: also filter the inputs (parallel filtering); `"auto"`: whenever the states
      are filtered, so that both sides of the model see the same filter.
    - `trim`: samples dropped at each end; `"auto"`: one cut-off period (1 without a filter).
    - `decimate`: parallel decimation of the equations by this factor: every column of the regressor
      and the target pass the same zero-phase anti-aliasing filter (`scipy.signal.decimate`), then
      every `decimate`-th row is kept. The filter acts on both sides of the linear model alike, so it
      removes noise without biasing the estimate. `"auto"`: to a Nyquist frequency of twice the
      cut-off (at most 13; 1 without a filter).
    - `inputs`: how an input sample pairs with the acceleration at that sample. `"held"` (default)
      treats the inputs as the zero-order hold the contract says they are: a central difference at
      $t_k$ spans the intervals held at `us[k-1]` and `us[k]`, so their weighted mean is used
      (pairing with `us[k]` alone leaves an $O(h)$ bias). `"sampled"` pairs `us[k]` as is: right
      for a measured force or torque sampled at $t_k$ (the EMPS reference model does this; on EMPS
      the half-sample shift between the two moves $F_v$ by 2 %).
    - `weighting`: `"none"` (ordinary least squares) or `"joint"`: weight each joint's equations
      by the inverse of its residual variance from a first ordinary fit (Gautier's weighted least
      squares; joints with noisier torque count less).

    ??? cite

        M. Gautier, "Dynamic identification of robots with power model", Proc. IEEE ICRA 1997
        (the filtering and decimation recipe, and weighted least squares); A. Janot, M. Gautier
        and M. Brunot, "Data set and reference models of EMPS", Nonlinear System Identification
        Benchmarks workshop, 2019.
    """

    lowpass_hz: float | None | Literal["auto"] = "auto"
    lowpass_order: int | Literal["auto"] = "auto"
    lowpass_inputs: bool | Literal["auto"] = "auto"
    trim: int | Literal["auto"] = "auto"
    decimate: int | Literal["auto"] = "auto"
    inputs: Literal["held", "sampled"] = "held"
    weighting: Literal["none", "joint"] = "none"


class Power(eqx.Module):
    r"""The power least-squares model (Gautier 1997): $\dot q^\top B u = \dot H + \dot q^\top F(\dot q)$.

    Each sample gives one equation. $\dot H = \dot w\,\theta$ is the central difference of the
    energy regressor columns; no acceleration is needed. With `lowpass_hz` every column of the
    regressor and the target are filtered by the same zero-phase Butterworth filter before the
    difference (parallel filtering: the model stays exact, the noise is cut).

    **Arguments:** `lowpass_hz` (or `None`), `lowpass_order` (default 4), `trim` (samples dropped
    at each end, default 1), `decimate` (parallel decimation as in `Dynamic`, default 1).

    ??? cite

        M. Gautier, "Dynamic identification of robots with power model", Proc. IEEE ICRA 1997.
    """

    lowpass_hz: float | None = None
    lowpass_order: int = 4
    trim: int = 1
    decimate: int = 1


class Energy(eqx.Module):
    r"""The energy least-squares model (Gautier and Khalil 1988), one equation per window.

    Over a window $[t_a, t_b]$: $\int \dot q^\top B u\,dt = (w(t_b) - w(t_a))\,\theta +
    \int \dot q^\top F\,dt$. Integrals use the trapezoid rule on the recorded grid, with the input
    held over each interval (zero-order hold), so irregular sampling is handled exactly as
    recorded. No acceleration is needed.

    **Arguments:**

    - `window`: samples per window (default 10).
    - `stride`: samples between window starts (default `window`: consecutive windows).
    - `lowpass_hz`, `lowpass_order`: optional zero-phase filter of the states first.

    ??? cite

        M. Gautier and W. Khalil, "On the identification of the inertial parameters of robots",
        Proc. 27th IEEE CDC, 1988; M. Gautier, "Dynamic identification of robots with power
        model", Proc. IEEE ICRA 1997 (comparison of the energy, power and dynamic models).
    """

    window: int = 10
    stride: int | None = None
    lowpass_hz: float | None = None
    lowpass_order: int = 4

    def __check_init__(self):
        if self.window < 1:
            raise ValueError(f"Energy: `window` must be at least 1 sample, got {self.window}")
        if self.stride is not None and self.stride < 1:
            raise ValueError(f"Energy: `stride` must be at least 1, got {self.stride}")


class Identification(eqx.Module):
    r"""The result of `identify`.

    **Fields:**

    - `system`: the system with the fitted parameters (for two-link arms with
      `friction="coulomb"`, `Extended` with `CoulombFriction` at both joints; after the output-error
      refinement also with `RotorInertia` at the elbow).
    - `estimate`, `std_errors`: parameter values and standard errors, in the order of `names`.
    - `names`: parameter names (the contract's; `Ir2` for the elbow's rotor inertia).
    - `condition_number`: of the column-scaled regressor (least-squares methods) or of the
      Jacobian at the solution (`SimulationFit`).
    - `rank`: numerical rank.
    - `n_samples`: samples that entered the fit.
    - `residual_rms`: root-mean-square residual of the fitted equations.
    - `relative_error`: $\lVert A\hat\theta - y\rVert / \lVert y\rVert$ of the (unweighted)
      equations: for `Dynamic` the relative force/torque error (EMPS reports 4.08 %); for
      `SimulationFit` the relative simulation error of the states.
    - `method`, `friction`, `system_name`: as in the contract's output.
    - `fit`: the `LeastSquaresFit` (least-squares methods) or `None`.
    - `settings`: per record, the filter and derivative settings used and why (`Dynamic`).
    - `consistency`: the `Consistency` of the returned estimate: violated conditions, and which
      the constrained fit had to enforce.
    - `validation`: the `HeldOutError` of the returned model (open-loop simulation error against
      horizon on held-out data), or `None` when nothing could be held out.
    - `stages`: per stage (`"least_squares"`, and `"output_error"` after a refinement), its
      parameters, equation error and held-out simulation error, as a JSON-ready dict.
    - `solution`: for the iterative method (`SimulationFit`), the engine's `Solution` this result
      is built from (the same names, estimate, standard errors and covariance, plus the result
      code, steps and losses); `None` for the least-squares methods, whose `fit` holds the same.
    - `record_offsets`: for `Dynamic` on two records or more, each record's constant offset on each
      joint's recorded force (from each half of the record too) and whether they differ between
      records (`RecordOffsets`, see `dynax._identify._offsets`): a sensor zero that changes from one
      recording to the next, which no model term carries; `None` otherwise.

    **Properties** in `Solution`'s spelling: `value` (= `estimate`), `covariance`; and
    `parameters` / `standard_errors` as `{name: value}` (`Solution.estimates()` /
    `Solution.standard_errors()`).
    """

    system: AbstractSystem
    estimate: Float[Array, " n_params"]
    std_errors: Float[Array, " n_params"]
    condition_number: Float[Array, ""]
    rank: Array
    residual_rms: Float[Array, ""]
    relative_error: Float[Array, ""]
    fit: LeastSquaresFit | None
    names: tuple[str, ...] = eqx.field(static=True)
    n_samples: int = eqx.field(static=True)
    method: str = eqx.field(static=True)
    friction: str = eqx.field(static=True)
    system_name: str = eqx.field(static=True)
    settings: tuple = ()
    consistency: Consistency | None = None
    validation: HeldOutError | None = None
    stages: dict | None = None
    solution: Solution | None = None
    record_offsets: RecordOffsets | None = None

    @property
    def value(self) -> Float[Array, " n_params"]:
        """The estimate (`Solution`'s name for it)."""
        return self.estimate

    @property
    def covariance(self) -> Float[Array, "n_params n_params"] | None:
        """The estimate's covariance, from the solution (iterative) or the least-squares fit; `None`
        where neither applies (after the output-error refinement, whose stage reports standard errors)."""
        if self.solution is not None:
            return self.solution.covariance
        if self.fit is not None and self.fit.covariance.shape[0] == self.estimate.shape[0] and "simulation" not in self.method:
            return self.fit.covariance
        return None

    @property
    def parameters(self) -> dict[str, float]:
        """Parameter name -> value."""
        return {n: float(v) for n, v in zip(self.names, np.asarray(self.estimate))}

    @property
    def standard_errors(self) -> dict[str, float]:
        """Parameter name -> standard error."""
        return {n: float(v) for n, v in zip(self.names, np.asarray(self.std_errors))}

    def to_json(self) -> dict:
        """The contract's `identify` output object, extended with `settings`, `consistency`,
        `validation`, `stages` and `record_offsets` where they apply."""
        out = {
            "system": self.system_name,
            "method": self.method,
            "friction": self.friction,
            "parameters": self.parameters,
            "std_errors": self.standard_errors,
            "condition_number": float(self.condition_number),
            "n_samples": int(self.n_samples),
            "relative_error": float(self.relative_error),
        }
        if self.settings:
            out["settings"] = [_jsonable(s) for s in self.settings]
        if self.consistency is not None:
            out["consistency"] = self.consistency.to_json()
        out["validation"] = None if self.validation is None else self.validation.to_json()
        if self.stages:
            out["stages"] = self.stages
        if self.record_offsets is not None:
            out["record_offsets"] = self.record_offsets.to_json()
        return out


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, np.integer)) or (hasattr(value, "shape") and np.shape(value) == ()):
        return float(value)
    return value


def _as_list(data) -> list[Trajectory]:
    if isinstance(data, Trajectory):
        return [data]
    if isinstance(data, Sequence) and data and all(isinstance(d, Trajectory) for d in data):
        return list(data)
    raise UsageError(f"identify: `data` must be a Trajectory or a non-empty list of Trajectory, got {type(data).__name__}")


def _check_data(system, trajectories):
    for k, traj in enumerate(trajectories):
        if traj.xs.shape[1] != system.n_states or traj.us.shape[1] != system.n_inputs:
            raise UsageError(
                f"identify: trajectory {k} has {traj.xs.shape[1]} states and {traj.us.shape[1]} inputs "
                f"({traj.state_names}, {traj.input_names}) but {type(system).__name__} has "
                f"{system.state_names} and {system.input_names}"
            )


def _needs(traj, n, method):
    if len(traj) < n:
        raise DataError(
            f"{len(traj)} samples are too few for the {method} model (it needs at least {n})",
            path=traj.source or None,
        )


def _trim_and_decimate(rows, target, trim, decimate):
    import scipy.signal  # lazily: keeps `import dynax` light

    """Drop `trim` rows at each end, then decimate rows and target alike (parallel filtering)."""
    if trim < 0 or decimate < 1:
        raise UsageError(f"`trim` must be >= 0 and `decimate` >= 1, got {trim}, {decimate}")
    n = rows.shape[0]
    rows, target = rows[trim : n - trim], target[trim : n - trim]
    if decimate > 1:
        if rows.shape[0] <= 27 * decimate:
            raise DataError(f"{rows.shape[0]} rows are too few to decimate by {decimate}")
        rows = jnp.asarray(scipy.signal.decimate(np.asarray(rows), decimate, axis=0, zero_phase=True))
        target = jnp.asarray(scipy.signal.decimate(np.asarray(target), decimate, axis=0, zero_phase=True))
    return rows, target


def _held_input_at_samples(ts, us):
    r"""The input that central differences "see" at each sample under the zero-order hold.

    The central difference at $t_k$ is $(h_2 s_1 + h_1 s_2)/(h_1 + h_2)$, a weighted mean of the
    slopes over $[t_{k-1}, t_k]$ (input `us[k-1]`) and $[t_k, t_{k+1}]$ (input `us[k]`). Pairing it
    with `us[k]` alone would leave an $O(h)$ bias wherever the input moves; the same weighted mean of
    the held inputs keeps the model consistent to $O(h^2)$.
    """
    h1 = (ts[1:-1] - ts[:-2])[:, None]
    h2 = (ts[2:] - ts[1:-1])[:, None]
    interior = (h2 * us[:-2] + h1 * us[1:-1]) / (h1 + h2)
    return jnp.concatenate([us[:1], interior, us[-1:]])


def _dynamic_equations(system, ts, xs, us, friction, held):
    """Regressor `(time, joints, params)` and generalised forces `(time, joints)` of the dynamic model.

    The regressor is its own compiled call: fused into one program with the differences, XLA's CPU
    backend re-evaluates the vmapped Jacobian for each neighbouring slice and runs several times
    slower than the two calls.
    """
    ddq, forces = _accelerations_and_forces(system, ts, xs, us, held)
    return dynamic_regressor(system, xs, ddq, friction), forces


@eqx.filter_jit
def _accelerations_and_forces(system, ts, xs, us, held):
    if held:
        us = _held_input_at_samples(ts, us)
    _, dq = _positions(system, xs)
    return central_difference(ts, dq), generalised_force(system, us)


def _resolve_dynamic(traj, method: Dynamic) -> dict:
    """The settings used on one record: explicit ones as given, `"auto"` ones from its spectra."""
    fields = ("lowpass_hz", "lowpass_order", "lowpass_inputs", "trim", "decimate")
    auto = [f for f in fields if isinstance(getattr(method, f), str) and getattr(method, f) == "auto"]
    settings = {f: getattr(method, f) for f in fields}
    reason = "explicit settings"
    if auto and settings["lowpass_hz"] != "auto":
        # An explicit cut-off is the user's recipe: the rest keeps the classic values.
        classic = {"lowpass_order": 4, "lowpass_inputs": False, "trim": 1, "decimate": 1}
        settings.update({f: classic[f] for f in auto})
        reason = f"explicit cut-off; {', '.join(auto)} at their classic values"
        auto = []
    elif auto:
        uniform = _uniform(traj)
        choice = choose_filter(uniform)
        settings["lowpass_hz"] = cutoff = choice.cutoff_hz
        if settings["lowpass_order"] == "auto":
            settings["lowpass_order"] = choice.order
        if settings["lowpass_inputs"] == "auto":
            settings["lowpass_inputs"] = cutoff is not None
        if cutoff is None:
            trim, decimate = 1, 1
        else:
            trim, decimate = trim_and_decimation(1.0 / uniform.dt, cutoff, len(uniform))
        if settings["trim"] == "auto":
            settings["trim"] = trim
        if settings["decimate"] == "auto":
            settings["decimate"] = decimate
        reason = choice.reason if len(auto) == len(fields) else f"{', '.join(auto)} from the spectra: {choice.reason}"
        settings["noise_std"] = choice.noise_std
        settings["band_hz"] = choice.band_hz
    if settings["lowpass_hz"] is not None and not settings["lowpass_hz"] > 0:
        raise UsageError(f"Dynamic: `lowpass_hz` must be a positive frequency, None or 'auto', got {settings['lowpass_hz']!r}")
    settings["record"] = traj.source or None
    settings["chosen_from_data"] = auto
    settings["reason"] = reason
    return settings


def _dynamic_rows(system, traj, method: Dynamic, friction):
    settings = _resolve_dynamic(traj, method)
    cutoff, order, trim = settings["lowpass_hz"], settings["lowpass_order"], settings["trim"]
    _needs(traj, 2 * trim + 3, "dynamic")
    if cutoff is not None:
        traj = _uniform(traj)
        xs = _lowpass(traj, traj.xs, cutoff, order)
    else:
        xs = traj.xs
    if method.inputs not in ("held", "sampled"):
        raise UsageError(f"Dynamic: `inputs` must be 'held' or 'sampled', got {method.inputs!r}")
    us = traj.us
    if cutoff is not None and settings["lowpass_inputs"]:
        if method.inputs == "held":
            us = _held_input_at_samples(traj.ts, us)
        us = _lowpass(traj, us, cutoff, order)
        held = False
    else:
        held = method.inputs == "held"
    ys, forces = _dynamic_equations(system, traj.ts, xs, us, friction, held)
    if settings["decimate"] > 1:
        ys, forces = _trim_and_decimate(ys, forces, trim, settings["decimate"])
        trim = 0
    elif trim < 0 or settings["decimate"] < 1:
        raise UsageError(f"`trim` must be >= 0 and `decimate` >= 1, got {trim}, {settings['decimate']}")
    # Without decimation the trim is a slice that `_joint_blocks` takes in the same compiled call.
    return ys, forces, ys.shape[0] - 2 * trim, settings, trim


def _interval_integrals(ts, values_left, values_right):
    h = jnp.diff(ts)
    h = h.reshape(h.shape + (1,) * (values_left.ndim - 1))
    return 0.5 * h * (values_left + values_right)


def _joined(energy_part, dissipative_part, columns):
    """The rows with every column in its place: `energy_part` in the energy columns, the rest from `dissipative_part`."""
    order = np.argsort(np.asarray(columns[0] + columns[1], dtype=int))
    return jnp.concatenate([energy_part, dissipative_part], axis=-1)[..., order]


@eqx.filter_jit
def _model_columns(system, xs, us, friction, columns):
    """The energy regressor's energy columns and the friction-power regressor's dissipative columns,
    the generalised forces and the velocities at every sample.

    One compiled call, and the differences and integrals another: in one program with them, XLA's
    CPU backend fuses the vmapped Jacobians into every shifted slice that reads them and evaluates
    them several times (the power model ran at a quarter of numpy's speed that way).
    """
    _, dq = _positions(system, xs)
    w, f = energy_and_friction_rows(system, xs, friction)
    energy, dissipative = columns
    return w[:, list(energy)], f[:, list(dissipative)], generalised_force(system, us), dq


def _integrate_intervals(ts, dq, tau, f):
    tau = tau[:-1]  # on [t_j, t_{j+1}] the input is us[j]
    work = _interval_integrals(ts, row_dot(dq[:-1], tau), row_dot(dq[1:], tau))
    dissipated = _interval_integrals(ts, f[:-1], f[1:])
    return work, dissipated


def _power_rows(system, traj, method: Power, friction):
    _needs(traj, 2 * method.trim + 3, "power")
    if method.lowpass_hz is not None:
        traj = _uniform(traj)
    rows, target = _power_equations(system, traj.ts, traj.xs, traj.us, friction)
    if method.lowpass_hz is not None:
        inner = traj.slice(1, -1)
        rows, target = (_lowpass(inner, v, method.lowpass_hz, method.lowpass_order) for v in (rows, target))
    rows, target = _trim_and_decimate(rows, target, max(method.trim - 1, 0), method.decimate)
    return rows, target, rows.shape[0]


def _power_equations(system, ts, xs, us, friction):
    columns = column_kinds(system, friction)
    w, f, tau, dq = _model_columns(system, xs, us, friction, columns)
    return _power_balance(ts, w, f, tau, dq, columns)


@eqx.filter_jit
def _power_balance(ts, w, f, tau, dq, columns):
    work, dissipated = _integrate_intervals(ts, dq, tau, f)
    # dH/dt by central differences of the energy columns; the powers averaged with the same weights
    # over the two neighbouring intervals, so each row is exact to O(h^2) under the zero-order hold.
    h = jnp.diff(ts)
    h1, h2 = h[:-1], h[1:]
    a1, a2 = h2 / (h1 + h2) / h1, h1 / (h1 + h2) / h2
    dw = (a1[:, None] * (w[1:-1] - w[:-2]) + a2[:, None] * (w[2:] - w[1:-1]))
    f = a1[:, None] * dissipated[:-1] + a2[:, None] * dissipated[1:]
    p = a1 * work[:-1] + a2 * work[1:]
    return _joined(dw, f, columns), p


def _energy_rows(system, traj, method: Energy, friction):
    window = method.window
    stride = method.stride or window
    _needs(traj, window + 1, "energy")
    if method.lowpass_hz is not None:
        traj = _uniform(traj)
        xs = _lowpass(traj, traj.xs, method.lowpass_hz, method.lowpass_order)
    else:
        xs = traj.xs
    n_windows = (len(traj) - window - 1) // stride + 1  # windows [i stride, i stride + window] inside the record
    rows, target = _energy_equations(system, traj.ts, xs, traj.us, friction, n_windows, window, stride)
    return rows, target, (n_windows - 1) * stride + window + 1


def _energy_equations(system, ts, xs, us, friction, n_windows, window, stride):
    """One energy-balance equation per window `[i stride, i stride + window]`, `i < n_windows`."""
    columns = column_kinds(system, friction)
    w, f, tau, dq = _model_columns(system, xs, us, friction, columns)
    return _energy_balance(ts, w, f, tau, dq, n_windows, window, stride, columns)


@eqx.filter_jit
def _energy_balance(ts, w, f, tau, dq, n_windows, window, stride, columns):
    work, dissipated = _integrate_intervals(ts, dq, tau, f)
    # Each window's integrals as the sum of its `window` intervals, not as differences of running
    # sums: XLA's CPU cumsum of 100,000 rows is slow, and differences of long running sums lose
    # digits. Windows that tile the record (the default) are a reshape; overlapping or spaced
    # ones a gather.
    last = (n_windows - 1) * stride  # start of the last window
    gained = w[window : last + window + 1 : stride] - w[: last + 1 : stride]  # strided slices, not gathers
    if stride == window:
        def window_sums(v):
            return v[: n_windows * window].reshape((n_windows, window) + v.shape[1:]).sum(axis=1)
    else:
        intervals = stride * jnp.arange(n_windows)[:, None] + jnp.arange(window)[None, :]  # (windows, window)

        def window_sums(v):
            return jnp.sum(v[intervals], axis=1)

    return _joined(gained, window_sums(dissipated), columns), window_sums(work)


def _system_name(system):
    base = system.system if isinstance(system, Extended) else system
    return _SYSTEM_NAMES.get(type(base), type(base).__name__)


def _fitted_system(system, names, estimate):
    """`system` carrying the estimate; base parameters the fitted model leaves out are as the system's
    `with_base_parameters` sets them (a linear axis fitted without Coulomb friction gets `coulomb = 0`)."""
    return with_parameters(system, names, jnp.asarray(estimate))


_CONSISTENCY = ("constrain", "check", "off")


class _LeastSquaresStage(eqx.Module):
    system: AbstractSystem
    names: tuple[str, ...] = eqx.field(static=True)
    estimate: Array
    fit: LeastSquaresFit
    a: Array
    y: Array
    n_samples: int = eqx.field(static=True)
    label: str = eqx.field(static=True)
    settings: tuple
    consistency: Consistency
    offsets: RecordOffsets | None


def _equations(system, trajectories, method, friction, weights, rcond):
    """The stacked least-squares problem `(a, y, weights, names, n_samples, label, settings, counts)`;
    `counts` (for `Dynamic`) each record's rows per joint, else `()`."""
    system = with_friction(system, friction)
    names = parameter_names(system, friction)
    settings, counts = (), ()
    if isinstance(method, Dynamic):
        parts = [_dynamic_rows(system, t, method, friction) for t in trajectories]
        a, y = _joint_blocks([p[0] for p in parts], [p[1] for p in parts], tuple(p[4] for p in parts))
        counts = tuple(int(p[2]) for p in parts)
        n_samples = sum(counts)
        settings = tuple(p[3] for p in parts)
        n_joints = parts[0][0].shape[1]
        if method.weighting == "joint" and weights is None:
            first = least_squares(a, y, names=names, rcond=rcond)
            residual = (a @ first.estimate - y).reshape(n_joints, -1)
            variance = jnp.mean(residual**2, axis=1)
            variance = jnp.where(variance > 0, variance, jnp.max(variance) + jnp.finfo(a.dtype).tiny)
            weights = jnp.repeat(1.0 / variance, a.shape[0] // n_joints)
        elif method.weighting not in ("none", "joint"):
            raise UsageError(f"Dynamic: `weighting` must be 'none' or 'joint', got {method.weighting!r}")
        label = "dynamic"
    elif isinstance(method, (Power, Energy)):
        rows, label = (_power_rows, "power") if isinstance(method, Power) else (_energy_rows, "energy")
        parts = [rows(system, t, method, friction) for t in trajectories]
        a = jnp.concatenate([p[0] for p in parts])
        y = jnp.concatenate([p[1] for p in parts])
        n_samples = sum(p[2] for p in parts)
    else:
        raise UsageError(
            f"identify: `method` must be Dynamic(), Power(), Energy() or SimulationFit(), got {type(method).__name__}"
        )
    return system, a, y, weights, names, n_samples, label, settings, counts


@eqx.filter_jit
def _joint_blocks(rows, forces, trims):
    """The records' dynamic equations `(time, joints, params)`, each without `trim` rows at either end,
    stacked joint by joint (all of joint 1's rows, then joint 2's), so that a per-joint weight is one
    block of rows; one compiled call (op by op, the copies took twice as long as the regressor)."""
    ys = jnp.concatenate([r[t : r.shape[0] - t] for r, t in zip(rows, trims)])
    forces = jnp.concatenate([f[t : f.shape[0] - t] for f, t in zip(forces, trims)])
    return jnp.transpose(ys, (1, 0, 2)).reshape(-1, ys.shape[2]), forces.T.reshape(-1)


def _joint_positions(system, trajectories):
    """The records' joint positions, stacked (one compiled call: slicing op by op costs more than the check)."""
    return _stacked_positions(system, [t.xs for t in trajectories])


@eqx.filter_jit
def _stacked_positions(system, states):
    return jnp.concatenate([_positions(system, xs)[0] for xs in states])


def _least_squares_stage(system, trajectories, method, friction, weights, rcond, consistency):
    system, a, y, weights, names, n_samples, label, settings, counts = _equations(
        system, trajectories, method, friction, weights, rcond
    )
    fit = least_squares(a, y, names=names, weights=weights, rcond=rcond)
    estimate = fit.estimate
    fitted = _fitted_system(system, names, estimate)
    qs = _joint_positions(system, trajectories)
    check = check_consistency(fitted, names, estimate, qs, warn=consistency == "check")
    if consistency == "constrain" and check.violated:
        estimate, _ = consistent_least_squares(system, names, a, y, weights, start=fit.estimate)
        fitted = _fitted_system(system, names, estimate)
        after = check_consistency(fitted, names, estimate, qs, warn=False)
        check = Consistency(after.violated, active=check.violated, constrained=True,
                            min_mass_eigenvalue=after.min_mass_eigenvalue)
        if after.violated:
            warnings.warn("the constrained fit did not reach a consistent estimate: " + "; ".join(after.violated),
                          InconsistentEstimateWarning, stacklevel=3)
    offsets = record_offsets(a, y, counts, _split(system)[0].joint_names, record_labels(trajectories)) if counts else None
    return _LeastSquaresStage(fitted, names, estimate, fit, a, y, int(n_samples),
                              label, settings, check, offsets)


def _relative_equation_error(a, y, estimate):
    return jnp.linalg.norm(a @ estimate - y) / jnp.linalg.norm(y)


def _stage_json(method, names, estimate, std, relative_error, validation, **extra):
    out = {"method": method, "parameters": {n: float(v) for n, v in zip(names, np.asarray(estimate))},
           "std_errors": {n: float(v) for n, v in zip(names, np.asarray(std))},
           "relative_equation_error": None if relative_error is None else float(relative_error),
           "validation": None if validation is None else validation.to_json()}
    out.update(extra)
    return out


def _signal_band_hz(trajectories) -> float | None:
    """The widest velocity signal band over the records, or `None` when no record's velocities are noisy."""
    bands = [c.cutoff_hz for c in (choose_filter(_uniform(t)) for t in trajectories) if c.cutoff_hz is not None]
    return max(bands) if bands else None


def _refinement_method(refine, system, method, trajectories):
    """The `SimulationFit` that refines the least-squares estimate, or `None`.

    `"auto"`: two-link arms whose velocities carry measurement noise (real data), with segments of
    one period of the signal band's edge (long enough to show the motion, short enough that a
    chaotic run's divergence does not swamp the fit), 60 Levenberg-Marquardt steps, and 4 integrator
    steps per sample.
    """
    if refine is None or refine is False:
        return None
    arm = _split(system)[0].refinement_terms() is not None
    if not (refine is True or isinstance(refine, SimulationFit) or (isinstance(refine, str) and refine == "auto")):
        raise UsageError(f"identify: `refine` must be 'auto', True, False or a SimulationFit(), got {refine!r}")
    if not arm:
        if isinstance(refine, str):
            return None
        raise UsageError("identify: the output-error refinement is for two-link arms; use SimulationFit() as the method")
    if isinstance(refine, SimulationFit):
        return refine
    band = _signal_band_hz(trajectories)
    if band is None and isinstance(refine, str):
        return None  # noise-free velocities: least squares is not biased, nothing to refine
    segment = 1.0 / band if band is not None else 0.25
    # Four integrator steps per sample of the fitted grid (40 per band period): the smoothed Coulomb
    # friction (tanh at 0.01 rad/s) is stiff, and two steps left a visible bias on synthetic data.
    return SimulationFit(segment_s=segment, fit_initial_states=False, max_steps=60, simulation=FixedGrid(substeps=4))


def _named_parameters(system, names) -> Parameters:
    """The `Parameters` of the named coefficients (fields of the nominal system and of its joint
    terms) of a system the regressors know, named as `parameter_names` names them, in tree order."""
    base, terms = _split(system)
    fields = [n for n in names if hasattr(base, n) and not isinstance(getattr(type(base), n, None), property)]
    named_terms = [i for i, t in enumerate(terms) if t.parameter_name(base) in names]
    labels = fields + [terms[i].parameter_name(base) for i in named_terms]

    def places(tree):  # `tree` is shaped like `system` (a bare system or `Extended`)
        nominal = tree.system if base is not system else tree
        return [getattr(nominal, n) for n in fields] + [tree.terms[i].coefficient for i in named_terms]

    spec = eqx.tree_at(places, jax.tree.map(lambda _: False, system), [True] * len(labels))
    tags = eqx.tree_at(places, jax.tree.map(lambda _: "", system), labels)
    selected = Parameters.of(system, spec)
    ordered = tuple(tag for tag, chosen in zip(jax.tree.leaves(tags), selected.selection) if chosen)
    return Parameters.of(system, spec, names=ordered)


def _identify_by_simulation(system, trajectories, method: SimulationFit, friction) -> Identification:
    """`identify` with `SimulationFit`: the output-error fit of the system's named coefficients
    (the regressors' names, for the systems they know) or of its `parameter_filter()`."""
    try:
        system = with_friction(system, friction)
        names = parameter_names(system, friction)
    except UsageError:
        names = None  # any other system: its own parameter filter, named by its labels or tree paths
    if names is not None:
        # Start from the system's values; the coefficients not in `names` (a linear axis's Coulomb
        # term under viscous friction) are fixed.
        system = _fitted_system(system, names, parameter_vector(system, friction))
        parameters = _named_parameters(system, names)
    else:
        parameters = Parameters.of(system)
    result = fit_simulation_error(
        system, trajectories, filter_spec=parameters, segment_s=method.segment_s,
        fit_initial_states=method.fit_initial_states, continuity_weight=method.continuity_weight,
        rtol=method.rtol, atol=method.atol, max_steps=method.max_steps, simulation=method.simulation,
    )
    # The system's part of the engine's solution: the same names, estimate, errors and covariance.
    n = parameters.size
    full = result.solution
    solution = Solution(
        model=result.system, value=full.value[:n], parameters=parameters, covariance=full.covariance[:n, :n],
        std_errors=full.std_errors[:n], result=full.result, loss=full.loss, initial_loss=full.initial_loss,
        steps=full.steps, n_residuals=full.n_residuals,
    )
    order = np.arange(n) if names is None else np.asarray([parameters.names.index(name) for name in names])
    return Identification(
        system=result.system,
        estimate=solution.value[order],
        std_errors=solution.std_errors[order],
        condition_number=result.condition_number,
        rank=result.rank,
        residual_rms=result.residual_rms,
        relative_error=result.relative_error,
        fit=None,
        names=parameters.names if names is None else tuple(names),
        n_samples=result.n_samples,
        method="simulation",
        friction=friction,
        system_name=_system_name(system),
        solution=solution,
    )


def _validation_split(system, trajectories, validation, weights, holdout, horizons_s):
    """`(fitted, held, source)`: the records to fit, the held-out records and what they are.

    The `validation` records when given (all of the data is fitted); otherwise the last `holdout`
    fraction of each record (`"auto"`: 0.2, or 0 when row weights are given: they index every row)."""
    if validation is not None:
        held = _as_list(validation)
        _check_data(system, held)
        return trajectories, held, "validation records"
    fraction = (0.0 if weights is not None else 0.2) if holdout == "auto" else float(holdout)
    if fraction <= 0:
        return trajectories, [], ""
    fitted, held = split_for_validation(trajectories, fraction, max(horizons_s))
    return fitted, held, f"held-out last {fraction:.0%} of each record (not fitted)"


def _validated_simulation_fit(system, fitted, method, friction, consistency, validate) -> Identification:
    """`identify` by `SimulationFit`, with its consistency check and held-out validation."""
    result = _identify_by_simulation(system, fitted, method, friction)
    check = None
    if _has_conditions(system):
        qs = _joint_positions(result.system, fitted)
        check = check_consistency(result.system, result.names, result.estimate, qs, warn=consistency != "off")
    held_out = validate(result.system)
    stage = _stage_json("simulation", result.names, result.estimate, result.std_errors, None, held_out)
    return eqx.tree_at(lambda r: (r.consistency, r.validation, r.stages), result,
                       (check, held_out, {"simulation": stage}), is_leaf=lambda x: x is None)


def _refined_stage(ls, fitted, method, friction, rcond, consistency, refinement, validate):
    """The output-error refinement from the least-squares stage `ls`: `(final, stage json)`, where
    `final` holds what `identify` returns (system, names, estimate, standard errors, equation error
    on the least-squares rows, validation, consistency, method label)."""
    refined = refine_by_simulation(ls.system, ls.names, fitted, refinement)
    _, a, y, _, _, _, _, _, _ = _equations(refined.system, fitted, method, friction, None, rcond)
    error = _relative_equation_error(a, y, jnp.asarray(refined.estimate))
    qs = _joint_positions(refined.system, fitted)
    check = check_consistency(refined.system, refined.names, refined.estimate, qs, warn=consistency != "off")
    check = Consistency(check.violated, active=(), constrained=True, min_mass_eigenvalue=check.min_mass_eigenvalue)
    held_out = validate(refined.system)
    stage = _stage_json(
        "simulation", refined.names, refined.estimate, refined.std_errors, error, held_out,
        consistency=check.to_json(), initial_residual_rms=refined.initial_residual_rms,
        residual_rms=refined.residual_rms, steps=refined.steps, dt=refined.dt, segment_s=refined.segment_s,
        model="least-squares model + RotorInertia(joint=1), consistent parametrisation",
    )
    final = dict(system=refined.system, names=refined.names, estimate=jnp.asarray(refined.estimate),
                 std=jnp.asarray(refined.std_errors), error=error, validation=held_out, consistency=check,
                 label=f"{ls.label}+simulation")
    return final, stage


def identify(
    system: AbstractSystem,
    data: Trajectory | Sequence[Trajectory],
    method: "Dynamic | Power | Energy | SimulationFit" = Dynamic(),
    *,
    friction: Friction = "viscous",
    weights: Float[Array, " rows"] | None = None,
    rcond: float = 1e-7,
    consistency: Literal["constrain", "check", "off"] = "constrain",
    refine="auto",
    validation: Trajectory | Sequence[Trajectory] | None = None,
    holdout: float | Literal["auto"] = "auto",
    horizons_s: Sequence[float] = DEFAULT_HORIZONS_S,
) -> Identification:
    r"""Fit the parameters of `system` to measured trajectories, and validate the result.

    The least-squares methods (`Dynamic`, `Power`, `Energy`) build the linear-in-parameter model
    of each trajectory, stack the rows of all of them and solve one weighted least-squares problem
    (QR and SVD of the column-scaled regressor); they return standard errors from the residual
    variance, the condition number and the numerical rank. `SimulationFit` minimises the
    simulation error through the integrator instead (see `fit_simulation_error`).

    By default, on top:

    - `Dynamic`'s filter and derivative settings are chosen per record from its spectra
      (`choose_filter`) and reported in `settings`;
    - the estimate is checked for physical consistency (`check_consistency`); an inconsistent
      least-squares estimate is replaced by the constrained fit over the consistent set
      (`consistent_least_squares`), and `consistency.active` names what had to be enforced;
    - for two-link arms whose velocities carry measurement noise (real data), the least-squares
      estimate is refined by the output-error fit with the elbow motor's rotor inertia, consistent
      by construction (`refine_by_simulation`), and both stages are reported;
    - the returned model is simulated open loop on held-out data (`validation`, or the last 20 %
      of each record, which then does not enter the fit) and the position RMSE against horizon is
      reported next to the equation error;
    - with `Dynamic` on two records or more, each record's constant offset on each joint's
      recorded force is estimated (from each half of the record too) and tested for differing
      between records (`record_offsets`, a sensor zero that changes from one recording to the
      next); reported, not used.

    **Arguments:**

    - `system`: `Acrobot`, `DoublePendulum` or `LinearAxis` (least squares), or any system
      (`SimulationFit`). Its parameter values are the starting point of `SimulationFit` and are
      otherwise ignored.
    - `data`: a `Trajectory` or a list of them (same system).
    - `method`: `Dynamic()` (default), `Power()`, `Energy()` or `SimulationFit()`.
    - `friction`: `"viscous"` (default) or `"coulomb"` (adds `fc1`, `fc2`, or the linear axis's
      `coulomb`).
    - `weights`: optional row weights for the least-squares problem, one per stacked equation
      (for `Dynamic`, all of joint 1's equations come first, then joint 2's).
    - `rcond`: relative singular-value threshold of the numerical rank.
    - `consistency`: `"constrain"` (default: fit over the consistent set when the plain estimate
      is inconsistent), `"check"` (return the plain estimate; warn with
      `InconsistentEstimateWarning` naming each violated condition) or `"off"`.
    - `refine`: `"auto"` (default: refine two-link arms on noisy data), `True`, `False`, or the
      `SimulationFit` settings to refine with.
    - `validation`: held-out records; when given, all of `data` is fitted.
    - `holdout`: fraction of each record held out when no `validation` is given (`"auto"`: 0.2,
      or 0 when row `weights` are given); 0 fits everything and reports no validation.
    - `horizons_s`: validation horizons [s] (default 0.1, 0.25, 0.5).

    **Returns:** an `Identification`.

    **Raises:** `IdentifiabilityError` (a `DataError`) when the data do not determine all
    parameters, naming the unidentified combinations; `DataError` when a record is too short;
    `UsageError` for a system or method that does not fit.
    """
    warn_if_float32("identification")  # the float64 policy: say so, once, naming the switch

    trajectories = _as_list(data)
    _check_data(system, trajectories)
    if consistency not in _CONSISTENCY:
        raise UsageError(f"identify: `consistency` must be one of {_CONSISTENCY}, got {consistency!r}")
    horizons_s = tuple(float(h) for h in horizons_s)
    fitted, held, source = _validation_split(system, trajectories, validation, weights, holdout, horizons_s)

    def validate(model):
        return held_out_error(model, held, horizons_s, source=source) if held else None

    if isinstance(method, SimulationFit):
        return _validated_simulation_fit(system, fitted, method, friction, consistency, validate)

    ls = _least_squares_stage(system, fitted, method, friction, weights, rcond, consistency)
    ls_error = _relative_equation_error(ls.a, ls.y, ls.estimate)
    ls_validation = validate(ls.system)
    std = ls.fit.std_errors
    stages = {"least_squares": _stage_json(ls.label, ls.names, ls.estimate, std, ls_error, ls_validation,
                                           consistency=ls.consistency.to_json())}
    refinement = _refinement_method(refine, ls.system, method, fitted)
    final = dict(system=ls.system, names=ls.names, estimate=ls.estimate, std=std, error=ls_error,
                 validation=ls_validation, consistency=ls.consistency, label=ls.label)
    if refinement is not None:
        final, stages["output_error"] = _refined_stage(ls, fitted, method, friction, rcond, consistency,
                                                       refinement, validate)
    return Identification(
        system=final["system"],
        estimate=jnp.asarray(final["estimate"]),
        std_errors=jnp.asarray(final["std"]),
        condition_number=ls.fit.condition_number,
        rank=ls.fit.rank,
        residual_rms=ls.fit.residual_rms,
        relative_error=final["error"],
        fit=ls.fit,
        names=final["names"],
        n_samples=ls.n_samples,
        method=final["label"],
        friction=friction,
        system_name=_system_name(system),
        settings=ls.settings,
        consistency=final["consistency"],
        validation=final["validation"],
        stages=stages,
        record_offsets=ls.offsets,
    )


def _has_conditions(system):
    """Whether the least-squares models know `system` and it has physical-consistency conditions."""
    try:
        base, _ = _split(system)
    except UsageError:
        return False
    return bool(base.base_parameter_kinds())
