"""Linear-quadratic regulation: linearisation by autodiff and regulators from the Riccati solvers
(`dynax._control._riccati`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._model._system import AbstractSystem
from ._linear_design import lqr_matrices
from ._riccati import solve_continuous_are, solve_discrete_are


def linearise(
    system: AbstractSystem,
    x_eq: Float[ArrayLike, " n_states"],
    u_eq: Float[ArrayLike, " n_inputs"],
    t: float = 0.0,
) -> tuple[Float[Array, "n_states n_states"], Float[Array, "n_states n_inputs"]]:
    r"""Linearise $\dot x = f(t, x, u)$ about $(x_{eq}, u_{eq})$ by forward-mode autodiff.

    **Arguments:**

    - `system`: a dynax system.
    - `x_eq`: the state to linearise about, ordered as `system.state_names`.
    - `u_eq`: the input to linearise about, ordered as `system.input_names`.
    - `t`: the time (only matters for time-varying systems).

    **Returns:**

    `(A, B)` with $A = \partial f / \partial x$ and $B = \partial f / \partial u$ at the point.
    """
    x_eq = jnp.asarray(x_eq)
    u_eq = jnp.asarray(u_eq)
    if x_eq.shape != (system.n_states,):
        raise ValueError(f"linearise: `x_eq` must have shape ({system.n_states},), got {x_eq.shape}")
    if u_eq.shape != (system.n_inputs,):
        raise ValueError(f"linearise: `u_eq` must have shape ({system.n_inputs},), got {u_eq.shape}")
    dtype = jnp.result_type(x_eq, u_eq, float)
    x_eq, u_eq = x_eq.astype(dtype), u_eq.astype(dtype)
    a, b = jax.jacfwd(lambda x, u: system.vector_field(t, x, u), argnums=(0, 1))(x_eq, u_eq)
    return a, b


# ---------------------------------------------------------------- regulators


class LQR(eqx.Module):
    r"""A linear-quadratic regulator $u = u_{eq} - K (x \ominus x_{eq})$ about an equilibrium.

    $x \ominus x_{eq}$ is the state error with the entries listed in `angles` wrapped to
    $[-\pi, \pi)$, so a pendulum that went once round is still upright. `cost_to_go(x)` is
    $(x \ominus x_{eq})^\top S (x \ominus x_{eq})$, the quantity Drake's Spong controller
    compares with its balancing threshold. Build one with `lqr` (continuous time) or
    `discrete_lqr`; an `LQR` is a controller, `__call__(t, x) -> u`.

    **Fields:**

    - `gain`: $K$, shape `(n_inputs, n_states)`.
    - `cost_to_go_matrix`: $S$, the Riccati solution, shape `(n_states, n_states)`.
    - `x_eq`, `u_eq`: the equilibrium.
    - `angles`: indices of the state entries that are angles (static).
    """

    gain: Float[Array, "n_inputs n_states"]
    cost_to_go_matrix: Float[Array, "n_states n_states"]
    x_eq: Float[Array, " n_states"]
    u_eq: Float[Array, " n_inputs"]
    angles: tuple[int, ...] = eqx.field(static=True, default=())

    def error(self, x: Float[Array, " n_states"]) -> Float[Array, " n_states"]:
        """The state error from `x_eq`, with angles wrapped to $[-\\pi, \\pi)$."""
        dx = x - self.x_eq
        if self.angles:
            idx = jnp.asarray(self.angles)
            dx = dx.at[idx].set(wrap_angle(dx[idx]))
        return dx

    def cost_to_go(self, x: Float[Array, " n_states"]) -> Float[Array, ""]:
        r"""$(x \ominus x_{eq})^\top S (x \ominus x_{eq})$."""
        dx = self.error(x)
        return dx @ self.cost_to_go_matrix @ dx

    def __call__(self, t: Float[ArrayLike, ""], x: Float[Array, " n_states"]) -> Float[Array, " n_inputs"]:
        return self.u_eq - self.gain @ self.error(x)


def wrap_angle(angle: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    r"""Wrap angles to $[-\pi, \pi)$ (Drake's `wrap_to(angle, -pi, pi)`)."""
    angle = jnp.asarray(angle)
    return jnp.mod(angle + jnp.pi, 2 * jnp.pi) - jnp.pi


def _costs(system, q, r, dtype):
    q = jnp.asarray(q, dtype)
    r = jnp.asarray(r, dtype)
    if r.ndim == 0:
        r = r * jnp.eye(system.n_inputs, dtype=dtype)
    if q.ndim == 1:
        q = jnp.diag(q)
    return q, r


def lqr(
    system: AbstractSystem | Float[ArrayLike, "n_states n_states"],  # or python-control's A
    x_eq: Float[ArrayLike, " n_states"] | Float[ArrayLike, "n_states n_inputs"],  # or B
    u_eq: Float[ArrayLike, " n_inputs"] | Float[ArrayLike, "n_states n_states"],  # or Q
    q: Float[ArrayLike, "n_states n_states"]
    | Float[ArrayLike, " n_states"]
    | Float[ArrayLike, "n_inputs n_inputs"]  # or R
    | Float[ArrayLike, ""]
    | None = None,
    r: Float[ArrayLike, "n_inputs n_inputs"] | Float[ArrayLike, ""] | None = None,
    *,
    angles: tuple[int, ...] = (),
) -> LQR | tuple[Array, Array, Array]:
    r"""The continuous-time infinite-horizon LQR of `system` linearised about `(x_eq, u_eq)`.

    Also python-control's matrix form: `lqr(A, B, Q, R) -> (K, S, E)` (positional, four
    matrices) returns the gain, the Riccati solution and the closed-loop eigenvalues; see
    `dynax.control.lqr_matrices`.

    Minimises $\int_0^\infty \delta x^\top Q \delta x + \delta u^\top R \delta u \, dt$ for the
    linearisation $\delta\dot x = A \delta x + B \delta u$ (`linearise`); $K = R^{-1} B^\top S$
    with $S$ from `solve_continuous_are`. Differentiable with respect to the system's
    parameters, the equilibrium and the costs (Drake's `LinearQuadraticRegulator`).

    **Arguments:**

    - `system`: a dynax system.
    - `x_eq`, `u_eq`: the equilibrium (`system.vector_field(0, x_eq, u_eq)` should be zero).
    - `q`: state cost, `(n_states, n_states)` or its diagonal `(n_states,)`.
    - `r`: input cost, `(n_inputs, n_inputs)`, or a scalar for $rI$.
    - `angles`: indices of the state entries that are angles (wrapped in the error).

    **Returns:**

    An `LQR` controller.

    ??? cite

        R. E. Kalman, "Contributions to the theory of optimal control", Boletin de la Sociedad
        Matematica Mexicana 5, 1960.
    """
    if not isinstance(system, AbstractSystem):  # python-control's lqr(A, B, Q, R)
        if r is not None or angles:
            raise ValueError(
                "lqr: the matrix form is lqr(A, B, Q, R) (four matrices); the system form is "
                "lqr(system, x_eq, u_eq, q, r)"
            )
        if q is None:
            raise ValueError("lqr(A, B, Q, R): `R` is missing")
        return lqr_matrices(system, x_eq, u_eq, q)
    if q is None or r is None:
        raise ValueError(f"lqr: the cost `{'q' if q is None else 'r'}` is missing")
    return _lqr(system, x_eq, u_eq, q, r, tuple(angles))


@eqx.filter_jit
def _lqr(system, x_eq, u_eq, q, r, angles):
    a, b = linearise(system, x_eq, u_eq)
    q, r = _costs(system, q, r, a.dtype)
    s = solve_continuous_are(a, b, q, r)
    k = jnp.linalg.solve(r, b.T @ s)
    return LQR(k, s, jnp.asarray(x_eq, a.dtype), jnp.asarray(u_eq, a.dtype), angles)


def discrete_lqr(
    system: AbstractSystem,
    x_eq: Float[ArrayLike, " n_states"],
    u_eq: Float[ArrayLike, " n_inputs"],
    q: Float[ArrayLike, "n_states n_states"],
    r: Float[ArrayLike, "n_inputs n_inputs"],
    dt: float,
    *,
    angles: tuple[int, ...] = (),
) -> LQR:
    r"""The discrete-time LQR for `system` sampled with period `dt` under a zero-order hold.

    The linearisation is discretised exactly, $A_d = e^{A\,dt}$ and
    $B_d = \int_0^{dt} e^{A s} ds\, B$ (one matrix exponential of the augmented matrix), and the
    cost is the sum $\sum_k \delta x_k^\top Q \delta x_k + \delta u_k^\top R \delta u_k$. Use it
    for controllers that run at a fixed rate, like `simulate_closed_loop`'s.

    **Arguments:** as `lqr`, plus the sample period `dt` [s].

    **Returns:** an `LQR` controller whose `cost_to_go_matrix` solves the DARE.
    """
    return _discrete_lqr(system, x_eq, u_eq, q, r, dt, tuple(angles))


@eqx.filter_jit
def _discrete_lqr(system, x_eq, u_eq, q, r, dt, angles):
    a, b = linearise(system, x_eq, u_eq)
    q, r = _costs(system, q, r, a.dtype)
    n, m = b.shape
    augmented = jnp.zeros((n + m, n + m), a.dtype).at[:n, :n].set(a).at[:n, n:].set(b)
    phi = jax.scipy.linalg.expm(augmented * dt)
    ad, bd = phi[:n, :n], phi[:n, n:]
    s = solve_discrete_are(ad, bd, q, r)
    k = jnp.linalg.solve(r + bd.T @ s @ bd, bd.T @ s @ ad)
    return LQR(k, s, jnp.asarray(x_eq, a.dtype), jnp.asarray(u_eq, a.dtype), angles)
