"""The factor graph on disk: one record per factor, from which the GTSAM factor is built and
which is saved as JSON (``graph.json``, :func:`save_graph`; read back by :func:`load_graph`).

Records are plain dicts, so a graph can be saved, inspected and re-optimised with GTSAM without
this package's estimator state: :func:`load_graph` rebuilds GTSAM's own factors for the standard
types and the ``CustomFactor``s of :mod:`slam.backends.isam2.factors` for the others.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gtsam
import numpy as np
import numpy.typing as npt
from gtsam.symbol_shorthand import B, D, G, K, X

from features.geometry import FloatArray
from slam.backends.isam2.config import GraphConfig
from slam.backends.isam2.factors import (
    heading_factor,
    line_equality_factor,
    line_factor,
    noise_model,
    odometry_factor,
)

__all__ = [
    "GRAPH_FORMAT",
    "key_name",
    "key_of",
    "pose_of",
    "factor_record",
    "start_records",
    "factor_from_record",
    "values_to_json",
    "save_graph",
    "load_graph",
]

GRAPH_FORMAT = "sonarslam-graph/1"


def key_name(key: int) -> str:
    """``gtsam.Symbol`` string of a key: ``X(12)`` is ``"x12"``."""
    return str(gtsam.Symbol(key).string())


def key_of(name: str) -> int:
    """The key of a :func:`key_name` string."""
    return int(gtsam.Symbol(name[0], int(name[1:])).key())


def pose_of(p: gtsam.Pose2) -> FloatArray:
    """``(x_m, y_m, yaw_rad)`` of a ``gtsam.Pose2``."""
    return np.array([p.x(), p.y(), p.theta()])


def factor_record(
    kind: str, keys: Sequence[int], z: npt.ArrayLike, cov: npt.ArrayLike, **extra: Any
) -> dict[str, Any]:
    """The record of one factor (types in :func:`save_graph`)."""
    return {
        "type": kind,
        "keys": [key_name(k) for k in keys],
        "measurement": np.atleast_1d(np.asarray(z, dtype=np.float64)).tolist(),
        "covariance": np.atleast_2d(np.asarray(cov, dtype=np.float64)).tolist(),
        **extra,
    }


def start_records(
    wTb0: FloatArray, P0: FloatArray, config: GraphConfig
) -> tuple[list[dict[str, Any]], gtsam.Values]:
    """The factors and initial values of a graph's start: a prior on the start position,
    the AHRS bias ``B(0)`` (and ``D(0)``, ``G(0)``, ``K(0)`` when estimated) with their priors, and the
    start heading as an AHRS heading factor on ``X(0)`` (the start yaw came from the AHRS, so it
    carries the bias; its white noise is ``ahrs_white_sigma_deg``'s, P0's heading is not used)."""
    records = [factor_record("PoseTranslationPrior2D", [X(0)], wTb0[:2], P0[:2, :2])]
    values = gtsam.Values()
    b0 = np.deg2rad(config.ahrs_bias_prior_deg)
    var_b = np.deg2rad(config.ahrs_bias_sigma_deg) ** 2
    records.append(factor_record("PriorFactorVector", [B(0)], [b0], [[var_b]]))
    values.insert(B(0), np.array([b0]))
    if config.estimate_misalignment:
        var_d = np.deg2rad(config.misalignment_sigma_deg) ** 2
        records.append(factor_record("PriorFactorVector", [D(0)], [0.0], [[var_d]]))
        values.insert(D(0), np.zeros(1))
    if config.estimate_gyro_scale:
        records.append(
            factor_record("PriorFactorVector", [G(0)], [1.0], [[config.gyro_scale_sigma**2]])
        )
        values.insert(G(0), np.ones(1))
    if config.dvl_scale_sigma > 0.0:
        records.append(
            factor_record("PriorFactorVector", [K(0)], [0.0], [[config.dvl_scale_sigma**2]])
        )
        values.insert(K(0), np.zeros(1))
    values.insert(X(0), gtsam.Pose2(*wTb0))
    var_white = np.deg2rad(config.ahrs_white_sigma_deg) ** 2
    records.append(factor_record("HeadingBias", [X(0), B(0)], [wTb0[2]], [[var_white]]))
    return records, values


def factor_from_record(record: dict[str, Any]) -> gtsam.NonlinearFactor:
    """Build the GTSAM factor a record describes (see :func:`save_graph` for the types)."""
    kind = record["type"]
    keys = [key_of(k) for k in record["keys"]]
    z = np.asarray(record["measurement"], dtype=np.float64)
    cov = np.asarray(record["covariance"], dtype=np.float64)
    if kind == "PoseTranslationPrior2D":
        return gtsam.PoseTranslationPrior2D(keys[0], z, noise_model(cov))
    if kind == "PriorFactorPose2":
        return gtsam.PriorFactorPose2(keys[0], gtsam.Pose2(*z), noise_model(cov))
    if kind == "BetweenFactorPose2":
        robust = record.get("robust")
        noise = (
            noise_model(cov) if robust is None else noise_model(cov, robust["kernel"], robust["k"])
        )
        return gtsam.BetweenFactorPose2(keys[0], keys[1], gtsam.Pose2(*z), noise)
    if kind == "PriorFactorVector":
        return gtsam.PriorFactorVector(keys[0], z, noise_model(cov))
    if kind == "BetweenFactorVector":
        return gtsam.BetweenFactorVector(keys[0], keys[1], z, noise_model(cov))
    if kind == "HeadingBias":
        return heading_factor(keys[0], keys[1], float(z[0]), float(np.sqrt(cov[0, 0])))
    if kind == "DvlGyroOdometry":
        chars = [name[0] for name in record["keys"]]
        return odometry_factor(
            keys[0],
            keys[1],
            z,
            cov,
            misalignment_key=keys[chars.index("d")] if "d" in chars else None,
            scale_key=keys[chars.index("g")] if "g" in chars else None,
            yaw_raw_rad=float(record["yaw_raw"]),
            d_t_d_scale=record["d_t_d_scale"],
            scale0=float(record["scale0"]),
            dvl_scale_key=keys[chars.index("k")] if "k" in chars else None,
        )
    if kind == "LineEquality":
        return line_equality_factor(keys[0], keys[1], bool(z[0]), np.sqrt(np.diag(cov)))
    if kind == "LineObservation":
        robust = record.get("robust")
        return line_factor(
            keys[0],
            keys[1],
            z,
            cov,
            record["bTs"],
            None if robust is None else robust["kernel"],
            1.345 if robust is None else float(robust["k"]),
        )
    raise ValueError(f"unknown factor type {kind!r}")


def values_to_json(values: gtsam.Values) -> dict[str, dict[str, Any]]:
    """``{"x0": {"type": "Pose2", "value": [x, y, yaw]}, "l3": {"type": "Vector", ...}}``."""
    out: dict[str, dict[str, Any]] = {}
    for key in values.keys():
        name = key_name(key)
        if name[0] == "x":
            out[name] = {"type": "Pose2", "value": pose_of(values.atPose2(key)).tolist()}
        else:
            out[name] = {"type": "Vector", "value": np.asarray(values.atVector(key)).tolist()}
    return out


def save_graph(
    path: str | Path,
    records: Sequence[dict[str, Any]],
    values: gtsam.Values,
    meta: dict[str, Any] | None = None,
) -> None:
    """Write a graph and its values as JSON (read back by :func:`load_graph`).

    Format (``"format": "sonarslam-graph/1"``)::

        {"format": ..., "meta": {...},
         "factors": [{"type": T, "keys": ["x0", "l3"], "measurement": [...],
                      "covariance": [[...]], ...}, ...],
         "values": {"x0": {"type": "Pose2", "value": [x, y, yaw]},
                    "l3": {"type": "Vector", "value": [rho, theta]},
                    "b0": {"type": "Vector", "value": [b]}}}

    Keys are ``gtsam.Symbol`` strings (``x12`` is ``X(12)``). Factor types, their measurement
    and covariance (the covariance of the factor's error, as ``noiseModel.Gaussian``):

    * ``PoseTranslationPrior2D`` ``[x, y]`` (GTSAM's: the position of a Pose2, covariance in
      the world frame), ``PriorFactorPose2`` and ``BetweenFactorPose2`` ``[x, y, yaw]``
      (GTSAM's, covariance in the local tangent);
    * ``PriorFactorVector``, ``BetweenFactorVector``: GTSAM's (the latter ties the AHRS bias
      of consecutive nodes, ``b_j - b_i``, when it is a random walk);
    * ``HeadingBias`` on ``(x, b)``: ``[yaw_meas]``, error ``wrap(yaw + b - yaw_meas)``;
    * ``DvlGyroOdometry`` on ``(x_i, x_j[, d][, g][, k])``: ``[x, y, yaw]`` integrated with
      ``delta = 0``, gyro scale ``"scale0"`` and no DVL scale error, plus ``"yaw_raw"`` (the gyro's integral) and
      ``"d_t_d_scale"`` ``[dx/ds, dy/ds]`` (:func:`slam.backends.isam2.factors.odometry_residual`);
    * ``LineObservation`` on ``(x, l)``: ``[rho, theta]`` in the sonar frame, plus ``"bTs"``
      ``[x, y, yaw]`` and ``"robust"`` (``null`` or ``{"kernel": "huber", "k": 1.345}``);
      error :func:`slam.model.lines.line_residual`;
    * ``LineEquality`` on ``(l_keep, l_drop)``: ``[flipped]`` (0 or 1), a diagonal covariance;
      two landmarks found to be one wall (:func:`slam.backends.isam2.factors.line_equality_residual`).

    ``meta`` holds what is not a factor: node times, the sonar mounting, the settings.
    """
    doc = {
        "format": GRAPH_FORMAT,
        "meta": meta or {},
        "factors": list(records),
        "values": values_to_json(values),
    }
    Path(path).write_text(json.dumps(doc) + "\n")


def load_graph(path: str | Path) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """Read a graph written by :func:`save_graph`.

    Returns
    -------
    graph : gtsam.NonlinearFactorGraph
        GTSAM's own factors for the standard types, ``CustomFactor`` from
        :mod:`slam.backends.isam2.factors` for the others.
    values : gtsam.Values
    """
    doc = json.loads(Path(path).read_text())
    if doc.get("format") != GRAPH_FORMAT:
        raise ValueError(f"{path}: not a {GRAPH_FORMAT} file")
    graph = gtsam.NonlinearFactorGraph()
    for record in doc["factors"]:
        graph.add(factor_from_record(record))
    values = gtsam.Values()
    for name, item in doc["values"].items():
        v = np.asarray(item["value"], dtype=np.float64)
        if item["type"] == "Pose2":
            values.insert(key_of(name), gtsam.Pose2(*v))
        else:
            values.insert(key_of(name), v.reshape(-1))
    return graph, values
