"""The one exception every reader raises on bad input, printable as a single line."""

from __future__ import annotations

import os


class InputError(Exception):
    """Bad input at path:line:column (1-based; line is None for whole-file problems)."""

    def __init__(self, path, line: int | None, column: int | None, message: str):
        self.path = os.fspath(path)
        self.line = line
        self.column = column
        # The CLI prints str(self) as its one-line reason, so a stray newline would break that.
        self.message = " ".join(str(message).split())
        super().__init__(str(self))

    def __str__(self) -> str:
        where = self.path
        if self.line is not None:
            where += f":{self.line}"
            if self.column is not None:
                where += f":{self.column}"
        return f"{where}: {self.message}"

    def __reduce__(self):
        # Pickle (worker pools) by the constructor's arguments, not by str(self).
        return (type(self), (self.path, self.line, self.column, self.message))
