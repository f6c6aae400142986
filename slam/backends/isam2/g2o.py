"""The pose graph in g2o's text format (``graph.g2o``), which ``gtsam.readG2o`` and g2o load.

g2o's 2D types hold poses (``VERTEX_SE2 id x y theta``) and relative poses with their
information (``EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33``, the upper triangle of the
inverse covariance in the order ``(x, y, theta)``, as ``gtsam.BetweenFactorPose2``). Of our graph
(:func:`sonarslam.slam.backends.isam2.graph_io.save_graph`) that is the poses at the estimate and the
odometry; a g2o file cannot hold:

* the line landmarks ``L(j)`` and their ``LineObservation`` factors (g2o's 2D types have points
  and poses, no line through a sonar mounting),
* the AHRS ``HeadingBias`` factors and the bias ``B(0)`` (or ``B(k)`` per node tied by
  ``BetweenFactorVector`` when it is a random walk): g2o has no unary heading factor nor a
  scalar variable,
* the priors (``PoseTranslationPrior2D``, ``PriorFactorVector``, ``PriorFactorPose2``): GTSAM's
  reader adds none, so fix ``X(0)`` with a prior before optimising,
* the DVL misalignment ``D(0)`` and gyro scale ``G(0)`` of a ``DvlGyroOdometry`` that estimates
  them: such an edge is written at ``delta = 0``, ``s = scale0``.

The scan matcher's relative poses (``BetweenFactorPose2`` with ``"constraint"``,
:mod:`sonarslam.slam.backends.isam2.scans`) are ``EDGE_SE2`` too; their robust kernel is not (g2o's file
format has no kernel: a reader applies its own), which the warning counts.

``DvlGyroOdometry`` without those variables is ``BetweenFactorPose2`` to first order
(:func:`sonarslam.slam.backends.isam2.factors.odometry_residual`), so it is written as ``EDGE_SE2``. The
whole graph is ``graph.json`` (:func:`sonarslam.slam.backends.isam2.graph_io.load_graph`). Vertex ``k`` of
the file is ``X(k)``.
"""

from __future__ import annotations

import json
import warnings
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.slam.backends.isam2.graph_io import GRAPH_FORMAT

__all__ = ["G2O_EDGE_TYPES", "G2oExport", "write_g2o", "graph_json_to_g2o"]

#: Our factor types that become ``EDGE_SE2``.
G2O_EDGE_TYPES = ("DvlGyroOdometry", "BetweenFactorPose2")


@dataclass(frozen=True)
class G2oExport:
    """What :func:`write_g2o` wrote and left out.

    Attributes
    ----------
    path : Path
    vertices, edges : int
        ``VERTEX_SE2`` and ``EDGE_SE2`` lines.
    left_out : dict of str to int
        Factors g2o cannot hold, by type.
    approximated : int
        Odometry edges written without their misalignment / gyro-scale variables.
    scan_edges : int
        Of the edges, the scan matcher's relative poses.
    unkerneled : int
        Edges whose robust kernel the file cannot hold.
    whole : str
        The file that holds the whole graph.
    """

    path: Path
    vertices: int
    edges: int
    left_out: dict[str, int] = field(default_factory=dict)
    approximated: int = 0
    whole: str = "graph.json"
    scan_edges: int = 0
    unkerneled: int = 0

    def message(self) -> str:
        """One line for the warning and the terminal."""
        gone = ", ".join(f"{n} {kind}" for kind, n in sorted(self.left_out.items()))
        text = (
            f"{self.path.name} holds the {self.vertices} poses and {self.edges} relative-pose"
            f" factors (EDGE_SE2: {self.edges - self.scan_edges} odometry, {self.scan_edges} scan);"
            f" g2o cannot hold {gone or 'nothing else here'}"
        )
        if self.unkerneled:
            text += f"; {self.unkerneled} edges lost their robust kernel"
        if self.approximated:
            text += f"; {self.approximated} odometry edges lost their misalignment/scale terms"
        return text + f" ({self.whole} has the whole graph)"


def _pose_index(name: str) -> int:
    if name[0] != "x":
        raise ValueError(f"not a pose key: {name!r}")
    return int(name[1:])


def _edge(record: dict[str, Any]) -> str:
    i, j = (_pose_index(k) for k in record["keys"][:2])
    z = np.asarray(record["measurement"], dtype=np.float64)
    info = np.linalg.inv(np.asarray(record["covariance"], dtype=np.float64))
    info = 0.5 * (info + info.T)
    upper = info[np.triu_indices(3)]
    return f"EDGE_SE2 {i} {j} " + " ".join(f"{v:.17g}" for v in (*z, *upper))


def write_g2o(
    path: str | Path,
    factors: list[dict[str, Any]],
    values: dict[str, dict[str, Any]],
    whole: str = "graph.json",
    warn: bool = True,
) -> G2oExport:
    """Write the poses and odometry of a graph (``graph.json``'s ``factors`` and ``values``) as
    g2o; warns (``UserWarning``, unless ``warn`` is False: a caller that reports
    :meth:`G2oExport.message` itself) naming the factors it left out (module docstring)."""
    out = Path(path)
    lines = []
    poses = sorted(
        (_pose_index(name), v["value"]) for name, v in values.items() if v["type"] == "Pose2"
    )
    for k, (x, y, yaw) in poses:
        lines.append(f"VERTEX_SE2 {k} {x:.17g} {y:.17g} {yaw:.17g}")
    left_out: Counter[str] = Counter()
    approximated = edges = scan_edges = unkerneled = 0
    for record in factors:
        if record["type"] not in G2O_EDGE_TYPES:
            left_out[record["type"]] += 1
            continue
        approximated += len(record["keys"]) > 2
        scan_edges += "constraint" in record
        unkerneled += record.get("robust") is not None
        lines.append(_edge(record))
        edges += 1
    out.write_text("\n".join(lines) + "\n")
    result = G2oExport(
        out, len(poses), edges, dict(left_out), approximated, whole, scan_edges, unkerneled
    )
    if warn and (left_out or approximated or unkerneled):
        warnings.warn(result.message(), UserWarning, stacklevel=2)
    return result


def graph_json_to_g2o(
    json_path: str | Path, g2o_path: str | Path | None = None, warn: bool = True
) -> G2oExport:
    """``graph.json`` (:func:`sonarslam.slam.backends.isam2.graph_io.save_graph`) to ``graph.g2o`` beside
    it (or ``g2o_path``); ``warn`` as :func:`write_g2o`'s."""
    src = Path(json_path)
    doc = json.loads(src.read_text())
    if doc.get("format") != GRAPH_FORMAT:
        raise ValueError(f"{src}: not a {GRAPH_FORMAT} file")
    return write_g2o(
        g2o_path or src.with_suffix(".g2o"), doc["factors"], doc["values"], src.name, warn
    )
