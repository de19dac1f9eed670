"""The errors dynax raises for bad input. The CLI maps both to exit status 2."""


class DataError(ValueError):
    """A measured-data file was refused. The message names the file, the column and the row.

    **Attributes:** `path`, `column` (or `None`), `row` (1-based data row, or `None`).
    """

    def __init__(self, message: str, *, path=None, column=None, row=None):
        where = []
        if path is not None:
            where.append(f"file {path}")
        if column is not None:
            where.append(f"column '{column}'")
        if row is not None:
            where.append(f"row {row}")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)
        self.path, self.column, self.row = path, column, row


class UsageError(ValueError):
    """A command or function was called with arguments that cannot work (exit status 2 on the CLI)."""


def located(warning: Warning, *, file=None, column=None, rows=None, times=None, fix=None) -> Warning:
    """`warning` (an instance, for `warnings.warn`) carrying where it applies as `warning.location`: a dict
    of `file`, `column`, `rows` (first and last 1-based data row), `t0`, `t1` (seconds; `times=(t0, None)`
    for a stretch to the record's end) and `fix`, the known ones only. The command line writes them into its
    JSON's `warnings` entry; the text says them too.
    """
    where = {"file": file, "column": column, "rows": rows, "fix": fix}
    if times is not None:
        where["t0"], where["t1"] = times
    warning.location = {k: v for k, v in where.items() if v is not None}  # pyright: ignore[reportAttributeAccessIssue]
    return warning
