"""The metrics system-identification users look for: fit %, residual tests, AIC/FPE, cross-validation.

The definitions follow MATLAB's System Identification Toolbox (`compare`, `resid`, `aic`, `fpe`),
which follows Ljung's textbook, so numbers can be compared with what users already know. These are
diagnostics computed once on the host (numpy), not inside a compiled loop.

??? cite

    L. Ljung, *System Identification: Theory for the User*, 2nd ed., Prentice Hall, 1999
    (section 16.6, model validation; section 16.4, AIC and FPE). H. Akaike, "A new look at the
    statistical model identification", IEEE TAC 19(6), 1974. G. M. Ljung and G. E. P. Box, "On a
    measure of lack of fit in time series models", Biometrika 65(2), 1978.
"""

from collections.abc import Callable, Sequence
import math
from typing import Any

import equinox as eqx
from jaxtyping import ArrayLike, Float
import numpy as np

from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._simulate import simulation_error


def _as_columns(name: str, values: ArrayLike) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise ValueError(f"`{name}` must have shape (time,) or (time, channels), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        row = int(np.argwhere(~np.isfinite(arr))[0, 0])
        raise ValueError(f"`{name}` has a non-finite value at row {row} (a diverged simulation?)")
    return arr


def nrmse_fit(measured: Float[ArrayLike, "..."], simulated: Float[ArrayLike, "..."]) -> Float[np.ndarray, " channels"]:
    r"""The fit percentage of MATLAB's `compare`: $100\,(1 - \|y - \hat y\| / \|y - \bar y\|)$ per channel.

    100 % is a perfect fit; 0 % is no better than the measured mean; it is negative when worse.
    Compare simulated (open-loop) outputs for a simulation fit, one-step predictions for a
    prediction fit.

    **Arguments:**

    - `measured`: $y$, shape `(time,)` or `(time, channels)`.
    - `simulated`: $\hat y$, the same shape.

    **Returns:** the fit [%] per channel, shape `(channels,)`.

    **Raises:** `ValueError` on a shape mismatch, a non-finite value, or a constant measured channel
    (the fit is undefined).
    """
    y = _as_columns("measured", measured)
    y_hat = _as_columns("simulated", simulated)
    if y.shape != y_hat.shape:
        raise ValueError(f"nrmse_fit: `measured` {y.shape} and `simulated` {y_hat.shape} differ in shape")
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    if np.any(spread == 0):
        raise ValueError(f"nrmse_fit: measured channel(s) {np.flatnonzero(spread == 0).tolist()} are constant")
    return 100.0 * (1.0 - np.linalg.norm(y - y_hat, axis=0) / spread)


def horizon_fit(
    system,
    trajectory: Trajectory,
    horizon_s: float,
    *,
    states: Sequence[str] | None = None,
    max_windows: int = 200,
) -> dict[str, float]:
    r"""Fit % of the `horizon_s`-ahead prediction, as MATLAB's `compare(data, sys, k)` with $k = H/dt$.

    From many start samples (`dynax.simulation_error`'s windows) the model is simulated open loop
    from the measured state under the recorded inputs; its states $H$ seconds later are compared
    with the measured ones by `nrmse_fit`. A long horizon approaches the pure simulation fit; the
    diagnosis's reference horizon is the natural choice. A diverged window makes that state's
    fit `-inf`.

    **Arguments:**

    - `system`: the model (its first states are the trajectory's).
    - `trajectory`: the measured (held-out) record.
    - `horizon_s`: $H$ [s].
    - `states`: which states to score (default all of the trajectory's).
    - `max_windows`: at most this many start samples, spread over the record.

    **Returns:** state name -> fit [%].
    """
    names = trajectory.state_names
    states = tuple(names if states is None else states)
    unknown = [s for s in states if s not in names]
    if unknown:
        raise ValueError(f"horizon_fit: {unknown} are not states of the trajectory; the states are {names}")
    error = simulation_error(system, trajectory, (horizon_s,), max_windows=max_windows, states=states)
    errors = np.asarray(error.errors)
    k = errors.shape[1] - 1
    rows = np.asarray(error.starts) + k
    measured = np.asarray(trajectory.xs)[rows]
    predicted = measured + errors[:, k, :]
    out = {}
    for s in states:
        i = names.index(s)
        finite = np.all(np.isfinite(predicted[:, i]))
        out[s] = float(nrmse_fit(measured[:, i], predicted[:, i])[0]) if finite else -math.inf
    return out


def _normal_quantile(confidence: float) -> float:
    if not 0 < confidence < 1:
        raise ValueError(f"`confidence` must be in (0, 1), got {confidence}")
    from scipy.stats import norm

    return float(norm.ppf(0.5 + confidence / 2))


def _correlation(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """$\\hat R_{ab}(\\tau) / \\sqrt{\\hat R_a(0) \\hat R_b(0)}$ for $\\tau = -M..M$, biased (1/N) estimate."""
    n = a.shape[0]
    a = a - a.mean()
    b = b - b.mean()
    raw = (
        np.array(
            [np.dot(a[: n - t], b[t:]) if t >= 0 else np.dot(a[-t:], b[: n + t]) for t in range(-max_lag, max_lag + 1)]
        )
        / n
    )  # sum_t a_t b_{t+tau} / n
    scale = math.sqrt(np.dot(a, a) / n * np.dot(b, b) / n)
    return raw / scale if scale > 0 else np.zeros(2 * max_lag + 1)


class WhitenessTest(eqx.Module):
    r"""Residual autocorrelation with confidence bounds (MATLAB `resid`), per output channel.

    **Fields:**

    - `lags`: $1..M$.
    - `autocorrelation`: normalised $\hat\rho_e(\tau)$, shape `(channels, M)`.
    - `bound`: the band $\pm z_{(1+c)/2} / \sqrt N$ a white sequence stays inside with probability $c$ at each lag.
    - `q_statistic`, `p_value`: the Ljung-Box portmanteau statistic $N(N+2)\sum \hat\rho^2(\tau)/(N-\tau)$
      per channel and its $\chi^2_M$ tail probability (one test over all lags).
    - `white`: per channel, `p_value >= 1 - confidence` (no significant correlation left).
    - `confidence`: $c$.
    """

    lags: np.ndarray
    autocorrelation: np.ndarray
    bound: float
    q_statistic: np.ndarray
    p_value: np.ndarray
    white: np.ndarray
    confidence: float


def whiteness_test(
    residuals: Float[ArrayLike, " time *channels"], *, max_lag: int = 25, confidence: float = 0.99
) -> WhitenessTest:
    r"""Is what the model leaves unexplained white? The autocorrelation test of MATLAB's `resid`.

    A model that captured the dynamics leaves prediction errors that are uncorrelated in time; a
    correlation outside the bound at some lag is dynamics the model misses (Ljung 1999, 16.6).
    Use one-step prediction errors; open-loop simulation errors are correlated even for a
    correct model with noise, so this test is for predictors and noise models.

    **Arguments:**

    - `residuals`: shape `(time,)` or `(time, channels)`.
    - `max_lag`: $M$, the largest lag (MATLAB's default 25).
    - `confidence`: $c$, the confidence level of the bound (MATLAB's default 0.99).

    **Returns:** a `WhitenessTest`.
    """
    e = _as_columns("residuals", residuals)
    n = e.shape[0]
    if not 1 <= max_lag < n - 1:
        raise ValueError(f"whiteness_test: `max_lag` must be in [1, {n - 2}] for {n} samples, got {max_lag}")
    z = _normal_quantile(confidence)
    rho = np.stack([_correlation(e[:, j], e[:, j], max_lag)[max_lag + 1 :] for j in range(e.shape[1])])
    lags = np.arange(1, max_lag + 1)
    q = n * (n + 2) * np.sum(rho**2 / (n - lags), axis=1)
    from scipy.stats import chi2

    p = chi2.sf(q, max_lag)
    return WhitenessTest(lags, rho, z / math.sqrt(n), q, p, p >= 1 - confidence, confidence)


class CrossCorrelationTest(eqx.Module):
    r"""Residual-input cross-correlation with confidence bounds (MATLAB `resid`).

    **Fields:**

    - `lags`: $-M..M$ (a positive lag: the input leads the residual).
    - `cross_correlation`: normalised $\hat\rho_{eu}(\tau)$, shape `(channels, n_inputs, 2M+1)`.
    - `bound`: per channel and input, $z_{(1+c)/2}\sqrt{P/N}$ with
      $P = \sum_{|k| \le M} \hat\rho_e(k)\hat\rho_u(k)$ (Ljung 1999, eq. 16.73), shape `(channels, n_inputs)`.
    - `q_statistic`, `p_value`: per channel and input, $N \hat\rho^\top C^{-1} \hat\rho$ over the
      $2M+1$ lags, with $C$ the lags' covariance by Bartlett's formula
      $C_{\tau_1\tau_2} = \sum_{|k|\le M} \hat\rho_e(k)\hat\rho_u(k + \tau_1 - \tau_2)$, and its
      $\chi^2$ tail probability (Ljung 1999, eq. 16.75, generalised to a coloured residual; the
      eigen-directions of $C$ below $10^{-3}$ of its largest are dropped, with their degrees of freedom):
      one test over all lags, so testing 51 lags does not raise the false-alarm rate the way
      counting bars outside the band does, and a coloured input does not either.
    - `independent`: per channel and input, `p_value >= 1 - confidence`.
    - `confidence`: $c$.
    """

    lags: np.ndarray
    cross_correlation: np.ndarray
    bound: np.ndarray
    q_statistic: np.ndarray
    p_value: np.ndarray
    independent: np.ndarray
    confidence: float


def cross_correlation_test(
    residuals: Float[ArrayLike, " time *channels"],
    inputs: Float[ArrayLike, "..."],
    *,
    max_lag: int = 25,
    confidence: float = 0.99,
) -> CrossCorrelationTest:
    r"""Do the residuals still depend on past inputs? The cross-correlation test of MATLAB's `resid`.

    A correlation between the input at time $t$ and the residual at $t + \tau$ ($\tau > 0$) outside
    the bound means some of the input's effect is not in the model; at $\tau < 0$ it points to
    feedback in the data. The bound accounts for the input's and the residual's own correlation
    (Ljung 1999, 16.6), so a coloured input does not raise false alarms.

    **Arguments:**

    - `residuals`: shape `(time,)` or `(time, channels)`.
    - `inputs`: the recorded inputs, shape `(time,)` or `(time, n_inputs)`.
    - `max_lag`, `confidence`: as `whiteness_test`.

    **Returns:** a `CrossCorrelationTest`.
    """
    e = _as_columns("residuals", residuals)
    u = _as_columns("inputs", inputs)
    n = e.shape[0]
    if u.shape[0] != n:
        raise ValueError(f"cross_correlation_test: `inputs` has {u.shape[0]} samples but `residuals` has {n}")
    if not 1 <= max_lag < n - 1:
        raise ValueError(f"cross_correlation_test: `max_lag` must be in [1, {n - 2}] for {n} samples, got {max_lag}")
    z = _normal_quantile(confidence)
    lags = np.arange(-max_lag, max_lag + 1)
    # Bartlett: for independent e and u, Cov(rho_eu(t1), rho_eu(t2)) = (1/N) sum_k rho_e(k) rho_u(k + t1 - t2).
    wide = min(3 * max_lag, n - 2)
    rho_e = [_correlation(e[:, i], e[:, i], max_lag) for i in range(e.shape[1])]
    rho_u = [_correlation(u[:, j], u[:, j], wide) for j in range(u.shape[1])]
    xc = np.stack(
        [np.stack([_correlation(u[:, j], e[:, i], max_lag) for j in range(u.shape[1])]) for i in range(e.shape[1])]
    )
    shifts = lags[:, None] - lags[None, :]
    ks = np.arange(-max_lag, max_lag + 1)
    bound = np.zeros(xc.shape[:2])
    q = np.zeros(xc.shape[:2])
    dof = np.zeros(xc.shape[:2], dtype=int)
    for i, re in enumerate(rho_e):
        for j, ru in enumerate(rho_u):
            index = np.clip(ks[None, None, :] + shifts[..., None], -wide, wide) + wide
            cov = np.sum(re[None, None, :] * ru[index], axis=-1)
            cov = 0.5 * (cov + cov.T)
            w, v = np.linalg.eigh(cov)
            # Directions the truncated estimate of C barely resolves would turn estimation noise into
            # evidence: keep those above 1e-3 of the largest and count only them as degrees of freedom.
            keep = w > 1e-3 * max(w.max(), 1e-300)
            bound[i, j] = z * math.sqrt(max(cov[max_lag, max_lag], 1e-12) / n)
            proj = v[:, keep].T @ xc[i, j]
            q[i, j] = n * np.sum(proj**2 / w[keep])
            dof[i, j] = keep.sum()
    from scipy.stats import chi2

    p_value = chi2.sf(q, dof)
    return CrossCorrelationTest(lags, xc, bound, q, p_value, p_value >= 1 - confidence, confidence)


def _loss_matrix(residuals):
    e = _as_columns("residuals", residuals)
    n = e.shape[0]
    sign, logdet = np.linalg.slogdet(e.T @ e / n)
    if sign <= 0:
        raise ValueError("the residual covariance is singular (an exact fit, or a channel of zeros)")
    return n, e.shape[1], logdet


def fpe(residuals: Float[ArrayLike, " time *channels"], n_params: int) -> float:
    r"""Akaike's final prediction error, as MATLAB's `fpe`: $\det(\tfrac1N E^\top E)\,\frac{1 + d/N}{1 - d/N}$.

    The expected prediction-error loss on fresh data; smaller is better. Compare models fitted
    to the same data (for example the nominal and an extended model).

    **Arguments:** `residuals` (prediction errors, `(time,)` or `(time, channels)`); `n_params` $d$,
    the number of estimated parameters.

    **Returns:** the FPE.
    """
    n, _, logdet = _loss_matrix(residuals)
    if not 0 <= n_params < n:
        raise ValueError(f"fpe: `n_params` must be in [0, {n}), got {n_params}")
    return float(np.exp(logdet) * (1 + n_params / n) / (1 - n_params / n))


def aic(residuals: Float[ArrayLike, " time *channels"], n_params: int, *, small_sample: bool = False) -> float:
    r"""Akaike's information criterion, as MATLAB's `aic` (raw):
    $N \log\det(\tfrac1N E^\top E) + 2d + N n_y (\log 2\pi + 1)$.

    The Gaussian log-likelihood penalised by the parameter count; smaller is better. Differences
    matter, not values: a difference over about 10 is strong support for the smaller one.

    **Arguments:**

    - `residuals`: prediction errors, `(time,)` or `(time, channels)`.
    - `n_params`: $d$.
    - `small_sample`: add the correction $2d(d+1)/(N-d-1)$ (AICc), advisable when $N/d < 40$.

    **Returns:** the AIC.
    """
    n, n_y, logdet = _loss_matrix(residuals)
    if not 0 <= n_params < n - 1:
        raise ValueError(f"aic: `n_params` must be in [0, {n - 1}), got {n_params}")
    value = n * logdet + 2 * n_params + n * n_y * (math.log(2 * math.pi) + 1)
    if small_sample:
        value += 2 * n_params * (n_params + 1) / (n - n_params - 1)
    return float(value)


def kfold_splits(trajectory: Trajectory, k: int) -> list[tuple[list[Trajectory], Trajectory]]:
    """Split one record into `k` contiguous blocks; fold `i` holds out block `i` and trains on the rest.

    Blocks are contiguous in time (never shuffled: neighbouring samples of a dynamic record are
    not independent). The training part of a fold is a list of one or two trajectories (before and
    after the held-out block), the form `identify` accepts.

    **Arguments:** `trajectory`; `k` the number of folds (each block needs at least 3 samples).

    **Returns:** a list of `(train, validation)` pairs.
    """
    n = len(trajectory)
    if k < 2 or n // k < 3:
        raise UsageError(f"kfold_splits: need 2 <= k <= {n // 3} for {n} samples, got k = {k}")
    edges = np.linspace(0, n, k + 1).round().astype(int)
    folds = []
    for i in range(k):
        train = [trajectory.slice(a, b) for a, b in ((0, edges[i]), (edges[i + 1], n)) if b - a >= 3]
        folds.append((train, trajectory.slice(edges[i], edges[i + 1])))
    return folds


def leave_one_out_splits(trajectories: Sequence[Trajectory]) -> list[tuple[list[Trajectory], Trajectory]]:
    """Multi-experiment cross-validation: fold `i` holds out experiment `i` and trains on the others.

    **Arguments:** `trajectories`, at least two records of the same system.

    **Returns:** a list of `(train, validation)` pairs.
    """
    trajectories = list(trajectories)
    if len(trajectories) < 2:
        raise UsageError(f"leave_one_out_splits: need at least 2 experiments, got {len(trajectories)}")
    return [(trajectories[:i] + trajectories[i + 1 :], held) for i, held in enumerate(trajectories)]


def cross_validate(
    fit: Callable[[list[Trajectory]], Any],
    score: Callable[[Any, Trajectory], float],
    splits: Sequence[tuple[list[Trajectory], Trajectory]],
) -> np.ndarray:
    """Fit on each fold's training part and score on its held-out part.

    **Arguments:**

    - `fit`: `fit(train) -> model`, e.g. `lambda train: identify(system, train, Power()).system`.
    - `score`: `score(model, validation) -> float`, e.g. a simulation-error RMSE or a fit %.
    - `splits`: from `kfold_splits` or `leave_one_out_splits`.

    **Returns:** the scores, one per fold (their spread is the uncertainty of the estimate).
    """
    return np.array([float(score(fit(train), validation)) for train, validation in splits])
