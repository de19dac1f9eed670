"""Loading measured data: the contract's columns, mapping, scale and every bad-file case."""

import numpy as np
import pytest
import scipy.io

import dynax
import dynax.internal
from dynax.internal import parse_assignments
from tests.conftest import DFKI_MAPPING

HEADER = "t,q1,q2,dq1,dq2,tau2"


def write(tmp_path, text, name="run.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def good_rows(n=5):
    return "\n".join(f"{0.01 * i},{0.1 * i},0,0,0,1" for i in range(n))


def test_loads_contract_csv(tmp_path):
    path = write(tmp_path, HEADER + "\n" + good_rows())
    tr = dynax.load_trajectory(path, "acrobot")
    assert tr.state_names == ("q1", "q2", "dq1", "dq2") and tr.input_names == ("tau2",)
    assert tr.xs.shape == (5, 4) and tr.us.shape == (5, 1)
    np.testing.assert_allclose(tr.state("q1"), 0.1 * np.arange(5))


def test_missing_column_names_file_and_column(tmp_path):
    path = write(tmp_path, "t,q1,q2,dq1,tau2\n" + "\n".join("0,0,0,0,0".replace("0,", f"{i},", 1) for i in range(5)))
    with pytest.raises(dynax.DataError, match=r"run\.csv.*column 'dq2'.*missing"):
        dynax.load_trajectory(path, "acrobot")


@pytest.mark.parametrize(
    "text",
    [
        HEADER.replace(",", ";") + "\n" + good_rows().replace(",", ";"),  # a spreadsheet's export, comma locale
        HEADER.replace(",", "\t") + "\n" + good_rows().replace(",", "\t"),  # a tab-separated log
        "# rig 2, run 7\n# operator: A\n" + HEADER + "\n" + good_rows(),  # comment lines above the header
        "# " + HEADER + "\n" + good_rows(),  # numpy.savetxt(..., header=HEADER)
    ],
    ids=["semicolons", "tabs", "comments", "savetxt"],
)
def test_other_separators_and_comment_lines_read_as_the_csv(tmp_path, text):
    reference = dynax.load_trajectory(write(tmp_path, HEADER + "\n" + good_rows(), "plain.csv"), "acrobot")
    tr = dynax.load_trajectory(write(tmp_path, text), "acrobot")
    np.testing.assert_array_equal(tr.xs, reference.xs)
    np.testing.assert_array_equal(tr.us, reference.us)


def test_a_header_repeated_inside_the_file_is_named_as_two_logs_joined(tmp_path):
    path = write(tmp_path, HEADER + "\n" + good_rows() + "\n" + HEADER + "\n" + good_rows())
    with pytest.raises(dynax.DataError, match=r"row 6: the header repeats at file line 7: two logs joined"):
        dynax.load_trajectory(path, "acrobot")


def test_a_decimal_comma_is_named_with_its_cell(tmp_path):
    rows = "\n".join(";".join(v.replace(".", ",") for v in row.split(",")) for row in good_rows().split("\n"))
    path = write(tmp_path, HEADER.replace(",", ";") + "\n" + rows)
    with pytest.raises(dynax.DataError, match=r"column 't', row 1: non-numeric value '0,0' \(a decimal comma"):
        dynax.load_trajectory(path, "acrobot")


def test_columns_named_with_case_or_units_get_the_whole_mapping_suggested(tmp_path):
    header = "Time [s],Q1 [rad],Q2 [rad],dq1,DQ2,tau2 (N m)"
    path = write(tmp_path, header + "\n" + good_rows())
    with pytest.raises(dynax.DataError, match="missing column") as e:
        dynax.load_trajectory(path, "acrobot")
    # every column the file names alike is suggested at once, quoted for the shell (`dq1` is the contract's own)
    assert "--map 't=Time [s],q1=Q1 [rad],q2=Q2 [rad],dq2=DQ2,tau2=tau2 (N m)'" in str(e.value)
    mapping = {"t": "Time [s]", "q1": "Q1 [rad]", "q2": "Q2 [rad]", "dq2": "DQ2", "tau2": "tau2 (N m)"}
    tr = dynax.load_trajectory(path, "acrobot", mapping=mapping)
    np.testing.assert_allclose(tr.state("q1"), 0.1 * np.arange(5))


def test_non_numeric_value_names_row(tmp_path):
    rows = good_rows().split("\n")
    rows[2] = "0.02,abc,0,0,0,1"
    path = write(tmp_path, HEADER + "\n" + "\n".join(rows))
    with pytest.raises(dynax.DataError, match=r"column 'q1', row 3: non-numeric value 'abc'") as e:
        dynax.load_trajectory(path, "acrobot")
    assert e.value.row == 3 and e.value.column == "q1" and str(path) == e.value.path


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_non_finite_value_names_row(tmp_path, bad):
    rows = good_rows().split("\n")
    rows[4] = f"0.04,0.4,0,{bad},0,1"
    path = write(tmp_path, HEADER + "\n" + "\n".join(rows))
    with pytest.raises(dynax.DataError, match=r"column 'dq1', row 5: non-finite"):
        dynax.load_trajectory(path, "acrobot")


@pytest.mark.parametrize("times", [[0, 0.01, 0.01, 0.03, 0.04], [0, 0.01, 0.02, 0.015, 0.04]])
def test_time_must_strictly_increase(tmp_path, times):
    text = HEADER + "\n" + "\n".join(f"{t},0,0,0,0,1" for t in times)
    path = write(tmp_path, text)
    with pytest.raises(dynax.DataError, match=r"column 't', row \d: time does not strictly increase"):
        dynax.load_trajectory(path, "acrobot")


def test_too_few_samples(tmp_path):
    path = write(tmp_path, HEADER + "\n" + good_rows(3))
    with pytest.raises(dynax.DataError, match="has 3 samples; at least 10"):
        dynax.load_trajectory(path, "acrobot", sampling=dynax.Sampling(min_samples=10))


def test_ragged_row(tmp_path):
    path = write(tmp_path, HEADER + "\n0,0,0,0,0,1\n0.01,0,0,0\n")
    with pytest.raises(dynax.DataError, match="row 2: has 4 fields"):
        dynax.load_trajectory(path, "acrobot")


def test_empty_and_missing_file(tmp_path):
    with pytest.raises(dynax.DataError, match="empty"):
        dynax.load_trajectory(write(tmp_path, ""), "acrobot")
    with pytest.raises(dynax.DataError, match="no such file"):
        dynax.load_trajectory(tmp_path / "nope.csv", "acrobot")


def test_mapping_and_scale(tmp_path):
    path = write(tmp_path, "time,a,b,c,d,volts\n" + "\n".join(f"{0.1 * i},{i},0,0,0,2" for i in range(4)))
    tr = dynax.load_trajectory(
        path,
        "acrobot",
        mapping={"t": "time", "q1": "a", "q2": "b", "dq1": "c", "dq2": "d", "tau2": "volts"},
        scale={"tau2": 1.5, "q1": 2.0},
    )
    np.testing.assert_allclose(tr.us[:, 0], 3.0)
    np.testing.assert_allclose(tr.state("q1"), 2.0 * np.arange(4))


def test_mapping_names_unknown_column(tmp_path):
    path = write(tmp_path, HEADER + "\n" + good_rows())
    with pytest.raises(dynax.UsageError, match=r"`mapping` names \['tau9'\]"):
        dynax.load_trajectory(path, "acrobot", mapping={"tau9": "x"})
    with pytest.raises(dynax.DataError, match=r"column 'nothere': missing column \(mapped from 'q1'\)"):
        dynax.load_trajectory(path, "acrobot", mapping={"q1": "nothere"})


def test_npz_round_trip(tmp_path):
    ts = np.linspace(0, 1, 11)
    tr = dynax.Trajectory(
        ts,
        np.random.default_rng(0).normal(size=(11, 4)),
        np.ones((11, 2)),
        ("q1", "q2", "dq1", "dq2"),
        ("tau1", "tau2"),
        "double_pendulum",
    )
    for name in ("run.npz", "run.csv"):
        dynax.save_trajectory(tr, tmp_path / name)
        back = dynax.load_trajectory(tmp_path / name, "double_pendulum")
        np.testing.assert_allclose(back.xs, tr.xs, rtol=1e-15)
        np.testing.assert_allclose(back.ts, tr.ts, rtol=1e-15)


def test_mat_file_with_mapping_scale_and_estimated_velocity(tmp_path):
    t = np.linspace(0, 1, 101)[:, None]
    scipy.io.savemat(tmp_path / "axis.mat", {"time": t, "pos": t**2, "volts": np.ones_like(t), "gain": 3.0})
    tr = dynax.load_trajectory(
        tmp_path / "axis.mat", "linear_axis", mapping={"t": "time", "q": "pos", "force": "volts"}, scale={"force": 35.0}
    )
    assert tr.state_names == ("q", "dq")
    np.testing.assert_allclose(tr.us, 35.0)
    # dq estimated from q = t^2 by central differences: exact (2t) in the interior.
    np.testing.assert_allclose(tr.state("dq")[1:-1], 2 * t[1:-1, 0], atol=1e-12)


def test_backward_differences_are_the_derivative_half_an_interval_back_on_an_irregular_grid():
    # On any grid the backward difference of a quadratic is its derivative at the interval's midpoint.
    ts = np.cumsum(np.random.default_rng(3).uniform(0.001, 0.006, size=200))
    ys = np.stack([0.7 * ts**2 - ts, -2.0 * ts**2 + 0.3], axis=1)
    mid = 0.5 * (ts[1:] + ts[:-1])
    v = np.asarray(dynax.internal.backward_difference(ts, ys))
    np.testing.assert_allclose(v[1:], np.stack([1.4 * mid - 1.0, -4.0 * mid], axis=1), rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(v[0], v[1])
    with pytest.raises(ValueError, match="time >= 2"):
        dynax.internal.backward_difference(ts[:1], ys[:1])


def test_arm_records_of_encoder_positions_alone_get_central_difference_velocities(tmp_path):
    # Many rigs log only encoder angles: dq1 and dq2 are then estimated without lag, by second-order
    # central differences on the recorded (here irregular) time stamps, exact for a quadratic at every
    # interior sample (a backward difference would be the derivative half an interval earlier). A dq
    # mapped to a column that is not there is still an error, and so is one velocity without the other
    # (test_missing_column_names_file_and_column).
    t = np.cumsum(np.random.default_rng(4).uniform(0.002, 0.008, size=120))
    q1, q2 = 0.3 * t**2 - t, -0.5 * t**2 + 0.2
    table = "t,pos1,pos2,tau1,tau2\n" + "".join(f"{a:.17g},{b:.17g},{c:.17g},0,-0.1\n" for a, b, c in zip(t, q1, q2))
    (tmp_path / "encoders.csv").write_text(table)
    mapping = {"q1": "pos1", "q2": "pos2"}
    run = dynax.load_trajectory(tmp_path / "encoders.csv", "double_pendulum", mapping=mapping)
    np.testing.assert_allclose(run.state("dq1")[1:-1], 0.6 * t[1:-1] - 1.0, atol=1e-9)
    np.testing.assert_allclose(run.state("dq2")[1:-1], -t[1:-1], atol=1e-9)
    acrobot = dynax.load_trajectory(tmp_path / "encoders.csv", "acrobot", mapping=mapping)
    np.testing.assert_allclose(acrobot.xs, run.xs)
    with pytest.raises(dynax.DataError, match=r"column 'vel1': missing column \(mapped from 'dq1'\)"):
        dynax.load_trajectory(tmp_path / "encoders.csv", "double_pendulum", mapping=dict(mapping, dq1="vel1"))
    with pytest.raises(dynax.DataError, match="column 'q1': missing column"):
        dynax.load_trajectory(tmp_path / "encoders.csv", "double_pendulum", mapping={"q2": "pos2"})


def test_dfki_files_read_without_their_velocity_columns_get_the_logged_filter_band(datasets):
    # The rig's logger computed vel_meas as backward differences of pos_meas. Read as encoder angles
    # alone, the velocities are central differences (no half-sample lag), whose noise vanishes at the
    # Nyquist frequency; `choose_filter` reads their noise floor from the angles' backward differences,
    # so the band it picks is the one the logged velocities give (within 5 %, on every run).
    positions_only = {k: v for k, v in DFKI_MAPPING.items() if not k.startswith("dq")}
    for path in sorted((datasets / "dfki_double_pendulum" / "sys_id").glob("trajectory_*.csv")):
        logged = dynax.load_trajectory(path, "double_pendulum", mapping=DFKI_MAPPING)
        estimated = dynax.load_trajectory(path, "double_pendulum", mapping=positions_only)
        np.testing.assert_allclose(estimated.xs[:, :2], logged.xs[:, :2])
        bands = [dynax.internal.choose_filter(dynax.resample(r, r.dt)).band_hz for r in (estimated, logged)]
        for name in ("dq1", "dq2"):
            assert abs(bands[0][name] / bands[1][name] - 1) < 0.05, (path.name, name, bands)


def test_offset_is_added_after_scale_and_checked(tmp_path):
    path = write(tmp_path, HEADER + "\n" + good_rows())
    run = dynax.load_trajectory(path, "acrobot", scale={"q1": 2.0}, offset={"q1": np.pi, "tau2": -0.5})
    np.testing.assert_allclose(run.state("q1"), 2.0 * 0.1 * np.arange(5) + np.pi)
    np.testing.assert_allclose(np.asarray(run.us)[:, 0], 0.5)
    with pytest.raises(dynax.UsageError, match="offset.*'q9'"):
        dynax.load_trajectory(path, "acrobot", offset={"q9": 1.0})
    with pytest.raises(dynax.UsageError, match="`offset` for 'q1' must be finite"):
        dynax.load_trajectory(path, "acrobot", offset={"q1": float("nan")})
    assert parse_assignments("q1=3.141593,q2=0", "--offset", numeric=True, zero=True) == {"q1": 3.141593, "q2": 0.0}


def test_parse_assignments():
    assert parse_assignments("t=time, q1=pos", "--map", numeric=False) == {"t": "time", "q1": "pos"}
    assert parse_assignments("force=35.15", "--scale", numeric=True) == {"force": 35.15}
    with pytest.raises(dynax.UsageError, match="--map: 'q1' is not of the form"):
        parse_assignments("q1", "--map", numeric=False)
    with pytest.raises(dynax.UsageError, match="not a number"):
        parse_assignments("force=abc", "--scale", numeric=True)


def test_dfki_runs_load_through_mapping(datasets):
    for run in ("00", "03", "12"):
        tr = dynax.load_trajectory(
            datasets / "dfki_double_pendulum" / "sys_id" / f"trajectory_{run}.csv",
            "double_pendulum",
            mapping=DFKI_MAPPING,
        )
        assert tr.input_names == ("tau1", "tau2") and len(tr) > 3000
        assert not tr.is_uniform  # the rig jitters; it is kept as recorded
        assert np.all(np.diff(np.asarray(tr.ts)) > 0)


def test_emps_loads_from_mat(datasets):
    tr = dynax.load_trajectory(
        datasets / "emps" / "DATA_EMPS.mat",
        "linear_axis",
        mapping={"q": "qm", "force": "vir"},
        scale={"force": 35.15065188},
    )
    assert len(tr) == 24841
    assert abs(tr.duration - 24.84) < 0.01


def test_gap_is_refused_with_its_place_and_records_with_pauses_split_into_runs(tmp_path):
    times = np.r_[0.01 * np.arange(30), 60.0 + 0.01 * np.arange(20)]
    path = write(tmp_path, HEADER + "\n" + "\n".join(f"{t!r},{t},0,0,0,1" for t in times.tolist()))
    with pytest.raises(
        dynax.DataError, match=r"column 't', row 31: a gap in the record: time jumps from 0\.29\d* to 60\.0 s"
    ):
        dynax.load_trajectory(path, "acrobot")
    record = dynax.load_trajectory(path, "acrobot", sampling=dynax.Sampling(max_gap=None))
    runs = dynax.internal.split_at_gaps(record)
    assert [len(r) for r in runs] == [30, 20]
    np.testing.assert_array_equal(runs[1].ts, times[30:])
    np.testing.assert_array_equal(runs[1].state("q1"), times[30:])
    # Jitter of a few intervals, as real rigs have, is neither refused nor split.
    jitter = np.cumsum(0.01 * np.r_[0, np.random.default_rng(0).uniform(0.5, 4.0, 60)])
    path = write(tmp_path, HEADER + "\n" + "\n".join(f"{t!r},0,0,0,0,1" for t in jitter.tolist()), "jitter.csv")
    assert len(dynax.internal.split_at_gaps(dynax.load_trajectory(path, "acrobot"))) == 1


def test_near_duplicate_time_stamp_is_refused(tmp_path):
    times = np.r_[0.01 * np.arange(10), 0.09 + 1e-12, 0.1 + 0.01 * np.arange(10)]
    path = write(tmp_path, HEADER + "\n" + "\n".join(f"{t!r},0,0,0,0,1" for t in times.tolist()))
    with pytest.raises(dynax.DataError, match=r"row 11: near-duplicate time stamps"):
        dynax.load_trajectory(path, "acrobot")
    assert len(dynax.load_trajectory(path, "acrobot", sampling=dynax.Sampling(min_step=None))) == 21
