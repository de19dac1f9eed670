r"""Multi-step-ahead prediction from every sample, and the flight-model scores built on it.

Flight models are scored as the field scores them: from every sample of a held-out flight the
model is rolled out open loop under the recorded inputs (zero-order hold) for $h$ samples, and the
prediction at $h$ is compared with the measurement there. `predict_ahead` gives the predicted
states; `flight_error` the mean absolute and root-mean-square errors per group of states at each
$h$, and the cumulative MAE over $h = 1..H$.

Each rollout takes one classical Runge-Kutta step per sample interval inside a `lax.scan`, and the
rollouts are `vmap`ped over start samples: one compiled program per (model structure, record length,
horizon), in the dtype of the trajectory (float32 for throughput, float64 for identification).

**Steps the model's fastest mode needs.** A fixed-step method is stable only while $h\lambda$ stays in
its stability region for every eigenvalue $\lambda$ of the model's Jacobian; RK4's contains the
left half-disk $|h\lambda| \le 2.6$ (its real-axis limit is 2.785; Hairer and Wanner 1996, sec. IV.2).
A fitted model can have a mode faster than the sample rate resolves (a rate damping of 341 1/s at
100 Hz is $h\lambda = -3.4$), and its rollout then diverges through the integrator, not through
the model; inside the region but near its edge it is stable and wrong (at $h\lambda = -2$ RK4
multiplies by 0.33 where the mode decays by 0.14). So `predict_ahead` reads the model's Jacobian at
up to `_JACOBIAN_SAMPLES` of the record's samples and splits each sample interval into as many equal
RK4 substeps as keep $|h\lambda| \le$ `_RK4_RADIUS` (1) at the fastest of them, where RK4's factor
is within 2 % of $e^{h\lambda}$ on the negative real axis; a model whose modes are all slower
(every fitted NanoBench flight model: $|\lambda| \le 14$ 1/s at 100 Hz) keeps one step per
sample, so its scores do not change.

??? cite

    E. Hairer, G. Wanner, *Solving Ordinary Differential Equations II: Stiff and
    Differential-Algebraic Problems*, 2nd ed., Springer 1996, sec. IV.2.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._model._helicopter import quaternion_angle
from ._sim_error import SimulationError

#: The state groups of `flight_error`, with their units.
FLIGHT_GROUPS = ("position", "velocity", "attitude", "body_rate")
FLIGHT_UNITS = {"position": "m", "velocity": "m/s", "attitude": "rad", "body_rate": "rad/s"}


_RK4_RADIUS = 1.0  # |h lambda| at which RK4 follows a decaying mode to 2 % per step (stable to 2.6)
_JACOBIAN_SAMPLES = 64  # the record's samples at which the model's fastest mode is read
_MAX_SUBSTEPS = 64  # beyond this the model is stiff for any explicit method: it diverges and is reported


def _rk4(system, x, u, dt):
    f = lambda y: system.vector_field(0.0, y, u)
    k1 = f(x)
    k2 = f(x + 0.5 * dt * k1)
    k3 = f(x + 0.5 * dt * k2)
    k4 = f(x + dt * k3)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


@eqx.filter_jit
def _predict(system, xs, us, dt, starts, lags, n_steps: int, substeps: int):
    h = dt / substeps

    def window(k):
        u_win = jax.lax.dynamic_slice_in_dim(us, k, n_steps)

        def step(x, u):
            x_next = jax.lax.fori_loop(0, substeps, lambda _, y: _rk4(system, y, u, h), x)
            return x_next, x_next

        _, path = jax.lax.scan(step, xs[k], u_win)
        return path[lags - 1]

    return jax.vmap(window)(starts)


@eqx.filter_jit
def _jacobians(system, xs, us):
    return jax.vmap(lambda x, u: jax.jacfwd(lambda y: system.vector_field(0.0, y, u))(x))(xs, us)


def stable_substeps(model, trajectory: Trajectory) -> int:
    r"""The RK4 substeps per sample interval that resolve `model`'s fastest mode on `trajectory`.

    The largest eigenvalue modulus $\rho$ of the model's Jacobian $\partial f/\partial x$ at up to
    `_JACOBIAN_SAMPLES` evenly spaced samples (with their inputs) gives
    $\lceil \rho\,\Delta t / r \rceil$ substeps, $r$ = `_RK4_RADIUS` = 1, at least 1 and at most `_MAX_SUBSTEPS`. A
    Jacobian that is not finite at some sample gives 1 there: the rollout reports it as diverged.
    """
    n = len(trajectory)
    index = np.unique(np.linspace(0, n - 1, min(n, _JACOBIAN_SAMPLES)).round().astype(int))
    xs, us = trajectory.xs[index], trajectory.us[index]
    model = jax.tree.map(lambda a: a.astype(xs.dtype) if eqx.is_inexact_array(a) else a, model)
    jac = np.asarray(_jacobians(model, xs, us.astype(xs.dtype)), float)
    finite = np.all(np.isfinite(jac), axis=(1, 2))
    if not finite.any():
        return 1
    rho = float(np.max(np.abs(np.linalg.eigvals(jac[finite]))))
    return int(min(max(1, np.ceil(rho * float(trajectory.dt) / _RK4_RADIUS)), _MAX_SUBSTEPS))


def _check_steps(steps) -> tuple[int, ...]:
    if isinstance(steps, str) or not hasattr(steps, "__iter__"):
        raise UsageError(f"predict_ahead: `steps` must be a sequence of whole numbers of samples, got {steps!r}")
    steps = tuple(steps)
    # a fraction (2.5) would be truncated to another horizon, a bool read as 1: neither is a number of samples
    if not all(isinstance(s, int | np.integer) and not isinstance(s, bool | np.bool_) for s in steps):
        raise UsageError(f"predict_ahead: `steps` must be whole numbers of samples, got {steps!r}")
    steps = tuple(int(s) for s in steps)
    if not steps or min(steps) < 1:
        raise UsageError(f"predict_ahead: `steps` must be one or more positive numbers of samples, got {steps}")
    return steps


def _check_columns(model, trajectory: Trajectory) -> None:
    """The record's states must be the model's (where the model names them): another system's record would be
    rolled out as this model's states."""
    if not isinstance(trajectory, Trajectory):
        raise UsageError(f"predict_ahead: `trajectory` must be a Trajectory, got {type(trajectory).__name__}")
    names = getattr(model, "state_names", None)
    measured = tuple(trajectory.state_names)
    if names is not None and len(names) > len(measured) and tuple(names[: len(measured)]) == measured:
        raise UsageError(
            f"predict_ahead: {type(model).__name__} has internal states {tuple(names[len(measured) :])} that a "
            "record does not hold, and predict_ahead starts every prediction from a measured sample; score such a "
            "model with `dynax.simulation_error`, which starts them along the record"
        )
    if names is not None and measured != tuple(names):
        raise UsageError(
            f"predict_ahead: the trajectory's states {tuple(trajectory.state_names)} are not "
            f"{type(model).__name__}'s {tuple(names)}"
        )
    n_inputs = getattr(model, "n_inputs", None)
    optional = len(getattr(model, "optional_inputs", ()))  # inputs a record may leave out (a quadrotor's vbat)
    if n_inputs is not None and not n_inputs - optional <= trajectory.us.shape[1] <= n_inputs:
        raise UsageError(
            f"predict_ahead: the trajectory has {trajectory.us.shape[1]} inputs {tuple(trajectory.input_names)} but "
            f"{type(model).__name__} has {n_inputs}"
        )


def _check_uniform(trajectory: Trajectory, caller: str) -> None:
    if not trajectory.is_uniform:
        where = f" ({trajectory.source})" if trajectory.source else ""
        raise UsageError(f"{caller}: the trajectory{where} must be uniformly sampled; resample it first")


def predict_ahead(
    model, trajectory: Trajectory, steps=(1, 10, 50), substeps: int | None = None
) -> Float[Array, "starts steps n_states"]:
    r"""Open-loop predictions $h$ samples ahead from every sample of a record.

    Row $i$ starts from the measured state at sample $i$ and rolls the model forward under the
    recorded inputs (zero-order hold, one RK4 step per sample interval, or more where the model's
    fastest mode needs them: see the module); column $j$ is the state
    predicted `steps[j]` samples later, for comparison with `trajectory.xs[i + steps[j]]`. Starts
    too close to the end for the longest step are left out: there are `len(trajectory) - max(steps)`
    rows.

    **Arguments:**

    - `model`: any system (`vector_field(t, x, u)`) whose states are the trajectory's, e.g. a fitted
      `Quadrotor` or the `ConstantVelocity` baseline.
    - `trajectory`: a uniformly sampled record (the model's state and input columns).
    - `steps`: the horizons in samples (default 1, 10, 50: 0.01, 0.1 and 0.5 s at 100 Hz).
    - `substeps`: RK4 steps per sample interval; `None` (default) chooses them from the model's
      fastest mode on this record (`stable_substeps`: 1 for a model the sample rate resolves).

    **Returns:** the predicted states, shape `(starts, len(steps), n_states)`, in the trajectory's dtype
    (the model's arrays are cast to it: `trajectory.astype(jnp.float32)` predicts in float32).
    """
    steps = _check_steps(steps)
    _check_columns(model, trajectory)
    _check_uniform(trajectory, "predict_ahead")
    n = len(trajectory) - max(steps)
    if n < 1:
        raise UsageError(
            f"predict_ahead: the record has {len(trajectory)} samples, too few for {max(steps)} steps ahead"
        )
    if substeps is None:
        substeps = stable_substeps(model, trajectory)
    elif isinstance(substeps, bool) or not isinstance(substeps, int | np.integer) or substeps < 1:
        raise UsageError(f"predict_ahead: `substeps` must be a positive whole number or None, got {substeps!r}")
    xs, us = trajectory.xs, trajectory.us
    dt = jnp.asarray(trajectory.dt, xs.dtype)
    # The model's arrays in the trajectory's dtype: a float32 record rolls out in float32.
    model = jax.tree.map(lambda a: a.astype(xs.dtype) if eqx.is_inexact_array(a) else a, model)
    starts, lags = jnp.arange(n), jnp.asarray(steps)
    return _predict(model, xs, us.astype(xs.dtype), dt, starts, lags, max(steps), int(substeps))


def group_errors(predicted, measured):
    """Per group, the size of the error at each prediction: Euclidean norms [m, m/s, rad/s] and the
    geodesic angle between the attitudes [rad]."""
    angle = jnp.vectorize(quaternion_angle, signature="(4),(4)->()")(predicted[..., 3:7], measured[..., 3:7])
    return jnp.stack(
        [
            jnp.linalg.norm(predicted[..., 0:3] - measured[..., 0:3], axis=-1),
            jnp.linalg.norm(predicted[..., 7:10] - measured[..., 7:10], axis=-1),
            angle,
            jnp.linalg.norm(predicted[..., 10:13] - measured[..., 10:13], axis=-1),
        ],
        axis=-1,
    )


def flight_error(model, flights, steps=(1, 10, 50)) -> SimulationError:
    r"""The flight-model scores of `model` on one record or several (pooled over their start samples).

    **Arguments:**

    - `model`: a system with the `quadrotor` states (a fitted `Quadrotor`, `ConstantVelocity`).
    - `flights`: a `Trajectory` or a list (e.g. the usable runs of held-out flights); a run too
      short for the longest horizon is skipped.
    - `steps`: the horizons in samples at which `mae` and `rmse` are reported; the cumulative MAE
      runs over every horizon from 1 to `max(steps)`.

    **Returns:** a `SimulationError` with the error sizes per state group (`state_names`:
    `FLIGHT_GROUPS`): the norm of the position [m], world-velocity [m/s] and body-rate [rad/s]
    errors and the geodesic angle between the attitudes [rad]; `mae_per_state` and
    `rmse_per_state` of shape `(step, group)` (`inf` where a rollout diverged), `cumulative_mae`,
    `n_windows` the start samples scored and `diverged_fraction` the share whose rollout left the
    finite range by the longest horizon. Its `rmse` is `None`: the groups have different units.

    Each start is rolled out as `predict_ahead` rolls it out (its record's substeps). The runs that share a
    sample interval, a dtype and substeps are joined into one array and their starts scored in chunks of at
    most `_CHUNK` (windows never cross from one run into the next): one compiled program per model, whatever
    the number and lengths of the runs, and memory bounded by a chunk.
    """
    steps = _check_steps(steps)
    horizon = max(steps)
    flights = [flights] if isinstance(flights, Trajectory) else list(flights)
    runs: dict[tuple, list[Trajectory]] = {}
    for f in flights:
        if len(f) <= horizon:
            continue
        _check_uniform(f, "flight_error")
        # (the intervals to 12 digits: the median steps of runs on one grid can differ in their last bits)
        runs.setdefault((float(f"{f.dt:.12g}"), f.xs.dtype, stable_substeps(model, f)), []).append(f)
    if not runs:
        raise UsageError(f"flight_error: no record is longer than the horizon of {horizon} samples")
    abs_sum = np.zeros((horizon, len(FLIGHT_GROUPS)))
    sq_sum = np.zeros((horizon, len(FLIGHT_GROUPS)))
    n = diverged = 0
    for (dt, dtype, substeps), group in runs.items():
        xs = jnp.concatenate([f.xs for f in group])
        us = jnp.concatenate([f.us for f in group]).astype(dtype)
        offsets = np.cumsum([0] + [len(f) for f in group])[:-1]
        starts = np.concatenate([o + np.arange(len(f) - horizon) for o, f in zip(offsets, group)])
        cast = jax.tree.map(lambda a: a.astype(dtype) if eqx.is_inexact_array(a) else a, model)
        size = min(_CHUNK, len(starts))  # every chunk this size (the last one padded): one compiled program
        for c in range(0, len(starts), size):
            chunk = starts[c : c + size]
            padded = np.concatenate([chunk, np.full(size - len(chunk), chunk[-1])])
            valid = np.arange(size) < len(chunk)
            a, s, d = _error_sums(cast, xs, us, jnp.asarray(dt, dtype), jnp.asarray(padded), valid, horizon, substeps)
            abs_sum += np.asarray(a, float)
            sq_sum += np.asarray(s, float)
            diverged += int(d)
        n += len(starts)
    dt = float(next(f for f in flights if len(f) > horizon).dt)
    mae_all, rmse_all = abs_sum / n, np.sqrt(sq_sum / n)  # (horizon, group)
    index = np.asarray(steps) - 1
    return SimulationError(
        horizons_s=tuple(s * dt for s in steps),
        n_windows=n,
        diverged_fraction=diverged / n,
        state_names=FLIGHT_GROUPS,
        rmse_per_state=jnp.asarray(rmse_all[index]),
        steps=steps,
        dt=dt,
        mae_per_state=jnp.asarray(mae_all[index]),
        cumulative_mae=jnp.asarray(mae_all.mean(axis=0)),
    )


_CHUNK = 2048  # starts per call of `_error_sums` in `flight_error`: a chunk x horizon x 13 rollout in memory


@eqx.filter_jit
def _error_sums(system, xs, us, dt, starts, valid, horizon: int, substeps: int):
    """Over the `valid` ones of `starts`, the sums of the per-group errors and of their squares at each step
    1..`horizon` (`inf` where a rollout left the finite range), and the number of such rollouts."""
    lags = jnp.arange(1, horizon + 1)
    predicted = _predict(system, xs, us, dt, starts, lags, horizon, substeps)
    err = group_errors(predicted, xs[starts[:, None] + lags[None, :]])  # (starts, horizon, group)
    finite = jnp.all(jnp.isfinite(err), axis=(1, 2))
    err = jnp.where(finite[:, None, None], err, jnp.inf)
    kept = valid[:, None, None]
    return (
        jnp.sum(jnp.where(kept, err, 0.0), axis=0),
        jnp.sum(jnp.where(kept, err**2, 0.0), axis=0),
        jnp.sum(valid & ~finite),
    )
