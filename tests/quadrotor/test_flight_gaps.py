"""Gaps in a flight log's time: up to `MAX_FLIGHT_GAP` (3) sample intervals are interpolated without a note, and
against a synthetic flight's truth (scipy's DOP853, not dynax's model) the interpolated states miss it by less than
the noise such a flight logs (synthetic_flight: 0.5 mm, 5 mm/s, 0.02 rad/s); a longer gap is noted where it is, its
interpolated samples left out of fitting."""

import numpy as np
import pytest

import dynax

from .synthetic_flight import quadrotor_flight, STATE_NAMES


def _with_gap(folder, intervals, first=300):
    """A noise-free synthetic flight written without samples `first .. first + intervals - 2`: `intervals`
    intervals between the recorded samples either side; `(path, truth)`."""
    truth = quadrotor_flight(6.0, seed=1, noise=False)
    table = np.column_stack([np.asarray(truth.ts), np.asarray(truth.xs), np.asarray(truth.us)])
    table = np.delete(table, np.arange(first, first + intervals - 1), axis=0)
    path = folder / "gap.csv"
    header = ["t", *STATE_NAMES, *truth.input_names]
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.17g}" for v in row) for row in table))
    return path, truth


@pytest.mark.parametrize("intervals", [2, 3])
def test_a_gap_of_up_to_three_intervals_is_bridged_within_the_noise(tmp_path, intervals):
    path, truth = _with_gap(tmp_path, intervals)
    data, notes = dynax.load_flight(path)
    assert np.allclose(np.asarray(data.ts), np.asarray(truth.ts))  # the grid is the flight's own
    missing = slice(300, 300 + intervals - 1)
    error = np.abs(np.asarray(data.xs)[missing] - np.asarray(truth.xs)[missing])
    assert error[:, :3].max() < 5e-4 and error[:, 7:10].max() < 5e-3 and error[:, 10:13].max() < 2e-2
    assert not notes.glitches and np.asarray(notes.usable).all()


@pytest.mark.parametrize("intervals", [4, 5, 10])
def test_a_longer_gap_is_noted_where_it_is_and_left_out(tmp_path, intervals):
    path, truth = _with_gap(tmp_path, intervals)
    data, notes = dynax.load_flight(path)
    (gap,) = notes.glitches
    assert gap.kind == "gap" and gap.column == "t" and gap.n_samples == intervals - 1
    assert gap.start == pytest.approx(2.99) and gap.stop == pytest.approx(2.99 + 0.01 * intervals)
    usable = np.asarray(notes.usable)
    assert not usable[300 : 300 + intervals - 1].any() and usable[299] and usable[300 + intervals - 1]
    assert gap.row == 301 and f"{intervals - 1} samples interpolated" in notes.describe()[0]
