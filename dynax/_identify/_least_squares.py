r"""Weighted linear least squares with identifiability diagnostics (SVD).

The regressor's columns are first scaled to unit norm, so the condition number and the numerical
rank do not depend on the parameters' units; then the SVD $W^{1/2} A D^{-1} = U S V^\top$ gives the
rank, the estimate and its covariance. The SVD is of the regressor itself (through its QR
factorisation), never of $A^\top A$, so float32 problems keep the accuracy of numpy's `lstsq`.
Singular values below `rcond` times the largest mark directions of the (scaled) parameter space
that the data do not determine; they are reported by name, as linear combinations of parameters.
"""

import jax
import jax.numpy as jnp
from jaxtyping import ArrayLike, Float
import numpy as np
import optimistix as optx

from .._errors import DataError
from .._fit import Parameters, Solution, Statistics


class IdentifiabilityError(DataError):
    """The data do not determine some parameter combinations (a rank-deficient regressor).

    **Attributes:** `unidentified` (the combinations, as strings), `rank`, `n_params`,
    `condition_number`.
    """

    def __init__(self, message, *, unidentified=(), rank=None, n_params=None, condition_number=None, path=None):
        super().__init__(message, path=path)
        self.unidentified = tuple(unidentified)
        self.rank, self.n_params, self.condition_number = rank, n_params, condition_number


# Relative standard error above which a size parameter counts as poorly determined: its 95 % interval
# then spans more than half of its value either way.
POORLY_DETERMINED = 0.25


class PoorlyDeterminedWarning(UserWarning):
    """The data determine some of the machine's size parameters only poorly (`poorly_determined`):
    the regressor has full rank, but noise, not the motion, sets those estimates."""


def poorly_determined(names, estimate, std_errors, which, threshold: float = POORLY_DETERMINED) -> dict[str, float]:
    r"""The parameters among `which` whose relative standard error $\sigma_i / |\hat\theta_i|$ exceeds
    `threshold` (default `POORLY_DETERMINED`), name -> that ratio (`inf` for an estimate of zero).

    A regressor can have full numerical rank and still leave parameters to the noise: records with
    little motion (a machine at rest, a short or gentle record, one joint barely moving) give
    columns that are nearly zero or nearly parallel, and standard errors as large as the estimates.
    The relative standard deviation is how identification practice reads it (Gautier, "Numerical
    calculation of the base inertial parameters of robots", J. Robotic Systems 8(4), 1991; Swevers,
    Verdonck and De Schutter, "Dynamic model identification for industrial robots", IEEE Control
    Systems Magazine 27(5), 2007). Only size parameters are judged (inertias, gravity terms, mass):
    a friction coefficient near zero has a large relative error because it is small.
    """
    out = {}
    for name, value, std in zip(names, np.asarray(estimate, dtype=float), np.asarray(std_errors, dtype=float)):
        if name not in which:
            continue
        ratio = float(std / abs(value)) if value != 0 else float("inf")
        if not ratio <= threshold:  # NaN counts as poorly determined
            out[name] = ratio
    return out


def describe_poorly_determined(poorly: dict[str, float]) -> str:
    """`poorly_determined`'s result as text: `theta2 (34 %), theta1 (estimate zero)`; a ratio of 100 or
    more is an estimate near zero (held at a bound), NaN one with no standard error."""
    return ", ".join(
        f"{name} ({100 * ratio:.0f} %)"
        if ratio < 100
        else f"{name} (estimate zero)"
        if ratio == np.inf
        else f"{name} (estimate near zero, standard error {ratio:.3g} times it)"
        if np.isfinite(ratio)
        else f"{name} (no standard error)"
        for name, ratio in poorly.items()
    )


# Ratio of a parameter's standard error to its error with every other parameter known, above which it
# counts as determined mostly jointly: then over 99 % of its variance is shared with the others.
JOINTLY_DETERMINED = 10.0


def jointly_determined(
    names, covariance, which=None, threshold: float = JOINTLY_DETERMINED, partner: float = 0.5, max_partners: int = 3
) -> dict[str, dict]:
    r"""The parameters (among `which`, default all) that the data determine mostly in combination
    with others: name -> `{"with": [partners], "correlations": [...], "inflation": ratio}`.

    A parameter's standard error $\sigma_i$ set against its error were every other parameter known,
    $1/\sqrt{(C^{-1})_{ii}}$, is the square root of its variance inflation factor,
    $\sqrt{(R^{-1})_{ii}}$ with $R$ the correlation matrix (Belsley, Kuh and Welsch, *Regression
    Diagnostics*, 1980, ch. 3). Above `threshold` (default 10: a variance inflation of 100, over
    99 % of the variance shared; the common rule of thumb flags an inflation of 10, which a
    two-link arm's base parameters reach routinely) the motion separates the parameter from
    others only through a small difference: most of its error is shared with them, and a
    combination of them is known much better than each alone. Its partners are the (at most
    `max_partners`) parameters most correlated with it, at `partner` (0.5) or more in magnitude;
    `"correlations"` gives those correlations. Whether that matters is the standard error's to say:
    on MuJoCo records of an arm swung to about 1 rad, $I_{r2}$ (7.5 % standard error, ratio 16) is
    told apart from $\theta_3$ only through $\cos q_2 - 1$ and came out 29 % off; on an acrobot
    turning over, $\theta_1$ and $\theta_3$ are correlated (ratios 12 and 19) and still within
    0.3 %. Parameters with an undefined variance are left out.
    """
    c = np.asarray(covariance, dtype=float)
    keep = np.isfinite(np.diag(c)) & (np.diag(c) > 0)
    sub = c[np.ix_(keep, keep)]
    if keep.sum() < 2 or not np.all(np.isfinite(sub)):
        return {}
    sd = np.sqrt(np.diag(sub))
    corr = sub / np.outer(sd, sd)
    inflation = np.sqrt(np.maximum(np.diag(np.linalg.pinv(corr, hermitian=True)), 1.0))
    kept = [n for n, k in zip(names, keep) if k]
    out = {}
    for i, name in enumerate(kept):
        if (which is not None and name not in which) or not inflation[i] > threshold:
            continue
        partners = [j for j in np.argsort(-np.abs(corr[i])) if j != i and abs(corr[i, j]) >= partner][:max_partners]
        out[name] = {
            "with": [kept[j] for j in partners],
            "correlations": [float(corr[i, j]) for j in partners],
            "inflation": float(inflation[i]),
        }
    return out


def _in_null_space(directions, rank: int, tol: float = 1e-6):
    """Which parameters have a part in the null space spanned by `directions[rank:]` (each row
    scaled to a largest entry of 1, as `_solve` gives them): those the data leave undetermined. A
    parameter outside it is estimable, and its pseudo-inverse variance is its variance (Searle,
    *Linear Models*, 1971, on estimable functions)."""
    null = jnp.abs(jnp.asarray(directions)[rank:])
    return jnp.any(null > tol, axis=0) if null.shape[0] else jnp.zeros(null.shape[1], bool)


_CHUNK_ROWS = 256


def tsqr_r(a):
    r"""The triangular factor $R$ of a tall matrix by tall-skinny QR (TSQR), without forming $Q$.

    The rows are split into blocks of `_CHUNK_ROWS`; each block is factored on its own (one
    batched Householder QR), and the stacked triangular factors are factored again, until few rows
    are left. $R$ is that of a Householder QR of the whole matrix up to the signs of its rows, and
    TSQR is as backward stable as Householder QR; on a CPU it runs many times faster than one
    Householder QR of a 100,000-row matrix (short blocks stay in cache), and on a GPU the blocks
    run in parallel.

    ??? cite

        J. Demmel, L. Grigori, M. Hoemmen and J. Langou, "Communication-optimal parallel and
        sequential QR and LU factorizations", SIAM Journal on Scientific Computing 34(1), 2012.
    """
    m, n = a.shape
    chunk = max(_CHUNK_ROWS, 4 * n)
    while a.shape[0] > 2 * chunk:
        blocks = a.shape[0] // chunk
        head = a[: blocks * chunk].reshape(blocks, chunk, n)
        r = jnp.linalg.qr(head, mode="r")  # (blocks, n, n): each block's triangular factor
        a = jnp.concatenate([r.reshape(-1, n), a[blocks * chunk :]])
    return jnp.linalg.qr(a, mode="r")


@jax.jit
def _solve(a, y, w, rcond):
    r"""Column-scaled weighted least squares by factoring the regressor itself (QR, then SVD of R).

    $[W^{1/2} A,\ W^{1/2} y] = Q [R, c; 0, \rho]$ (Householder, as TSQR: `tsqr_r`), so
    $c = Q^\top W^{1/2} y$ comes with $R$ and $Q$ is never formed. The column norms $D$ of
    $W^{1/2} A$ are those of $R$, and $W^{1/2} A D^{-1} = Q (R D^{-1})$ (Householder QR commutes
    with column scaling), so no pass over the rows scales them. $R D^{-1} = U_R S V^\top$, so
    $W^{1/2} A D^{-1} = (Q U_R) S V^\top$ is the SVD of the scaled regressor, obtained without
    forming $A^\top A$ (which would square the condition number and lose half the digits: in
    float32 two columns that differ by $10^{-3}$ of their scale would not be told apart). The
    estimate is $D^{-1} V S^{+} U_R^\top c$ at the numerical rank, and the residual's squared norm
    is $\rho^2$ plus the parts of $U_R^\top c$ in the directions dropped from the rank.
    """
    m, n = a.shape
    if w is None:  # unweighted: no pass over the rows to apply unit weights
        aw, yw = a, y
    else:
        sw = jnp.sqrt(w)
        aw = a * sw[:, None]
        yw = y * sw
    r_full = tsqr_r(jnp.concatenate([aw, yw[:, None]], axis=1))
    r, qty = r_full[:n, :n], r_full[:n, n]
    rho = r_full[n, n] if r_full.shape[0] > n else jnp.zeros((), a.dtype)  # m == n rows: y is in range
    scale = jnp.linalg.norm(r, axis=0)
    scale = jnp.where(scale > 0, scale, 1.0)
    u_r, s, vt = jnp.linalg.svd(r / scale[None, :])
    finite = jnp.all(jnp.isfinite(s)) & (s[0] > 0)
    rank = jnp.where(finite, jnp.sum(s > rcond * s[0]), 0)
    cond = jnp.where(finite & (s[-1] > 0), s[0] / jnp.where(s[-1] > 0, s[-1], 1.0), jnp.inf)
    keep = jnp.arange(n) < rank
    inv_s = jnp.where(keep, 1.0 / jnp.where(s > 0, s, 1.0), 0.0)
    projected = u_r.T @ qty  # (Q U_R)^T W^{1/2} y
    z = vt.T @ (inv_s * projected)
    pinv_gram = (vt.T * inv_s[None, :] ** 2) @ vt
    estimate = z / scale
    residual2 = rho**2 + jnp.sum(jnp.where(keep, 0.0, projected**2))
    dof = jnp.maximum((m if w is None else jnp.minimum(m, jnp.sum(w > 0))) - rank, 1)
    covariance = residual2 / dof * pinv_gram / jnp.outer(scale, scale)
    directions = vt / scale[None, :]
    directions = directions / jnp.max(jnp.abs(directions), axis=1, keepdims=True)
    residual_rms = jnp.sqrt(residual2 / m)
    return estimate, covariance, s, directions, cond, rank, residual_rms


def least_squares(
    regressor: Float[ArrayLike, "rows n_params"],
    target: Float[ArrayLike, " rows"],
    *,
    names: tuple[str, ...] | None = None,
    weights: Float[ArrayLike, " rows"] | None = None,
    rcond: float = 1e-7,
    allow_rank_deficient: bool = False,
) -> Solution:
    r"""Solve $\min_\theta \lVert W^{1/2}(A\theta - y)\rVert^2$, with standard errors and identifiability.

    **Arguments:**

    - `regressor`: $A$, shape `(rows, n_params)`.
    - `target`: $y$, shape `(rows,)`.
    - `names`: parameter names for messages (default `p0, p1, ...`).
    - `weights`: non-negative row weights $W$ (default 1), e.g. inverse noise variances.
    - `rcond`: singular values of the column-scaled regressor below `rcond * s_max` count as zero.
    - `allow_rank_deficient`: if `False` (default) a rank-deficient problem raises
      `IdentifiabilityError` naming the unidentified combinations; if `True` the minimum-norm
      solution (in scaled coordinates) is returned with infinite standard errors.

    **Returns:** a `Solution` whose `model` and `value` are the estimate $\hat\theta$, with
    `covariance` $\sigma^2 (A^\top W A)^{+}$ from the residual variance
    $\sigma^2 = \lVert r \rVert^2_W / (m - \operatorname{rank})$ and `std_errors` its diagonal's
    roots (short of full rank, `allow_rank_deficient`, `inf` for each parameter with a part in the
    null space, the pseudo-inverse's for the others), and `statistics` (`dynax.internal.Statistics`): the
    singular values and directions of the column-scaled weighted regressor, its condition number
    and numerical rank, the residual RMS and the row count.

    **Raises:** `IdentifiabilityError` (a `DataError`) when the data do not determine all
    parameters; `ValueError` on shape mismatches.

    ??? cite

        M. Gautier, "Numerical calculation of the base inertial parameters of robots", Journal of
        Robotic Systems 8(4), 1991 (QR/SVD identifiability); G. H. Golub and C. F. Van Loan,
        *Matrix Computations*, 4th ed., sections 5.3-5.5; J. Demmel, L. Grigori, M. Hoemmen and
        J. Langou, "Communication-optimal parallel and sequential QR and LU factorizations", SIAM
        Journal on Scientific Computing 34(1), 2012 (TSQR).
    """
    a = jnp.asarray(regressor)
    y = jnp.asarray(target)
    if a.ndim != 2:
        raise ValueError(f"least_squares: `regressor` must be 2-d (rows, n_params), got shape {a.shape}")
    if y.shape != (a.shape[0],):
        raise ValueError(f"least_squares: `target` must have shape ({a.shape[0]},), got {y.shape}")
    m, n = a.shape
    names = tuple(names) if names is not None else tuple(f"p{i}" for i in range(n))
    if len(names) != n:
        raise ValueError(f"least_squares: {len(names)} `names` for {n} regressor columns")
    w = None if weights is None else jnp.asarray(weights, a.dtype)
    if w is not None and w.shape != (m,):
        raise ValueError(f"least_squares: `weights` must have shape ({m},), got {w.shape}")
    if m < n:
        w = jnp.ones(m, a.dtype) if w is None else w
        a = jnp.concatenate([a, jnp.zeros((n - m, n), a.dtype)])
        y = jnp.concatenate([y, jnp.zeros(n - m, y.dtype)])
        w = jnp.concatenate([w, jnp.zeros(n - m, w.dtype)])
    estimate, covariance, s, directions, cond, rank, residual_rms = _solve(a, y, w, rcond)
    rank = int(rank)
    std = jnp.sqrt(jnp.diag(covariance))
    if rank < n:  # a parameter with a part in the null space is not estimable: no finite error
        std = jnp.where(_in_null_space(directions, rank), jnp.inf, std)
    statistics = Statistics(
        condition_number=cond,
        rank=jnp.asarray(rank),
        singular_values=s,
        directions=directions,
        residual_rms=residual_rms,
        n_rows=m,
    )
    loss = 0.5 * m * residual_rms**2
    fit = Solution(
        model=estimate,
        value=estimate,
        parameters=Parameters.of(estimate, names=names),
        covariance=covariance,
        std_errors=std,
        result=optx.RESULTS.successful,
        loss=loss,
        initial_loss=loss,
        steps=jnp.asarray(0),
        n_residuals=m,
        statistics=statistics,
    )
    cond = float(cond)
    if rank < n and not allow_rank_deficient:
        unidentified = statistics.unidentified(names)
        listed = "; ".join(unidentified)
        raise IdentifiabilityError(
            f"the data do not identify all parameters: numerical rank {rank} of {n} "
            f"(condition number {cond:.3g}, {m} equations). Unidentified parameter combination(s): {listed}. "
            "Excite the system more (larger and richer inputs, more motion in every joint, more samples) "
            "or fix these parameters.",
            unidentified=unidentified,
            rank=rank,
            n_params=n,
            condition_number=cond,
        )
    return fit
