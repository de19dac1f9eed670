"""dynax: differentiable dynamics, system identification, model-discrepancy diagnosis and optimal control.

Load measured data, identify a model's parameters, show what its simulation gets wrong and name the
cause, learn vehicle models and evaluate them. Exit status: 0 success, 2 bad input or usage,
1 internal failure, 130 interrupted (Ctrl-C). Progress bars go to stderr when it is a terminal
(--progress forces them, --quiet silences them). Compiled code is kept between runs in
$XDG_CACHE_HOME/dynax/jax (--no-cache skips it).
"""

import argparse
import importlib
import sys
import traceback

from .._errors import DataError, UsageError
from .._version import __version__
from ._cache import enable_compilation_cache
from ._common import check_command_output
from ._notes import collecting

# Each module defines `register(subparsers)`, which adds its sub-command and sets `run=...`
# (a function `run(args) -> int`) as the parser default.
_COMMANDS = ("_demo", "_identify", "_diagnose", "_fit", "_evaluate", "_control")

EXIT_INTERRUPTED = 130  # 128 + SIGINT, as shells report a Ctrl-C


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        self.print_usage(sys.stderr)
        print(f"dynax: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def _add_output_options(parser: argparse.ArgumentParser, *, default) -> None:
    """`--quiet` / `--progress`, accepted before and after the sub-command."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("-q", "--quiet", action="store_true", default=default, help="no progress bars")
    group.add_argument(
        "--progress", action="store_true", default=default, help="show progress bars even when stderr is not a terminal"
    )
    parser.add_argument(
        "--no-cache",
        action="store_true",
        default=default,
        help="do not use the compilation cache (compiled code kept between runs in "
        "$XDG_CACHE_HOME/dynax/jax; DYNAX_NO_CACHE=1 does the same)",
    )


def build_parser() -> argparse.ArgumentParser:
    summary, _, details = __doc__.partition("\n\n")
    parser = _Parser(
        prog="dynax", description=f"{summary}\n\n{details}", formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"dynax {__version__}")
    _add_output_options(parser, default=False)
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    subparsers.required = True
    for name in _COMMANDS:
        importlib.import_module(f".{name}", __package__).register(subparsers)
    for sub in subparsers.choices.values():
        # SUPPRESS: given after the sub-command they count, absent they leave the global value alone.
        _add_output_options(sub, default=argparse.SUPPRESS)
    return parser


def main(argv=None, *, run=None) -> int:
    """The `dynax` command: parse `argv` (default `sys.argv[1:]`), check the output path, turn on the compilation
    cache, run the sub-command under the progress mode `--quiet`/`--progress` choose, and map what it raises to
    the exit status (2 bad input or usage, 130 interrupted, 1 internal failure).

    `run`: a function `run(args) -> int` called in place of the sub-command's own, with everything around it
    as it is: for checking what `main` does around a command (the progress mode it runs under, the status of
    what it raises) without the command's work.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    from .._progress import progress_mode

    mode = "never" if args.quiet else "always" if args.progress else "auto"
    try:
        check_command_output(args)  # before any work: a bad --out costs a second, not a fit
        enable_compilation_cache(disabled=args.no_cache)
        with progress_mode(mode), collecting():  # the warnings and notes the written JSON carries (`_notes.py`)
            return int((run or args.run)(args) or 0)
    except (DataError, UsageError) as e:
        print(f"dynax {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"dynax {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception:
        traceback.print_exc()
        print(f"dynax {args.command}: internal failure (see the traceback above)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
