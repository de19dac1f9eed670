"""Comparison helpers shared across the suite, in the manner of optimistix's and diffrax's `tests/helpers.py`."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


def tree_allclose(x, y, *, rtol=1e-7, atol=1e-9):
    """Whether two PyTrees have the same structure, the same leaf types and close leaves."""
    # `eqx.tree_equal` answers False for a structure mismatch and a boolean array for a leaf comparison
    return bool(eqx.tree_equal(x, y, typematch=True, rtol=rtol, atol=atol))


def finite_difference_jvp(fn, primals, tangents, eps=None):
    """Central-difference directional derivative of `fn` at `primals` along `tangents` (float64 only).

    Returns `(fn(*primals), tangents_out)`. The step defaults to $\\epsilon^{1/3}$ times the largest
    primal magnitude (at least 1), which balances the $O(h^2)$ truncation error of central differences
    against the $O(\\epsilon/h)$ rounding error: about 1e-10 relative for smooth functions of order one.
    """
    assert jax.config.jax_enable_x64, "finite differences need float64"
    leaves = [jnp.max(jnp.abs(p)) for p in jax.tree.leaves(primals) if jnp.size(p)] + [jnp.asarray(1.0)]
    scale = float(jnp.max(jnp.stack(leaves)))
    h = np.cbrt(np.finfo(np.float64).eps) * scale if eps is None else eps
    plus = jax.tree.map(lambda p, t: p + h * t, primals, tangents)
    minus = jax.tree.map(lambda p, t: p - h * t, primals, tangents)
    out_plus, out_minus = fn(*plus), fn(*minus)
    return fn(*primals), jax.tree.map(lambda a, b: (a - b) / (2 * h), out_plus, out_minus)


def assert_jvp_matches_finite_differences(fn, primals, tangents, *, rtol=1e-5, atol=1e-8, eps=None):
    """`jax.jvp` of `fn` against central differences along `tangents`, leaf by leaf."""
    out, tangents_out = jax.jvp(fn, primals, tangents)
    out_fd, tangents_fd = finite_difference_jvp(fn, primals, tangents, eps)
    assert tree_allclose(out, out_fd, rtol=1e-12, atol=1e-12)
    for autodiff, fd in zip(jax.tree.leaves(tangents_out), jax.tree.leaves(tangents_fd)):
        np.testing.assert_allclose(np.asarray(autodiff), np.asarray(fd), rtol=rtol, atol=atol)


def random_tangent(key, tree):
    """A standard-normal tangent with the structure of `tree` (array leaves only)."""
    leaves, treedef = jax.tree.flatten(tree)
    keys = jax.random.split(key, len(leaves))
    return jax.tree.unflatten(
        treedef, [jax.random.normal(k, jnp.shape(x), jnp.result_type(x)) for k, x in zip(keys, leaves)]
    )
