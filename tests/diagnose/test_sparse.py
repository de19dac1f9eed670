"""Sparse regression of the discovery search: STLSQ, cross-validation by group, stability selection."""

import numpy as np

from dynax.internal import sparse_search, Stability, stlsq


def _design(n, m, seed, correlated=False):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, m))
    if correlated:  # column 1 is a noisy copy of column 0, as q and sin(q) are
        X[:, 1] = X[:, 0] + 0.3 * rng.normal(size=n)
    return X, rng


def test_stlsq_recovers_a_sparse_law_from_noisy_data():
    X, rng = _design(2000, 12, seed=0)
    truth = np.zeros(12)
    truth[[2, 7]] = [1.5, -0.8]
    y = X @ truth + 0.5 * rng.normal(size=2000)
    coef = stlsq(X, y, 0.1, max_terms=4, ridge=1e-6)
    assert set(np.flatnonzero(coef)) == {2, 7}
    np.testing.assert_allclose(coef[[2, 7]], truth[[2, 7]], atol=0.05)  # 0.5 / sqrt(2000) ~ 0.011 per coefficient


def test_stlsq_respects_the_bound_on_the_number_of_terms():
    X, rng = _design(500, 8, seed=1)
    y = X @ np.arange(1.0, 9.0) + 0.1 * rng.normal(size=500)
    assert np.count_nonzero(stlsq(X, y, 0.0, max_terms=3)) == 3


def test_sparse_search_finds_the_true_term_among_correlated_ones():
    X, rng = _design(3000, 10, seed=2, correlated=True)
    y = 2.0 * X[:, 0] + 1.0 * rng.normal(size=3000)
    groups = np.repeat(np.arange(5), 600)
    fit = sparse_search(X, y, groups, max_terms=3, stability=Stability(block=100))
    assert fit.statistics.selected == (0,)
    assert abs(fit.value[0] - 2.0) < 0.1 and fit.names == ("[0]",)
    assert fit.model[0] == fit.value[0] and not np.any(fit.model[1:])  # the coefficient of every feature
    assert fit.statistics.cv_r2 > 0.5
    assert fit.loss < 0.5 * fit.initial_loss


def test_sparse_search_on_noise_keeps_nothing():
    # Pure noise: no feature should be stably selected (a false discovery rate check over seeds).
    false = 0
    for seed in range(5):
        X, rng = _design(1500, 15, seed=10 + seed)
        groups = np.repeat(np.arange(5), 300)
        fit = sparse_search(X, rng.normal(size=1500), groups, max_terms=3, stability=Stability(block=50, seed=seed))
        false += len(fit.statistics.selected) > 0 and fit.statistics.cv_r2 > 0.05
    assert false == 0


def test_the_sparse_search_is_a_method_that_fits_records():
    # The correlated design above, cut into five records of 600 samples (the candidate columns as
    # states, the target as the input): each record is a group of the cross-validation.
    import jax.numpy as jnp
    import pytest

    import dynax
    from dynax.internal import FeatureRegression, SparseSearch

    X, rng = _design(3000, 10, seed=2, correlated=True)
    y = 2.0 * X[:, 0] + 1.0 * rng.normal(size=3000)
    names = tuple(f"x{k}" for k in range(10))
    records = [
        dynax.Trajectory(
            jnp.arange(600) * 0.01, jnp.asarray(X[k : k + 600]), jnp.asarray(y[k : k + 600, None]), names, ("y",)
        )
        for k in range(0, 3000, 600)
    ]
    regression = FeatureRegression(lambda r: np.asarray(r.xs), lambda r: np.asarray(r.us[:, 0]), names=names)
    method = SparseSearch(stability=Stability(block=100))
    fit = method.fit(regression, records)
    assert isinstance(method, dynax.AbstractMethod) and method.label == "sparse"
    assert fit.names == ("x0",) and abs(float(fit.value[0]) - 2.0) < 0.1
    # the search on the stacked arrays, one group per record
    direct = sparse_search(X, y, np.repeat(np.arange(5), 600), stability=Stability(block=100))
    np.testing.assert_array_equal(np.asarray(fit.value), np.asarray(direct.value))
    # one record: cut into contiguous pieces for the cross-validation
    assert method.fit(regression, records[0]).statistics.selected[:1] == (0,)
    with pytest.raises(dynax.UsageError, match="FeatureRegression"):
        method.fit(dynax.Acrobot(), records)
