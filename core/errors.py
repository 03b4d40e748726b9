"""Errors meant for users: each names the file, the column and the row at fault."""

from __future__ import annotations

import sys
from pathlib import Path

PROG = ""  # the program that one-line errors name ("eosp solve", "train.py"); set by eosp.args.Parser


def prog() -> str:
    """The program name one-line errors start with: :data:`PROG`, else the script's file name."""
    return PROG or Path(sys.argv[0]).name or "eosp"


def error_line(message: object) -> str:
    """The one line a user error prints: ``PROG: error: MESSAGE`` (MESSAGE names the file or option first)."""
    return f"{prog()}: error: {message}"


class InputError(ValueError):
    """Bad input data.  ``str()`` is one line: ``file: column 'c', row r: what is wrong``.

    Rows are 0-based positions in the file as written (the first data row is row 0).
    """

    def __init__(self, file: object, message: str, column: str | None = None, row: int | None = None):
        self.file = str(file)
        self.column = column
        self.row = row
        self.message = message
        where = [self.file]
        if column is not None:
            where.append(f"column '{column}'")
        if row is not None:
            where.append(f"row {row}")
        super().__init__(": ".join([where[0], ", ".join(where[1:])]) + f": {message}" if len(where) > 1
                         else f"{self.file}: {message}")

    def __reduce__(self):
        # Ray and multiprocessing send exceptions between processes by pickling them
        return (type(self), (self.file, self.message, self.column, self.row))


class Refused(SystemExit):
    """A job refuses its arguments or its surroundings: one line ``PROG: error: ...`` on stderr, exit status 2.

    ``message`` keeps ``error: ...``.  Printed when raised, because Python prints a SystemExit's code only
    when it is not an int, and then exits with status 1."""

    def __init__(self, message: str):
        self.message = f"error: {message}"
        print(error_line(message), file=sys.stderr, flush=True)
        super().__init__(2)
