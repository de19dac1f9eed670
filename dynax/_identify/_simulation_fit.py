r"""Output-error identification: fit parameters by minimising the simulation error, with multiple shooting.

The record is cut into segments of `segment_s` seconds. Each segment is simulated from its own
initial state (a free variable, started at the measured state), and the residuals are the
simulated-minus-measured states of every segment, scaled per state by the data's spread, plus the
continuity defects between consecutive segments (the end of one segment against the start of the
next), weighted by `continuity_weight`. Short segments keep the problem well conditioned on long
or unstable records (a single shooting fit of a chaotic double pendulum has a cost surface full of
local minima); the continuity defects tie the segments back into one trajectory.

The problem is solved by the engine's `fit_least_squares` (Levenberg-Marquardt, optimistix) using
forward-mode Jacobians through the fixed-grid integrator: the number of unknowns (parameters plus
segment states) is small compared with the number of residuals, which is where forward mode is the
right tool. What is fitted is a `Parameters` filter over `(system, initial states)`, so the
parameters carry the names of their tree paths (or the system's `parameter_labels()`).
"""

from collections.abc import Sequence
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PyTree
import numpy as np

from .._data._trajectory import Trajectory
from .._errors import DataError, UsageError
from .._fit import (
    AbstractStatistics,
    clustered_covariance,
    fit_least_squares,
    jackknife_covariance,
    LeastSquaresOptions,
    levenberg_marquardt,
    Parameters,
    Solution,
    Statistics,
)
from .._model._system import AbstractSystem
from .._progress import bar_token, ProgressBar
from .._simulate import complete_state, FixedGrid, simulate
from .._simulate._sim_error import HISTORY_GRID, history_steps
from ._least_squares import least_squares
from ._method import AbstractMethod, as_records, FitSettings
from ._regressors import parameter_names, parameter_vector, split_terms, with_friction, with_parameters


class SimulationFit(AbstractMethod):
    """The output-error (simulation-error) method for `identify`; see `fit_simulation_error`.

    Its `fit(system, records, settings)` fits the named coefficients the regressors know (the
    nominal system's base parameters and its joint terms' coefficients, with
    `settings.friction="coulomb"` the Coulomb friction too), in the contract's order, or for any
    other system its `parameter_filter()`, starting from `system`'s values.

    **Arguments:**

    - `segment_s`: multiple-shooting segment length [s] (default 1.0).
    - `fit_initial_states`: fit each segment's initial state (default `True`) or start from the
      measured one.
    - `continuity_weight`: weight of the continuity defects between segments (default 10).
    - `stagger`: how many cuts of the records into segments to fit at once, each starting a
      `1/stagger` of a segment after the last (default 1; more needs `fit_initial_states=False`).
    - `rtol`, `atol`: Levenberg-Marquardt tolerances (default 1e-8).
    - `max_steps`: iteration budget (default 100).
    - `simulation`: the `simulate` method (default `FixedGrid()`, which forward-mode autodiff can
      differentiate, as Levenberg-Marquardt's Jacobian needs).
    """

    segment_s: float = 1.0
    fit_initial_states: bool = True
    continuity_weight: float = 10.0
    rtol: float = 1e-8
    atol: float = 1e-8
    max_steps: int = eqx.field(static=True, default=100)
    simulation: FixedGrid = FixedGrid()
    stagger: int = eqx.field(static=True, default=1)

    @property
    def label(self) -> str:
        return "simulation"

    @property
    def stage_kind(self) -> str:
        return "simulation"

    def n_samples(self, solution: Solution, records: list[Trajectory]) -> int:
        del records
        statistics = solution.statistics
        assert isinstance(statistics, OutputErrorStatistics)
        return statistics.n_samples

    def fit(self, system, records, settings: FitSettings = FitSettings()) -> Solution:
        """The output-error fit of `system`'s named coefficients (the regressors' names, for the systems
        they know) or of its `parameter_filter()`, from `system`'s values."""
        trajectories = as_records(records)
        friction = settings.friction
        try:
            system = with_friction(system, friction)
            names = parameter_names(system, friction)
        except UsageError:
            names = None  # any other system: its own parameter filter, named by its labels or tree paths
        if names is not None:
            # Start from the system's values; the coefficients not in `names` (a linear axis's Coulomb
            # term under viscous friction) are fixed.
            system = with_parameters(system, names, jnp.asarray(parameter_vector(system, friction)))
            parameters = named_parameters(system, names)
        else:
            parameters = Parameters.of(system)
        solution = fit_simulation_error(system, trajectories, self, filter_spec=parameters)
        if names is not None and tuple(names) != parameters.names:  # the contract's order, not the tree's
            order = np.asarray([parameters.names.index(name) for name in names])
            value = solution.value[order]
            solution = eqx.tree_at(
                lambda s: (s.value, s.parameters, s.std_errors, s.covariance),
                solution,
                (
                    value,
                    Parameters.of(value, names=tuple(names)),
                    solution.std_errors[order],
                    solution.covariance[np.ix_(order, order)],
                ),
            )
        return solution


def named_parameters(system, names) -> Parameters:
    """The `Parameters` of the named coefficients (fields of the nominal system and of its joint
    terms) of a system the regressors know, named as `parameter_names` names them, in tree order."""
    base, terms = split_terms(system)
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


class OutputErrorStatistics(AbstractStatistics):
    r"""What an output-error fit adds to its `Solution` (as `solution.statistics`).

    **Fields:**

    - `initial_states`: fitted (or measured) initial state of each segment, `(segment, n_states)`.
    - `jacobian`: the `Statistics` of the column-scaled Jacobian of all unknowns (parameters, then
      fitted initial states): condition number, rank, singular values and directions.
    - `record_covariance`: with measured initial states and at least `MIN_RECORDS_FOR_SPREAD`
      records, the covariance of the fitted parameters by the linearised delete-one-record
      jackknife (`dynax._fit.jackknife_covariance`): how far the estimate moves when one record is
      left out. It carries what differs from one record to the next (a friction or offset of that
      day), which no error estimated within records can; else `None`.
    - `residual_rms`, `initial_residual_rms`: root-mean-square of the scaled state residuals at
      the solution and at the start.
    - `relative_error`: $\lVert \hat x - x \rVert / \lVert x \rVert$ over all segment samples (unscaled).
    - `n_segments`, `n_samples`: bookkeeping.
    - `diverged_segments`, `initial_diverged_segments`: how many segments' rollouts diverged (a
      non-finite state) at the solution and at the start. The fit counts such a segment's residuals
      as `DIVERGED` each, which is smaller than those of a model bad enough: a solution where more
      segments diverge than at the start has gamed that count, not fitted the data.
    """

    initial_states: Float[Array, "segment n_states"]
    jacobian: Statistics
    residual_rms: Float[Array, ""]
    initial_residual_rms: Float[Array, ""]
    relative_error: Float[Array, ""]
    record_covariance: Array | None = None
    n_segments: int = eqx.field(static=True, default=0)
    n_samples: int = eqx.field(static=True, default=0)
    diverged_segments: int = eqx.field(static=True, default=0)
    initial_diverged_segments: int = eqx.field(static=True, default=0)

    @property
    def ended_worse(self) -> bool:
        """More segments' rollouts diverge at the solution than at the start."""
        return self.diverged_segments > self.initial_diverged_segments


DIVERGED = 1e3  # a diverged rollout's residual at every state and sample from the divergence on
CLUSTER_SEGMENTS = 4  # segment lengths per block of the clustered covariance
MIN_RECORDS_FOR_SPREAD = 3  # records the delete-one-record jackknife needs (two give one difference)


def segment_clustered_covariance(jac, r, ts, owner, trajectories, segment_s: float) -> np.ndarray | None:
    r"""The cluster-robust (sandwich) covariance of the scaled unknowns, clusters being blocks of time.

    A segment simulated from its *measured* initial state carries that state's noise all along it,
    and where the model is not exact its error drifts with the manoeuvre: the residuals of a segment,
    of the staggered cuts that overlap it and of its neighbours are correlated, and the Gauss-Newton
    covariance $\hat\sigma^2 (J^\top J)^{-1}$, which counts every residual as independent, is too
    small (6 to 9 times in the standard errors on a MuJoCo-made arm, `tests/identify/test_mujoco_data.py`).
    The engine's sandwich (`dynax._fit.clustered_covariance`) allows any correlation and any variance
    within a cluster. Clusters: each record cut into blocks of `CLUSTER_SEGMENTS` segment lengths, a segment in the
    block where it starts (only the segments that straddle a block's end correlate across it). With
    fewer than twice as many blocks as unknowns, blocks of one segment length; with fewer still,
    `None` (too few clusters to estimate a covariance from: the caller keeps Gauss-Newton's). With few
    blocks the sandwich runs low (measured on a linear model with a shock per segment: 13 % low in the
    standard errors with 15 blocks, 2 % with 50; a few 10 s records give about 70).
    """
    n_segments, n_unknowns = ts.shape[0], jac.shape[1]
    offsets = np.array([float(trajectories[o].ts[0]) for o in owner])
    since = np.asarray(ts[:, 0]) - offsets
    for block in (CLUSTER_SEGMENTS * segment_s, segment_s):
        keys = np.stack([owner, np.floor(since / block + 1e-9).astype(int)], axis=1)
        _, cluster = np.unique(keys, axis=0, return_inverse=True)
        n_clusters = int(cluster.max()) + 1
        if n_clusters >= 2 * n_unknowns:
            break
    else:
        return None
    # Without fitted initial states the residuals are the segments' states alone, segment by segment.
    rows = np.repeat(cluster.reshape(-1), r.shape[0] // n_segments)
    return np.asarray(clustered_covariance(jnp.asarray(jac), jnp.asarray(r), jnp.asarray(rows), n_clusters)[0])


def record_jackknife_covariance(jac, r, owner, n_records: int) -> np.ndarray | None:
    """The delete-one-record jackknife covariance of the scaled unknowns (see `OutputErrorStatistics`),
    or `None` with fewer than `MIN_RECORDS_FOR_SPREAD` records."""
    if n_records < MIN_RECORDS_FOR_SPREAD:
        return None
    rows = np.repeat(np.asarray(owner), r.shape[0] // len(owner))
    return np.asarray(jackknife_covariance(jnp.asarray(jac), jnp.asarray(r), jnp.asarray(rows), n_records)[0])


def simulation_segments(trajectories, segment_s, stagger: int = 1):
    """Cut every record into equal-length segments sharing their end samples.

    With `stagger` $k > 1$, $k$ such cuts of each record, the $j$-th starting $j/k$ of a segment
    later (segments start every $1/k$ of a segment): every sample is fitted from $k$ different
    distances to its segment's start. Only the first cut's segments are `follows`-linked (the
    continuity defects are for fitted initial states, which staggered cuts do not have).
    """
    length, cuts = _segment_starts(trajectories, segment_s, stagger)
    ts, xs, us, follows, owner = [], [], [], [], []
    n_samples = 0
    for j, (traj, (base, starts)) in enumerate(zip(trajectories, cuts)):
        for k, s in enumerate(starts):
            ts.append(np.asarray(traj.ts[s : s + length]))
            xs.append(np.asarray(traj.xs[s : s + length]))
            us.append(np.asarray(traj.us[s : s + length]))
            follows.append(0 < k < len(base))
            owner.append(j)
        n_samples += base[-1] + length
    return np.stack(ts), np.stack(xs), np.stack(us), np.asarray(follows), np.asarray(owner), n_samples


def _segment_starts(trajectories, segment_s, stagger):
    """`(length, [(base, starts) per record])`: `simulation_segments`'s segment length in samples, and per record
    the first cut's start samples and every cut's."""
    dt = float(np.median(np.diff(np.asarray(trajectories[0].ts))))
    shortest = min(len(t) for t in trajectories)
    if shortest < 2:
        raise DataError(f"{shortest} samples are too few for a simulation fit")
    length = min(max(int(round(segment_s / dt)) + 1, 2), shortest)
    cuts = []
    for traj in trajectories:
        base = list(range(0, len(traj) - length + 1, length - 1))
        shifted = [s + round(i * (length - 1) / stagger) for i in range(1, stagger) for s in base]
        cuts.append((base, base + [s for s in shifted if s + length <= len(traj)]))
    return length, cuts


def segment_histories(trajectories, segment_s, stagger: int, n_before: int):
    """`(ts_before, xs_before, us_before)`, each `(segment, n_before + 1, ...)`: the `n_before` samples of record
    before each of `simulation_segments`'s segments and its first sample (the record's first sample repeated, at
    its sample interval, before its start, as the diagnosis's `make_windows` pads), along which a model's internal
    states start (`complete_state`)."""
    _, cuts = _segment_starts(trajectories, segment_s, stagger)
    tb, xb, ub = [], [], []
    for traj, (_, starts) in zip(trajectories, cuts):
        dt = float(traj.dt)
        t_all, x_all, u_all = np.asarray(traj.ts), np.asarray(traj.xs), np.asarray(traj.us)
        for s in starts:
            idx = np.arange(s - n_before, s + 1)
            tb.append(t_all[s] + dt * (idx - s))
            xb.append(x_all[np.maximum(idx, 0)])
            ub.append(u_all[np.maximum(idx, 0)])
    return np.stack(tb), np.stack(xb), np.stack(ub)


class _Unknowns(eqx.Module):
    """What the output-error fit moves: the system and the segments' initial states."""

    system: AbstractSystem
    initial_states: Float[Array, "segment n_states"]


class _Segments(eqx.Module):
    """The data of the fit: segments, per-state scale, continuity links and weights."""

    ts: Array
    xs: Array
    us: Array
    sigma: Array
    link: Array
    continuity_weight: Array
    segment_weight: Array
    # The record before each segment (`segment_histories`), for a model with internal states (`history_steps`);
    # `None` for one without: the same program as before.
    ts_before: Array | None = None
    xs_before: Array | None = None
    us_before: Array | None = None


def _residuals(unknowns: _Unknowns, data: _Segments, *, simulation: FixedGrid, fit_initial_states: bool):
    """Scaled simulated-minus-measured states of every segment, then the weighted continuity defects."""
    model, x0 = unknowns.system, unknowns.initial_states
    n = data.xs.shape[-1]

    def rollout(x0, t, u):  # the model's internal states, if any, start as `complete_state` completes them
        return simulate(model, complete_state(model, x0, u[0]), t, u, method=simulation, throw=False).xs[:, :n]

    def along(x0, t, u, tb, xb, ub):  # ... along the record before the segment
        start = complete_state(model, x0, u[0], tb, ub, HISTORY_GRID, xb)
        return simulate(model, start, t, u, method=simulation, throw=False).xs[:, :n]

    if data.ts_before is None:
        sims = jax.vmap(rollout)(x0, data.ts, data.us)
    else:
        sims = jax.vmap(along)(x0, data.ts, data.us, data.ts_before, data.xs_before, data.us_before)
    r = (sims - data.xs) / data.sigma[None, None, :] * data.segment_weight[:, None, None]
    r = jnp.where(jnp.isfinite(r), r, DIVERGED)
    out = [r.reshape(-1)]
    if fit_initial_states and x0.shape[0] > 1:
        defect = (sims[:-1, -1] - x0[1:]) / data.sigma[None, :] * data.link[:, None] * jnp.sqrt(data.continuity_weight)
        out.append(jnp.where(jnp.isfinite(defect), defect, DIVERGED).reshape(-1))
    return jnp.concatenate(out)


@eqx.filter_jit
def _solve(unknowns, parameters: Parameters, data: _Segments, scale, solver, method: "SimulationFit", token=None):
    """The engine's Levenberg-Marquardt, and the Jacobian (scaled unknowns) at the solution; one
    compiled program per problem shape. Of `method`, the rollouts' `simulation`, `fit_initial_states`
    and `max_steps` are read (static); the tolerances are `solver`'s."""
    residuals = functools.partial(
        _residuals, simulation=method.simulation, fit_initial_states=method.fit_initial_states
    )
    solution = fit_least_squares(
        residuals,
        unknowns,
        parameters,
        data,
        solver=solver,
        scale=scale,
        max_steps=method.max_steps,
        options=LeastSquaresOptions(jac="dense", nonfinite=None, progress_token=token),
    )
    # The engine's residuals (at the solution and at the start) and Jacobian (scaled unknowns), as it
    # formed them: no further rollout of the data to compile or run.
    return solution, solution.residuals, solution.initial_residuals, solution.jacobian


def fit_simulation_error(
    system: AbstractSystem,
    trajectories: Trajectory | Sequence[Trajectory],
    method: SimulationFit = SimulationFit(),
    *,
    filter_spec: PyTree[bool] | Parameters | None = None,
    state_scale: Float[Array | np.ndarray, " n_states"] | None = None,
    record_weights: Float[Array | np.ndarray, " n_records"] | None = None,
    progress: bool | None = None,
    solver=None,
) -> Solution:
    r"""Fit the elements of `system` selected by `filter_spec` by minimising the simulation error.

    Generic over systems: any `AbstractSystem` whose `vector_field` is differentiable, with any
    filter of what to fit (the others stay fixed). The cost is

    $$\sum_{s,k} \lVert (\hat x_s(t_k) - x(t_k)) / \sigma \rVert^2
    + w \sum_s \lVert (\hat x_s(t_{end}) - x_{0,s+1}) / \sigma \rVert^2$$

    over segments $s$ simulated from their initial states $x_{0,s}$, where $\sigma$ is the
    per-state scale (default: the data's standard deviation of each state). It is minimised by the
    engine's `fit_least_squares` (Levenberg-Marquardt) on the unknowns scaled by $|p_0|$ (parameters)
    and $\sigma$ (initial states).

    **Arguments:**

    - `system`: the starting model.
    - `trajectories`: a `Trajectory` or a list of them.
    - `method`: the fit's settings, a `SimulationFit` (default `SimulationFit()`): `segment_s`,
      `fit_initial_states`, `continuity_weight` $w$, `stagger`, the Levenberg-Marquardt `rtol`,
      `atol` and `max_steps`, and the rollouts' `simulation` (`FixedGrid`), each described below.
    - `filter_spec`: what to fit: a filter over `system` as `dynax.Parameters.of` takes (a PyTree
      of bools or callables like `system`, with boolean arrays for single elements), or a
      `Parameters` of `system`; default the system's `parameter_filter()` (every inexact array
      leaf unless the system says otherwise), named by its `parameter_labels()` or tree paths.
    - `method.segment_s`: segment length [s] for multiple shooting (a value longer than the record means
      single shooting).
    - `method.fit_initial_states`: also fit each segment's initial state (default `True`).
    - `method.continuity_weight`: $w$, weight of the continuity defects (only with fitted initial
      states).
    - `method.rtol`, `method.atol`, `method.max_steps`: Levenberg-Marquardt settings.
    - `method.simulation`: `FixedGrid` settings of the rollouts.
    - `state_scale`: $\sigma$, shape `(n_states,)`.
    - `progress`: a bar per Levenberg-Marquardt iteration with the loss on stderr (`None`: when
      stderr is a terminal, see `dynax.internal.progress_mode`; `False` never).
    - `record_weights`: optional weight per trajectory multiplying its state residuals (default 1).
    - `solver`: the Levenberg-Marquardt to minimise with, as `dynax.internal.levenberg_marquardt` builds it
      (its tolerances then replace `method.rtol` and `method.atol`); default the engine's,
      `levenberg_marquardt(rtol=method.rtol, atol=method.atol, jacobian="accepted", damping="nielsen")`.
    - `method.stagger`: $k$, how many cuts of the records into segments are fitted together, each starting
      $1/k$ of a segment after the one before (default 1: one cut). A model that is not exact fits
      a record differently depending on where its segments start (how far each sample is from its
      segment's initial state); $k$ cuts average that out. Each cut's residuals are weighted by
      $1/\sqrt{k}$, so the cost stays the size of one cut's. Only with `fit_initial_states=False`
      (staggered segments start from the measured state).

    **Internal states.** A model with states beyond the measured ones that `complete_state` can integrate (an
    `Extended` with an input lag or delay, or a term with states of its own: `history_steps`) starts each segment's
    at rest under the input `HISTORY_S` (0.5 s) before the segment (the record's first sample repeated before its
    start) and integrates them along the recorded inputs and measured states up to the segment's start
    (`segment_histories`, `complete_state` with `xs_before`), as `simulation_error` and the diagnosis's windows
    do; at rest under the segment's first input, a 0.1 s lag biased a mass fitted on 0.3 s segments by 90 %
    (`tests/identify/test_lag_history.py`). The nominal part of the start is the fitted (or measured) initial
    state. `refine_by_simulation`'s wrappers of such a model (`ConsistentSystem`, `TimedInputs`) expose what this
    reads (`applied_input`, `state_terms`, `nominal_n_states`) and start alike. A model without internal states
    starts as before (`complete_state` of the first state): the same compiled program.

    **Standard errors.** With fitted initial states, and white measurement noise, the residuals are
    independent and the Gauss-Newton covariance $\hat\sigma^2 (J^\top J)^{-1}$ is the right one.
    From measured initial states they are not: a segment carries its start's noise all along, and
    the staggered cuts repeat the same samples. The covariance is then the cluster-robust sandwich
    over blocks of each record (`CLUSTER_SEGMENTS` segment lengths), which allows any correlation
    within a block; with too few blocks for it (fewer than twice the unknowns, even at one segment
    length each), Gauss-Newton's with the errors multiplied by $\sqrt{k}$ for the repeated samples.

    **Returns:** the engine's `Solution`: `model` is the fitted system, `value`, `names`,
    `covariance` and `std_errors` are the fitted parameters' (the initial states are in
    `statistics`, an `OutputErrorStatistics`, with the fit's residual sizes and divergence counts).

    ??? cite

        H. G. Bock and K. J. Plitt, "A multiple shooting algorithm for direct solution of optimal
        control problems", IFAC World Congress, 1984; L. Ljung, *System Identification: Theory
        for the User*, 2nd ed., 1999, ch. 7 (output-error models); J. J. More, "The
        Levenberg-Marquardt algorithm: implementation and theory", 1978.
    """
    segment_s, fit_initial_states, stagger = method.segment_s, method.fit_initial_states, method.stagger
    if isinstance(trajectories, Trajectory):
        trajectories = [trajectories]
    trajectories = list(trajectories)
    if not trajectories:
        raise UsageError("fit_simulation_error: `trajectories` is empty")
    if not segment_s > 0:
        raise UsageError(f"fit_simulation_error: `segment_s` must be positive, got {segment_s}")
    if not (isinstance(stagger, (int, np.integer)) and stagger >= 1):
        raise UsageError(f"fit_simulation_error: `stagger` must be a positive integer, got {stagger!r}")
    if stagger > 1 and fit_initial_states:
        raise UsageError(
            "fit_simulation_error: `stagger` > 1 needs `fit_initial_states=False` "
            "(staggered segments start from the measured state)"
        )
    chosen = filter_spec if isinstance(filter_spec, Parameters) else Parameters.of(system, filter_spec)
    if chosen.size == 0:
        raise UsageError("fit_simulation_error: `filter_spec` selects no array leaves to fit")
    ts, xs, us, follows, owner, n_samples = simulation_segments(trajectories, segment_s, stagger)
    p0 = chosen.vector(system)
    dtype = jnp.result_type(p0.dtype, xs.dtype)
    ts, xs, us = (jnp.asarray(a, dtype) for a in (ts, xs, us))
    if state_scale is None:
        flat = np.concatenate([np.asarray(t.xs) for t in trajectories])
        state_scale = np.std(flat, axis=0)
        state_scale = np.where(state_scale > 0, state_scale, 1.0)
    sigma = jnp.asarray(state_scale, dtype)
    weight = np.ones(len(trajectories)) if record_weights is None else np.asarray(record_weights, dtype=float)
    if weight.shape != (len(trajectories),) or not np.all(weight > 0):
        raise UsageError(f"fit_simulation_error: `record_weights` must be {len(trajectories)} positive numbers")
    n_before = history_steps(system, xs.shape[-1], float(trajectories[0].dt))
    history = (None, None, None)
    if n_before:
        history = tuple(jnp.asarray(a, dtype) for a in segment_histories(trajectories, segment_s, stagger, n_before))
    data = _Segments(
        ts,
        xs,
        us,
        sigma,
        jnp.asarray(follows[1:], dtype),  # segment s+1 continues segment s
        jnp.asarray(method.continuity_weight, dtype),
        jnp.asarray(weight[owner] / np.sqrt(stagger), dtype),
        *history,
    )
    # The unknowns: the system's chosen elements, then (when fitted) every segment's initial state,
    # scaled by |p0| (or 1) and by the state scale.
    unknowns = _Unknowns(system, xs[:, 0])
    x0_names = tuple(f"initial_states[{s},{i}]" for s in range(xs.shape[0]) for i in range(xs.shape[2]))
    parameters = Parameters(
        chosen.names + (x0_names if fit_initial_states else ()),
        chosen.selection + ((tuple(range(xs[:, 0].size)),) if fit_initial_states else ((),)),
    )
    p_scale = jnp.where(jnp.abs(p0) > 0, jnp.abs(p0), 1.0).astype(dtype)
    scale = jnp.concatenate([p_scale, jnp.tile(sigma, xs.shape[0])]) if fit_initial_states else p_scale
    if solver is None:
        solver = levenberg_marquardt(rtol=method.rtol, atol=method.atol, jacobian="accepted", damping="nielsen")
    # Only what shapes the compiled program is static (the continuity weight travels in `data`, the
    # tolerances in `solver`): one compilation per problem shape, whatever the segment length.
    program = SimulationFit(
        fit_initial_states=fit_initial_states, max_steps=method.max_steps, simulation=method.simulation
    )
    with ProgressBar(method.max_steps, "output-error fit", progress=progress, reduce="last") as bar:
        solution, r, r0, jac = _solve(unknowns, parameters, data, scale, solver, program, bar_token(bar))
        jax.block_until_ready(r)
    n_params = chosen.size
    n_state_residuals = xs.size
    linearised = least_squares(jac, -r, names=parameters.names, allow_rank_deficient=True)
    # An unknown the data leave undetermined (a part in the Jacobian's null space: `least_squares`
    # gives it an infinite error) has NaN in every covariance's row and column: the pseudo-inverse
    # would give it finite numbers, zero where the Jacobian vanishes (every rollout diverged).
    unidentified = ~np.isfinite(np.asarray(linearised.std_errors))

    def unscaled(c):
        c = np.array(c, dtype=float) * np.asarray(scale)[:, None] * np.asarray(scale)[None, :]
        c[unidentified, :] = c[:, unidentified] = np.nan
        return jnp.asarray(c, dtype)

    covariance = unscaled(linearised.covariance * stagger)
    std = jnp.where(unidentified, jnp.inf, jnp.sqrt(jnp.maximum(jnp.diag(covariance), 0.0)))
    record_covariance = None
    if not fit_initial_states:
        clustered = segment_clustered_covariance(np.asarray(jac), np.asarray(r), ts, owner, trajectories, segment_s)
        if clustered is not None:
            covariance = unscaled(clustered)
            std = jnp.where(unidentified, jnp.inf, jnp.sqrt(jnp.maximum(jnp.diag(covariance), 0.0)))
        spread = record_jackknife_covariance(np.asarray(jac), np.asarray(r), owner, len(trajectories))
        record_covariance = None if spread is None else unscaled(spread)
    fitted = solution.model
    diverged, initial_diverged = (
        int(np.sum(np.any(np.asarray(res[:n_state_residuals]).reshape(xs.shape[0], -1) == DIVERGED, axis=1)))
        for res in (r, r0)
    )
    statistics = OutputErrorStatistics(
        initial_states=fitted.initial_states,
        jacobian=linearised.statistics,
        residual_rms=jnp.sqrt(jnp.mean(r[:n_state_residuals] ** 2) * stagger),  # undo the cuts' 1/sqrt(k)
        initial_residual_rms=jnp.sqrt(jnp.mean(r0[:n_state_residuals] ** 2) * stagger),
        relative_error=jnp.linalg.norm(r[:n_state_residuals].reshape(xs.shape) * jnp.broadcast_to(sigma, xs.shape))
        * np.sqrt(stagger)
        / jnp.linalg.norm(xs),
        record_covariance=None if record_covariance is None else record_covariance[:n_params, :n_params],
        n_segments=int(xs.shape[0]),
        n_samples=int(n_samples),
        diverged_segments=diverged,
        initial_diverged_segments=initial_diverged,
    )
    return Solution(
        model=fitted.system,
        value=solution.value[:n_params],
        parameters=chosen,
        covariance=covariance[:n_params, :n_params],
        std_errors=std[:n_params],
        result=solution.result,
        loss=solution.loss,
        initial_loss=solution.initial_loss,
        steps=solution.steps,
        n_residuals=solution.n_residuals,
        residuals=solution.residuals,
        initial_residuals=solution.initial_residuals,
        statistics=statistics,
    )
