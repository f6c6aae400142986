"""The project's own exceptions and warning: bad input data, an optional dependency missing."""

from __future__ import annotations

from pathlib import Path

__all__ = ["DataError", "DataWarning", "MissingExtraError"]


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


class MissingExtraError(ImportError):
    """A feature needs an optional dependency that is not installed; names the extra that
    installs it (``pyproject.toml``'s ``[project.optional-dependencies]``).

    Parameters
    ----------
    extra : str
        The extra, e.g. ``"sweep"``: ``pip install 'sonarslam[sweep]'``.
    feature : str
        What needs it, e.g. ``"a sweep on Dask"``.
    missing : ModuleNotFoundError
        The failed import (its ``name`` is the missing module).
    """

    def __init__(self, extra: str, feature: str, missing: ModuleNotFoundError) -> None:
        self.extra = extra
        module = (missing.name or "?").split(".")[0]
        super().__init__(
            f"{feature} needs {module}, which is not installed: pip install 'sonarslam[{extra}]'"
            f" (in a clone of the repository: make venv, or pip install -e '.[{extra}]')",
            name=missing.name,
        )
