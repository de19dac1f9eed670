"""Property-based (hypothesis): the loaders, fed random malformed files, refuse them with a message or
return exactly what the file says; never another exception, never a non-finite value."""

import pathlib
import tempfile

from hypothesis import given, HealthCheck, settings
from hypothesis import strategies as st
import numpy as np
import pytest

import dynax
from dynax.internal import MAX_MAGNITUDE, parse_assignments

NAMES = ("t", "q1", "q2", "dq1", "dq2", "tau2")
SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

numbers = st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr)
oddities = st.sampled_from(
    [
        "",
        " ",
        "1_0",
        "nan",
        "-inf",
        "1e400",
        " 2.5 ",
        "0x1f",
        "1,5",
        "\u0662",
        "1e",
        ".",
        "+-1",
        "True",
        "None",
        "1e308",
        "-1e13",
        "\x00",
        "\ufeff1",
        "'1'",
    ]
)
cells = st.one_of(numbers, numbers, oddities, st.text(max_size=6))


def _float_or_none(cell):
    """An independent reading of a cell: Python's float, minus what the contract refuses."""
    text = cell.strip()
    if "_" in text or not text.isascii():
        return None
    try:
        return float(text)
    except ValueError:
        return None


@st.composite
def csv_files(draw):
    n = draw(st.integers(0, 12))
    header = list(NAMES)
    shuffle = draw(st.permutations(range(len(header))))
    header = [header[i] for i in shuffle]
    if draw(st.booleans()):
        header.append(draw(st.sampled_from([*NAMES, "extra", ""])))  # an extra, possibly duplicated, column
    if draw(st.integers(0, 5)) == 0:
        header.remove(draw(st.sampled_from(NAMES)))
    dt = draw(st.sampled_from([0.01, 1e-3, 0.5]))
    rows = []
    for i in range(n):
        row = []
        for name in header:
            if draw(st.integers(0, 9)) == 0:
                row.append(draw(cells))
            elif name == "t":
                row.append(repr(i * dt))
            else:
                row.append(repr(draw(st.floats(-10, 10))))
        if draw(st.integers(0, 30)) == 0:
            row = row[:-1]  # ragged
        rows.append(row)
    bom = "\ufeff" if draw(st.integers(0, 5)) == 0 else ""
    return bom + "\n".join(",".join(r) for r in [header, *rows]) + "\n", header, rows


def _check_loaded(tr, header, rows):
    ts, xs, us = np.asarray(tr.ts), np.asarray(tr.xs), np.asarray(tr.us)
    assert np.all(np.isfinite(ts)) and np.all(np.isfinite(xs)) and np.all(np.isfinite(us))
    assert np.all(np.abs(xs) <= MAX_MAGNITUDE) and np.all(np.diff(ts) > 0)
    table = {name: [_float_or_none(r[j]) for r in rows] for j, name in enumerate(header)}
    loaded = {"t": ts, **{n: xs[:, i] for i, n in enumerate(tr.state_names)}, "tau2": us[:, 0]}
    for name, values in loaded.items():
        np.testing.assert_array_equal(values, np.asarray(table[name], dtype=float))


@SETTINGS
@given(csv_files())
def test_random_csv_is_refused_with_a_message_or_read_exactly(case):
    text, header, rows = case
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "run.csv"
        path.write_text(text, encoding="utf-8")
        try:
            tr = dynax.load_trajectory(path, "acrobot")
        except (dynax.DataError, dynax.UsageError) as e:
            assert str(path) in str(e) and len(str(e)) > len(str(path)) + 10
            return
    _check_loaded(tr, header, rows)


@SETTINGS
@given(st.binary(max_size=600), st.sampled_from(["run.csv", "run.npz", "run.mat", "run.txt"]))
def test_random_bytes_are_refused_with_a_message(data, name):
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / name
        path.write_bytes(data)
        with pytest.raises((dynax.DataError, dynax.UsageError)) as e:
            dynax.load_trajectory(path, "acrobot")
        assert str(path) in str(e.value)


arrays = st.one_of(
    st.builds(
        lambda v: np.asarray(v), st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=5, max_size=5)
    ),
    st.builds(
        lambda v: np.asarray(v, dtype=complex), st.lists(st.complex_numbers(max_magnitude=10), min_size=5, max_size=5)
    ),
    st.builds(lambda v: np.asarray(v), st.lists(st.integers(-5, 5), min_size=5, max_size=5)),
    st.builds(lambda v: np.asarray(v), st.lists(st.booleans(), min_size=5, max_size=5)),
    st.builds(lambda v: np.asarray(v), st.lists(st.text(max_size=3), min_size=5, max_size=5)),
    st.builds(lambda v: np.asarray(v).reshape(5, 2), st.lists(st.floats(-1, 1), min_size=10, max_size=10)),
    st.builds(lambda v: np.asarray(v), st.lists(st.floats(-1, 1), min_size=0, max_size=8)),
)


@SETTINGS
@given(st.dictionaries(st.sampled_from([*NAMES, "x"]), arrays, min_size=1, max_size=7))
def test_random_npz_is_refused_with_a_message_or_read_exactly(columns):
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "run.npz"
        columns = dict(columns)
        if "t" in columns and columns["t"].dtype.kind == "f" and columns["t"].shape == (5,):
            columns["t"] = np.arange(5) * 0.01  # a valid clock, so that other columns decide
        np.savez(path, **columns)
        try:
            tr = dynax.load_trajectory(path, "acrobot")
        except (dynax.DataError, dynax.UsageError) as e:
            assert str(path) in str(e) and "np.str_" not in str(e)
            return
    assert np.all(np.isfinite(np.asarray(tr.xs))) and np.all(np.isfinite(np.asarray(tr.us)))
    for i, name in enumerate(tr.state_names):
        np.testing.assert_array_equal(np.asarray(tr.xs[:, i]), np.asarray(columns[name], dtype=float).reshape(-1))


@SETTINGS
@given(st.text(max_size=30), st.booleans())
def test_random_assignments_are_refused_with_a_message_or_parsed(text, numeric):
    try:
        parsed = parse_assignments(text, "--scale" if numeric else "--map", numeric=numeric)
    except dynax.UsageError as e:
        assert str(e).startswith("--scale" if numeric else "--map")
        return
    for name, value in parsed.items():
        assert name and name == name.strip() and "=" not in name
        if numeric:
            assert np.isfinite(value) and value != 0
