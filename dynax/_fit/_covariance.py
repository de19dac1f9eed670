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
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int


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
