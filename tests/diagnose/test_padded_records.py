"""Whole records of other lengths share the compiled one-step residuals, and the padding that does it changes no
number: the jitted per-sample functions run on each record padded to a power of two and are cut back (see
`dynax.internal.padded_length`). Without it each flight log of its own length compiled the screening and
the structure probe anew: most of a whole-flight quadrotor diagnosis's first minutes."""

import jax
import jax.numpy as jnp
import numpy as np

import dynax
from dynax import Extended, InputLag, LinearAxis, Trajectory
from dynax.internal import (
    acceleration_residuals,
    interval_increments,
    predicted_accelerations,
    savitzky_golay,
    sg_window,
    shared_length,
)

MODEL = Extended(LinearAxis(coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0)), (InputLag(0, 0.04),))


def _record(n: int, seed: int) -> Trajectory:
    """`n` samples of a linear axis whose force acts through a 40 ms lag, under a multisine, measured with noise
    (an adaptive solver, not the fixed grid of the residuals)."""
    rng = np.random.default_rng(seed)
    ts = 0.01 * np.arange(n)
    freqs = rng.uniform(0.3, 2.0, 5)
    us = (40.0 * np.sum(np.sin(2 * np.pi * freqs[None] * ts[:, None] + rng.uniform(0, 6.28, 5)), axis=1))[:, None]
    x0 = MODEL.initial_state(jnp.zeros(2), jnp.asarray(us[0]))
    sim = dynax.simulate(MODEL, x0, jnp.asarray(ts), jnp.asarray(us), method=dynax.Adaptive(rtol=1e-9, atol=1e-11))
    xs = np.asarray(sim.xs)[:, :2] + 1e-5 * rng.standard_normal((n, 2))
    return Trajectory(jnp.asarray(ts), jnp.asarray(xs), jnp.asarray(us), ("q", "dq"), ("force",), "linear_axis")


def test_records_of_other_lengths_share_one_compilation_and_keep_their_residuals():
    compiled = []

    def listen(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled.append(str(kwargs.get("fun_name", "")))

    records = [_record(300, 0), _record(437, 1)]  # both pad to 512 samples
    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        results = [acceleration_residuals(MODEL, rec) for rec in records]
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    # Unpadded, each length compiled its own (two each); padded, at most one (none if another test made it).
    assert sum("predicted_accelerations" in name for name in compiled) <= 1, compiled
    assert sum("interval_increments" in name for name in compiled) <= 1, compiled

    for rec, (residuals, _, predicted, keep) in zip(records, results):
        n = len(rec)
        assert residuals.shape == (n - 2 * sg_window(rec.dt), 1) and keep == slice(
            sg_window(rec.dt), n - sg_window(rec.dt)
        )
        ts, w, idx = rec.ts, sg_window(rec.dt), jnp.asarray([1])
        smooth = savitzky_golay(ts, rec.xs, window=w, order=5)  # the states as a local quintic reads them
        us_before = jnp.concatenate([rec.us[:1], rec.us[:-1]])
        right, left = (np.asarray(a) for a in predicted_accelerations(MODEL, ts, smooth, rec.us, idx, us_before, True))
        # The model's acceleration integrated over each interval under its held input, then read as the measured one.
        velocity = np.concatenate(
            [[[0.0]], np.cumsum(0.5 * np.diff(np.asarray(ts))[:, None] * (right[:-1] + left[1:]), 0)]
        )
        reference = savitzky_golay(ts, velocity, window=w, order=3, deriv=1)
        np.testing.assert_allclose(predicted, np.asarray(reference)[keep], rtol=1e-10, atol=1e-10)
        # The residuals: the velocity increments' drift from the model's, accumulated and read by the same filter.
        increments = interval_increments(MODEL, ts, smooth, rec.us, idx)
        drift = jnp.diff(rec.xs[:, 1:], axis=0) - increments
        accumulated = jnp.concatenate([jnp.zeros((1, 1)), jnp.cumsum(drift, axis=0)])
        measured = savitzky_golay(ts, accumulated, window=w, order=3, deriv=1)
        np.testing.assert_allclose(residuals, np.asarray(measured)[keep], rtol=1e-10, atol=1e-10)
        # The lag is in the model: its residuals are the measurement noise's, far below the acceleration's.
        assert np.std(residuals) < 0.05 * np.std(predicted)


def test_a_diagnosis_records_padded_to_their_longest_share_one_compilation_and_keep_every_bit():
    """`shared_length`: a diagnosis's training and held-out records (here 1,200 and 300 samples, which pad to 2,048
    and 512 on their own) run on one length, so each model's per-sample functions compile once for both, and a
    record's residuals on the longer padding are its own, bit for bit."""
    records = [_record(1200, 2), _record(300, 3)]
    length = shared_length(records)
    assert length == 2048
    compiled = []

    def listen(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled.append(str(kwargs.get("fun_name", "")))

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        shared = [acceleration_residuals(MODEL, rec, length=length) for rec in records]
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    assert sum("predicted_accelerations" in name for name in compiled) <= 1, compiled
    assert sum("interval_increments" in name for name in compiled) <= 1, compiled
    for rec, padded_shared in zip(records, shared):
        own = acceleration_residuals(MODEL, rec)
        for a, b in zip(padded_shared[:3], own[:3]):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        assert padded_shared[3] == own[3]
