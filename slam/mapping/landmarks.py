"""The ``map.json`` record of a line landmark, shared by every back end."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from features.geometry import segment_on_line

__all__ = ["landmark_record"]


def landmark_record(
    landmark_id: int,
    line_w: npt.ArrayLike,
    cov: npt.ArrayLike,
    s_min_m: float,
    s_max_m: float,
    observations: int,
) -> dict[str, Any]:
    """One landmark of ``map.json``: id, ``rho``/``theta`` (world), 2x2 ``cov``, world
    ``endpoints`` of its extent ``[s_min_m, s_max_m]`` along the line, observation count."""
    line = np.asarray(line_w, dtype=np.float64)
    return {
        "id": int(landmark_id),
        "rho": float(line[0]),
        "theta": float(line[1]),
        "cov": np.asarray(cov, dtype=np.float64).tolist(),
        "endpoints": segment_on_line(line, s_min_m, s_max_m).tolist(),
        "observations": int(observations),
    }
