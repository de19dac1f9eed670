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
