r"""Multi-step open-loop predictions of a `Helicopter` from every start time, and the H-step loss.

Everything here works on *windows*: from start sample $t$ the model is rolled out open loop from
the measured state $x_t$ under the recorded inputs (zero-order hold), one diffrax `Tsit5` step per
sample interval, restarted at every sample as `dynax.simulate` does. Windows are `vmap`ped over
start times; the per-window sample slices are taken inside the vmapped function, so no
`(start, lag, state)` copy of the data is ever made.
"""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int
import numpy as np

from ..._data._trajectory import Trajectory
from ..._errors import UsageError
from ..._model._helicopter import (
    ANGULAR_RATE,
    BODY,
    Helicopter,
    HELICOPTER_STATE_NAMES,
    POSITION,
    QUATERNION,
    quaternion_angle,
    VELOCITY,
)

#: The state groups of the evaluate metric, with their units.
STATE_GROUPS = ("velocity", "angular_rate", "position", "orientation")


def check_helicopter_data(trajectory: Trajectory, where: str) -> float:
    """Check a trajectory is uniformly sampled helicopter data; return its sample interval."""
    if tuple(trajectory.state_names) != HELICOPTER_STATE_NAMES:
        raise UsageError(
            f"{where}: the trajectory must have the helicopter states {HELICOPTER_STATE_NAMES}, "
            f"got {tuple(trajectory.state_names)}"
        )
    if len(trajectory) < 3:
        raise UsageError(f"{where}: the trajectory needs at least 3 samples, got {len(trajectory)}")
    if not trajectory.is_uniform:
        raise UsageError(
            f"{where}: vehicle learning needs uniformly sampled data; resample first "
            "(dynax._data.resample(trajectory, dt))"
        )
    return trajectory.dt


def horizon_steps(horizon_s: float, dt: float, where: str) -> int:
    """The number of samples in a horizon [s] (at least 1)."""
    steps = int(round(float(horizon_s) / dt))
    if steps < 1:
        raise UsageError(f"{where}: the horizon {horizon_s} s is shorter than one sample ({dt} s)")
    return steps


def _solver_step(system: Helicopter, x, u, dt):
    term = diffrax.ODETerm(lambda t, y, args: system.vector_field(t, y, args))
    solver = diffrax.Tsit5(scan_kind="bounded")  # forward and reverse mode (see dynax.FixedGrid)
    zero = jnp.zeros((), x.dtype)
    state = solver.init(term, zero, zero + dt, x, u)
    y, _, _, _, _ = solver.step(term, zero, zero + dt, x, u, state, made_jump=True)
    return y


def rollout(
    system: Helicopter, x0: Float[Array, " 13"], us: Float[Array, "lag n_inputs"], dt
) -> Float[Array, "steps 13"]:  # steps = lag + 1
    """Open-loop states `x0, x1, ..., x_H` under the zero-order-hold inputs `us` (one Tsit5 step each)."""

    def step(x, u):
        x_next = _solver_step(system, x, u, dt)
        return x_next, x_next

    _, xs = jax.lax.scan(step, x0, us)
    return jnp.concatenate([x0[None], xs])


def valid_starts(n_samples: int, n_steps: int, stride: int = 1, breaks=None) -> np.ndarray:
    """Start indices of every window of `n_steps` intervals that fits in the record.

    `breaks` (optional): the sample indices at which a new record begins in a record made by
    joining several; a window that would cross one is left out (every `stride`-th of the rest).
    """
    if n_samples - 1 - n_steps < 0:
        raise UsageError(f"the record has {n_samples} samples, too few for a {n_steps}-step horizon")
    if breaks is None or len(breaks) == 0:
        return np.arange(0, n_samples - n_steps, max(1, int(stride)))
    starts = np.arange(0, n_samples - n_steps)
    record = np.searchsorted(np.asarray(breaks), np.arange(n_samples), side="right")
    starts = starts[record[starts] == record[starts + n_steps]]
    if starts.size == 0:
        raise UsageError(f"no record is long enough for a {n_steps}-step horizon")
    return starts[:: max(1, int(stride))]


def _padded(trajectory: Trajectory, extra: int):
    xs, us = trajectory.xs, trajectory.us
    if extra:
        xs = jnp.concatenate([xs, jnp.repeat(xs[-1:], extra, axis=0)])
        us = jnp.concatenate([us, jnp.zeros((extra, us.shape[1]), us.dtype)])
    return xs, us


def lagged_loss(
    system: Helicopter,
    trajectory: Trajectory,
    n_steps: int,
    *,
    starts: Int[Array, " window"] | None = None,
    weights: Float[Array, "6"] | Float[Array, "lag 6"] | None = None,
    checkpoint_segment: int | None = None,
) -> Float[Array, ""]:
    r"""The lagged (H-step) criterion: the mean squared open-loop prediction error of the body
    velocities and rates over lags $1..H$ from every start time.

    $$L(\theta) = \frac{1}{|T| H} \sum_{t\in T}\sum_{h=1}^{H} \big\| \Lambda^{1/2}
    (\hat s_{t+h\mid t}(\theta) - s_{t+h}) \big\|^2,$$

    where $s = (u, v, w, p, q, r)$ and $\hat s_{t+h\mid t}$ is the model's rollout from the measured
    state $x_t$. The squared error accumulates inside the rollout, whose scan is split into segments of
    `checkpoint_segment` steps (default $\lceil\sqrt H\rceil$) wrapped in `jax.checkpoint`: reverse-mode
    differentiation stores only the segment boundaries and recomputes inside a segment, so the
    memory of a gradient grows like $\sqrt H$ rather than $H$.

    **Arguments:**

    - `system`: the `Helicopter`.
    - `trajectory`: uniformly sampled helicopter data.
    - `n_steps`: the horizon $H$ in samples.
    - `starts`: the start indices (default: every start with a full window).
    - `weights`: $\Lambda$, per body state (default ones), or per lag and body state (shape `(n_steps, 6)`,
      row $h-1$ weighting lag $h$: `Lagged(lag_weights="relative")`).
    - `checkpoint_segment`: steps per checkpointed segment; `0` turns checkpointing off.

    **Returns:** the scalar loss.

    ??? cite "Reference"

        P. Abbeel and A. Y. Ng, "Learning first-order Markov models for control", NIPS 17, 2004.
    """
    dt = trajectory.ts[1] - trajectory.ts[0]
    if starts is None:
        starts = jnp.asarray(valid_starts(len(trajectory), n_steps))
    weights = jnp.ones(6, trajectory.xs.dtype) if weights is None else jnp.asarray(weights, trajectory.xs.dtype)
    segment = math.ceil(math.sqrt(n_steps)) if checkpoint_segment is None else int(checkpoint_segment)
    segment = n_steps if segment <= 0 else min(segment, n_steps)
    n_segments = math.ceil(n_steps / segment)
    padded = n_segments * segment
    xs, us = _padded(trajectory, padded - n_steps)
    lag_mask = (jnp.arange(1, padded + 1) <= n_steps).astype(xs.dtype).reshape(n_segments, segment)
    if weights.ndim == 2:  # one row per lag (padded lags are masked out)
        weights = jnp.concatenate([weights, jnp.ones((padded - n_steps, 6), weights.dtype)])
        lag_weights = weights.reshape(n_segments, segment, 6)
    else:
        lag_weights = jnp.broadcast_to(weights, (n_segments, segment, 6))

    def window(k):
        u_win = jax.lax.dynamic_slice_in_dim(us, k, padded).reshape(n_segments, segment, -1)
        s_win = jax.lax.dynamic_slice_in_dim(xs, k + 1, padded)[:, BODY].reshape(n_segments, segment, 6)

        def inner(x, row):
            u, s, m, w = row
            x_next = _solver_step(system, x, u, dt)
            e = x_next[BODY] - s
            return x_next, m * (e * e) @ w

        def outer(x, rows):
            x_end, errs = jax.lax.scan(inner, x, rows)
            return x_end, jnp.sum(errs)

        if segment < n_steps:
            outer = jax.checkpoint(outer)
        _, totals = jax.lax.scan(outer, xs[k], (u_win, s_win, lag_mask, lag_weights))
        return jnp.sum(totals)

    return jnp.mean(jax.vmap(window)(starts)) / n_steps


def predict_windows(
    system: Helicopter, trajectory: Trajectory, starts: Int[Array, " window"], n_steps: int
) -> tuple[Float[Array, "window steps 13"], Float[Array, "window steps 13"], Float[Array, "window lag n_inputs"]]:
    """Rollouts from `starts` over `n_steps`: the predicted states, the measured states and the inputs."""
    dt = trajectory.ts[1] - trajectory.ts[0]

    def window(k):
        u_win = jax.lax.dynamic_slice_in_dim(trajectory.us, k, n_steps)
        x_win = jax.lax.dynamic_slice_in_dim(trajectory.xs, k, n_steps + 1)
        return rollout(system, x_win[0], u_win, dt), x_win, u_win

    return jax.vmap(window)(starts)


def group_errors(predicted: Float[Array, "... 13"], measured: Float[Array, "... 13"]) -> dict[str, Array]:
    """Squared errors per state group: $\\|\\cdot\\|^2$ of the velocity, rate and position errors, and
    the squared rotation angle between the attitudes."""
    angle = jnp.vectorize(quaternion_angle, signature="(4),(4)->()")(
        predicted[..., QUATERNION], measured[..., QUATERNION]
    )
    return {
        "velocity": jnp.sum((predicted[..., VELOCITY] - measured[..., VELOCITY]) ** 2, axis=-1),
        "angular_rate": jnp.sum((predicted[..., ANGULAR_RATE] - measured[..., ANGULAR_RATE]) ** 2, axis=-1),
        "position": jnp.sum((predicted[..., POSITION] - measured[..., POSITION]) ** 2, axis=-1),
        "orientation": angle**2,
    }


@eqx.filter_jit
def _group_mse(system, trajectory, starts, n_steps, lags):
    def window(k):
        pred, meas, _ = predict_windows(system, trajectory, k[None], n_steps)
        errors = group_errors(pred[0][lags], meas[0][lags])
        return errors

    errors = jax.lax.map(window, starts, batch_size=256)
    # A diverged window counts as an infinite error (reported, not a NaN in the table).
    finite = jnp.all(jnp.stack([jnp.isfinite(v) for v in errors.values()]), axis=0)
    out = {name: jnp.mean(jnp.where(finite, value, jnp.inf), axis=0) for name, value in errors.items()}
    out["diverged_fraction"] = jnp.mean(~finite, axis=0)
    return out


def prediction_error(
    system: Helicopter,
    trajectory: Trajectory,
    horizons_s=(0.1, 0.5, 1.0, 2.0),
    *,
    stride: int = 1,
) -> dict[str, Float[Array, " horizon"]]:
    r"""Mean squared open-loop prediction error per state group at each horizon (the evaluate metric).

    From every start sample (every `stride`-th) that leaves room for the longest horizon, the model is
    rolled out from the measured state under the recorded inputs. At horizon $h$ the squared errors
    are: velocity $\|\hat\nu - \nu\|^2$ [m^2/s^2], angular rate $\|\hat\omega - \omega\|^2$
    [rad^2/s^2], position $\|\hat{\mathbf p} - \mathbf p\|^2$ [m^2] and orientation the squared
    rotation angle between predicted and measured attitude [rad^2], each averaged over start times.
    A horizon of 0 gives zeros.

    **Arguments:**

    - `system`: the learned `Helicopter`.
    - `trajectory`: held-out helicopter data, uniformly sampled.
    - `horizons_s`: the horizons [s].
    - `stride`: take every `stride`-th start sample.

    **Returns:** a dict `velocity`, `angular_rate`, `position`, `orientation` -> array over horizons
    (`inf` where some rollout diverged), and `diverged_fraction`, the fraction of windows whose
    rollout left the finite range by each horizon.
    """
    dt = check_helicopter_data(trajectory, "prediction_error")
    horizons = [float(h) for h in horizons_s]
    if not horizons or any(h < 0 or not math.isfinite(h) for h in horizons):
        raise UsageError(f"prediction_error: horizons must be non-negative seconds, got {horizons_s}")
    lags = [int(round(h / dt)) for h in horizons]
    n_steps = max(max(lags), 1)
    starts = jnp.asarray(valid_starts(len(trajectory), n_steps, stride))
    result = _group_mse(system, trajectory, starts, n_steps, jnp.asarray(lags))
    return {name: result[name] for name in (*STATE_GROUPS, "diverged_fraction")}
