"""Reading whitespace-separated numeric logs with ``%`` headers, strictly.

The policy for bad input, shared by every reader of the project (README, "Bad input"):

========================================  ============================================
input                                     result
========================================  ============================================
missing or unreadable file                :class:`DataError` naming the file
non-numeric field                         :class:`DataError` naming file and line
row with the wrong number of columns      row skipped; one :class:`DataWarning` per file
(short, long, or a truncated last line)   with the count and the first line numbers
time going backwards                      :class:`DataError` naming file and line
no data row at all                        :class:`DataError` naming the file
========================================  ============================================

A skipped row is one sample of a sensor that samples many times a second; every estimator
copes with a missing sample (that is a sensor gap), and the warning says how many there were.
A non-numeric field or time going backwards means the file is not what we think it is, so
nothing is guessed.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from datasets.errors import DataError, DataWarning
from features.geometry import FloatArray

__all__ = ["Table", "read_table", "check_time_order", "is_number"]


@dataclass(frozen=True)
class Table:
    """Numeric rows of a log with the 1-based line number of each row in its file."""

    path: Path
    data: FloatArray  # (N, n_columns)
    line_numbers: np.ndarray  # (N,) int
    skipped: int


def read_table(
    path: str | Path,
    n_columns: int | None = None,
    min_columns: int = 1,
    time_column: int | None = 0,
) -> Table:
    """Read the numeric rows of a log.

    Parameters
    ----------
    path : str or Path
        The log file. Lines starting with ``%`` and blank lines are skipped; fields are separated
        by runs of spaces or tabs; CRLF line ends are accepted.
    n_columns : int, optional
        Expected number of fields per row; by default, the count of the first data row.
    min_columns : int
        Smallest acceptable ``n_columns``.
    time_column : int or None
        Column that must not decrease (Unix s); None to skip the check.

    Returns
    -------
    Table

    Raises
    ------
    DataError
        See the module docstring.
    """
    p = Path(path)
    try:
        text = p.read_bytes().decode("latin-1")
    except FileNotFoundError as exc:
        raise DataError(p, None, "file not found") from exc
    except OSError as exc:
        raise DataError(p, None, f"cannot read: {exc.strerror}") from exc

    rows: list[FloatArray] = []
    line_numbers: list[int] = []
    bad_lines: list[int] = []
    expected = n_columns
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("%"):
            continue
        fields = line.split()
        if expected is None:
            if len(fields) < min_columns:
                bad_lines.append(number)
                continue
            expected = len(fields)
        if len(fields) != expected:
            bad_lines.append(number)
            continue
        try:
            values = np.array(fields, dtype=np.float64)
        except ValueError:
            bad = next(f for f in fields if not is_number(f))
            raise DataError(p, number, f"non-numeric field {bad!r}") from None
        if not np.all(np.isfinite(values)):
            raise DataError(p, number, "field is NaN or infinite")
        rows.append(values)
        line_numbers.append(number)

    if not rows:
        raise DataError(p, None, "no data rows")
    if bad_lines:
        shown = ", ".join(str(n) for n in bad_lines[:5]) + (" ..." if len(bad_lines) > 5 else "")
        warnings.warn(
            f"{p}: skipped {len(bad_lines)} row(s) without {expected} columns (lines {shown})",
            DataWarning,
            stacklevel=2,
        )
    table = Table(
        path=p,
        data=np.vstack(rows),
        line_numbers=np.asarray(line_numbers, dtype=np.int64),
        skipped=len(bad_lines),
    )
    if time_column is not None:
        check_time_order(table, time_column)
    return table


def check_time_order(table: Table, column: int = 0) -> None:
    """Raise :class:`DataError` at the first row whose time is before the previous row's."""
    t = table.data[:, column]
    back = np.flatnonzero(np.diff(t) < 0.0)
    if back.size:
        i = int(back[0]) + 1
        raise DataError(
            table.path,
            int(table.line_numbers[i]),
            f"time goes backwards ({t[i]:.3f} s after {t[i - 1]:.3f} s)",
        )


def is_number(text: str) -> bool:
    """True when ``float(text)`` parses (the readers' test for a non-numeric field)."""
    try:
        float(text)
    except ValueError:
        return False
    return True
