"""Quadrotor flight logs: the NanoBench files load as they are, ground segments are found and left
out, and a glitch injected into a copy is flagged with its column and time."""

import gzip
import pathlib

import numpy as np
import pytest

import dynax

NANOBENCH = pathlib.Path(__file__).resolve().parents[2].parent / "shared" / "datasets" / "nanobench"
STAR = NANOBENCH / "B8_star_fast_rep1.csv.gz"
# The documented map (docs/flight_data.md): Vicon position, attitude, velocity and body rates, PWM
# motor commands and the battery voltage.
NANOBENCH_MAP = {
    "x": "px",
    "y": "py",
    "z": "pz",
    "p": "wx_vicon",
    "q": "wy_vicon",
    "r": "wz_vicon",
    "m1": "motor_motor_m1",
    "m2": "motor_motor_m2",
    "m3": "motor_motor_m3",
    "m4": "motor_motor_m4",
    "vbat": "pwr_pm_vbat",
}

pytestmark = pytest.mark.skipif(not STAR.exists(), reason="the NanoBench flights are not in ../shared/datasets")


def _write(path, header, table):
    with gzip.open(path, "wt") as f:
        f.write(",".join(header) + "\n")
        np.savetxt(f, table, delimiter=",", fmt="%.17g")


def test_gzip_csv_loads_like_the_csv(tmp_path, star_table):
    header, table = star_table
    plain = tmp_path / "star.csv"
    plain.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.17g}" for v in row) for row in table[:300]))
    packed = tmp_path / "star.csv.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    a = dynax.load_trajectory(plain, "quadrotor", mapping=NANOBENCH_MAP)
    b = dynax.load_trajectory(packed, "quadrotor", mapping=NANOBENCH_MAP)
    np.testing.assert_array_equal(np.asarray(a.xs), np.asarray(b.xs))
    assert a.input_names == ("m1", "m2", "m3", "m4", "vbat")
    # vbat is optional: without it in the map or the file, the inputs are the motors alone.
    no_vbat = {k: v for k, v in NANOBENCH_MAP.items() if k != "vbat"}
    c = dynax.load_trajectory(packed, "quadrotor", mapping=no_vbat)
    assert c.input_names == ("m1", "m2", "m3", "m4")


def test_ground_segments_found_on_a_real_flight(star_table):
    trajectory, notes = dynax.load_flight(STAR, mapping=NANOBENCH_MAP)
    assert trajectory.is_uniform
    # The vehicle rests on the floor until about 2-3 s, and the motors stop about 3.5 s before the end.
    first, last = notes.ground[0], notes.ground[-1]
    assert first[0] == 0.0 and 1.5 < first[1] < 4.0
    assert last[1] == pytest.approx(trajectory.duration, abs=0.02) and trajectory.duration - last[0] > 3.0
    assert not notes.glitches  # this flight is clean
    usable = np.asarray(notes.usable)
    assert 0.8 * len(trajectory) < usable.sum() < 0.9 * len(trajectory)
    runs = dynax.usable_segments(trajectory, notes, 100)
    assert runs and all(np.all(np.asarray(r.us[:, :4]) > 0) for r in runs)  # motors run in every kept run


def test_injected_glitches_are_flagged_with_column_and_time(tmp_path, star_table):
    header, table = star_table
    table = table.copy()
    t0 = table[0, 0]
    gyro = header.index("wx_vicon")
    k = 2000  # mid-flight
    table[k, gyro] = 312.0  # a gyro sample of hundreds of rad/s
    jump = 2500
    table[jump:, header.index("px")] += 0.3  # a position jump the velocity does not explain
    path = tmp_path / "glitched.csv.gz"
    _write(path, header, table)
    trajectory, notes = dynax.load_flight(path, mapping=NANOBENCH_MAP)
    found = {(g.column, g.kind): g for g in notes.glitches}
    rate = found[("p", "rate_range")]
    assert rate.start == pytest.approx(table[k, 0] - t0, abs=0.011) and rate.n_samples == 1 and rate.worst == 312.0
    position = found[("x,y,z", "position_jump")]
    assert position.start == pytest.approx(table[jump, 0] - t0, abs=0.011)
    usable = np.asarray(notes.usable)
    i = int(np.argmin(np.abs(np.asarray(trajectory.ts) - table[k, 0])))
    assert not usable[i] and usable[i - 5] and usable[i + 5]
    assert any("rate_range" in line for line in notes.describe())


def test_the_loader_names_a_missing_column(tmp_path, star_table):
    header, table = star_table
    path = tmp_path / "short.csv.gz"
    _write(path, header, table[:50])
    with pytest.raises(dynax.DataError, match="motor_speed_1"):
        dynax.load_trajectory(path, "quadrotor", mapping={**NANOBENCH_MAP, "m1": "motor_speed_1"})


def test_a_short_freeze_in_flight_is_noted_whatever_the_catch_up(tmp_path, star_table):
    # Honest motion capture never repeats px, py, pz while the vehicle moves; 0.12 s held (too short for
    # `stuck`'s 0.25 s) and eased back in steps below `max_jump` is still a fault, said once, as x,y,z.
    header, table = star_table
    table = table.copy()
    idx = [header.index(c) for c in ("px", "py", "pz")]
    k, n = 2000, 12
    held = table[k - 1, idx].copy()
    table[k : k + n, idx] = held
    for j in range(3):
        table[k + n + j, idx] = held + (table[k + n + j, idx] - held) * (j + 1) / 4
    assert np.max(np.linalg.norm(np.diff(table[k - 1 : k + n + 5, idx], axis=0), axis=1)) < 0.05
    path = tmp_path / "frozen.csv.gz"
    _write(path, header, table)
    trajectory, notes = dynax.load_flight(path, mapping=NANOBENCH_MAP)
    (frozen,) = [g for g in notes.glitches if g.kind == "stuck"]
    assert frozen.column == "x,y,z" and frozen.n_samples == n
    assert frozen.start == pytest.approx(table[k, 0] - table[0, 0], abs=0.011)
    assert not [g for g in notes.glitches if g.kind == "velocity"]  # the position is named, not its velocity
    i = int(np.argmin(np.abs(np.asarray(trajectory.ts) - table[k, 0])))
    assert not np.asarray(notes.usable)[i : i + n].any() and np.asarray(notes.usable)[i - 5]


def test_a_frame_logged_twice_is_no_freeze(tmp_path, star_table):
    # one repeat of the three columns (a frame logged twice, as on the floor of two NanoBench flights) says
    # nothing: the rule needs two repeats while the vehicle moves
    header, table = star_table
    table = table.copy()
    idx = [header.index(c) for c in ("px", "py", "pz")]
    table[2000, idx] = table[1999, idx]
    path = tmp_path / "twice.csv.gz"
    _write(path, header, table)
    assert not dynax.load_flight(path, mapping=NANOBENCH_MAP)[1].glitches
