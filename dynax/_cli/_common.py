"""Options and checks shared by the sub-commands: data options, output paths, JSON inputs.

Everything here runs before any work, so that a user's mistake costs a second, not a fit.
"""

import argparse
import json
import math
import os
import pathlib
import re
import tempfile

from .._data import parse_assignments
from .._errors import DataError, UsageError
from ._notes import current

# What each sub-command writes to --out.
OUTPUT_KIND = {"demo": "directory", "diagnose": "directory", "identify": "file", "fit": "file", "evaluate": "file"}
# The arguments that name files a sub-command reads.
INPUT_ARGUMENTS = ("data", "validation", "model", "nominal")
# Files a report folder may hold for dynax to replace it whole (what `demo` and `diagnose` write).
REPORT_SUFFIXES = (".json", ".md", ".png", ".csv", ".npz", ".svg", ".pdf")


def add_data_options(parser: argparse.ArgumentParser) -> None:
    """Add the contract's `--map NAME=COLUMN,...` and `--scale NAME=FACTOR,...`, and `--offset NAME=VALUE,...`."""
    parser.add_argument("--map", default=None, help="NAME=COLUMN,... for files whose columns are named otherwise")
    parser.add_argument("--scale", default=None, help="NAME=FACTOR,... multiplied into columns (units)")
    parser.add_argument(
        "--offset",
        default=None,
        help="NAME=VALUE,... added to columns after --scale (an angle's zero: q1=3.14159 for a rig "
        "that reads 0 upright)",
    )


def add_time_option(parser: argparse.ArgumentParser) -> None:
    """Add `--even-times` (`identify`, `diagnose`): re-stamp each record's samples evenly."""
    parser.add_argument(
        "--even-times",
        action="store_true",
        help="the samples are evenly spaced and their time stamps jitter (a logger that stamps each sample "
        "when it receives or writes it): re-stamp each on its tick of the steady clock fitted to the record's "
        "stamps (a dropped sample leaves its tick out)",
    )


def add_velocity_option(parser: argparse.ArgumentParser) -> None:
    """Add `--velocities measured|positions` (`identify`; `diagnose` has its own, with `auto`)."""
    parser.add_argument(
        "--velocities",
        choices=("measured", "positions"),
        default="measured",
        help="measured (default): the files' velocity columns as recorded; positions: leave them unread "
        "and estimate the velocities from the positions (central differences, which do not lag, on the times "
        "the positions imply where a time stamp disagrees with them): for a "
        "logged velocity that lags its angle",
    )


def data_options(args: argparse.Namespace) -> tuple[dict, dict, dict]:
    """The parsed `--map`, `--scale` and `--offset` (UsageError naming the malformed one)."""
    return (
        parse_assignments(args.map, "--map", numeric=False),
        parse_assignments(args.scale, "--scale", numeric=True),
        parse_assignments(args.offset, "--offset", numeric=True, zero=True),
    )


def output_file(path: str, example: str) -> pathlib.Path:
    """`--out` as a file path, refusing an existing directory (with an example file name)."""
    out = pathlib.Path(path)
    if out.is_dir():
        raise UsageError(f"--out {out} is a directory; give a file name such as {out / example}")
    return out


def _writable_folder(out: pathlib.Path) -> None:
    """Refuse an output whose nearest existing ancestor is a file or a folder we may not write in."""
    ancestor = out.absolute().parent
    while not ancestor.exists():
        if ancestor.is_symlink():
            raise UsageError(f"--out {out}: {ancestor} is a broken link")
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise UsageError(f"--out {out}: {ancestor} is a file, not a folder")
    try:  # a real probe: permissions, ACLs and read-only mounts all answer it
        with tempfile.TemporaryFile(dir=ancestor, prefix=".dynax-probe."):
            pass
    except OSError as e:
        reason = "permission denied" if isinstance(e, PermissionError) else (e.strerror or str(e))
        raise UsageError(f"--out {out}: cannot write in the folder {ancestor} ({reason})") from None


# The temporary names written beside --out (`.NAME.staging.XXXXXXXX`, `.NAME.XXXXXXXX.tmp`) add this many
# characters to its last component.
_STAGING_CHARS = 24


def _name_lengths(out: pathlib.Path) -> None:
    """Refuse an --out whose name (or a folder's on the way) is longer than the file system allows."""
    try:
        name_max = os.pathconf(os.getcwd(), "PC_NAME_MAX")
        path_max = os.pathconf(os.getcwd(), "PC_PATH_MAX")
    except (OSError, ValueError, AttributeError):
        name_max, path_max = 255, 4096
    if len(os.fsencode(str(out.absolute()))) + _STAGING_CHARS > path_max:
        raise UsageError(
            f"--out: the path is {len(os.fsencode(str(out.absolute())))} bytes long; the file system "
            f"allows {path_max} (less {_STAGING_CHARS} for the temporary name)"
        )
    for part in out.parts:
        if len(os.fsencode(part)) > name_max:
            raise UsageError(
                f"--out: the name '{part[:40]}...' is {len(os.fsencode(part))} bytes long; the file system "
                f"allows {name_max}"
            )
    if len(os.fsencode(out.name)) + _STAGING_CHARS > name_max:
        raise UsageError(
            f"--out: the name '{out.name[:40]}...' is {len(os.fsencode(out.name))} bytes long; with the "
            f"temporary name it is written under first it must stay under {name_max - _STAGING_CHARS}"
        )


def _report_folder_replaceable(out: pathlib.Path) -> None:
    """An existing --out folder is replaced whole; refuse one that holds anything dynax did not write."""
    foreign = sorted(
        p.name
        for p in out.iterdir()
        if not (p.is_file() and not p.is_symlink() and p.suffix.lower() in REPORT_SUFFIXES)
    )
    if foreign:
        raise UsageError(
            f"--out {out} exists and holds {foreign[:3]}{' ...' if len(foreign) > 3 else ''}, which dynax did not "
            "write; the report folder is replaced whole, so give a new or empty folder (or a previous report's)"
        )


def check_output(path, *, kind: str, inputs=()) -> pathlib.Path:
    """Refuse an `--out` that cannot be written, before any work is done.

    **Arguments:**

    - `path`: the `--out` argument.
    - `kind`: `"file"` (replaced atomically, so an existing device or pipe such as `/dev/null` is
      refused rather than replaced) or `"directory"` (a report folder, replaced whole).
    - `inputs`: the paths the command reads; `--out` may not be one of them (nor, for a folder,
      contain one).

    **Raises:** `UsageError` naming the problem: a folder where a file is due or the reverse, a
    parent that is a file, a folder without write permission, an input that would be overwritten,
    a report folder holding other files.
    """
    if not str(path).strip():
        raise UsageError("--out is empty")
    out = pathlib.Path(path)
    _name_lengths(out)
    if kind == "file" and out.is_dir():
        raise UsageError(f"--out {out} is a directory; give a file name such as {out / 'result.json'}")
    if kind == "directory" and out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file; give a folder for the report")
    if kind == "file" and out.exists() and not out.is_file():
        raise UsageError(
            f"--out {out} is not a regular file (a device, pipe or socket); the result is written to a "
            "temporary file renamed into place, which would replace it: give a file path"
        )
    _writable_folder(out)
    target = out.resolve()
    for given in inputs:
        if given is None or not os.path.exists(given):
            continue
        source = pathlib.Path(given).resolve()
        if source == target:
            raise UsageError(f"--out {out} is the input {given}; writing would overwrite it")
        if kind == "directory" and target in source.parents:
            raise UsageError(f"--out {out} holds the input {given}; replacing the report folder would delete it")
    if kind == "directory" and out.is_dir():
        _report_folder_replaceable(out)
    return out


def check_command_output(args: argparse.Namespace) -> None:
    """`check_output` for a parsed command line (the main entry point calls it before running)."""
    kind = OUTPUT_KIND.get(getattr(args, "command", None))
    if kind is None or getattr(args, "out", None) is None:
        return
    inputs = []
    for name in INPUT_ARGUMENTS:  # a data argument may take several files (TRAIN..., --validation ...)
        given = getattr(args, name, None)
        inputs.extend(given if isinstance(given, (list, tuple)) else [given])
    check_output(args.out, kind=kind, inputs=inputs)


def _refuse_constant(what, path, text=""):
    """`json.loads`' `parse_constant`: refuse `NaN` and `Infinity`, naming the key they stand under and the line."""

    def refuse(name):
        where = ""
        found = re.search(rf"(?<![\w\"]){re.escape(name)}(?![\w\"])", text)
        if found:
            keys = re.findall(r'"((?:[^"\\]|\\.)*)"\s*:', text[: found.start()])
            line = text.count("\n", 0, found.start()) + 1
            where = f" in '{keys[-1]}' (line {line})" if keys else f" (line {line})"
        raise DataError(f"holds {name}{where}, which is not a JSON number; {what} must hold finite numbers", path=path)

    return refuse


def read_json_object(path, what: str) -> dict:
    """Read a JSON file that must hold an object, refusing what is not (as `DataError` naming the file).

    Refused: a missing file, a directory, bytes that are not UTF-8, invalid JSON, `NaN`/`Infinity`
    and numbers that overflow to infinity, and a top-level value that is not an object.
    """
    try:
        raw = pathlib.Path(path).read_bytes()
    except FileNotFoundError:
        raise DataError("no such file", path=path) from None
    except IsADirectoryError:
        raise DataError(f"is a directory, not {what}", path=path) from None
    except OSError as e:
        raise DataError(f"cannot be read ({e.strerror or e})", path=path) from None

    def number(text):
        value = float(text)
        if not math.isfinite(value):
            raise DataError(f"holds the number {text}, which overflows; {what} must hold finite numbers", path=path)
        return value

    try:
        text = raw.decode("utf-8-sig")
        obj = json.loads(text, parse_float=number, parse_constant=_refuse_constant(what, path, text))
    except UnicodeDecodeError:
        raise DataError(f"is not UTF-8 text (a binary file?); {what} is JSON", path=path) from None
    except json.JSONDecodeError as e:
        raise DataError(f"is not valid JSON ({e})", path=path) from None
    if not isinstance(obj, dict):
        raise DataError(f"holds a JSON {type(obj).__name__}, not the object {what} is", path=path)
    return obj


def read_nominal_parameters(path) -> dict[str, float]:
    """The `parameters` object of a `--nominal` JSON (e.g. written by `dynax identify`), checked.

    **Raises:** `DataError` naming the file and the entry: no `parameters` object, or a value that
    is not a finite number (a string, `null`, `NaN`, a list).
    """
    obj = read_json_object(path, "a --nominal parameters file")
    parameters = obj.get("parameters")
    if not isinstance(parameters, dict):
        found = "no 'parameters'" if parameters is None else f"a JSON {type(parameters).__name__} as 'parameters'"
        raise DataError(f"has {found}; --nominal needs an object of name: number", path=path)
    values = {}
    for name, value in parameters.items():
        try:
            ok = not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(float(value))
        except OverflowError:
            ok = False
        if not ok:
            raise DataError(f"parameter '{name}' is {json.dumps(value)[:40]}, not a finite number", path=path)
        values[name] = float(value)
    return values


# Standard errors scale with the residual standard deviation; estimated from d degrees of freedom
# it is uncertain by about 1/sqrt(2 d) (chi-square), so d >= 8 keeps the errors within about 25 %.
MIN_RESIDUAL_DOF = 8
# The most base parameters dynax identifies for one system (two-link arm with Coulomb friction).
MAX_BASE_PARAMETERS = 9


def min_fit_samples(n_parameters: int = MAX_BASE_PARAMETERS, *, trim: int = 2) -> int:
    """The fewest samples a fit of `n_parameters` is run on: one equation per sample at least, the
    `trim` samples lost to differentiation at the ends, and `MIN_RESIDUAL_DOF` left over for the
    standard errors. Fewer is refused rather than fitted (3 samples fit 7 parameters exactly, with
    standard errors of noise)."""
    return n_parameters + MIN_RESIDUAL_DOF + trim


def finite_seconds(value: float, argument: str) -> float:
    """A positive finite number of seconds, or a `UsageError` naming the argument."""
    if not (math.isfinite(value) and value > 0):
        raise UsageError(f"{argument} must be a positive finite number of seconds, got {value}")
    return value


def add_exclude_option(parser: argparse.ArgumentParser) -> None:
    """Add `--exclude [FILE@]T0:T1,...`: stretches of time cut out of the records before anything is fitted."""
    parser.add_argument(
        "--exclude",
        default=None,
        metavar="[FILE@]T0:T1,...",
        help="cut these stretches of time [s] out of the records before anything is fitted (an end may "
        "be open: 8.8: cuts from 8.8 s on; FILE@ limits a stretch to the file of that name); a cut "
        "inside a record leaves two records, fitted as separate runs",
    )


def _excluded(records, spans, what: str, origins: dict):
    """Each record less the stretches of `spans` that name its file (or no file), and the notes saying so;
    `origins` gains each piece's file and the file's row before its first (`{piece source: (file, rows)}`)."""
    import pathlib

    import numpy as np

    from .._data import exclude_stretches

    out, notes = [], []
    for record in records:
        mine = [
            (t0, t1)
            for where, t0, t1 in spans
            if where is None or where in (record.source, pathlib.Path(record.source).name)
        ]
        pieces = exclude_stretches(record, mine)
        if pieces != [record]:
            kept = sum(len(p) for p in pieces)
            notes.append(
                (
                    f"--exclude: {len(record) - kept} of {len(record)} samples of {record.source} left out"
                    + (f", leaving {len(pieces)} {what}s" if len(pieces) != 1 else ""),
                    record.source,
                )
            )
            for piece in pieces:
                origins[piece.source] = (record.source, int(np.searchsorted(np.asarray(record.ts), piece.ts[0])))
        out.extend(pieces)
    return out, notes


def load_records(args, system: str, *, min_samples: int, lenient: tuple = ()) -> tuple[list, list | None, list[str]]:
    """Read the command's DATA and `--validation` files, cut `--exclude`'s stretches, and check what remains.

    Each record is checked for located faults (`dynax.check_records`); a fault that would make the fit
    wrong is a refusal (`DataError`, exit status 2) naming its file, column, rows and times and the fix;
    milder ones are printed as `warning:` lines on stderr, and so are the notes of `--exclude`; each is kept
    for the JSON's `warnings` (`_notes.py`). `lenient` names `Check` kinds that are warnings here whatever
    their severity (e.g. a zero input when the parameters are known).

    **Returns:** `(train, validation or None, notes)`: the lines printed, for a report's notes.
    """
    import warnings

    from .._data import check_records, load_trajectory, parse_exclude, Sampling
    from .._data._sanity import Severity

    mapping, scale, offset = data_options(args)
    spans = parse_exclude(getattr(args, "exclude", None))
    known = {pathlib.Path(p).name for p in [*args.data, *(getattr(args, "validation", None) or [])]}
    known |= set(args.data) | set(getattr(args, "validation", None) or [])
    for where, _, _ in spans:
        if where is not None and where not in known:
            raise UsageError(f"--exclude names the file '{where}', which is none of the records given")

    def read(paths):
        with warnings.catch_warnings():  # the check runs below, on what --exclude leaves
            warnings.simplefilter("ignore")
            return [
                load_trajectory(
                    p,
                    system,
                    mapping=mapping,
                    scale=scale,
                    offset=offset,
                    sampling=Sampling(min_samples=min_samples, even=bool(getattr(args, "even_times", False))),
                    check=False,
                    velocities="positions" if getattr(args, "velocities", None) == "positions" else "measured",
                )
                for p in paths
            ]

    origins: dict = {}  # a piece --exclude left: its file, and the rows before it there (for `warnings`)
    train, notes = _excluded(read(args.data), spans, "record", origins)
    validation = None
    if getattr(args, "validation", None):
        validation, more = _excluded(read(args.validation), spans, "held-out record", origins)
        notes += more
    for name, records in (("DATA", train), ("--validation", validation)):
        if records is not None and not records:
            raise UsageError(f"--exclude leaves nothing of the {name} records")
        for record in records or ():
            if len(record) < min_samples:
                raise DataError(
                    f"has {len(record)} samples after --exclude; at least {min_samples} are needed", path=record.source
                )
    check = check_records(train, validation or ())
    refusals = [f for f in check.refusals if f.kind not in lenient]
    if refusals:
        from .._data._sanity import DataCheck

        DataCheck(tuple(refusals)).raise_refusals()
    said = current()
    lines = []
    for text, source in notes:
        said.note("exclude", text, file=source)
        lines.append(text)
    for finding in check.findings:
        if finding.severity == Severity.WARN or finding.kind in lenient:
            file, before = origins.get(finding.source, (finding.source, 0))
            rows = None if finding.rows is None else tuple(r + before for r in finding.rows)
            said.finding(finding, file=file, rows=rows)  # the file's rows, where the message counts the piece's
            lines.append(f"warning: {finding.describe()}")
    return train, validation, lines
