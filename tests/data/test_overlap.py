"""Stretches two records share, sample for sample: found at their rows in copies, and never in real repeats."""

import re

import numpy as np

import dynax
from tests.conftest import DFKI_MAPPING
from tests.quadrotor.test_flight_data import NANOBENCH_MAP


def _shared(records, validation=()):
    """The `duplicate` findings of `check_records` (the records' other findings, such as the DFKI velocities'
    lag, are not what is tested here)."""
    return [f for f in dynax.check_records(records, validation).findings if f.kind == "duplicate"]


def _record(ts, xs, us, source):
    names = ("q1", "q2", "dq1", "dq2")
    return dynax.Trajectory(ts, np.asarray(xs), np.asarray(us)[:, None], names, ("tau2",), "acrobot", source)


def test_an_excerpt_restamped_and_saved_with_fewer_digits_is_found_at_its_rows(datasets, tmp_path):
    # 20 s of DFKI run 00 cut out, its clock started from zero, saved with five significant digits: the
    # encoders' own quantum is finer than that rounding, so only the tolerance for a coarser copy finds it
    run = dynax.load_trajectory(
        datasets / "dfki_double_pendulum" / "sys_id" / "trajectory_00.csv",
        "double_pendulum",
        mapping=DFKI_MAPPING,
        check=False,
    )
    ts, xs, us = (np.asarray(a, float) for a in (run.ts, run.xs, run.us))
    cut = slice(2000, 4001)
    table = np.column_stack([ts[cut] - ts[cut][0], xs[cut], us[cut]])
    path = tmp_path / "excerpt.csv"
    header = "t,q1,q2,dq1,dq2,tau1,tau2"
    path.write_text(header + "\n" + "\n".join(",".join(f"{v:.5g}" for v in row) for row in table) + "\n")
    excerpt = dynax.load_trajectory(path, "double_pendulum", check=False)
    [finding] = _shared([run], [excerpt])
    assert finding.severity == "refuse" and finding.rows == (1, 2001)
    assert "rows 2001-4001" in finding.message and "in-sample" in finding.message
    # the cut it offers takes the excerpt's rows out of the training run, and at most a sample either side
    t0, t1 = (float(v) for v in re.match(r"--exclude trajectory_00\.csv@([\d.]+):([\d.]+) ", finding.fix).groups())
    assert ts[1998] < t0 <= ts[2000] and ts[4000] <= t1 < ts[4002], (finding.fix, ts[1998:2001], ts[4000:4003])


def test_real_repeats_of_one_motion_share_no_stretch(datasets):
    # the six DFKI runs (trajectories the rig ran more than once among them), and NanoBench's flights of one
    # shape at other speeds and repetitions: their sensors' noise parts every row
    runs = [
        dynax.load_trajectory(path, "double_pendulum", mapping=DFKI_MAPPING, check=False)
        for path in sorted((datasets / "dfki_double_pendulum" / "sys_id").glob("trajectory_*.csv"))
    ]
    assert _shared(runs[:3], runs[3:]) == [] and _shared(runs) == []
    names = ("B2_circle_fast_rep2", "B2_circle_medium_rep3", "B2_circle_slow_rep2", "B6_linear_ramp_rep1")
    flights = [dynax.load_flight(datasets / "nanobench" / f"{n}.csv.gz", mapping=NANOBENCH_MAP)[0] for n in names]
    flights.append(dynax.load_flight(datasets / "nanobench" / "B6_linear_ramp_rep2.csv.gz", mapping=NANOBENCH_MAP)[0])
    assert _shared(flights) == []


def test_records_that_rest_at_one_pose_then_move_apart_share_nothing():
    # both rest 2 s at the bottom under zero torque, read by the same quantised encoder (the rows agree exactly),
    # then swing under other torques; a third repeats the first's motion with encoder noise of one count
    ts = np.arange(0.0, 6.0, 0.01)
    quantum = 2 * np.pi / 4096
    records = []
    for k, (amplitude, noise) in enumerate(((0.8, 0.0), (0.5, 0.0), (0.8, 1.0))):
        moving = ts >= 2.0
        q1 = np.where(moving, amplitude * np.sin(2.1 * (ts - 2.0)) * (1 - np.exp(-(ts - 2.0))), 0.0)
        q2 = np.where(moving, 0.5 * amplitude * np.sin(3.3 * (ts - 2.0)), 0.0)
        rng = np.random.default_rng(k)
        q1 = quantum * np.round(q1 / quantum + noise * rng.integers(-1, 2, len(ts)) * moving)
        q2 = quantum * np.round(q2 / quantum)
        xs = np.column_stack([q1, q2, np.gradient(q1, ts), np.gradient(q2, ts)])
        records.append(_record(ts, xs, np.where(moving, amplitude * np.cos(ts), 0.0), f"run{k}.csv"))
    assert _shared(records[:1], records[1:]) == [] and _shared(records) == []
    # ... while the first record's swing given again is found, and only the swing (the rest is not evidence)
    copy = _record(ts[300:] - 3.0, np.asarray(records[0].xs)[300:], np.asarray(records[0].us)[300:, 0], "copy.csv")
    [finding] = _shared(records[:1], [copy])
    assert finding.rows == (1, 300) and "rows 301-600" in finding.message


def test_a_copy_at_half_or_twice_the_rate_is_found_either_way_round():
    # every other row kept (a log decimated to 50 Hz), or samples interpolated between the rows (resampled to
    # 200 Hz): the rows the two share are found whichever is the training record
    ts = np.arange(0.0, 6.0, 0.01)
    q1, q2 = 0.8 * np.sin(2.1 * ts), 0.4 * np.sin(3.3 * ts + 0.5)
    xs = np.column_stack([q1, q2, np.gradient(q1, ts), np.gradient(q2, ts)])
    us = np.cos(1.7 * ts)
    full = _record(ts, xs, us, "full.csv")
    half = _record(ts[::2], xs[::2], us[::2], "half.csv")
    fine = np.arange(0.0, ts[-1] + 1e-9, 0.005)
    double = _record(
        fine, np.column_stack([np.interp(fine, ts, c) for c in xs.T]), np.interp(fine, ts, us), "double.csv"
    )
    for training, held_out, rows, said in (
        (full, half, (1, 300), "every 2nd row of the record full.csv's rows 1-599"),
        (half, full, (1, 599), "holds the record half.csv's rows 1-300"),
        (full, double, (1, 1199), "holds the record full.csv's rows 1-600"),
        (double, full, (1, 600), "every 2nd row of the record double.csv's rows 1-1199"),
    ):
        [finding] = _shared([training], [held_out])
        assert finding.rows == rows and said in finding.message and "in-sample" in finding.message, finding.message


def test_a_copy_resampled_at_another_rate_is_found_on_the_originals_path():
    # 100 Hz read onto 150 Hz and 60 Hz clocks, linearly (numpy, pandas' default) or by a cubic spline (scipy),
    # a stretch of it re-stamped from zero: no row is shared, every row lies between two of the original's
    from scipy.interpolate import CubicSpline

    ts = np.arange(0.0, 8.0, 0.01)
    q1, q2 = 0.8 * np.sin(2.1 * ts) + 0.2 * np.sin(5.3 * ts), 0.4 * np.sin(3.3 * ts + 0.5)
    xs = np.column_stack([q1, q2, np.gradient(q1, ts), np.gradient(q2, ts)])
    us = np.cos(1.7 * ts) + 0.3 * np.sin(4.1 * ts)
    full = _record(ts, xs, us, "full.csv")
    for rate, how in ((150.0, "linear"), (60.0, "linear"), (150.0, "cubic"), (73.0, "cubic")):
        other = np.arange(2.0, 6.0, 1 / rate)
        if how == "linear":
            ys, u = np.column_stack([np.interp(other, ts, c) for c in xs.T]), np.interp(other, ts, us)
        else:
            ys, u = CubicSpline(ts, xs)(other), CubicSpline(ts, us)(other)
        copy = _record(other - 2.0, ys, u, "copy.csv")
        [finding] = _shared([full], [copy])
        assert finding.severity == "refuse" and finding.rows == (1, len(other)), (rate, how, finding.rows)
        assert "resampled at another rate" in finding.message and "in-sample" in finding.message, finding.message
        first, last = (int(v) for v in re.search(r"rows (\d+)-(\d+) \(t", finding.message).groups())
        assert first in (200, 201) and last in (600, 601), (rate, how, finding.message)
        assert "--exclude full.csv@" in finding.fix
    # ... and a record of the same motion measured again (encoder noise of a thousandth of its spread) is not
    rng = np.random.default_rng(3)
    noisy = xs + 1e-3 * np.std(xs, 0) * rng.standard_normal(xs.shape)
    other = np.arange(2.0, 6.0, 1 / 150)
    again = _record(
        other - 2.0, np.column_stack([np.interp(other, ts, c) for c in noisy.T]), np.interp(other, ts, us), "again.csv"
    )
    assert _shared([full], [again]) == []


def test_a_resampled_copy_of_a_record_with_a_dropout_is_found_either_side_of_the_gap():
    # a motion-capture dropout logged as NaN rows in the original (left out of a flight with a note, not refused):
    # the copy read onto 150 Hz carries the gap; the stretches either side of it are still found
    ts = np.arange(0.0, 8.0, 0.01)
    q1, q2 = 0.8 * np.sin(2.1 * ts) + 0.2 * np.sin(5.3 * ts), 0.4 * np.sin(3.3 * ts + 0.5)
    xs = np.column_stack([q1, q2, np.gradient(q1, ts), np.gradient(q2, ts)])
    us = np.cos(1.7 * ts) + 0.3 * np.sin(4.1 * ts)
    xs[400:405] = np.nan
    other = np.arange(2.0, 6.0, 1 / 150)
    copy = _record(
        other - 2.0, np.column_stack([np.interp(other, ts, c) for c in xs.T]), np.interp(other, ts, us), "copy.csv"
    )
    found = _shared([_record(ts, xs, us, "full.csv")], [copy])
    gap = np.flatnonzero(~np.isfinite(np.asarray(copy.xs)).all(1)) + 1  # 1-based rows
    assert len(found) == 2 and all("resampled at another rate" in f.message for f in found), found
    (a0, a1), (b0, b1) = found[0].rows, found[1].rows
    assert a0 == 1 and a1 < gap[0] and b0 > gap[-1] and b1 == len(other), (found[0].rows, found[1].rows, gap)
    # ... and a record whose every other row is a gap has no path to lie on: nothing found, nothing raised
    holes = xs.copy()
    holes[::2] = np.nan
    assert _shared([_record(ts, holes, us, "holes.csv")], [copy]) == []
