"""Linear-system design in python-control's shape: `lqr(A, B, Q, R)`, `dlqr`, `lqe`, `ctrb`, `obsv`.

The same names, argument orders and returns as python-control (and MATLAB), so code ports by
changing the import; unlike python-control these run under `jit` and `vmap` and are
differentiable (the Riccati solutions are, see `solve_continuous_are`). The system-level
`lqr(system, x_eq, u_eq, q, r)` of `_lqr.py` linearises a nonlinear dynax system first.
"""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Complex, Float

from ._riccati import solve_continuous_are, solve_discrete_are


def _matrix(name: str, function: str, value, rows: int | None = None, cols: int | None = None) -> Array:
    m = jnp.asarray(value)
    if m.ndim == 0 and rows is not None and rows == cols:
        m = m * jnp.eye(rows, dtype=jnp.result_type(m, float))  # a scalar cost means a multiple of I
    if m.ndim != 2 or (rows is not None and m.shape[0] != rows) or (cols is not None and m.shape[1] != cols):
        want = f"({'n' if rows is None else rows}, {'m' if cols is None else cols})"
        raise ValueError(f"{function}: `{name}` must have shape {want}, got {m.shape}")
    return m


def _square(name: str, function: str, value) -> Array:
    m = _matrix(name, function, value)
    if m.shape[0] != m.shape[1]:
        raise ValueError(f"{function}: `{name}` must be square, got shape {m.shape}")
    return m


def ctrb(a: Float[ArrayLike, "n n"], b: Float[ArrayLike, "n m"]) -> Float[Array, "n n*m"]:
    r"""The controllability matrix $[B,\ AB,\ \dots,\ A^{n-1}B]$ (python-control's `ctrb`).

    The pair is controllable when it has rank $n$ (check with `jnp.linalg.matrix_rank`, or
    better its smallest singular value relative to the largest).

    **Arguments:** `a` $(n, n)$; `b` $(n, m)$.

    **Returns:** shape `(n, n * m)`.
    """
    a = _square("a", "ctrb", a)
    n = a.shape[0]
    b = _matrix("b", "ctrb", b, rows=n)
    blocks = [b]
    for _ in range(n - 1):
        blocks.append(a @ blocks[-1])
    return jnp.concatenate(blocks, axis=1)


def obsv(a: Float[ArrayLike, "n n"], c: Float[ArrayLike, "p n"]) -> Float[Array, "n*p n"]:
    r"""The observability matrix $[C;\ CA;\ \dots;\ CA^{n-1}]$ (python-control's `obsv`).

    **Arguments:** `a` $(n, n)$; `c` $(p, n)$.

    **Returns:** shape `(n * p, n)`.
    """
    a = _square("a", "obsv", a)
    n = a.shape[0]
    c = _matrix("c", "obsv", c, cols=n)
    blocks = [c]
    for _ in range(n - 1):
        blocks.append(blocks[-1] @ a)
    return jnp.concatenate(blocks, axis=0)


def lqr_matrices(
    a: Float[ArrayLike, "n n"], b: Float[ArrayLike, "n m"], q: Float[ArrayLike, "n n"], r: Float[ArrayLike, "m m"]
) -> tuple[Float[Array, "m n"], Float[Array, "n n"], Complex[Array, " n"]]:
    r"""Continuous-time LQR of $\dot x = Ax + Bu$: `(K, S, E)` as python-control's `lqr(A, B, Q, R)`.

    $u = -Kx$ minimises $\int x^\top Q x + u^\top R u\,dt$; $K = R^{-1}B^\top S$ with $S$ the
    stabilising CARE solution; $E$ the closed-loop eigenvalues, $\operatorname{eig}(A - BK)$.
    Reached as `dynax.control.lqr(A, B, Q, R)`.

    **Arguments:** `a` $(n, n)$, `b` $(n, m)$, `q` $(n, n)$, `r` $(m, m)$ or a scalar for $rI$.

    **Returns:** `(K, S, E)`.
    """
    a = _square("A", "lqr", a)
    n = a.shape[0]
    b = _matrix("B", "lqr", b, rows=n)
    q = _matrix("Q", "lqr", q, rows=n, cols=n)
    r = _matrix("R", "lqr", r, rows=b.shape[1], cols=b.shape[1])
    s = solve_continuous_are(a, b, q, r)
    k = jnp.linalg.solve(r.astype(s.dtype), b.astype(s.dtype).T @ s)
    return k, s, jnp.linalg.eigvals(a - b @ k)


def dlqr(
    a: Float[ArrayLike, "n n"], b: Float[ArrayLike, "n m"], q: Float[ArrayLike, "n n"], r: Float[ArrayLike, "m m"]
) -> tuple[Float[Array, "m n"], Float[Array, "n n"], Complex[Array, " n"]]:
    r"""Discrete-time LQR of $x_{k+1} = Ax_k + Bu_k$: `(K, S, E)` as python-control's `dlqr`.

    $u_k = -Kx_k$ minimises $\sum x_k^\top Q x_k + u_k^\top R u_k$;
    $K = (R + B^\top S B)^{-1} B^\top S A$ with $S$ the stabilising DARE solution;
    $E = \operatorname{eig}(A - BK)$ (inside the unit circle).

    **Arguments:** as `lqr(A, B, Q, R)`, for the discrete-time matrices.

    **Returns:** `(K, S, E)`.
    """
    a = _square("A", "dlqr", a)
    n = a.shape[0]
    b = _matrix("B", "dlqr", b, rows=n)
    q = _matrix("Q", "dlqr", q, rows=n, cols=n)
    r = _matrix("R", "dlqr", r, rows=b.shape[1], cols=b.shape[1])
    s = solve_discrete_are(a, b, q, r)
    a, b, r = (m.astype(s.dtype) for m in (a, b, r))
    k = jnp.linalg.solve(r + b.T @ s @ b, b.T @ s @ a)
    return k, s, jnp.linalg.eigvals(a - b @ k)


def lqe(
    a: Float[ArrayLike, "n n"],
    g: Float[ArrayLike, "n w"],
    c: Float[ArrayLike, "p n"],
    qn: Float[ArrayLike, "w w"],
    rn: Float[ArrayLike, "p p"],
) -> tuple[Float[Array, "n p"], Float[Array, "n n"], Complex[Array, " n"]]:
    r"""The steady-state Kalman(-Bucy) filter gain: `(L, P, E)` as python-control's `lqe(A, G, C, QN, RN)`.

    For $\dot x = Ax + Bu + Gw$, $y = Cx + v$ with white noises of intensities $Q_N$ and $R_N$,
    the estimator $\dot{\hat x} = A\hat x + Bu + L(y - C\hat x)$ with $L = PC^\top R_N^{-1}$ is
    optimal; $P$ (the error covariance) solves the dual CARE
    $AP + PA^\top - PC^\top R_N^{-1} C P + G Q_N G^\top = 0$; $E = \operatorname{eig}(A - LC)$.

    **Arguments:** `a` $(n, n)$, `g` $(n, w)$, `c` $(p, n)$, `qn` $(w, w)$, `rn` $(p, p)$.

    **Returns:** `(L, P, E)`.

    ??? cite

        R. E. Kalman and R. S. Bucy, "New results in linear filtering and prediction theory",
        Journal of Basic Engineering 83(1), 1961.
    """
    a = _square("A", "lqe", a)
    n = a.shape[0]
    g = _matrix("G", "lqe", g, rows=n)
    c = _matrix("C", "lqe", c, cols=n)
    qn = _matrix("QN", "lqe", qn, rows=g.shape[1], cols=g.shape[1])
    rn = _matrix("RN", "lqe", rn, rows=c.shape[0], cols=c.shape[0])
    p = solve_continuous_are(a.T, c.T, g @ qn @ g.T, rn)  # duality: the estimator is the LQR of (A^T, C^T)
    gain = jnp.linalg.solve(rn.astype(p.dtype), c.astype(p.dtype) @ p).T
    return gain, p, jnp.linalg.eigvals(a - gain @ c)
