"""What a command said about its answer, kept for the JSON it writes: the `warnings` list.

Every warning and note a command gives on the terminal (a data check's finding, a Python warning raised
by the work, the command's own `note:` and `WARNING` lines) is also an entry of the `warnings` list of
the JSON it writes, so a script that reads the answer sees what the terminal said about trusting it.
An entry is `{"kind", "category", "message"}` and, where known, `file`, `column`, `rows` (first and
last 1-based data row), `t0`, `t1` (seconds) and `fix`:

- `category` `"data"`: a located finding of the data checks; `kind` is its `Check` name (`glitch`,
  `stamps`, ...) or a flight's (`ground`, and the glitch kinds of `dynax.load_flight`).
- `category` a Python warning class (`InconsistentEstimateWarning`, `DataWarning`, `RuntimeWarning`,
  ...): a warning raised by the work, with `kind` the same class name.
- `category` `"note"`: the command's own line; `kind` names it (`poorly_determined`, `exclude`, ...).

`collecting()` (around each command, in `dynax._cli._main.main`) catches Python warnings where they are
raised, shows them on stderr as Python would, and keeps them. A warning of dynax's own classes is kept
even where Python's filters (`-W ignore`, `PYTHONWARNINGS`) keep it off the terminal: a script that
silences the terminal still reads it in the JSON.
"""

import contextlib
import contextvars
import math
import sys
import warnings


class RunNotes:
    """The warnings and notes of one command run, in the order given (an identical entry is kept once)."""

    def __init__(self):
        self.entries: list[dict] = []

    def add(self, kind: str, message: str, *, category: str = "note", **where) -> dict:
        """Keep one entry (`where`: `file`, `column`, `rows`, `t0`, `t1`, `fix`; `None` values left out)."""
        entry: dict = {"kind": str(kind), "category": category, "message": str(message)}
        for key, value in where.items():
            if value is None:
                continue
            if key == "rows":
                value = [int(v) for v in value]
            elif key in ("t0", "t1"):
                value = float(value) if math.isfinite(float(value)) else None
                if value is None:
                    continue
            entry[key] = str(value) if key in ("file", "column", "fix") else value
        if entry not in self.entries:
            self.entries.append(entry)
        return entry

    def note(
        self, kind: str, message: str, *, line: str | None = None, stream=None, category: str = "note", **where
    ) -> None:
        """Print `line` (default `note: MESSAGE`) to `stream` (default stderr) and keep the note."""
        print(f"note: {message}" if line is None else line, file=sys.stderr if stream is None else stream)
        self.add(kind, message, category=category, **where)

    def finding(self, finding, *, line: str | None = None, stream=None, file=None, rows=None) -> None:
        """Print a data check's `Finding` (`warning: ...` on stderr) and keep it with its location (`file`, `rows`:
        the file and its rows where the finding's record is a piece of it that `--exclude` left)."""
        text = finding.describe()
        print(f"warning: {text}" if line is None else line, file=sys.stderr if stream is None else stream)
        t0, t1 = finding.times if finding.times is not None else (None, None)
        self.add(
            str(finding.kind),
            text,
            category="data",
            file=file or finding.source or None,
            column=finding.column,
            rows=finding.rows if rows is None else rows,
            t0=t0,
            t1=t1,
            fix=finding.fix,
        )

    def warning(self, message, category) -> None:
        """Keep a Python warning (its class name as kind and category; the location where it carries one)."""
        where = getattr(message, "location", None) if isinstance(message, Warning) else None
        name = category.__name__
        self.add(name, str(message), category=name, **(where or {}))

    def to_json(self) -> list[dict]:
        return [dict(e) for e in self.entries]


_CURRENT: contextvars.ContextVar[RunNotes | None] = contextvars.ContextVar("dynax_run_notes", default=None)


def current() -> RunNotes:
    """The running command's notes (outside `collecting`, a fresh list that nothing reads)."""
    notes = _CURRENT.get()
    return RunNotes() if notes is None else notes


def dynax_warning_classes() -> tuple[type[Warning], ...]:
    """The warning classes dynax defines (every subclass of `Warning` whose module is dynax's)."""
    from .. import _data, _diagnose, _identify, _precision  # noqa: F401 - the packages that define them, loaded

    found, todo = [], [Warning]
    while todo:
        cls = todo.pop()
        for sub in cls.__subclasses__():
            todo.append(sub)
            if sub.__module__.split(".")[0] == "dynax" and sub not in found:
                found.append(sub)
    return tuple(found)


@contextlib.contextmanager
def collecting():
    """Collect the warnings and notes of the command run inside (`current()` gives them to its writers).

    Python warnings are caught where they are raised: each is kept and shown on stderr at once, as Python
    would show it under the filters in force when the command started (so the terminal says what it said
    before). dynax's own warning classes always reach the list, whatever those filters."""
    notes = RunNotes()
    token = _CURRENT.set(notes)
    try:
        with warnings.catch_warnings():  # filters and showwarning restored on the way out
            user_filters = list(warnings.filters)
            shown = warnings.showwarning
            ours = dynax_warning_classes()
            for cls in ours:
                warnings.filterwarnings("always", category=cls)
            registry: dict = {}  # what was shown once, for the "default" and "module" actions

            def show(message, category, filename, lineno, file=None, line=None):
                notes.warning(message, category)
                if not issubclass(category, ours):  # it came through the user's own filters
                    shown(message, category, filename, lineno, file, line)
                    return
                # "always" let it through to be kept: show it as the user's filters would have
                filters: list = warnings.filters  # pyright: ignore[reportAssignmentType] - a list at run time
                kept, here = filters[:], warnings.showwarning
                filters[:] = user_filters
                warnings.showwarning = shown
                try:
                    warnings.warn_explicit(message, category, filename, lineno, registry=registry)
                finally:
                    filters[:] = kept
                    warnings.showwarning = here

            warnings.showwarning = show
            yield notes
    finally:
        _CURRENT.reset(token)


def with_warnings(obj: dict) -> dict:
    """`obj` with the running command's `warnings` list added (an empty list when nothing was said)."""
    out = dict(obj)
    out["warnings"] = current().to_json()
    return out
