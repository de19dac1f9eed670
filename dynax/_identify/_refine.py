r"""Output-error refinement of a least-squares estimate, over the physically consistent set.

Least squares on the inverse-dynamics model differentiates noisy velocities into $\ddot q$: noise
in the regressor biases the estimate (errors in variables). The output-error fit has no such bias;
it only needs a start near the answer, which least squares gives. `refine_by_simulation` takes the
least-squares model, adds the rotor inertia of the elbow motor (`RotorInertia(1)`: with the
contract's base parameters this is the whole of a geared motor's effect, diagonal and the
off-diagonal coupling $-g_r I_r$, see `dynax._identify._consistency`), and fits every parameter by
`fit_simulation_error` (Levenberg-Marquardt, optimistix) through a `ConsistentParametrisation`, so
every iterate is physically consistent. A `Stiction` level the least-squares stage read from a rest
under load stays at or above the torque held there and the joint's Coulomb level (both lower bounds;
`dynax._identify._static_friction` says why a bound and not a free or a fixed level).

The data it fits are the records cut to 40 samples per period of their signal band's edge
(`choose_filter`; inputs averaged over each new interval), so that the integrator takes as few
steps as the motion needs, with the measured encoder positions and velocities from a local cubic
fit of those positions: each segment starts from the measured position and a velocity about a
hundred times less noisy than a one-sample difference (a driver's), without the amplitude loss of a low-pass filter
at the band's edge (which on a large-amplitude run distorts the very motion that is fitted). The
segments are `method`'s (`identify` uses one band period, in four staggered cuts, see
`SimulationFit.stagger`). Each state's residual is divided by its measurement-noise level
(`measurement_noise_std`): maximum likelihood under white measurement noise, which lets the
precise encoder positions, not the noisy velocity estimate, decide.

When the torques are measurements sampled at the state samples (a motor current read with the
encoders) rather than commands held between them, the contract's zero-order hold applies each
sample half a step late, and a driver's latency adds to that; an output-error fit is sensitive to
it (a half-sample shift of the torques can move a held-out prediction error by tens of per cent),
while the least-squares equations are not. So the fit also estimates the **input
timing**: over each interval of its grid the model is driven by the recorded input read $\alpha$
steps later than the interval's own sample, linearly interpolated between samples (`TimedInputs`,
$|\alpha| \le 3$; $\alpha = 0$ is the zero-order hold as recorded). It is
reported as the latency $\tau = \Delta t/2 - \alpha h$ [s], the time by which an input acts
after the sample that records it (negative: before it), with $\Delta t$ the records' interval and
$h$ the fit's grid: 0 for a torque sampled without delay, $\Delta t/2$ for a command held as the
contract says. The returned
model is the physical one, without the timing: it is simulated, like any other, under the
contract's zero-order hold.

Records differ in how well the model can follow them (a chaotic large-amplitude swing-up leaves a
larger output error than a gentle run, through model error the noise level does not capture), so
by default (`record_weights="ml"`) each record's residual variance is an unknown of its own:
maximum likelihood for independent Gaussian errors with one variance $\sigma_r^2$ per record,
whose profile likelihood is $-\tfrac12 \sum_r N_r \log \mathrm{SSR}_r(\theta)$. It is maximised by
iterative reweighting: fit with the weights $1/\hat\sigma_r^2$, estimate
$\hat\sigma_r^2 = \mathrm{SSR}_r / (N_r - p_r)$ from each record's own residuals ($p_r$ the initial
states fitted on it), refit from the previous estimate, until the weights settle (Bard,
*Nonlinear Parameter Estimation*, 1974, sec. 4-6 and 7-6; Walter & Pronzato, *Identification of
Parametric Models from Experimental Data*, 1997, sec. 3.3-3.4; Ljung, *System Identification*,
2nd ed., 1999, sec. 7.4). A variance below the measurement noise's is not believed: $\hat\sigma_r$
has a floor of 1 in the residual's unit (the noise level) and of a tenth of the records' median,
so that no record a short or easy one fits almost exactly takes over the fit.
"""

import abc
import contextlib
import contextvars
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._context import set_within
from .._data._derivatives import butterworth_filtfilt, resample
from .._data._rest import zeroed_at_rest
from .._data._spectra import choose_filter, measurement_noise_std, velocities_from_positions
from .._data._trajectory import Trajectory
from .._fit import AbstractStatistics, Parameters, Solution
from .._model._extensions import Extended
from .._model._system import AbstractSystem
from .._simulate import complete_state, FixedGrid, simulate
from .._simulate._sim_error import HISTORY_GRID, history_steps, nominal_states
from ._consistency import consistent_parametrisation, ConsistentParametrisation
from ._regressors import parameter_vector, split_terms, with_parameters
from ._simulation_fit import (
    DIVERGED,
    fit_simulation_error,
    OutputErrorStatistics,
    segment_histories,
    simulation_segments,
    SimulationFit,
)

RECORD_WEIGHTS = ("ml", "motion", "equal")
DEFAULT_RECORD_WEIGHTS = "ml"  # what `identify`'s refinement uses
MAX_REWEIGHTS = 3  # refits after the first fit, at most
SETTLED = 0.1  # weights settled: no record's weight changed by more than 10 %
SAMPLES_PER_PERIOD = 40.0  # grid of the fit: samples per period of the signal band's edge


class AbstractWrapper(AbstractSystem):
    """A system that stands for another one (`wrapped`: its terms, whatever its parameter values) during a fit.

    It passes on what `complete_state` reads to start the wrapped model's internal states along the record
    (`state_terms`, `nominal_n_states`; each wrapper gives `applied_input` under its own inputs), so a fit through
    the wrapper starts them as `fit_simulation_error` does for the model itself (`history_steps`).
    """

    @property
    @abc.abstractmethod
    def wrapped(self) -> AbstractSystem:
        """The model the wrapper stands for (its structure; parameter values may be the wrapper's to set)."""

    @property
    def state_terms(self) -> tuple:
        """The wrapped model's terms with states of their own besides the input terms' (`Extended.state_terms`)."""
        return getattr(self.wrapped, "state_terms", ())

    @property
    def nominal_n_states(self) -> int:
        """The measured states; the rest are the wrapped model's internal states."""
        return nominal_states(self.wrapped)


class ConsistentSystem(AbstractWrapper):
    r"""A system whose parameters are a point $\phi$ of a `ConsistentParametrisation`.

    Its only inexact leaf is `phi`; `model` is the system it stands for, with
    $\theta = \theta(\phi)$ in the parameters `names`. Fitting `phi` (e.g. with
    `fit_simulation_error`) searches the consistent set only. Its internal states, if `model` has any, start as
    `model`'s do (`applied_input`, `state_terms`, `nominal_n_states` pass them on to `complete_state`).
    """

    phi: jax.Array
    template: AbstractSystem
    parametrisation: ConsistentParametrisation
    names: tuple[str, ...] = eqx.field(static=True)

    @property
    def state_names(self):
        return self.template.state_names

    @property
    def input_names(self):
        return self.template.input_names

    @property
    def model(self) -> AbstractSystem:
        return with_parameters(self.template, self.names, self.parametrisation.theta(self.phi))

    def vector_field(self, t, x, u):
        return self.model.vector_field(t, x, u)

    def initial_state(self, x0, u0):
        """The model's full state from a measured one (its internal states: `Extended.initial_state`)."""
        return self.model.initial_state(x0, u0)  # pyright: ignore[reportAttributeAccessIssue] (called where it has one)

    # What `complete_state` reads to start the model's internal states along the record before a segment, as
    # `fit_simulation_error` does for the model itself (`history_steps`; called only where it has internal states).
    def applied_input(self, u, z):
        """The model's applied input and its input terms' state derivative (`Extended.applied_input`)."""
        return self.model.applied_input(u, z)  # pyright: ignore[reportAttributeAccessIssue] (called where it has one)

    @property
    def wrapped(self) -> AbstractSystem:
        return self.template


INPUT_REACH = 3  # samples of the fit's grid either side that the input timing may reach


class TimedInputs(AbstractWrapper):
    r"""`system` driven by its input read `alpha` steps of the grid later than each interval's sample.

    Its inputs are, per sample $k$, the samples $u_{k-R}, \dots, u_{k+R}$ of `system`'s inputs
    (`with_neighbour_inputs`, $R$ = `reach`); over the interval that starts at sample $k$ it applies
    the recorded input linearly interpolated at $k + \alpha$, with $\alpha$ clipped to $[-R, R]$:
    $\alpha = 0$ is the zero-order hold as recorded, $\alpha = 1/2$ the interval's mean of a signal
    sampled at the samples, $\alpha > 0$ an input that acts before the sample that records it. `system`'s internal
    states, if any, start along a record's history under the input read alike (`applied_input`, as
    `complete_state` reads it).
    """

    system: AbstractSystem
    alpha: jax.Array
    reach: int = eqx.field(static=True, default=INPUT_REACH)

    @property
    def state_names(self):
        return self.system.state_names

    @property
    def input_names(self):
        return _neighbour_names(self.system.input_names, self.reach)

    def vector_field(self, t, x, u):
        return self.system.vector_field(t, x, self._timed(u))

    def _timed(self, u):
        """The recorded input read `alpha` steps later, from the stencil `u` of its samples."""
        n = u.shape[-1] // (2 * self.reach + 1)
        stencil = u.reshape(u.shape[:-1] + (2 * self.reach + 1, n))
        position = jnp.clip(self.alpha, -self.reach, self.reach) + self.reach
        i = jnp.clip(jnp.floor(position), 0, 2 * self.reach - 1).astype(int)
        f = position - i
        return (1 - f) * stencil[..., i, :] + f * stencil[..., i + 1, :]

    # As `ConsistentSystem`'s: what `complete_state` reads to start `system`'s internal states along the record.
    def applied_input(self, u, z):
        """`system`'s applied input and input terms' state derivative, under the input read `alpha` steps later."""
        return self.system.applied_input(self._timed(u), z)  # pyright: ignore[reportAttributeAccessIssue]

    @property
    def wrapped(self) -> AbstractSystem:
        return self.system

    def initial_state(self, x0, u0):
        """`system`'s full state from a measured one, under the input recorded at the start (the stencil's
        centre)."""
        n = u0.shape[-1] // (2 * self.reach + 1)
        centre = u0[..., self.reach * n : (self.reach + 1) * n]
        return self.system.initial_state(x0, centre)  # pyright: ignore[reportAttributeAccessIssue] (where it has one)


def _neighbour_names(names, reach):
    return tuple(f"{n}[k{j:+d}]" if j else n for j in range(-reach, reach + 1) for n in names)


def with_neighbour_inputs(record: Trajectory, reach: int = INPUT_REACH) -> Trajectory:
    r"""`record` whose inputs at each sample $k$ are its samples $k - R, \dots, k + R$ (`reach` $R$; the
    ends repeat their first and last samples), as `TimedInputs` reads them."""
    us = record.us
    padded = jnp.concatenate([jnp.repeat(us[:1], reach, axis=0), us, jnp.repeat(us[-1:], reach, axis=0)])
    shifted = [padded[reach + j : reach + j + us.shape[0]] for j in range(-reach, reach + 1)]
    return Trajectory(
        record.ts,
        record.xs,
        jnp.concatenate(shifted, axis=1),
        record.state_names,
        _neighbour_names(tuple(record.input_names), reach),
        record.system,
        record.source,
    )


def with_refinement_terms(system: AbstractSystem) -> AbstractSystem:
    """`system` with the terms its `refinement_terms()` names (a two-link arm's `RotorInertia(joint=1)`,
    at zero) where it has no term of that kind at that joint."""
    base, terms = split_terms(system)
    have = {(type(t), t.joint) for t in terms}
    extra = tuple(t for t in base.refinement_terms() if (type(t), t.joint) not in have)
    return Extended(base, terms + extra) if extra else system


class RefinementStatistics(AbstractStatistics):
    r"""What `refine_by_simulation` adds to its `Solution` (as `solution.statistics`).

    **Fields:**

    - `initial_residual_rms`, `residual_rms`: the scaled state residual at the start and at the end.
    - `relative_error`: $\lVert \hat x - x \rVert / \lVert x \rVert$ of the states fitted (NaN for a kept start).
    - `dt`, `segment_s`: the grid and segment length fitted.
    - `n_samples`: samples fitted.
    - `record_weights`: the final weight of each record's residuals; `record_sigma`: each record's
      residual scale at the end, in units of the measurement noise; `reweights`: refits done.
    - `input_alpha`, `input_latency_s`: the input timing, $\alpha$ in steps of the fit's grid (see
      `TimedInputs`) and the latency $\Delta t/2 - \alpha h$ of the inputs behind their samples
      [s] (see the module's docstring); `None` when not fitted.
    - `kept_start`: the fit ended worse than its start (a warning said so), and the solution is the
      start, unrefined.
    - `record_std_errors`: from the delete-one-record jackknife (`OutputErrorStatistics.record_covariance`)
      through the parametrisation's Jacobian: how far each parameter moves when one record is left
      out; `None` with fewer than three records.
    - `diverged_segments`: `(at its end, at its start, segments)`, the segments whose rollouts
      diverged in the last fit that ran (a fit that ends with more of them than it started with
      counts as worse).
    """

    initial_residual_rms: float = eqx.field(static=True)
    residual_rms: float = eqx.field(static=True)
    relative_error: float = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    segment_s: float = eqx.field(static=True)
    n_samples: int = eqx.field(static=True)
    record_weights: tuple[float, ...] = eqx.field(static=True, default=())
    record_sigma: tuple[float, ...] = eqx.field(static=True, default=())
    reweights: int = eqx.field(static=True, default=0)
    input_alpha: float | None = eqx.field(static=True, default=None)
    input_latency_s: float | None = eqx.field(static=True, default=None)
    kept_start: bool = eqx.field(static=True, default=False)
    record_std_errors: np.ndarray | None = None
    diverged_segments: tuple[int, int, int] = eqx.field(static=True, default=(0, 0, 0))


def motion_records(
    records: list[Trajectory], *, filtered: bool | str = "positions", rests=None
) -> tuple[list[Trajectory], float]:
    """The records on a grid of about 40 samples per period of their signal band's edge.

    Each record (resampled at its median interval if irregular) is cut to every `d`-th sample,
    `d` the integer nearest to that grid; its inputs become the mean over each block of `d`
    samples (the same impulse as the recorded zero-order hold, without aliasing the torque noise);
    its states are, with `filtered="positions"` (default), the measured positions and the
    velocities of a local cubic fit of them (`velocities_from_positions`); with `True`, the
    states low-passed at their signal band (`choose_filter`); with `False`, as measured. With `rests`
    (each record's `rest_stretches`), the velocities are zero where a joint rests and its measured speed
    is within the noise (`dynax.internal.speeds_zeroed_at_rest`'s rule, read on the measured record):
    the start state of a window at rest, as `identify` validates it.

    **Returns:** `(records, dt)`.
    """
    uniform = [r if r.is_uniform else resample(r, r.dt) for r in records]
    choices = [choose_filter(r) for r in uniform]
    bands = [c.cutoff_hz for c in choices if c.cutoff_hz is not None]
    out, steps = [], []
    for k, (record, choice) in enumerate(zip(uniform, choices)):
        d = max(1, int(round(1.0 / (SAMPLES_PER_PERIOD * max(bands)) / record.dt))) if bands else 1
        xs, us = np.asarray(record.xs), np.asarray(record.us)
        if filtered == "positions" and choice.cutoff_hz is not None:
            xs = velocities_from_positions(xs, record.dt, choice.cutoff_hz)
        elif filtered and choice.cutoff_hz is not None:
            xs = np.asarray(butterworth_filtfilt(record.ts, xs, cutoff_hz=choice.cutoff_hz, order=choice.order))
        if rests is not None and rests[k]:
            xs = zeroed_at_rest(xs, record, rests[k])
        n = (len(record) // d) * d
        us = us[:n].reshape(n // d, d, -1).mean(axis=1)
        out.append(
            Trajectory(
                jnp.asarray(np.asarray(record.ts)[:n:d]),
                jnp.asarray(xs[:n:d]),
                jnp.asarray(us),
                record.state_names,
                record.input_names,
                record.system,
                record.source,
            )
        )
        steps.append(d * record.dt)
    return out, float(np.median(steps))


@eqx.filter_jit
def _segment_squares(system, x0, ts, xs, us, scale, simulation: FixedGrid, history=None):
    """Sum of squared scaled state residuals of each segment simulated from its initial state, its internal states
    (if any) started along `history` (`segment_histories`' `(ts_before, xs_before, us_before)`) as the output-error
    fit starts them; without one (a model without internal states), as `complete_state` of the first state."""
    n = xs.shape[-1]

    def rollout(x, t, u):  # the model's internal states, if any, start as `complete_state` completes them
        return simulate(system, complete_state(system, x, u[0]), t, u, method=simulation, throw=False).xs[:, :n]

    def along(x, t, u, tb, xb, ub):  # ... along the record before the segment
        start = complete_state(system, x, u[0], tb, ub, HISTORY_GRID, xb)
        return simulate(system, start, t, u, method=simulation, throw=False).xs[:, :n]

    sims = jax.vmap(rollout)(x0, ts, us) if history is None else jax.vmap(along)(x0, ts, us, *history)
    r = (sims - xs) / scale[None, None, :]
    r = jnp.where(jnp.isfinite(r), r, DIVERGED)  # as the fit counts a diverged rollout
    return jnp.sum(r**2, axis=(1, 2))


def record_residual_scale(system, initial_states, records, scale, method: SimulationFit) -> np.ndarray:
    r"""Each record's residual scale $\hat\sigma_r = \sqrt{\mathrm{SSR}_r / (N_r - p_r)}$ at a fit.

    `system` and `initial_states` are a `fit_simulation_error` solution on `records` (cut into the
    same segments, `method.segment_s`); residuals are in units of `scale` (per state); $p_r$ counts
    the initial states fitted on record $r$ (none unless `method.fit_initial_states`).

    The segments are simulated as the fit simulated them: a model with internal states (`history_steps`: an input
    lag's or delay's filter, `Stiction`'s memory of rest) starts them along the `HISTORY_S` of record before each
    segment (`segment_histories`, `complete_state` with `xs_before`), so $\hat\sigma_r$ is the fit's own residual
    scale; one without takes the same program as before. (Started at rest under each segment's first input, a true
    lagged axis's scale was the lag's start error, not the noise: `tests/identify/test_lag_history.py`.)
    """
    ts, xs, us, _, owner, _ = simulation_segments(records, method.segment_s, method.stagger)
    dtype = jnp.result_type(initial_states)
    n_before = history_steps(system, xs.shape[-1], float(records[0].dt))
    history = None
    if n_before:  # as `fit_simulation_error` cuts it
        history = tuple(
            jnp.asarray(a, dtype) for a in segment_histories(records, method.segment_s, method.stagger, n_before)
        )
    squares = np.asarray(
        _segment_squares(
            system,
            initial_states,
            *(jnp.asarray(a, dtype) for a in (ts, xs, us)),
            jnp.asarray(scale, dtype),
            method.simulation,
            history=history,
        )
    )
    per_segment = xs.shape[1] * xs.shape[2] - (xs.shape[2] if method.fit_initial_states else 0)
    ssr = np.bincount(owner, weights=squares, minlength=len(records))
    dof = np.bincount(owner, minlength=len(records)) * per_segment
    return np.sqrt(ssr / np.maximum(dof, 1))


def ml_weights(sigma: np.ndarray) -> np.ndarray:
    r"""Weights $1/\hat\sigma_r$ of the residuals (so $1/\hat\sigma_r^2$ of their squares), mean 1,
    with $\hat\sigma_r$ floored at the noise level (1) and at a tenth of the records' median."""
    floored = np.maximum(sigma, max(1.0, 0.1 * float(np.median(sigma))))
    weights = 1.0 / floored
    return weights / np.mean(weights)


REFINEMENT_OPTIONS: contextvars.ContextVar[dict | None] = contextvars.ContextVar(
    "dynax_refinement_options", default=None
)
_OPTIONS = ("filtered", "fit", "input_timing", "record_weights", "rests")


@contextlib.contextmanager
def refinement_options(**options):
    """Within the block, `identify`'s output-error refinement calls `refine_by_simulation` with these keyword
    arguments (`record_weights`, `input_timing`, `filtered`, `rests`; see there), and `fit`, where given, in place
    of `fit_simulation_error` (called alike, returning its `Solution`). For comparing the refinement with a
    variant of it inside the whole pipeline (another record weighting, no input timing, another solver), and for
    driving its handling of a fit that ends worse than its start, which no known input forces."""
    unknown = sorted(set(options) - set(_OPTIONS))
    if unknown:
        raise TypeError(f"refinement_options: unknown option(s) {unknown}; choose from {list(_OPTIONS)}")
    with set_within(REFINEMENT_OPTIONS, options):
        yield


def refine_by_simulation(
    system: AbstractSystem,
    names: tuple[str, ...],
    records: list[Trajectory],
    method: SimulationFit,
    *,
    filtered: bool | str = "positions",
    record_weights: str | None = None,
    input_timing: bool = True,
    rests=None,
) -> Solution:
    """Refine a two-link arm's least-squares model by the output-error fit, consistent by construction.

    **Arguments:** `system` (the least-squares model, carrying its estimate; rotor inertia at the
    elbow is added if missing), `names` its parameter names, `records` to fit, `method` the
    `SimulationFit` settings (segment length, steps), `record_weights` how the records' residuals
    are weighted: `"ml"` (default) each by its own residual scale, estimated by iterative
    reweighting (maximum likelihood with one unknown noise variance per record, see the module's
    docstring; starts from the `"motion"` weights), `"motion"` each inversely to its motion's
    amplitude (RMS of the joint positions about their mean), `"equal"` all alike; `None`:
    `DEFAULT_RECORD_WEIGHTS` (`"ml"`); `input_timing` (default `True`): also fit the input timing
    $\alpha$ (`TimedInputs`, see the module's docstring), else drive the model by the zero-order
    hold as recorded; `rests` (each record's `rest_stretches`): windows start at zero speed where a joint
    rests within its record's speed noise (`motion_records`). Inside `refinement_options(fit=...)`, that
    function is called in place of `fit_simulation_error`.

    A model with internal states (`Stiction` with a `dwell_time`, its memory of rest, as `identify` adds it) starts
    them along the record before each segment, as `fit_simulation_error` starts a bare model's (`history_steps`,
    `segment_histories`): `ConsistentSystem` and `TimedInputs` pass on what `complete_state` reads. So do the
    record weights' residual scales (`record_residual_scale`). A model without takes the programs it always took.

    **Returns:** the engine's `Solution` in the contract's base parameters: `model` the refined
    system, `value`, `names`, `std_errors` and `covariance` (the fit's, cluster-robust over blocks
    of time, carried through the parametrisation's Jacobian), `steps` over every refit, and
    `statistics` a `RefinementStatistics`.
    """
    record_weights = DEFAULT_RECORD_WEIGHTS if record_weights is None else record_weights
    if record_weights not in RECORD_WEIGHTS:
        raise ValueError(
            f"refine_by_simulation: `record_weights` must be one of {RECORD_WEIGHTS}, got {record_weights!r}"
        )
    base = split_terms(system)[0]
    if base.refinement_terms() is None:
        raise TypeError(
            f"refine_by_simulation: {type(base).__name__} names no refinement_terms(); it refines two-link arms"
        )
    model = with_refinement_terms(system)
    friction = "coulomb" if any(n.startswith("fc") for n in names) else "viscous"
    from ._regressors import parameter_names

    names = parameter_names(model, friction)
    start = parameter_vector(model, friction)
    scale = jnp.maximum(jnp.abs(start), 1e-3 * jnp.max(jnp.abs(start[:5])))
    parametrisation = consistent_parametrisation(model, names, scale)
    wrapped = ConsistentSystem(parametrisation.phi(start), model, parametrisation, names)
    fitted, dt = motion_records(records, filtered=filtered, rests=rests)
    if input_timing:
        wrapped = TimedInputs(wrapped, jnp.zeros((), jnp.result_type(wrapped.phi)))
        fitted = [with_neighbour_inputs(r) for r in fitted]
    filter_spec = jax.tree.map(lambda _: False, wrapped)
    filter_spec = eqx.tree_at(
        lambda s: (s.system.phi, s.alpha) if input_timing else s.phi,
        filter_spec,
        (True, True) if input_timing else True,
    )
    # Maximum likelihood under white measurement noise: each state weighted by its noise level.
    noise = np.median(
        np.stack([measurement_noise_std(r if r.is_uniform else resample(r, r.dt)) for r in records]), axis=0
    )
    # First guess of each record's residual scale: its motion's amplitude (a large-amplitude,
    # chaotic run must not swamp the rest).
    motion = np.array(
        [
            float(np.sqrt(np.mean(np.square(np.asarray(r.xs[:, :2]) - np.mean(np.asarray(r.xs[:, :2]), 0)))))
            for r in fitted
        ]
    )
    weights = np.ones(len(fitted)) if record_weights == "equal" else (1.0 / motion) / np.mean(1.0 / motion)

    output_error = (REFINEMENT_OPTIONS.get() or {}).get("fit", fit_simulation_error)

    def fit_with(start, weights):
        return output_error(
            start,
            fitted,
            method,
            filter_spec=filter_spec,
            state_scale=jnp.asarray(noise),
            record_weights=weights,
        )

    result = last = fit_with(wrapped, weights)
    initial_rms, steps = float(result.statistics.initial_residual_rms), int(result.steps)
    diverged = _ended_worse(result)
    if diverged:  # keep the start: the least-squares model, rotor inertia at zero
        warnings.warn(
            f"refine_by_simulation: the output-error fit ended worse than its start ({_how_worse(result)}); "
            "the least-squares model is kept",
            RuntimeWarning,
            stacklevel=2,
        )
    else:
        sigma = record_residual_scale(result.model, result.statistics.initial_states, fitted, noise, method)
    reweights = 0
    while not diverged and record_weights == "ml" and reweights < MAX_REWEIGHTS:
        new = ml_weights(sigma)
        if np.max(np.abs(np.log(new / weights))) < np.log1p(SETTLED):
            break  # the weights the last fit used are (within 10 %) those its residuals imply
        refit = fit_with(result.model, new)
        steps += int(refit.steps)
        last = refit
        if _ended_worse(refit):
            warnings.warn(
                f"refine_by_simulation: a reweighted output-error fit ended worse than its start "
                f"({_how_worse(refit)}); the fit before it is kept",
                RuntimeWarning,
                stacklevel=2,
            )
            break
        weights, result = new, refit
        reweights += 1
        sigma = record_residual_scale(result.model, result.statistics.initial_states, fitted, noise, method)
    final = wrapped if diverged else result.model
    consistent = final.system if input_timing else final
    refined = consistent.model
    estimate = np.asarray(parameter_vector(refined, friction))
    # Standard errors through the parametrisation's Jacobian (delta method).
    jac = np.asarray(jax.jacfwd(parametrisation.theta)(consistent.phi))
    n_phi = consistent.phi.shape[0]
    phi_cov = np.full((n_phi, n_phi), np.nan) if diverged else np.asarray(result.covariance)[:n_phi, :n_phi]
    alpha = latency = None
    if input_timing and not diverged:  # a kept start has measured no timing
        alpha = float(jnp.clip(final.alpha, -INPUT_REACH, INPUT_REACH))
        record_dt = float(np.median([float(np.median(np.diff(np.asarray(r.ts)))) for r in records]))
        latency = 0.5 * record_dt - alpha * dt
    spread = result.statistics.record_covariance
    spread = None if diverged or spread is None else np.asarray(spread)[:n_phi, :n_phi]
    covariance = delta_method_covariance(jac, phi_cov)
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))  # NaN stays NaN
    record_std = None if spread is None else np.sqrt(np.maximum(np.diag(delta_method_covariance(jac, spread)), 0.0))
    # A kept start: its own residual, no relative error or record scales of a fit.
    assert isinstance(result.statistics, OutputErrorStatistics)
    rms, relative = (
        (initial_rms, float("nan"))
        if diverged
        else (float(result.statistics.residual_rms), float(result.statistics.relative_error))
    )
    statistics = RefinementStatistics(
        initial_residual_rms=initial_rms,
        residual_rms=rms,
        relative_error=relative,
        dt=dt,
        segment_s=method.segment_s,
        n_samples=result.statistics.n_samples,
        record_weights=tuple(float(w) for w in weights),
        record_sigma=() if diverged else tuple(float(v) for v in sigma),
        reweights=reweights,
        input_alpha=alpha,
        input_latency_s=latency,
        kept_start=diverged,
        record_std_errors=record_std,
        diverged_segments=(
            last.statistics.diverged_segments,
            last.statistics.initial_diverged_segments,
            last.statistics.n_segments,
        ),
    )
    value = jnp.asarray(estimate)
    return Solution(
        model=refined,
        value=value,
        parameters=Parameters.of(value, names=names),
        covariance=jnp.asarray(covariance),
        std_errors=jnp.asarray(std),
        result=optx.RESULTS.nonlinear_divergence if diverged else optx.RESULTS.successful,
        loss=result.initial_loss if diverged else result.loss,
        initial_loss=result.initial_loss,
        steps=jnp.asarray(steps),
        n_residuals=result.n_residuals,
        statistics=statistics,
    )


def delta_method_covariance(jac: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    r"""$J C J^\top$, the covariance of $\theta(\varphi)$ from that of $\varphi$ (the delta method), where an
    unknown the data do not determine has NaN in its row and column of $C$: the parameters that depend on it
    (a non-zero column of $J$) get NaN rows and columns, and the others their finite covariance. A plain
    product would give every parameter NaN, since $0 \cdot \mathrm{NaN}$ is NaN."""
    undetermined = ~np.isfinite(np.diag(covariance))
    out = jac @ np.where(np.isfinite(covariance), covariance, 0.0) @ jac.T
    depends = np.any(jac[:, undetermined] != 0, axis=1)
    out[depends, :] = np.nan
    out[:, depends] = np.nan
    return out


def _ended_worse(result) -> bool:
    """Whether an output-error fit ended worse than its start: as the engine reports it, or with
    the rollouts of more segments diverging than at its start. A diverged segment costs the fit a
    fixed `DIVERGED` per residual, less than a bad enough model's finite error, so a fit from a poor
    start (data that hardly excite the dynamics) can lower its cost by making every rollout
    diverge: its Jacobian is then zero and it stops there."""
    return bool(result.result == optx.RESULTS.nonlinear_divergence) or result.statistics.ended_worse


def _how_worse(result) -> str:
    stats = result.statistics
    if stats.ended_worse:
        return (
            f"the rollouts of {stats.diverged_segments} of its {stats.n_segments} segments diverge, "
            f"{stats.initial_diverged_segments} at its start"
        )
    return f"scaled residual {float(stats.initial_residual_rms):.4g} -> {float(stats.residual_rms):.4g}"
