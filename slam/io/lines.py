"""``lines.jsonl`` back into line features: the files ``sonarslam extract`` and ``sonarslam run``
write (one :meth:`sonarslam.features.line.LineFeature.to_json` object per line; a run adds ``landmark``).

The segment ends are stored in the world; they are taken back into the frame R with the
stored pose of R, so :meth:`LineFeature.endpoints_world` gives them back unchanged.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.errors import DataError
from sonarslam.features.geometry import inverse, transform_points
from sonarslam.features.line import LineFeature

__all__ = ["line_from_json", "read_lines_jsonl"]

_REQUIRED = ("t", "x", "y", "yaw", "rho", "theta", "cov", "endpoints")
#: Every field of :meth:`LineFeature.to_json`; the rest of a row are a run's extras.
_FEATURE = (*_REQUIRED, "votes", "n_voters", "bTs")


def line_from_json(d: dict[str, Any]) -> LineFeature:
    """One ``lines.jsonl`` object as a :class:`LineFeature` (KeyError/ValueError when malformed)."""
    missing = [k for k in _REQUIRED if k not in d]
    if missing:
        raise KeyError(f"missing fields {missing}")
    wTr = np.array([d["x"], d["y"], d["yaw"]], dtype=np.float64)
    cov = np.asarray(d["cov"], dtype=np.float64)
    ends_w = np.asarray(d["endpoints"], dtype=np.float64)
    if cov.shape != (2, 2) or ends_w.shape != (2, 2):
        raise ValueError(f"cov and endpoints must be 2x2, got {cov.shape} and {ends_w.shape}")
    if not (np.all(np.isfinite(wTr)) and np.all(np.isfinite(cov)) and np.all(np.isfinite(ends_w))):
        raise ValueError("non-finite pose, covariance or endpoints")
    bTs = None
    if d.get("bTs") is not None:
        try:
            bTs = np.asarray(d["bTs"], dtype=np.float64)
        except (TypeError, ValueError):
            bTs = np.full(0, np.nan)
        if bTs.shape != (3,) or not np.all(np.isfinite(bTs)):
            raise ValueError(
                f"bTs must be three finite numbers (x_m, y_m, yaw_rad), got {d['bTs']}"
            )
    return LineFeature(
        t=float(d["t"]),
        wTr=wTr,
        rho_m=float(d["rho"]),
        theta_rad=float(d["theta"]),
        cov=cov,
        votes=int(d.get("votes", 0)),
        endpoints_r=transform_points(inverse(wTr), ends_w),
        n_voters=int(d.get("n_voters", 0)),
        bTs=bTs,
    )


def read_lines_jsonl(path: str | Path) -> tuple[list[LineFeature], list[dict[str, Any]]]:
    """Read a ``lines.jsonl``.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    lines : list of LineFeature
        In file order.
    extras : list of dict
        The fields of each row that are not the line feature's (a run's ``landmark``), in the
        same order.

    Raises
    ------
    DataError
        A missing file, a row that is not a JSON object with the fields of
        :meth:`LineFeature.to_json`, or a file without lines; names the file and line.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        raise DataError(p, None, "file not found") from exc
    lines: list[LineFeature] = []
    extras: list[dict[str, Any]] = []
    for number, row in enumerate(text.splitlines(), start=1):
        if not row.strip():
            continue
        try:
            d = json.loads(row)
            if not isinstance(d, dict):
                raise ValueError("not a JSON object")
            lines.append(line_from_json(d))
        except (KeyError, ValueError, TypeError) as exc:
            raise DataError(p, number, f"not a line feature: {exc}") from exc
        extras.append({k: v for k, v in d.items() if k not in _FEATURE})
    if not lines:
        raise DataError(p, None, "no lines")
    return lines, extras
