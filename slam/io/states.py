"""The track of a slowly varying state of a closed loop: ``heading_error.csv``, the AHRS heading
error ``b`` (the AHRS measures ``yaw + b``) at each time with its sd, written by a back end whose
``b`` walks (``ahrs_bias_walk_deg_per_sqrt_s > 0``) and read by ``sonarslam report``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.errors import DataError
from sonarslam.features.geometry import FloatArray

__all__ = ["HEADING_ERROR_FILE", "write_heading_error", "read_heading_error"]

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
