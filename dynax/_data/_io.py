"""Read and write measured data: CSV, NPZ and MATLAB `.mat` files, per the data contract."""

from collections.abc import Mapping
import csv
import gzip
import io
import os
import pathlib
import re
import shlex
from typing import Literal
import zipfile
import zlib

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import DataError, UsageError
from .._precision import check_times_for_float32
from ._columns import ATTITUDE, columns_for, optional_groups, OPTIONAL_INPUTS
from ._flight_kinematics import attitude_angles, check_unit_quaternions
from ._matlab import read_mat_columns
from ._sampling import check_time_stamps, MAX_GAP, MIN_STEP
from ._trajectory import Trajectory
from ._velocities import check_velocities, velocity_pairs

TIME = "t"


# A decimal number as a measuring program writes it (what Python's float() accepts minus digit
# separators "1_0" and non-ASCII digits); nan/inf are read so that they are refused by name.
_NUMBER = re.compile(r"\s*[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf|infinity|nan)\s*", re.IGNORECASE)

# Beyond this magnitude a value in SI units is no measurement of these machines (and its square
# overflows a least-squares problem's sums or swamps every other sample in float64).
MAX_MAGNITUDE = 1e12


def _open_text(path):
    """The text of a file, refusing a directory, an unreadable file, binary data or bytes that are not UTF-8."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except IsADirectoryError:
        raise DataError("is a directory, not a data file", path=path) from None
    except OSError as e:
        raise DataError(f"cannot be read ({e.strerror or e})", path=path) from None
    if raw[:2] == b"\x1f\x8b":  # gzip's magic number: a compressed CSV (`.csv.gz`) reads like the CSV
        try:
            raw = gzip.decompress(raw)
        except EOFError:  # cut short (a copy or a download that stopped): say how far it reads
            read = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS).decompress(raw)
            lines = read.count(b"\n")
            raise DataError(
                f"is truncated: its gzip stream stops in line {lines + 1} (data row {lines}) without its end "
                "marker; copy or download the file again",
                path=path,
            ) from None
        except (OSError, zlib.error) as e:
            raise DataError(f"is a damaged gzip file ({e})", path=path) from None
    if b"\x00" in raw:
        line = raw.count(b"\n", 0, raw.index(b"\x00")) + 1
        raise DataError(f"is not a text CSV file (a NUL byte at line {line}); give a CSV, .npz or .mat file", path=path)
    try:
        return raw.decode("utf-8-sig")  # the byte-order mark spreadsheet programs write is stripped
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        raise DataError(
            f"is not UTF-8 text (byte 0x{raw[e.start]:02x} at line {line}); save it as UTF-8 CSV", path=path
        ) from None


def _read_csv(path):
    """The columns of a CSV file as lists of cells. Comment lines (`#`) before the header are skipped, as numpy's
    and pandas' readers can (the last one is the header where numbers follow it, as `numpy.savetxt` writes); a
    header with no comma but semicolons or tabs sets the separator (a spreadsheet's export in a locale whose
    decimal mark is the comma, or a tab-separated log)."""
    text = _open_text(path)
    lines = text.splitlines(keepends=True)
    skipped = 0
    while skipped < len(lines) and lines[skipped].lstrip().startswith("#"):
        skipped += 1
    first = lines[skipped] if skipped < len(lines) else ""
    delimiter = next((d for d in (";", "\t") if "," not in first and d in first), ",")
    if skipped and all(_NUMBER.fullmatch(c) for c in first.strip().split(delimiter)):
        # numpy's `savetxt(..., header=...)` writes the header as the last comment line
        skipped -= 1
        lines[skipped] = lines[skipped].lstrip().removeprefix("#").lstrip()
    text = "".join(lines[skipped:])
    try:
        reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
        try:
            header = next(reader)
        except StopIteration:
            raise DataError("the file is empty (a header row is required)", path=path) from None
        header = [h.strip() for h in header]
        rows = list(reader)
    except csv.Error as e:
        raise DataError(f"is not a readable CSV file ({e})", path=path) from None
    while rows and not any(c.strip() for c in rows[-1]):
        rows.pop()  # trailing blank lines
    _check_unique(path, header)
    for i, row in enumerate(rows):
        if [c.strip() for c in row] == header:
            raise DataError(
                f"the header repeats at file line {i + 2 + skipped}: two logs joined into one file? split it there "
                "and give the parts as two records",
                path=path,
                row=i + 1,
            )
        if len(row) != len(header):
            raise DataError(
                f"has {len(row)} fields but the header has {len(header)} (file line {i + 2 + skipped})",
                path=path,
                row=i + 1,
            )
    columns = {}
    for j, name in enumerate(header):
        columns[name] = [row[j] for row in rows]
    return columns


def _plain_name(column: str) -> str:
    """A column name without case, spaces or a unit in brackets: `"Q1 [rad]"` -> `"q1"`."""
    return re.sub(r"[\[(].*?[\])]", "", column).strip().lower().replace(" ", "")


def _alike_columns(wanted, raw, mapping) -> dict:
    """For the wanted names the file lacks (and no mapping names), the one column of the file that differs from the
    name only by case, spaces or a unit in brackets (time also as `time`): the `--map` a refusal can suggest whole."""
    out = {}
    for name in wanted:
        if name in mapping or name in raw:
            continue
        plain = {name.lower(), "time"} if name == TIME else {name.lower()}
        alike = [c for c in raw if _plain_name(c) in plain and not set(c) & set(",=")]
        if len(alike) == 1:
            out[name] = alike[0]
    return out


def _check_unique(path, names):
    seen = {}
    for j, name in enumerate(names):
        if name in seen:
            raise DataError(
                f"the column name appears twice (columns {seen[name] + 1} and {j + 1}); rename one of them",
                path=path,
                column=name,
            )
        seen[name] = j


def _to_float(path, name, values):
    """Convert a column to a 1-d float64 array, naming the first cell that is not a real number."""
    arr = np.asarray(values)
    if arr.dtype.kind in "US":  # text: the CSV's cells, or strings stored in an .npz
        arr = arr.reshape(-1)
        for i, v in enumerate(arr.tolist()):
            text = v if isinstance(v, str) else v.decode("latin-1")
            if not _NUMBER.fullmatch(text):
                hint = (
                    " (a decimal comma: write numbers with a decimal point, e.g. export the CSV in an English locale)"
                    if _NUMBER.fullmatch(text.replace(",", ".", 1))
                    else ""
                )
                raise DataError(f"non-numeric value {str(v)!r}{hint}", path=path, column=name, row=i + 1)
        return arr.astype(np.float64)
    if arr.dtype.kind == "c":
        raise DataError("holds complex numbers; a measured column must be real", path=path, column=name)
    if arr.dtype.kind not in "biuf":
        raise DataError(f"holds values of type {arr.dtype} where numbers are expected", path=path, column=name)
    if arr.ndim > 1 and sum(d > 1 for d in arr.shape) > 1:
        raise DataError(f"is an array of shape {arr.shape}; a column must be one vector", path=path, column=name)
    return arr.astype(np.float64).reshape(-1)


def _read_npz(path):
    if os.path.isdir(path):
        raise DataError("is a directory, not a data file", path=path)
    if not zipfile.is_zipfile(path):
        raise DataError("is not an .npz archive (not a zip file); give a CSV, .npz or .mat file", path=path)
    try:
        with np.load(path, allow_pickle=False) as data:
            return {str(k): data[k] for k in data.files}
    except Exception as e:
        raise DataError(f"cannot be read as .npz ({e})", path=path) from None


def _check_finite(path, column, arr, after):
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise DataError(f"non-finite value {float(arr[bad[0]])}{after}", path=path, column=column, row=int(bad[0]) + 1)
    big = np.flatnonzero(np.abs(arr) > MAX_MAGNITUDE)
    if big.size:
        raise DataError(
            f"value {float(arr[big[0]]):g}{after} is beyond {MAX_MAGNITUDE:g} in magnitude: no measurement "
            "in SI units is that large (wrong units, or a corrupt cell?)",
            path=path,
            column=column,
            row=int(big[0]) + 1,
        )


def _check_names(argument, given, allowed, system):
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        raise UsageError(
            f"`{argument}` names {unknown}, which are not columns of '{system}'; expected some of {list(allowed)}"
        )


class Sampling(eqx.Module):
    """What sampling `load_trajectory` requires of a record.

    **Arguments:**

    - `min_samples`: refuse files with fewer samples (the method's need; default 2).
    - `max_gap`: refuse a time step longer than this many median intervals (default 10): a gap
      in the record, which every method would otherwise bridge by holding or interpolating.
      `None` accepts gaps; then cut the record with `split_at_gaps`.
    - `min_step`: refuse a time step shorter than this fraction of the median interval (default
      0.01): a near-duplicate stamp, across which derivatives are noise. `None` accepts it.
    - `even`: the samples are evenly spaced and their stamps jitter (a logger that stamps each sample
      when it receives or writes it, not when it was read): re-stamp each on its tick of the steady clock
      fitted to the stamps (`steady_ticks`; a sample dropped leaves its tick out; default `False`: kept as
      recorded). Refused where two samples fall on one tick (stamps that jitter by half an interval or
      more). `check_records` says when a record needs it.
    """

    min_samples: int = 2
    max_gap: float | None = MAX_GAP
    min_step: float | None = MIN_STEP
    even: bool = False


def load_trajectory(
    path: str | os.PathLike,
    system: str,
    *,
    mapping: Mapping[str, str] | None = None,
    scale: Mapping[str, float] | None = None,
    offset: Mapping[str, float] | None = None,
    sampling: Sampling = Sampling(),
    check: bool = True,
    velocities: Literal["measured", "positions"] = "measured",
) -> Trajectory:
    """Load a measured data file as a `Trajectory`, checking it against the data contract.

    CSV (header row), `.npz` (one array per column) and MATLAB `.mat` (v4 to v7.3; vectors by
    name, matrix variables such as iddata-style `y`, `u` by column as `name[col]`, 0-based) are
    read. Sampling may be irregular; it is kept as recorded.

    **Arguments:**

    - `path`: the file.
    - `system`: `"acrobot"`, `"double_pendulum"`, `"linear_axis"`, `"helicopter"` or `"quadrotor"`;
      fixes the required columns (`t`, then the states, then the inputs). An optional input
      (the quadrotor's `vbat`) that the file lacks and no option names is left out of the inputs.
    - `mapping`: contract name -> column name in the file, for files named otherwise, e.g.
      `{"t": "time", "q1": "pos_meas1", ...}`. Unmapped names are looked up as they are.
    - `scale`: contract name -> factor multiplied into that column after reading (units), e.g.
      `{"force": 35.15}` when the file holds volts.
    - `offset`: contract name -> value added to that column after `scale`, e.g. `{"q1": math.pi}`
      for a rig whose shoulder reads 0 upright (the contract's angles are 0 hanging down).
    - `sampling`: what the time stamps must meet, a `Sampling`: at least `min_samples` samples
      (default 2), no step longer than `max_gap` median intervals (default 10: a gap in the record;
      `None` accepts gaps, then cut the record with `split_at_gaps`) or shorter than `min_step` of
      one (default 0.01: a near-duplicate stamp; `None` accepts it).
    - `check`: read the record for located faults (`dynax.check_records`: glitches, stuck sensors,
      wrapped angles, stretches where a velocity is not its position's derivative, a velocity that
      lags its angle, constant or zero columns, time in milliseconds) and warn a `DataWarning`
      naming each, with its rows and times (default `True`).
    - `velocities`: `"measured"` (default) reads the file's velocity columns; `"positions"` leaves them
      unread and estimates every velocity from the positions, as for a file of positions alone
      (below): the fix for a logged velocity that lags its angle (a driver's filter or backward
      difference; the `lag` check names it).

    **Returns:**

    A `Trajectory` whose times are a float64 numpy array (kept on the host, whatever JAX's
    mode) and whose states and inputs are JAX arrays in float64 when JAX's float64 mode is on
    (`jax.config.update("jax_enable_x64", True)`), float32 otherwise. In float32 mode a record
    whose times float32 cannot resolve to 1 % of a step raises a `PrecisionWarning` naming the file.

    **Raises:**

    `DataError` naming the file, column and row for: a file that is not UTF-8 CSV, `.npz` or
    `.mat` (or is a directory), a missing or duplicated column, a non-numeric (`"1_0"` included),
    complex or non-finite value, a value beyond $10^{12}$ in magnitude (before or after `scale`),
    time that does not strictly increase, a gap or a near-duplicate time stamp, too few samples,
    a non-zero column of an input the system ignores (`tau1` in a file read as `acrobot`),
    a measured velocity column that is not the derivative of its position column (other units, the
    opposite sign, another joint's column: `dynax._data._velocities`; the error names the gain and
    the `scale` that fixes a unit).
    `UsageError` for a `mapping`/`scale` that names no column of the system, or a zero or
    non-finite `scale` factor. A UTF-8 byte-order mark is ignored.

    Velocities that are not in the file (encoder positions alone) are estimated from the
    positions, when the file has none of the system's velocities and none is mapped (one present
    and another absent is a misnamed column, and an error); a quadrotor's world velocities and its body rates
    are two such groups, the rates estimated from the attitude (`attitude_angles`: its summed body-frame steps):

    - every system: by second-order central differences (`central_difference`), which do not lag, on
      the recorded time stamps but where a stamp disagrees with the positions (a logger that stalls
      between reading the encoders and the clock stamps them late): there on the time the positions
      imply (`sample_times_from_positions`; the returned times stay as recorded). A backward
      difference (what a motor driver logs) is the derivative half an interval earlier, which biases
      every parameter fitted to it. `choose_filter` reads the noise floor of such a velocity from
      the angle's backward difference, so the filter band is the one the logged velocities would give.
    """
    return load_columns(
        path, system, mapping=mapping, scale=scale, offset=offset, sampling=sampling, check=check, velocities=velocities
    )[0]


def load_columns(
    path: str | os.PathLike,
    system: str,
    *,
    mapping: Mapping[str, str] | None = None,
    scale: Mapping[str, float] | None = None,
    offset: Mapping[str, float] | None = None,
    sampling: Sampling = Sampling(),
    check: bool = True,
    velocities: Literal["measured", "positions"] = "measured",
) -> tuple[Trajectory, tuple[str, ...]]:
    """`load_trajectory`, and the names of the states it estimated (`OPTIONAL_STATES`: not in the file)."""
    path = str(path)
    state_names, input_names = columns_for(system)
    wanted = (TIME, *state_names, *input_names)
    mapping = dict(mapping or {})
    scale = dict(scale or {})
    _check_names("mapping", mapping, wanted, system)
    _check_names("scale", scale, wanted, system)
    for name, factor in scale.items():
        if not (np.isfinite(factor) and factor != 0):
            raise UsageError(f"`scale` for '{name}' must be a finite non-zero factor, got {factor}")
    offset = dict(offset or {})
    _check_names("offset", offset, wanted, system)
    for name, shift in offset.items():
        if not np.isfinite(shift):
            raise UsageError(f"`offset` for '{name}' must be finite, got {shift}")
    if not os.path.exists(path):
        raise DataError("no such file", path=path)
    suffix = pathlib.Path(path).suffix.lower()
    if suffix == ".npz":
        raw = _read_npz(path)
    elif suffix == ".mat":
        raw = read_mat_columns(path)
    else:
        raw = _read_csv(path)

    absent_inputs = {
        name
        for name in OPTIONAL_INPUTS.get(system, ())
        if mapping.get(name, name) not in raw
        and name not in mapping
        and name not in (scale or {})
        and name not in offset
    }
    if absent_inputs:
        input_names = tuple(name for name in input_names if name not in absent_inputs)
        wanted = (TIME, *state_names, *input_names)
    # Velocities are estimated only when the file has none of them: one present and another absent
    # is a misnamed column, not a record of positions alone (likewise a quadrotor's body rates).
    if velocities not in ("measured", "positions"):
        raise UsageError(f"`velocities` must be 'measured' or 'positions', got {velocities!r}")
    from_positions = velocities == "positions"
    optional = {}
    for group in optional_groups(system):
        from_attitude = any(source == ATTITUDE for source, _ in group.values())
        if (from_positions and not from_attitude) or not any(name in mapping or name in raw for name in group):
            optional.update(group)
    if from_positions and not optional:
        raise UsageError(f"`velocities='positions'`: '{system}' has no velocity that is estimated from a position")
    values = {}
    for name in wanted:
        column = mapping.get(name, name)
        if name in optional and from_positions:
            continue
        if column not in raw:
            if name in optional:
                continue
            mapped = f" (mapped from '{name}')" if column != name else ""
            advice = "" if name in mapping else "; use a mapping (--map NAME=COLUMN) if it is named otherwise"
            alike = _alike_columns(wanted, raw, mapping)
            if alike:
                given = ",".join(f"{k}={v}" for k, v in alike.items())
                advice += f"; columns named alike but for case, spaces or a unit: --map {shlex.quote(given)}"
            raise DataError(f"missing column{mapped}; the file has {sorted(raw)}{advice}", path=path, column=column)
        arr = _to_float(path, column, raw[column])
        _check_finite(path, column, arr, "")
        factor = float(scale.get(name, 1.0))
        if factor != 1.0:
            with np.errstate(over="ignore"):
                arr = arr * factor
            _check_finite(path, column, arr, f" after scaling by {factor:g}")
        arr = arr + float(offset.get(name, 0.0))
        values[name] = arr

    _check_ignored_inputs(path, system, raw, mapping)
    n = values[TIME].shape[0]
    for name, arr in values.items():
        if arr.shape[0] != n:
            raise DataError(f"has {arr.shape[0]} samples but time has {n}", path=path, column=mapping.get(name, name))
    need = max(sampling.min_samples, 2)
    if n < need:
        raise DataError(f"has {n} samples; at least {need} are needed", path=path)
    ts = values[TIME]
    column = mapping.get(TIME, TIME)
    check_time_stamps(ts, path=path, column=column, max_gap=sampling.max_gap, min_step=sampling.min_step)
    if sampling.even:
        ts = values[TIME] = even_stamps(ts, path=path, column=column)
    from ._derivatives import backward_difference, central_difference, sample_times_from_positions

    difference = {"backward": backward_difference, "central": central_difference}
    # differenced on the times the positions were read at: a stamp taken late (a logger's stall between
    # reading the encoders and the clock) would divide their steps by the wrong intervals
    sources = [values[source] for source, _ in optional.values() if source != ATTITUDE]
    sampled = sample_times_from_positions(ts, np.stack(sources, 1))[0] if sources else ts
    angles = None
    for name, (source, how) in optional.items():
        if source == ATTITUDE:  # a body rate: the derivative of the attitude's summed body-frame steps
            if angles is None:  # from unit quaternions only (a zero row would differentiate into NaN)
                quats = np.stack([values[c] for c in ("qw", "qx", "qy", "qz")], axis=1)
                check_unit_quaternions(quats, path, mapping)
                angles = attitude_angles(quats)
            values[name] = np.asarray(difference[how](sampled, angles[:, ("p", "q", "r").index(name)]))
        else:
            values[name] = np.asarray(difference[how](sampled, values[source]))
    measured = {v: q for v, q in velocity_pairs(state_names).items() if v not in optional}
    check_velocities(ts, values, measured, path=path, columns={n: mapping.get(n, n) for n in wanted}, scale=scale)
    xs = np.stack([values[s] for s in state_names], axis=1)
    us = np.stack([values[s] for s in input_names], axis=1)
    check_times_for_float32(ts, path)
    trajectory = Trajectory(ts, jnp.asarray(xs), jnp.asarray(us), state_names, input_names, system, path)
    if check:
        from ._sanity import check_record

        check_record(trajectory, estimated=tuple(optional)).warn(stacklevel=3)
    return trajectory, tuple(optional)


def even_stamps(ts: np.ndarray, *, path=None, column: str = TIME) -> np.ndarray:
    """The ticks of the steady clock the stamps jitter about (`Sampling(even=True)`; `steady_ticks`): evenly
    spaced, a sample dropped leaving its tick out. Refused (`DataError`) where two samples fall on one tick:
    the stamps jitter by half an interval or more, and no steady clock can be read from them."""
    from ._sampling import steady_ticks

    found = steady_ticks(ts)
    if found is None:
        raise DataError(
            "even time stamps asked for, but the stamps cannot be read as a steady clock's ticks: two samples "
            "fall on one tick (stamps that jitter by half an interval or more); keep the stamps as recorded",
            path=path,
            column=column,
        )
    return found[0]


# Contract input columns a system ignores: a file that holds them non-zero was recorded on another system.
IGNORED_INPUTS = {"acrobot": {"tau1": "double_pendulum"}}


def _check_ignored_inputs(path, system, raw, mapping):
    for name, other in IGNORED_INPUTS.get(system, {}).items():
        if name not in raw or name in mapping.values():
            continue
        arr = _to_float(path, name, raw[name])
        with np.errstate(invalid="ignore"):
            nonzero = np.flatnonzero(np.isfinite(arr) & (arr != 0))
        if nonzero.size:
            k = int(nonzero[np.argmax(np.abs(arr[nonzero]))])
            raise DataError(
                f"is non-zero in {nonzero.size} of {arr.size} samples (largest {arr[k]:.4g} at row {k + 1}), but "
                f"'{system}' has no such input: it would be dropped and its effect ascribed to the model. Read the "
                f"file as '{other}', or zero or remove the column if it is not applied",
                path=path,
                column=name,
            )


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


def parse_assignments(text: str | None, argument: str, *, numeric: bool, zero: bool = False) -> dict:
    """Parse `NAME=VALUE,NAME=VALUE` (the CLI's `--map`, `--scale` and `--offset`), naming what is
    malformed; numeric values must be finite, and non-zero unless `zero` (an offset may be 0)."""
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
        if name in result:
            raise UsageError(f"{argument}: '{name}' is given twice")
        if numeric:
            what = "value" if zero else "factor"
            if not _NUMBER.fullmatch(value):
                raise UsageError(f"{argument}: the {what} for '{name}' is not a number: '{value}'")
            value = float(value)
            if not np.isfinite(value):
                raise UsageError(f"{argument}: the {what} for '{name}' is not finite: '{value}'")
            if value == 0 and not zero:
                raise UsageError(f"{argument}: the factor for '{name}' is zero, which would erase the column")
        result[name] = value
    return result
