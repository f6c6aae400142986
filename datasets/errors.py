"""The project's own exception and warning for bad input data."""

from __future__ import annotations

from pathlib import Path

__all__ = ["DataError", "DataWarning"]


class DataError(ValueError):
    """Input that cannot be read safely; names the file and, where there is one, the line.

    Parameters
    ----------
    path : str or Path
        The file (or directory) at fault.
    line : int or None
        1-based line number in ``path``, None when the fault is not at one line.
    message : str
        What is wrong.
    """

    def __init__(self, path: str | Path, line: int | None, message: str) -> None:
        self.path = Path(path)
        self.line = line
        self.message = message
        where = f"{self.path}:{line}" if line is not None else f"{self.path}"
        super().__init__(f"{where}: {message}")


class DataWarning(UserWarning):
    """A row was skipped safely; the message names the file, line and count."""
