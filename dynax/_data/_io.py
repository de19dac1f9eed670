"""Read and write measured data: CSV, NPZ and MATLAB `.mat` files, per the data contract."""

import csv
import os
import pathlib
from collections.abc import Mapping

import jax.numpy as jnp
import numpy as np

from .._errors import DataError, UsageError
from ._columns import columns_for, OPTIONAL_STATES
from .._precision import check_times_for_float32
from ._matlab import read_mat_columns
from ._trajectory import Trajectory

TIME = "t"


def _read_csv(path):
    with open(path, newline="") as f:
        reader = csv.reader(f)
        try:
            header = next(reader)
        except StopIteration:
            raise DataError("the file is empty (a header row is required)", path=path) from None
        header = [h.strip() for h in header]
        rows = list(reader)
    while rows and not any(c.strip() for c in rows[-1]):
        rows.pop()  # trailing blank lines
    for i, row in enumerate(rows):
        if len(row) != len(header):
            raise DataError(
                f"has {len(row)} fields but the header has {len(header)} (file line {i + 2})", path=path, row=i + 1
            )
    columns = {}
    for j, name in enumerate(header):
        columns[name] = [row[j] for row in rows]
    return columns


def _to_float(path, name, values):
    """Convert a column to float64, naming the first bad cell."""
    try:
        return np.asarray(values, dtype=np.float64).reshape(-1)
    except (ValueError, TypeError):
        for i, v in enumerate(values):
            try:
                float(v)
            except (ValueError, TypeError):
                raise DataError(f"non-numeric value {v!r}", path=path, column=name, row=i + 1) from None
        raise


def _read_npz(path):
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except Exception as e:
        raise DataError(f"cannot be read as .npz ({e})", path=path) from None


def _check_names(argument, given, allowed, system):
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        raise UsageError(
            f"`{argument}` names {unknown}, which are not columns of '{system}'; expected some of {list(allowed)}"
        )


def load_trajectory(
    path: str | os.PathLike,
    system: str,
    *,
    mapping: Mapping[str, str] | None = None,
    scale: Mapping[str, float] | None = None,
    min_samples: int = 2,
) -> Trajectory:
    """Load a measured data file as a `Trajectory`, checking it against the data contract.

    CSV (header row), `.npz` (one array per column) and MATLAB `.mat` (v4 to v7.3; vectors by
    name, matrix variables such as iddata-style `y`, `u` by column as `name[col]`, 0-based) are
    read. Sampling may be irregular; it is kept as recorded.

    **Arguments:**

    - `path`: the file.
    - `system`: `"acrobot"`, `"double_pendulum"`, `"linear_axis"` or `"helicopter"`; fixes the
      required columns (`t`, then the states, then the inputs).
    - `mapping`: contract name -> column name in the file, for files named otherwise, e.g.
      `{"t": "time", "q1": "pos_meas1", ...}`. Unmapped names are looked up as they are.
    - `scale`: contract name -> factor multiplied into that column after reading (units), e.g.
      `{"force": 35.15}` when the file holds volts.
    - `min_samples`: refuse files with fewer samples (the method's need).

    **Returns:**

    A `Trajectory` whose times are a float64 numpy array (kept on the host, whatever JAX's
    mode) and whose states and inputs are JAX arrays in float64 when JAX's float64 mode is on
    (`jax.config.update("jax_enable_x64", True)`), float32 otherwise. In float32 mode a record
    whose times float32 cannot resolve to 1 % of a step raises a `PrecisionWarning` naming the file.

    **Raises:**

    `DataError` naming the file, column and row for: a missing column, a non-numeric or
    non-finite value, time that does not strictly increase, too few samples.
    `UsageError` for a `mapping`/`scale` that names no column of the system.

    For `linear_axis`, a missing `dq` column is estimated from `q` by central differences.
    """
    path = str(path)
    state_names, input_names = columns_for(system)
    wanted = (TIME, *state_names, *input_names)
    mapping = dict(mapping or {})
    scale = dict(scale or {})
    _check_names("mapping", mapping, wanted, system)
    _check_names("scale", scale, wanted, system)
    if not os.path.exists(path):
        raise DataError("no such file", path=path)
    suffix = pathlib.Path(path).suffix.lower()
    if suffix == ".npz":
        raw = _read_npz(path)
    elif suffix == ".mat":
        raw = read_mat_columns(path)
    else:
        raw = _read_csv(path)

    optional = OPTIONAL_STATES.get(system, {})
    values = {}
    for name in wanted:
        column = mapping.get(name, name)
        if column not in raw:
            if name in optional and name not in mapping:
                continue
            mapped = f" (mapped from '{name}')" if column != name else ""
            raise DataError(
                f"missing column{mapped}; the file has {sorted(raw)}"
                + ("" if name in mapping else "; use a mapping (--map NAME=COLUMN) if it is named otherwise"),
                path=path,
                column=column,
            )
        arr = _to_float(path, column, raw[column])
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise DataError(f"non-finite value {float(arr[bad[0]])}", path=path, column=column, row=int(bad[0]) + 1)
        values[name] = arr * float(scale.get(name, 1.0))

    n = values[TIME].shape[0]
    for name, arr in values.items():
        if arr.shape[0] != n:
            raise DataError(f"has {arr.shape[0]} samples but time has {n}", path=path, column=mapping.get(name, name))
    if n < max(min_samples, 2):
        raise DataError(f"has {n} samples; at least {max(min_samples, 2)} are needed", path=path)
    ts = values[TIME]
    steps = np.diff(ts)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise DataError(
            f"time does not strictly increase ({float(ts[k - 1])} then {float(ts[k])})",
            path=path,
            column=mapping.get(TIME, TIME),
            row=k + 1,
        )
    from ._derivatives import central_difference

    for name, source in optional.items():
        if name not in values:
            values[name] = np.asarray(central_difference(ts, values[source]))
    xs = np.stack([values[s] for s in state_names], axis=1)
    us = np.stack([values[s] for s in input_names], axis=1)
    check_times_for_float32(ts, path)
    return Trajectory(ts, jnp.asarray(xs), jnp.asarray(us), state_names, input_names, system, path)


def save_trajectory(trajectory: Trajectory, path: str | os.PathLike) -> None:
    """Write a `Trajectory` as a contract CSV (`t`, states, inputs) or, for a `.npz` path, as NPZ.

    The file is written atomically (a temporary file renamed into place).
    """
    path = pathlib.Path(path)
    names = (TIME, *trajectory.state_names, *trajectory.input_names)
    table = np.column_stack([np.asarray(trajectory.ts), np.asarray(trajectory.xs), np.asarray(trajectory.us)])
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        if path.suffix.lower() == ".npz":
            with open(tmp, "wb") as f:
                np.savez(f, **{n: table[:, i] for i, n in enumerate(names)})
        else:
            np.savetxt(tmp, table, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def parse_assignments(text: str | None, argument: str, *, numeric: bool) -> dict:
    """Parse `NAME=VALUE,NAME=VALUE` (the CLI's `--map` and `--scale`), naming what is malformed."""
    result = {}
    if not text:
        return result
    for item in text.split(","):
        if not item.strip():
            continue
        name, sep, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name or not value:
            raise UsageError(f"{argument}: '{item}' is not of the form NAME=VALUE")
        if numeric:
            try:
                value = float(value)
            except ValueError:
                raise UsageError(f"{argument}: the factor for '{name}' is not a number: '{value}'") from None
            if not np.isfinite(value):
                raise UsageError(f"{argument}: the factor for '{name}' is not finite: '{value}'")
        result[name] = value
    return result
