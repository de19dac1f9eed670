r"""The least-squares models of `identify` and their equations.

- `Dynamic()`: the inverse-dynamics model $Y(q, \dot q, \ddot q)\,\theta = B u$, both joints' rows
  stacked (never summed); needs $\ddot q$, by central differences of (optionally low-passed)
  velocities; every filter setting chosen from the record's spectra unless given.
- `Power()`: the power model $\dot q^\top B u = \frac{d}{dt} H + \dot q^\top F(\dot q)$; no $\ddot q$.
- `Energy()`: the energy model $\int_{t_a}^{t_b} \dot q^\top B u\,dt = H(t_b) - H(t_a) +
  \int_{t_a}^{t_b} \dot q^\top F\,dt$ over windows, by the trapezoid rule; no $\ddot q$.

`stacked_equations` stacks one model's rows over the records: what `identify`'s least-squares stage solves
and what `record_offsets` tests. Each model is an `AbstractMethod` whose `equations` builds its rows
and whose `fit` solves them by plain (weighted) least squares.
"""

import abc
import dataclasses
from typing import ClassVar, Literal

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._data._derivatives import butterworth_filtfilt, central_difference, resample
from .._data._spectra import choose_filter, trim_and_decimation
from .._data._trajectory import Trajectory
from .._errors import DataError, UsageError
from .._fit import Solution
from ._least_squares import least_squares
from ._method import AbstractMethod, as_records, FitSettings, Fitted, IdentifyJob, Prepared
from ._regressors import (
    column_kinds,
    dynamic_regressor,
    energy_and_friction_rows,
    generalised_force,
    parameter_names,
    positions_and_velocities,
    row_dot,
    with_friction,
    with_parameters,
)


def uniformly_sampled(trajectory: Trajectory) -> Trajectory:
    """The record itself if uniformly sampled, else resampled at its median interval."""
    return trajectory if trajectory.is_uniform else resample(trajectory, trajectory.dt)


def row_times(records, settings, counts) -> list[np.ndarray]:
    """Each record's time of each of its equation rows (`Dynamic`'s, one block per joint): row `k` of a
    record is its sample `trim + k * decimate` at its median interval (the equations are trimmed and then
    decimated, `settings`; a record is resampled uniformly where it is low-passed)."""
    out = []
    for record, setting, count in zip(records, settings, counts):
        ts = np.asarray(uniformly_sampled(record).ts if setting.get("lowpass_hz") is not None else record.ts)
        samples = setting["trim"] + np.arange(count) * setting["decimate"]
        out.append(ts[np.minimum(samples, len(ts) - 1)])
    return out


def _lowpass(trajectory, ys, cutoff_hz, order):
    return butterworth_filtfilt(trajectory.ts, ys, cutoff_hz=cutoff_hz, order=order)


class AbstractLeastSquares(AbstractMethod):
    r"""A least-squares method: the system's equations, linear in its base parameters, stacked over the
    records and solved by weighted least squares (QR and SVD of the column-scaled regressor).

    `fit` solves the method's equations as they are; its steps (what `identify` runs) add the
    least-squares stages: `prepare`, each record's angle zeros; `fit_stage`, force offsets, the
    consistency constraint, errors robust to rows correlated in time and friction at rest;
    `refine`, the output-error refinement (`dynax._identify._stages`). The hooks below say which of them apply.

    **Class attributes:** `refits_without_loaded_rests`, whether the stage is refitted without the
    rows where a joint rests under load (default `False`).

    **Properties:** `adds_static_friction` (the model gets `Stiction` where the records rest under
    load; default `False`: the rests are read and reported), `force_offsets` (each record's constant
    force offset is fitted, `Dynamic`'s `offsets`), `joint_weighted` (each joint's equations are
    weighted by its residual variance), `angle_zeros_mode` (each record's angle zeros are fitted
    where every joint is a driven angle: `"compare"`, kept where they fit better than force
    offsets; `"always"`, refused on other systems; `None`, default).
    """

    rcond: eqx.AbstractVar[float]
    refits_without_loaded_rests: ClassVar[bool] = False

    @abc.abstractmethod
    def equations(self, system, trajectories, friction):
        """The method's equations on `trajectories`: `(a, y, n_samples, settings, counts, record_rows)`
        (see `stacked_equations`)."""

    @property
    def adds_static_friction(self) -> bool:
        return False

    @property
    def force_offsets(self) -> bool | str:
        return False

    @property
    def joint_weighted(self) -> bool:
        return False

    @property
    def angle_zeros_mode(self) -> Literal["compare", "always"] | None:
        return None

    def fit(self, system, records, settings: FitSettings = FitSettings()) -> Solution:
        """The least-squares estimate of `system`'s base parameters (`parameter_names`) from `records`.

        **Returns:** a `Solution` whose `model` is `system` carrying the estimate (with
        `settings.friction="coulomb"`, extended with the Coulomb friction terms), with the
        regressor's `Statistics`.
        """
        model, a, y, weights, names, _, _, _, _, _ = stacked_equations(
            system, as_records(records), self, settings.friction, settings.weights, self.rcond
        )
        solution = least_squares(a, y, names=names, weights=weights, rcond=self.rcond)
        return eqx.tree_at(lambda s: s.model, solution, with_parameters(model, names, solution.value))

    def prepare(self, system, records: list[Trajectory], job: IdentifyJob) -> Prepared:
        """Each record's angle zeros where they apply, fitted out of the records and the held-out
        tails when chosen (`least_squares_prepare`)."""
        from ._stages import least_squares_prepare  # the stages build on the methods

        return least_squares_prepare(self, system, records, job)

    def fit_stage(self, system, prepared: Prepared) -> Fitted:
        """The least-squares stage and friction at rest (`least_squares_fit`)."""
        from ._stages import least_squares_fit

        return least_squares_fit(self, system, prepared)

    def refine(self, system, prepared: Prepared, fitted: Fitted) -> Fitted:
        """The output-error refinement where it applies (`least_squares_refine`)."""
        from ._stages import least_squares_refine

        return least_squares_refine(self, system, prepared, fitted)


class Dynamic(AbstractLeastSquares):
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
      for a measured force or torque sampled at $t_k$ (the EMPS reference model does this; the
      half-sample shift between the two moves a viscous friction by percents).
    - `weighting`: `"none"` (ordinary least squares) or `"joint"`: weight each joint's equations
      by the inverse of its residual variance from a first ordinary fit of the same equations
      (offsets removed when they are estimated; Gautier's weighted least squares; joints with
      noisier torque count less).
    - `offsets`: estimate, with the parameters, one constant offset of the recorded force per record
      and driven joint (a current-based torque's zero, which differs from one recording to the
      next: the "offset" term of Gautier's and the EMPS models, here per record), and fit the
      output-error refinement to the records less them; reported in the least-squares stage, not
      part of the returned model. `"auto"`: with the settings chosen from the data (no explicit
      `lowpass_hz`) on systems whose model has no constant term of its own (two-link arms; a linear
      axis has its `offset` parameter already). A small motion about an equilibrium that an offset
      has shifted otherwise biases the gravity terms (on one short run, to a fraction of their
      value). On an arm whose every joint is a driven angle, `"auto"` also fits one *angle zero*
      per record and joint instead (an encoder zeroed where the arm stood when the recording
      began, `dynax._identify._angle_zeros`) and keeps whichever of the two leaves the smaller
      equation error (as many unknowns). `"angles"` fits the
      angle zeros whatever the error (such arms only); `True` the force offsets.
    - `rcond`: relative singular-value threshold of the numerical rank (default 1e-7).
    - `static_friction`: where a joint of the records rests under load, give the model `Stiction` at
      it, fit `Dynamic` without those rows and refine the static level with the rest (see
      `result.static_friction`). Default `False`: the rests are found and reported, the model keeps
      its friction law of the speed (on the DFKI rig's leave-one-run-out folds the static level costs
      the held-out runs that never rest a few percent; see "Friction at rest" in the guide).

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
    offsets: bool | Literal["auto", "angles"] = "auto"
    rcond: float = 1e-7
    static_friction: bool = False

    refits_without_loaded_rests: ClassVar[bool] = True

    @property
    def adds_static_friction(self) -> bool:
        return self.static_friction

    @property
    def label(self) -> str:
        return "dynamic"

    @property
    def force_offsets(self) -> bool | str:
        return self.offsets

    @property
    def joint_weighted(self) -> bool:
        return self.weighting == "joint"

    @property
    def angle_zeros_mode(self) -> Literal["compare", "always"] | None:
        if self.offsets == "angles":
            return "always"
        if self.offsets == "auto" and isinstance(self.lowpass_hz, str) and self.lowpass_hz == "auto":
            return "compare"
        return None

    def equations(self, system, trajectories, friction):
        parts = [dynamic_rows(system, t, self, friction) for t in trajectories]
        a, y, counts = stacked_dynamic_equations(parts)
        n_samples = sum(counts)
        settings = tuple(p[3] for p in parts)
        if self.weighting not in ("none", "joint"):
            raise UsageError(f"Dynamic: `weighting` must be 'none' or 'joint', got {self.weighting!r}")
        return a, y, n_samples, settings, counts, counts


class Power(AbstractLeastSquares):
    r"""The power least-squares model (Gautier 1997): $\dot q^\top B u = \dot H + \dot q^\top F(\dot q)$.

    Each sample gives one equation. $\dot H = \dot w\,\theta$ is the central difference of the
    energy regressor columns; no acceleration is needed. With `lowpass_hz` every column of the
    regressor and the target are filtered by the same zero-phase Butterworth filter before the
    difference (parallel filtering: the model stays exact, the noise is cut).

    **Arguments:** `lowpass_hz` (or `None`), `lowpass_order` (default 4), `trim` (samples dropped
    at each end, default 1), `decimate` (parallel decimation as in `Dynamic`, default 1), `rcond`
    (the numerical rank's relative singular-value threshold, default 1e-7).

    ??? cite

        M. Gautier, "Dynamic identification of robots with power model", Proc. IEEE ICRA 1997.
    """

    lowpass_hz: float | None = None
    lowpass_order: int = 4
    trim: int = 1
    decimate: int = 1
    rcond: float = 1e-7

    @property
    def label(self) -> str:
        return "power"

    def equations(self, system, trajectories, friction):
        return _stacked_records([power_rows(system, t, self, friction) for t in trajectories])


class Energy(AbstractLeastSquares):
    r"""The energy least-squares model (Gautier and Khalil 1988), one equation per window.

    Over a window $[t_a, t_b]$: $\int \dot q^\top B u\,dt = (w(t_b) - w(t_a))\,\theta +
    \int \dot q^\top F\,dt$. Integrals use the trapezoid rule on the recorded grid, with the input
    held over each interval (zero-order hold), so irregular sampling is handled exactly as
    recorded. No acceleration is needed.

    **Arguments:**

    - `window`: samples per window (default 10).
    - `stride`: samples between window starts (default `window`: consecutive windows).
    - `lowpass_hz`, `lowpass_order`: optional zero-phase filter of the states first.
    - `rcond`: relative singular-value threshold of the numerical rank (default 1e-7).

    ??? cite

        M. Gautier and W. Khalil, "On the identification of the inertial parameters of robots",
        Proc. 27th IEEE CDC, 1988; M. Gautier, "Dynamic identification of robots with power
        model", Proc. IEEE ICRA 1997 (comparison of the energy, power and dynamic models).
    """

    window: int = 10
    stride: int | None = None
    lowpass_hz: float | None = None
    lowpass_order: int = 4
    rcond: float = 1e-7

    def __check_init__(self):
        if self.window < 1:
            raise ValueError(f"Energy: `window` must be at least 1 sample, got {self.window}")
        if self.stride is not None and self.stride < 1:
            raise ValueError(f"Energy: `stride` must be at least 1, got {self.stride}")

    @property
    def label(self) -> str:
        return "energy"

    def equations(self, system, trajectories, friction):
        return _stacked_records([energy_rows(system, t, self, friction) for t in trajectories])


def _stacked_records(parts):
    """`equations`'s tuple for rows stacked record by record (`Power`, `Energy`)."""
    a = jnp.concatenate([p[0] for p in parts])
    y = jnp.concatenate([p[1] for p in parts])
    n_samples = sum(p[2] for p in parts)
    return a, y, n_samples, (), (), tuple(int(p[0].shape[0]) for p in parts)


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
    _, dq = positions_and_velocities(system, xs)
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
        uniform = uniformly_sampled(traj)
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
        raise UsageError(
            f"Dynamic: `lowpass_hz` must be a positive frequency, None or 'auto', got {settings['lowpass_hz']!r}"
        )
    settings["record"] = traj.source or None
    settings["chosen_from_data"] = auto
    settings["reason"] = reason
    return settings


def dynamic_rows(system, traj, method: Dynamic, friction):
    return dynamic_rows_of(system, dynamic_signals(traj, method), friction)


@dataclasses.dataclass(frozen=True)
class DynamicSignals:
    """One record as the dynamic model reads it: its (filtered) states `xs`, inputs `us` and times
    `ts`, whether the inputs are `held`, and its `settings`. A constant shift of `xs` is the
    signals of the shifted record: the zero-phase filters pass constants unchanged."""

    ts: jnp.ndarray | np.ndarray
    xs: jnp.ndarray | np.ndarray
    us: jnp.ndarray | np.ndarray
    held: bool
    settings: dict


def dynamic_signals(traj, method: Dynamic) -> DynamicSignals:
    """The record's settings (`_resolve_dynamic`) and its signals filtered by them."""
    settings = _resolve_dynamic(traj, method)
    cutoff, order, trim = settings["lowpass_hz"], settings["lowpass_order"], settings["trim"]
    _needs(traj, 2 * trim + 3, "dynamic")
    if cutoff is not None:
        traj = uniformly_sampled(traj)
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
    return DynamicSignals(traj.ts, xs, us, held, settings)


def dynamic_rows_of(system, signals: DynamicSignals, friction):
    """`(rows, forces, count, settings, trim)` of one record's dynamic equations from its signals."""
    s = signals
    trim = s.settings["trim"]
    ys, forces = _dynamic_equations(system, s.ts, s.xs, s.us, friction, s.held)
    if s.settings["decimate"] > 1:
        ys, forces = _trim_and_decimate(ys, forces, trim, s.settings["decimate"])
        trim = 0
    elif trim < 0 or s.settings["decimate"] < 1:
        raise UsageError(f"`trim` must be >= 0 and `decimate` >= 1, got {trim}, {s.settings['decimate']}")
    # Without decimation the trim is a slice that `_joint_blocks` takes in the same compiled call.
    return ys, forces, ys.shape[0] - 2 * trim, s.settings, trim


def stacked_dynamic_equations(parts):
    """`(a, y, counts)`: the records' `dynamic_rows_of` parts stacked joint by joint."""
    a, y = _joint_blocks([p[0] for p in parts], [p[1] for p in parts], tuple(p[4] for p in parts))
    return a, y, tuple(int(p[2]) for p in parts)


def _interval_integrals(ts, values_left, values_right):
    h = jnp.diff(ts)
    h = h.reshape(h.shape + (1,) * (values_left.ndim - 1))
    return 0.5 * h * (values_left + values_right)


def _joined(energy_part, dissipative_part, columns):
    """The rows with every column in its place: `energy_part` in the energy columns, the rest from
    `dissipative_part`."""
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
    _, dq = positions_and_velocities(system, xs)
    w, f = energy_and_friction_rows(system, xs, friction)
    energy, dissipative = columns
    return w[:, list(energy)], f[:, list(dissipative)], generalised_force(system, us), dq


def _integrate_intervals(ts, dq, tau, f):
    tau = tau[:-1]  # on [t_j, t_{j+1}] the input is us[j]
    work = _interval_integrals(ts, row_dot(dq[:-1], tau), row_dot(dq[1:], tau))
    dissipated = _interval_integrals(ts, f[:-1], f[1:])
    return work, dissipated


def power_rows(system, traj, method: Power, friction):
    _needs(traj, 2 * method.trim + 3, "power")
    if method.lowpass_hz is not None:
        traj = uniformly_sampled(traj)
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
    dw = a1[:, None] * (w[1:-1] - w[:-2]) + a2[:, None] * (w[2:] - w[1:-1])
    f = a1[:, None] * dissipated[:-1] + a2[:, None] * dissipated[1:]
    p = a1 * work[:-1] + a2 * work[1:]
    return _joined(dw, f, columns), p


def energy_rows(system, traj, method: Energy, friction):
    window = method.window
    stride = method.stride or window
    _needs(traj, window + 1, "energy")
    if method.lowpass_hz is not None:
        traj = uniformly_sampled(traj)
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
    return _energy_balance(ts, w, f, tau, dq, (n_windows, window, stride), columns)


@eqx.filter_jit
def _energy_balance(ts, w, f, tau, dq, windows: tuple[int, int, int], columns):
    """The energy balance over `windows = (n_windows, window, stride)`, static integers: one window per
    `[i stride, i stride + window]` intervals, `i < n_windows`."""
    n_windows, window, stride = windows
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


def stacked_equations(system, trajectories, method, friction, weights, rcond):
    """The stacked least-squares problem `(a, y, weights, names, n_samples, label, settings, counts,
    record_rows)`; `counts` (for `Dynamic`) each record's rows per joint, else `()`; `record_rows`
    each record's rows per time step's block (`counts` for `Dynamic`, whose rows are stacked joint by
    joint; each record's rows for `Power` and `Energy`, stacked record by record)."""
    system = with_friction(system, friction)
    names = parameter_names(system, friction)
    a, y, n_samples, settings, counts, record_rows = method.equations(system, trajectories, friction)
    label = method.label
    return system, a, y, weights, names, n_samples, label, settings, counts, record_rows


def joint_weights(a, y, names, rcond, n_joints):
    """`Dynamic(weighting="joint")`'s row weights for equations stacked joint by joint: the inverse of
    each joint's residual variance from an ordinary least-squares fit of `(a, y)` (Gautier's weighted
    least squares). Pass the equations the weighted fit will solve (offsets already removed), so
    that what the parameters cannot explain, not a record's offset, sets each joint's weight."""
    first = least_squares(a, y, names=names, rcond=rcond)
    residual = (a @ first.value - y).reshape(n_joints, -1)
    variance = jnp.mean(residual**2, axis=1)
    variance = jnp.where(variance > 0, variance, jnp.max(variance) + jnp.finfo(a.dtype).tiny)
    return jnp.repeat(1.0 / variance, a.shape[0] // n_joints)


@eqx.filter_jit
def _joint_blocks(rows, forces, trims):
    """The records' dynamic equations `(time, joints, params)`, each without `trim` rows at either end,
    stacked joint by joint (all of joint 1's rows, then joint 2's), so that a per-joint weight is one
    block of rows; one compiled call (op by op, the copies took twice as long as the regressor)."""
    ys = jnp.concatenate([r[t : r.shape[0] - t] for r, t in zip(rows, trims)])
    forces = jnp.concatenate([f[t : f.shape[0] - t] for f, t in zip(forces, trims)])
    return jnp.transpose(ys, (1, 0, 2)).reshape(-1, ys.shape[2]), forces.T.reshape(-1)
