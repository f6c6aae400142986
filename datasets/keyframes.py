"""The marina keyframes: thresholded 360 deg scans (ASCII PCD) back to beams with exact times.

Each PCD point is a bin of one beam in the SONAR frame, ``x = r cos a, y = r sin a``, with ``a``
the raw transducer angle (a multiple of the head step) and ``r`` the bin range (a multiple of
the bin size). Scan ``k`` starts at ``keyFrameBeginning``, a row of ``IS_timestamps``, at transducer angle 0.
The marina README says the beam with angle index ``j = a / step`` was taken at
``IS_timestamps[row(begin) + j]`` (``scan_direction=+1``). Measured here, GPS-free: the head
turns the other way, ``IS_timestamps[row(begin) + (-j mod n)]`` (``scan_direction=-1``, the
default): with dead-reckoning poses the motion-corrected map is much sharper (summed entropy of
60 s windows 389.5 against 402.8 for the best forward mapping of any start angle; GPS poses
agree). Every beam of a scan is returned, also those with no point (an empty beam is
information too), in time order.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from sonarslam.datasets.cache import load_cached, save_cached
from sonarslam.datasets.errors import DataError
from sonarslam.datasets.logfile import (
    MAX_UNIX_TIME_S,
    Table,
    check_ascii,
    iter_line_blocks,
    parse_table,
    text_lines,
)
from sonarslam.datasets.records import BeamSeries
from sonarslam.features.geometry import FloatArray
from sonarslam.sonar.beam import SonarHead

__all__ = ["read_pcd", "iter_pcd", "read_pcd_xy", "read_keyframe_times", "read_keyframes"]

_MATCH_TOLERANCE_S = 0.001  # keyFrameBeginning equals an IS_timestamps row to < 1 ms (README)
_GRID_TOLERANCE = 0.01  # points must lie within 1 % of a step / bin of the polar grid


_INT_RE = re.compile(r"[0-9]+")
_SPACES = re.compile(r"[ \t]+")
#: The header line of ``keyFrameTimeStamps.csv``.
KEYFRAME_CSV_HEADER = ("keyFrame", "keyFrameBeginning", "keyFrameEnd")


def read_pcd(path: str | Path) -> Table:
    """Read an ASCII PCD with fields starting ``x y``: the points (N, n_fields) with the
    physical line of each (:class:`sonarslam.datasets.logfile.Table`; the header's length is the file's).

    Raises
    ------
    DataError
        :func:`iter_pcd`'s.
    """
    p = Path(path)
    parts = list(iter_pcd(p))
    cut = next((t.cut_line for t in parts if t.cut_line is not None), None)
    return Table(
        p,
        np.vstack([t.data for t in parts]),
        np.concatenate([t.line_numbers for t in parts]),
        int(cut is not None),
        cut_line=cut,
    )


def iter_pcd(path: str | Path) -> Iterator[Table]:
    """The points of an ASCII PCD with fields starting ``x y``, a block of rows at a time
    (:func:`sonarslam.datasets.logfile.iter_line_blocks`): the memory of one block, whatever the file's
    size. At least one table (empty when the file has no point); its ``POINTS`` are checked
    against the rows when the last block has been read.

    Raises
    ------
    DataError
        A header byte that is not ASCII (a UTF-8 byte-order mark included: PCD is ASCII), no
        ``DATA ascii`` line, FIELDS not starting with ``x y``, POINTS not a whole number or not
        the count of point rows, a row with another number of fields, a field that is not a
        finite number (the strict tokenizer, :mod:`sonarslam.datasets.logfile`).
    """
    p = Path(path)
    header: dict[str, str] = {}
    data_line: int | None = None
    names: list[str] = []
    n_rows = 0
    cut: int | None = None
    for first, lines, open_end in iter_line_blocks(p):
        start = 0
        if data_line is None:
            for i, raw in enumerate(lines):
                check_ascii(p, first + i, raw)
                line = raw.strip(" \t")
                if not line or line.startswith("#"):
                    continue
                key, *value = _SPACES.split(line, maxsplit=1)
                header[key] = value[0] if value else ""
                if key == "DATA":
                    data_line = first + i
                    start = i + 1
                    break
            if data_line is None:  # the header goes on in the next block
                continue
            if header.get("DATA") != "ascii":
                raise DataError(p, None, "no 'DATA ascii' header line")
            names = _SPACES.split(header.get("FIELDS", ""))
            if names[:2] != ["x", "y"]:
                raise DataError(
                    p, None, f"FIELDS must start with 'x y', got {header.get('FIELDS')!r}"
                )
            if not _INT_RE.fullmatch(header.get("POINTS", "")):
                raise DataError(p, None, "POINTS header missing or not a whole number")
        numbered = [
            (number, line.strip(" \t"))
            for number, line in enumerate(lines[start:], start=first + start)
            if line.strip(" \t")
        ]
        if not numbered:
            continue
        table = parse_table(
            p,
            numbered,
            open_end,
            n_columns=len(names),
            time_column=None,
            used_columns=(0, 1),
            skip_wrong_columns=False,
            warn=False,
            require_rows=False,
        )
        cut = table.cut_line if table.cut_line is not None else cut
        n_rows += table.line_numbers.size
        if n_rows > int(header["POINTS"]):
            break  # the count is wrong: said below, without reading the rest
        yield table
    if data_line is None:
        raise DataError(p, None, "no 'DATA ascii' header line")
    n_points = int(header["POINTS"])
    if n_rows > n_points:
        raise DataError(p, None, f"POINTS says {n_points} but the file has more point rows")
    if n_rows != n_points:
        if not n_rows:
            note = "" if cut is None else f" (line {cut} has no line end and may be cut)"
            raise DataError(p, None, f"POINTS says {n_points} but the file has no point rows{note}")
        raise DataError(p, None, f"POINTS says {n_points} but the file has {n_rows} point rows")
    if not n_rows:
        yield Table(p, np.zeros((0, len(names))), np.zeros(0, dtype=np.int64), 0)


def read_pcd_xy(path: str | Path) -> FloatArray:
    """Read an ASCII PCD with fields ``x y z``; returns the points' ``(x, y)``, shape (N, 2)."""
    return read_pcd(path).data[:, :2].copy()


def read_keyframe_times(path: str | Path) -> tuple[np.ndarray, FloatArray, FloatArray, np.ndarray]:
    """Read ``keyFrameTimeStamps.csv``: ``(keyframe numbers, begin times, end times, lines)``.

    The first line must be the header ``keyFrame,keyFrameBeginning,keyFrameEnd`` (a file
    without it would lose its first keyframe); keyframe numbers are whole, increasing numbers;
    times are Unix times, each scan ending after it begins and beginning no earlier than the
    previous one. ``lines`` (K,) are the physical line numbers of the rows.
    """
    p = Path(path)
    lines, terminated = text_lines(p)
    names = tuple(f.strip(" \t") for f in lines[0].split(",")) if lines else ()
    if names != KEYFRAME_CSV_HEADER:
        raise DataError(p, 1, f"expected the header line {','.join(KEYFRAME_CSV_HEADER)!r}")
    numbered = [
        (number, line.strip(" \t"))
        for number, line in enumerate(lines[1:], start=2)
        if line.strip(" \t")
    ]
    if not numbered:
        raise DataError(p, None, "no data rows")
    table = parse_table(
        p,
        numbered,
        None if terminated else len(lines),
        n_columns=3,
        time_column=1,
        used_columns=(0, 1),
        delimiter=",",
        skip_wrong_columns=False,
    )
    k, begin, end = table.data.T
    rows = table.line_numbers

    def first(bad: np.ndarray, message: str) -> None:
        if np.any(bad):
            raise DataError(p, int(rows[np.flatnonzero(bad)[0]]), message)

    first((k != np.rint(k)) | (k < 0) | (k >= 2**31), "keyframe number is not a whole number")
    first(np.concatenate([[False], np.diff(k) <= 0]), "keyframe numbers must increase")
    first(~(end > begin), "keyframe ends before it begins")
    first(end >= MAX_UNIX_TIME_S, "keyframe end is not a Unix time")
    return k.astype(np.int64), begin.copy(), end.copy(), rows.copy()


def read_keyframes(
    keyframe_dir: str | Path,
    is_timestamps_s: FloatArray,
    head: SonarHead,
    scan_direction: int = -1,
    cache: bool = True,
) -> BeamSeries:
    """Rebuild the thresholded beams of every keyframe with their exact times.

    Parameters
    ----------
    keyframe_dir : str or Path
        Folder with ``pclKeyFrame{k}.pcd`` and ``keyFrameTimeStamps.csv``.
    is_timestamps_s : ndarray, shape (M,)
        Beam times from ``*_IS_timestamps.log`` (Unix s).
    head : SonarHead
        Step and bin size of the scans.
    scan_direction : int
        +1: angle index ``j`` is the ``j``-th beam of the scan; -1: the ``(-j mod n)``-th
        (see the module docstring).
    cache : bool
        Keep the beams in a versioned ``.npz`` (:mod:`sonarslam.datasets.cache`) and read them from it
        while the keyframe files, the beam times and the head are the same.

    Returns
    -------
    BeamSeries
        ``thresholded`` beams (255 at the bins that passed, 0 elsewhere), in time order.

    Raises
    ------
    DataError
        A missing PCD, a keyframe start that is no IS_timestamps row, a point off the polar
        grid or beyond the last bin, scans that overlap in time.
    """
    if scan_direction not in (-1, 1):
        raise ValueError(f"scan_direction must be +1 or -1, got {scan_direction}")
    folder = Path(keyframe_dir)
    times_path = folder / "keyFrameTimeStamps.csv"
    numbers, begins, _, csv_lines = read_keyframe_times(times_path)
    pcds = [folder / f"pclKeyFrame{k}.pcd" for k in numbers]
    for pcd in pcds:
        if not pcd.is_file():
            read_pcd(pcd)  # the reader's own message (missing, a directory, a FIFO...)
    key = {
        "head": [head.n_bins, head.bin_size_m, head.step_rad],
        "scan_direction": scan_direction,
        "is_timestamps": is_timestamps_s,
    }
    if cache:
        hit = load_cached(folder, "keyframes", [times_path, *pcds], key)
        try:
            if hit is not None and hit["intensities"].shape[1] == head.n_bins:
                t, a, bins = hit["t_s"], hit["angle_rad"], hit["intensities"]
                return BeamSeries(t, a, bins, thresholded=True)
        except (KeyError, ValueError, IndexError):
            pass  # not a cache of these beams: parsed again
    beams = _rebuild_keyframes(
        times_path, numbers, begins, csv_lines, pcds, is_timestamps_s, head, scan_direction
    )
    if cache:
        save_cached(
            folder,
            "keyframes",
            [times_path, *pcds],
            key,
            {
                "t_s": beams.t_s,
                "angle_rad": beams.transducer_angle_rad,
                "intensities": beams.intensities,
            },
        )
    return beams


def _on_grid(
    points: Table, head: SonarHead, raw_head: SonarHead, beams_per_scan: int
) -> tuple[np.ndarray, np.ndarray]:
    """The angle index and bin of each point of a PCD block; a point off the polar grid or
    beyond the last bin is a :class:`DataError` naming its line."""
    xy = points.data[:, :2]
    a = np.arctan2(xy[:, 1], xy[:, 0]) % (2.0 * np.pi)
    j_float = a / head.step_rad
    j = np.rint(j_float).astype(np.int64) % beams_per_scan
    r = np.hypot(xy[:, 0], xy[:, 1])
    bin_float = raw_head.range_to_bin_float(r)  # the PCD's points lie at the raw bin ranges
    bins = np.rint(bin_float).astype(np.int64)
    off_grid = (np.abs(j_float - np.rint(j_float)) > _GRID_TOLERANCE) | (
        np.abs(bin_float - bins) > _GRID_TOLERANCE
    )
    bad = off_grid | (bins < 0) | (bins >= head.n_bins)
    if np.any(bad):
        raise DataError(
            points.path,
            int(points.line_numbers[int(np.flatnonzero(bad)[0])]),
            "point is not on the sonar's polar grid (step, bin size, range)",
        )
    return j, bins


def _rebuild_keyframes(
    times_path: Path,
    numbers: np.ndarray,
    begins: FloatArray,
    csv_lines: np.ndarray,
    pcds: list[Path],
    is_timestamps_s: FloatArray,
    head: SonarHead,
    scan_direction: int,
) -> BeamSeries:
    """:func:`read_keyframes` from the files: every PCD parsed and put on the polar grid."""
    beams_per_scan = int(round(2.0 * np.pi / head.step_rad))
    n = len(pcds) * beams_per_scan
    t_s = np.empty(n)
    angle = np.empty(n)
    intensities = np.zeros((n, head.n_bins), dtype=np.uint8)
    raw_head = replace(head, range_offset_m=0.0)
    last_row = -1
    order = (scan_direction * np.arange(beams_per_scan)) % beams_per_scan  # angle index in time
    for s, (k, begin, line, pcd) in enumerate(
        zip(numbers, begins, csv_lines.tolist(), pcds, strict=True)
    ):
        row = int(np.searchsorted(is_timestamps_s, begin))
        candidates = [r for r in (row - 1, row) if 0 <= r < is_timestamps_s.size]
        row = min(candidates, key=lambda r: abs(is_timestamps_s[r] - begin))
        if abs(is_timestamps_s[row] - begin) > _MATCH_TOLERANCE_S:
            raise DataError(
                times_path, line, f"keyframe {k} start {begin:.3f} is no IS_timestamps row"
            )
        if row + beams_per_scan > is_timestamps_s.size:
            raise DataError(times_path, line, f"keyframe {k} runs past the last IS timestamp")
        if row < last_row:
            raise DataError(times_path, line, f"keyframe {k} starts before the previous scan ends")
        last_row = row + beams_per_scan
        mask = np.zeros((beams_per_scan, head.n_bins), dtype=np.uint8)
        for points in iter_pcd(pcd):  # a block at a time: a PCD of any size fits
            j, bins = _on_grid(points, head, raw_head, beams_per_scan)
            mask[j, bins] = 255
        rows = slice(s * beams_per_scan, (s + 1) * beams_per_scan)
        t_s[rows] = is_timestamps_s[row : row + beams_per_scan]  # the i-th beam in time ...
        angle[rows] = order * head.step_rad  # ... has angle index (scan_direction i) mod n
        intensities[rows] = mask[order]
    return BeamSeries(t_s, angle, intensities, thresholded=True)
