r"""Learning criteria for vehicle body models: one-step, lagged (EM-free) and backprop.

All three fit the free weights $\theta = W[M]$ of a `Helicopter`'s body model (see
`dynax._model._helicopter`), whose body-frame derivatives are linear in $\theta$. The frequency-domain
criterion lives in `_frequency.py`.

**The affine multi-step predictor.** Fix a trajectory of states $\hat x_0, \dots, \hat x_H$ (the
current model's rollout from the measured $x_t$, or for one-step the measured states themselves).
In the world frame the velocity obeys $\frac{d}{dt}(R\nu) = R(\omega\times\nu + k_\nu) + R W_\nu\phi$,
and the body rates $\dot\omega = k_\omega + W_\omega\phi$. Integrating with the trapezoidal rule over
each zero-order-hold interval,

$$\hat\nu_{t+h} = \hat R_h^\top\Big(R_t\nu_t + \sum_{j<h}\tfrac{\Delta t}{2}\big[\hat R_j(\hat\omega_j\times\hat\nu_j
+ \hat k_j + W_\nu\hat\phi_j) + \hat R_{j+1}(\cdots)_{j+1}\big]\Big),\qquad
\hat\omega_{t+h} = \omega_t + \sum_{j<h}\tfrac{\Delta t}{2}\big[\hat k_j + W_\omega\hat\phi_j + \cdots_{j+1}\big],$$

which is *affine in $\theta$* once the states $\hat x_j$ (hence $\hat R_j$, $\hat\phi_j$, $\hat k_j$) are
fixed. Minimising the squared error of these predictions against the measured $s_{t+h}$ is one
linear least-squares problem. The frame change (rotation of the body axes along the way) is thereby
removed exactly, and the acceleration model's known part contributes $R(\omega\times\nu + k_\nu) = g$.

- `OneStep`: $H = 1$ on the measured states: least squares on finite-difference
  accelerations with the frame change removed (for the linear model: on next-step velocities).
- `Lagged`: the paper's EM-free iteration: roll the current model out from every start, solve
  the least squares above with the rollout states fixed, then a backtracking line search on the
  true lagged loss (`lagged_loss`) between the old and new weights. The loss decreases monotonically.
  Holding the predicted states fixed is an approximation: the iteration's fixed point solves
  $J_\text{fixed}^\top\Lambda r = 0$, not $J^\top\Lambda r = 0$ with the full Jacobian of the
  predictions, so it stops above the loss's minimum (7 % in hover, 12 % aerobatic on the
  experiment's flights). `Lagged(state_sensitivities=True)` uses the full Jacobian (forward mode
  through the rollout), making each solve a Gauss-Newton step on the true loss.
- `Backprop`: the same lagged loss minimised directly by L-BFGS (optax) with gradients through
  the checkpointed diffrax rollouts, vmapped over start times.

??? cite "References"

    P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to modeling
    helicopters", NIPS 18, 2005.

    P. Abbeel and A. Y. Ng, "Learning first-order Markov models for control", NIPS 17, 2004.
"""

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..._data._trajectory import Trajectory
from ..._model._helicopter import ANGULAR_RATE, BODY, Helicopter, QUATERNION, VELOCITY, quaternion_to_rotation
from ._windows import check_helicopter_data, horizon_steps, lagged_loss, rollout, valid_starts


class OneStep(eqx.Module):
    r"""One-step least squares on accelerations (finite-difference targets, frame change removed).

    **Fields:** `ridge`: a small Tikhonov term on the normal equations (relative to their trace).
    """

    ridge: float = 1e-10


class Lagged(eqx.Module):
    r"""The lagged criterion over `horizon` seconds, minimised by the EM-free iteration.

    **Fields:**

    - `horizon`: $H$ [s] (default 1.0).
    - `max_iterations`: EM-free iterations (default 20).
    - `tolerance`: stop when the relative loss decrease is below this (default 1e-4).
    - `stride`: use every `stride`-th start time (default 1: every start).
    - `batch_size`: start times per batch when accumulating the normal equations.
    - `ridge`: Tikhonov term relative to the trace of the normal equations.
    - `step_sizes`: the line search's steps along (new - old) weights, tried in order.
    - `best_step`: take the best of all `step_sizes` (an exact line search on that grid) rather than
      the first that decreases the loss.
    - `state_sensitivities`: *not the paper's algorithm* (default `False`). With `True` the design
      matrix is the full Jacobian of the rollout's body states with respect to the weights,
      including how the weights move the predicted states at which the features are evaluated, and
      the offset is the rollout itself: each least-squares solve is then a Gauss-Newton step on
      the true lagged loss, whose fixed point is a stationary point of that loss. The paper's
      EM-free iteration holds the predicted states fixed, so its fixed point is stationary for a
      slightly different problem (see `docs/helicopter.md`, "The EM-free approximation").

    ??? cite "Reference"

        P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to
        modeling helicopters", NIPS 18, 2005 (Section 4, the EM-free algorithm).
    """

    horizon: float = 1.0
    max_iterations: int = eqx.field(static=True, default=20)
    tolerance: float = 1e-4
    stride: int = eqx.field(static=True, default=1)
    batch_size: int = eqx.field(static=True, default=128)
    ridge: float = 1e-10
    step_sizes: tuple[float, ...] = eqx.field(static=True, default=(1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125))
    best_step: bool = eqx.field(static=True, default=False)
    state_sensitivities: bool = eqx.field(static=True, default=False)


class Backprop(eqx.Module):
    r"""The lagged loss minimised directly by L-BFGS (optax) through checkpointed diffrax rollouts.

    **Fields:**

    - `horizon`: $H$ [s] (default 1.0).
    - `max_steps`: optimiser steps (default 100).
    - `tolerance`: stop when the relative loss decrease over a step is below this (default 1e-7).
    - `stride`: use every `stride`-th start time.
    - `checkpoint_segment`: steps per checkpointed segment (`None`: $\lceil\sqrt{H}\rceil$; 0: off).
    - `target_loss`: stop as soon as the loss is at or below this (for timing comparisons).
    """

    horizon: float = 1.0
    max_steps: int = eqx.field(static=True, default=100)
    tolerance: float = 1e-7
    stride: int = eqx.field(static=True, default=1)
    checkpoint_segment: int | None = eqx.field(static=True, default=None)
    target_loss: float | None = None


class VehicleFit(eqx.Module):
    """The result of `fit_vehicle`.

    **Fields:**

    - `system`: the fitted `Helicopter`.
    - `criterion`: the criterion's name (`one-step`, `frequency`, `lagged`, `backprop`).
    - `loss`: the final value of the criterion's own loss (for `lagged` and `backprop` the lagged loss).
    - `history`: `(seconds since start, loss)` after each iteration, as a tuple of pairs.
    - `n_samples`: the number of samples fitted.
    - `statistics`: for the frequency criterion, `(name, value, Cramer-Rao bound %, insensitivity %)`
      of each identified weight (empty for the others).
    - `eliminated`: for the frequency criterion, the weights its structure reduction dropped, in order.
    """

    system: Helicopter
    criterion: str = eqx.field(static=True)
    loss: float = eqx.field(static=True)
    history: tuple = eqx.field(static=True)
    n_samples: int = eqx.field(static=True)
    statistics: tuple = eqx.field(static=True, default=())
    eliminated: tuple = eqx.field(static=True, default=())


_lagged_loss_jit = eqx.filter_jit(lagged_loss)  # compiled once per (model structure, data shape, horizon)


def _with_theta(system: Helicopter, theta) -> Helicopter:
    return eqx.tree_at(lambda h: h.body_model, system, system.body_model.with_parameter_vector(theta))


def _window_prediction(system: Helicopter, theta, states, inputs, dt):
    """The affine predictor (module docstring): body states at lags 1..H, shape (H, 6)."""
    body_model = system.body_model.with_parameter_vector(theta)

    def point(x, u):
        rotation = quaternion_to_rotation(x[QUATERNION])
        s = x[BODY]
        d = body_model(x[QUATERNION], s, u)
        world = rotation @ (jnp.cross(s[3:], s[:3]) + d[:3])
        return world, d[3:]

    wa, ra = jax.vmap(point)(states[:-1], inputs)
    wb, rb = jax.vmap(point)(states[1:], inputs)
    x0 = states[0]
    v_world = (quaternion_to_rotation(x0[QUATERNION]) @ x0[VELOCITY])[None, :] + jnp.cumsum(dt / 2 * (wa + wb), axis=0)
    rotations = jax.vmap(quaternion_to_rotation)(states[1:, QUATERNION])
    v_body = jnp.einsum("hji,hj->hi", rotations, v_world)
    rates = x0[ANGULAR_RATE][None, :] + jnp.cumsum(dt / 2 * (ra + rb), axis=0)
    return jnp.concatenate([v_body, rates], axis=-1)


@eqx.filter_jit
def _normal_equations(system, trajectory, starts, n_steps, weights, use_rollout, batch_size, sensitivities=False):
    """Accumulate $A^\\top \\Lambda A$ and $A^\\top\\Lambda(y - c)$ over windows, in batches.

    With `sensitivities` (only with `use_rollout`), $A$ is the Jacobian of the rollout's body states
    and $c = \\hat s(\\theta) - A\\theta$: the Gauss-Newton linearisation of the true predictions.
    """
    theta = system.body_model.parameter_vector()
    dt = trajectory.ts[1] - trajectory.ts[0]
    n_params = theta.shape[0]
    w = jnp.tile(weights, n_steps)

    def window(k):
        measured = jax.lax.dynamic_slice_in_dim(trajectory.xs, k, n_steps + 1)
        inputs = jax.lax.dynamic_slice_in_dim(trajectory.us, k, n_steps)
        target = measured[1:, BODY].reshape(-1)
        if sensitivities:
            g = lambda th: rollout(_with_theta(system, th), measured[0], inputs, dt)[1:, BODY].reshape(-1)  # noqa: E731
            value, design = g(theta), jax.jacfwd(g)(theta)
            offset = value - design @ theta
            return design.T @ (w[:, None] * design), design.T @ (w * (target - offset)), jnp.sum(w * (value - target) ** 2)
        states = rollout(system, measured[0], inputs, dt) if use_rollout else measured
        states = jax.lax.stop_gradient(states)
        f = lambda th: _window_prediction(system, th, states, inputs, dt).reshape(-1)  # noqa: E731
        design = jax.jacfwd(f)(theta)
        offset = f(jnp.zeros_like(theta))
        return design.T @ (w[:, None] * design), design.T @ (w * (target - offset)), jnp.sum(w * (f(theta) - target) ** 2)

    n = starts.shape[0]
    n_batches = -(-n // batch_size)
    padded = jnp.concatenate([starts, jnp.zeros(n_batches * batch_size - n, starts.dtype)])
    mask = (jnp.arange(n_batches * batch_size) < n).astype(theta.dtype)

    def batch(carry, rows):
        ks, m = rows
        ata, atb, sse = jax.vmap(window)(ks)
        return (
            carry[0] + jnp.einsum("b,bij->ij", m, ata),
            carry[1] + m @ atb,
            carry[2] + m @ sse,
        ), None

    init = (jnp.zeros((n_params, n_params), theta.dtype), jnp.zeros(n_params, theta.dtype), jnp.zeros((), theta.dtype))
    (ata, atb, sse), _ = jax.lax.scan(batch, init, (padded.reshape(n_batches, batch_size), mask.reshape(n_batches, batch_size)))
    return ata, atb, sse / (n * n_steps)


def _solve(ata, atb, ridge):
    scale = jnp.trace(ata) / ata.shape[0]
    return jnp.linalg.solve(ata + ridge * scale * jnp.eye(ata.shape[0], dtype=ata.dtype), atb)


def _starts(trajectory, n_steps, stride):
    return jnp.asarray(valid_starts(len(trajectory), n_steps, stride))


def _weights(weights, dtype):
    return jnp.ones(6, dtype) if weights is None else jnp.asarray(weights, dtype)


def fit_one_step(system: Helicopter, trajectory: Trajectory, criterion: OneStep = OneStep(), *, weights=None) -> VehicleFit:
    """Fit by one-step least squares (see `OneStep` and the module docstring)."""
    check_helicopter_data(trajectory, "fit_one_step")
    t0 = time.perf_counter()
    w = _weights(weights, trajectory.xs.dtype)
    starts = _starts(trajectory, 1, 1)
    ata, atb, _ = _normal_equations(system, trajectory, starts, 1, w, False, 1024)
    theta = _solve(ata, atb, criterion.ridge)
    fitted = _with_theta(system, theta)
    _, _, loss = _normal_equations(fitted, trajectory, starts, 1, w, False, 1024)
    loss = float(loss)
    return VehicleFit(fitted, "one-step", loss, ((time.perf_counter() - t0, loss),), len(trajectory))


def fit_lagged(
    system: Helicopter, trajectory: Trajectory, criterion: Lagged = Lagged(), *, weights=None, callback=None
) -> VehicleFit:
    """Minimise the lagged loss by the EM-free iteration with line search (see `Lagged`).

    `callback(iteration, loss)` is called after every iteration (for progress).
    """
    dt = check_helicopter_data(trajectory, "fit_lagged")
    n_steps = horizon_steps(criterion.horizon, dt, "fit_lagged")
    starts = _starts(trajectory, n_steps, criterion.stride)
    w = _weights(weights, trajectory.xs.dtype)
    loss_fn = lambda s: _lagged_loss_jit(s, trajectory, n_steps, starts=starts, weights=w)  # noqa: E731
    t0 = time.perf_counter()
    current = float(loss_fn(system))
    history = [(time.perf_counter() - t0, current)]
    for iteration in range(criterion.max_iterations):
        ata, atb, _ = _normal_equations(
            system, trajectory, starts, n_steps, w, True, criterion.batch_size, criterion.state_sensitivities
        )
        theta_old = system.body_model.parameter_vector()
        theta_new = _solve(ata, atb, criterion.ridge)
        accepted = None
        for step in criterion.step_sizes:
            candidate = _with_theta(system, theta_old + step * (theta_new - theta_old))
            value = float(loss_fn(candidate))
            if np.isfinite(value) and value < (current if accepted is None else accepted[1]):
                accepted = candidate, value
                if not criterion.best_step:
                    break
        if accepted is None:
            break
        system, value = accepted
        improvement = (current - value) / current
        current = value
        history.append((time.perf_counter() - t0, current))
        if callback is not None:
            callback(iteration, current)
        if improvement < criterion.tolerance:
            break
    return VehicleFit(system, "lagged", current, tuple(history), len(trajectory))


def fit_backprop(
    system: Helicopter, trajectory: Trajectory, criterion: Backprop = Backprop(), *, weights=None, callback=None
) -> VehicleFit:
    """Minimise the lagged loss by L-BFGS with gradients through checkpointed rollouts (see `Backprop`)."""
    dt = check_helicopter_data(trajectory, "fit_backprop")
    n_steps = horizon_steps(criterion.horizon, dt, "fit_backprop")
    starts = _starts(trajectory, n_steps, criterion.stride)
    w = _weights(weights, trajectory.xs.dtype)

    def loss_fn(theta):
        return lagged_loss(
            _with_theta(system, theta), trajectory, n_steps, starts=starts, weights=w,
            checkpoint_segment=criterion.checkpoint_segment,
        )

    optimiser = optax.lbfgs()
    value_and_grad = optax.value_and_grad_from_state(loss_fn)

    @jax.jit
    def step(theta, state):
        value, grad = value_and_grad(theta, state=state)
        updates, state = optimiser.update(grad, state, theta, value=value, grad=grad, value_fn=loss_fn)
        return optax.apply_updates(theta, updates), state, value

    theta = system.body_model.parameter_vector()
    state = optimiser.init(theta)
    t0 = time.perf_counter()
    current = float(jax.jit(loss_fn)(theta))
    history = [(time.perf_counter() - t0, current)]
    for iteration in range(criterion.max_steps):
        new_theta, new_state, _ = step(theta, state)
        value = float(optax.tree_utils.tree_get(new_state, "value"))  # the loss at `new_theta`
        if not np.isfinite(value):
            break
        improvement = (current - value) / current
        theta, state, current = new_theta, new_state, value
        history.append((time.perf_counter() - t0, current))
        if callback is not None:
            callback(iteration, current)
        if criterion.target_loss is not None and current <= criterion.target_loss:
            break
        if 0 <= improvement < criterion.tolerance:
            break
    return VehicleFit(_with_theta(system, theta), "backprop", current, tuple(history), len(trajectory))


def lagged_loss_of(system: Helicopter, trajectory: Trajectory, horizon: float, *, stride: int = 1, weights=None) -> float:
    """The lagged loss of `system` on `trajectory` over `horizon` seconds (every `stride`-th start)."""
    dt = check_helicopter_data(trajectory, "lagged_loss_of")
    n_steps = horizon_steps(horizon, dt, "lagged_loss_of")
    starts = _starts(trajectory, n_steps, stride)
    w = _weights(weights, trajectory.xs.dtype)
    return float(_lagged_loss_jit(system, trajectory, n_steps, starts=starts, weights=w))


def lagged_loss_gradient_norm(
    system: Helicopter, trajectory: Trajectory, horizon: float, *, stride: int = 1, weights=None
) -> float:
    """The norm of the lagged loss's gradient with respect to the body model's weights.

    Zero at a stationary point of the loss; at the EM-free fixed point it is not (see `Lagged`).
    """
    dt = check_helicopter_data(trajectory, "lagged_loss_gradient_norm")
    n_steps = horizon_steps(horizon, dt, "lagged_loss_gradient_norm")
    starts = _starts(trajectory, n_steps, stride)
    w = _weights(weights, trajectory.xs.dtype)
    theta = system.body_model.parameter_vector()
    grad = jax.jit(jax.grad(lambda t: lagged_loss(_with_theta(system, t), trajectory, n_steps, starts=starts, weights=w)))(theta)
    return float(jnp.linalg.norm(grad))
