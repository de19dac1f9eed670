r"""The cluster-robust (sandwich) covariance of a least-squares fit whose residuals are correlated within groups.

The Gauss-Newton covariance $\hat\sigma^2 (J^\top J)^{+}$ counts every residual as independent. An
output-error fit's residuals are not: a rollout started from a measured state carries that state's
noise all along, and where the model is not exact its error drifts with the manoeuvre. With the
residuals grouped into clusters that are independent of one another (windows, blocks of segments),

$$\operatorname{cov}(\hat z) = A \Big(\sum_g s_g s_g^\top\Big) A \,\frac{G}{G-1}, \qquad
A = (J^\top J)^{+}, \qquad s_g = J_g^\top r_g,$$

allows any correlation and any variance within a cluster; $G$ counts the clusters that hold a
residual (a cluster whose score is zero, a left-out window, does not count).

??? cite

    K.-Y. Liang and S. L. Zeger, "Longitudinal data analysis using generalized linear models",
    Biometrika 73(1), 1986; H. White, "A heteroskedasticity-consistent covariance matrix estimator
    and a direct test for heteroskedasticity", Econometrica 48(4), 1980; A. C. Cameron and
    D. L. Miller, "A practitioner's guide to cluster-robust inference", J. Human Resources 50(2),
    2015 (the $G/(G-1)$ factor, and the estimator's downward bias with few clusters).

With few clusters (a handful of records) the sandwich runs low. `jackknife_covariance` is the
delete-one-cluster jackknife instead, linearised: leaving cluster $g$ out moves the estimate by one
Gauss-Newton step, $\delta_g = (J^\top J - J_g^\top J_g)^{+} s_g$ (the full fit's gradient is zero,
so the rest's is $-s_g$), and

$$\operatorname{cov}(\hat z) = \frac{G-1}{G} \sum_g (\delta_g - \bar\delta)(\delta_g - \bar\delta)^\top .$$

It is the sandwich with each cluster's own leverage taken out (the "CR3" estimator), which errs on
the large side where the sandwich errs on the small one. A direction that one cluster alone
determines has no step without it (the pseudo-inverse leaves it out), so its spread is understated:
the least-squares stage's rank and `poorly_determined` are the check for that.

??? cite

    J. G. MacKinnon and H. White, "Some heteroskedasticity-consistent covariance matrix estimators
    with improved finite sample properties", J. Econometrics 29(3), 1985; R. M. Bell and
    D. F. McCaffrey, "Bias reduction in standard errors for linear regression with multi-stage
    samples", Survey Methodology 28(2), 2002; Cameron and Miller 2015, sec. VI.

A least-squares fit of equations sampled in time (the inverse-dynamics rows of a record) has
residuals correlated from one sample to the next instead: a low-pass filter spreads each sample's
noise over its neighbours, and where the model misses an effect its error follows the motion.
`serial_covariance` is then the sandwich with the scores of each time step,
$s_t = \sum_{i \in t} J_i r_i$ (rows sharing a time step, e.g. a record's joints, summed), and a
Bartlett kernel over their lags within each record,

$$\Omega = \sum_{\text{records}} \Big(\Gamma_0 + \sum_{l \ge 1} \big(1 - \tfrac{l}{S}\big)_+
(\Gamma_l + \Gamma_l^\top)\Big), \qquad \Gamma_l = \sum_t s_t s_{t-l}^\top, \qquad
\operatorname{cov}(\hat z) = A \,\Omega\, A \,\frac{T}{T - n},$$

with the bandwidth $S$ chosen from the data by Andrews' AR(1) plug-in rule: each score
component's first autocorrelation $\rho_a$ and innovation variance $\sigma_a^2$ (of the
column-scaled regressor, so that the components weigh alike) give
$\alpha = \sum_a \frac{4\rho_a^2\sigma_a^4}{(1-\rho_a)^6(1+\rho_a)^2} \big/ \sum_a
\frac{\sigma_a^4}{(1-\rho_a)^4}$ and $S = 1.1447\,(\alpha T)^{1/3}$ over the $T$ time steps, with
$\rho_a$ clipped to $\pm 0.97$ and $S$ to the shortest record. Independent residuals give
$\rho_a \approx 0$, $S$ near 1 and the usual covariance; residuals correlated over many samples
give errors several times larger (as a real rig's filtered inverse-dynamics rows do).

??? cite

    W. K. Newey and K. D. West, "A simple, positive semi-definite, heteroskedasticity and
    autocorrelation consistent covariance matrix", Econometrica 55(3), 1987; D. W. K. Andrews,
    "Heteroskedasticity and autocorrelation consistent covariance matrix estimation",
    Econometrica 59(3), 1991 (the automatic bandwidth: the AR(1) plug-in and the Bartlett
    kernel's constant 1.1447).
"""

import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int
import numpy as np
import scipy.fft

# Andrews (1991): the Bartlett kernel's optimal-bandwidth constant. The AR(1) coefficients are
# clipped so that a near-unit root does not ask for an unbounded bandwidth (the shortest record caps
# it in any case).
_BARTLETT = 1.1447
_MAX_RHO = 0.97


def _scores(jac, residuals, clusters, n_clusters):
    """Each cluster's score $s_g = J_g^\top r_g$, `(n_clusters, n)`."""
    return jax.ops.segment_sum(jac * residuals[:, None], clusters, num_segments=n_clusters)


def clustered_covariance(
    jac: Float[Array, "m n"], residuals: Float[Array, " m"], clusters: Int[Array, " m"], n_clusters: int
) -> tuple[Float[Array, "n n"], Array]:
    """The sandwich covariance of the unknowns `jac` is taken in, with residual `i` in cluster `clusters[i]`
    (`0 <= clusters < n_clusters`, a static number); jittable and `vmap`-able.

    **Returns:** `(covariance, G)`, `G` the clusters counted (see the module).
    """
    scores = _scores(jac, residuals, clusters, n_clusters)
    used = jnp.sum(jnp.any(scores != 0, axis=1))
    bread = jnp.linalg.pinv(jac.T @ jac, hermitian=True)
    return bread @ (scores.T @ scores) @ bread * used / jnp.maximum(used - 1, 1), used


def jackknife_covariance(
    jac: Float[Array, "m n"], residuals: Float[Array, " m"], clusters: Int[Array, " m"], n_clusters: int
) -> tuple[Float[Array, "n n"], Array]:
    """The linearised delete-one-cluster jackknife covariance (see the module), arguments as
    `clustered_covariance`'s; jittable.

    **Returns:** `(covariance, G)`, `G` the clusters counted, as `clustered_covariance`'s.
    """
    scores = _scores(jac, residuals, clusters, n_clusters)
    # One cluster's Gram matrix at a time: no (m, n, n) intermediate.
    grams = jax.lax.map(lambda g: (jac * (clusters == g)[:, None]).T @ jac, jnp.arange(n_clusters))
    held = jnp.any(scores != 0, axis=1)
    gram = jac.T @ jac
    deltas = jax.vmap(lambda g, s: jnp.linalg.pinv(gram - g, hermitian=True) @ s)(grams, scores)
    n_used = jnp.sum(held)
    mean = jnp.sum(jnp.where(held[:, None], deltas, 0.0), axis=0) / jnp.maximum(n_used, 1)
    centred = jnp.where(held[:, None], deltas - mean[None, :], 0.0)
    return centred.T @ centred * (n_used - 1) / jnp.maximum(n_used, 1), n_used


def serial_bandwidth(pieces: list[np.ndarray]) -> float:
    """Andrews' AR(1) plug-in bandwidth of the Bartlett kernel (see the module) for score series
    `pieces`, one `(T_r, n)` array per record, columns on a common scale."""
    # one record's pieces are read in place (the same rows in the same order as their concatenation)
    lead = pieces[0][1:] if len(pieces) == 1 else np.concatenate([p[1:] for p in pieces])
    lag = pieces[0][:-1] if len(pieces) == 1 else np.concatenate([p[:-1] for p in pieces])
    norm = np.sum(lag * lag, axis=0)
    rho = np.clip(np.sum(lead * lag, axis=0) / np.where(norm > 0, norm, 1.0), -_MAX_RHO, _MAX_RHO)
    sigma2 = np.mean((lead - rho * lag) ** 2, axis=0)
    keep = sigma2 > 0
    if not np.any(keep):
        return 1.0
    rho, s4 = rho[keep], sigma2[keep] ** 2
    alpha = np.sum(4 * rho**2 * s4 / ((1 - rho) ** 6 * (1 + rho) ** 2)) / np.sum(s4 / (1 - rho) ** 4)
    steps = sum(len(p) for p in pieces)
    return float(max(_BARTLETT * (alpha * steps) ** (1 / 3), 1.0))


def bartlett_lags(p: np.ndarray, bandwidth: float) -> np.ndarray:
    r"""$\sum_{l \ge 1} (1 - l/S)_+ \Gamma_l$ of one record's scores `p`, `(T, n)`, with
    $\Gamma_l[a, b] = \sum_t p_{t+l, a}\, p_{t, b}$: every lag's cross-products at once through the
    FFT (zero-padded, so not circular), $O(n^2 T \log T)$ instead of $O(n^2 T S)$."""
    n_steps, n = p.shape
    lags = min(math.ceil(bandwidth), n_steps)
    weights = np.maximum(1.0 - np.arange(lags) / bandwidth, 0.0)
    weights[0] = 0.0  # lag 0 is the meat's own term
    if lags < 2:
        return np.zeros((n, n))
    size = scipy.fft.next_fast_len(n_steps + lags)
    spectrum = scipy.fft.rfft(p, n=size, axis=0)
    conjugate = np.conj(np.asarray(spectrum))
    out = np.empty((n, n))
    for a in range(n):
        correlation = scipy.fft.irfft(spectrum[:, a : a + 1] * conjugate, n=size, axis=0)[:lags]
        out[a] = weights @ correlation
    return out


def serial_covariance(
    jac: Float[Array | np.ndarray, "m n"],
    residuals: Float[Array | np.ndarray, " m"],
    steps: Int[Array | np.ndarray, " m"],
    record_steps: tuple[int, ...],
    bandwidth: float | None = None,
) -> tuple[Float[Array, "n n"], float]:
    r"""The covariance of the unknowns of a least-squares fit whose residuals are correlated in time
    (see the module): Bartlett-kernel sandwich over each record's time steps. Host-side (the
    bandwidth is chosen from the data).

    **Arguments:**

    - `jac`, `residuals`: the weighted regressor $W^{1/2}A$ and residual $W^{1/2}(y - A\hat z)$.
    - `steps`: each row's time step, counted through the records (`0 <= steps < sum(record_steps)`);
      rows sharing a step (the joints of one sample) are summed into one score.
    - `record_steps`: each record's number of time steps, in order; no lag crosses a record.
    - `bandwidth`: the kernel's $S$ (lags below it count); default Andrews' plug-in.

    **Returns:** `(covariance, bandwidth)`.
    """
    jac = np.asarray(jac, dtype=float)
    residuals = np.asarray(residuals, dtype=float)
    n_steps = int(sum(record_steps))
    scale = np.linalg.norm(jac, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    scaled = jac / scale
    # `_scores` in numpy: host-side and float64 whatever JAX's x64 setting (segment_sum would follow it);
    # `bincount` adds each step's rows in row order, as `np.add.at` does, in one pass per column
    steps = np.asarray(steps)
    terms = scaled * residuals[:, None]
    scores = np.stack([np.bincount(steps, terms[:, k], minlength=n_steps) for k in range(jac.shape[1])], axis=1)
    bounds = np.cumsum((0,) + tuple(record_steps))
    pieces = [scores[a:b] for a, b in zip(bounds[:-1], bounds[1:]) if b - a > 1]
    if bandwidth is None:
        bandwidth = serial_bandwidth(pieces) if pieces else 1.0
        bandwidth = min(bandwidth, max(min(len(p) for p in pieces) - 1, 1) if pieces else 1.0)
    meat = scores.T @ scores
    for p in pieces:
        lagged = bartlett_lags(p, bandwidth)
        meat += lagged + lagged.T
    bread = np.linalg.pinv(scaled.T @ scaled, hermitian=True)
    used = int(np.sum(np.any(scores != 0, axis=1)))
    n = jac.shape[1]
    covariance = bread @ meat @ bread * used / max(used - n, 1) / np.outer(scale, scale)
    return jnp.asarray(covariance), float(bandwidth)
