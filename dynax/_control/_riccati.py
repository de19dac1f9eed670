"""The continuous and discrete algebraic Riccati equations, solved in JAX.

Both Riccati solvers are pure JAX (they run under `jit` and `vmap`, on any backend) and are
differentiable: the forward solve is an iteration, but derivatives come from the implicit
function theorem applied to the Riccati equation at its solution, so they cost one Lyapunov
(or Stein) solve and do not depend on how many iterations the forward solve took.
"""

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


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
