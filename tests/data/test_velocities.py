"""A measured velocity column that is not the derivative of its position column is refused at load,
naming the gain, the likely unit mix-up and the `scale` that fixes it."""

import numpy as np
import pytest

import dynax
from dynax.internal import velocity_gain

DT = 0.002


def arm_columns(seed=0, seconds=8.0, rest=False):
    """Two joints under smooth motion (or at rest), velocities from the exact derivative plus white noise
    of 0.2 rad/s (the DFKI rig's level), encoder noise 1e-4 rad."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, DT)
    amplitude = 0.0 if rest else 1.0
    q1 = amplitude * (0.8 * np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 1.9 * t + 1.0))
    q2 = amplitude * (1.2 * np.sin(2 * np.pi * 0.45 * t + 0.4) - 0.2 * np.cos(2 * np.pi * 2.6 * t))
    dq1 = amplitude * (
        0.8 * 2 * np.pi * 0.7 * np.cos(2 * np.pi * 0.7 * t) + 0.3 * 2 * np.pi * 1.9 * np.cos(2 * np.pi * 1.9 * t + 1.0)
    )
    dq2 = amplitude * (
        1.2 * 2 * np.pi * 0.45 * np.cos(2 * np.pi * 0.45 * t + 0.4)
        + 0.2 * 2 * np.pi * 2.6 * np.sin(2 * np.pi * 2.6 * t)
    )
    return {
        "t": t,
        "pos1": q1 + 1e-4 * rng.normal(size=t.size),
        "pos2": q2 + 1e-4 * rng.normal(size=t.size),
        "vel1": dq1 + 0.2 * rng.normal(size=t.size),
        "vel2": dq2 + 0.2 * rng.normal(size=t.size),
        "tau1": 0.1 * np.sin(t),
        "tau2": -0.1 * np.sin(t),
    }


MAPPING = {"q1": "pos1", "q2": "pos2", "dq1": "vel1", "dq2": "vel2"}


def write(tmp_path, columns, name="run.csv"):
    path = tmp_path / name
    names = list(columns)
    np.savetxt(path, np.column_stack([columns[n] for n in names]), delimiter=",", header=",".join(names), comments="")
    return path


def load(path, **kwargs):
    return dynax.load_trajectory(path, "double_pendulum", mapping=MAPPING, **kwargs)


def test_velocities_in_the_positions_units_load_and_their_gain_is_one(tmp_path):
    columns = arm_columns()
    run = load(write(tmp_path, columns))
    gain, std, corr = velocity_gain(run.ts, run.state("q1"), run.state("dq1"))
    assert abs(gain - 1) < 3 * std + 1e-3 and corr > 0.99
    # a record at rest cannot tell, and is let through (its velocities are noise alone)
    load(write(tmp_path, arm_columns(rest=True), "rest.csv"))


def test_velocities_in_degrees_per_second_are_refused_with_the_scale_that_fixes_them(tmp_path):
    columns = arm_columns()
    columns["vel1"] = np.degrees(columns["vel1"])
    path = write(tmp_path, columns)
    with pytest.raises(
        dynax.DataError,
        match=r"column 'vel1': it is not the derivative of 'pos1' \(q1\): .* 57\.[23]"
        r".*degrees per second, the position in radians.*'dq1': 0\.0174533",
    ):
        load(path)
    run = load(path, scale={"dq1": np.pi / 180})  # the fix it names
    np.testing.assert_allclose(run.state("dq1"), np.radians(columns["vel1"]), rtol=1e-12)


def test_a_velocity_of_the_opposite_sign_or_in_rpm_is_refused(tmp_path):
    columns = arm_columns()
    columns["vel2"] = -columns["vel2"]
    with pytest.raises(dynax.DataError, match=r"column 'vel2'.*opposite sign.*'dq2': -1\b"):
        load(write(tmp_path, columns))
    columns = arm_columns()
    columns["vel1"] = columns["vel1"] * 60 / (2 * np.pi)
    with pytest.raises(dynax.DataError, match=r"column 'vel1'.*rpm, the position in radians.*'dq1': 0\.10472"):
        load(write(tmp_path, columns, "rpm.csv"))


def test_a_position_in_degrees_or_millimetres_beside_its_velocity_in_si_units_is_the_one_scaled(tmp_path):
    # the velocity is right and its position is not: the fix scales the position (it advised leaving the velocity
    # columns out, which keeps the position in degrees)
    columns = arm_columns()
    columns["pos2"] = np.degrees(columns["pos2"])
    path = write(tmp_path, columns)
    with pytest.raises(
        dynax.DataError,
        match=r"column 'vel2'.*radians per second, the position in degrees; if so, scale the position "
        r"\(`scale=\{'q2': 0\.0174533\}`, `--scale q2=0\.0174533`\)",
    ):
        load(path)
    run = load(path, scale={"q2": np.pi / 180})  # the fix it names
    np.testing.assert_allclose(run.state("q2"), np.radians(columns["pos2"]), rtol=1e-12)
    # both off: rpm against a position in degrees
    columns = arm_columns()
    columns["pos1"], columns["vel1"] = np.degrees(columns["pos1"]), columns["vel1"] * 60 / (2 * np.pi)
    with pytest.raises(
        dynax.DataError, match=r"rpm, the position in degrees; if so, scale them .*dq1=0\.10472,q1=0\.0174533"
    ):
        load(write(tmp_path, columns, "both.csv"))


def test_a_placeholder_velocity_column_of_zeros_is_refused_with_the_way_out(tmp_path):
    columns = arm_columns()
    columns["vel1"] = np.zeros_like(columns["vel1"])
    with pytest.raises(dynax.DataError, match=r"column 'vel1'.*its mean is 0 \+- .*leave its columns out"):
        load(write(tmp_path, columns))


def test_swapped_velocity_columns_are_named_as_swapped(tmp_path):
    path = write(tmp_path, arm_columns())
    with pytest.raises(
        dynax.DataError,
        match=r"column 'vel2'.*not the derivative of 'pos1'.*derivative of 'pos2' "
        r"\(q2\).*columns of dq1 and dq2 swapped",
    ):
        dynax.load_trajectory(path, "double_pendulum", mapping=dict(MAPPING, dq1="vel2", dq2="vel1"))


def test_a_linear_axis_velocity_in_millimetres_per_second_is_refused(tmp_path):
    t = np.arange(0.0, 5.0, 0.001)
    q = 0.1 * np.sin(2 * np.pi * 0.5 * t)
    table = {"t": t, "q": q, "dq": 1000 * 0.1 * 2 * np.pi * 0.5 * np.cos(2 * np.pi * 0.5 * t), "force": np.ones_like(t)}
    with pytest.raises(
        dynax.DataError, match=r"column 'dq'.*millimetres per second, the position in metres.*'dq': 0\.001"
    ):
        dynax.load_trajectory(write(tmp_path, table), "linear_axis")


def test_the_dfki_rigs_velocities_are_the_derivatives_of_its_angles(datasets):
    # Real data, made independently of dynax: every run's logged velocities follow the angles with
    # gain 1 within 2 % (run 12, sampled 1.2 to 5.9 ms apart, is the farthest: the trapezoid mean of a
    # one-sample difference over irregular steps), far inside the check's 20 %.
    from tests.conftest import DFKI_MAPPING

    for path in sorted((datasets / "dfki_double_pendulum" / "sys_id").glob("trajectory_*.csv")):
        run = dynax.load_trajectory(path, "double_pendulum", mapping=DFKI_MAPPING)
        for q, dq in (("q1", "dq1"), ("q2", "dq2")):
            gain, _, corr = velocity_gain(run.ts, run.state(q), run.state(dq))
            assert abs(gain - 1) < 0.02 and corr > 0.999, (path.name, dq, gain, corr)


def test_identify_and_diagnose_check_records_built_in_python_too(tmp_path):
    # A Trajectory made from arrays (no file) gets the same check before anything is fitted.
    import jax.numpy as jnp

    from dynax import Trajectory

    columns = arm_columns()
    xs = np.column_stack([columns["pos1"], columns["pos2"], np.degrees(columns["vel1"]), columns["vel2"]])
    us = np.column_stack([columns["tau1"], columns["tau2"]])
    run = Trajectory(
        columns["t"],
        jnp.asarray(xs),
        jnp.asarray(us),
        ("q1", "q2", "dq1", "dq2"),
        ("tau1", "tau2"),
        "double_pendulum",
        "arrays",
    )
    with pytest.raises(dynax.DataError, match=r"file arrays, column 'dq1': it is not the derivative of 'q1'.*degrees"):
        dynax.identify(dynax.DoublePendulum(), run, dynax.Dynamic())
    with pytest.raises(dynax.DataError, match=r"column 'dq1'.*degrees"):
        dynax.diagnose(dynax.DoublePendulum(), run, progress=False)


def _slow_axis(seed=0, motion=0.04, noise=1e-3, seconds=30.0, rate=100.0, freqs=(0.21, 0.37, 0.53, 0.8)):
    """A linear axis that barely moves (speed `motion` m/s rms) under motion-capture noise of `noise` m, logged
    at `rate`, its velocity the exact derivative plus 5 mm/s of noise: the position's change over a 50 ms block
    is about as noisy as it is large."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate)
    freqs = np.asarray(freqs)
    phases = rng.uniform(0, 2 * np.pi, freqs.size)
    q = np.sin(2 * np.pi * freqs[:, None] * t + phases[:, None]).sum(0) / freqs.size
    dq = (2 * np.pi * freqs[:, None] * np.cos(2 * np.pi * freqs[:, None] * t + phases[:, None])).sum(0) / freqs.size
    k = motion / float(np.sqrt(np.mean(dq**2)))
    return {
        "t": t,
        "q": k * q + noise * rng.normal(size=t.size),
        "dq": k * dq + 5e-3 * rng.normal(size=t.size),
        "force": np.sin(t),
    }


def test_a_velocity_beside_a_position_noisy_against_its_motion_is_not_refused(tmp_path):
    # Noise in the position's change over a block pulls the gain towards zero (errors in the variables): here to
    # about 0.67, which read alone refuses a right velocity. With that noise taken out it reads 1.
    table = _slow_axis()
    run = dynax.load_trajectory(write(tmp_path, table), "linear_axis")
    gain, std, _ = velocity_gain(run.ts, run.state("q"), run.state("dq"))
    assert gain < 0.8 and abs(gain - 1) > 5 * std  # what the uncorrected reading says
    # so noisy that the position's change is no larger than its noise: the record cannot tell
    dynax.load_trajectory(write(tmp_path, _slow_axis(noise=4e-3), "noisier.csv"), "linear_axis")
    # a velocity the logger differenced from the same noisy positions shares their noise, and its gain is 1
    central = dict(table, dq=np.gradient(table["q"], table["t"]))
    dynax.load_trajectory(write(tmp_path, central, "central.csv"), "linear_axis")


def test_a_wrong_velocity_beside_a_noisy_position_is_still_refused(tmp_path):
    table = _slow_axis()
    with pytest.raises(dynax.DataError, match=r"column 'dq'.*centimetres|column 'dq'.*not the derivative"):
        dynax.load_trajectory(write(tmp_path, dict(table, dq=100 * table["dq"]), "cm.csv"), "linear_axis")
    with pytest.raises(dynax.DataError, match=r"column 'dq'.*not the derivative"):
        dynax.load_trajectory(write(tmp_path, dict(table, dq=0.5 * table["dq"]), "half.csv"), "linear_axis")
    other = _slow_axis(seed=1, freqs=(0.29, 0.43, 0.61, 0.9))  # another axis's velocity, of the same size
    with pytest.raises(dynax.DataError, match=r"column 'dq'.*not the derivative"):
        dynax.load_trajectory(write(tmp_path, dict(table, dq=other["dq"]), "other.csv"), "linear_axis")
