"""Sampling-based estimate of the region of attraction of a saturated LQR loop, as a cost-to-go level."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from .._model._system import AbstractSystem
from .._simulate import FixedGrid
from ._closed_loop import simulate_closed_loop
from ._lqr import LQR


class _Saturated(eqx.Module):
    controller: LQR
    limit: float

    def __call__(self, t, x):
        return jnp.clip(self.controller(t, x), -self.limit, self.limit)


class RegionOfAttraction(eqx.Module):
    """The result of `estimate_region_of_attraction`.

    **Fields:**

    - `rho`: the estimated level: every sampled state with cost-to-go below it was brought to
      the equilibrium by the saturated LQR loop.
    - `levels`: the cost-to-go levels that were sampled, shape `(levels,)`.
    - `converged_fraction`: the fraction of sampled states that converged at each level.
    """

    rho: Float[Array, ""]
    levels: Float[Array, " levels"]
    converged_fraction: Float[Array, " levels"]


class RegionSampling(eqx.Module):
    """How `estimate_region_of_attraction` samples and tests states.

    **Fields:**

    - `levels`: the cost-to-go levels to test (default `None`: 40 values from 1 to 1e5, geometric).
    - `n_directions`: sampled directions per level.
    - `horizon`, `control_rate`: the length [s] and rate [Hz] of each test rollout.
    - `tolerance`: the cost-to-go below which a rollout counts as converged.
    """

    levels: Float[Array, " levels"] | None = None
    n_directions: int = eqx.field(static=True, default=128)
    horizon: float = eqx.field(static=True, default=4.0)
    control_rate: float = eqx.field(static=True, default=100.0)
    tolerance: float = 1e-2


def estimate_region_of_attraction(
    plant: AbstractSystem,
    controller: LQR,
    key: PRNGKeyArray,
    *,
    torque_limit: float = 20.0,
    sampling: RegionSampling = RegionSampling(),
    method: FixedGrid = FixedGrid(),
) -> RegionOfAttraction:
    r"""Estimate the largest sub-level set $\{x : V(x) < \rho\}$ of the LQR cost-to-go that the saturated loop attracts.

    States are sampled on level sets $V(x) = \rho_j$ of the cost-to-go
    $V(x) = (x \ominus x_{eq})^\top S (x \ominus x_{eq})$ along `n_directions` random
    directions (uniform on the unit sphere in the metric of $S$), the plant is simulated under
    the LQR torque clipped at `torque_limit` for `horizon` seconds at `control_rate`, and a
    sample converged if it ends with $V < $ `tolerance` (the last four in `sampling`). $\rho$ is
    the largest level below which every sample converged. It is an inner estimate of the true
    region of attraction as far as sampling goes (a sampled, not a certified, estimate: compare
    the sums-of-squares certificates of the cited chapter). All rollouts are one `vmap`.

    **Arguments:**

    - `plant`: the system (for the acrobot, the nonlinear model the LQR was designed on, or the
      truth, to see how the region shrinks under model error).
    - `controller`: the `LQR` whose region is estimated.
    - `key`: PRNG key for the directions.
    - `torque_limit`: the actuator saturation.
    - `sampling`: a `RegionSampling`: the levels, the directions per level, the test rollouts'
      length and rate, and the convergence tolerance.
    - `method`: the fixed-grid solver of the test rollouts.

    **Returns:** a `RegionOfAttraction` with `rho`, `levels` and `converged_fraction`.

    ??? cite

        R. Tedrake, *Underactuated Robotics*, ch. 9 ("Lyapunov analysis": regions of
        attraction as sub-level sets of the LQR cost-to-go).
    """
    s = controller.cost_to_go_matrix
    dtype = s.dtype
    n = s.shape[0]
    levels, n_directions, tolerance = sampling.levels, sampling.n_directions, sampling.tolerance
    horizon, control_rate = sampling.horizon, sampling.control_rate
    if levels is None:
        levels = jnp.geomspace(1.0, 1e5, 40).astype(dtype)
    levels = jnp.asarray(levels, dtype)
    w = jax.random.normal(key, (n_directions, n), dtype)
    w = w / jnp.linalg.norm(w, axis=1, keepdims=True)
    # x - x_eq = L^{-T} w sqrt(rho) with S = L L^T gives V = rho exactly.
    chol = jnp.linalg.cholesky(s)
    directions = jax.scipy.linalg.solve_triangular(chol.T, w.T, lower=False).T
    steps = int(round(horizon * control_rate))
    ts = jnp.arange(steps + 1, dtype=dtype) / control_rate
    loop_controller = _Saturated(controller, torque_limit)

    def converged(level, direction):
        x0 = controller.x_eq + jnp.sqrt(level) * direction
        loop = simulate_closed_loop(plant, loop_controller, x0, ts, method=method)
        final = controller.cost_to_go(loop.xs[-1])
        return jnp.isfinite(final) & (final < tolerance)

    ok = jax.vmap(lambda level: jax.vmap(lambda d: converged(level, d))(directions))(levels)
    fraction = jnp.mean(ok.astype(dtype), axis=1)
    all_ok = jnp.cumprod(jnp.all(ok, axis=1).astype(jnp.int32)).astype(bool)
    last = jnp.sum(all_ok) - 1
    rho = jnp.where(last >= 0, levels[jnp.maximum(last, 0)], jnp.asarray(0.0, dtype))
    return RegionOfAttraction(rho=rho, levels=levels, converged_fraction=fraction)
