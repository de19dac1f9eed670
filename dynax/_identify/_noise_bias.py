r"""Velocity noise the spectra read as negligible, checked against the fit it would bias.

`choose_filter` leaves a record's velocities unfiltered when their noise, differenced into accelerations, is under
1 % of the accelerations' rms. That bounds the errors-in-variables bias relative to the accelerations, not to the
forces the parameters are read from: on an arm that swings mostly under gravity, where a small torque balances large
accelerations, white noise of 1e-4 rad/s on the velocities of a 1 kHz record (0.6 % of the accelerations' rms once
differenced) leaves every inertia and gravity parameter of the dynamic model 3 % low, with standard errors a
hundred times smaller than that.

The check is simulation-extrapolation (SIMEX): the bias of least squares grows with the variance of the noise in the
regressor, so the shift of the estimate when the same noise is added once more (variance doubled) estimates the
bias the recorded noise already causes. The least-squares stage is fitted unfiltered on the records the spectra
left unfiltered, as recorded and with their velocities' noise (the floor `choose_filter` read) added again; where a
parameter moves by more than 3 of its standard errors and by more than 0.5 %, those records are filtered at their
signal band as noisy records are. Only the least-squares stage is filtered: the output-error refinement follows the
records' own spectra, and noise this small needs none (on a 10-minute 1 kHz record it costs 8 minutes for nothing).

??? cite

    J. R. Cook and L. A. Stefanski, "Simulation-extrapolation estimation in parametric measurement error models",
    Journal of the American Statistical Association 89(428), 1994.
"""

import dataclasses
import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._data._spectra import band_filter, choose_filter, differenced_noise_ratios, FILTER_RULE
from .._errors import DataError, UsageError
from ._equations import Dynamic, uniformly_sampled
from ._ls_stage import least_squares_stage

MOVED_STD = 3.0  # a shift of more than this many standard errors of the estimate ...
MOVED_SHARE = 0.005  # ... and more than this share of the parameter's value: the noise biases the fit
PROBED_RATIO = 1e-3  # records whose differenced noise is under this share of the accelerations' rms are not probed
SEED = 20250101  # the added noise's draw (fixed: the same records give the same decision)


def noise_bias_rule(system, records, method, friction, weights, rcond):
    """A `filter_rule` that filters at their signal band the records whose velocity noise, read as negligible,
    biases `method`'s least-squares estimate (see the module notes), or `None` where none does (or the check does
    not apply: a method other than `Dynamic` with its cut-off chosen from the data, row `weights` given, or a rule
    already in force).
    """
    if not isinstance(method, Dynamic) or not (isinstance(method.lowpass_hz, str) and method.lowpass_hz == "auto"):
        return None
    if FILTER_RULE.get() is not None or weights is not None:  # a rule in force; row weights fit one set of rows
        return None
    choices = [choose_filter(uniformly_sampled(r)) for r in records]
    probed = [
        i
        for i, (r, c) in enumerate(zip(records, choices))
        if band_filter(r, c) is not c
        and max(differenced_noise_ratios(r, c.noise_std, c.sample_rate_hz).values()) > PROBED_RATIO
    ]
    if not probed:
        return None
    unfiltered = dataclasses.replace(method, lowpass_hz=None)
    plain_records = [records[i] for i in probed]
    noisier = [_with_noise_again(records[i], choices[i], k) for k, i in enumerate(probed)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            plain = least_squares_stage(system, plain_records, unfiltered, friction, None, rcond, "off")
            again = least_squares_stage(system, noisier, unfiltered, friction, None, rcond, "off")
        except (DataError, UsageError):  # too few rows, unidentifiable: the fit itself says so
            return None
    value, std = np.asarray(plain.estimate, float), np.asarray(plain.fit.std_errors, float)
    shift = np.asarray(again.estimate, float) - value
    share = np.abs(shift) / np.maximum(np.abs(value), np.finfo(float).tiny)
    moved = (np.abs(shift) > MOVED_STD * std) & (share > MOVED_SHARE)
    if not moved.any():
        return None
    k = int(np.argmax(np.where(moved, share, 0.0)))
    why = (
        "velocity noise under 1 % of the accelerations' rms once differenced, yet with that noise added once more "
        f"the unfiltered least-squares estimate moves {plain.names[k]} by {shift[k] / value[k]:+.1%} "
        f"({abs(shift[k]) / std[k]:.0f} standard errors; errors in variables, SIMEX): "
    )

    def rule(trajectory, choice, *, snr):
        return band_filter(trajectory, choice, snr=snr, why=why)

    return rule


def _with_noise_again(record, choice, k: int):
    """`record` with white noise of each velocity's floor (`choice.noise_std`) added to it once more."""
    n = len(record.state_names) // 2
    rng = np.random.default_rng(SEED + k)
    xs = np.array(record.xs, dtype=float)
    for j, name in enumerate(record.state_names[n:]):
        xs[:, n + j] += choice.noise_std.get(name, 0.0) * rng.standard_normal(len(xs))
    return eqx.tree_at(lambda r: r.xs, record, jnp.asarray(xs, dtype=jnp.asarray(record.xs).dtype))
