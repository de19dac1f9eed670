r"""The validation block of a diagnosis report: NRMSE fit % and residual tests, per model, on held-out runs.

What system-identification users read first (MATLAB's `compare` and `resid`, Ljung 1999, 16.6):

- **fit %** of the open-loop prediction at the reference horizon, from every held-out window
  (`dynax.nrmse_fit` on the predicted against the measured states $H$ seconds after each start,
  as `compare(data, sys, k)` with $k = H / dt$);
- **whiteness** of the one-step acceleration residuals (`dynax.whiteness_test`: Ljung-Box over
  lags $1..M$), and their **cross-correlation with the inputs** (`dynax.cross_correlation_test`).

The one-step residuals are the structure probe's (`acceleration_residuals`): measured minus model
acceleration, both through the same Savitzky-Golay filter of $w$ samples. That filter alone makes
neighbouring residuals correlated, for a perfect model too; the tests therefore read every $w$-th
residual, so the lags are $w\,dt$ apart (`lag_s` in the report) and a correct model's residuals,
measurement noise through the filter, are close to white at that spacing.

These are reported, not used for the verdict (the held-out paired test and the probe decide).

??? cite

    L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, section 16.6.
    G. M. Ljung and G. E. P. Box, "On a measure of lack of fit in time series models",
    Biometrika 65(2), 1978.
"""

import numpy as np

from .._validate import cross_correlation_test, nrmse_fit, whiteness_test
from ._residuals import acceleration_residuals, sg_window
from ._result import ResidualTests, Validation


def fit_percent(errors, measured, state_names) -> dict[str, float | None]:
    """NRMSE fit % per state of predictions `measured + errors` (both `(window, state)`); `None` where not finite."""
    errors, measured = np.asarray(errors), np.asarray(measured)
    out = {}
    for i, name in enumerate(state_names):
        predicted = measured[:, i] + errors[:, i]
        ok = np.all(np.isfinite(predicted)) and np.ptp(measured[:, i]) > 0
        out[name] = float(nrmse_fit(measured[:, i], predicted)[0]) if ok else None
    return out


def residual_tests(
    model, record, *, max_lag: int = 25, confidence: float = 0.99, length: int = 0
) -> ResidualTests | None:
    """Whiteness and input cross-correlation tests of `model`'s one-step residuals on one held-out `record`.

    The residuals are read every `w` samples (`w` the filter window; see the module docs); `max_lag`
    is lowered to a quarter of what is left. `None` if fewer than 20 residuals are left (or one is not finite).
    `length`: the samples the per-sample functions run on at least (`acceleration_residuals`).
    """
    residuals, _, _, keep = acceleration_residuals(model, record, length=length)
    stride = sg_window(record.dt)
    r = np.asarray(residuals)[::stride]
    us = np.asarray(record.us)[keep][::stride]
    n = r.shape[0]
    if n < 20 or not np.all(np.isfinite(r)):
        return None
    lag = int(min(max_lag, n // 4))
    white = whiteness_test(r, max_lag=lag, confidence=confidence)
    cross = cross_correlation_test(r, us, max_lag=lag, confidence=confidence)
    channels = tuple(model.state_names[i] for i in model.velocity_indices)
    return ResidualTests(
        run=record.source or "held-out run",
        channels=channels,
        inputs=tuple(record.input_names),
        lag_s=round(float(stride * record.dt), 9),
        max_lag=lag,
        confidence=confidence,
        whiteness_p=tuple(float(p) for p in white.p_value),
        white=tuple(bool(w) for w in white.white),
        peak_autocorrelation=tuple(float(np.max(np.abs(a))) for a in white.autocorrelation),
        autocorrelation_bound=float(white.bound),
        cross_correlation_p=tuple(tuple(float(p) for p in row) for row in cross.p_value),
        independent=tuple(tuple(bool(i) for i in row) for row in cross.independent),
        peak_cross_correlation=tuple(tuple(float(np.max(np.abs(c))) for c in row) for row in cross.cross_correlation),
        cross_correlation_bound=tuple(tuple(float(b) for b in row) for row in cross.bound),
    )


def validation_summary(
    model, records, errors_at_horizon, measured_at_horizon, horizon_s: float, *, length: int = 0
) -> Validation:
    """The `validation` block of one model: fit % at the reference horizon over every held-out window and
    the residual tests on each held-out run.

    **Arguments:** `model`; `records` the held-out runs; `errors_at_horizon (window, state)` the
    model's simulated-minus-measured states `horizon_s` after each window's start, and
    `measured_at_horizon` the measured states there; `length` the samples the residuals' per-sample functions run
    on at least (a diagnosis passes its records' `shared_length`, so that they reuse the screening's compilations).
    """
    names = tuple(records[0].state_names)
    tests = tuple(t for t in (residual_tests(model, rec, length=length) for rec in records) if t is not None)
    return Validation(float(horizon_s), fit_percent(errors_at_horizon, measured_at_horizon, names), tests)
