"""Hostile but ordinary inputs (`tests/cli/hostile_cases.py`) through the console script's entry point, and
the located data checks behind them (`dynax.check_records`, `dynax.exclude_stretches`).

Every case ends in a right answer, a located refusal (exit 2, one line naming column, row or time and the
fix) or a located warning: never a traceback, never exit 0 with a wrong answer, never advice that would
make the data worse. Cases that run a fit are `heavy`; those that repeat a kept case's check through a longer run
are `slow`.
"""

import re
import warnings

from hypothesis import assume, given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

import dynax
from dynax.internal import cli_main as main
from tests.cli.hostile_cases import CASES, GOOD, make_fixtures, run_case


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    return make_fixtures(tmp_path_factory.mktemp("hostile"))


def _params(cases):
    def marks(c):
        return [mark for mark, on in ((pytest.mark.heavy, c.heavy), (pytest.mark.slow, c.slow)) if on]

    return [pytest.param(c, id=c.id, marks=marks(c)) for c in cases]


@pytest.mark.parametrize("case", _params(CASES))
def test_hostile_input_gets_a_right_answer_or_a_located_refusal(case, fixtures, tmp_path):
    outcome = run_case(case, tmp_path / "case", fixtures, main)
    assert outcome.verdict in GOOD, (
        f"{outcome.verdict}: exit {outcome.status}; expected {case.expect} with {case.needles}; stderr:\n"
        f"{outcome.stderr[-3000:]}"
    )


def test_the_corpus_covers_every_class_of_fault():
    kinds = {c.kind for c in CASES}
    assert {
        "glitch",
        "stuck",
        "wrapped",
        "jump",
        "velocity",
        "velocity_lag",
        "stamps",
        "swapped",
        "zero",
        "ignored_input",
        "time_units",
        "angle_units",
        "duplicate",
        "non_finite",
        "time",
        "magnitude",
        "model",
        "args",
        "clean",
    } <= kinds
    assert len(CASES) >= 40 and len({c.id for c in CASES}) == len(CASES)


# --- the checks from Python ---------------------------------------------------------------------------


def _record(ts, q, tau, system="acrobot", source="run.csv"):
    """An acrobot record with velocities the central differences of its angles (as encoder-only files give)."""
    dq = np.gradient(q, ts, axis=0)
    return dynax.Trajectory(
        ts, np.column_stack([q, dq]), tau[:, None], ("q1", "q2", "dq1", "dq2"), ("tau2",), system, source
    )


def _smooth(seed, n=600, dt=0.01):
    rng = np.random.default_rng(seed)
    ts = np.arange(n) * dt
    freqs, phases = rng.uniform(0.2, 3.0, (3, 4)), rng.uniform(0, 2 * np.pi, (3, 4))
    waves = [
        np.sum(rng.uniform(0.1, 1.0, 4)[:, None] * np.sin(2 * np.pi * f[:, None] * ts + p[:, None]), axis=0)
        for f, p in zip(freqs, phases)
    ]
    return ts, np.column_stack(waves[:2]), waves[2]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), noise=st.sampled_from([0.0, 1e-4, 1e-3]))
def test_smooth_records_with_or_without_noise_raise_no_alarm(seed, noise):
    ts, q, tau = _smooth(seed)
    q = q + noise * np.random.default_rng(seed + 1).standard_normal(q.shape)
    assert not dynax.check_records([_record(ts, q, tau)]).findings


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), row=st.integers(0, 599), size=st.floats(2.0, 1e3), column=st.sampled_from([0, 1]))
def test_a_single_sample_glitch_is_named_at_its_row(seed, row, size, column):
    ts, q, tau = _smooth(seed)
    spread = np.percentile(q[:, column], 99) - np.percentile(q[:, column], 1)
    q[row, column] += size * spread * (1 if row % 2 else -1)
    found = dynax.check_records([_record(ts, q, tau)]).findings
    glitches = [f for f in found if f.kind == "glitch"]
    assert glitches and glitches[0].column == ("q1", "q2")[column] and glitches[0].rows == (row + 1, row + 1)
    assert glitches[0].fix.startswith("--exclude")


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), row=st.integers(1, 598), start=st.sampled_from([0.0, 86_400.0, 1.772681685527e9]))
def test_the_cut_a_glitch_is_given_leaves_out_that_sample_whatever_the_clock(seed, row, start):
    # A logger's clock may be Unix time (1.77e9 s): the offered `--exclude` must still name the glitch's
    # neighbours to the sample, not a time rounded to six digits (thousands of seconds away, or T0 == T1).
    ts, q, tau = _smooth(seed)
    ts = ts + start
    spread = np.percentile(q[:, 0], 99) - np.percentile(q[:, 0], 1)
    q[row, 0] += 50 * spread
    record = _record(ts, q, tau)
    glitch = next(f for f in dynax.check_records([record]).findings if f.kind == "glitch")
    a, b = glitch.fix.removeprefix("--exclude ").split(":")  # both ends included, as `exclude_stretches` reads them
    left_out = ts[(ts >= float(a)) & (ts <= float(b))]
    assert ts[row] in left_out and len(left_out) <= 3 and np.all(np.abs(left_out - ts[row]) <= 0.011)
    said = re.search(r"t = (\S+) s", glitch.describe())
    assert said is not None and abs(float(said.group(1)) - ts[row]) < 1e-3


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    row=st.integers(4, 595),
    fraction=st.floats(0.1, 0.8),
    column=st.sampled_from([0, 1]),
    sign=st.sampled_from([-1.0, 1.0]),
)
def test_a_position_that_leaps_and_stays_is_named_at_its_row(seed, row, fraction, column, sign):
    ts, q, tau = _smooth(seed)
    spread = np.percentile(q[:, column], 99) - np.percentile(q[:, column], 1)
    # an encoder re-zeroed (or rows dropped) at `row`: a leap of a tenth of the range or more, and beyond any step
    # the motion makes (at 100 Hz a fast stretch steps a tenth of the range itself)
    leap = max(fraction * spread, 40.0 * float(np.max(np.abs(np.diff(q[:, column])))))
    assume(abs(leap - 2 * np.pi * round(leap / (2 * np.pi))) > 0.2 * 2 * np.pi)  # a whole turn is `wrapped`'s
    q[row:, column] += sign * leap
    found = dynax.check_records([_record(ts, q, tau)]).findings
    jumps = [f for f in found if f.kind == "jump"]
    assert jumps and jumps[0].column == ("q1", "q2")[column] and jumps[0].rows == (row, row + 1)
    assert jumps[0].fix == f"--exclude {ts[row - 2]:.6g}:{ts[row + 1]:.6g}"
    assert not [f for f in found if f.kind == "glitch"]  # not out and back


@pytest.mark.parametrize("rate_hz", [100, 1000])
def test_an_encoder_that_rests_and_then_moves_raises_no_alarm(rate_hz):
    # counts of a 4096-line encoder: at rest one count flickers, then the joint breaks away (stick-slip)
    ts = np.arange(0.0, 4.0, 1.0 / rate_hz)
    count = 2 * np.pi / 4096
    moving = np.clip(ts - 1.5, 0.0, None)
    q1 = 0.8 * np.sin(2.0 * np.pi * 0.7 * moving) + 1.5 * moving**2 * (ts < 1.7)
    q2 = np.where(ts < 2.0, 0.3, 0.3 + 0.5 * np.sin(2.0 * np.pi * 1.3 * (ts - 2.0)))
    rng = np.random.default_rng(0)
    q = np.round(np.column_stack([q1, q2]) / count + rng.integers(0, 2, (len(ts), 2))) * count
    tau = np.sin(2.0 * np.pi * 0.5 * ts)
    assert not [f for f in dynax.check_records([_record(ts, q, tau)]).findings if f.kind == "jump"]


def test_a_velocity_wrong_in_one_stretch_is_located_and_no_scale_is_offered(tmp_path):
    ts, q, tau = _smooth(3, n=1000)
    record = _record(ts, q, tau)
    xs = np.array(record.xs)
    xs[700:, 3] *= -1.0  # dq2's sign flips at 7 s
    path = tmp_path / "flip.csv"
    dynax.save_trajectory(dynax.Trajectory(ts, xs, record.us, record.state_names, record.input_names), path)
    with pytest.warns(dynax.DataWarning, match=r"column 'dq2', rows 701-1000, t = 7 to 9.99 s"):
        loaded = dynax.load_trajectory(path, "acrobot")  # not refused with a --scale: the gain is 1 elsewhere
    kept = dynax.exclude_stretches(loaded, [(6.99, np.inf)])
    assert len(kept) == 1 and float(kept[0].ts[-1]) < 7.0
    assert not dynax.check_records(kept).findings


def test_a_cut_inside_a_record_leaves_two_named_records():
    ts, q, tau = _smooth(4)
    pieces = dynax.exclude_stretches(_record(ts, q, tau), [(2.0, 2.5)])
    assert [len(p) for p in pieces] == [200, 349]
    assert pieces[0].source == "run.csv [0-1.99 s]" and pieces[1].source.startswith("run.csv [2.51")


def test_identify_and_diagnose_warn_of_a_glitch_before_fitting():
    ts, q, tau = _smooth(5)
    q[100, 1] += 50.0
    record = _record(ts, q, tau)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check = dynax.check_records([record], [record])
    assert {f.kind for f in check.findings} >= {"glitch", "duplicate"}
    assert any("row 101" in f.describe() for f in check.refusals)
    with pytest.raises(dynax.DataError, match="column 'q2', row 101"):
        check.raise_refusals()
    assert not caught  # check_records itself reports; warning is the loaders' and fits' job


def test_from_physical_refuses_impossible_parameters_and_keeps_jit_and_grad():
    import jax

    with pytest.raises(ValueError, match="`I2` = -0.05"):
        dynax.DoublePendulum.from_physical(I2=-0.05)
    with pytest.raises(ValueError, match="`g`"):
        dynax.Acrobot.from_physical(g=-9.81)
    theta4 = jax.jit(lambda m: dynax.Acrobot.from_physical(m1=m).theta4)
    assert float(theta4(1.0)) == pytest.approx(14.715)
    assert float(jax.grad(lambda m: dynax.Acrobot.from_physical(m1=m).theta4)(1.0)) == pytest.approx(9.81 * 0.5)
    assert np.allclose(jax.vmap(theta4)(np.array([1.0, 2.0])), [14.715, 19.62])
    with pytest.raises(Exception, match="`m1` is not a physical value"):
        theta4(-1.0).block_until_ready()
