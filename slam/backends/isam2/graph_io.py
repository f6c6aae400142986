"""The factor graph on disk: one record per factor, from which the GTSAM factor is built and
which is saved as JSON (``graph.json``, :func:`save_graph`; read back by :func:`load_graph`).

Each factor is a typed :class:`FactorRecord` (its :class:`FactorKind`, keys, measurement,
covariance and what its type needs beyond them), built into GTSAM by :meth:`FactorRecord.to_gtsam`
through one builder per kind; its JSON form lets a graph be saved, inspected and re-optimised
with GTSAM without this package's estimator state: :func:`load_graph` rebuilds GTSAM's own
factors for the standard types and the ``CustomFactor``s of :mod:`sonarslam.slam.backends.isam2.factors`
for the others.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import gtsam
import numpy as np
import numpy.typing as npt
from gtsam.symbol_shorthand import B, C, D, G, K, R, X

from sonarslam.features.geometry import FloatArray
from sonarslam.slam.backends.isam2.config import GraphConfig
from sonarslam.slam.backends.isam2.factors import (
    calibrated_line_factor,
    calibrated_scan_factor,
    heading_factor,
    line_equality_factor,
    line_factor,
    mount_prior_dvl_factor,
    noise_model,
    odometry_factor,
)

__all__ = [
    "GRAPH_FORMAT",
    "LEARNED_SCALE_SIGMA",
    "key_name",
    "key_of",
    "pose_of",
    "FactorKind",
    "Robust",
    "OdometryTerms",
    "FactorRecord",
    "start_records",
    "values_to_json",
    "save_graph",
    "load_graph",
    "values_from_json",
]

GRAPH_FORMAT = "sonarslam-graph/1"

#: The prior sigma of the DVL scale error ``K(0)`` of a graph told none (``dvl_scale_sigma =
#: 0``) that learns its walk (``learn_noise`` with ``"dvl_scale"``): 0, numerically.
LEARNED_SCALE_SIGMA = 1e-4


def key_name(key: int) -> str:
    """``gtsam.Symbol`` string of a key: ``X(12)`` is ``"x12"``."""
    return str(gtsam.Symbol(key).string())


def key_of(name: str) -> int:
    """The key of a :func:`key_name` string."""
    return int(gtsam.Symbol(name[0], int(name[1:])).key())


def pose_of(p: gtsam.Pose2) -> FloatArray:
    """``(x_m, y_m, yaw_rad)`` of a ``gtsam.Pose2``."""
    return np.array([p.x(), p.y(), p.theta()])


class FactorKind(Enum):
    """The factor types of a graph, by their name in ``graph.json`` (:func:`save_graph`)."""

    POSE_TRANSLATION_PRIOR = "PoseTranslationPrior2D"
    PRIOR_POSE = "PriorFactorPose2"
    BETWEEN_POSE = "BetweenFactorPose2"
    PRIOR_VECTOR = "PriorFactorVector"
    BETWEEN_VECTOR = "BetweenFactorVector"
    HEADING_BIAS = "HeadingBias"
    DVL_GYRO_ODOMETRY = "DvlGyroOdometry"
    LINE_EQUALITY = "LineEquality"
    LINE_OBSERVATION = "LineObservation"
    LINE_OBSERVATION_CALIBRATED = "LineObservationCalibrated"
    SCAN_CALIBRATED = "ScanRegistrationCalibrated"
    MOUNT_PRIOR_DVL = "SonarMountPriorDvl"


@dataclass(frozen=True)
class Robust:
    """A robust kernel on a factor's whitened error: ``kernel`` ``"huber"`` or ``"cauchy"``,
    width ``k`` (sigmas)."""

    kernel: str
    k: float


@dataclass(frozen=True)
class OdometryTerms:
    """What a ``DvlGyroOdometry`` factor needs beyond its measurement: the gyro's heading
    integral ``yaw_raw_rad``, the translation's derivative by the gyro scale ``d_t_d_scale``
    ``(dx/ds, dy/ds)`` (m) and the gyro scale ``scale0`` it was integrated with
    (:func:`sonarslam.slam.backends.isam2.factors.odometry_residual`)."""

    yaw_raw_rad: float
    d_t_d_scale: tuple[float, float]
    scale0: float


@dataclass(frozen=True, eq=False)
class FactorRecord:
    """One factor of the graph, as decided and as saved: :meth:`to_gtsam` builds it,
    :meth:`to_json` / :meth:`from_json` are its ``graph.json`` form (:func:`save_graph`).

    Attributes
    ----------
    kind : FactorKind
    keys : tuple of int
        GTSAM keys of its variables, in the factor's order.
    z : ndarray, shape (d,)
        The measurement.
    cov : ndarray, shape (d, d)
        The covariance of the factor's error (``noiseModel.Gaussian``).
    bTs : ndarray, shape (3,), optional
        The sonar mounting of a ``LineObservation``; of the calibrated kinds, the mounting
        assumed (the front end's, and the factor's when the mounting is not a variable).
    kTb : ndarray, shape (3,), optional
        Of a ``LineObservationCalibrated``: the body's pose at the observation in its node's
        frame.
    robust : Robust, optional
        A kernel (``LineObservation``, ``BetweenFactorPose2``).
    odometry : OdometryTerms, optional
        Of a ``DvlGyroOdometry``.
    constraint : str, optional
        Where a ``BetweenFactorPose2`` came from beside the odometry (``"scan-revisit"``).
    """

    kind: FactorKind
    keys: tuple[int, ...]
    z: FloatArray
    cov: FloatArray
    bTs: FloatArray | None = None
    robust: Robust | None = None
    odometry: OdometryTerms | None = None
    constraint: str | None = None
    kTb: FloatArray | None = None

    @classmethod
    def of(
        cls,
        kind: FactorKind,
        keys: Sequence[int],
        z: npt.ArrayLike,
        cov: npt.ArrayLike,
        **extra: Any,
    ) -> FactorRecord:
        """A record from array-likes (``z`` at least 1-d, ``cov`` at least 2-d, as floats)."""
        return cls(
            kind,
            tuple(int(k) for k in keys),
            np.atleast_1d(np.asarray(z, dtype=np.float64)),
            np.atleast_2d(np.asarray(cov, dtype=np.float64)),
            **extra,
        )

    def to_gtsam(self) -> gtsam.NonlinearFactor:
        """The GTSAM factor (GTSAM's own for the standard types, a ``CustomFactor`` of
        :mod:`sonarslam.slam.backends.isam2.factors` for the others)."""
        return _BUILDERS[self.kind](self)

    def to_json(self) -> dict[str, Any]:
        """The ``graph.json`` form: ``type``, ``keys`` (``gtsam.Symbol`` strings),
        ``measurement``, ``covariance`` and what the type has beyond them."""
        out: dict[str, Any] = {
            "type": self.kind.value,
            "keys": [key_name(k) for k in self.keys],
            "measurement": self.z.tolist(),
            "covariance": self.cov.tolist(),
        }
        if self.odometry is not None:
            out["yaw_raw"] = self.odometry.yaw_raw_rad
            out["d_t_d_scale"] = list(self.odometry.d_t_d_scale)
            out["scale0"] = self.odometry.scale0
        if self.bTs is not None:
            out["bTs"] = self.bTs.tolist()
        if self.kTb is not None:
            out["kTb"] = self.kTb.tolist()
        if self.robust is not None or self.kind in _LINE_KINDS:
            out["robust"] = None if self.robust is None else asdict(self.robust)
        if self.constraint is not None:
            out["constraint"] = self.constraint
        return out

    @classmethod
    def from_json(cls, item: dict[str, Any], where: str = "graph") -> FactorRecord:
        """A record from its ``graph.json`` form; a ValueError naming ``where`` (the file and
        the factor) and what is wrong otherwise."""
        if not isinstance(item, dict):
            raise ValueError(f"{where}: a factor is a JSON object, got {type(item).__name__}")
        try:
            kind = FactorKind(item["type"])
            keys = [key_of(k) for k in item["keys"]]
            z = np.asarray(item["measurement"], dtype=np.float64)
            cov = np.asarray(item["covariance"], dtype=np.float64)
            robust = item.get("robust")
            odometry = None
            if kind is FactorKind.DVL_GYRO_ODOMETRY:
                jx, jy = (float(v) for v in item["d_t_d_scale"])
                odometry = OdometryTerms(float(item["yaw_raw"]), (jx, jy), float(item["scale0"]))
            bTs = item.get("bTs")
            kTb = item.get("kTb")
            record = cls.of(
                kind,
                keys,
                z,
                cov,
                bTs=None if bTs is None else np.asarray(bTs, dtype=np.float64),
                robust=None if robust is None else Robust(robust["kernel"], float(robust["k"])),
                odometry=odometry,
                constraint=item.get("constraint"),
                kTb=None if kTb is None else np.asarray(kTb, dtype=np.float64),
            )
        except (KeyError, TypeError, ValueError, IndexError) as e:
            raise ValueError(f"{where}: {item.get('type', '?')!r} factor: {e!r}") from e
        low, high = _N_KEYS.get(kind, (2, 2))
        if not low <= len(keys) <= high:
            n = f"{low}" if low == high else f"{low} to {high}"
            raise ValueError(f"{where}: {kind.value} factor takes {n} keys, got {len(keys)}")
        size = _Z_SIZE.get(kind)
        if record.z.ndim != 1 or (size is not None and record.z.size != size):
            raise ValueError(
                f"{where}: {kind.value} factor: measurement of shape {record.z.shape}, expected"
                f" {size if size is not None else 'a vector'}"
            )
        for name, pose in (("bTs", record.bTs), ("kTb", record.kTb)):
            if pose is not None and pose.shape != (3,):
                raise ValueError(
                    f"{where}: {kind.value} factor: {name} of shape {pose.shape}, expected (3,)"
                )
        if record.robust is not None and record.robust.kernel not in ("huber", "cauchy"):
            raise ValueError(
                f"{where}: {kind.value} factor: robust kernel {record.robust.kernel!r},"
                " expected 'huber' or 'cauchy'"
            )
        if record.cov.shape != (record.z.size, record.z.size):
            raise ValueError(
                f"{where}: {kind.value} factor: covariance {record.cov.shape} does not match"
                f" the measurement's {record.z.size} values"
            )
        if kind in _NEEDS_BTS and record.bTs is None:
            raise ValueError(f"{where}: {kind.value} factor without bTs")
        if kind is FactorKind.LINE_OBSERVATION_CALIBRATED and record.kTb is None:
            raise ValueError(f"{where}: {kind.value} factor without kTb")
        return record


_LINE_KINDS = (FactorKind.LINE_OBSERVATION, FactorKind.LINE_OBSERVATION_CALIBRATED)
_NEEDS_BTS = (*_LINE_KINDS, FactorKind.SCAN_CALIBRATED)


#: How many keys a factor of each kind takes (the others: two).
_N_KEYS = {
    FactorKind.POSE_TRANSLATION_PRIOR: (1, 1),
    FactorKind.PRIOR_POSE: (1, 1),
    FactorKind.PRIOR_VECTOR: (1, 1),
    FactorKind.DVL_GYRO_ODOMETRY: (2, 5),
    FactorKind.LINE_OBSERVATION_CALIBRATED: (2, 4),
    FactorKind.SCAN_CALIBRATED: (2, 4),
    FactorKind.MOUNT_PRIOR_DVL: (2, 2),
}


#: The measurement's size of each kind (the vector priors and betweens: any).
_Z_SIZE = {
    FactorKind.POSE_TRANSLATION_PRIOR: 2,
    FactorKind.PRIOR_POSE: 3,
    FactorKind.BETWEEN_POSE: 3,
    FactorKind.HEADING_BIAS: 1,
    FactorKind.DVL_GYRO_ODOMETRY: 3,
    FactorKind.LINE_EQUALITY: 1,
    FactorKind.LINE_OBSERVATION: 2,
    FactorKind.LINE_OBSERVATION_CALIBRATED: 2,
    FactorKind.SCAN_CALIBRATED: 3,
    FactorKind.MOUNT_PRIOR_DVL: 3,
}


def _noise(record: FactorRecord) -> gtsam.noiseModel.Base:
    robust = record.robust
    if robust is None:
        return noise_model(record.cov)
    return noise_model(record.cov, robust.kernel, robust.k)


def _dvl_gyro_odometry(record: FactorRecord) -> gtsam.NonlinearFactor:
    assert record.odometry is not None, "a DvlGyroOdometry record has its terms"
    keys = record.keys
    by_char = {chr(gtsam.Symbol(k).chr()): k for k in keys[2:]}
    terms = record.odometry
    return odometry_factor(
        keys[0],
        keys[1],
        record.z,
        record.cov,
        misalignment_key=by_char.get("d"),
        scale_key=by_char.get("g"),
        yaw_raw_rad=terms.yaw_raw_rad,
        d_t_d_scale=list(terms.d_t_d_scale),
        scale0=terms.scale0,
        dvl_scale_key=by_char.get("k"),
    )


def _line_observation(record: FactorRecord) -> gtsam.NonlinearFactor:
    assert record.bTs is not None, "a LineObservation record has its mounting"
    robust = record.robust
    return line_factor(
        record.keys[0],
        record.keys[1],
        record.z,
        record.cov,
        record.bTs.tolist(),
        None if robust is None else robust.kernel,
        1.345 if robust is None else robust.k,
    )


def _calibration_keys(record: FactorRecord) -> dict[str, int]:
    """The mounting ``C(0)`` and range scale ``R(0)`` among a calibrated factor's keys, by
    their symbol's character."""
    return {chr(gtsam.Symbol(k).chr()): k for k in record.keys[2:]}


def _line_calibrated(record: FactorRecord) -> gtsam.NonlinearFactor:
    assert record.bTs is not None and record.kTb is not None, "checked when read or made"
    by_char = _calibration_keys(record)
    robust = record.robust
    return calibrated_line_factor(
        record.keys[0],
        record.keys[1],
        record.z,
        record.cov,
        record.kTb,
        record.bTs,
        mount_key=by_char.get("c"),
        scale_key=by_char.get("r"),
        robust=None if robust is None else robust.kernel,
        robust_k=1.345 if robust is None else robust.k,
    )


def _scan_calibrated(record: FactorRecord) -> gtsam.NonlinearFactor:
    assert record.bTs is not None, "checked when read or made"
    by_char = _calibration_keys(record)
    robust = record.robust
    return calibrated_scan_factor(
        record.keys[0],
        record.keys[1],
        record.z,
        record.cov,
        record.bTs,
        mount_key=by_char.get("c"),
        scale_key=by_char.get("r"),
        robust=None if robust is None else robust.kernel,
        robust_k=1.0 if robust is None else robust.k,
    )


_BUILDERS: dict[FactorKind, Callable[[FactorRecord], gtsam.NonlinearFactor]] = {
    FactorKind.POSE_TRANSLATION_PRIOR: lambda r: gtsam.PoseTranslationPrior2D(
        r.keys[0], r.z, noise_model(r.cov)
    ),
    FactorKind.PRIOR_POSE: lambda r: gtsam.PriorFactorPose2(
        r.keys[0], gtsam.Pose2(*r.z), noise_model(r.cov)
    ),
    FactorKind.BETWEEN_POSE: lambda r: gtsam.BetweenFactorPose2(
        r.keys[0], r.keys[1], gtsam.Pose2(*r.z), _noise(r)
    ),
    FactorKind.PRIOR_VECTOR: lambda r: gtsam.PriorFactorVector(r.keys[0], r.z, noise_model(r.cov)),
    FactorKind.BETWEEN_VECTOR: lambda r: gtsam.BetweenFactorVector(
        r.keys[0], r.keys[1], r.z, noise_model(r.cov)
    ),
    FactorKind.HEADING_BIAS: lambda r: heading_factor(
        r.keys[0], r.keys[1], float(r.z[0]), float(np.sqrt(r.cov[0, 0]))
    ),
    FactorKind.DVL_GYRO_ODOMETRY: _dvl_gyro_odometry,
    FactorKind.LINE_EQUALITY: lambda r: line_equality_factor(
        r.keys[0], r.keys[1], bool(r.z[0]), np.sqrt(np.diag(r.cov))
    ),
    FactorKind.LINE_OBSERVATION: _line_observation,
    FactorKind.LINE_OBSERVATION_CALIBRATED: _line_calibrated,
    FactorKind.SCAN_CALIBRATED: _scan_calibrated,
    FactorKind.MOUNT_PRIOR_DVL: lambda r: mount_prior_dvl_factor(r.keys[0], r.keys[1], r.z, r.cov),
}


def start_records(
    wTb0: FloatArray, P0: FloatArray, config: GraphConfig, bTs: FloatArray | None = None
) -> tuple[list[FactorRecord], gtsam.Values]:
    """The factors and initial values of a graph's start: a prior on the start position,
    the AHRS bias ``B(0)`` (and ``D(0)``, ``G(0)``, ``K(0)``, the sonar mounting ``C(0)`` around
    ``bTs``, the range scale ``R(0)`` around 1, when estimated) with their priors, and the
    start heading as an AHRS heading factor on ``X(0)`` (the start yaw came from the AHRS, so it
    carries the bias; its white noise is ``ahrs_white_sigma_deg``'s, P0's heading is not used)."""
    prior = FactorKind.PRIOR_VECTOR
    records = [FactorRecord.of(FactorKind.POSE_TRANSLATION_PRIOR, [X(0)], wTb0[:2], P0[:2, :2])]
    values = gtsam.Values()
    b0 = np.deg2rad(config.ahrs_bias_prior_deg)
    var_b = np.deg2rad(config.noise.ahrs_bias_sigma_deg) ** 2
    records.append(FactorRecord.of(prior, [B(0)], [b0], [[var_b]]))
    values.insert(B(0), np.array([b0]))
    if config.estimate_misalignment:
        var_d = np.deg2rad(config.misalignment_sigma_deg) ** 2
        records.append(FactorRecord.of(prior, [D(0)], [0.0], [[var_d]]))
        values.insert(D(0), np.zeros(1))
    if config.estimate_gyro_scale:
        records.append(FactorRecord.of(prior, [G(0)], [1.0], [[config.gyro_scale_sigma**2]]))
        values.insert(G(0), np.ones(1))
    if config.noise.dvl_scale_sigma > 0.0 or "dvl_scale" in config.learned_kinds:
        # a scale error learned to walk from none told starts known to LEARNED_SCALE_SIGMA
        sigma = max(config.noise.dvl_scale_sigma, LEARNED_SCALE_SIGMA)
        records.append(FactorRecord.of(prior, [K(0)], [0.0], [[sigma**2]]))
        values.insert(K(0), np.zeros(1))
    if config.estimate_sonar_mount:
        if bTs is None:
            raise ValueError("start_records: estimate_sonar_mount needs the mounting bTs")
        cov_c = np.diag(
            [
                config.sonar_mount_sigma_m**2,
                config.sonar_mount_sigma_m**2,
                np.deg2rad(config.sonar_mount_sigma_deg) ** 2,
            ]
        )
        if config.sonar_yaw_prior == "dead_reckoning" and config.estimate_misalignment:
            # the yaw known relative to the DVL's track: its prior on yaw - delta
            records.append(FactorRecord.of(FactorKind.MOUNT_PRIOR_DVL, [C(0), D(0)], bTs, cov_c))
        else:
            records.append(FactorRecord.of(prior, [C(0)], bTs, cov_c))
        values.insert(C(0), np.asarray(bTs, dtype=np.float64))
    if config.range_scale_sigma > 0.0:
        records.append(FactorRecord.of(prior, [R(0)], [1.0], [[config.range_scale_sigma**2]]))
        values.insert(R(0), np.ones(1))
    values.insert(X(0), gtsam.Pose2(*wTb0))
    var_white = np.deg2rad(config.noise.ahrs_white_sigma_deg) ** 2
    records.append(FactorRecord.of(FactorKind.HEADING_BIAS, [X(0), B(0)], [wTb0[2]], [[var_white]]))
    return records, values


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
    records: Sequence[FactorRecord],
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
      ``"d_t_d_scale"`` ``[dx/ds, dy/ds]`` (:func:`sonarslam.slam.backends.isam2.factors.odometry_residual`);
    * ``LineObservation`` on ``(x, l)``: ``[rho, theta]`` in the sonar frame, plus ``"bTs"``
      ``[x, y, yaw]`` and ``"robust"`` (``null`` or ``{"kernel": "huber", "k": 1.345}``);
      error :func:`sonarslam.slam.model.lines.line_residual`;
    * ``LineObservationCalibrated`` on ``(x, l[, c][, r])``: as ``LineObservation`` with the
      sonar mounting ``c`` and range scale ``r`` as variables, plus ``"kTb"`` (the body at the
      observation in the node's frame) and ``"bTs"`` (the mounting when ``c`` is absent); error
      :func:`sonarslam.slam.model.calibration.line_residual_calibrated`;
    * ``ScanRegistrationCalibrated`` on ``(x_i, x_j[, c][, r])``: ``[x, y, yaw]`` a scan
      registration, ``"bTs"`` the mounting the front end assumed, ``"robust"``, ``"constraint"``;
      error :func:`sonarslam.slam.model.calibration.scan_residual`;
    * ``LineEquality`` on ``(l_keep, l_drop)``: ``[flipped]`` (0 or 1), a diagonal covariance;
      two landmarks found to be one wall (:func:`sonarslam.slam.backends.isam2.factors.line_equality_residual`).

    ``meta`` holds what is not a factor: node times, the sonar mounting, the settings.
    """
    doc = {
        "format": GRAPH_FORMAT,
        "meta": meta or {},
        "factors": [r.to_json() for r in records],
        "values": values_to_json(values),
    }
    Path(path).write_text(json.dumps(doc) + "\n")


def load_graph(path: str | Path) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """Read a graph written by :func:`save_graph`.

    Returns
    -------
    graph : gtsam.NonlinearFactorGraph
        GTSAM's own factors for the standard types, ``CustomFactor`` from
        :mod:`sonarslam.slam.backends.isam2.factors` for the others.
    values : gtsam.Values
    """
    doc = json.loads(Path(path).read_text())
    if doc.get("format") != GRAPH_FORMAT:
        raise ValueError(f"{path}: not a {GRAPH_FORMAT} file")
    graph = gtsam.NonlinearFactorGraph()
    for i, item in enumerate(doc["factors"]):
        where = f"{path}: factor {i}"
        record = FactorRecord.from_json(item, where)
        try:
            graph.add(record.to_gtsam())
        except (TypeError, ValueError, RuntimeError) as e:
            raise ValueError(f"{where}: {record.kind.value} factor: {e}") from e
    return graph, values_from_json(doc["values"])


def values_from_json(items: dict[str, Any]) -> gtsam.Values:
    """The ``values`` object of a :func:`save_graph` file as ``gtsam.Values`` (poses as
    ``Pose2``, the other variables as vectors)."""
    values = gtsam.Values()
    for name, item in items.items():
        v = np.asarray(item["value"], dtype=np.float64)
        if item["type"] == "Pose2":
            values.insert(key_of(name), gtsam.Pose2(*v))
        else:
            values.insert(key_of(name), v.reshape(-1))
    return values
