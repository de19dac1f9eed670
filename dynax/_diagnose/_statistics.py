r"""The held-out significance test of `diagnose`: paired window differences, a HAC variance, Benjamini-Hochberg, run
agreement.

Open-loop windows start every 0.05 s but run for the reference horizon, so neighbouring windows
share most of their data and their paired error differences $d_t$ are strongly autocorrelated.
Counting every window as independent would claim far too much. The test divides the mean
difference by a heteroskedasticity-and-autocorrelation-consistent (HAC) standard error, the
long-run variance of $d_t$ over the number of windows, estimated within each held-out run (runs
never share a lag product; each run is centred on its own mean and the runs' estimates pooled).

**The default (`method="flat_top"`): a flat-top lag window over the correlation length.** With
$M$ the correlation length in windows (the longer of the number of windows that overlap, where
correlation is certain, and the lag at which the differences' sample autocorrelation falls below
0.1, the latter capped: see `correlation_length`),

$$\hat\sigma^2 = \frac{\sum_{|k| \le 2M} w(k/M)\,\hat\gamma_k}{1 - \sum_{|k| \le 2M} w(k/M)/n},
\qquad w(x) = \min(1, \max(0, 2 - |x|)),
\qquad \hat\gamma_k = \frac{1}{n-k}\sum_t (d_t-\bar d)(d_{t+k}-\bar d),$$

the flat-top (trapezoid) lag window of Politis and Romano (1995): full weight up to lag $M$, so no
smoothing bias for correlation shorter than $M$ (the Bartlett weights of Newey and West 1987, and
batch means, down-weight exactly the correlation that overlapping windows certainly have), and a
taper to $2M$ that still counts part of a longer correlation. The divisor removes the part of the
long-run variance that centring on the run's own mean takes away (about $3M/n$ of it, large on a
6 s record). The statistic is referred to Student's t with the equivalent degrees of freedom of
the estimator, $3n/(8M) - 1$ per run, summed over runs ($8/3$ is $\int w^2$; Sun 2014).

The flat-top window is not positive semi-definite: a run whose differences swing with the
manoeuvre over two to three correlation lengths has negative autocovariances at the fully weighted
lags, and its estimate can be zero or negative, typically when a candidate helps a lot but by an
amount that varies (in the acrobot demo, the true cause, 98.6 % better, got no variance and
p = 1 and lost to a look-alike). Such a run's sum is then taken over the autocovariances' absolute
values, $\hat\gamma_0 + 2\sum_k w(k/M)\lvert\hat\gamma_k\rvert$, an upper bound of the same window's
sum (the positive part Politis 2011 discusses is zero here, and a positive semi-definite kernel
such as Bartlett's would be small exactly where the estimate is least reliable). This only ever
adds variance: on no-effect data it claims no more than before (see Calibration).

**Calibration.** `experiments/test_calibration.py` measures the false-claim rate on no-effect
data (overlapping-window averages of white, AR(1) and ARMA(1,1) noise and of AR(1) noise with
Student-t(3) innovations, at the record lengths of the tests, the helicopter flights and the DFKI
runs; 600 records each) for each estimator here. At a nominal 1 %, over the 35 configurations whose
noise has a correlation time up to 10 strides (0.5 s), the flat-top window claims an effect in
0.87 % of no-effect records on average and in at most 1.7 % in any one configuration (within two
binomial standard errors of 1 %; 0.92 % before the bound for non-positive estimates above); the
truncated window $\sum_{|k|\le M}\hat\gamma_k$ (Hansen 1982; White and Domowitz 1984) with the same
centring correction has 15 % more power but 1.1 % on average
and up to 3.2 %; overlapping batch means (`"obm"`; Meketon and Schmeiser 1984, t with $1.5(n/b-1)$
degrees of freedom, batch twice the correlation length, what a Bartlett HAC with Andrews' (1991)
bandwidth amounts to) 2.8 % on average and up to 5 %; the earlier non-overlapping batch means
(`"nbm"`, Carlstein 1986) 2.1 % and up to 4.2 %. The default is the most powerful of them that stays
at the level. With slower noise (correlation time 33 strides, 1.7 s, on records of 5-20 s) no
estimator here is calibrated (flat-top up to 8.7 %): the cap on the correlation length reads such
slow correlation as an effect that varies with the manoeuvre. Block resampling (the moving-block
bootstrap of Kunsch 1989, the stationary bootstrap of Politis and Romano 1994) is not used: one or
two held-out runs of a few hundred windows make only a handful of blocks of the needed length, too
few for its quantiles at the levels used here.

Several candidates are tested in each round. `diagnose` controls the false-discovery rate among
them with the Benjamini-Hochberg step-up procedure over every candidate still in the search (those
not refitted count with p = 1: the shortlist is chosen with the held-out residuals, so it may not
be the family): where no candidate has an effect it is the family-wise error rate (so `none` stays
`none` with probability `1 - alpha`), and where several candidates do (friction at two joints) it
does not make each pay for all the others, as Bonferroni does; for the best candidate alone it is
the Bonferroni threshold `alpha / m`. Holm's step-down procedure (family-wise control under any
dependence) is here too. A cause must also help on most held-out runs, not on one.

??? cite

    L. P. Hansen, "Large sample properties of generalized method of moments estimators",
    Econometrica 50(4), 1982; H. White and I. Domowitz, "Nonlinear regression with dependent
    observations", Econometrica 52(1), 1984 (the truncated lag window). D. N. Politis and J. P.
    Romano, "Bias-corrected nonparametric spectral estimation", Journal of Time Series Analysis
    16(1), 1995 (flat-top windows). M. S. Meketon and B. Schmeiser, "Overlapping batch means: something for nothing?",
    Proceedings of the Winter Simulation Conference, 1984. W. K. Newey and K. D. West, "A simple,
    positive semi-definite, heteroskedasticity and autocorrelation consistent covariance matrix",
    Econometrica 55(3), 1987. D. W. K. Andrews, "Heteroskedasticity and autocorrelation consistent
    covariance matrix estimation", Econometrica 59(3), 1991. N. M. Kiefer and T. J. Vogelsang,
    "A new asymptotic theory for heteroskedasticity-autocorrelation robust tests", Econometric
    Theory 21(6), 2005. Y. Sun, "Let's fix it: fixed-b asymptotics versus small-b asymptotics in
    heteroskedasticity and autocorrelation robust inference", Journal of Econometrics 178(3), 2014.
    E. Carlstein, "The use of subseries values for estimating the variance of a general statistic
    from a stationary sequence", Annals of Statistics 14(3), 1986 (non-overlapping batches, the
    previous estimator; `paired_block_test(..., method="nbm")`). H. R. Kunsch, "The jackknife and
    the bootstrap for general stationary observations", Annals of Statistics 17(3), 1989; D. N.
    Politis and J. P. Romano, "The stationary bootstrap", Journal of the American Statistical
    Association 89(428), 1994 (block resampling; with one or two held-out runs of a few hundred
    strongly overlapping windows it has too few blocks to beat the t approximation here).
    D. N. Politis, "Higher-order accurate, positive semidefinite estimation of large-sample
    covariance and spectral density matrices", Econometric Theory 27(4), 2011 (flat-top estimates
    that are not positive). Y. Benjamini and Y. Hochberg, "Controlling the false discovery rate: a practical and
    powerful approach to multiple testing", Journal of the Royal Statistical Society B 57(1), 1995;
    Y. Benjamini and D. Yekutieli, "The control of the false discovery rate in multiple testing
    under dependency", Annals of Statistics 29(4), 2001. S. Holm, "A simple sequentially
    rejective multiple test procedure", Scandinavian Journal of Statistics 6(2), 1979.
    F. X. Diebold and R. S. Mariano, "Comparing predictive accuracy", Journal of Business &
    Economic Statistics 13(3), 1995.
"""

import numpy as np

MAX_LAG_OVER_OVERLAP = 2  # correlation longer than this many horizons (and MIN_LAG_CAP windows) is read
MIN_LAG_CAP = 10  # as an effect that varies with the manoeuvre, not as noise


def log_ratio_differences(score_ref, score_new) -> np.ndarray:
    """Per-window improvement `log((score_ref + floor) / (score_new + floor))` (positive: the new model is better).

    Improvements are multiplicative, so the test is on log ratios; a floor of a tenth of the typical
    window error keeps windows where both models are at the noise floor (a machine at rest) from
    counting as large changes either way.
    """
    score_ref, score_new = np.asarray(score_ref, float), np.asarray(score_new, float)
    floor = 0.1 * float(np.median(score_ref)) + 1e-300
    return np.log((score_ref + floor) / (score_new + floor))


def typical_gain(score_ref, score_new, rms: bool = False) -> float:
    """The gain of the typical window: one minus the geometric mean of the windows' error ratios, floored as the
    test's (`1 - exp(-mean(log_ratio_differences))`), the practical size the paired test's mean estimates.

    Scale-free: every window counts alike, as in the test, where the pooled `1 - mean(new) / mean(ref)` weighs
    windows by their error (one run with ten times the others' error carries the pooled gain alone). A gain in
    mean squared window error, like the pooled one; `rms=True` gives the same in root mean square
    (`1 - exp(-mean / 2)`). The floor makes it read a little less than the pooled gain of a uniform effect (a
    window at the median error reads a ratio $r$ as $(r + 0.1) / 1.1$): it never overstates a gain.
    """
    d = float(np.mean(log_ratio_differences(score_ref, score_new)))
    return float(1.0 - np.exp(-d / (2.0 if rms else 1.0)))


def decorrelation_lag(d, runs, threshold: float = 0.1) -> int:
    """The first lag (in windows) at which the within-run sample autocorrelation of `d` falls below `threshold`."""
    d, runs = np.asarray(d, float), np.asarray(runs)
    sizes = [int(np.sum(runs == r)) for r in np.unique(runs)]
    max_lag = max(1, min(sizes) // 4)
    num, den = np.zeros(max_lag + 1), 0.0
    for r in np.unique(runs):
        x = d[runs == r] - np.mean(d[runs == r])
        den += float(x @ x)
        for k in range(min(max_lag, x.size - 1) + 1):
            num[k] += float(x[k:] @ x[: x.size - k])
    if den == 0.0:
        return 1
    below = np.flatnonzero(num / den < threshold)
    return int(below[0]) if below.size else max_lag


class PairedTest:
    """The result of `paired_block_test`: `mean`, `std_error`, `df`, `p_value` (one-sided), `batch` (windows
    per batch), `method`, `per_run` (mean difference on each held-out run) and `df_offset`, the degrees of
    freedom the test loses whatever the length: each run's own mean costs one batch (OBM: 1.5 per run used;
    the lag-window tests: 1 per run used; NBM: 1 in all), so lengthening every run `r` times gives
    `r (df + df_offset) - df_offset` degrees of freedom, not `r df` (`length_for_shift`)."""

    def __init__(self, mean, std_error, df, p_value, batch, per_run, method="obm", df_offset=0.0):
        self.mean, self.std_error, self.df, self.p_value = mean, std_error, df, p_value
        self.batch, self.per_run, self.method, self.df_offset = batch, per_run, method, df_offset

    def __repr__(self):
        return (
            f"PairedTest(mean={self.mean:.4g}, std_error={self.std_error:.3g}, df={self.df:.3g}, "
            f"p_value={self.p_value:.3g}, batch={self.batch}, method={self.method!r}, per_run={self.per_run})"
        )


BATCH_OVER_CORRELATION = 2.0  # OBM/NBM batch over the correlation length


def correlation_length(d, runs, overlap: int) -> int:
    """How many windows the differences stay correlated: the longer of `overlap` and `decorrelation_lag`.

    `overlap` consecutive windows share data, so correlation that long is certain; slowly changing
    excitation makes it longer, which `decorrelation_lag` (where the within-run sample
    autocorrelation falls below 0.1) sees. That lag is capped at `MAX_LAG_OVER_OVERLAP` times `overlap`
    or `MIN_LAG_CAP` windows, whichever is longer: correlation longer than that is read as an effect
    that varies with the manoeuvre, not as noise (counting it as noise would leave no power).
    """
    d, runs = np.asarray(d, float), np.asarray(runs)
    overlap = max(int(overlap), 1)
    longest = max(MAX_LAG_OVER_OVERLAP * overlap, MIN_LAG_CAP)
    return max(1, min(max(overlap, decorrelation_lag(d, runs)), longest))


def obm_batch(d, runs, overlap: int) -> int:
    """The batch length of the OBM test: `BATCH_OVER_CORRELATION` times `correlation_length`, at most a third of the
    shortest run."""
    shortest = min(int(np.sum(np.asarray(runs) == r)) for r in np.unique(runs))
    return max(1, min(int(np.ceil(BATCH_OVER_CORRELATION * correlation_length(d, runs, overlap))), shortest // 3))


def _obm(x, b):
    """Overlapping-batch-means estimate of the long-run variance of `x` (Meketon and Schmeiser 1984)."""
    n = x.size
    c = np.concatenate([[0.0], np.cumsum(x)])
    batch_means = (c[b:] - c[:-b]) / b
    return n * b / ((n - b + 1) * (n - b)) * float(np.sum((batch_means - np.mean(x)) ** 2))


DEFAULT_METHOD = "flat_top"  # the most powerful calibrated one (experiments/test_calibration.py)


def paired_block_test(d, runs, overlap: int, batch: int | None = None, method: str | None = None) -> PairedTest:
    """One-sided test that the mean of the paired differences `d` is positive (see the module docs).

    **Arguments:** `d` the per-window differences, in start order within each run; `runs` the run
    index of each window; `overlap` how many consecutive windows share data (horizon over stride);
    `batch` the lag window `M` (`"flat_top"`, `"truncated"`) or batch length (`"obm"`, `"nbm"`),
    by default from the data (`correlation_length`, `obm_batch`); `method` `"flat_top"` (the default,
    `DEFAULT_METHOD`), `"truncated"`, `"obm"` (overlapping batch means, t with 1.5 (n/b - 1) degrees
    of freedom per run) or `"nbm"` (the earlier non-overlapping batch means). The last three are
    kept for `experiments/test_calibration.py`, which compares their false-claim rates.

    **Returns:** a `PairedTest`.
    """
    d, runs = np.asarray(d, float), np.asarray(runs)
    if d.shape != runs.shape or d.ndim != 1 or d.size == 0:
        raise ValueError(
            f"paired_block_test: `d` and `runs` must be equal-length 1-D arrays, got {d.shape} and {runs.shape}"
        )
    method = DEFAULT_METHOD if method is None else method
    if method not in ("obm", "nbm", "truncated", "flat_top"):
        raise ValueError(f"paired_block_test: `method` must be 'obm', 'nbm', 'truncated' or 'flat_top', got {method!r}")
    overlap = max(int(overlap), 1)
    if method == "nbm":
        return _nbm_test(d, runs, overlap, batch)
    if method in ("truncated", "flat_top"):
        return _kernel_test(d, runs, overlap, batch, method)
    labels = np.unique(runs)
    sizes = np.asarray([int(np.sum(runs == r)) for r in labels])
    if batch is None:
        batch = obm_batch(d, runs, overlap)
    batch = max(int(batch), 1)
    mean = float(np.mean(d))
    per_run, weighted, df, offset = {}, 0.0, 0.0, 0.0
    for r, n in zip(labels, sizes):
        dr = d[runs == r]
        per_run[int(r)] = float(np.mean(dr))
        if n >= 2 * batch and n > batch + 1:  # too short a run says nothing about the variance
            weighted += n * _obm(dr, batch)
            df += 1.5 * (n / batch - 1)
            offset += 1.5
    if df <= 0 or weighted < 0:
        return PairedTest(mean, np.inf, 0.0, 1.0, batch, per_run)
    used = sum(n for n in sizes if n >= 2 * batch and n > batch + 1)
    long_run_var = weighted / used
    se = float(np.sqrt(long_run_var / d.size))
    if se == 0.0:
        return PairedTest(mean, 0.0, df, 0.0 if mean > 0 else 1.0, batch, per_run, df_offset=offset)
    import scipy.stats  # lazily: keeps `import dynax` light

    return PairedTest(mean, se, df, float(scipy.stats.t.sf(mean / se, df)), batch, per_run, df_offset=offset)


def _kernel_test(d, runs, overlap, lags, method):
    """HAC t test with the truncated (rectangular) or flat-top (trapezoid) lag window over the correlation length."""
    import scipy.stats

    labels = np.unique(runs)
    M = max(int(correlation_length(d, runs, overlap) if lags is None else lags), 1)
    extent = M if method == "truncated" else 2 * M
    c2 = 2.0 if method == "truncated" else 8.0 / 3.0  # integral of the squared lag window, in units of M
    mean = float(np.mean(d))
    per_run, total, used, df, offset = {}, 0.0, 0, 0.0, 0.0
    for r in labels:
        dr = d[runs == r]
        per_run[int(r)] = float(np.mean(dr))
        n = dr.size
        if n <= 2 * extent:
            continue
        x = dr - np.mean(dr)
        g = np.array([x[k:] @ x[: n - k] / (n - k) for k in range(extent + 1)])
        k = np.arange(extent + 1)
        w = np.ones(extent + 1) if method == "truncated" else np.clip(2.0 - k / M, 0.0, 1.0)
        width = 1.0 + 2.0 * float(np.sum(w[1:]))
        # Centring on the run's own mean removes about width / n of the long-run variance from the sum.
        lrv = (g[0] + 2.0 * float(np.sum(w[1:] * g[1:]))) / (1.0 - width / n)
        if lrv <= 0.0:  # neither lag window is positive semi-definite: bound the sum by |autocovariances|
            lrv = (g[0] + 2.0 * float(np.sum(w[1:] * np.abs(g[1:])))) / (1.0 - width / n)
        total += n * lrv
        used += n
        df += n / (c2 * M) - 1.0
        offset += 1.0
    if used == 0 or df <= 0 or total <= 0:
        return PairedTest(mean, np.inf, 0.0, 1.0, M, per_run, method)
    se = float(np.sqrt(total / used / d.size))
    return PairedTest(mean, se, df, float(scipy.stats.t.sf(mean / se, df)), M, per_run, method, offset)


def _nbm_test(d, runs, overlap, batch):
    """The earlier test: non-overlapping batch means (Carlstein 1986), batch twice the correlation length."""
    if batch is None:
        longest = max(MAX_LAG_OVER_OVERLAP * overlap, MIN_LAG_CAP)
        batch = 2 * min(max(overlap, decorrelation_lag(d, runs)), longest)
    means, per_run = [], {}
    for r in np.unique(runs):
        dr = d[runs == r]
        per_run[int(r)] = float(np.mean(dr))
        means += [float(np.mean(x)) for x in np.array_split(dr, max(1, dr.size // batch))]
    m = np.asarray(means)
    mean = float(np.mean(d))
    if m.size < 2:
        return PairedTest(mean, np.inf, 0, 1.0, batch, per_run, "nbm")
    se = float(np.std(m, ddof=1) / np.sqrt(m.size))
    df = m.size - 1
    if se == 0.0:
        return PairedTest(mean, 0.0, df, 0.0 if mean > 0 else 1.0, batch, per_run, "nbm", 1.0)
    import scipy.stats

    t = float(np.mean(m)) / se
    return PairedTest(mean, se, df, float(scipy.stats.t.sf(t, df)), batch, per_run, "nbm", 1.0)


def benjamini_hochberg(p_values, alpha: float) -> np.ndarray:
    """Benjamini-Hochberg step-up procedure: which of `p_values` are rejected at false-discovery rate `alpha`.

    When no candidate has an effect this is the family-wise error rate: `none` stays `none` with
    probability at least `1 - alpha`. Valid for independent or positively dependent tests (the
    candidates' tests share the reference model's windows, which makes them positively dependent).
    """
    p = np.asarray(p_values, float)
    m = p.size
    order = np.argsort(p)
    passed = np.flatnonzero(p[order] <= alpha * np.arange(1, m + 1) / m)
    rejected = np.zeros(m, bool)
    if passed.size:
        rejected[order[: passed[-1] + 1]] = True
    return rejected


def holm(p_values, alpha: float) -> np.ndarray:
    """Holm's step-down procedure: which of `p_values` are rejected at family-wise level `alpha`."""
    p = np.asarray(p_values, float)
    m = p.size
    rejected = np.zeros(m, bool)
    for rank, i in enumerate(np.argsort(p)):
        if p[i] <= alpha / (m - rank):
            rejected[i] = True
        else:
            break
    return rejected


def holm_adjusted(p_values) -> np.ndarray:
    """Holm's adjusted p-values: `holm(p, alpha)` rejects exactly those at or below `alpha`."""
    p = np.asarray(p_values, float)
    m = p.size
    order = np.argsort(p)
    adjusted = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adjusted[i] = running
    return adjusted


def helps_on_most_runs(per_run: dict) -> bool:
    """A cause must help on most held-out runs: its mean improvement is positive on more than half of them."""
    values = np.asarray(list(per_run.values()), float)
    return bool(values.size and np.sum(values > 0) > values.size / 2)


def detectable_gain(std_error: float, df: float, alpha: float, power: float = 0.8) -> float:
    r"""The smallest typical gain the test would detect with probability `power` at level `alpha`.

    `std_error` is that of the mean log ratio $\bar d$ of mean squared window errors; a gain $g$ is a shift of
    $-\log(1 - g)$ in it, so the shift `detectable_shift` finds is the gain $1 - e^{-\text{shift}}$ in mean squared
    window error: the unit of `typical_gain` and of the candidates' gains the rules read and the report gives.
    """
    if not np.isfinite(std_error) or std_error <= 0:
        return 0.0
    return float(-np.expm1(-detectable_shift(std_error, df, alpha, power)))


def detectable_shift(std_error: float, df: float, alpha: float, power: float = 0.8) -> float:
    r"""The mean log ratio the one-sided paired t-test (level `alpha`, `df` degrees of freedom, standard error
    `std_error`) detects with probability `power`: the noncentrality $\delta$ at which the noncentral t exceeds
    $t_{1-\alpha,\nu}$ with that probability, times $s$ (Cohen 1988, ch. 2). The usual shortcut
    $(t_{1-\alpha,\nu} + t_{\text{power},\nu})\,s$ understates it where $\nu$ is small and $\alpha$ too: by 7 % at
    $\nu = 5$, $\alpha = 0.001$ (power 73 %, not 80 %), 1 % at $\nu = 20$ and the same level."""
    import warnings

    import scipy.optimize
    import scipy.stats

    t = float(scipy.stats.t.isf(alpha, df))
    hi = 2.0 * (t + float(scipy.stats.t.ppf(power, df))) + 1.0

    def short(delta: float) -> float:
        with warnings.catch_warnings():  # the series converges slowly at one degree of freedom; the root is found
            warnings.simplefilter("ignore", RuntimeWarning)
            return float(scipy.stats.nct.sf(t, df, delta)) - power

    while short(hi) < 0.0:
        hi *= 2.0
    root = scipy.optimize.root_scalar(short, bracket=(0.0, hi), method="brentq", xtol=1e-12)
    return float(root.root) * std_error


def length_for_shift(
    shift: float, std_error: float, df: float, df_offset: float, alpha: float, power: float = 0.8
) -> float:
    r"""How many times longer every held-out run must be for the test to detect a mean log ratio `shift` with
    probability `power` (`detectable_shift`), with the window-to-window variation seen.

    Lengthening every run $r$ times divides the standard error by $\sqrt r$ and gives
    $\nu(r) = r(\nu + c) - c$ degrees of freedom, where $c$ is `df_offset` (`PairedTest`). Holding $\nu$ fixed,
    $r = (\delta_\nu s / \text{shift})^2$ overstates the length where $\nu$ is small: the noncentrality $\delta$
    falls as the degrees of freedom grow, so the detectable shift falls faster than $1/\sqrt r$, and at the length
    read with $\nu$ fixed the test detects the shift with far more than `power` (96 % rather than 80 % on three
    runs of 40 windows at level 0.005, 1.5 times the length needed; `experiments/power_length.py`). The factor
    solves $\delta_{\nu(r)}\, s / \sqrt r = \text{shift}$ for $r$, no shorter than leaves one degree of freedom.
    """
    import scipy.optimize

    if not np.isfinite(shift):
        return float("nan")  # no length detects an undefined shift
    if not (np.isfinite(std_error) and std_error > 0 and shift > 0 and df > 0):
        return np.inf if shift > 0 else 0.0
    offset = max(float(df_offset), 0.0)
    lowest = (1.0 + offset) / (df + offset)  # one degree of freedom left

    def excess(log_r: float) -> float:
        r = float(np.exp(log_r))
        return detectable_shift(std_error / np.sqrt(r), r * (df + offset) - offset, alpha, power) - shift

    lo = float(np.log(min(lowest, 1.0)))
    if excess(lo) <= 0.0:
        return float(np.exp(lo))
    hi = max(0.0, 2.0 * float(np.log(detectable_shift(std_error, df, alpha, power) / shift)))
    while excess(hi) > 0.0:
        hi += 1.0
    root = scipy.optimize.root_scalar(excess, bracket=(lo, hi), method="brentq", xtol=1e-10)
    return float(np.exp(root.root))
