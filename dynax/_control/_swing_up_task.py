"""The acrobot swing-up as an optimisation objective over controller parameters."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._model._system import AbstractSystem
from .._simulate import FixedGrid
from ._closed_loop import ClosedLoop, simulate_closed_loop, swing_up_reward, swing_up_time
from ._swing_up import SpongController


def random_starts(key: PRNGKeyArray, n: int, half_width: float = 0.5, dtype=None) -> Float[Array, "n 4"]:
    """`n` acrobot start states at rest with both angles uniform within `half_width` rad of hanging down."""
    dtype = jnp.result_type(float) if dtype is None else dtype
    angles = jax.random.uniform(key, (n, 2), dtype, minval=-half_width, maxval=half_width)
    return jnp.concatenate([angles, jnp.zeros((n, 2), dtype)], axis=1)


class SwingUpTask(eqx.Module):
    r"""Swing-up-and-balance of an acrobot plant by a `SpongController`, as `task(params, key) -> reward`.

    `params` are the controller's $\theta = (k_e, k_p, k_d, \phi)$. Each episode starts either
    from `start` (the fixed-start regime) or, when `start` is `None`, from a random state at
    rest with both angles uniform within `start_half_width` of hanging down (drawn from `key`),
    and runs the closed loop (`simulate_closed_loop`) for `duration` seconds at `control_rate`
    Hz. The reward is `swing_up_reward`. The plant may differ from the controller's internal
    model (tune on an identified model, evaluate on the truth).

    **Arguments:**

    - `plant`: the system the controller drives.
    - `controller`: the controller template whose parameters are replaced (`with_params`).
    - `duration`: the episode length [s] (default 20).
    - `control_rate`: controller and sampling rate [Hz] (default 100).
    - `start`: a fixed start state, or `None` for random starts.
    - `start_half_width`: the half-width of the random starts' angles [rad] (default 0.5).
    - `method`: the integration method (`FixedGrid`).
    """

    plant: AbstractSystem
    controller: SpongController
    duration: float = eqx.field(static=True, default=20.0)
    control_rate: float = eqx.field(static=True, default=100.0)
    start: Float[Array, " 4"] | None = None
    start_half_width: float = eqx.field(static=True, default=0.5)
    method: FixedGrid = FixedGrid()

    @property
    def dtype(self):
        return jnp.result_type(self.controller.system.theta1)

    @property
    def ts(self) -> Float[Array, " time"]:
        """The control sample times."""
        n = int(round(self.duration * self.control_rate))
        return jnp.arange(n + 1, dtype=self.dtype) / self.control_rate

    def rollout(self, params: Float[ArrayLike, " 4"], x0: Float[ArrayLike, " 4"]) -> ClosedLoop:
        """One closed-loop episode of the controller with `params` from `x0`."""
        controller = self.controller.with_params(jnp.asarray(params, self.dtype))
        return simulate_closed_loop(self.plant, controller, jnp.asarray(x0, self.dtype), self.ts, method=self.method)

    def start_state(self, key: PRNGKeyArray) -> Float[Array, " 4"]:
        """The episode's start: `start`, or a random one drawn from `key`."""
        if self.start is not None:
            return jnp.asarray(self.start, self.dtype)
        return random_starts(key, 1, self.start_half_width, self.dtype)[0]

    def __call__(self, params: Float[ArrayLike, " 4"], key: PRNGKeyArray) -> Float[Array, ""]:
        return swing_up_reward(self.rollout(params, self.start_state(key)))

    def evaluate(self, params: Float[ArrayLike, " 4"], starts: Float[ArrayLike, "n 4"]) -> dict[str, Array]:
        """The controller with `params` from each of `starts` (`vmap`ped).

        **Returns:** a dict with `success_rate` (fraction settled at the end, see
        `swing_up_time`), `mean_time_s` (settling time, failures counted as the episode length),
        `reward` (mean `swing_up_reward`), and per-start `times` and `successes`.
        """

        def one(x0):
            loop = self.rollout(params, x0)
            time, success = swing_up_time(loop.ts, loop.xs)
            return time, success, swing_up_reward(loop)

        times, successes, rewards = jax.vmap(one)(jnp.asarray(starts, self.dtype))
        return dict(
            success_rate=jnp.mean(successes.astype(self.dtype)),
            mean_time_s=jnp.mean(times),
            reward=jnp.mean(rewards),
            times=times,
            successes=successes,
        )
