import numpy as np
import pytest
from scipy.integrate import solve_ivp

import dynax
from dynax.internal import sample_times_from_positions
from tests.reference import arm_reference


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


# A DFKI-like arm (the lab's model_3.0 in base parameters, rounded, more damping), made apart from dynax's
# model code: `tests.reference.arm_reference` by scipy's DOP853.
ARM = (0.054, 0.05, 0.036, 2.37, 1.78, 0.02, 0.02)
ENCODER_COUNT = 2 * np.pi / 16384  # the rig's 14-bit encoders


def _arm_torque(t, x):
    """Pumped for 2.5 s (the elbow spins over the top at up to 26 rad/s), then held at rest under load by a PD
    law with the gravity torque fed forward."""
    if t < 2.5:
        return np.array([1.2 * np.sin(5.65 * t) + 0.6 * np.sin(13.2 * t), 0.48 * np.sin(8.8 * t + 1.0)])
    q, dq = x[:2], x[2:]
    gravity = np.array([ARM[3] * np.sin(q[0]) + ARM[4] * np.sin(q[0] + q[1]), ARM[4] * np.sin(q[0] + q[1])])
    return gravity - 20.0 * (q - np.array([0.6, -0.4])) - 2.0 * dq


def _arm_record(times):
    sol = solve_ivp(
        lambda t, x: arm_reference(ARM, x, _arm_torque(t, x)),
        (times[0], times[-1]),
        [0.0, 0.0, 0.0, 0.0],
        t_eval=times,
        method="DOP853",
        rtol=1e-11,
        atol=1e-12,
    )
    return sol.y.T


def _stalled_record(n=2500, seed=3):
    """The arm's record on jittered 1.6 ms steps with a stall every 40 rows or so: 3.3 ms added to the interval
    after the stalled row, whose stamp is taken 60 to 95 % of that late. (true times, stamps, stalled rows, the
    true states, the angles on the encoder's counts, the torques)."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(1.2e-3, 2.2e-3, n - 1)  # jittered, as the rig's 1.6 ms run
    stalls = np.arange(20, n - 20, 40) + rng.integers(-5, 6, len(range(20, n - 20, 40)))
    stalled = np.zeros(n, bool)
    stalled[stalls] = True
    true = np.r_[0.0, np.cumsum(steps + np.where(stalled[:-1], 3.3e-3, 0.0))]
    x = _arm_record(true)
    stamps = true + np.where(stalled, rng.uniform(0.6, 0.95, n) * 3.3e-3, 0.0)
    q = np.round(x[:, :2] / ENCODER_COUNT) * ENCODER_COUNT
    us = np.array([_arm_torque(t, s) for t, s in zip(true, x)])
    return true, stamps, stalled, x, q, us


def test_stamps_taken_late_leave_the_velocities_from_the_angles_right_in_every_stretch(tmp_path):
    """A logger that stalls between reading the encoders and reading the clock (the DFKI rig's run 12: 43
    rows stamped 0.5 to 4.1 ms late): central differences on the stamps read such a row's velocity up to 18 rad/s
    off in a fast spin (rms 0.87 rad/s over the spin, 0.38 over the settling); on the times the angles imply
    they are as right as on the true times, in the spin, the settling and the rest.
    """
    true, stamps, _, x, q, us = _stalled_record()
    path = tmp_path / "spin.csv"
    np.savetxt(path, np.column_stack([stamps, q, us]), delimiter=",", header="t,q1,q2,tau1,tau2", comments="")
    loaded = dynax.load_trajectory(path, "double_pendulum", check=False)
    assert np.array_equal(np.asarray(loaded.ts), np.loadtxt(path, delimiter=",", skiprows=1)[:, 0])
    error = np.abs(np.asarray(loaded.xs)[:, 2:] - x[:, 2:])
    # the same differences on the true times: the encoder's quantization, 0.05 rad/s rms, 0.3 at worst
    floor = np.abs(np.asarray(dynax.central_difference(true, q)) - x[:, 2:])
    moving = np.abs(x[:, 2:]).max(axis=1) > 2.0
    for stretch in (true < 2.5, (true >= 2.5) & (true < 3.5), true >= 3.5):
        assert np.sqrt(np.mean(error[stretch] ** 2)) <= 1.2 * np.sqrt(np.mean(floor[stretch] ** 2))
        if (stretch & moving).any():  # where the angles time a stamp, the velocity is as right as on the true times
            assert error[stretch & moving].max() <= floor[stretch & moving].max() + 0.1
        # where they move too little to, a late stamp moves the velocity by a few times the encoder's noise
        assert error[stretch].max() <= 1.0
    assert np.abs(x[true < 2.5, 3]).max() > 20  # the spin is fast


@pytest.mark.parametrize("rate_hz", [100.0, 1000.0])
def test_clean_records_move_no_stamp(rate_hz):
    """The stamps of clean records (time uniform or truly jittered; angles exact or on the encoder's counts)
    agree with their angles: none is moved, so their velocities are the central differences as before."""
    rng = np.random.default_rng(int(rate_hz))
    for jitter in (0.0, 0.4):
        times = np.arange(0.0, 4.0, 1 / rate_hz) + rng.uniform(-jitter, jitter, int(4.0 * rate_hz)) / rate_hz
        x = _arm_record(times)
        for q in (x[:, :2], np.round(x[:, :2] / ENCODER_COUNT) * ENCODER_COUNT):
            sampled, rows = sample_times_from_positions(times, q)
            assert rows.size == 0 and np.array_equal(sampled, times)


def test_stamps_that_disagree_with_the_angles_are_named_at_their_rows_with_the_logged_velocities_harm(tmp_path):
    """The stalled logger's record with its velocities logged as the rig's are (backward differences on the
    stamps): a `stamps` warning names the late rows (those the angles can time: the arm moving) and no other,
    how late, what the logged velocities miss there, and the fix; the same record stamped on its true times
    gets none."""
    true, stamps, stalled, x, q, us = _stalled_record()
    for times, late in ((stamps, True), (true, False)):
        dq = np.r_[[[0.0, 0.0]], np.diff(q, axis=0) / np.diff(times)[:, None]]
        path = tmp_path / f"logged_{late}.csv"
        header = "t,q1,q2,dq1,dq2,tau1,tau2"
        np.savetxt(path, np.column_stack([times, q, dq, us]), delimiter=",", header=header, comments="")
        loaded = dynax.load_trajectory(path, "double_pendulum", check=False)
        found = [f for f in dynax.check_records([loaded]).findings if f.kind == "stamps"]
        if not late:
            assert not found
            continue
        (finding,) = found
        assert finding.severity == "warn" and finding.column == "t"
        assert finding.fix.startswith("--velocities positions")
        rows = [int(r) for r in finding.message.split("(rows ")[1].split(" and ")[0].split(", ")]
        assert all(stalled[r - 1] for r in rows)  # the rows shown are late ones, 1-based
        count = int(finding.message.split(" time stamps")[0])
        moving = np.abs(x[:, 2:]).max(axis=1) > 2.0
        assert 0.8 * np.sum(stalled & moving) <= count <= np.sum(stalled)
        assert "ms late against a" in finding.message


def test_resample_puts_inputs_on_the_grid_by_the_rule_asked():
    # a zero-order hold logged at irregular stamps: the hold takes the value in force at each grid time, the
    # average keeps the hold's integral over each new interval, linear interpolates; the switch sets the default
    from dynax.internal import input_resampling

    ts = np.array([0.0, 0.011, 0.019, 0.031, 0.040, 0.049])
    us = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])[:, None]
    xs = np.column_stack([ts, np.ones_like(ts)])
    record = dynax.Trajectory(ts, xs, us, ("x", "v"), ("u",))
    held = dynax.resample(record, 0.01)
    np.testing.assert_allclose(np.asarray(held.ts), [0.0, 0.01, 0.02, 0.03, 0.04])
    np.testing.assert_allclose(np.asarray(held.us)[:, 0], [0.0, 0.0, 2.0, 2.0, 4.0])
    averaged = np.asarray(dynax.resample(record, 0.01, inputs="average").us)[:, 0]
    # [0.02, 0.03): 2 until 0.031 -> 2 throughout; [0.01, 0.02): 0 to 0.011, 1 to 0.019, 2 after
    np.testing.assert_allclose(averaged[1:3], [(0.001 * 0 + 0.008 * 1 + 0.001 * 2) / 0.01, 2.0])
    linear = np.asarray(dynax.resample(record, 0.01, inputs="linear").us)[:, 0]
    np.testing.assert_allclose(linear, np.interp([0.0, 0.01, 0.02, 0.03, 0.04], ts, us[:, 0]))
    with input_resampling("linear"):
        np.testing.assert_allclose(np.asarray(dynax.resample(record, 0.01).us)[:, 0], linear)
    np.testing.assert_allclose(np.asarray(dynax.resample(record, 0.01).us)[:, 0], [0.0, 0.0, 2.0, 2.0, 4.0])
    with pytest.raises(dynax.UsageError, match="inputs"):
        dynax.resample(record, 0.01, inputs="cubic")
