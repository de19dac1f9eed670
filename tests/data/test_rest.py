"""`rest_stretches`: a joint held still is found with its times; a reversal or a slow swing is not rest.
`speed_noise_at_rest`: the velocity noise at rest (`Stiction`'s stick band) on records of known noise."""

import numpy as np

import dynax
from dynax.internal import rest_stretches, speed_noise_at_rest


def record(q1, q2, dt):
    ts = np.arange(len(q1)) * dt
    xs = np.stack([q1, q2, np.gradient(q1, dt), np.gradient(q2, dt)], 1)
    noise = np.random.default_rng(0).normal(0, 0.1, xs[:, 2:].shape)  # a driver's velocity noise at rest
    xs[:, 2:] += noise
    return dynax.Trajectory(ts, xs, np.zeros((len(ts), 2)), ("q1", "q2", "dq1", "dq2"), ("tau1", "tau2"))


def test_a_held_joint_is_found_and_a_reversal_is_not():
    dt = 0.002
    t = np.arange(0, 6, dt)
    q1 = 0.8 * np.sin(2 * np.pi * 0.5 * t)  # reverses every second, never rests
    q2 = np.where(t < 2.0, np.sin(2 * np.pi * 0.5 * t), np.where(t < 3.5, 0.0, 0.3 * np.sin(2 * np.pi * (t - 3.5))))
    q2 = q2 + np.random.default_rng(1).integers(-1, 2, len(t)) * 1e-3  # encoder steps
    found = rest_stretches(record(q1, q2, dt), record="r")
    assert [s.coordinate for s in found] == ["q2"]
    (held,) = found
    assert abs(held.start_s - 2.0) < 0.05 and abs(held.stop_s - 3.5) < 0.05 and held.record == "r"
    # A slow swing (0.2 rad/s) is motion, not rest, whatever its velocity noise.
    slow = record(0.2 * t, 0.2 * t, dt)
    assert rest_stretches(slow) == ()


def test_gaussian_noise_at_rest():
    rng = np.random.default_rng(0)
    for sigma in (0.01, 0.1):
        speeds = sigma * rng.standard_normal(1000)
        np.testing.assert_allclose(speed_noise_at_rest(speeds), sigma, rtol=0.1)


def test_a_driver_that_reads_zero_between_encoder_counts():
    # An encoder of 2 mrad resolution over a joint that jitters by 1 mrad at rest, read as the difference of
    # counts over one sample: most samples read zero, the rest +-1 rad/s. The median magnitude is zero; the
    # noise a state measured at rest starts from is the rms of what is read.
    rng = np.random.default_rng(1)
    counts = np.round((1e-3 * rng.standard_normal(2001) + 0.3e-3) / 2e-3)
    speeds = np.diff(counts) * 2e-3 / 0.002
    assert np.mean(speeds == 0.0) > 0.5 and np.median(np.abs(speeds)) == 0.0
    np.testing.assert_allclose(speed_noise_at_rest(speeds), np.sqrt(np.mean(speeds**2)))
    assert speed_noise_at_rest(speeds) > 0.3


def test_no_samples_no_noise():
    assert speed_noise_at_rest(np.zeros(0)) == 0.0


def test_a_heavy_arms_slow_reversal_is_not_a_rest_and_a_held_joint_that_drifts_is():
    # A reversal at 0.4 rad/s^2 stays within the range test's 12.5 mrad for half a second, longer than the
    # quarter second a rest takes; with 1 mrad of white encoder noise one parabola explains it, so it is no
    # rest. A joint held for a second while its encoder creeps by a few mrad and steps between counts is.
    dt = 0.005
    t = np.arange(0, 3, dt)
    rng = np.random.default_rng(4)
    q1 = 0.2 * (t - 1.5) ** 2 + 1e-3 * rng.standard_normal(len(t))
    held = 2e-3 * np.round((0.004 * (t - 1.0)) / 2e-3)  # a 4 mrad/s creep read by a 2 mrad encoder
    q2 = np.where(t < 1.0, 0.5 * (1.0 - t) ** 2, np.where(t < 2.0, held, 0.5 * (t - 2.0) ** 2 + held[-1]))
    q2 = q2 + 1e-3 * rng.standard_normal(len(t))
    found = rest_stretches(record(q1, q2, dt), record="r")
    assert [s.coordinate for s in found] == ["q2"]
    assert found[0].duration > 0.9


def test_every_window_within_the_range_rests():
    # Plateaus of random lengths (with 0.1 mrad of noise: flat, no parabola) joined by fast moves: the rests are
    # the samples of every 0.25 s window whose range is within 0.05 rad/s times 0.25 s, counted here window by
    # window.
    dt, width = 0.01, 25
    rng = np.random.default_rng(7)
    pieces = []
    for _ in range(12):
        level = rng.uniform(-1, 1)
        pieces += [np.full(int(rng.integers(5, 80)), level), level + np.linspace(0, 0.5, int(rng.integers(3, 30)))]
    q1 = np.concatenate(pieces) + 1e-4 * rng.standard_normal(sum(len(p) for p in pieces))
    q2 = np.sin(np.arange(len(q1)) * dt * 3.0)  # never rests
    resting = np.zeros(len(q1), bool)
    for i in range(len(q1) - width + 1):
        if np.ptp(q1[i : i + width]) <= 0.05 * 0.25:
            resting[i : i + width] = True
    edges = np.flatnonzero(np.diff(np.concatenate([[0], resting.astype(int), [0]])))
    expected = list(zip(edges[::2], edges[1::2]))
    found = rest_stretches(record(q1, q2, dt))
    assert expected and [(s.start, s.stop) for s in found] == expected
    assert all(s.coordinate == "q1" for s in found)
