import numpy as np
import pytest

import dynax


def test_central_difference_exact_for_quadratics_on_irregular_grid():
    rng = np.random.default_rng(1)
    ts = np.cumsum(rng.uniform(0.001, 0.003, 200))
    ys = np.stack([3 * ts**2 - ts, np.ones_like(ts)], axis=1)
    d = dynax.central_difference(ts, ys)
    np.testing.assert_allclose(d[1:-1, 0], 6 * ts[1:-1] - 1, rtol=1e-9)
    np.testing.assert_allclose(d[:, 1], 0, atol=1e-12)


def test_savitzky_golay_differentiates_a_sine():
    ts = np.arange(0, 2, 0.001)
    ys = np.sin(3 * ts)[:, None]
    d = dynax.savitzky_golay(ts, ys, window=31, order=4, deriv=1)
    np.testing.assert_allclose(d[50:-50, 0], 3 * np.cos(3 * ts[50:-50]), atol=1e-6)
    dd = dynax.savitzky_golay(ts, ys, window=51, order=4, deriv=2)
    np.testing.assert_allclose(dd[60:-60, 0], -9 * np.sin(3 * ts[60:-60]), atol=1e-3)


def test_butterworth_is_zero_phase_and_removes_noise():
    ts = np.arange(0, 5, 0.001)
    clean = np.sin(2 * np.pi * 1.0 * ts)
    noisy = clean + 0.2 * np.sin(2 * np.pi * 150 * ts)
    out = dynax.butterworth_filtfilt(ts, noisy, cutoff_hz=20.0)
    # No phase lag: the filtered 1 Hz sine lies on the clean one away from the ends.
    np.testing.assert_allclose(out[500:-500], clean[500:-500], atol=2e-3)


def test_filters_refuse_irregular_grids_and_resample_fixes_it():
    rng = np.random.default_rng(2)
    ts = np.cumsum(rng.uniform(0.001, 0.004, 500))
    xs = np.stack([np.sin(ts), np.cos(ts)], axis=1)
    with pytest.raises(dynax.UsageError, match="irregular.*resample"):
        dynax.butterworth_filtfilt(ts, xs, cutoff_hz=10.0)
    tr = dynax.Trajectory(ts, xs, np.arange(500.0)[:, None], ("q", "dq"), ("force",))
    r = dynax.resample(tr, 0.002)
    assert r.is_uniform
    np.testing.assert_allclose(r.xs[:, 0], np.sin(r.ts), atol=1e-5)
    # Inputs are a zero-order hold: each new sample takes the value in force at its time.
    held = np.searchsorted(ts, np.asarray(r.ts), side="right") - 1
    np.testing.assert_array_equal(r.us[:, 0], held)


def test_bad_filter_arguments():
    ts = np.arange(0, 1, 0.01)
    with pytest.raises(dynax.UsageError, match="cutoff_hz"):
        dynax.butterworth_filtfilt(ts, np.sin(ts), cutoff_hz=80.0)
    with pytest.raises(dynax.UsageError, match="window"):
        dynax.savitzky_golay(ts, np.sin(ts), window=10)
