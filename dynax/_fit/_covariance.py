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
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int


def clustered_covariance(
    jac: Float[Array, "m n"], residuals: Float[Array, " m"], clusters: Int[Array, " m"], n_clusters: int
) -> tuple[Float[Array, "n n"], Array]:
    """The sandwich covariance of the unknowns `jac` is taken in, with residual `i` in cluster `clusters[i]`
    (`0 <= clusters < n_clusters`, a static number); jittable and `vmap`-able.

    **Returns:** `(covariance, G)`, `G` the clusters counted (see the module).
    """
    scores = jax.ops.segment_sum(jac * residuals[:, None], clusters, num_segments=n_clusters)
    used = jnp.sum(jnp.any(scores != 0, axis=1))
    bread = jnp.linalg.pinv(jac.T @ jac, hermitian=True)
    return bread @ (scores.T @ scores) @ bread * used / jnp.maximum(used - 1, 1), used
