r"""The one solve: nonlinear least squares and minimisation through optimistix, compiled, vmappable.

Every iterative fit in dynax is a call of `fit_least_squares` (Levenberg-Marquardt by default;
residuals such as simulated-minus-measured states) or `fit_minimise` ((L-)BFGS by default; a
scalar loss such as a long-horizon prediction error). Both take the model itself (any pytree) and
a `Parameters` saying which elements move; the solver sees a scaled vector
$z$ with $p = p_0 + s \odot z$, so parameters of very different sizes are equally well conditioned.
The optimistix solve runs in a compiled `while_loop` with its convergence test, so the functions
are `jit`- and `vmap`-compatible (under `vmap` every batch member iterates until all have
converged), and they never synchronise with the host.

??? cite

    K. Levenberg, "A method for the solution of certain non-linear problems in least squares",
    Quarterly of Applied Mathematics 2, 1944; D. W. Marquardt, "An algorithm for least-squares
    estimation of nonlinear parameters", SIAM J. Applied Mathematics 11(2), 1963;
    J. Nocedal and S. J. Wright, *Numerical Optimization*, 2nd ed., 2006 (BFGS, ch. 6);
    P. Kidger et al., optimistix, 2024.
"""

from collections.abc import Callable
import functools
from typing import Any

import equinox as eqx
import jax
from jax.custom_derivatives import SymbolicZero
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PyTree
import optimistix as optx

from .._progress import report
from ._levenberg_marquardt import levenberg_marquardt
from ._parameters import Parameters
from ._solution import Solution

DEFAULT_LEAST_SQUARES = levenberg_marquardt(rtol=1e-8, atol=1e-8)
DEFAULT_MINIMISER = optx.BFGS(rtol=1e-8, atol=1e-8)


def _parameters(model, parameters) -> Parameters:
    if isinstance(parameters, Parameters):
        return parameters
    return Parameters.of(model, parameters)


def _scale(p0, scale):
    if scale is None:
        return jnp.where(jnp.abs(p0) > 0, jnp.abs(p0), 1.0)
    scale = jnp.broadcast_to(jnp.asarray(scale, p0.dtype), p0.shape)
    return scale


def dense_forward(fn: Callable[[Array, Any], Array]) -> Callable[[Array, Any], Array]:
    """`fn(z, dynamic)` with a JVP rule that forms the whole Jacobian in `z` by one `jacfwd` and
    applies it as a matrix.

    Levenberg-Marquardt needs the whole Jacobian (a few parameters, many residuals) at every step.
    Linearising a rollout the usual way gives a primal and a separate linear rollout, which the
    solver then materialises column by column; this rule is one rollout with all parameter
    tangents, and a fraction of the compilation (on an output-error fit through diffrax rollouts,
    20 s of compilation became a few seconds). Tangents in `dynamic` (implicit differentiation of a
    solution with respect to the data) are pushed through a plain JVP, and only when present.
    """

    @jax.custom_jvp
    def dense(z, dynamic):
        return fn(z, dynamic)

    @functools.partial(dense.defjvp, symbolic_zeros=True)
    def dense_jvp(primals, tangents):
        z, dynamic = primals
        dz, ddynamic = tangents
        J, r = jax.jacfwd(lambda q: (fn(q, dynamic),) * 2, has_aux=True)(z)
        out = jnp.zeros_like(r) if isinstance(dz, SymbolicZero) else J @ dz
        leaves = jax.tree.leaves(ddynamic, is_leaf=lambda t: isinstance(t, SymbolicZero))
        if not all(isinstance(t, SymbolicZero) for t in leaves):
            ddynamic = jax.tree.map(
                lambda t, x: jnp.zeros_like(x) if isinstance(t, SymbolicZero) else t,
                ddynamic,
                dynamic,
                is_leaf=lambda t: isinstance(t, SymbolicZero),
            )
            out = out + jax.jvp(lambda d: fn(z, d), (dynamic,), (ddynamic,))[1]
        return r, out

    return dense


def _report_step(token, **info):
    """optimistix's `verbose` hook: each entry is `(label, value)`."""
    report(token, info["num_steps"][1], loss=info["loss_last_accepted_step"][1])


def undetermined_unknowns(gram: Float[Array, "n n"], tol: float = 1e-6) -> tuple[Array, Array]:
    r"""Which unknowns of a Gauss-Newton matrix $J^\top J$ have a part in its numerical null space
    (eigenvalues at or below the pseudo-inverse's cut-off, `10 n eps` of the largest), and its rank.
    Those unknowns the data do not determine: `fit_least_squares` gives them an infinite standard
    error. An unknown outside the null space is estimable and its pseudo-inverse variance is its
    variance; a null vector counts where an entry is over `tol` of its largest. Jittable.

    **Returns:** `(undetermined, rank)`."""
    n = gram.shape[0]
    values, vectors = jnp.linalg.eigh(gram)
    null = values <= 10.0 * n * jnp.finfo(gram.dtype).eps * jnp.max(jnp.abs(values))
    loading = jnp.abs(vectors) / jnp.maximum(
        jnp.max(jnp.abs(vectors), axis=0, keepdims=True), jnp.finfo(gram.dtype).tiny
    )
    return jnp.any(null[None, :] & (loading > tol), axis=1), n - jnp.sum(null)


class LeastSquaresOptions(eqx.Module):
    """How `fit_least_squares` differentiates and reads the residuals, and what it reports.

    **Arguments:**

    - `jac`: `"fwd"` (forward mode: few parameters, many residuals, the usual case), `"dense"`
      (forward mode with the whole Jacobian formed by one `jacfwd` per step and applied as a matrix:
      the same numbers, far less compilation through long rollouts) or `"bwd"`.
    - `nonfinite`: value substituted for non-finite residuals (a diverging rollout), so the solver
      backs away from them instead of stopping on NaN (default 1e3); `None` keeps them.
    - `covariance`: compute the Gauss-Newton covariance at the solution (one more Jacobian; default
      `True`).
    - `progress_token`: a `dynax.internal.ProgressBar`'s token (`dynax.internal.bar_token(bar)`);
      each iteration then reports its step and loss to that bar through the solver's `verbose` hook
      (`jax.debug.callback`), as diffrax's progress meter does. Solvers without a `verbose` field
      report nothing.
    """

    jac: str = eqx.field(static=True, default="fwd")
    nonfinite: float | None = 1e3
    covariance: bool = eqx.field(static=True, default=True)
    progress_token: Array | None = None


def fit_least_squares(
    residuals: Callable[[PyTree, Any], Float[Array, " m"]],
    model: PyTree,
    parameters: Parameters | PyTree[Any] | None = None,
    args: PyTree[Any] = None,
    *,
    solver: optx.AbstractLeastSquaresSolver = DEFAULT_LEAST_SQUARES,
    scale: Float[ArrayLike, " n"] | Float[ArrayLike, ""] | None = None,
    max_steps: int = 256,
    options: LeastSquaresOptions = LeastSquaresOptions(),
) -> Solution:
    r"""Fit the free elements of `model` by minimising $\tfrac12 \lVert r(\text{model}) \rVert^2$.

    **Arguments:**

    - `residuals`: `residuals(model, args) -> r`, a 1-D array; any model the filter leaves fixed is
      passed through unchanged.
    - `model`: the starting model (any pytree).
    - `parameters`: a `Parameters`, or a filter to make one (`Parameters.of(model, filter)`); default
      the model's `parameter_filter()`.
    - `args`: passed to `residuals` (data, windows, ...); batched under `vmap` like anything else.
    - `solver`: an optimistix least-squares solver (default Levenberg-Marquardt, `rtol = atol = 1e-8`).
    - `scale`: per-parameter scale $s$ (default $|p_0|$, or 1 where $p_0 = 0$); a zero scale freezes
      that parameter.
    - `max_steps`: iteration budget; running out gives `result = max_steps_reached`, never an error.
      A solution whose loss is not finite or above the starting loss gets `result =
      nonlinear_divergence` (its value is still the solver's last point, for inspection).
    - `options`: a `LeastSquaresOptions`: the Jacobian's mode (`jac`), the value that replaces a
      non-finite residual (`nonfinite`), whether to compute the covariance (`covariance`) and a
      progress bar's token (`progress_token`).

    **Returns:** a `Solution`.
    """
    jac, nonfinite, covariance, progress_token = (
        options.jac,
        options.nonfinite,
        options.covariance,
        options.progress_token,
    )
    parameters = _parameters(model, parameters)
    p0 = parameters.vector(model)
    s = _scale(p0, scale)
    if progress_token is not None and hasattr(solver, "verbose"):
        solver = eqx.tree_at(lambda sv: sv.verbose, solver, jax.tree_util.Partial(_report_step, progress_token))

    # What the residuals read, split into arrays and the rest: with `jac="dense"` every array is an
    # explicit input of the custom JVP (a custom rule must not close over what a caller may trace).
    args_static = eqx.filter(args, eqx.is_array, inverse=True)
    closed, closed_static = eqx.partition((model, p0, s), eqx.is_array)

    def evaluate(z, dynamic):
        args_dynamic, closed_dynamic = dynamic
        model_, p0_, s_ = eqx.combine(closed_dynamic, closed_static)
        r = residuals(parameters.with_vector(model_, p0_ + s_ * z), eqx.combine(args_dynamic, args_static))
        if nonfinite is not None:
            r = jnp.where(jnp.isfinite(r), r, nonfinite)
        return r

    rollout = dense_forward(evaluate) if jac == "dense" else evaluate

    def fn(z, args):
        return rollout(z, (eqx.filter(args, eqx.is_array), closed))

    z0 = jnp.zeros_like(p0)
    solution = optx.least_squares(
        fn, solver, z0, args, options={"jac": "fwd" if jac == "dense" else jac}, max_steps=max_steps, throw=False
    )
    z = solution.value
    # A Gauss-Newton-type solver (Levenberg-Marquardt, Gauss-Newton, Dogleg) ends holding the residuals
    # and the linearisation at its last accepted point, which is `z`: reuse them instead of tracing the
    # residual function twice more (that halves the compilation of a fit through long rollouts).
    info = getattr(solution.state, "f_info", None)
    final = isinstance(info, optx.FunctionInfo.ResidualJac)
    r = info.residual if final else fn(z, args)
    r0 = fn(z0, args)
    # A solver must not end worse than it started; if it does (a step accepted on a Jacobian that
    # misled the trust region, or a loss that is not finite), say so in the result.
    worse = jnp.logical_not(jnp.sum(r**2) <= jnp.sum(r0**2))
    result = optx.RESULTS.where(worse, optx.RESULTS.nonlinear_divergence, solution.result)
    m, n = r.shape[0], z.shape[0]
    J = None
    if covariance and n:
        if final:
            J = info.jac.as_matrix()
        else:
            J = jax.jacrev(fn)(z, args) if jac == "bwd" else jax.jacfwd(fn)(z, args)
        gram = J.T @ J
        # A free unknown with a part in the null space the pseudo-inverse drops is not determined
        # by the data: no finite error (the pseudo-inverse gives it a finite one, zero where its
        # column of J is zero). A frozen one (zero scale) has a zero column by construction. The
        # residual variance counts the rank as the unknowns spent, neither of those.
        undetermined, rank = undetermined_unknowns(gram)
        undetermined = undetermined & (s != 0)
        sigma2 = jnp.sum(r**2) / jnp.maximum(m - rank, 1)
        cov_z = sigma2 * jnp.linalg.pinv(gram, hermitian=True)
        cov_z = jnp.where(undetermined[:, None] | undetermined[None, :], jnp.nan, cov_z)
        cov = cov_z * s[:, None] * s[None, :]
    else:
        cov = jnp.full((n, n), jnp.nan, p0.dtype)
        undetermined = jnp.zeros(n, bool)
    std = jnp.sqrt(jnp.maximum(jnp.diag(cov), 0.0)) if n else jnp.zeros(0, p0.dtype)
    std = jnp.where(undetermined, jnp.inf, jnp.where(jnp.isnan(jnp.diag(cov)), jnp.nan, std)) if n else std
    value = p0 + s * z
    return Solution(
        model=parameters.with_vector(model, value),
        value=value,
        parameters=parameters,
        covariance=cov,
        std_errors=std,
        result=result,
        loss=0.5 * jnp.sum(r**2),
        initial_loss=0.5 * jnp.sum(r0**2),
        steps=solution.stats["num_steps"],
        n_residuals=int(m),
        loss_history=solution.stats.get("loss_history"),
        time_history=solution.stats.get("time_history"),
        jacobian=J,
        residuals=r,
        initial_residuals=r0,
    )


def fit_minimise(
    loss: Callable[[PyTree, Any], Float[Array, ""]],
    model: PyTree,
    parameters: Parameters | PyTree[Any] | None = None,
    args: PyTree[Any] = None,
    *,
    solver: optx.AbstractMinimiser = DEFAULT_MINIMISER,
    scale: Float[ArrayLike, " n"] | Float[ArrayLike, ""] | None = None,
    max_steps: int = 256,
    covariance: bool = True,
) -> Solution:
    r"""Fit the free elements of `model` by minimising a scalar `loss(model, args)` (default BFGS).

    Arguments as for `fit_least_squares`. The covariance is the inverse of the loss's Hessian at the
    solution (computed by forward-over-reverse autodiff), which is the parameter covariance when the
    loss is a negative log-likelihood; NaN where the Hessian is not positive definite.
    `covariance=False` skips the Hessian (it costs about one gradient per parameter; NaN instead).
    A solver that records a loss history (`OptaxLBFGS`) passes it on as `Solution.loss_history`
    and `Solution.time_history`.

    **Returns:** a `Solution`.
    """
    parameters = _parameters(model, parameters)
    p0 = parameters.vector(model)
    s = _scale(p0, scale)

    def fn(z, args):
        return loss(parameters.with_vector(model, p0 + s * z), args)

    z0 = jnp.zeros_like(p0)
    solution = optx.minimise(fn, solver, z0, args, max_steps=max_steps, throw=False)
    z = solution.value
    n = z.shape[0]
    if n and covariance:
        H = jax.jacfwd(jax.grad(fn))(z, args)
        H = 0.5 * (H + H.T)
        pd = jnp.all(jnp.linalg.eigvalsh(H) > 0)
        cov = jnp.where(pd, jnp.linalg.pinv(H, hermitian=True), jnp.nan) * s[:, None] * s[None, :]
        std = jnp.sqrt(jnp.abs(jnp.diag(cov)))
    else:
        cov, std = jnp.full((n, n), jnp.nan, p0.dtype), jnp.full(n, jnp.nan, p0.dtype)
    value = p0 + s * z
    return Solution(
        model=parameters.with_vector(model, value),
        value=value,
        parameters=parameters,
        covariance=cov,
        std_errors=std,
        result=solution.result,
        loss=fn(z, args),
        initial_loss=fn(z0, args),
        steps=solution.stats["num_steps"],
        loss_history=solution.stats.get("loss_history"),
        time_history=solution.stats.get("time_history"),
    )


fit_least_squares_jit = eqx.filter_jit(fit_least_squares)
