"""Linear-quadratic regulation: linearisation by autodiff and Riccati equations solved in JAX.

Both Riccati solvers are pure JAX (they run under `jit` and `vmap`, on any backend) and are
differentiable: the forward solve is an iteration, but derivatives come from the implicit
function theorem applied to the Riccati equation at its solution, so they cost one Lyapunov
(or Stein) solve and do not depend on how many iterations the forward solve took.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._model._system import AbstractSystem


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


def _check_riccati(name, a, b, q, r):
    a, b, q, r = (jnp.asarray(m) for m in (a, b, q, r))
    dtype = jnp.result_type(a, b, q, r, float)
    a, b, q, r = (m.astype(dtype) for m in (a, b, q, r))
    n = a.shape[0] if a.ndim == 2 else -1
    if a.ndim != 2 or a.shape != (n, n):
        raise ValueError(f"{name}: `a` must be a square matrix, got shape {a.shape}")
    if b.ndim != 2 or b.shape[0] != n:
        raise ValueError(f"{name}: `b` must have shape ({n}, n_inputs), got {b.shape}")
    m = b.shape[1]
    if q.shape != (n, n):
        raise ValueError(f"{name}: `q` must have shape ({n}, {n}), got {q.shape}")
    if r.shape != (m, m):
        raise ValueError(f"{name}: `r` must have shape ({m}, {m}), got {r.shape}")
    return a, b, q, r


def _symmetrise(x):
    return 0.5 * (x + x.T)


@jax.jit
def _solve_sylvester_kron(left, right, c):
    """Solve `left @ X + X @ right = c` for square `X` by the Kronecker (vec) form; small n only."""
    n = c.shape[0]
    eye = jnp.eye(n, dtype=c.dtype)
    # vec(L X) = (I kron L) vec X, vec(X R) = (R^T kron I) vec X, column-major vec.
    op = jnp.kron(eye, left) + jnp.kron(right.T, eye)
    x = jnp.linalg.solve(op, c.T.reshape(-1))
    return x.reshape(n, n).T


@jax.jit
def _solve_stein_kron(a, c):
    """Solve `X - a^T X a = c` by the Kronecker form."""
    n = c.shape[0]
    eye = jnp.eye(n * n, dtype=c.dtype)
    op = eye - jnp.kron(a.T, a.T)
    x = jnp.linalg.solve(op, c.T.reshape(-1))
    return x.reshape(n, n).T


# ---------------------------------------------------------------- continuous time


@functools.partial(jax.jit, static_argnums=4)
def _care_sign(a, b, q, r, iterations):
    """Forward CARE solve: the matrix sign function of the Hamiltonian, then Newton polish."""
    n = a.shape[0]
    g = b @ jnp.linalg.solve(r, b.T)
    hamiltonian = jnp.block([[a, -g], [-q, -a.T]])

    def newton(_, z):
        z_inv = jnp.linalg.inv(z)
        # Determinantal scaling (Byers 1987) speeds up the first iterations.
        _, logdet = jnp.linalg.slogdet(z)
        c = jnp.exp(-logdet / (2 * n))
        c = jnp.where(jnp.isfinite(c) & (c > 0), c, 1.0)
        return 0.5 * (c * z + z_inv / c)

    w = jax.lax.fori_loop(0, iterations, newton, hamiltonian)
    eye = jnp.eye(n, dtype=a.dtype)
    # [W12; W22 + I] X = -[W11 + I; W21]
    lhs = jnp.concatenate([w[:n, n:], w[n:, n:] + eye], axis=0)
    rhs = -jnp.concatenate([w[:n, :n] + eye, w[n:, :n]], axis=0)
    x = jnp.linalg.lstsq(lhs, rhs)[0]
    x = _symmetrise(x)

    def kleinman(_, x):
        # Newton-Kleinman refinement: (A - G X)^T X' + X' (A - G X) = -(Q + X G X).
        acl = a - g @ x
        return _symmetrise(_solve_sylvester_kron(acl.T, acl, -(q + x @ g @ x)))

    return jax.lax.fori_loop(0, 2, kleinman, x)


@functools.partial(jax.custom_jvp, nondiff_argnums=(4,))
def _care(a, b, q, r, iterations):
    return _care_sign(a, b, q, r, iterations)


@_care.defjvp
def _care_jvp(iterations, primals, tangents):
    a, b, q, r = primals
    da, db, dq, dr = tangents
    x = _care(a, b, q, r, iterations)
    k = jnp.linalg.solve(r, b.T @ x)
    acl = a - b @ k
    # Envelope form of the CARE, 0 = min_K Q + K'RK + (A-BK)'X + X(A-BK), differentiated at K*.
    dacl = da - db @ k
    forcing = dq + k.T @ dr @ k + dacl.T @ x + x @ dacl
    dx = _solve_sylvester_kron(acl.T, acl, -forcing)
    return x, _symmetrise(dx)


def solve_continuous_are(
    a: Float[ArrayLike, "n n"],
    b: Float[ArrayLike, "n m"],
    q: Float[ArrayLike, "n n"],
    r: Float[ArrayLike, "m m"],
    *,
    iterations: int = 60,
) -> Float[Array, "n n"]:
    r"""Solve the continuous-time algebraic Riccati equation, differentiably.

    Finds the stabilising solution $X = X^\top \succeq 0$ of
    $A^\top X + X A - X B R^{-1} B^\top X + Q = 0$ (as `scipy.linalg.solve_continuous_are`).
    The forward solve is Newton's iteration for the matrix sign function of the Hamiltonian
    with determinantal scaling, followed by two Newton-Kleinman refinement steps. Derivatives
    with respect to all four matrices come from the implicit function theorem: one Lyapunov
    equation in the closed-loop matrix $A - BK$. Lyapunov equations are solved in Kronecker
    form, so this suits the small state dimensions of control problems (up to ~30 states).

    **Arguments:**

    - `a`: state matrix, shape `(n, n)`.
    - `b`: input matrix, shape `(n, m)`.
    - `q`: state cost, symmetric positive semi-definite, shape `(n, n)`.
    - `r`: input cost, symmetric positive definite, shape `(m, m)`.
    - `iterations`: sign-function Newton iterations (quadratic convergence; the default is ample).

    **Returns:**

    The stabilising solution $X$, shape `(n, n)`.

    ??? cite

        R. Byers, "Solving the algebraic Riccati equation with the matrix sign function",
        Linear Algebra and its Applications 85, 1987. D. Kleinman, "On an iterative technique
        for Riccati equation computations", IEEE TAC 13(1), 1968.
    """
    a, b, q, r = _check_riccati("solve_continuous_are", a, b, q, r)
    return _care(a, b, q, r, iterations)


# ---------------------------------------------------------------- discrete time


@functools.partial(jax.jit, static_argnums=4)
def _dare_doubling(a, b, q, r, iterations):
    """Structure-preserving doubling algorithm for the DARE."""
    n = a.shape[0]
    eye = jnp.eye(n, dtype=a.dtype)
    g = b @ jnp.linalg.solve(r, b.T)

    def step(_, carry):
        ak, gk, hk = carry
        w = eye + gk @ hk
        w_inv_a = jnp.linalg.solve(w, ak)
        w_inv_g = jnp.linalg.solve(w, gk)
        a_next = ak @ w_inv_a
        g_next = gk + ak @ w_inv_g @ ak.T
        h_next = hk + w_inv_a.T @ hk @ ak
        return a_next, _symmetrise(g_next), _symmetrise(h_next)

    _, _, x = jax.lax.fori_loop(0, iterations, step, (a, g, q))

    def newton(_, x):
        # One Hewer (Newton) step: X' = Acl' X' Acl + Q + K' R K.
        k = jnp.linalg.solve(r + b.T @ x @ b, b.T @ x @ a)
        acl = a - b @ k
        return _symmetrise(_solve_stein_kron(acl, q + k.T @ r @ k))

    return jax.lax.fori_loop(0, 1, newton, x)


@functools.partial(jax.custom_jvp, nondiff_argnums=(4,))
def _dare(a, b, q, r, iterations):
    return _dare_doubling(a, b, q, r, iterations)


@_dare.defjvp
def _dare_jvp(iterations, primals, tangents):
    a, b, q, r = primals
    da, db, dq, dr = tangents
    x = _dare(a, b, q, r, iterations)
    k = jnp.linalg.solve(r + b.T @ x @ b, b.T @ x @ a)
    acl = a - b @ k
    # Envelope form X = min_K Q + K'RK + (A-BK)' X (A-BK), differentiated at K*.
    dacl = da - db @ k
    forcing = dq + k.T @ dr @ k + dacl.T @ x @ acl + acl.T @ x @ dacl
    dx = _solve_stein_kron(acl, forcing)
    return x, _symmetrise(dx)


def solve_discrete_are(
    a: Float[ArrayLike, "n n"],
    b: Float[ArrayLike, "n m"],
    q: Float[ArrayLike, "n n"],
    r: Float[ArrayLike, "m m"],
    *,
    iterations: int = 40,
) -> Float[Array, "n n"]:
    r"""Solve the discrete-time algebraic Riccati equation, differentiably.

    Finds the stabilising solution of
    $X = A^\top X A - A^\top X B (R + B^\top X B)^{-1} B^\top X A + Q$
    (as `scipy.linalg.solve_discrete_are`) by the structure-preserving doubling algorithm
    (quadratically convergent) and one Hewer/Newton refinement step. Derivatives come from the
    implicit function theorem: one Stein equation in the closed-loop matrix.

    **Arguments:**

    - `a`, `b`, `q`, `r`: as in `solve_continuous_are`, for $x_{k+1} = A x_k + B u_k$.
    - `iterations`: doubling iterations (each squares the convergence factor).

    **Returns:**

    The stabilising solution $X$, shape `(n, n)`.

    ??? cite

        E. K.-W. Chu, H.-Y. Fan, W.-W. Lin, "A structure-preserving doubling algorithm for
        continuous-time algebraic Riccati equations", Linear Algebra Appl. 396, 2005;
        G. Hewer, "An iterative technique for the computation of the steady state gains for
        the discrete optimal regulator", IEEE TAC 16(4), 1971.
    """
    a, b, q, r = _check_riccati("solve_discrete_are", a, b, q, r)
    return _dare(a, b, q, r, iterations)


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
    system: AbstractSystem,
    x_eq: Float[ArrayLike, " n_states"],
    u_eq: Float[ArrayLike, " n_inputs"],
    q: Float[ArrayLike, "n_states n_states"] | None = None,
    r: Float[ArrayLike, "n_inputs n_inputs"] | None = None,
    *,
    angles: tuple[int, ...] = (),
) -> LQR:
    r"""The continuous-time infinite-horizon LQR of `system` linearised about `(x_eq, u_eq)`.

    Also python-control's matrix form: `lqr(A, B, Q, R) -> (K, S, E)` (positional, four
    matrices) returns the gain, the Riccati solution and the closed-loop eigenvalues; see
    `dynax.lqr_matrices`.

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
            raise ValueError("lqr: the matrix form is lqr(A, B, Q, R) (four matrices); the system form is "
                             "lqr(system, x_eq, u_eq, q, r)")
        if q is None:
            raise ValueError("lqr(A, B, Q, R): `R` is missing")
        from ._linear_design import lqr_matrices

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
