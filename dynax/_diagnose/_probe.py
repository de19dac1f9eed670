r"""The residual probe's regularisation, chosen by cross-validation over runs.

The probe is a ridge regression of one-step residuals on a generic feature library. Fitted on some
runs and scored on others, an unregularised fit reads the runs' different excitation as structure
that does not transfer (negative held-out $R^2$), and then hides the structure that does. The ridge
strength is chosen by leave-one-run-out cross-validation on the training runs (on a single run,
by three contiguous folds), so the probe keeps only what predicts residuals on a run it was not
fitted on.

??? cite

    A. E. Hoerl and R. W. Kennard, "Ridge regression: biased estimation for nonorthogonal
    problems", Technometrics 12(1), 1970. M. Stone, "Cross-validatory choice and assessment of
    statistical predictions", Journal of the Royal Statistical Society B 36(2), 1974.
"""

import numpy as np

RIDGE_GRID = (1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0)


def ridge_fit(Phi, R, strength: float):
    """Ridge coefficients for standardised features `Phi (n, p)` and targets `R (n, k)`; penalty `strength * n`
    (the last column, the constant, is not penalised)."""
    penalty = strength * Phi.shape[0] * np.eye(Phi.shape[1])
    penalty[-1, -1] = 0.0
    return np.linalg.solve(Phi.T @ Phi + penalty + 1e-12 * np.eye(Phi.shape[1]), Phi.T @ R)


def folds_by_run(sizes) -> list[np.ndarray]:
    """Sample indices of each fold: one fold per run, or three contiguous folds of a single run."""
    sizes = list(sizes)
    if len(sizes) == 1:
        return np.array_split(np.arange(sizes[0]), 3)
    edges = np.cumsum([0] + sizes)
    return [np.arange(a, b) for a, b in zip(edges[:-1], edges[1:])]


def cross_validated_ridge(Phi, R, sizes, grid=RIDGE_GRID) -> tuple[float, dict]:
    """The ridge strength from `grid` with the smallest leave-one-run-out squared error.

    **Arguments:** `Phi (n, p)` standardised features, `R (n, k)` residuals, stacked run after run;
    `sizes` the samples per run.

    **Returns:** `(strength, {strength: cross-validated R^2})`.
    """
    folds = folds_by_run(sizes)
    total = float(np.sum(R**2))
    scores = {}
    for strength in grid:
        sse = 0.0
        for fold in folds:
            train = np.setdiff1d(np.arange(Phi.shape[0]), fold)
            beta = ridge_fit(Phi[train], R[train], strength)
            sse += float(np.sum((R[fold] - Phi[fold] @ beta) ** 2))
        scores[strength] = 1.0 - sse / max(total, 1e-300)
    best = max(scores, key=scores.get)
    return best, scores
