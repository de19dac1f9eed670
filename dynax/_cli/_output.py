"""Write outputs all-or-nothing: a refused input or a failure leaves the output location untouched.

Files are written to a temporary name and renamed into place, then given the mode a plain write
would (0666 or 0777 less the umask), not the private mode of a temporary file. A report folder is
built beside its target and swapped in whole, so no file of an earlier report survives into it.
Non-finite numbers are never written as if they were numbers: JSON has none, so they become
`null`, listed by location under the top-level key `non_finite`, with a warning on stderr.
"""

import contextlib
import json
import math
import os
import pathlib
import shutil
import sys
import tempfile
import uuid

import numpy as np


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _to_json(value, where, non_finite):
    if isinstance(value, dict):
        return {str(k): _to_json(v, f"{where}/{k}", non_finite) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_to_json(v, f"{where}/{i}", non_finite) for i, v in enumerate(value)]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return _to_json(np.asarray(value).tolist(), where, non_finite)
    if isinstance(value, float) and not math.isfinite(value):
        non_finite[where or "/"] = "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
        return None
    return value


def to_json(obj) -> tuple[object, dict[str, str]]:
    """`obj` as plain JSON values, and the locations (`/key/index`) of non-finite numbers made `null`."""
    non_finite = {}
    return _to_json(obj, "", non_finite), non_finite


def write_json(path, obj) -> None:
    """Write `obj` (dicts, lists, numbers, JAX/numpy arrays) as JSON atomically (temp file + rename).

    A non-finite number is written as `null`; for a top-level object its location and kind are
    added under `"non_finite"` (e.g. `{"/mse/velocity/3": "inf"}`), and a warning goes to stderr.
    """
    path = pathlib.Path(path)
    value, non_finite = to_json(obj)
    if non_finite:
        if isinstance(value, dict):
            value["non_finite"] = non_finite
        where = ", ".join(f"{k} ({v})" for k, v in list(non_finite.items())[:5])
        print(
            f"warning: {path}: non-finite values written as null at {where}" + (" ..." if len(non_finite) > 5 else ""),
            file=sys.stderr,
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(value, f, indent=2, allow_nan=False)
            f.write("\n")
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)
        raise


@contextlib.contextmanager
def staged_directory(out):
    """Yield a fresh temporary folder beside `out`; on success it replaces `out` whole.

    An earlier folder at `out` is moved aside, the new one renamed into place, and the old one
    removed, so the result holds exactly what this run wrote. On an exception nothing changes at
    `out`. Check `out` first with `check_output(..., kind="directory")`, which refuses a folder
    holding anything but a report.
    """
    out = pathlib.Path(out)
    parent = out.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
    stage = pathlib.Path(tempfile.mkdtemp(dir=parent, prefix=f".{out.name}.staging."))
    try:
        yield stage
        os.chmod(stage, 0o777 & ~_umask())
        old = parent / f".{out.name}.old.{uuid.uuid4().hex[:8]}"
        if out.exists() or out.is_symlink():
            os.rename(out, old)
        try:
            os.rename(stage, out)
        except BaseException:
            if old.exists() or old.is_symlink():
                os.rename(old, out)
            raise
        if old.is_symlink() or old.is_file():
            old.unlink()
        elif old.exists():
            shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
