r"""Sparse regression for the discovery search: sequentially thresholded ridge least squares with
cross-validation by run and stability selection over subsamples of blocks.

The columns are standardised, so the threshold is on a coefficient's effect in units of the
target's spread. The threshold is chosen by cross-validation over *groups* (runs, or contiguous
pieces of one run: neighbouring samples are not independent), with the one-standard-error rule
(the sparsest threshold whose score is within one standard error of the best). The features kept
are those selected in at least `min_frequency` of the fits on random halves of the blocks (the
stability selection of Meinshausen and Buehlmann), at most `max_terms` of them.

??? cite

    S. L. Brunton, J. L. Proctor and J. N. Kutz, "Discovering governing equations from data by
    sparse identification of nonlinear dynamical systems", PNAS 113(15), 2016 (SINDy, sequentially
    thresholded least squares). S. H. Rudy, S. L. Brunton, J. L. Proctor and J. N. Kutz,
    "Data-driven discovery of partial differential equations", Science Advances 3(4), 2017
    (STRidge). N. Meinshausen and P. Buehlmann, "Stability selection", J. Royal Statistical
    Society B 72(4), 2010. T. Hastie, R. Tibshirani and J. Friedman, *The Elements of Statistical
    Learning*, 2nd ed., 2009, section 7.10 (cross-validation, one-standard-error rule).
"""

from collections.abc import Callable, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._errors import UsageError
from .._fit import AbstractStatistics, Parameters, Solution
from .._identify._method import AbstractMethod, as_records, FitSettings

THRESHOLDS = (0.01, 0.02, 0.05, 0.08, 0.1, 0.15, 0.2, 0.3, 0.5)  # STLSQ thresholds tried (standardised units)


def stlsq(
    features: np.ndarray, target: np.ndarray, threshold: float, *, max_terms: int, ridge: float = 1e-3, n_iter: int = 10
) -> np.ndarray:
    r"""Sequentially thresholded ridge least squares on standardised columns (Brunton et al. 2016).

    Repeatedly solve ridge least squares on the active columns and drop those whose coefficient
    is below `threshold` in magnitude; if more than `max_terms` remain, keep the largest.

    **Arguments:** `features` `(time, n_features)` and `target` `(time,)`, both standardised by the
    caller; `threshold`; `max_terms`; `ridge` (relative to the number of samples); `n_iter`.

    **Returns:** coefficients `(n_features,)`, zero where not selected.
    """
    n, m = features.shape
    active = np.ones(m, bool)
    coef = np.zeros(m)
    for _ in range(n_iter):
        coef = np.zeros(m)
        if not active.any():
            break
        A = features[:, active]
        coef[active] = np.linalg.solve(A.T @ A + ridge * n * np.eye(A.shape[1]), A.T @ target)
        keep = active & (np.abs(coef) >= threshold)
        if keep.sum() > max_terms:
            order = np.argsort(-np.abs(np.where(keep, coef, 0.0)))
            keep = np.zeros(m, bool)
            keep[order[:max_terms]] = True
        if np.array_equal(keep, active):
            break
        active = keep
    coef[~active] = 0.0
    return coef


def _standardise(features, target):
    # Scaled by their root mean square and not centred: a constant column is a feature like the
    # others (a constant force), not an intercept hidden from the selection.
    sd = np.sqrt(np.mean(features**2, axis=0))
    sd = np.where(sd > 0, sd, 1.0)
    scale = float(np.sqrt(np.mean(target**2))) or 1.0
    return features / sd, target / scale, np.zeros_like(sd), sd, scale


def group_cv_r2(features, target, groups, fit) -> tuple[float, np.ndarray]:
    """Leave-one-group-out $R^2$ (against zero) of `fit(features, target) -> coefficients`, columns scaled on the
    training part.

    **Returns:** `(pooled R^2, per-group R^2)`.
    """
    sse, sst, per_group = 0.0, 0.0, []
    for g in np.unique(groups):
        test = groups == g
        Z, y, mu, sd, scale = _standardise(features[~test], target[~test])
        coef = fit(Z, y)
        pred = ((features[test] - mu) / sd) @ coef * scale
        e = float(np.sum((target[test] - pred) ** 2))
        s = float(np.sum(target[test] ** 2)) or 1.0
        sse, sst = sse + e, sst + s
        per_group.append(1 - e / s)
    return 1 - sse / max(sst, 1e-300), np.asarray(per_group)


class SparseStatistics(AbstractStatistics):
    """What the sparse search adds to its `Solution` (as `solution.statistics`).

    **Fields:** `selected` (indices of the kept features), `frequency` (selection frequency of every feature
    over the subsamples), `threshold` (chosen by cross-validation), `cv_r2` (leave-one-group-out $R^2$ of the
    kept features), `thresholds`, `cv_curve` (the cross-validated $R^2$ of each threshold).
    """

    selected: tuple[int, ...] = eqx.field(static=True)
    frequency: np.ndarray
    threshold: float
    cv_r2: float
    thresholds: tuple[float, ...] = eqx.field(static=True)
    cv_curve: tuple[float, ...] = eqx.field(static=True)


class Stability(eqx.Module):
    """The stability selection of `sparse_search` (Meinshausen and Buehlmann): `n_subsamples` random halves of the
    blocks of `block` consecutive samples, drawn with `seed`; a feature is kept if, at some threshold between the
    cross-validated best and the one chosen, it is selected in at least `min_frequency` of them."""

    n_subsamples: int = eqx.field(default=40, static=True)
    min_frequency: float = eqx.field(default=0.6, static=True)
    block: int = eqx.field(default=50, static=True)
    seed: int = eqx.field(default=0, static=True)


class FeatureRegression(eqx.Module):
    """What `SparseSearch.fit` fits: a target linear in candidate features, both read from a record.

    **Fields:** `features` (`features(record) -> (time, n_features)`, the candidate columns),
    `target` (`target(record) -> (time,)`), `names` (the features' names; `None`: `[k]`).
    """

    features: Callable = eqx.field(static=True)
    target: Callable = eqx.field(static=True)
    names: tuple[str, ...] | None = eqx.field(static=True, default=None)


class SparseSearch(AbstractMethod):
    r"""The sparse search as an identification method: sequentially thresholded ridge least squares
    (STLSQ) on standardised columns, the threshold chosen by cross-validation over groups with the
    one-standard-error rule, the features kept by stability selection over half-subsamples of blocks
    (the module's docstring).

    `fit(FeatureRegression(...), records)` searches the records' stacked rows, each record a group of
    the cross-validation (one record: `n_pieces` contiguous pieces of it); `search(features, target,
    groups)` does the same on arrays already stacked (what the discovery search calls, per coordinate).

    **Fields:**

    - `max_terms`: bound on the number of features kept (default 3).
    - `thresholds`: the STLSQ thresholds tried (standardised units).
    - `stability`: the stability selection over subsamples of blocks (`Stability`).
    - `n_pieces`: the groups one record is cut into for cross-validation (default 5).
    """

    max_terms: int = eqx.field(default=3, static=True)
    thresholds: tuple[float, ...] = eqx.field(default=THRESHOLDS, static=True, converter=tuple)
    stability: Stability = Stability()
    n_pieces: int = eqx.field(default=5, static=True)

    @property
    def label(self) -> str:
        return "sparse"

    def fit(self, system, records, settings: FitSettings = FitSettings()) -> Solution:
        """The sparse model of `system.target` on `system.features` (a `FeatureRegression`) over `records`.

        **Returns:** `search`'s `Solution`.
        """
        del settings  # nothing of a run's settings applies: the columns are the system's
        if not isinstance(system, FeatureRegression):
            raise UsageError(f"SparseSearch fits a FeatureRegression, got {type(system).__name__}")
        trajectories = as_records(records)
        features = np.concatenate([np.asarray(system.features(r), float) for r in trajectories])
        target = np.concatenate([np.asarray(system.target(r), float).reshape(-1) for r in trajectories])
        if len(trajectories) >= 2:
            groups = np.concatenate([np.full(len(r), k) for k, r in enumerate(trajectories)])
        else:
            groups = np.minimum(np.arange(len(target)) * self.n_pieces // len(target), self.n_pieces - 1)
        return self.search(features, target, groups, names=system.names)

    def search(
        self, features: np.ndarray, target: np.ndarray, groups: np.ndarray, *, names: Sequence[str] | None = None
    ) -> Solution:
        r"""Sparse model of `target` on `features`: STLSQ, threshold by cross-validation over `groups`,
        stability selection.

        **Arguments:**

        - `features` `(time, n_features)`, `target` `(time,)` (not standardised).
        - `groups` `(time,)`: the run (or contiguous piece of a run) of each sample; cross-validation
          leaves one group out at a time (at least 2 groups).
        - `names`: the features' names (default `[k]`).

        **Returns:** a `Solution`: its `model` the coefficient of every feature (zero where not kept),
        its `value` the least-squares coefficients of the kept features on the original scale (no
        separate intercept: a constant is the library's `constant` feature), named by feature; no
        covariance (NaN); `loss` and `initial_loss` half the squared residual with and without them;
        its `statistics` a `SparseStatistics`.
        """
        max_terms, thresholds, stability = self.max_terms, self.thresholds, self.stability
        features, target, groups = np.asarray(features, float), np.asarray(target, float), np.asarray(groups)
        if len(np.unique(groups)) < 2:
            raise ValueError("sparse_search: cross-validation by run needs at least 2 groups")
        m = features.shape[1]
        curve, spread = [], []
        for thr in thresholds:
            r2, per = group_cv_r2(features, target, groups, lambda Z, y: stlsq(Z, y, thr, max_terms=max_terms))
            curve.append(r2)
            spread.append(per.std(ddof=1) / np.sqrt(len(per)) if len(per) > 1 else 0.0)
        best = int(np.argmax(curve))
        # One-standard-error rule: the largest threshold (sparsest model) within one SE of the best.
        chosen = max(i for i in range(len(thresholds)) if curve[i] >= curve[best] - spread[best])
        threshold = float(thresholds[chosen])
        n_subsamples, min_frequency, block = stability.n_subsamples, stability.min_frequency, stability.block
        rng = np.random.default_rng(stability.seed)
        n_blocks = max(2, features.shape[0] // block)
        block_of = np.minimum(np.arange(features.shape[0]) // block, n_blocks - 1)
        # Meinshausen and Buehlmann take, for each feature, its largest selection frequency over a set
        # of regularisation levels; here the thresholds from the cross-validated best to the one chosen.
        levels = [float(thresholds[i]) for i in range(min(best, chosen), chosen + 1)]
        counts = np.zeros((len(levels), m))
        for _ in range(n_subsamples):
            half = rng.choice(n_blocks, size=n_blocks // 2, replace=False)
            rows = np.isin(block_of, half)
            Z, y, *_ = _standardise(features[rows], target[rows])
            for i, level in enumerate(levels):
                counts[i] += stlsq(Z, y, level, max_terms=max_terms) != 0
        frequency = (counts / n_subsamples).max(axis=0)
        stable = [int(k) for k in np.argsort(-frequency) if frequency[k] >= min_frequency][:max_terms]
        selected = tuple(sorted(stable))
        coefficients = np.zeros(0)
        cv_r2 = 0.0
        if selected:
            cols = list(selected)
            Z, y, mu, sd, scale = _standardise(features[:, cols], target)
            beta = np.linalg.lstsq(Z, y, rcond=None)[0]
            coefficients = beta * scale / sd[: len(cols)]
            cv_r2, _ = group_cv_r2(
                features[:, cols], target, groups, lambda Z_, y_: np.linalg.lstsq(Z_, y_, rcond=None)[0]
            )
        coefficients = np.asarray(coefficients, float)
        every = np.zeros(m)
        every[list(selected)] = coefficients
        mask = np.zeros(m, bool)
        mask[list(selected)] = True
        parameters = Parameters.of(every, mask, names=None if names is None else tuple(names[k] for k in selected))
        n = len(selected)
        residual = target - features[:, list(selected)] @ coefficients
        return Solution(
            model=every,
            value=jnp.asarray(coefficients),
            parameters=parameters,
            covariance=jnp.full((n, n), jnp.nan),
            std_errors=jnp.full(n, jnp.nan),
            result=optx.RESULTS.successful,
            loss=jnp.asarray(0.5 * float(residual @ residual)),
            initial_loss=jnp.asarray(0.5 * float(target @ target)),
            steps=jnp.asarray(1),
            n_residuals=len(target),
            statistics=SparseStatistics(
                selected=selected,
                frequency=frequency,
                threshold=threshold,
                cv_r2=float(cv_r2),
                thresholds=tuple(float(t) for t in thresholds),
                cv_curve=tuple(float(c) for c in curve),
            ),
        )


def sparse_search(
    features: np.ndarray,
    target: np.ndarray,
    groups: np.ndarray,
    *,
    max_terms: int = 3,
    thresholds=THRESHOLDS,
    stability: Stability = Stability(),
    names: Sequence[str] | None = None,
) -> Solution:
    """`SparseSearch(max_terms, thresholds, stability).search(features, target, groups, names=names)`: the
    sparse search on stacked arrays (see `SparseSearch.search`)."""
    return SparseSearch(max_terms=max_terms, thresholds=thresholds, stability=stability).search(
        features, target, groups, names=names
    )
