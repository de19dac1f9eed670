"""Time stamps that jitter about evenly spaced samples: told from samples read at jittered times, and re-stamped."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import dynax
from tests.conftest import DFKI_MAPPING
from tests.reference import arm_reference

THETA = (1.333, 1.33, 1.0, 14.715, 9.81, 0.1, 0.1)  # Drake's acrobot in base parameters


def _drive(t):
    return 0.8 * np.sin(2.3 * t) + 0.6 * np.sin(5.1 * t + 1.0), 1.5 * np.sin(1.7 * t) + np.sin(3.9 * t + 0.3)


def _arm(read_at):
    """The arm (both joints driven; scipy's DOP853) read at the times `read_at`."""
    sol = solve_ivp(
        lambda t, x: arm_reference(THETA, x, _drive(t)),
        (read_at[0], read_at[-1]),
        [0.3, -0.2, 0.0, 0.0],
        t_eval=read_at,
        method="DOP853",
        rtol=1e-10,
        atol=1e-11,
    )
    return sol.y.T, np.array([_drive(t) for t in read_at])


def _record(stamps, xs, us, source="run.csv"):
    names = ("q1", "q2", "dq1", "dq2")
    return dynax.Trajectory(stamps, xs, us, names, ("tau1", "tau2"), "double_pendulum", source)


def _stamps_findings(record):
    return [f for f in dynax.check_records([record]).findings if f.kind == "stamps"]


def test_stamps_jittered_about_even_samples_are_refused_and_samples_read_at_jittered_times_are_not():
    rng = np.random.default_rng(0)
    even = np.arange(0.0, 6.0, 0.01)
    jitter = rng.uniform(-0.002, 0.002, len(even))  # 0.12 intervals RMS
    xs, us = _arm(even)
    # read evenly, stamped on receipt: the positions follow the grid, not their stamps
    [finding] = _stamps_findings(_record(even + jitter, xs, us))
    assert finding.severity == "refuse" and finding.column == "t" and "--even-times" in finding.fix
    assert "jitter by 0.1" in finding.message, finding.message
    # ... also where one joint barely moves (its encoder flickers between two counts: noise on either time base)
    held = np.array(xs, copy=True)
    held[:, 0] = 0.3 + 0.0015 * rng.integers(0, 2, len(even))
    held[:, 2] = 0.0
    [finding] = _stamps_findings(_record(even + jitter, held, us))
    assert finding.severity == "refuse"
    # read at jittered times and stamped truly: nothing to say
    xs_jittered, us_jittered = _arm(even + jitter)
    assert _stamps_findings(_record(even + jitter, xs_jittered, us_jittered)) == []
    # a steady clock of coarser resolution than the interval (300 Hz stamped to the millisecond) is the same fault
    fine = np.arange(0.0, 3.0, 1 / 300)
    xs300, us300 = _arm(fine)
    [coarse] = _stamps_findings(_record(np.round(fine, 3), xs300, us300))
    assert coarse.severity == "refuse"


def test_even_times_restamps_to_a_steady_clock_dropped_samples_and_all(tmp_path):
    rng = np.random.default_rng(1)
    even = np.arange(0.0, 6.0, 0.01)
    xs, us = _arm(even)
    stamps = even + rng.uniform(-0.002, 0.002, len(even))
    table = np.column_stack([stamps, xs, us])
    path = tmp_path / "run.csv"
    np.savetxt(path, table, delimiter=",", header="t,q1,q2,dq1,dq2,tau1,tau2", comments="")
    with pytest.warns(dynax.DataWarning, match="jitter"):
        dynax.load_trajectory(path, "double_pendulum")
    restamped = dynax.load_trajectory(path, "double_pendulum", sampling=dynax.Sampling(even=True))
    grid = np.asarray(restamped.ts)
    assert np.abs(grid - even).max() < 0.004 and np.allclose(np.diff(grid), np.diff(grid)[0])
    assert _stamps_findings(restamped) == []
    # one sample dropped near the end (row 551): its tick is left out, where an even grid between the first and
    # last stamps would put every sample before it up to half an interval late
    np.savetxt(path, np.delete(table, 550, axis=0), delimiter=",", header="t,q1,q2,dq1,dq2,tau1,tau2", comments="")
    restamped = dynax.load_trajectory(path, "double_pendulum", sampling=dynax.Sampling(even=True))
    assert np.abs(np.asarray(restamped.ts) - np.delete(even, 550)).max() < 0.004
    # stamps that put two samples on one tick tell no steady clock: refused, not guessed
    ambiguous = even.copy()
    ambiguous[100], ambiguous[101] = 1.004, 1.0049  # 0.4 of an interval late, then 0.51 early: both on tick 100
    np.savetxt(
        path,
        np.column_stack([ambiguous, xs, us]),
        delimiter=",",
        header="t,q1,q2,dq1,dq2,tau1,tau2",
        comments="",
    )
    with pytest.raises(dynax.DataError, match=r"column 't': even time stamps asked for.*one tick"):
        dynax.load_trajectory(path, "double_pendulum", sampling=dynax.Sampling(even=True), check=False)


def test_real_records_stamped_truly_are_not_flagged(datasets):
    # the DFKI runs' stamps jitter by 2 to 37 % of their interval (late stamps among them), the positions
    # follow them; EMPS is sampled evenly
    for path in sorted((datasets / "dfki_double_pendulum" / "sys_id").glob("trajectory_*.csv")):
        run = dynax.load_trajectory(path, "double_pendulum", mapping=DFKI_MAPPING, check=False)
        assert not [f for f in _stamps_findings(run) if "jitter" in f.message], path.name
    emps = dynax.load_trajectory(
        datasets / "emps" / "DATA_EMPS.mat", "linear_axis", mapping={"q": "qm", "force": "vir"}, check=False
    )
    assert _stamps_findings(emps) == []
