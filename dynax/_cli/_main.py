"""The `dynax` console script. Exit status: 0 success, 2 bad input or usage, 1 internal failure."""

import argparse
import importlib
import sys
import traceback

from .._errors import DataError, UsageError
from ._common import check_command_output

# Each module defines `register(subparsers)`, which adds its sub-command and sets `run=...`
# (a function `run(args) -> int`) as the parser default.
_COMMANDS = ("_demo", "_identify", "_diagnose", "_fit", "_evaluate")


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        self.print_usage(sys.stderr)
        print(f"dynax: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="dynax", description=__doc__)
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    subparsers.required = True
    for name in _COMMANDS:
        importlib.import_module(f".{name}", __package__).register(subparsers)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        check_command_output(args)  # before any work: a bad --out costs a second, not a fit
        return int(args.run(args) or 0)
    except (DataError, UsageError) as e:
        print(f"dynax {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("dynax: interrupted", file=sys.stderr)
        return 1
    except Exception:
        traceback.print_exc()
        print(f"dynax {args.command}: internal failure (see the traceback above)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
