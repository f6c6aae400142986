"""The one strict tokenizer of the project's text inputs, and the policy for bad input.

Every reader of a text file goes through here (the logs, the keyframe CSV and PCDs, the
``sonarslam.toml`` files, ``truth.json``):

* **Files.** Only regular files are read: a directory, a FIFO, a device or a socket (also
  behind a symlink) is refused *before* reading (a FIFO would block for ever, ``/dev/zero`` would
  fill the memory); a symlink loop or an unreadable file is a :class:`DataError`; so is a file
  over :data:`MAX_FILE_BYTES`.
* **Encoding.** Stated per format: logs, CSV and PCD are ASCII (their ``%`` header lines may hold
  any byte: they are read as Latin-1 and never parsed); TOML and JSON are UTF-8. A byte that is
  not text in the stated encoding is a :class:`DataError` naming its line.
* **Lines.** Physical lines end at ``\\r\\n``, ``\\r`` or ``\\n`` and nothing else (Python's
  ``splitlines`` also breaks at ``\\x0b``, ``\\x0c``, ``\\x1c``-``\\x1e`` and ``\\x85``, which
  shifts every later line number); every message names the 1-based physical line.
* **Fields.** Separated by runs of spaces and tabs only (``str.split()`` also splits at
  ``\\xa0``, ``\\x1f``...). A number is ``[+-]digits[.[digits]][e[+-]digits]`` or ``[+-].digits[...]``
  (:data:`NUMBER`): no ``nan``, ``inf``, ``1_000``, ``0x10``, non-ASCII digits or a dangling
  ``.`` or ``1e``; and
  it must be finite as a float64 (``1e999`` is not).
* **A cut last line.** A last line without a line end may have been cut inside its last field
  (``0.0314...`` read as ``0.03``). It is taken only when its fields have the shape (decimals,
  or digits of a whole number) of the same columns in every complete row, or when that column is
  not used; otherwise it is skipped as cut, with the warning below.

The policy for bad input, shared by every reader (docs/bad-input.md):

=========================================  ============================================
input                                      result
=========================================  ============================================
missing, special or unreadable file        :class:`DataError` naming the file
byte that is not text (stated encoding)    :class:`DataError` naming file and line
non-numeric or non-finite field            :class:`DataError` naming file and line
time going backwards or not a Unix time    :class:`DataError` naming file and line
row with the wrong number of columns       row skipped; one :class:`DataWarning` per file
(short, long), or a cut last line          with the count and the first line numbers
no data row at all                         :class:`DataError` naming the file
=========================================  ============================================

A skipped row is one sample of a sensor that samples many times a second; every estimator
copes with a missing sample (that is a sensor gap), and the warning says how many there were.
A non-numeric field or time going backwards means the file is not what we think it is, so
nothing is guessed. Implausible values of valid syntax (a DVL speed of 50 m/s, a GPS fix at
0/0) are the sensors' faults, gated with counted warnings after reading (:mod:`sonarslam.datasets.gates`).
"""

from __future__ import annotations

import os
import re
import stat
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.features.geometry import FloatArray
from sonarslam.settings import NUMBER

__all__ = [
    "NUMBER",
    "MAX_FILE_BYTES",
    "MAX_UNIX_TIME_S",
    "Table",
    "BLOCK_BYTES",
    "open_regular",
    "check_ascii",
    "read_bytes",
    "iter_line_blocks",
    "iter_tables",
    "read_text",
    "split_lines",
    "text_lines",
    "data_lines",
    "read_table",
    "parse_table",
    "parse_row",
    "parse_number",
    "check_time_order",
    "check_unix_times",
    "is_number",
]

#: Larger files are refused (they are not logs of this kind; reading them would exhaust memory).
MAX_FILE_BYTES = 2**31
#: Times are Unix seconds in ``[0, MAX_UNIX_TIME_S)`` (the year 2286).
MAX_UNIX_TIME_S = 1e10
#: Bytes of text the streaming readers parse at a time (:func:`iter_line_blocks`): a few MB
#: of text become ~10x that in tokens while parsed, whatever the size of the file.
BLOCK_BYTES = 1 << 21

_NUMBER_RE = re.compile(NUMBER)
_ROW_RE = re.compile(rf"{NUMBER}(?:[ \t]+{NUMBER})*")
_CSV_ROW_RE = re.compile(rf"{NUMBER}(?:[ \t]*,[ \t]*{NUMBER})*")
_LINE_BREAK = re.compile(r"\r\n|\r|\n")
_FIELD_SEP = re.compile(r"[ \t]+")
_NOT_TEXT = re.compile(r"[^\t\x20-\x7e]")
_NUMBER_PREFIX = re.compile(r"[+-]?[0-9]*\.?[0-9]*(?:[eE][+-]?)?")
_SHAPE = re.compile(r"[+-]?([0-9]*)(?:\.([0-9]+))?(?:[eE][+-]?([0-9]+))?")
_KINDS = (
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


@contextmanager
def open_regular(path: str | Path) -> Iterator[BinaryIO]:
    """A regular file opened for reading in binary; anything else is a :class:`DataError`
    naming it, and so is an error while reading it.

    The file is opened without blocking and checked with ``fstat`` before a byte is read, so a
    FIFO or a device behind a symlink is refused instead of blocking or filling the memory.
    """
    p = Path(path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(p, flags)
    except FileNotFoundError as exc:
        raise DataError(p, None, "file not found") from exc
    except OSError as exc:
        raise DataError(p, None, f"cannot open: {exc.strerror or exc}") from exc
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise DataError(p, None, "is a directory, not a file")
        for test, kind in _KINDS:
            if test(mode):
                raise DataError(p, None, f"is {kind}, not a regular file")
        if not stat.S_ISREG(mode):
            raise DataError(p, None, "is not a regular file")
        size = os.fstat(fd).st_size
        if size > MAX_FILE_BYTES:
            raise DataError(p, None, f"is {size} bytes, more than the {MAX_FILE_BYTES} accepted")
        with os.fdopen(fd, "rb", closefd=False) as fh:
            yield fh
    except OSError as exc:
        raise DataError(p, None, f"cannot read: {exc.strerror or exc}") from exc
    finally:
        os.close(fd)


def read_bytes(path: str | Path) -> bytes:
    """The bytes of a regular file (:func:`open_regular`)."""
    with open_regular(path) as fh:
        return fh.read()


def iter_line_blocks(
    path: str | Path, block_bytes: int = BLOCK_BYTES
) -> Iterator[tuple[int, list[str], int | None]]:
    """The physical lines of a regular file (ASCII or Latin-1 text, :func:`split_lines`'
    breaks) a block of about ``block_bytes`` at a time, so that a reader holds one block of
    text, never the file: ``(number of the block's first line, lines, open_end)``, where
    ``open_end`` is, in the last block only, the number of the file's last line when it has no
    line end (else None). A file without bytes gives one block without lines."""
    number = 1
    carry = b""
    held: list[str] = []  # the block before: the last block is yielded with it (a cut last
    # line is judged against the lines before it, :func:`parse_table`)
    with open_regular(path) as fh:
        while True:
            chunk = fh.read(block_bytes)
            data = carry + chunk
            if not chunk:  # the end of the file
                lines, terminated = split_lines(data.decode("latin-1"))
                lines = held + lines
                yield number, lines, None if terminated else number + len(lines) - 1
                return
            end = len(data) - 1 if data.endswith(b"\r") else len(data)  # \r of a split \r\n
            cut = max(data.rfind(b"\n", 0, end), data.rfind(b"\r", 0, end))
            if cut < 0:  # a line longer than the block
                carry = data
                continue
            carry = data[cut + 1 :]
            lines = _LINE_BREAK.split(data[: cut + 1].decode("latin-1"))
            lines.pop()  # the empty text after the last break
            if held:
                yield number, held, None
                number += len(held)
            held = lines


def _line_of(data: bytes, offset: int) -> int:
    """1-based physical line of a byte offset (breaks ``\\r\\n``, ``\\r``, ``\\n``)."""
    head = data[:offset]
    return head.count(b"\n") + head.count(b"\r") - head.count(b"\r\n") + 1


def read_text(path: str | Path, encoding: str) -> str:
    """A regular file (:func:`read_bytes`) decoded strictly with ``encoding``; a byte that is
    not text in it is a :class:`DataError` naming its line."""
    p = Path(path)
    data = read_bytes(p)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        line = _line_of(data, exc.start)
        byte = data[exc.start]
        raise DataError(p, line, f"byte 0x{byte:02X} is not {encoding} text") from None


def split_lines(text: str) -> tuple[list[str], bool]:
    """Physical lines (breaks ``\\r\\n``, ``\\r``, ``\\n`` only) and whether the last one ended
    with a break (False: it may have been cut). An empty text has no line."""
    if not text:
        return [], True
    lines = _LINE_BREAK.split(text)
    terminated = lines[-1] == ""
    if terminated:
        lines.pop()
    return lines, terminated


def text_lines(path: str | Path, encoding: str = "latin-1") -> tuple[list[str], bool]:
    """:func:`read_text` then :func:`split_lines`."""
    return split_lines(read_text(path, encoding))


def parse_number(text: str) -> float | None:
    """The finite float of a field in the grammar :data:`NUMBER`, else None."""
    if not _NUMBER_RE.fullmatch(text):
        return None
    value = float(text)
    return value if np.isfinite(value) else None


def is_number(text: str) -> bool:
    """True when ``text`` is a finite number in the grammar :data:`NUMBER`."""
    return parse_number(text) is not None


def check_ascii(path: Path, number: int, line: str) -> None:
    """A :class:`DataError` naming the line and column of the first byte of ``line`` that is not
    printable ASCII (or a tab)."""
    bad = _NOT_TEXT.search(line)
    if bad is not None:
        raise DataError(
            path,
            number,
            f"byte 0x{ord(bad.group()):02X} at column {bad.start() + 1} is not ASCII text",
        )


def parse_row(path: Path, number: int, fields: Sequence[str]) -> FloatArray:
    """The finite numbers of one row's fields; a :class:`DataError` naming the line and the
    first field that is not one."""
    for f in fields:
        if not _NUMBER_RE.fullmatch(f):
            raise DataError(path, number, f"non-numeric field {f!r}")
    values = np.array(fields, dtype=np.float64)
    if not np.all(np.isfinite(values)):
        bad = fields[int(np.flatnonzero(~np.isfinite(values))[0])]
        raise DataError(path, number, f"field {bad!r} is not a finite number")
    return values


def _shape(field: str) -> tuple[int, int, int]:
    """``(decimals, exponent digits, digits of a whole number)`` of a number's text: what a cut
    inside the field changes."""
    m = _SHAPE.fullmatch(field)
    if m is None:
        return (-1, -1, -1)
    whole, decimals, exponent = m.group(1), m.group(2) or "", m.group(3) or ""
    plain = not decimals and not exponent
    return (len(decimals), len(exponent), len(whole) if plain else 0)


@dataclass(frozen=True)
class Table:
    """Numeric rows of a log with the 1-based physical line number of each row in its file."""

    path: Path
    data: FloatArray  # (N, n_columns)
    line_numbers: np.ndarray  # (N,) int
    skipped: int
    skipped_lines: tuple[int, ...] = ()  # rows skipped for their number of columns
    cut_line: int | None = None  # a last line skipped as cut


def data_lines(path: str | Path, comment: str = "%") -> tuple[list[tuple[int, str]], int | None]:
    """The data lines of a log, ``(physical line number, text stripped of spaces/tabs)``,
    without blank lines and lines starting with ``comment``; and the number of the file's last
    line when it has no line end (None otherwise)."""
    return _numbered_lines(read_text(path, "latin-1"), comment)


def _numbered_lines(text: str, comment: str = "%") -> tuple[list[tuple[int, str]], int | None]:
    """:func:`data_lines` of a file's text."""
    lines, terminated = split_lines(text)
    numbered = []
    for number, raw in enumerate(lines, start=1):
        line = raw.strip(" \t")
        if line and not line.startswith(comment):
            numbered.append((number, line))
    return numbered, None if terminated else len(lines)


def read_table(
    path: str | Path,
    n_columns: int | None = None,
    min_columns: int = 1,
    time_column: int | None = 0,
    used_columns: Sequence[int] | None = None,
    trust_last_line: bool = False,
) -> Table:
    """Read the numeric rows of a log (the module docstring's rules).

    Parameters
    ----------
    path : str or Path
        The log file. Lines starting with ``%`` (after spaces/tabs) and blank lines are skipped.
    n_columns : int, optional
        Expected number of fields per row; by default, the count of the first data row.
    min_columns : int
        Smallest acceptable ``n_columns``.
    time_column : int or None
        Column of Unix times (s) that must not decrease; None to skip the check.
    used_columns : sequence of int, optional
        The columns the caller uses (default all): a last line without a line end whose last
        field is in an unused column is taken as it is.
    trust_last_line : bool
        Take a last line without a line end as it is; for callers that check its values
        themselves (``*_SETUP.log``: its step must divide the turn).

    Returns
    -------
    Table

    Raises
    ------
    DataError
        See the module docstring.
    """
    p = Path(path)
    data = read_bytes(p)
    fast = _fast_table(p, data, n_columns, min_columns)
    if fast is not None:
        if time_column is not None:
            check_unix_times(fast, time_column)
            check_time_order(fast, time_column)
        return fast
    numbered, open_end = _numbered_lines(data.decode("latin-1"))
    return parse_table(
        p,
        numbered,
        None if trust_last_line else open_end,
        n_columns=n_columns,
        min_columns=min_columns,
        time_column=time_column,
        used_columns=used_columns,
    )


def parse_table(
    path: Path,
    numbered: Sequence[tuple[int, str]],
    open_end: int | None,
    n_columns: int | None = None,
    min_columns: int = 1,
    time_column: int | None = 0,
    used_columns: Sequence[int] | None = None,
    delimiter: str | None = None,
    skip_wrong_columns: bool = True,
    warn: bool = True,
    require_rows: bool = True,
) -> Table:
    """The numeric rows of numbered data lines (:func:`data_lines`); :func:`read_table`'s rules.

    ``open_end``: the number of the file's last line when it has no line end (it may be cut),
    else None. ``delimiter``: None for runs of spaces and tabs, else one character (``","``)
    with spaces and tabs around a field ignored. ``skip_wrong_columns``: a row with the wrong
    number of fields is skipped and counted (True) or a :class:`DataError` (False).
    ``warn``: warn of skipped rows here (False: the caller, which reads the file in blocks,
    warns once per file); ``require_rows``: no row at all is a :class:`DataError` (False: an
    empty table).
    """
    lines = list(numbered)
    expected = n_columns
    fast = _fast_block(lines, expected, open_end, min_columns, delimiter)
    parts: list[FloatArray] = []
    line_numbers: list[int] = []
    if fast is not None:  # every line but an open-ended last one is clean: no loop needed
        expected, block = fast
        parts.append(block)
        line_numbers = [number for number, _ in lines[: block.shape[0]]]
    rows: list[list[str]] = []  # the rows the loop takes (their fields)
    bad_lines: list[int] = []
    cut_line: int | None = None
    row_re = _ROW_RE if delimiter is None else _CSV_ROW_RE
    for number, line in lines[len(line_numbers) :]:
        clean = row_re.fullmatch(line) is not None
        if not clean:
            check_ascii(path, number, line)
        if delimiter is not None:
            fields = [f.strip(" \t") for f in line.split(delimiter)]
        else:  # on a clean line str.split() splits at runs of spaces and tabs only
            fields = line.split() if clean else _FIELD_SEP.split(line)
        at_open_end = number == open_end
        if expected is None and len(fields) >= min_columns and not at_open_end:
            expected = len(fields)
        if expected is None or len(fields) != expected:
            if not skip_wrong_columns:
                raise DataError(path, number, f"expected {expected} fields, got {len(fields)}")
            bad_lines.append(number)
            continue
        if at_open_end and _cut_inside(fields):
            cut_line = number
            continue
        rows.append(fields)
        line_numbers.append(number)
    if rows and line_numbers[-1] == open_end and not _vouched(lines, rows, used_columns, delimiter):
        cut_line = line_numbers.pop()
        rows.pop()
    if rows:
        first = len(line_numbers) - len(rows)
        for i, fields in enumerate(rows):  # names the first field that is no finite number
            if not _finite_row(fields):
                parse_row(path, line_numbers[first + i], fields)
        parts.append(np.array(rows, dtype=np.float64))
    if not line_numbers and require_rows:
        cut = "" if cut_line is None else f" (line {cut_line} has no line end and may be cut)"
        raise DataError(path, None, f"no data rows{cut}")
    if warn:
        _warn_skipped(path, expected, bad_lines, cut_line)
    table = Table(
        path=path,
        data=(parts[0] if len(parts) == 1 else np.vstack(parts))
        if parts
        else np.zeros((0, expected or 0)),
        line_numbers=np.asarray(line_numbers, dtype=np.int64),
        skipped=len(bad_lines) + (cut_line is not None),
        skipped_lines=tuple(bad_lines),
        cut_line=cut_line,
    )
    if time_column is not None and line_numbers:
        check_unix_times(table, time_column)
        check_time_order(table, time_column)
    return table


def iter_tables(
    path: str | Path,
    n_columns: int | None = None,
    min_columns: int = 1,
    time_column: int | None = 0,
    used_columns: Sequence[int] | None = None,
    comment: str = "%",
    block_bytes: int = BLOCK_BYTES,
) -> Iterator[Table]:
    """:func:`read_table`'s rows a block at a time (:func:`iter_line_blocks`): the same rules,
    line numbers and messages, one warning per file for the rows skipped (after the last
    block), times checked across blocks; memory of one block, not of the file."""
    p = Path(path)
    expected = n_columns
    skipped: list[int] = []
    cut: int | None = None
    rows = 0
    last_t: tuple[float, int] | None = None  # the previous block's last time and its line
    for first, lines, open_end in iter_line_blocks(p, block_bytes):
        numbered = []
        for number, raw in enumerate(lines, start=first):
            line = raw.strip(" \t")
            if line and not line.startswith(comment):
                numbered.append((number, line))
        if not numbered:
            continue
        table = parse_table(
            p,
            numbered,
            open_end,
            n_columns=expected,
            min_columns=min_columns,
            time_column=time_column,
            used_columns=used_columns,
            warn=False,
            require_rows=False,
        )
        skipped += table.skipped_lines
        cut = table.cut_line if table.cut_line is not None else cut
        if not table.line_numbers.size:
            continue
        expected = table.data.shape[1]
        if time_column is not None:
            t_first = float(table.data[0, time_column])
            if last_t is not None and t_first < last_t[0]:
                raise DataError(
                    p,
                    int(table.line_numbers[0]),
                    f"time goes backwards ({t_first:.3f} s after {last_t[0]:.3f} s)",
                )
            last_t = (float(table.data[-1, time_column]), int(table.line_numbers[-1]))
        rows += table.line_numbers.size
        yield table
    if not rows:
        note = "" if cut is None else f" (line {cut} has no line end and may be cut)"
        raise DataError(p, None, f"no data rows{note}")
    _warn_skipped(p, expected, skipped, cut)


def _finite_row(fields: list[str]) -> bool:
    """Whether every field is a number of the grammar that is finite as a float64."""
    if not all(_NUMBER_RE.fullmatch(f) for f in fields):
        return False
    return bool(np.all(np.isfinite(np.array(fields, dtype=np.float64))))


#: ``10.0 ** k`` for ``k`` = 0-15, each exact in a float64.
_POW10 = np.array([float(f"1e{k}") for k in range(16)])
#: Most significant digits a field converted arithmetically may hold: below 2**53, so exact.
_EXACT_DIGITS = 15


def _numbers(text: bytes) -> FloatArray:
    """The float64 of each field of ``text`` (ASCII of :data:`_NUMERIC_BYTES`, fields
    separated by spaces, tabs and ``\\n``), as ``np.array(text.split(), dtype=np.float64)``
    gives them, in one flat array; a ValueError for a field that is no number.

    A field ``[+-]digits[.digits]`` (or ``[+-].digits``) of at most 15 digits, the bulk of a
    log (all of a raw sonar log's intensities), is converted arithmetically: its digits as a
    whole number ``m`` (exact below 2**53) divided by ``10**k`` (exact for ``k`` <= 15), a
    single IEEE division, so the correctly rounded value of the decimal, which is what the
    string conversion gives (Clinger 1990, "How to read floating point numbers accurately",
    the exact case). The other fields (exponents, more digits) go through the string
    conversion.
    """
    code = np.frombuffer(text, dtype=np.uint8)
    if code.size == 0:
        return np.zeros(0)
    is_char = (code != 32) & (code != 9) & (code != 10)
    edge = np.diff(is_char.view(np.int8), prepend=np.int8(0), append=np.int8(0))
    starts = np.flatnonzero(edge == 1)
    ends = np.flatnonzero(edge == -1)  # one past each field's last byte
    is_digit = (code >= 48) & (code <= 57)
    digits_to = np.cumsum(is_digit, dtype=np.int32)  # digits up to each byte (inclusive)
    digits_at = np.flatnonzero(is_digit)
    first = digits_to[starts] - is_digit[starts]  # index in digits_at of a field's first digit
    n_digits = digits_to[ends - 1] - first
    marks = np.flatnonzero(is_char & ~is_digit)  # signs, points, exponents
    field_of = np.searchsorted(starts, marks, side="right") - 1
    mark = code[marks]
    n_fields = starts.size
    points = np.bincount(field_of[mark == 46], minlength=n_fields)
    signs = np.bincount(field_of[(mark == 43) | (mark == 45)], minlength=n_fields)
    others = np.bincount(field_of[(mark == 101) | (mark == 69)], minlength=n_fields)
    lead = code[starts]
    signed = (lead == 43) | (lead == 45)
    plain = (
        (points <= 1)
        & (others == 0)
        & (signs == signed)
        & (n_digits >= 1)
        & (n_digits <= _EXACT_DIGITS)
    )
    # digits after the point: the field's digits less those before the point
    after = np.zeros(n_fields, dtype=np.int64)
    at_point = mark == 46
    with_point = field_of[at_point]
    after[with_point] = (first + n_digits)[with_point] - digits_to[marks[at_point]]
    whole = np.zeros(n_fields, dtype=np.int64)
    for d in np.flatnonzero(np.bincount(n_digits[plain], minlength=1)):
        sel = np.flatnonzero(plain & (n_digits == d))
        places = digits_at[first[sel, None] + np.arange(d)]  # (G, d)
        weights = 10 ** np.arange(d - 1, -1, -1, dtype=np.int64)
        whole[sel] = (code[places].astype(np.int64) - 48) @ weights
    values = whole.astype(np.float64) / _POW10[np.where(plain, after, 0)]
    values = np.where(lead == 45, -values, values)
    rest = np.flatnonzero(~plain)
    if rest.size:
        values[rest] = np.array([text[starts[i] : ends[i]] for i in rest], dtype=np.float64)
    return values


#: The bytes a data line of the common case holds: ASCII digits, signs, points, exponents,
#: spaces and tabs (and the line ends).
_NUMERIC_BYTES = b"0123456789eE+-. \t\n"


def _fields_per_line(code: np.ndarray) -> np.ndarray:
    """(L,) int: the fields (runs of bytes other than space, tab and ``\\n``) of each line of
    the bytes ``code`` (N,) uint8, whose every line ends with ``\\n``."""
    is_char = (code != 32) & (code != 9) & (code != 10)
    first_chars = np.flatnonzero(is_char[1:] & ~is_char[:-1]) + 1  # where each field starts
    if is_char[0]:
        first_chars = np.concatenate([[0], first_chars])
    ends = np.flatnonzero(code == 10)
    return np.diff(np.searchsorted(first_chars, ends), prepend=0)


def _fast_table(path: Path, data: bytes, n_columns: int | None, min_columns: int) -> Table | None:
    """:func:`read_table`'s rows of a whole file in the common case, on its bytes in a few
    vectorised passes: a head of comment and blank lines, then only lines of ASCII numbers of
    the grammar (or blank ones), every data line with the same count of fields, all finite,
    line ends ``\\n`` or ``\\r\\n`` only and the last line ended. Else None: the line-by-line
    reader (:func:`parse_table`) then reads the file and names what is wrong. The values are
    those of :func:`parse_table` (the same conversion of the same fields), the times are left
    to the caller to check."""
    if b"\r" in data:
        if data.count(b"\r") != data.count(b"\r\n"):
            return None  # a line break \r alone: the line-by-line reader's
        data = data.replace(b"\r\n", b"\n")
    if not data.endswith(b"\n"):
        return None  # no file, or a last line that may be cut: judged line by line
    start, number = 0, 1  # the head: comment and blank lines
    while start < len(data):
        end = data.index(b"\n", start)
        line = data[start:end].strip(b" \t")
        if line and not line.startswith(b"%"):
            break
        start, number = end + 1, number + 1
    body = data[start:]
    if not body or body.translate(None, _NUMERIC_BYTES):
        return None  # no data line, or a byte of another kind (a comment below the head...)
    per_line = _fields_per_line(np.frombuffer(body, dtype=np.uint8))
    rows = np.flatnonzero(per_line)  # blank lines hold no field
    n = int(per_line[rows[0]]) if n_columns is None else n_columns
    if n < max(min_columns, 1) or np.any(per_line[rows] != n):
        return None
    # the conversion of :func:`_fast_block`: exactly the grammar NUMBER on this alphabet
    try:
        values = _numbers(body).reshape(rows.size, n)
    except ValueError:
        return None
    if not np.all(np.isfinite(values)):
        return None
    return Table(
        path=path,
        data=values,
        line_numbers=(rows + number).astype(np.int64),
        skipped=0,
    )


def _fast_block(
    lines: list[tuple[int, str]],
    n_columns: int | None,
    open_end: int | None,
    min_columns: int,
    delimiter: str | None,
) -> tuple[int, FloatArray] | None:
    """The common case in a few vectorised passes: when every line (but an open-ended last
    one) holds only ASCII numbers of the grammar, all with the same count of fields, all
    finite: ``(n_columns, data (N, n_columns))``; else None (the caller's line-by-line loop
    then finds and names what is wrong)."""
    if delimiter is not None:
        return None
    body = lines[:-1] if lines and lines[-1][0] == open_end else lines
    if not body:
        return None
    flat = ("\n".join(line for _, line in body) + "\n").encode("ascii", errors="replace")
    if flat.translate(None, _NUMERIC_BYTES):
        return None  # a byte of another kind (a non-ASCII one is "?" here)
    per_line = _fields_per_line(np.frombuffer(flat, dtype=np.uint8))
    n = int(per_line[0]) if n_columns is None else n_columns
    if n < max(min_columns, 1) or np.any(per_line != n):
        return None
    # numpy's conversion of ASCII tokens of these characters accepts exactly the grammar
    # NUMBER (tested exhaustively to 6 characters in tests/test_fuzz_readers.py)
    try:
        data = _numbers(flat).reshape(len(body), n)
    except ValueError:
        return None
    if not np.all(np.isfinite(data)):
        return None
    return n, data


def _cut_inside(fields: list[str]) -> bool:
    """Whether a row's last field is the start of a number cut short (``1.``, ``1e-``, ``-``)
    while the others are numbers."""
    last = fields[-1]
    return (
        not _NUMBER_RE.fullmatch(last)
        and _NUMBER_PREFIX.fullmatch(last) is not None
        and all(_NUMBER_RE.fullmatch(f) for f in fields[:-1])
    )


def _vouched(
    lines: list[tuple[int, str]],
    rows: list[list[str]],
    used_columns: Sequence[int] | None,
    delimiter: str | None,
) -> bool:
    """Whether the last row taken (its line has no line end) is whole: its last field is in an
    unused column, or has the shape of that column in every other data line."""
    column = len(rows[-1]) - 1
    if used_columns is not None and column not in used_columns:
        return True
    shape = _shape(rows[-1][-1])
    others = [
        line.rsplit(delimiter, 1)[-1].strip(" \t")
        if delimiter is not None
        else _FIELD_SEP.split(line)[-1]
        for _, line in lines[:-1]
    ]
    return bool(others) and all(_shape(f) == shape for f in others)


def _warn_skipped(path: Path, expected: int | None, bad_lines: list[int], cut: int | None) -> None:
    parts = []
    if bad_lines:
        shown = ", ".join(str(n) for n in bad_lines[:5]) + (" ..." if len(bad_lines) > 5 else "")
        parts.append(f"skipped {len(bad_lines)} row(s) without {expected} columns (lines {shown})")
    if cut is not None:
        parts.append(f"skipped line {cut}: it has no line end and may be cut inside a field")
    if parts:
        warnings.warn(f"{path}: {'; '.join(parts)}", DataWarning, stacklevel=4)


def check_unix_times(table: Table, column: int = 0) -> None:
    """Raise :class:`DataError` at the first row whose time is not a Unix time in
    ``[0, MAX_UNIX_TIME_S)`` s."""
    t = table.data[:, column]
    bad = np.flatnonzero((t < 0.0) | (t >= MAX_UNIX_TIME_S))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            table.path,
            int(table.line_numbers[i]),
            f"time {t[i]:.6g} s is not a Unix time (0 to {MAX_UNIX_TIME_S:.0e} s)",
        )


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
