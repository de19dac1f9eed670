r"""Output-error identification: fit parameters by minimising the simulation error, with multiple shooting.

The record is cut into segments of `segment_s` seconds. Each segment is simulated from its own
initial state (a free variable, started at the measured state), and the residuals are the
simulated-minus-measured states of every segment, scaled per state by the data's spread, plus the
continuity defects between consecutive segments (the end of one segment against the start of the
next), weighted by `continuity_weight`. Short segments keep the problem well conditioned on long
or unstable records (a single shooting fit of a chaotic double pendulum has a cost surface full of
local minima); the continuity defects tie the segments back into one trajectory.

The problem is solved with Levenberg-Marquardt (optimistix) using forward-mode Jacobians through
the fixed-grid integrator: the number of unknowns (parameters plus segment states) is small compared
with the number of residuals, which is where forward mode is the right tool.
"""

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, PyTree

from .._data._trajectory import Trajectory
from .._errors import DataError, UsageError
from .._model._linear_axis import LinearAxis
from .._model._system import AbstractSystem
from .._simulate import FixedGrid, simulate
from ._least_squares import least_squares, LeastSquaresFit

class SimulationFit(eqx.Module):
    """The output-error (simulation-error) method for `identify`; see `fit_simulation_error`.

    **Arguments:**

    - `segment_s`: multiple-shooting segment length [s] (default 1.0).
    - `fit_initial_states`: fit each segment's initial state (default `True`) or start from the
      measured one.
    - `continuity_weight`: weight of the continuity defects between segments (default 10).
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


class SimulationFitResult(eqx.Module):
    r"""The result of `fit_simulation_error`.

    **Fields:**

    - `system`: the system with the fitted leaves.
    - `initial_states`: fitted (or measured) initial state of each segment, `(segment, n_states)`.
    - `parameters`: the fitted leaves, flattened, shape `(n_params,)`.
    - `std_errors`: their standard errors (Gauss-Newton covariance at the solution), same shape.
    - `condition_number`, `rank`: of the column-scaled Jacobian of all unknowns.
    - `residual_rms`: root-mean-square of the scaled state residuals at the solution.
    - `initial_residual_rms`: the same at the starting point.
    - `relative_error`: $\lVert \hat x - x \rVert / \lVert x \rVert$ over all segment samples (unscaled).
    - `n_segments`, `n_samples`, `steps`: bookkeeping.
    """

    system: AbstractSystem
    initial_states: Float[Array, "segment n_states"]
    parameters: Float[Array, " n_params"]
    std_errors: Float[Array, " n_params"]
    condition_number: Float[Array, ""]
    rank: Array
    residual_rms: Float[Array, ""]
    initial_residual_rms: Float[Array, ""]
    relative_error: Float[Array, ""]
    n_segments: int = eqx.field(static=True)
    n_samples: int = eqx.field(static=True)
    steps: Array


def _segments(trajectories, segment_s):
    """Cut every record into equal-length segments sharing their end samples."""
    dt = float(np.median(np.diff(np.asarray(trajectories[0].ts))))
    shortest = min(len(t) for t in trajectories)
    if shortest < 2:
        raise DataError(f"{shortest} samples are too few for a simulation fit")
    length = min(max(int(round(segment_s / dt)) + 1, 2), shortest)
    ts, xs, us, follows, owner = [], [], [], [], []
    n_samples = 0
    for j, traj in enumerate(trajectories):
        starts = range(0, len(traj) - length + 1, length - 1)
        for k, s in enumerate(starts):
            ts.append(np.asarray(traj.ts[s : s + length]))
            xs.append(np.asarray(traj.xs[s : s + length]))
            us.append(np.asarray(traj.us[s : s + length]))
            follows.append(k > 0)
            owner.append(j)
        n_samples += starts[-1] + length
    return np.stack(ts), np.stack(xs), np.stack(us), np.asarray(follows), np.asarray(owner), n_samples


class _Config(eqx.Module):
    fit_initial_states: bool = eqx.field(static=True)
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)
    simulation: FixedGrid


@eqx.filter_jit
def _solve(fitted, fixed, ts, xs, us, sigma, link, continuity_weight, config: _Config, segment_weight):
    """Levenberg-Marquardt on the scaled unknowns; one compiled program per problem shape."""
    p0, unravel = jax.flatten_util.ravel_pytree(fitted)
    p0 = p0.astype(xs.dtype)
    p_scale = jnp.where(jnp.abs(p0) > 0, jnp.abs(p0), 1.0)
    x0_data = xs[:, 0]
    w_cont = jnp.sqrt(continuity_weight)

    def unpack(z):
        p = p0 + p_scale * z[: p0.size]
        x0 = x0_data + sigma * z[p0.size :].reshape(x0_data.shape) if config.fit_initial_states else x0_data
        return p, x0

    def residuals(z, _):
        p, x0 = unpack(z)
        model = eqx.combine(unravel(p), fixed)
        sims = jax.vmap(lambda x0, t, u: simulate(model, x0, t, u, method=config.simulation, throw=False).xs)(x0, ts, us)
        r = (sims - xs) / jnp.broadcast_to(sigma, xs.shape) * segment_weight[:, None, None]
        r = jnp.where(jnp.isfinite(r), r, 1e3)
        out = [r.reshape(-1)]
        if config.fit_initial_states and x0.shape[0] > 1:
            defect = (sims[:-1, -1] - x0[1:]) / sigma * link[:, None] * w_cont
            out.append(jnp.where(jnp.isfinite(defect), defect, 1e3).reshape(-1))
        return jnp.concatenate(out)

    n_z = p0.size + (x0_data.size if config.fit_initial_states else 0)
    z0 = jnp.zeros(n_z, xs.dtype)
    solver = optx.LevenbergMarquardt(rtol=config.rtol, atol=config.atol)
    solution = optx.least_squares(residuals, solver, z0, max_steps=config.max_steps, throw=False)
    z = solution.value
    return z, residuals(z, None), residuals(z0, None), jax.jacfwd(residuals)(z, None), solution.stats["num_steps"]


def fit_simulation_error(
    system: AbstractSystem,
    trajectories: Trajectory | Sequence[Trajectory],
    *,
    filter_spec: PyTree[bool] | None = None,
    segment_s: float = 1.0,
    fit_initial_states: bool = True,
    continuity_weight: float = 10.0,
    state_scale: Float[Array, " n_states"] | None = None,
    rtol: float = 1e-8,
    atol: float = 1e-8,
    max_steps: int = 100,
    simulation: FixedGrid = FixedGrid(),
    record_weights: Float[Array, " n_records"] | None = None,
) -> SimulationFitResult:
    r"""Fit the leaves of `system` selected by `filter_spec` by minimising the simulation error.

    Generic over systems: any `AbstractSystem` whose `vector_field` is differentiable, with any
    PyTree filter of what to fit (the others stay fixed). The cost is

    $$\sum_{s,k} \lVert (\hat x_s(t_k) - x(t_k)) / \sigma \rVert^2 + w \sum_s \lVert (\hat x_s(t_{end}) - x_{0,s+1}) / \sigma \rVert^2$$

    over segments $s$ simulated from their initial states $x_{0,s}$, where $\sigma$ is the
    per-state scale (default: the data's standard deviation of each state).

    **Arguments:**

    - `system`: the starting model.
    - `trajectories`: a `Trajectory` or a list of them.
    - `filter_spec`: a PyTree of bools like `system` (as for `eqx.partition`) marking the leaves
      to fit; default every inexact array leaf.
    - `segment_s`: segment length [s] for multiple shooting (a value longer than the record means
      single shooting).
    - `fit_initial_states`: also fit each segment's initial state (default `True`).
    - `continuity_weight`: $w$, weight of the continuity defects (only with fitted initial states).
    - `state_scale`: $\sigma$, shape `(n_states,)`.
    - `rtol`, `atol`, `max_steps`: Levenberg-Marquardt settings.
    - `simulation`: `FixedGrid` settings of the rollouts.
    - `record_weights`: optional weight per trajectory multiplying its state residuals (default 1).

    **Returns:** a `SimulationFitResult`.

    ??? cite

        H. G. Bock and K. J. Plitt, "A multiple shooting algorithm for direct solution of optimal
        control problems", IFAC World Congress, 1984; L. Ljung, *System Identification: Theory
        for the User*, 2nd ed., 1999, ch. 7 (output-error models); J. J. More, "The
        Levenberg-Marquardt algorithm: implementation and theory", 1978.
    """
    if isinstance(trajectories, Trajectory):
        trajectories = [trajectories]
    trajectories = list(trajectories)
    if not trajectories:
        raise UsageError("fit_simulation_error: `trajectories` is empty")
    if not segment_s > 0:
        raise UsageError(f"fit_simulation_error: `segment_s` must be positive, got {segment_s}")
    if filter_spec is None:
        filter_spec = jax.tree.map(eqx.is_inexact_array, system)
    fitted, fixed = eqx.partition(system, filter_spec)
    p0, unravel = jax.flatten_util.ravel_pytree(fitted)
    if p0.size == 0:
        raise UsageError("fit_simulation_error: `filter_spec` selects no array leaves to fit")
    ts, xs, us, follows, owner, n_samples = _segments(trajectories, segment_s)
    dtype = jnp.result_type(p0.dtype, xs.dtype)
    ts, xs, us = (jnp.asarray(a, dtype) for a in (ts, xs, us))
    p0 = p0.astype(dtype)
    if state_scale is None:
        flat = np.concatenate([np.asarray(t.xs) for t in trajectories])
        state_scale = np.std(flat, axis=0)
        state_scale = np.where(state_scale > 0, state_scale, 1.0)
    sigma = jnp.asarray(state_scale, dtype)
    link = jnp.asarray(follows[1:], dtype)  # segment s+1 continues segment s
    config = _Config(fit_initial_states, rtol, atol, max_steps, simulation)
    weight = np.ones(len(trajectories)) if record_weights is None else np.asarray(record_weights, dtype=float)
    if weight.shape != (len(trajectories),) or not np.all(weight > 0):
        raise UsageError(f"fit_simulation_error: `record_weights` must be {len(trajectories)} positive numbers")
    segment_weight = jnp.asarray(weight[owner], dtype)
    z, r, r0, jac, steps = _solve(fitted, fixed, ts, xs, us, sigma, link, jnp.asarray(continuity_weight, dtype), config,
                                  segment_weight)
    p0, unravel = jax.flatten_util.ravel_pytree(fitted)
    p0 = p0.astype(dtype)
    p_scale = jnp.where(jnp.abs(p0) > 0, jnp.abs(p0), 1.0)
    x0_data = xs[:, 0]
    n_z = z.size
    n_state_residuals = xs.size

    def unpack(z):
        p = p0 + p_scale * z[: p0.size]
        x0 = x0_data + sigma * z[p0.size :].reshape(x0_data.shape) if fit_initial_states else x0_data
        return p, x0

    names = tuple(f"p{i}" for i in range(p0.size)) + tuple(f"x0_{i}" for i in range(n_z - p0.size))
    linearised: LeastSquaresFit = least_squares(jac, -r, names=names, allow_rank_deficient=True)
    p, x0 = unpack(z)
    return SimulationFitResult(
        system=eqx.combine(unravel(p), fixed),
        initial_states=x0,
        parameters=p,
        std_errors=linearised.std_errors[: p0.size] * p_scale,
        condition_number=linearised.condition_number,
        rank=linearised.rank,
        residual_rms=jnp.sqrt(jnp.mean(r[:n_state_residuals] ** 2)),
        initial_residual_rms=jnp.sqrt(jnp.mean(r0[:n_state_residuals] ** 2)),
        relative_error=jnp.linalg.norm(r[:n_state_residuals].reshape(xs.shape) * jnp.broadcast_to(sigma, xs.shape)) / jnp.linalg.norm(xs),
        n_segments=int(xs.shape[0]),
        n_samples=int(n_samples),
        steps=steps,
    )


def _identify_by_simulation(system, trajectories, method: SimulationFit, friction):
    from ._identify import _fitted_system, _system_name, Identification
    from ._regressors import parameter_names, parameter_vector, with_friction

    try:
        system = with_friction(system, friction)
        names = parameter_names(system, friction)
    except UsageError:
        names = None  # any other system: fit every inexact array leaf, named by position
    if names is not None:
        # Start from the system's values; the leaves not in `names` (a linear axis's Coulomb term
        # under viscous friction) are fixed.
        system = _fitted_system(system, names, parameter_vector(system, friction))
        filter_spec = jax.tree.map(eqx.is_inexact_array, system)
        if isinstance(system, LinearAxis) and "coulomb" not in names:
            filter_spec = eqx.tree_at(lambda s: s.coulomb, filter_spec, False)
        # The fitted leaves flatten in field order, which is the order of `names`.
    else:
        filter_spec = jax.tree.map(eqx.is_inexact_array, system)
    result = fit_simulation_error(
        system,
        trajectories,
        filter_spec=filter_spec,
        segment_s=method.segment_s,
        fit_initial_states=method.fit_initial_states,
        continuity_weight=method.continuity_weight,
        rtol=method.rtol,
        atol=method.atol,
        max_steps=method.max_steps,
        simulation=method.simulation,
    )
    if names is None:
        names = _leaf_names(system, filter_spec)
        estimate, std = result.parameters, result.std_errors
    else:
        # The flattened leaves follow the fields' order, which is the order of `names`.
        estimate = parameter_vector(result.system, friction)
        std = result.std_errors
    return Identification(
        system=result.system,
        estimate=estimate,
        std_errors=std,
        condition_number=result.condition_number,
        rank=result.rank,
        residual_rms=result.residual_rms,
        relative_error=result.relative_error,
        fit=None,
        names=names,
        n_samples=result.n_samples,
        method="simulation",
        friction=friction,
        system_name=_system_name(system),
    )


def _leaf_names(system, filter_spec) -> tuple[str, ...]:
    """Names of the flattened fitted leaves, from their paths: `body_model.a[0,1]`."""
    fitted, _ = eqx.partition(system, filter_spec)
    names = []
    for path, leaf in jax.tree_util.tree_flatten_with_path(fitted)[0]:
        base = jax.tree_util.keystr(path).lstrip(".")
        shape = np.shape(leaf)
        if shape == ():
            names.append(base)
        else:
            names.extend(f"{base}[{','.join(map(str, idx))}]" for idx in np.ndindex(*shape))
    return tuple(names)
