r"""The held-out significance test of `diagnose`: paired window differences, batch-means variance, Holm, run agreement.

Open-loop windows start every 0.05 s but run for the reference horizon, so neighbouring windows
share most of their data and their paired error differences are strongly correlated. Counting one
independent window per horizon length ignores correlation that lasts longer than a window (slow
changes in excitation); counting every window as independent would claim far too much. Here the
variance of the mean difference is estimated from the differences' own correlation: within each
run the windows are cut into non-overlapping batches of consecutive windows, each batch twice as
long as the correlation lasts (at least the number of windows that overlap, and at least the lag
at which the differences' sample autocorrelation falls below 0.1, up to twice the overlap or ten
windows, whichever is longer), and
the batch means, nearly
independent, are compared with Student's t. This is the non-overlapping-block (subseries)
estimator of the variance of a mean, a Bartlett-free HAC estimator; runs never share a batch.

Several candidates are tested in each round. `diagnose` controls the false-discovery rate among
them with the Benjamini-Hochberg step-up procedure: where no candidate has an effect it is the
family-wise error rate (so `none` stays `none` with probability `1 - alpha`), and where several
candidates do (friction at two joints) it does not make each pay for all the others, as Bonferroni
does. Holm's step-down procedure (family-wise control under any dependence) is here too. A cause
must also help on most held-out runs, not on one.

??? cite

    E. Carlstein, "The use of subseries values for estimating the variance of a general statistic
    from a stationary sequence", Annals of Statistics 14(3), 1986. W. K. Newey and K. D. West,
    "A simple, positive semi-definite, heteroskedasticity and autocorrelation consistent covariance
    matrix", Econometrica 55(3), 1987. Y. Benjamini and Y. Hochberg, "Controlling the false
    discovery rate: a practical and powerful approach to multiple testing", Journal of the Royal
    Statistical Society B 57(1), 1995; Y. Benjamini and D. Yekutieli, "The control of the false
    discovery rate in multiple testing under dependency", Annals of Statistics 29(4), 2001. S. Holm, "A simple sequentially rejective multiple test
    procedure", Scandinavian Journal of Statistics 6(2), 1979. F. X. Diebold and R. S. Mariano,
    "Comparing predictive accuracy", Journal of Business & Economic Statistics 13(3), 1995.
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
    per batch) and `per_run` (mean difference on each held-out run)."""

    def __init__(self, mean, std_error, df, p_value, batch, per_run):
        self.mean, self.std_error, self.df, self.p_value = mean, std_error, df, p_value
        self.batch, self.per_run = batch, per_run

    def __repr__(self):
        return (f"PairedTest(mean={self.mean:.4g}, std_error={self.std_error:.3g}, df={self.df}, "
                f"p_value={self.p_value:.3g}, batch={self.batch}, per_run={self.per_run})")


def paired_block_test(d, runs, overlap: int, batch: int | None = None) -> PairedTest:
    """One-sided test that the mean of the paired differences `d` is positive (see the module docs).

    **Arguments:** `d` the per-window differences, in start order within each run; `runs` the run
    index of each window; `overlap` how many consecutive windows share data (horizon over stride);
    `batch` windows per batch (default twice the longer of `overlap` and `decorrelation_lag`, the
    latter at most `MAX_LAG_OVER_OVERLAP` times `overlap` or `MIN_LAG_CAP` windows, whichever is
    longer: on a real record a large effect that
    varies slowly with the manoeuvre (a wind seen at changing headings) makes the differences
    correlated for seconds; counting that as noise would leave a handful of batches and no power).

    **Returns:** a `PairedTest`.
    """
    d, runs = np.asarray(d, float), np.asarray(runs)
    if d.shape != runs.shape or d.ndim != 1 or d.size == 0:
        raise ValueError(f"paired_block_test: `d` and `runs` must be equal-length 1-D arrays, got {d.shape} and {runs.shape}")
    if batch is None:
        overlap = max(int(overlap), 1)
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
        return PairedTest(mean, np.inf, 0, 1.0, batch, per_run)
    se = float(np.std(m, ddof=1) / np.sqrt(m.size))
    df = m.size - 1
    if se == 0.0:
        return PairedTest(mean, 0.0, df, 0.0 if mean > 0 else 1.0, batch, per_run)
    import scipy.stats  # lazily: keeps `import dynax` light

    return PairedTest(mean, se, df, float(scipy.stats.t.sf(float(np.mean(m)) / se, df)), batch, per_run)


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


def helps_on_most_runs(per_run: dict) -> bool:
    """A cause must help on most held-out runs: its mean improvement is positive on more than half of them."""
    values = np.asarray(list(per_run.values()), float)
    return bool(values.size and np.sum(values > 0) > values.size / 2)


def detectable_gain(std_error: float, df: float, alpha: float, power: float = 0.8) -> float:
    """The smallest held-out RMSE gain the test would detect with probability `power` at level `alpha`.

    `std_error` is that of the mean log ratio of mean squared window errors; a gain $g$ in RMSE is a
    log ratio of $-2\\log(1 - g)$.
    """
    if not np.isfinite(std_error) or std_error <= 0:
        return 0.0
    import scipy.stats

    shift = (scipy.stats.t.isf(alpha, df) + scipy.stats.t.ppf(power, df)) * std_error
    return float(1.0 - np.exp(-shift / 2.0))
