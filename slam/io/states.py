"""The tracks of slowly varying quantities of a closed loop, written by a back end and read by
``sonarslam report``: ``heading_error.csv``, the AHRS heading error ``b`` (the AHRS measures
``yaw + b``) at each time with its sd, of a back end whose ``b`` walks
(``ahrs_bias_walk_deg_per_sqrt_s > 0``, or learned); ``noise.csv``, the noise a loop learns
(``learn_noise``, :mod:`sonarslam.slam.model.noise_learning`) at each of its steps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.errors import DataError
from sonarslam.features.geometry import FloatArray

__all__ = [
    "HEADING_ERROR_FILE",
    "write_heading_error",
    "read_heading_error",
    "NOISE_FILE",
    "NOISE_COLUMNS",
    "write_learned_noise",
    "read_learned_noise",
]

#: The file of the heading error's track in a run directory.
HEADING_ERROR_FILE = "heading_error.csv"

_HEADER = "t_s,b_deg,sd_deg"


def write_heading_error(
    path: str | Path, t_s: npt.ArrayLike, b_rad: npt.ArrayLike, sd_rad: npt.ArrayLike
) -> Path:
    """Write ``t_s, b_deg, sd_deg`` rows (Unix s, deg, deg) from radians; shapes (N,)."""
    rows = np.column_stack(
        [np.asarray(t_s, dtype=np.float64), np.rad2deg(b_rad), np.rad2deg(sd_rad)]
    )
    p = Path(path)
    np.savetxt(p, rows, fmt=["%.6f", "%.6f", "%.6f"], delimiter=",", header=_HEADER, comments="")
    return p


def read_heading_error(path: str | Path) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(t_s, b_deg, sd_deg)``, shapes (N,); DataError naming the file and line when a row is
    not three numbers or a header other than ``t_s,b_deg,sd_deg``."""
    p = Path(path)
    lines = p.read_text().splitlines()
    if not lines or lines[0].strip() != _HEADER:
        raise DataError(p, 1, f"expected the header {_HEADER!r}")
    out = np.empty((len(lines) - 1, 3))
    for i, line in enumerate(lines[1:]):
        parts = line.split(",")
        try:
            if len(parts) != 3:
                raise ValueError(f"{len(parts)} fields")
            out[i] = [float(v) for v in parts]
        except ValueError as e:
            raise DataError(p, i + 2, f"expected three numbers t_s,b_deg,sd_deg: {e}") from e
    return out[:, 0], out[:, 1], out[:, 2]


#: The file of the learned noise's track in a run directory.
NOISE_FILE = "noise.csv"
#: Its columns after ``t_s``: the heading walk (deg/sqrt(s)), the DVL scale walk (1/sqrt(s)),
#: the factors on the line and revisit covariances; empty where not learned.
NOISE_COLUMNS = (
    "heading_walk_deg_per_sqrt_s",
    "dvl_scale_walk_per_sqrt_s",
    "line_scale",
    "scan_scale",
)


def write_learned_noise(path: str | Path, t_s: npt.ArrayLike, values: npt.ArrayLike) -> Path:
    """Write ``t_s`` (N,) and ``values`` (N, 4) in :data:`NOISE_COLUMNS`' units and order (NaN:
    not learned, an empty cell)."""
    v = np.asarray(values, dtype=np.float64)
    rows = [",".join(("t_s", *NOISE_COLUMNS))]
    for t, row in zip(np.asarray(t_s, dtype=np.float64), v, strict=True):
        cells = ["" if not np.isfinite(x) else f"{x:.6g}" for x in row]
        rows.append(",".join([f"{t:.6f}", *cells]))
    p = Path(path)
    p.write_text("\n".join(rows) + "\n")
    return p


def read_learned_noise(path: str | Path) -> tuple[FloatArray, FloatArray]:
    """``(t_s (N,), values (N, 4))`` of :func:`write_learned_noise`, NaN where empty; DataError
    naming the file and line on another header or a row that is not five cells of numbers."""
    p = Path(path)
    lines = p.read_text().splitlines()
    head = ",".join(("t_s", *NOISE_COLUMNS))
    if not lines or lines[0].strip() != head:
        raise DataError(p, 1, f"expected the header {head!r}")
    t = np.empty(len(lines) - 1)
    v = np.empty((len(lines) - 1, len(NOISE_COLUMNS)))
    for i, line in enumerate(lines[1:]):
        parts = line.split(",")
        try:
            if len(parts) != 1 + len(NOISE_COLUMNS):
                raise ValueError(f"{len(parts)} fields")
            t[i] = float(parts[0])
            v[i] = [float(x) if x.strip() else np.nan for x in parts[1:]]
        except ValueError as e:
            raise DataError(p, i + 2, f"expected t_s and {len(NOISE_COLUMNS)} numbers: {e}") from e
    return t, v
