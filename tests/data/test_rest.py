"""`rest_stretches`: a joint held still is found with its times; a reversal or a slow swing is not rest."""

import numpy as np

import dynax
from dynax.internal import rest_stretches


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
