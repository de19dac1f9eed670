"""Closed-loop simulation with a controller in the loop, and swing-up metrics."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._model._system import AbstractSystem
from .._simulate import FixedGrid, mask_diverged, sample_interval
from ._lqr import wrap_angle

Controller = Callable[[Float[Array, ""], Float[Array, " n_states"]], Float[Array, " n_inputs"]]
"""A controller: a callable (usually an `eqx.Module`) `controller(t, x) -> u`."""


class ClosedLoop(eqx.Module):
    """The result of `simulate_closed_loop`.

    **Fields:**

    - `ts`: the control sample times, shape `(time,)`.
    - `xs`: the states at `ts`, shape `(time, n_states)`; `xs[0] = x0`. Past a divergence the
      rows are NaN.
    - `us`: the inputs the controller applied, held on $[t_k, t_{k+1})$, shape
      `(time, n_inputs)` (the last row is the controller's output at the final state).
    - `diverged_at`: the first sample time at which the state left the finite range, `inf` if it
      stayed bounded.
    """

    ts: Float[Array, " time"]
    xs: Float[Array, "time n_states"]
    us: Float[Array, "time n_inputs"]
    diverged_at: Float[Array, ""]


def simulate_closed_loop(
    system: AbstractSystem,
    controller: Controller,
    x0: Float[ArrayLike, " n_states"],
    ts: Float[ArrayLike, " time"],
    *,
    method: FixedGrid = FixedGrid(),
    divergence_bound: float = 1e6,
) -> ClosedLoop:
    r"""Simulate `system` under sampled-data feedback `u_k = controller(t_k, x_k)` with a zero-order hold.

    The controller runs at the sample times `ts` (for example 100 Hz); between samples the
    input is held and the plant is integrated with `method.substeps` steps of a diffrax solver,
    all inside one `lax.scan` (the same integration as `simulate(..., method=FixedGrid())`).
    The function is pure: `jit` it, `vmap` it over initial states or controller parameters,
    and differentiate through it. A divergent rollout is reported in `diverged_at`, never
    raised, so populations can contain unstable members.

    **Arguments:**

    - `system`: the plant (a dynax system).
    - `controller`: `controller(t, x) -> u` with `u` of shape `(n_inputs,)`; it sees the plant's
      state (full-state feedback).
    - `x0`: initial state, shape `(n_states,)`.
    - `ts`: strictly increasing control sample times, shape `(time,)`.
    - `method`: a `FixedGrid` integration method.
    - `divergence_bound`: a state entry larger than this in magnitude counts as divergence.

    **Returns:**

    A `ClosedLoop` with `ts`, `xs`, `us` and `diverged_at`.
    """
    if not isinstance(system, AbstractSystem):
        raise ValueError(f"simulate_closed_loop: `system` must be a dynax system, got {type(system).__name__}")
    if not isinstance(method, FixedGrid):
        raise ValueError(f"simulate_closed_loop: `method` must be FixedGrid, got {type(method).__name__}")
    x0 = jnp.asarray(x0)
    ts = jnp.asarray(ts)
    if x0.shape != (system.n_states,):
        raise ValueError(f"simulate_closed_loop: `x0` must have shape ({system.n_states},), got {x0.shape}")
    if ts.ndim != 1 or ts.shape[0] < 2:
        raise ValueError(f"simulate_closed_loop: `ts` must be 1-d with at least 2 samples, got shape {ts.shape}")
    dtype = jnp.result_type(x0, ts, float)
    return closed_loop_rollout(system, controller, x0.astype(dtype), ts.astype(dtype), method, divergence_bound)


# Compiled once per plant and controller structure, method and grid shape (as `simulate`'s rollout):
# called eagerly, a bare `lax.scan` over a closure made anew on every call is compiled on every call.
@eqx.filter_jit
def closed_loop_rollout(system, controller, x0, ts, method, divergence_bound):
    """`simulate_closed_loop`'s rollout: `controller(t, x)` held over each interval of `ts` as the input of
    `system` from `x0`. Compiled (`filter_jit`); its `__wrapped__` is the bare `lax.scan`."""
    dtype = x0.dtype
    advance = sample_interval(system, method, divergence_bound)

    def interval(carry, times):
        x, diverged_at = carry
        t0, t1, dt = times
        u = jnp.asarray(controller(t0, x), dtype).reshape(system.n_inputs)
        x_next, diverged_at = advance(x, diverged_at, t0, t1, dt, u)
        return (x_next, diverged_at), (x_next, u)

    init = (x0, jnp.asarray(jnp.inf, dtype))
    (x_last, diverged_at), (xs, us) = jax.lax.scan(interval, init, (ts[:-1], ts[1:], jnp.diff(ts)))
    u_last = jnp.asarray(controller(ts[-1], x_last), dtype).reshape(1, system.n_inputs)
    u_last = jnp.where(jnp.isfinite(diverged_at), jnp.nan, u_last)
    xs = jnp.concatenate([x0[None], mask_diverged(ts[1:], xs, diverged_at)])
    return ClosedLoop(ts=ts, xs=xs, us=jnp.concatenate([us, u_last]), diverged_at=diverged_at)


def upright_error(xs: Float[Array, "*batch 4"]) -> Float[Array, "*batch 4"]:
    r"""The acrobot state's deviation from upright $(\pi, 0, 0, 0)$, both angles wrapped to $[-\pi, \pi)$."""
    return jnp.concatenate(
        [
            wrap_angle(xs[..., :2] - jnp.broadcast_to(jnp.array([jnp.pi, 0.0], xs.dtype), xs[..., :2].shape)),
            xs[..., 2:],
        ],
        axis=-1,
    )


def is_upright(
    xs: Float[Array, "*batch 4"], *, angle_tol: float = 1e-2, rate_tol: float = 0.1
) -> Bool[Array, "*batch"]:
    """Whether acrobot states are within `angle_tol` rad and `rate_tol` rad/s of upright (Drake's test)."""
    e = upright_error(xs)
    ok = jnp.all(jnp.abs(e[..., :2]) < angle_tol, axis=-1) & jnp.all(jnp.abs(e[..., 2:]) < rate_tol, axis=-1)
    return ok & jnp.all(jnp.isfinite(xs), axis=-1)


def swing_up_time(
    ts: Float[Array, " time"],
    xs: Float[Array, "time 4"],
    *,
    angle_tol: float = 1e-2,
    rate_tol: float = 0.1,
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    r"""The time from the start after which the acrobot stays upright until the end of the episode.

    Upright means both wrapped angles within `angle_tol` rad and both rates within `rate_tol`
    rad/s of $(\pi, 0, 0, 0)$ (the tolerances of Drake's `run_swing_up` test). An episode that
    does not end settled is a failure and counts as the episode length $t_{end} - t_0$.

    **Arguments:**

    - `ts`, `xs`: a closed-loop trajectory (`ClosedLoop.ts`, `ClosedLoop.xs`).
    - `angle_tol`, `rate_tol`: the settling tolerances.

    **Returns:**

    `(time, success)`: the settling time [s] (the episode length on failure) and whether the
    episode ended settled.
    """
    ok = is_upright(xs, angle_tol=angle_tol, rate_tol=rate_tol)
    # settled[k]: upright from sample k to the end.
    settled = jnp.flip(jnp.cumprod(jnp.flip(ok).astype(jnp.int32))).astype(bool)
    success = settled[-1]
    first = jnp.argmax(settled)
    duration = ts[-1] - ts[0]
    return jnp.where(success, ts[first] - ts[0], duration), success


def swing_up_reward(loop: ClosedLoop, *, rate_weight: float = 0.01, input_weight: float = 1e-4) -> Float[Array, ""]:
    r"""The average reward of a swing-up episode: minus the mean height deficit, rates and effort.

    $r = -\frac{1}{N}\sum_k \big((1 - \cos e_1) + (1 - \cos(e_1 + e_2)) + w_{\dot q}\|\dot q_k\|^2
    + w_u u_k^2\big)$ with $e = x \ominus x_{up}$ the wrapped angle error: the first two terms are the
    normalised height deficits of link 1 and of link 2 (0 upright, 2 each hanging down), so
    pumping energy is rewarded on the way up and the reward is quadratic near upright. It
    rewards getting up early and staying there. A diverged episode gets the worst per-step cost
    for its remaining samples, so it is finite and worse than any bounded one.

    **Arguments:**

    - `loop`: a `ClosedLoop` of the acrobot.
    - `rate_weight`, `input_weight`: $w_{\dot q}$ and $w_u$.

    **Returns:**

    The average reward (a scalar in $[-4 - \ldots, 0]$).
    """
    e = upright_error(loop.xs)
    height = (1 - jnp.cos(e[:, 0])) + (1 - jnp.cos(e[:, 0] + e[:, 1]))
    per_step = height + rate_weight * jnp.sum(e[:, 2:] ** 2, -1) + input_weight * jnp.sum(loop.us**2, -1)
    worst = 4.0 + rate_weight * 400.0
    per_step = jnp.where(jnp.isfinite(per_step), jnp.minimum(per_step, worst), worst)
    return -jnp.mean(per_step)
