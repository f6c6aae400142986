"""The raw MSIS log ``*_IS.log``: reader and writer.

Format (as read by public readers of the marina dataset): 7 header lines starting with ``%``,
then one row per beam ``logTime sensorTime transducerAngle bin_1 ... bin_N`` separated by tabs or
spaces; ``logTime`` in Unix s, ``sensorTime`` in ms since midnight, the transducer angle in rad,
intensities 0-255.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.logfile import iter_tables
from sonarslam.datasets.records import BeamSeries
from sonarslam.sonar.beam import FloatArray, SonarBeam

__all__ = ["read_is_log", "write_is_log"]

_TURN_RAD = 2.0 * np.pi + 1e-6  # the log writes angles to 1e-6 rad

_HEADER = [
    "% ----------------------------------------------------------------------",
    "% MSIS raw log written by sonarslam",
    "% Data columns:",
    "% logTime (s), sensorTime (ms since midnight), transducerAngle (rad), bin_1 ... bin_N (0-255)",
    "% bins: {n_bins}",
    "% ----------------------------------------------------------------------",
    "%",
]


def read_is_log(path: str | Path, n_bins: int | None = None) -> BeamSeries:
    """Read a raw ``_IS.log`` into beams, a block of rows at a time.

    Parameters
    ----------
    path : str or Path
        The log.
    n_bins : int, optional
        Bins per beam; by default taken from the first beam row.

    Returns
    -------
    BeamSeries
        In file order (time never decreases); the bins as uint8 rows, so the memory is the
        beams' bins (one byte each) and one block of text (:func:`sonarslam.datasets.logfile.iter_tables`),
        not the file's rows as floats and Python objects.

    Raises
    ------
    DataError
        Bad input by :mod:`sonarslam.datasets.logfile` (missing or special file, non-numeric or
        non-finite field, time going backwards), an intensity that is not a whole number in
        0-255, a transducer angle beyond +-2 pi rad. Rows with a wrong bin count, or a last
        line without a line end that may be cut, are skipped with a warning.
    """
    times: list[FloatArray] = []
    angles: list[FloatArray] = []
    bins_u8: list[npt.NDArray[np.uint8]] = []
    for table in iter_tables(path, n_columns=None if n_bins is None else n_bins + 3, min_columns=4):
        bins = table.data[:, 3:]
        bad = np.any((bins < 0.0) | (bins > 255.0) | (bins != np.rint(bins)), axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataError(
                table.path, int(table.line_numbers[i]), "intensity not a whole number in 0-255"
            )
        bad = np.abs(table.data[:, 2]) > _TURN_RAD
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataError(
                table.path, int(table.line_numbers[i]), "transducer angle beyond +-2 pi rad"
            )
        times.append(table.data[:, 0].copy())
        angles.append(table.data[:, 2].copy())
        bins_u8.append(bins.astype(np.uint8))
    return BeamSeries(np.concatenate(times), np.concatenate(angles), np.concatenate(bins_u8))


#: ``"0 "`` ... ``"255 "`` as fixed-width bytes (padded with NUL): a uint8 beam's bins are
#: written through this table, as ``str`` of each value joined by spaces (the same text, without
#: a Python string per bin).
_BIN_TEXT = np.array([f"{v} ".encode("ascii") for v in range(256)], dtype="S4")


def _bins_text(intensities: npt.NDArray[np.generic]) -> str:
    """The bins of one beam as the log writes them: each value, space-separated."""
    if intensities.dtype == np.uint8:
        return _BIN_TEXT[intensities].tobytes().replace(b"\0", b"")[:-1].decode("ascii")
    return " ".join(map(str, intensities.astype(int).tolist()))


def write_is_log(path: str | Path, beams: Iterable[SonarBeam]) -> int:
    """Write beams as a raw ``_IS.log``; returns the number of rows written.

    The sensor time column is the log time in ms since midnight UTC, as the Miniking logs it.
    """
    p = Path(path)
    lines: list[str] = []
    n_bins = None
    for beam in beams:
        if n_bins is None:
            n_bins = beam.intensities.size
        elif beam.intensities.size != n_bins:
            raise ValueError(f"beam at t={beam.t} has {beam.intensities.size} bins, not {n_bins}")
        sensor_ms = int(round((beam.t % 86400.0) * 1000.0))
        bins = _bins_text(beam.intensities)
        lines.append(f"{beam.t:.3f}\t{sensor_ms}\t{beam.transducer_angle_rad:.6f}\t{bins}")
    header = [h.format(n_bins=n_bins or 0) for h in _HEADER]
    p.write_text("\n".join(header + lines) + "\n", encoding="ascii")
    return len(lines)
