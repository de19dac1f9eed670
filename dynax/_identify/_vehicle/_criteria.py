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

from collections.abc import Callable
import dataclasses
import functools
import time
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, Scalar
import numpy as np
import optimistix as optx

from ..._data._trajectory import Trajectory
from ..._errors import DataError, UsageError
from ..._fit import AbstractStatistics, fit_minimise, History, monitor, notify, OptaxLBFGS, Parameters, Solution
from ..._model._helicopter import (
    ANGULAR_RATE,
    BODY,
    BODY_AXES,
    Helicopter,
    QUATERNION,
    quaternion_to_rotation,
    VELOCITY,
)
from ..._precision import ENABLE_X64
from ..._progress import ProgressBar
from .._method import AbstractMethod, FitSettings, IdentifyJob, Prepared
from ._records import FlightHeldOut, vehicle_record
from ._windows import check_helicopter_data, horizon_steps, lagged_loss, rollout, valid_starts


def one_record(records, who: str) -> Trajectory:
    """The one record a vehicle criterion fits (`records`: a `Trajectory`, or a list of one); flights
    joined into one record carry `FitSettings.breaks`."""
    if isinstance(records, Trajectory):
        return records
    if isinstance(records, (list, tuple)) and len(records) == 1 and isinstance(records[0], Trajectory):
        return records[0]
    raise UsageError(
        f"{who}: a vehicle criterion fits one record (join flights into one and give `breaks`), got "
        f"{type(records).__name__}" + (f" of {len(records)}" if isinstance(records, (list, tuple)) else "")
    )


def in_system(system, solution: Solution) -> Solution:
    """A criterion's `Solution` of `system.as_helicopter()` as `system`'s: the fitted body model in
    `system` (`with_body_model`: a quadrotor keeps its input scales), its parameters named by `system`."""
    fitted = system.with_body_model(solution.model.body_model)
    return eqx.tree_at(lambda s: (s.model, s.parameters), solution, (fitted, Parameters.of(fitted)))


class AbstractVehicleCriterion(AbstractMethod):
    """A learning criterion for a vehicle's body model (`OneStep`, `Lagged`, `Backprop`,
    `FrequencyDomain`): its `fit` learns the body model of a vehicle (a `Helicopter`, a `Quadrotor`:
    a system with `as_helicopter`, `body_frame` and `with_body_model`) from the one record in the
    coordinates `as_helicopter()` is fitted in, joined flights' `FitSettings.breaks` marked.

    `identify` runs it as every method: `prepare` (below), `fit_stage` (the `fit` once) and the
    validation of the fitted vehicle on the held-out flights.
    """

    def prepare(self, system, records: list[Trajectory], job: IdentifyJob) -> Prepared:
        """The records as one record in `system`'s fitted coordinates (`system.body_frame`; several
        flights joined, each one after the first a break: `join_flights`), and the held-out flights
        scored by the vehicle horizon error (`flight_error`: `FlightHeldOut`)."""
        record, breaks = vehicle_record(system, records, job.settings.breaks)
        held = job.held_out
        job = dataclasses.replace(
            job,
            settings=dataclasses.replace(job.settings, breaks=breaks),
            held_out=FlightHeldOut(held.records, held.horizons_s, held.source, held.tails_of),
        )
        return Prepared(self, [record], job)


class OneStep(AbstractVehicleCriterion):
    r"""One-step least squares on accelerations (finite-difference targets, frame change removed).

    **Fields:** `ridge`: a small Tikhonov term on the normal equations (relative to their trace).
    """

    ridge: float = 1e-10

    @property
    def label(self) -> str:
        return "one-step"

    def fit(self, system, records, settings: FitSettings = FitSettings()) -> Solution:
        """`fit_one_step` of `system` on the one record (`settings.breaks`: where joined flights begin)."""
        record = one_record(records, "OneStep")
        return in_system(system, fit_one_step(system.as_helicopter(), record, self, breaks=settings.breaks))


class Lagged(AbstractVehicleCriterion):
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
    - `lag_weights`: how the lags $1..H$ count in the loss. `"uniform"` (the default, the paper's
      loss): every lag's squared error alike. `"relative"`: each lag's residual of each body state
      divided by that lag's typical error, $\sigma_{h,s}$, the RMS change of the state over $h$
      samples on the fitted record (the error of holding the state; for the body rates, the
      constant-velocity baseline's), so the loss is $\frac{1}{|T|H}\sum_t\sum_h\sum_s
      \Lambda_s(\hat s_{t+h|t,s} - s_{t+h,s})^2/\sigma_{h,s}^2$ and holding the state scores 1 per
      state at every lag. An error one step ahead is tens of times smaller than one $H$ ahead, so
      uniformly summed the long lags outweigh the short ones; flight models are scored at each
      horizon relative to a baseline, and the relative weights count every lag as that score does.
      A number $p$ between 0 and 1 divides each residual by $\sigma_{h,s}^p$ instead: 0 is
      `"uniform"`, 1 is `"relative"`, and values between give the short
      lags part of the weight. The scales come from the record being fitted (the training flights)
      and stay fixed over the iteration.

    ??? cite "Reference"

        P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to
        modeling helicopters", NIPS 18, 2005 (Section 4, the EM-free algorithm; the uniform loss).
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
    lag_weights: Literal["uniform", "relative"] | float = eqx.field(static=True, default="uniform")

    def __check_init__(self):
        if self.lag_weights in ("uniform", "relative"):
            return
        if isinstance(self.lag_weights, str) or not 0.0 <= float(self.lag_weights) <= 1.0:
            raise UsageError(
                f"Lagged: lag_weights is 'uniform', 'relative' or a number from 0 to 1, not {self.lag_weights!r}"
            )

    @property
    def label(self) -> str:
        return "lagged"

    def fit(self, system, records, settings: FitSettings = FitSettings()) -> Solution:
        """`fit_lagged` from the one-step fit (or, with `settings.warm_start`, from `system`), with a
        progress bar per iteration (`settings.progress`) and `settings.callback`."""
        return _iterated(self, fit_lagged, self.max_iterations, system, one_record(records, "Lagged"), settings)


class Backprop(AbstractVehicleCriterion):
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

    @property
    def label(self) -> str:
        return "backprop"

    def fit(self, system, records, settings: FitSettings = FitSettings()) -> Solution:
        """`fit_backprop` from the one-step fit (or, with `settings.warm_start`, from `system`), with a
        progress bar per step (`settings.progress`) and `settings.callback`."""
        return _iterated(self, fit_backprop, self.max_steps, system, one_record(records, "Backprop"), settings)


def _iterated(criterion, fit, limit: int, system, trajectory, settings: FitSettings) -> Solution:
    """An iterative criterion's `fit`: from the one-step fit unless warm-started, a bar per iteration."""
    name = f"{type(criterion).__name__.lower()} fit"
    with ProgressBar(limit, name, progress=settings.progress, reduce="last") as bar:

        def report(iteration, loss):
            bar.reach(iteration + 1, loss=loss)
            if settings.callback is not None:
                settings.callback(iteration, loss)

        helicopter = system.as_helicopter()
        if not settings.warm_start:
            helicopter = fit_one_step(helicopter, trajectory, breaks=settings.breaks).model
        return in_system(system, fit(helicopter, trajectory, criterion, callback=report, breaks=settings.breaks))


class VehicleStatistics(AbstractStatistics):
    """What a vehicle fit (`fit_vehicle`) adds to its `Solution` (as `solution.statistics`).

    **Fields:**

    - `criterion`: the criterion's name (`one-step`, `frequency`, `lagged`, `backprop`).
    - `n_samples`: the number of samples fitted.
    - `accuracy`: for the frequency criterion, `(name, value, Cramer-Rao bound %, insensitivity %)`
      of each identified weight (empty for the others).
    - `eliminated`: for the frequency criterion, the weights its structure reduction dropped, in order.
    """

    criterion: str = eqx.field(static=True)
    n_samples: int = eqx.field(static=True)
    accuracy: tuple = eqx.field(static=True, default=())
    eliminated: tuple = eqx.field(static=True, default=())


def recorded_loss(solution: Solution) -> float:
    """The last recorded value of a vehicle fit's loss history (the criterion's own loss; for
    `lagged` and `backprop` the lagged loss), NaN if none was recorded."""
    history = solution.history
    return history[-1][1] if history else float("nan")


def vehicle_solution(
    system: Helicopter, fitted: Helicopter, losses, seconds, statistics: VehicleStatistics
) -> Solution:
    """The `Solution` of a one-shot vehicle fit (one-step, frequency): the fitted body model's free
    weights by name, no covariance (NaN), one step, the loss as recorded."""
    theta = fitted.body_model.parameter_vector()
    return _without_covariance(
        system,
        fitted,
        theta,
        statistics,
        result=optx.RESULTS.successful,
        loss=losses[-1],
        initial_loss=jnp.asarray(jnp.nan, theta.dtype),
        steps=jnp.asarray(1),
        loss_history=losses,
        time_history=seconds,
    )


def _without_covariance(system, fitted, theta, statistics: VehicleStatistics, **outcome) -> Solution:
    """A vehicle fit's `Solution`: the weights `theta` by name, no covariance (NaN); `outcome` the engine's fields
    (result, losses, steps, histories)."""
    n = theta.shape[0]
    return Solution(
        model=fitted,
        value=theta,
        parameters=Parameters.of(system),
        covariance=jnp.full((n, n), jnp.nan, theta.dtype),
        std_errors=jnp.full(n, jnp.nan, theta.dtype),
        statistics=statistics,
        **outcome,
    )


def one_shot_history(loss, seconds):
    """`losses`, `seconds` arrays of a one-shot criterion."""
    return jnp.asarray([loss], jnp.float64 if jax.config.jax_enable_x64 else jnp.float32), jnp.asarray([seconds])


_lagged_loss_jit = eqx.filter_jit(lagged_loss)  # compiled once per (model structure, data shape, horizon)


def with_theta(system: Helicopter, theta) -> Helicopter:
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
def normal_equations(system, trajectory, starts, n_steps, weights, use_rollout, batch_size, sensitivities=False):
    """Accumulate $A^\\top \\Lambda A$ and $A^\\top\\Lambda(y - c)$ over windows, in batches.

    With `sensitivities` (only with `use_rollout`), $A$ is the Jacobian of the rollout's body states
    and $c = \\hat s(\\theta) - A\\theta$: the Gauss-Newton linearisation of the true predictions.
    """
    theta = system.body_model.parameter_vector()
    dt = trajectory.ts[1] - trajectory.ts[0]
    n_params = theta.shape[0]
    w = weights.reshape(-1) if weights.ndim == 2 else jnp.tile(weights, n_steps)  # lag-major, as `target`

    def window(k):
        measured = jax.lax.dynamic_slice_in_dim(trajectory.xs, k, n_steps + 1)
        inputs = jax.lax.dynamic_slice_in_dim(trajectory.us, k, n_steps)
        target = measured[1:, BODY].reshape(-1)
        if sensitivities:
            g = lambda th: rollout(with_theta(system, th), measured[0], inputs, dt)[1:, BODY].reshape(-1)  # noqa: E731
            value, design = g(theta), jax.jacfwd(g)(theta)
            offset = value - design @ theta
            return (
                design.T @ (w[:, None] * design),
                design.T @ (w * (target - offset)),
                jnp.sum(w * (value - target) ** 2),
            )
        states = rollout(system, measured[0], inputs, dt) if use_rollout else measured
        states = jax.lax.stop_gradient(states)
        f = lambda th: _window_prediction(system, th, states, inputs, dt).reshape(-1)  # noqa: E731
        design = jax.jacfwd(f)(theta)
        offset = f(jnp.zeros_like(theta))
        return (
            design.T @ (w[:, None] * design),
            design.T @ (w * (target - offset)),
            jnp.sum(w * (f(theta) - target) ** 2),
        )

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
    (ata, atb, sse), _ = jax.lax.scan(
        batch, init, (padded.reshape(n_batches, batch_size), mask.reshape(n_batches, batch_size))
    )
    return ata, atb, sse / (n * n_steps)


def ridge_solve(ata, atb, ridge):
    scale = jnp.trace(ata) / ata.shape[0]
    return jnp.linalg.solve(ata + ridge * scale * jnp.eye(ata.shape[0], dtype=ata.dtype), atb)


def _check_solvable(ata, ridge, theta, where: str) -> None:
    """Raise where the least-squares weights cannot be trusted: not finite, or normal equations (with the ridge
    `ridge_solve` adds) singular to the precision they were solved in (condition number times machine epsilon of at
    least 1; float32 with JAX's float64 mode off, on nearly collinear motor features). In float64 the relative ridge
    keeps the condition number far below that, so this never stops a float64 fit."""
    regularised = np.asarray(ata, dtype=np.float64)
    regularised = regularised + ridge * np.trace(regularised) / regularised.shape[0] * np.eye(regularised.shape[0])
    condition = float(np.linalg.cond(regularised))
    if bool(jnp.all(jnp.isfinite(theta))) and condition * float(jnp.finfo(ata.dtype).eps) < 1:
        return
    fix = f"call {ENABLE_X64} first, or " if ata.dtype == jnp.float32 else ""
    raise FloatingPointError(
        f"{where}: the least-squares weights cannot be trusted: the normal equations ({ata.dtype}, condition number "
        f"{condition:.3g}) are singular at that precision; {fix}raise the criterion's `ridge`"
    )


def _check_equations(system, windows: int, where: str, path) -> None:
    """Refuse a record that gives fewer one-step equations on a body axis than the weights the model fits there
    (its mask's row): the ridge, not the data, would set the rest, and the weights would be returned as if fitted."""
    free = np.asarray(system.body_model.mask, bool).sum(axis=1)
    axis = int(np.argmax(free))
    if windows < free[axis]:
        raise DataError(
            f"{where}: the record gives {windows} one-step equation(s) per body axis, fewer than the {int(free[axis])} "
            f"weights the model fits on `{BODY_AXES[axis]}`: give a longer flight (or fit fewer weights: the model's "
            "mask)",
            path=path or None,
        )


def window_starts(trajectory, n_steps, stride, breaks=None):
    return jnp.asarray(valid_starts(len(trajectory), n_steps, stride, breaks))


def state_weights(weights, dtype):
    return jnp.ones(6, dtype) if weights is None else jnp.asarray(weights, dtype)


def relative_lag_weights(trajectory: Trajectory, starts, n_steps: int, weights, power: float = 1.0):
    r"""`Lagged(lag_weights="relative")`'s weights, shape `(n_steps, 6)`: $\Lambda_s / \sigma_{h,s}^{2p}$
    (`power` $p$), with $\sigma_{h,s}^2$ the mean square change of body state $s$ over $h$ samples from
    the windows' `starts` (the error of holding the state; floored at $10^{-12}$ of the largest, for a
    state that never moves)."""
    body = trajectory.xs[:, BODY]
    ahead = body[starts[:, None] + jnp.arange(1, n_steps + 1)[None, :]]
    square = jnp.mean((ahead - body[starts][:, None, :]) ** 2, axis=0)
    square = jnp.maximum(square, 1e-12 * jnp.max(square))
    return weights[None, :] / square**power


def fit_one_step(
    system: Helicopter, trajectory: Trajectory, criterion: OneStep = OneStep(), *, weights=None, breaks=None
) -> Solution:
    r"""Fit by one-step least squares (see `OneStep` and the module docstring); `breaks`: see `fit_vehicle`.

    The `Solution`'s covariance is the least-squares one, $\hat\sigma^2 (A^\top A)^{-1}$ with
    $\hat\sigma^2$ the residual variance over the $6 \times$ windows residuals less the weights (a
    lower bound: the residuals are correlated in time).
    """
    check_helicopter_data(trajectory, "fit_one_step")
    t0 = time.perf_counter()
    w = state_weights(weights, trajectory.xs.dtype)
    starts = window_starts(trajectory, 1, 1, breaks)
    _check_equations(system, int(starts.shape[0]), "fit_one_step", trajectory.source)
    ata, atb, _ = normal_equations(system, trajectory, starts, 1, w, False, 1024)
    theta = ridge_solve(ata, atb, criterion.ridge)
    _check_solvable(ata, criterion.ridge, theta, "fit_one_step")
    fitted = with_theta(system, theta)
    ata, _, loss = normal_equations(fitted, trajectory, starts, 1, w, False, 1024)
    losses, seconds = one_shot_history(loss, time.perf_counter() - t0)
    solution = vehicle_solution(system, fitted, losses, seconds, VehicleStatistics("one-step", len(trajectory)))
    windows = int(starts.shape[0])  # `loss` is per window, its six body axes summed
    sigma2 = loss * windows / max(6 * windows - theta.shape[0], 1)
    covariance = sigma2 * jnp.linalg.pinv(ata)
    std = jnp.sqrt(jnp.diag(covariance))
    return eqx.tree_at(lambda s: (s.covariance, s.std_errors), solution, (covariance, std))


class _EMFreeState(eqx.Module):
    step: Int[Array, ""]
    f: Scalar
    terminate: Bool[Array, ""]
    history: History
    normal: Float[Array, "n n"]  # the last step's normal equations, for the precision check after the loop


class EMFree(optx.AbstractMinimiser):
    r"""The EM-free iteration of Abbeel, Ganapathi and Ng (2005) as an optimistix minimiser.

    Each step linearises the predictions about the current iterate (`linearise(theta, args) ->
    (A^T Lambda A, A^T Lambda (y - c))`, the normal equations of the affine predictor with the
    current rollout's states held fixed; see the module docstring), solves them with a small ridge
    term, and takes the first step size along (new - old) that lowers the true objective `fn`
    (or, with `best_step`, the best of all step sizes). It stops when no step size lowers the
    objective or when the relative decrease is below `rtol`. The objective never increases: each
    accepted step lowers it, and a step that lowers nothing ends the iteration.

    **Fields:**

    - `linearise`: the normal equations at `theta` (static).
    - `rtol`: the relative-decrease tolerance (`Lagged.tolerance`); `atol` unused.
    - `ridge`: Tikhonov term relative to the trace of the normal equations.
    - `step_sizes`, `best_step`: the line search (see `Lagged`).
    - `history`: length of the recorded loss and wall-clock history (`max_iterations + 1`).
    - `token`: a `dynax._fit.monitor` token; each accepted iteration is reported to the host.

    ??? cite "Reference"

        P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to
        modeling helicopters", NIPS 18, 2005 (Section 4, the EM-free algorithm).
    """

    linearise: Callable = eqx.field(static=True)
    rtol: float = 1e-4
    atol: float = 0.0
    norm: Callable = eqx.field(static=True, default=optx.max_norm)
    ridge: float = 1e-10
    step_sizes: tuple[float, ...] = eqx.field(static=True, default=(1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125))
    best_step: bool = eqx.field(static=True, default=False)
    history: int = eqx.field(static=True, default=1)
    token: Int[Array, ""] | int = 0

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        f, _ = fn(y, args)
        normal = jnp.zeros((y.shape[0], y.shape[0]), y.dtype)
        return _EMFreeState(jnp.array(0), f, jnp.array(False), History.start(max(self.history, 1), f), normal)

    def step(self, fn, y, args, options, state, tags):
        ata, atb = self.linearise(y, args)
        direction = ridge_solve(ata, atb, self.ridge) - y
        sizes = jnp.asarray(self.step_sizes, y.dtype)
        n_sizes = len(self.step_sizes)

        def untried(carry):
            i, _, _, accepted = carry
            return (i < n_sizes) & (jnp.asarray(self.best_step) | ~accepted)

        def try_size(carry):
            i, best_y, best_f, accepted = carry
            candidate = y + sizes[i] * direction
            value, _ = fn(candidate, args)
            better = jnp.isfinite(value) & (value < best_f)
            return (i + 1, jnp.where(better, candidate, best_y), jnp.where(better, value, best_f), accepted | better)

        _, new_y, new_f, accepted = jax.lax.while_loop(untried, try_size, (0, y, state.f, jnp.array(False)))
        terminate = ~accepted | ((state.f - new_f) / state.f < self.rtol)
        notify(self.token, state.step, new_f, accepted)
        history = state.history.record(state.step + 1, new_f, accepted)
        return new_y, _EMFreeState(state.step + 1, new_f, terminate, history, ata), None

    def terminate(self, fn, y, args, options, state, tags):
        return state.terminate, optx.RESULTS.successful

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return y, aux, state.history.stats()


def _lagged_objective(theta, args, *, n_steps):
    system, trajectory, starts, w = args
    return lagged_loss(with_theta(system, theta), trajectory, n_steps, starts=starts, weights=w)


def _em_free_normal_equations(theta, args, *, n_steps, batch_size, sensitivities):
    system, trajectory, starts, w = args
    ata, atb, _ = normal_equations(
        with_theta(system, theta), trajectory, starts, n_steps, w, True, batch_size, sensitivities
    )
    return ata, atb


@eqx.filter_jit
def _em_free(system, trajectory, starts, w, n_steps: int, criterion: Lagged, token):
    linearise = functools.partial(
        _em_free_normal_equations,
        n_steps=n_steps,
        batch_size=criterion.batch_size,
        sensitivities=criterion.state_sensitivities,
    )
    solver = EMFree(
        linearise,
        rtol=criterion.tolerance,
        ridge=criterion.ridge,
        step_sizes=criterion.step_sizes,
        best_step=criterion.best_step,
        history=criterion.max_iterations + 1,
        token=token,
    )
    objective = functools.partial(_lagged_objective, n_steps=n_steps)
    theta0 = system.body_model.parameter_vector()
    return optx.minimise(
        objective, solver, theta0, (system, trajectory, starts, w), max_steps=criterion.max_iterations, throw=False
    )


def _vehicle_solution(system, fitted, theta, solution, statistics: VehicleStatistics) -> Solution:
    """The engine's `Solution` of an iterative vehicle fit (no covariance: NaN)."""
    history = solution.stats["loss_history"]
    return _without_covariance(
        system,
        fitted,
        theta,
        statistics,
        result=solution.result,
        loss=solution.state.f,
        initial_loss=history[0],
        steps=solution.stats["num_steps"],
        loss_history=history,
        time_history=solution.stats["time_history"],
    )


def fit_lagged(
    system: Helicopter,
    trajectory: Trajectory,
    criterion: Lagged = Lagged(),
    *,
    weights=None,
    callback=None,
    breaks=None,
) -> Solution:
    """Minimise the lagged loss by the EM-free iteration with line search (see `Lagged`, `EMFree`).

    The whole iteration runs compiled (`optimistix.minimise` with the `EMFree` solver, one
    `while_loop`); `callback(iteration, loss)` is called from it after every accepted iteration
    (through `jax.debug.callback`, for progress).
    """
    dt = check_helicopter_data(trajectory, "fit_lagged")
    n_steps = horizon_steps(criterion.horizon, dt, "fit_lagged")
    starts = window_starts(trajectory, n_steps, criterion.stride, breaks)
    w = state_weights(weights, trajectory.xs.dtype)
    if criterion.lag_weights != "uniform":
        power = 1.0 if criterion.lag_weights == "relative" else float(criterion.lag_weights)
        w = relative_lag_weights(trajectory, starts, n_steps, w, power)
    with monitor(callback) as token:
        solution = _em_free(system, trajectory, starts, w, n_steps, criterion, token)
    theta = solution.value
    if int(solution.stats["num_steps"]) > 0:  # each step solved normal equations as ill-conditioned as the last
        _check_solvable(solution.state.normal, criterion.ridge, theta, "fit_lagged")
    fitted = with_theta(system, theta)
    return _vehicle_solution(system, fitted, theta, solution, VehicleStatistics("lagged", len(trajectory)))


def _backprop_loss(model, args, *, n_steps, checkpoint_segment):
    trajectory, starts, w = args
    return lagged_loss(model, trajectory, n_steps, starts=starts, weights=w, checkpoint_segment=checkpoint_segment)


@eqx.filter_jit
def _backprop(system, trajectory, starts, w, n_steps: int, criterion: Backprop, target, token):
    solver = OptaxLBFGS(rtol=criterion.tolerance, target=target, history=criterion.max_steps + 1, token=token)
    loss = functools.partial(_backprop_loss, n_steps=n_steps, checkpoint_segment=criterion.checkpoint_segment)
    # Unit scale: the solver sees the weights themselves, as optax's L-BFGS always did here.
    return fit_minimise(
        loss,
        system,
        Parameters.of(system),
        (trajectory, starts, w),
        solver=solver,
        scale=1.0,
        max_steps=criterion.max_steps,
        covariance=False,
    )


def fit_backprop(
    system: Helicopter,
    trajectory: Trajectory,
    criterion: Backprop = Backprop(),
    *,
    weights=None,
    callback=None,
    breaks=None,
) -> Solution:
    """Minimise the lagged loss by L-BFGS with gradients through checkpointed rollouts (see `Backprop`).

    The engine's `fit_minimise` with `OptaxLBFGS` (optax's L-BFGS as an optimistix minimiser), one
    compiled `while_loop`; `callback(iteration, loss)` is called from it after every step.
    """
    dt = check_helicopter_data(trajectory, "fit_backprop")
    n_steps = horizon_steps(criterion.horizon, dt, "fit_backprop")
    starts = window_starts(trajectory, n_steps, criterion.stride, breaks)
    w = state_weights(weights, trajectory.xs.dtype)
    target = -jnp.inf if criterion.target_loss is None else criterion.target_loss
    with monitor(callback) as token:
        solution = _backprop(system, trajectory, starts, w, n_steps, criterion, jnp.asarray(target, w.dtype), token)
    return eqx.tree_at(
        lambda s: s.statistics, solution, VehicleStatistics("backprop", len(trajectory)), is_leaf=lambda x: x is None
    )


def auto_stride(n_samples: int, n_steps: int, windows: int = 600) -> int:
    """The smallest stride that uses at most about `windows` start times of a record of `n_samples`
    samples with a horizon of `n_steps` samples (1: every start, when there are no more than that)."""
    n_starts = max(n_samples - n_steps, 1)
    return max(1, -(-n_starts // max(int(windows), 1)))


def lagged_loss_of(
    system: Helicopter, trajectory: Trajectory, horizon: float, *, stride: int = 1, weights=None
) -> float:
    """The lagged loss of `system` on `trajectory` over `horizon` seconds (every `stride`-th start)."""
    dt = check_helicopter_data(trajectory, "lagged_loss_of")
    n_steps = horizon_steps(horizon, dt, "lagged_loss_of")
    starts = window_starts(trajectory, n_steps, stride)
    w = state_weights(weights, trajectory.xs.dtype)
    return float(_lagged_loss_jit(system, trajectory, n_steps, starts=starts, weights=w))


def lagged_loss_gradient_norm(
    system: Helicopter, trajectory: Trajectory, horizon: float, *, stride: int = 1, weights=None
) -> float:
    """The norm of the lagged loss's gradient with respect to the body model's weights.

    Zero at a stationary point of the loss; at the EM-free fixed point it is not (see `Lagged`).
    """
    dt = check_helicopter_data(trajectory, "lagged_loss_gradient_norm")
    n_steps = horizon_steps(horizon, dt, "lagged_loss_gradient_norm")
    starts = window_starts(trajectory, n_steps, stride)
    w = state_weights(weights, trajectory.xs.dtype)
    theta = system.body_model.parameter_vector()
    grad = jax.jit(
        jax.grad(lambda t: lagged_loss(with_theta(system, t), trajectory, n_steps, starts=starts, weights=w))
    )(theta)
    return float(jnp.linalg.norm(grad))
