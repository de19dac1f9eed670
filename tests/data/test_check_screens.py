"""The data checks' cheap screens skip only work whose answer they have proven: the glitch search's
running median (`median_reach`, and a count in place of the median step), the velocity check's BLAS
gain (numpy sums with their rounding bound) and the wrap search (no step of half a turn). Each bound is
checked against the quantity it bounds, computed here another way, and whole records with each class
of fault give the same findings with the screens as with them switched off."""

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

import dynax
from dynax.internal import (
    check_trajectory_velocities,
    gain_surely_within,
    GLITCH_STEPS,
    MAX_VELOCITY_GAIN_ERROR,
    median_reach,
    screens_off,
    typical_step_covers,
)


def _running_median(x, window=7):
    """The glitch search's reference level, by `np.median` of each window: the first and last `window // 2`
    samples measured from the first and last full window."""
    h = window // 2
    full = np.median(np.lib.stride_tricks.sliding_window_view(x, window), axis=1)
    return np.concatenate([np.full(h, full[0]), full, np.full(h, full[-1])])


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 100_000),
    n=st.integers(7, 400),
    kind=st.sampled_from(["noise", "smooth", "steps", "spikes", "plateau", "ends"]),
)
def test_median_reach_bounds_every_residual(seed, n, kind):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    x = {
        "noise": rng.standard_normal(n),
        "smooth": np.sin(2 * np.pi * rng.uniform(0.1, 5) * t) + 1e-3 * rng.standard_normal(n),
        "steps": np.repeat(rng.uniform(-2, 2, n // 5 + 1), 5)[:n],
        "spikes": np.where(rng.random(n) < 0.05, rng.uniform(-100, 100, n), np.cos(t)),
        "plateau": np.where((t > 0.3 * t[-1]) & (t < 0.32 * t[-1]), 40.0, np.sin(t)),
        "ends": np.concatenate([[rng.uniform(-50, 50)], np.sin(t[1:-1]), [rng.uniform(-50, 50)]]),
    }[kind]
    residual = np.abs(x - _running_median(x))
    assert median_reach(x, 7) >= residual.max()
    assert np.isnan(median_reach(np.where(np.arange(n) == n // 2, np.nan, x), 7))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 100_000), n=st.integers(1, 2000), factor=st.floats(0.999, 1.001))
def test_the_count_says_yes_only_where_the_median_step_covers_the_reach(seed, n, factor):
    rng = np.random.default_rng(seed)
    steps = np.abs(rng.standard_normal(n)) * rng.choice([1.0, 1e-6, 1e3])
    if seed % 3 == 0:
        steps[: n // 2] = 0.0  # an exact tie at zero below the median
    typical = float(np.median(steps)) * 1.4826 + 1e-300
    reach = factor * GLITCH_STEPS * typical  # at the bound, either side
    if typical_step_covers(steps, reach):
        assert reach <= GLITCH_STEPS * typical
    lower_middle = np.sort(steps)[(n - 1) // 2]  # the count's criterion: the median is at least this
    if factor < 0.9999 and np.median(steps) > 0 and lower_middle >= 0.99995 * np.median(steps):
        assert typical_step_covers(steps, reach)  # not a screen that never says yes


@pytest.mark.parametrize("n", [40, 2000, 20_000, 50_000])  # beyond 10,000 entries BLAS's dot is threaded
@pytest.mark.parametrize("gain", [1.0, 0.8, 1.2, -1.0, 0.7999999999, 1.2000000001, 1.1999999999])
def test_the_numpy_gain_says_within_only_where_the_blas_gain_is(n, gain):
    rng = np.random.default_rng(n)
    for trial in range(20):
        slopes = rng.standard_normal(n) * 10.0 ** rng.uniform(-3, 3)
        means = gain * slopes + rng.choice([0.0, 1e-12, 1e-3]) * rng.standard_normal(n) * np.abs(slopes).max()
        if trial % 4 == 0:
            slopes[rng.random(n) < 0.5] = 0.0
        blas = float(slopes @ means) / float(slopes @ slopes)
        if gain_surely_within(slopes, means, MAX_VELOCITY_GAIN_ERROR):
            assert abs(blas - 1.0) <= MAX_VELOCITY_GAIN_ERROR
        elif abs(gain - 1.0) < 0.1:
            pytest.fail("a gain of 1 within the noise was not screened")


def _measured(seed, n=3000, dt=0.01):
    """An acrobot record whose velocities are measured (the analytic derivatives, with noise), so that every
    check reads them."""
    rng = np.random.default_rng(seed)
    ts = np.arange(n) * dt
    f, p, a = rng.uniform(0.2, 2.0, (2, 3)), rng.uniform(0, 2 * np.pi, (2, 3)), rng.uniform(0.2, 1.0, (2, 3))
    q = np.stack([np.sum(a[k][:, None] * np.sin(2 * np.pi * f[k][:, None] * ts + p[k][:, None]), 0) for k in (0, 1)])
    dq = np.stack(
        [
            np.sum(
                a[k][:, None] * 2 * np.pi * f[k][:, None] * np.cos(2 * np.pi * f[k][:, None] * ts + p[k][:, None]), 0
            )
            for k in (0, 1)
        ]
    )
    dq = dq + 1e-3 * rng.standard_normal(dq.shape)
    tau = np.repeat(rng.uniform(-2, 2, n // 50 + 1), 50)[:n]
    return ts, np.column_stack([q.T, dq.T]), tau[:, None]


def _faulty(kind, seed):
    rng = np.random.default_rng(seed)
    ts, xs, us = _measured(seed)
    n = len(ts)
    k = int(rng.integers(20, n - 20))
    column = int(rng.integers(0, 4))
    spread = np.percentile(xs[:, column], 99) - np.percentile(xs[:, column], 1)
    if kind == "glitch":  # one to three samples, from well under to well over the threshold
        xs[k : k + int(rng.integers(1, 4)), column] += rng.choice([-1, 1]) * rng.uniform(0.5, 4.0) * spread
    elif kind == "glitch_at_end":
        xs[rng.choice([0, 1, n - 2, n - 1]), column] += rng.uniform(1.0, 4.0) * spread
    elif kind == "glitch_input":
        us[k, 0] += rng.choice([-1, 1]) * rng.uniform(20.0, 40.0)  # beyond three times the range
    elif kind == "stuck":
        xs[k : k + 60, column] = xs[k, column]
    elif kind == "wrapped":
        xs[:, column % 2] = np.angle(np.exp(1j * 4.0 * xs[:, column % 2]))
    elif kind == "velocity":
        xs[k:, 2 + column % 2] *= rng.choice([-1.0, 0.5, 3.0])
    elif kind == "unit":
        xs[:, 2 + column % 2] *= 180.0 / np.pi
    return dynax.Trajectory(ts, xs, us, ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot", f"{kind}.csv")


@pytest.mark.parametrize("kind", ["clean", "glitch", "glitch_at_end", "glitch_input", "stuck", "wrapped", "velocity"])
@pytest.mark.parametrize("seed", range(6))
def test_each_fault_is_found_alike_with_and_without_the_screens(kind, seed):
    record = _faulty(kind, seed)
    screened = dynax.check_records([record], estimated=()).to_json()
    with screens_off():  # no glitch screen, no wrap screen
        full = dynax.check_records([record], estimated=()).to_json()
    assert screened == full
    if kind not in ("clean", "glitch", "glitch_at_end"):  # a small glitch may stay under the threshold
        assert screened, f"the {kind} fault was not found"


@pytest.mark.parametrize("kind", ["clean", "velocity", "unit"])
@pytest.mark.parametrize("seed", range(4))
def test_the_velocity_unit_check_refuses_alike_with_and_without_the_screen(kind, seed):
    record = _faulty(kind, seed)

    def outcome():
        try:
            check_trajectory_velocities(record)
        except dynax.DataError as error:
            return str(error)
        return None

    screened = outcome()
    with screens_off():
        full = outcome()
    assert screened == full
    assert (screened is not None) == (kind == "unit")


def _elbow_held_by_friction():
    """A two-link arm whose elbow, undriven and under a static friction of 0.6 N m, stands still for seconds while
    the shoulder swings (`tests.reference.stick_slip_arm`: an event-based integrator, no dynax code); encoders of
    14 bits (the angle repeats one count exactly while the joint stands), velocities measured with 1e-3 rad/s of
    noise."""
    from tests.reference import stick_slip_arm

    arm = dict(m1=0.6, m2=0.5, l1=0.3, lc1=0.3, lc2=0.25, I1=0.05, I2=0.04, b1=0.01, b2=0.01)
    theta = [float(v) for v in dynax.DoublePendulum.from_physical(**arm).base_parameters.values()]
    ts = np.arange(0, 6, 0.005)
    us = np.stack([0.9 * np.sin(2 * np.pi * 0.7 * ts), 0.0 * ts], 1)
    xs, stuck = stick_slip_arm(theta, np.zeros(4), ts, us, fc=(0.01, 0.3), fs=(0.02, 0.6), vst=0.05)
    count = 2 * np.pi / 2**14
    xs[:, :2] = np.round(xs[:, :2] / count) * count
    xs[:, 2:] += 1e-3 * np.random.default_rng(0).standard_normal((len(ts), 2))
    return ts, xs, us, stuck


def test_a_joint_held_still_by_friction_is_no_stuck_sensor_when_its_velocity_is_measured():
    ts, xs, us, stuck = _elbow_held_by_friction()
    assert stuck[:, 1].mean() > 0.5  # the elbow stands still most of the record, for seconds at a time
    names = ("q1", "q2", "dq1", "dq2")
    record = dynax.Trajectory(ts, xs, us, names, ("tau1", "tau2"), "double_pendulum", "held.csv")
    assert not [f for f in dynax.check_records([record], estimated=()).findings if str(f.kind) == "stuck"]
    # the same stretch with the elbow's velocity estimated from its angle cannot tell the two apart: refused
    estimated = dynax.check_records([record], estimated=("dq2",)).findings
    assert [f for f in estimated if str(f.kind) == "stuck" and f.column == "q2"]
    # a sensor that stops while its joint moves: its measured velocity carries the joint away
    frozen = xs.copy()
    k = int(np.argmax(np.abs(xs[:, 2]) > 1.0))
    frozen[k : k + 120, 0] = frozen[k, 0]
    record = dynax.Trajectory(ts, frozen, us, names, ("tau1", "tau2"), "double_pendulum", "frozen.csv")
    found = [f for f in dynax.check_records([record], estimated=()).findings if str(f.kind) == "stuck"]
    assert [f.column for f in found] == ["q1"]
