"""Options and checks shared by the sub-commands that read measured data."""

import argparse
import pathlib

from .._data import parse_assignments
from .._errors import UsageError


def add_data_options(parser: argparse.ArgumentParser) -> None:
    """Add the contract's `--map NAME=COLUMN,...` and `--scale NAME=FACTOR,...`."""
    parser.add_argument("--map", default=None, help="NAME=COLUMN,... for files whose columns are named otherwise")
    parser.add_argument("--scale", default=None, help="NAME=FACTOR,... multiplied into columns (units)")


def data_options(args: argparse.Namespace) -> tuple[dict, dict]:
    """The parsed `--map` and `--scale` (UsageError naming the malformed one)."""
    return parse_assignments(args.map, "--map", numeric=False), parse_assignments(args.scale, "--scale", numeric=True)


def output_file(path: str, example: str) -> pathlib.Path:
    """`--out` as a file path, refusing an existing directory (with an example file name)."""
    out = pathlib.Path(path)
    if out.is_dir():
        raise UsageError(f"--out {out} is a directory; give a file name such as {out / example}")
    return out
