"""A logged velocity that lags its angle (a driver's causal filter, a backward difference, a velocity stamped
late) is read by `velocity_lag` and named by the `lag` data check with its column, its lag in milliseconds, the
stretch it holds in and the fix (`--velocities positions`); clean records, noisy or jittered, raise nothing.

The records are sums of sines written out here, with their exact derivatives: nothing of dynax's model."""

import warnings

from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

import dynax
from dynax.internal import velocity_lag


def _motion(seed, rate_hz=100.0, seconds=8.0, jitter=0.0):
    """`(ts, q, dq)`: two joints as sums of four sines each (0.2 to 2 Hz), on a grid jittered by `jitter` of a
    step, with the exact derivatives."""
    rng = np.random.default_rng(seed)
    steps = (1.0 + jitter * rng.uniform(-1, 1, int(seconds * rate_hz))) / rate_hz
    ts = np.concatenate([[0.0], np.cumsum(steps)])
    f, p, a = rng.uniform(0.2, 2.0, (2, 4)), rng.uniform(0, 2 * np.pi, (2, 4)), rng.uniform(0.2, 0.8, (2, 4))
    w = 2 * np.pi * f
    q = np.stack([np.sum(a[k][:, None] * np.sin(w[k][:, None] * ts + p[k][:, None]), 0) for k in (0, 1)], 1)
    dq = np.stack([np.sum((a[k] * w[k])[:, None] * np.cos(w[k][:, None] * ts + p[k][:, None]), 0) for k in (0, 1)], 1)
    return ts, q, dq


def _record(ts, q, dq, source="run.csv"):
    tau = np.sin(1.3 * ts)[:, None]
    return dynax.Trajectory(ts, np.column_stack([q, dq]), tau, ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot", source)


def _lags(check):
    return [f for f in check.findings if f.kind == "lag"]


def test_the_lag_of_a_shift_a_backward_difference_and_a_filter_is_read():
    ts, q, dq = _motion(0, rate_hz=200.0)
    dt = 1 / 200
    late = np.concatenate([dq[:2], dq[:-2]])  # two samples late: 10 ms
    assert velocity_lag(ts, q[:, 0], late[:, 0]).lag == pytest.approx(0.010, rel=0.03)
    backward = np.concatenate([[dq[0]], np.diff(q, axis=0) / dt])
    assert velocity_lag(ts, q[:, 1], backward[:, 1]).lag == pytest.approx(dt / 2, rel=0.03)
    filtered, y = np.empty_like(dq[:, 0]), dq[0, 0]
    for i, x in enumerate(dq[:, 0]):  # causal first-order low-pass, 8 ms: a lag of about its time constant
        y += dt / (0.008 + dt) * (x - y)
        filtered[i] = y
    assert velocity_lag(ts, q[:, 0], filtered).lag == pytest.approx(0.008, rel=0.15)
    exact = velocity_lag(ts, q[:, 0], dq[:, 0])
    assert abs(exact.lag) < 1e-4 and abs(exact.lag) < 6 * exact.std_error + 1e-6
    early = velocity_lag(ts, q[:, 0], np.concatenate([dq[1:], dq[-1:]])[:, 0])
    assert early.lag == pytest.approx(-dt, rel=0.05)  # a velocity stamped early leads


def test_a_velocity_a_sample_late_is_refused_with_its_lag_and_the_fix():
    ts, q, dq = _motion(1)
    late = dq.copy()
    late[1:, 0] = dq[:-1, 0]
    found = _lags(dynax.check_records([_record(ts, q, late)], estimated=()))
    assert len(found) == 1, found
    f = found[0]
    assert (f.column, f.severity, f.rows) == ("dq1", "refuse", (1, len(ts)))
    assert "lags q1 by 10 ms" in f.message and "read in every stretch" in f.message
    assert f.fix.startswith("--velocities positions")


def test_a_velocity_that_leads_is_named_as_leading_not_as_a_filter():
    ts, q, dq = _motion(1)
    early = dq.copy()
    early[:-1, 0] = dq[1:, 0]  # a forward difference's place: one sample ahead
    (f,) = _lags(dynax.check_records([_record(ts, q, early)], estimated=()))
    assert "leads q1 by 10 ms" in f.message and "stamped ahead" in f.message, f.message
    assert "driver's filter" not in f.message, f.message


def test_a_lag_from_part_way_through_is_located_in_its_stretch():
    ts, q, dq = _motion(2, seconds=10.0)
    late = dq.copy()
    late[501:, 1] = dq[500:-1, 1]  # from t = 5 s on
    (f,) = _lags(dynax.check_records([_record(ts, q, late)], estimated=()))
    assert f.column == "dq2" and "lags q2" in f.message
    assert 4.3 <= f.times[0] <= 5.7 and f.times[1] == pytest.approx(10.0)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10_000), start_s=st.floats(2.0, 5.0), rate_hz=st.sampled_from([100.0, 500.0]))
@example(seed=2859, start_s=2.25, rate_hz=500.0)  # its first stretch too unsure to call lag-free, the next three free
def test_a_lag_that_starts_part_way_is_placed_to_a_few_samples(seed, start_s, rate_hz):
    # read in stretches of 0.5 s, the lag's start is placed inside the one it falls in, to a few samples where
    # the motion is brisk (`experiments/velocity_lag.py --edges`); a few records are refused by the velocity
    # check instead, and say no lag
    ts, q, dq = _motion(seed, rate_hz=rate_hz)
    k, start = round(0.01 * rate_hz), int(start_s * rate_hz)  # 10 ms late from sample `start` on
    late = dq.copy()
    late[start:, 0] = dq[start - k : len(ts) - k, 0]
    found = _lags(dynax.check_records([_record(ts, q, late)], estimated=()))
    assume(found)
    t0, t1 = found[0].times
    # The lag runs to the end; it shows where the motion is brisk (its error is the lag times the acceleration),
    # so the stretch found reaches the end unless what follows it moves far more slowly than the stretch itself.
    acc = np.abs(np.gradient(dq[:, 0], ts))
    quiet_tail = np.sqrt(np.mean(acc[ts > t1] ** 2)) < 0.25 * np.sqrt(np.mean(acc[(ts >= t0) & (ts <= t1)] ** 2))
    assert abs(t0 - ts[start]) <= 0.1 and (t1 >= ts[-1] - 0.1 or quiet_tail), found[0].times


@settings(max_examples=20, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    rate_hz=st.sampled_from([100.0, 250.0, 1000.0]),
    noise=st.sampled_from([(0.0, 0.0), (1e-4, 0.01), (1e-3, 0.1)]),
    jitter=st.sampled_from([0.0, 0.4]),
)
def test_clean_records_with_noise_or_jitter_raise_no_lag(seed, rate_hz, noise, jitter):
    ts, q, dq = _motion(seed, rate_hz=rate_hz, jitter=jitter)
    rng = np.random.default_rng(seed + 1)
    q = q + noise[0] * rng.standard_normal(q.shape)
    dq = dq + noise[1] * rng.standard_normal(dq.shape)
    assert not _lags(dynax.check_records([_record(ts, q, dq)], estimated=()))


def test_velocities_from_positions_reads_the_angles_and_leaves_the_logged_column(tmp_path):
    ts, q, dq = _motion(3)
    late = np.concatenate([dq[:1], dq[:-1]])
    path = tmp_path / "late.csv"
    table = np.column_stack([ts, q, late, np.sin(ts)])
    np.savetxt(path, table, delimiter=",", header="t,q1,q2,dq1,dq2,tau2", comments="")
    with pytest.warns(dynax.DataWarning, match=r"column 'dq1', rows 1-801, t = 0 to 8 s: lags q1 by 10 ms"):
        dynax.load_trajectory(path, "acrobot")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the angles' central differences do not lag: nothing to warn of
        record = dynax.load_trajectory(path, "acrobot", velocities="positions")
    central = np.gradient(q, ts, axis=0)
    assert np.allclose(np.asarray(record.xs)[:, 2:], central, rtol=0, atol=1e-9)
    with pytest.raises(dynax.UsageError, match="positions"):
        dynax.load_trajectory(path, "helicopter", velocities="positions")
