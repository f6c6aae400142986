"""Factor-graph SLAM with line landmarks on GTSAM iSAM2: the second back end.

:class:`LineIsam2` implements the :class:`slam.run.closed_loop.Backend` protocol of
:class:`slam.backends.ekf.LineEkf`, so :func:`slam.run.closed_loop.run_closed_loop` drives it unchanged::

    make_backend = isam2_backend_factory(dataset.config.sonar_mounting, GraphConfig())
    result = run_closed_loop(dataset, make_backend, extractor_config, pose_source_of=pose_source_of)
    smoothed = result.backend.smoothed_trajectory(covariances=True)

The graph (factors in :mod:`slam.backends.isam2.factors`):

* ``X(k)``: body poses ``wTb`` (``Pose2``) at *nodes*: one at each vote that returns lines and
  one every ``node_period_s`` otherwise;
* odometry between consecutive nodes: the motion model of the EKF (:func:`slam.model.motion.propagate`:
  DVL velocity, gyro yaw rate) integrated between them with its covariance (the error of a
  held DVL sample counted once per sample, ``dvl_noise``), as a
  ``BetweenFactorPose2`` (or, with ``estimate_misalignment`` / ``estimate_gyro_scale``, the
  same motion with its translation rotated by the DVL misalignment ``D(0)`` and its heading
  change scaled by the gyro scale ``G(0)``);
* AHRS heading ``z = yaw + b`` on ``(X(k), B(0))``, ``B(0)`` the constant AHRS bias with a prior
  (as the EKF: a bias with white noise on top, so that the compass never looks better than it
  is; a white-noise model at 1 Hz would make the graph overconfident in heading). The AHRS
  headings taken since the previous node (one every ``ahrs_period_s``, white, as in the EKF)
  are carried to the node by the gyro and averaged into one factor, so the graph has one pose
  per few seconds instead of one per heading;
* a prior on the start position (``PoseTranslationPrior2D``), and the start heading as an AHRS
  heading factor on ``X(0)`` (the start yaw came from the AHRS, so it carries the bias, as in
  the EKF);
* line observations on ``(X(k), L(j))``, ``L(j)`` a world line ``(rho, theta)``.

Nothing in the graph observes the AHRS bias or the start position beyond their priors: a
rotation of the whole run about the start position, taken back by the bias, changes no other
factor (``tests/test_factor_graph.py``). So the bias's rotation of the run is there in every
estimate, the EKF's too (which can gain spurious information on it).

iSAM2 is updated in batches: the factors of every vote with lines go in one update (after the
association), and between votes the pending odometry and heading factors are added at most
every ``update_period_s``. Until then the current pose is the newest optimised node composed
with the odometry since it (:attr:`LineIsam2.pose`, :attr:`LineIsam2.pose_cov`).

Association (:mod:`slam.mapping.association`, the EKF's module) uses the iSAM2 joint marginal of the
newest optimised node and of the candidate landmarks only (those individually compatible under
a loose gate with cached per-landmark marginals), propagated to the current time by the
odometry; a landmark is a candidate only for observations from the side of its line it was
seen from (:func:`sonar_side`). Landmarks are managed as in the EKF: a new line is tentative and
becomes a landmark when seen again; all its observations then enter the graph.

The seam to the front end is :class:`SmoothedPoseSource` (:func:`pose_source_of`): the
smoothed poses of the nodes, interpolated in between with the odometry, extrapolated past the
newest optimised node with the odometry since it (:func:`smoothed_poses`). With
``ExtractorConfig.requery_poses`` the extractor re-reads the poses of its whole stored sector at
every vote, so every correction of the graph reaches the motion-distortion correction.

Saving: :meth:`LineIsam2.save` writes the graph and the values as JSON (format in
:func:`save_graph`), :func:`load_graph` reads them back as GTSAM objects.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gtsam
import numpy as np
import numpy.typing as npt
from gtsam.symbol_shorthand import B, D, G, L, X
from scipy.stats import chi2

from features.geometry import (
    FloatArray,
    along_line,
    compose,
    compose_jacobians,
    line_frame_to_world,
    transform_points,
    wrap_angle,
)
from features.line import LineFeature
from slam.backends.isam2.factors import (
    heading_factor,
    line_factor,
    line_prediction,
    line_predictions,
    local_to_world,
    noise_model,
    odometry_factor,
)
from slam.io.trajectory import Trajectory
from slam.mapping.association import (
    FLIP_RHO,
    AssociationConfig,
    AssociationProblem,
    associate,
    extent_allowed,
    line_innovation,
)
from slam.mapping.landmarks import landmark_record
from slam.model.motion import held_velocity_variance_step
from sonar.beam import Mounting

__all__ = [
    "GraphConfig",
    "GraphLandmark",
    "LineIsam2",
    "SmoothedPoseSource",
    "smoothed_poses",
    "sonar_side",
    "pose_source_of",
    "isam2_backend_factory",
    "save_graph",
    "load_graph",
    "factor_from_record",
]


@dataclass(frozen=True)
class GraphConfig:
    """Settings of the factor graph, iSAM2 and the landmark management.

    Attributes
    ----------
    association : AssociationConfig
        Method and gate (the EKF's).
    ahrs_white_sigma_deg : float
        White noise of one AHRS heading (deg).
    ahrs_bias_prior_deg : float
        Prior mean of the constant AHRS bias ``B(0)`` (deg): the AHRS measures ``yaw + b``.
    ahrs_bias_sigma_deg : float
        Prior 1-sigma of the constant AHRS bias ``B(0)`` (deg). Nothing else in the graph
        observes it: line landmarks, DVL and gyro are blind to a rotation of the whole map and
        trajectory about the start position, which is what the bias does.
    ahrs_period_s : float
        An AHRS heading is used at most this often (s); the AHRS errors are not white.
    dvl_noise : {"hold", "white"}
        How the velocity noise adds up. ``"hold"``: the body velocity is a DVL sample held
        until the next one (:func:`slam.model.motion.velocity_input`), so its error is one draw per
        sample and the position error over a hold of ``T`` seconds is ``T * sigma``; steps with
        the same velocity as the previous one share it. ``"white"``: independent per motion
        step, ``(dt * sigma)**2`` each (the EKF's model), which with a 1.5 Hz DVL and 20
        records a second makes the position variance ~20x too small.
    gyro_sigma_radps : float
        Heading process noise of the odometry, as a yaw-rate noise (rad/s), added as
        ``(dt * sigma)**2`` per motion step as in the EKF.
    node_period_s : float
        A pose node at least this often (s); votes with lines add theirs.
    min_node_gap_s : float
        An observation this close (s) after the newest node goes on that node, carried by the
        odometry since it (:meth:`LineIsam2._node_now`), instead of on a new node.
    update_period_s : float
        Pending odometry and heading factors go into iSAM2 at most this often (s) between
        votes with lines (which always update).
    estimate_misalignment : bool
        Estimate the DVL misalignment ``D(0)`` (the EKF's ``delta``).
    misalignment_sigma_deg : float
        Its prior 1-sigma (deg).
    estimate_gyro_scale : bool
        Estimate the scale ``G(0)`` of the gyro's yaw rate: the odometry's heading change is
        ``s`` times the gyro's integral. The AHRS headings make it observable. On the marina
        the MTi's rate turns 0.86 times as fast as its heading; with ``s = 1`` the odometry and
        heading factors disagree by degrees every node.
    gyro_scale_sigma : float
        Prior 1-sigma of ``s`` around 1.
    tentative_observations : int
        A new line becomes a landmark when seen this many times, each compatible with the
        first (chi2 gate of ``association.gate_probability`` in the world frame) ...
    tentative_max_age_s : float
        ... within this time (s).
    min_rho_m : float
        Lines closer than this to the sonar are not used.
    line_cov_scale : float
        The extractor's line covariances are multiplied by this (1: taken as they are).
    side_gate : bool
        A landmark (or tentative line) is a candidate only for observations from the side of
        its line it was first seen from (:func:`sonar_side`).
    extent_margin_m : float or None
        A landmark is paired only with observations whose world segment reaches its extent
        within this margin (m), :func:`slam.mapping.association.extent_allowed`; None: no extent gate.
        10 m: on the marina it keeps a landmark from spanning the gap to a collinear wall of the
        other basin (extents of 200-490 m without it) and takes the ATE down by ~1 m; on the
        simulated harbours precision and recall do not move.
    robust : {None, "huber", "cauchy"}
        Robust kernel on the line factors. Huber by default: on the simulated harbours it
        changes the trajectory by centimetres; on the marina, 14 % of the repeated lines of one
        wall lie beyond the 99 % gate of their covariance even with GPS poses (heavy tails).
    robust_k : float
        Its width (sigmas).
    relinearize_threshold : float
        iSAM2 relinearises a variable whose delta exceeds this (m, rad). GTSAM's default; on
        the simulated harbours 0.01 with a check every update gives the same trajectory to the
        millimetre, and on the marina (where line loops pull the trajectory by metres) it
        relinearises most of the graph at every update and costs 10x more.
    relinearize_skip : int
        iSAM2 checks for relinearisation every this many updates (GTSAM's default).
    extra_iterations : int
        Extra ``ISAM2.update()`` calls (no new factors) after a vote with associated lines,
        so that loop closures converge.
    candidate_gate_probability : float
        Loose individual gate, with cached marginals and no cross-covariances, that selects the
        landmarks whose joint marginal is computed for the association.
    max_candidates : int
        At most this many candidate landmarks per vote (the nearest by that distance).
    pose_window_s : float
        After an update, the smoothed poses of the nodes this recent (s) are refreshed for the
        pose source when it is next asked (the front end's stored sector spans seconds); all of
        them for :meth:`LineIsam2.smoothed_trajectory`.
    """

    association: AssociationConfig = field(default_factory=AssociationConfig)
    ahrs_white_sigma_deg: float = 1.0
    ahrs_bias_prior_deg: float = 0.0
    ahrs_bias_sigma_deg: float = 2.0
    ahrs_period_s: float = 1.0
    dvl_noise: str = "hold"
    gyro_sigma_radps: float = 0.005
    node_period_s: float = 5.0
    min_node_gap_s: float = 0.1
    update_period_s: float = 5.0
    estimate_misalignment: bool = False
    misalignment_sigma_deg: float = 5.0
    estimate_gyro_scale: bool = False
    gyro_scale_sigma: float = 0.2
    tentative_observations: int = 2
    tentative_max_age_s: float = 60.0
    min_rho_m: float = 1.0
    line_cov_scale: float = 1.0
    side_gate: bool = True
    extent_margin_m: float | None = 10.0
    robust: str | None = "huber"
    robust_k: float = 1.345
    relinearize_threshold: float = 0.1
    relinearize_skip: int = 10
    extra_iterations: int = 1
    candidate_gate_probability: float = 0.9999
    max_candidates: int = 8
    pose_window_s: float = 30.0

    def __post_init__(self) -> None:
        if self.dvl_noise not in ("hold", "white"):
            raise ValueError(f"dvl_noise must be 'hold' or 'white', got {self.dvl_noise!r}")
        if self.robust not in (None, "huber", "cauchy"):
            raise ValueError(f"robust must be None, 'huber' or 'cauchy', got {self.robust!r}")
        if min(self.ahrs_white_sigma_deg, self.ahrs_bias_sigma_deg, self.gyro_sigma_radps) <= 0:
            raise ValueError("AHRS and gyro sigmas must be > 0")
        if self.ahrs_period_s <= 0 or self.node_period_s <= 0 or self.update_period_s < 0:
            raise ValueError("ahrs_period_s, node_period_s must be > 0, update_period_s >= 0")
        if self.tentative_observations < 1 or self.max_candidates < 1:
            raise ValueError("tentative_observations and max_candidates must be >= 1")


@dataclass
class GraphLandmark:
    """A line landmark ``L(id)``: observation count, extent along the line (m), and the side
    of the line the sonar saw it from (``+1``: ``rho_w > n . p_sonar``, see :func:`sonar_side`)."""

    id: int
    n_obs: int
    s_min_m: float
    s_max_m: float
    side: float = 1.0
    cov_cache: FloatArray = field(default_factory=lambda: np.eye(2) * 1e6)

    @property
    def key(self) -> int:
        return int(L(self.id))


@dataclass(eq=False)
class _Tentative:
    t: float
    line_w: FloatArray
    cov_w: FloatArray
    ends_w: FloatArray  # (2n, 2) world end points of its observations (m)
    observations: list[tuple[tuple[int, FloatArray], LineFeature]]  # ((node, bTs), line)
    side: float = 1.0


class _Rows:
    """Rows of floats appended one at a time into a doubling numpy buffer."""

    def __init__(self, width: int, capacity: int = 1024) -> None:
        self._buf = np.empty((capacity, width))
        self.n = 0

    def append(self, row: Sequence[float] | FloatArray) -> None:
        if self.n == self._buf.shape[0]:
            self._buf = np.concatenate([self._buf, np.empty_like(self._buf)])
        self._buf[self.n] = row
        self.n += 1

    @property
    def rows(self) -> FloatArray:
        return self._buf[: self.n]


class _HeadingMean:
    """AHRS headings since the last node, carried by the gyro to the next node and averaged.

    A heading ``z_i`` taken when the odometry chain's yaw was ``o_i`` is, at the node (chain yaw
    ``o_n``), ``c_i = z_i - o_i + o_n``; the factor takes their mean. Its variance is the white
    part ``sigma^2 / n`` (added by the caller) plus the gyro's random walk from the samples to
    the node, on average ``f_n - mean(f_i)`` with ``f`` the odometry's yaw variance since the
    previous node. (That gyro part is also in the odometry factor; the correlation is ignored,
    it is small next to the white part.)
    """

    __slots__ = ("n", "_sum", "_ref", "_sum_f")

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.n = 0
        self._sum = self._sum_f = self._ref = 0.0

    def add(self, yaw_meas_rad: float, chain_yaw_rad: float, f_rad2: float) -> None:
        c = yaw_meas_rad - chain_yaw_rad
        if self.n == 0:
            self._ref = c
        self._sum += self._ref + (c - self._ref + math.pi) % (2.0 * math.pi) - math.pi
        self._sum_f += f_rad2
        self.n += 1

    def at_node(self, chain_yaw_rad: float, f_rad2: float) -> tuple[float, float] | None:
        """Mean heading at the node and the gyro part of its variance, or None if empty."""
        if self.n == 0:
            return None
        z = float(wrap_angle(self._sum / self.n + chain_yaw_rad))
        return z, max(f_rad2 - self._sum_f / self.n, 0.0)


class _Motion:
    """Relative motion since a start, ``(x, y, yaw)`` in the start frame, and its covariance.

    The model of :func:`slam.model.motion.propagate` from the identity, in plain floats (it runs for
    every record): ``F = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]]``, ``Q = diag(qv, qv, qr)``.
    """

    __slots__ = ("x", "y", "yaw", "a", "b", "c", "d", "e", "f", "yaw_raw", "jx", "jy")

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.x = self.y = self.yaw = 0.0
        self.a = self.b = self.c = self.d = self.e = self.f = 0.0  # Pxx Pxy Pyy Pxyaw Pyyaw Pyaw
        self.yaw_raw = self.jx = self.jy = 0.0  # the gyro's own integral, d(x, y)/d(scale)

    def step(
        self, sx: float, sy: float, syaw: float, qv: float, qr: float, syaw_raw: float = 0.0
    ) -> None:
        """One step: body displacement ``(sx, sy)``, yaw change ``syaw`` (``syaw_raw`` before
        the gyro scale), velocity and yaw variances ``qv``, ``qr``."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        dx, dy = c * sx - s * sy, s * sx + c * sy
        # the step's direction turns with the scale through the yaw so far: d/ds = S d yaw_raw
        self.jx -= dy * self.yaw_raw
        self.jy += dx * self.yaw_raw
        self.yaw_raw += syaw_raw
        a, b, cc, d, e, f = self.a, self.b, self.c, self.d, self.e, self.f
        self.a = a - 2.0 * dy * d + dy * dy * f + qv
        self.b = b - dy * e + dx * d - dx * dy * f
        self.c = cc + 2.0 * dx * e + dx * dx * f + qv
        self.d = d - dy * f
        self.e = e + dx * f
        self.f = f + qr
        self.x += dx
        self.y += dy
        self.yaw += syaw

    def copy_from(self, other: _Motion, rotate_rad: float = 0.0) -> None:
        """Take another motion, its translation rotated by ``rotate_rad`` (the misalignment)."""
        c, s = math.cos(rotate_rad), math.sin(rotate_rad)
        self.x, self.y = c * other.x - s * other.y, s * other.x + c * other.y
        self.yaw = other.yaw
        self.a, self.b, self.c = other.a, other.b, other.c
        self.d, self.e, self.f = other.d, other.e, other.f
        self.yaw_raw, self.jx, self.jy = other.yaw_raw, other.jx, other.jy

    @property
    def pose(self) -> FloatArray:
        return np.array([self.x, self.y, self.yaw])

    @property
    def cov(self) -> FloatArray:
        """Covariance of ``(x, y, yaw)`` (m, m, rad)."""
        return np.array(
            [[self.a, self.b, self.d], [self.b, self.c, self.e], [self.d, self.e, self.f]]
        )

    def local_cov(self) -> FloatArray:
        """Covariance in the local tangent of the relative pose (``BetweenFactorPose2``'s)."""
        A = local_to_world(-self.yaw)
        return A @ self.cov @ A.T


def _pose_of(p: gtsam.Pose2) -> FloatArray:
    return np.array([p.x(), p.y(), p.theta()])


def sonar_side(wTb: FloatArray, lines_w: FloatArray, bTs: FloatArray) -> FloatArray:
    """Which side of each world line the sonar is on: ``sign(rho_w - n_w . p_sonar)``.

    A wall is seen from its water side only, so an observation from the other side of a
    landmark's line is another wall (the two faces of a jetty, parallel a few metres apart,
    are one line each with the same ``theta``: only this tells them apart when the pose is
    uncertain by metres).

    Parameters
    ----------
    wTb : ndarray, shape (3,)
    lines_w : ndarray, shape (K, 2)
        World lines as stored (not necessarily normalised).
    bTs : ndarray, shape (3,)

    Returns
    -------
    ndarray, shape (K,)
        +1 or -1.
    """
    x, y, _ = compose(wTb, bTs)
    lw = np.asarray(lines_w, dtype=np.float64).reshape(-1, 2)
    raw = lw[:, 0] - x * np.cos(lw[:, 1]) - y * np.sin(lw[:, 1])
    return np.where(raw < 0.0, -1.0, 1.0)


def _normalised_landmark(line: FloatArray, cov: FloatArray) -> tuple[FloatArray, FloatArray]:
    """A landmark's ``(rho, theta)`` normalised (``rho >= 0``), its covariance alike."""
    if line[0] < 0.0:
        return np.array([-line[0], float(wrap_angle(line[1] + np.pi))]), FLIP_RHO @ cov @ FLIP_RHO
    return np.array([line[0], float(wrap_angle(line[1]))]), cov


# -- factor records: one description per factor, used to build it and to save it ------------


def _key_name(key: int) -> str:
    return str(gtsam.Symbol(key).string())


def _key_of(name: str) -> int:
    return int(gtsam.Symbol(name[0], int(name[1:])).key())


def factor_from_record(record: dict[str, Any]) -> gtsam.NonlinearFactor:
    """Build the GTSAM factor a record describes (see :func:`save_graph` for the types)."""
    kind = record["type"]
    keys = [_key_of(k) for k in record["keys"]]
    z = np.asarray(record["measurement"], dtype=np.float64)
    cov = np.asarray(record["covariance"], dtype=np.float64)
    if kind == "PoseTranslationPrior2D":
        return gtsam.PoseTranslationPrior2D(keys[0], z, noise_model(cov))
    if kind == "PriorFactorPose2":
        return gtsam.PriorFactorPose2(keys[0], gtsam.Pose2(*z), noise_model(cov))
    if kind == "BetweenFactorPose2":
        return gtsam.BetweenFactorPose2(keys[0], keys[1], gtsam.Pose2(*z), noise_model(cov))
    if kind == "PriorFactorVector":
        return gtsam.PriorFactorVector(keys[0], z, noise_model(cov))
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
        )
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


def _record(kind: str, keys: Sequence[int], z: npt.ArrayLike, cov: npt.ArrayLike, **extra: Any):  # noqa: ANN202
    return {
        "type": kind,
        "keys": [_key_name(k) for k in keys],
        "measurement": np.atleast_1d(np.asarray(z, dtype=np.float64)).tolist(),
        "covariance": np.atleast_2d(np.asarray(cov, dtype=np.float64)).tolist(),
        **extra,
    }


def _values_to_json(values: gtsam.Values) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for key in values.keys():
        name = _key_name(key)
        if name[0] == "x":
            out[name] = {"type": "Pose2", "value": _pose_of(values.atPose2(key)).tolist()}
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
    * ``PriorFactorVector``: GTSAM's;
    * ``HeadingBias`` on ``(x, b)``: ``[yaw_meas]``, error ``wrap(yaw + b - yaw_meas)``;
    * ``DvlGyroOdometry`` on ``(x_i, x_j[, d][, g])``: ``[x, y, yaw]`` integrated with
      ``delta = 0`` and scale ``"scale0"``, plus ``"yaw_raw"`` (the gyro's integral) and
      ``"d_t_d_scale"`` ``[dx/ds, dy/ds]`` (:func:`slam.backends.isam2.factors.odometry_residual`);
    * ``LineObservation`` on ``(x, l)``: ``[rho, theta]`` in the sonar frame, plus ``"bTs"``
      ``[x, y, yaw]`` and ``"robust"`` (``null`` or ``{"kernel": "huber", "k": 1.345}``);
      error :func:`slam.backends.isam2.factors.line_residual`.

    ``meta`` holds what is not a factor: node times, the sonar mounting, the settings.
    """
    doc = {
        "format": "sonarslam-graph/1",
        "meta": meta or {},
        "factors": list(records),
        "values": _values_to_json(values),
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
    if doc.get("format") != "sonarslam-graph/1":
        raise ValueError(f"{path}: not a sonarslam-graph/1 file")
    graph = gtsam.NonlinearFactorGraph()
    for record in doc["factors"]:
        graph.add(factor_from_record(record))
    values = gtsam.Values()
    for name, item in doc["values"].items():
        v = np.asarray(item["value"], dtype=np.float64)
        if item["type"] == "Pose2":
            values.insert(_key_of(name), gtsam.Pose2(*v))
        else:
            values.insert(_key_of(name), v.reshape(-1))
    return graph, values


# -- the back end ------------------------------------------------------------------------------


class LineIsam2:
    """Line-landmark SLAM on iSAM2; see the module docstring.

    Parameters
    ----------
    t0_s : float
        Start time (Unix s).
    wTb0 : ndarray, shape (3,)
        Start pose (the start yaw is the AHRS's).
    P0 : ndarray, shape (3, 3)
        Its covariance; ``P0[2, 2]`` is taken as the white noise of that AHRS heading.
    sonar_mounting : Mounting
        ``bTs`` of the sonar head.
    config : GraphConfig
    """

    def __init__(
        self,
        t0_s: float,
        wTb0: FloatArray,
        P0: FloatArray,
        sonar_mounting: Mounting,
        config: GraphConfig,
    ) -> None:
        self.config = config
        self.bTs = sonar_mounting.as_pose()
        self.t_s = float(t0_s)
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(config.relinearize_threshold)
        params.relinearizeSkip = config.relinearize_skip
        self.isam = gtsam.ISAM2(params)
        self.graph = gtsam.NonlinearFactorGraph()  # every factor, for batch LM and saving
        self.records: list[dict[str, Any]] = []
        self.landmarks: list[GraphLandmark] = []
        self._tentative: list[_Tentative] = []
        self._pending = gtsam.NonlinearFactorGraph()
        self._pending_values = gtsam.Values()
        self._pending_nodes: list[tuple[int, float, FloatArray]] = []  # (k, t, chain at t)
        self.stats = {
            "observations": 0,
            "associated": 0,
            "new_landmarks": 0,
            "tentative_dropped": 0,
            "rejected_near": 0,
            "ahrs_updates": 0,
            "pose_nodes": 0,
            "isam_updates": 0,
            "factors": 0,
        }
        # tentative observations of a line that became a landmark, with its id: their factors
        # entered the graph when it was promoted
        self.seed_log: list[tuple[LineFeature, int]] = []
        self.association_log: list[tuple[float, int, int | None]] = []
        self.timing_s = {"isam_update": 0.0, "marginals": 0.0, "association": 0.0}
        self.update_log: list[tuple[float, float, int]] = []  # (t, wall s, new factors)
        # odometry: the chain O(t) for the pose source (yaw unwrapped), the motion since the
        # newest node (its odometry factor) and since the newest optimised node (the anchor)
        self._chain = _Rows(4)
        self._chain_pose = [0.0, 0.0, 0.0]
        self._chain.append([self.t_s, 0.0, 0.0, 0.0])
        self._since_node = _Motion()
        self._since_anchor = _Motion()
        self._delta_rad = 0.0
        self._scale = 1.0  # the gyro scale used to integrate (the newest estimate)
        self._since_node_scale = 1.0
        self._hold_v: tuple[float, float] | None = None
        self._hold_s = 0.0
        # optimised nodes: time, chain value at that time, smoothed pose
        self._node_t = _Rows(1)
        self._node_odo = _Rows(3)
        self._node_pose = _Rows(3)
        self._anchor_t: list[float] = []
        self._anchor_cov: list[FloatArray] = []
        self._n_nodes = 0
        self._last_node_t = -np.inf
        self._last_heading_t = -np.inf
        self._headings = _HeadingMean()
        self._last_update_t = -np.inf
        self._lm_est: dict[int, FloatArray] = {}
        self._new_landmarks: list[int] = []
        self._stale = False
        self._gate_candidates = float(chi2.ppf(config.candidate_gate_probability, 2))
        self._gate_tentative = float(chi2.ppf(config.association.gate_probability, 2))
        self._batch: gtsam.Values | None = None

        # X(0): prior on the position, start heading as an AHRS factor (it carries the bias)
        wTb0 = np.asarray(wTb0, dtype=np.float64)
        P0 = np.asarray(P0, dtype=np.float64)
        self._add_factor(_record("PoseTranslationPrior2D", [X(0)], wTb0[:2], P0[:2, :2]))
        var_b = np.deg2rad(config.ahrs_bias_sigma_deg) ** 2
        b0 = np.deg2rad(config.ahrs_bias_prior_deg)
        self._add_factor(_record("PriorFactorVector", [B(0)], [b0], [[var_b]]))
        self._pending_values.insert(B(0), np.array([b0]))
        if config.estimate_misalignment:
            var_d = np.deg2rad(config.misalignment_sigma_deg) ** 2
            self._add_factor(_record("PriorFactorVector", [D(0)], [0.0], [[var_d]]))
            self._pending_values.insert(D(0), np.zeros(1))
        if config.estimate_gyro_scale:
            var_s = config.gyro_scale_sigma**2
            self._add_factor(_record("PriorFactorVector", [G(0)], [1.0], [[var_s]]))
            self._pending_values.insert(G(0), np.ones(1))
        self._pending_values.insert(X(0), gtsam.Pose2(*wTb0))
        self._add_factor(_record("HeadingBias", [X(0), B(0)], [wTb0[2]], [[max(P0[2, 2], 1e-12)]]))
        self._register_node(0, self.t_s)
        self._update()

    # -- state access ----------------------------------------------------------------------

    @property
    def pose(self) -> FloatArray:
        """Current body pose: the newest optimised node composed with the odometry since it."""
        ax, ay, ayaw = self._anchor_xyyaw
        m = self._since_anchor
        c, s = math.cos(ayaw), math.sin(ayaw)
        yaw = (ayaw + m.yaw + math.pi) % (2.0 * math.pi) - math.pi
        return np.array([ax + c * m.x - s * m.y, ay + s * m.x + c * m.y, yaw])

    @property
    def pose_cov(self) -> FloatArray:
        """Its covariance in ``(x_m, y_m, yaw_rad)``: the node's iSAM2 marginal, propagated.

        ``J_a S J_a^T + J_b P J_b^T`` of :func:`features.geometry.compose_jacobians`, in floats
        (the driver asks for it at every record).
        """
        m = self._since_anchor
        c, s = math.cos(self._anchor_xyyaw[2]), math.sin(self._anchor_xyyaw[2])
        # J_a = I + u e3^T with u = (-s x - c y, c x - s y, 0)
        u0, u1 = -s * m.x - c * m.y, c * m.x - s * m.y
        (s00, s01, s02), (_, s11, s12), (_, _, s22) = self._anchor_cov_rows
        a00 = s00 + 2.0 * u0 * s02 + u0 * u0 * s22
        a01 = s01 + u0 * s12 + u1 * s02 + u0 * u1 * s22
        a11 = s11 + 2.0 * u1 * s12 + u1 * u1 * s22
        a02 = s02 + u0 * s22
        a12 = s12 + u1 * s22
        # J_b = blockdiag(R, 1)
        pa, pb, pc, pd, pe = m.a, m.b, m.c, m.d, m.e
        b00 = c * c * pa - 2.0 * c * s * pb + s * s * pc
        b01 = c * s * (pa - pc) + (c * c - s * s) * pb
        b11 = s * s * pa + 2.0 * c * s * pb + c * c * pc
        b02 = c * pd - s * pe
        b12 = s * pd + c * pe
        x00, x01, x11, x02, x12 = a00 + b00, a01 + b01, a11 + b11, a02 + b02, a12 + b12
        return np.array([[x00, x01, x02], [x01, x11, x12], [x02, x12, s22 + m.f]])

    @property
    def n_nodes(self) -> int:
        return self._n_nodes

    @property
    def ahrs_bias_rad(self) -> float:
        return float(self.isam.calculateEstimateVector(B(0))[0])

    @property
    def gyro_scale(self) -> float:
        if not self.config.estimate_gyro_scale:
            return 1.0
        return float(self.isam.calculateEstimateVector(G(0))[0])

    @property
    def misalignment_rad(self) -> float:
        if not self.config.estimate_misalignment:
            return 0.0
        return float(self.isam.calculateEstimateVector(D(0))[0])

    def landmark_line(self, lm: GraphLandmark) -> FloatArray:
        """Current estimate of a landmark's world line (not normalised), shape (2,)."""
        self._refresh()
        return self._lm_est[lm.id].copy()

    def pose_source(self) -> SmoothedPoseSource:
        """The smoothed trajectory as the front end's PoseSource (the plugin seam)."""
        return SmoothedPoseSource(self)

    # -- prediction (every record) ---------------------------------------------------------

    def predict(
        self, t_s: float, v_b_mps: FloatArray, sigma_v_mps: float, yaw_rate_radps: float
    ) -> FloatArray:
        """Integrate the motion model to ``t_s`` with the inputs held since the last step.

        Returns the relative motion ``bTb'`` of this step (the odometry the driver chains).
        """
        dt = t_s - self.t_s
        if dt <= 0.0:
            return np.zeros(3)
        vx, vy = float(v_b_mps[0]), float(v_b_mps[1])
        if self.config.dvl_noise == "hold" and (vx, vy) == self._hold_v:
            self._hold_s += dt  # the same DVL sample, the same error: it adds up linearly
        else:
            self._hold_v, self._hold_s = (vx, vy), dt
        if self.config.dvl_noise == "hold":
            qv = float(held_velocity_variance_step(self._hold_s, dt, sigma_v_mps))
        else:
            qv = (dt * sigma_v_mps) ** 2
        qr = (dt * self.config.gyro_sigma_radps) ** 2
        syaw_raw = dt * yaw_rate_radps
        syaw = self._scale * syaw_raw
        # the odometry factor's measurement: delta = 0, the gyro scale of the node's start
        self._since_node.step(dt * vx, dt * vy, syaw, qv, qr, syaw_raw)
        if self._delta_rad != 0.0:
            cd, sd = math.cos(self._delta_rad), math.sin(self._delta_rad)
            vx, vy = cd * vx - sd * vy, sd * vx + cd * vy
        sx, sy = dt * vx, dt * vy
        self._since_anchor.step(sx, sy, syaw, qv, qr)
        o = self._chain_pose
        c, s = math.cos(o[2]), math.sin(o[2])
        o[0] += c * sx - s * sy
        o[1] += s * sx + c * sy
        o[2] += syaw
        self._chain.append([t_s, o[0], o[1], o[2]])
        self.t_s = float(t_s)
        if t_s - self._last_node_t >= self.config.node_period_s:
            self._add_node()
            self._maybe_update()
        return np.array([sx, sy, syaw])

    # -- nodes and updates -----------------------------------------------------------------

    def _add_factor(self, record: dict[str, Any]) -> None:
        self._pending.add(factor_from_record(record))
        self.records.append(record)

    def _register_node(self, k: int, t_s: float) -> None:
        self._pending_nodes.append((k, t_s, np.array(self._chain_pose)))
        self._n_nodes = k + 1
        self._last_node_t = t_s
        self._since_node.reset()
        self._since_node_scale = self._scale
        self.stats["pose_nodes"] += 1

    def _add_node(self) -> int:
        """A node at the current time: its odometry factor and its AHRS heading factor."""
        k = self._n_nodes
        rel = self._since_node
        cfg = self.config
        if cfg.estimate_misalignment or cfg.estimate_gyro_scale:
            keys = [X(k - 1), X(k)]
            keys += [D(0)] if cfg.estimate_misalignment else []
            keys += [G(0)] if cfg.estimate_gyro_scale else []
            self._add_factor(
                _record(
                    "DvlGyroOdometry",
                    keys,
                    rel.pose,
                    rel.local_cov(),
                    yaw_raw=rel.yaw_raw,
                    d_t_d_scale=[rel.jx, rel.jy],
                    scale0=self._since_node_scale,
                )
            )
        else:
            self._add_factor(
                _record("BetweenFactorPose2", [X(k - 1), X(k)], rel.pose, rel.local_cov())
            )
        heading = self._headings.at_node(self._chain_pose[2], rel.f)
        if heading is not None:
            z, var = heading
            var += np.deg2rad(self.config.ahrs_white_sigma_deg) ** 2 / self._headings.n
            self._add_factor(_record("HeadingBias", [X(k), B(0)], [z], [[var]]))
            self._headings.reset()
        self._pending_values.insert(X(k), gtsam.Pose2(*self.pose))
        self._register_node(k, self.t_s)
        return k

    def _node_now(self) -> tuple[int, FloatArray]:
        """The node for an observation now, and the sonar mounting to use with it.

        A new node unless the newest one is less than ``min_node_gap_s`` old (odometry factors
        over a few milliseconds would be nearly singular); then that node, with the odometry
        since it folded into the mounting: ``bTs' = (odometry since the node) * bTs``.
        """
        if self.t_s - self._last_node_t < self.config.min_node_gap_s:
            return self._n_nodes - 1, compose(self._since_node.pose, self.bTs)
        return self._add_node(), self.bTs

    def _maybe_update(self) -> None:
        if self.t_s - self._last_update_t >= self.config.update_period_s:
            self._update()

    def _update(self, extra_iterations: int = 0) -> None:
        """Pending factors into iSAM2; refresh the anchor, the recent nodes and the landmarks.

        The anchor becomes the newest node; the odometry since it is the one since that node.
        """
        t0 = time.perf_counter()
        self.isam.update(self._pending, self._pending_values)
        for _ in range(extra_iterations):
            self.isam.update()
        wall = time.perf_counter() - t0
        self.timing_s["isam_update"] += wall
        self.update_log.append((self.t_s, wall, int(self._pending.size())))
        self.stats["isam_updates"] += 1 + extra_iterations
        self.stats["factors"] += self._pending.size()
        self.graph.push_back(self._pending)
        self._pending = gtsam.NonlinearFactorGraph()
        self._pending_values = gtsam.Values()
        self._batch = None
        for _k, t, odo in self._pending_nodes:
            self._node_t.append([t])
            self._node_odo.append(odo)
            self._node_pose.append([0.0, 0.0, 0.0])
        self._pending_nodes = []
        self._last_update_t = self.t_s
        # anchor: the newest node, now
        k = self._n_nodes - 1
        t1 = time.perf_counter()
        self._anchor_pose = _pose_of(self.isam.calculateEstimatePose2(X(k)))
        self._anchor_xyyaw = tuple(float(v) for v in self._anchor_pose)
        M = local_to_world(float(self._anchor_pose[2]))
        self._anchor_cov_w = M @ self.isam.marginalCovariance(X(k)) @ M.T
        self._anchor_cov_rows = tuple(tuple(float(v) for v in row) for row in self._anchor_cov_w)
        self.timing_s["marginals"] += time.perf_counter() - t1
        self._anchor_t.append(self._last_node_t)
        self._anchor_cov.append(self._anchor_cov_w)
        self._since_anchor.copy_from(self._since_node, self._delta_rad)
        if self.config.estimate_misalignment:
            self._delta_rad = float(self.isam.calculateEstimateVector(D(0))[0])
        if self.config.estimate_gyro_scale:
            self._scale = float(self.isam.calculateEstimateVector(G(0))[0])
        self._stale = True  # recent nodes and landmarks: refreshed when next asked for
        for lm_id in self._new_landmarks:  # marginals for the candidate gate
            self.landmarks[lm_id].cov_cache = self.isam.marginalCovariance(L(lm_id))
        self._new_landmarks = []

    def _refresh(self) -> None:
        """After an update, the smoothed poses of the recent nodes and the landmark lines."""
        if not self._stale:
            return
        self._refresh_nodes(self.t_s - self.config.pose_window_s)
        for lm in self.landmarks:
            self._lm_est[lm.id] = np.asarray(
                self._batch.atVector(lm.key)
                if self._batch is not None
                else self.isam.calculateEstimateVector(lm.key)
            )
        self._stale = False

    def _refresh_nodes(self, t_from_s: float) -> None:
        """Smoothed poses of the optimised nodes at or after ``t_from_s``."""
        times = self._node_t.rows[:, 0]
        first = int(np.searchsorted(times, t_from_s, side="left"))
        poses = self._node_pose.rows
        values = self._batch
        for k in range(first, times.size):
            p = (
                values.atPose2(X(k))
                if values is not None
                else self.isam.calculateEstimatePose2(X(k))
            )
            poses[k] = (p.x(), p.y(), p.theta())

    def update_heading(self, t_s: float, yaw_body_rad: float) -> bool:
        """Take an AHRS heading ``z = yaw + b`` (at most every ``ahrs_period_s``).

        It goes into the heading factor of the next node (:class:`_HeadingMean`).
        """
        if t_s - self._last_heading_t < self.config.ahrs_period_s:
            return False
        self._last_heading_t = t_s
        self._headings.add(float(yaw_body_rad), self._chain_pose[2], self._since_node.f)
        self.stats["ahrs_updates"] += 1
        return True

    # -- lines -----------------------------------------------------------------------------

    def _candidates(
        self, z: FloatArray, R: FloatArray, pose_w: FloatArray, P_pose_w: FloatArray
    ) -> list[GraphLandmark]:
        """Landmarks individually compatible with some observation under the loose gate.

        The gate uses the current pose covariance and each landmark's cached marginal, without
        their cross-covariance (conservative: it is positive between a pose and the lines it
        has seen), vectorised over all landmarks.
        """
        if not self.landmarks:
            return []
        lines = np.array([self._lm_est[lm.id] for lm in self.landmarks])
        C = np.array([lm.cov_cache for lm in self.landmarks])
        z_hat, H_pose, H_line = line_predictions(pose_w, lines, self.bTs)
        Hp = H_pose @ local_to_world(-float(pose_w[2]))
        S0 = np.einsum("kab,bc,kdc->kad", Hp, P_pose_w, Hp) + np.einsum(
            "kab,kbc,kdc->kad", H_line, C, H_line
        )
        # innovations of every (observation, landmark), in the representation of z nearest z_hat
        d_theta = wrap_angle(z[:, None, 1] - z_hat[None, :, 1])
        flip = np.abs(d_theta) > 0.5 * np.pi
        nu_rho = np.where(flip, -z[:, None, 0], z[:, None, 0]) - z_hat[None, :, 0]
        nu_theta = np.where(flip, wrap_angle(d_theta + np.pi), d_theta)
        S = S0[None] + R[:, None]
        s01 = np.where(flip, -S[..., 0, 1], S[..., 0, 1])  # diag(-1, 1) R diag(-1, 1)
        s01 = s01 + np.where(flip, S0[None, :, 0, 1] * 2.0, 0.0)  # S0 is not flipped
        s00, s11 = S[..., 0, 0], S[..., 1, 1]
        det = s00 * s11 - s01 * s01
        d2 = (s11 * nu_rho**2 - 2.0 * s01 * nu_rho * nu_theta + s00 * nu_theta**2) / det
        best = d2.min(axis=0)
        if self.config.side_gate:
            sides = np.array([lm.side for lm in self.landmarks])
            best = np.where(sonar_side(pose_w, lines, self.bTs) == sides, best, np.inf)
        gate = self._gate_candidates
        order = [int(j) for j in np.argsort(best) if best[j] <= gate]
        return [self.landmarks[j] for j in order[: self.config.max_candidates]]

    def _joint_covariance(self, cands: list[GraphLandmark]) -> FloatArray:
        """Joint covariance of ``[current pose (x, y, yaw), candidate lines]``.

        iSAM2's joint marginal of the anchor (newest optimised node) and the candidates, the
        anchor mapped to world coordinates and propagated by the odometry since it.
        """
        t0 = time.perf_counter()
        k_anchor = self._n_nodes - 1 - len(self._pending_nodes)
        keys = [X(k_anchor)] + [lm.key for lm in cands]
        J = self.isam.jointMarginalCovariance(keys).fullMatrix()
        self.timing_s["marginals"] += time.perf_counter() - t0
        n = J.shape[0]
        T = np.eye(n)
        J_a, J_b = compose_jacobians(self._anchor_pose, self._since_anchor.pose)
        T[:3, :3] = J_a @ local_to_world(float(self._anchor_pose[2]))
        P = T @ J @ T.T
        P[:3, :3] += J_b @ self._since_anchor.cov @ J_b.T
        for c, lm in enumerate(cands):
            lm.cov_cache = J[3 + 2 * c : 5 + 2 * c, 3 + 2 * c : 5 + 2 * c].copy()
        return P

    def update_lines(self, features: list[LineFeature]) -> list[int | None]:
        """Associate the lines of one vote (JCBB/NN on iSAM2 marginals), add them, update.

        Returns the landmark id of each feature (None: not associated).
        """
        use = [f for f in features if f.rho_m >= self.config.min_rho_m]
        self.stats["rejected_near"] += len(features) - len(use)
        if not use:
            return [None] * len(features)
        self.stats["observations"] += len(use)
        ta = time.perf_counter()
        self._refresh()
        z = np.array([f.z for f in use])
        R = np.array([f.cov for f in use]) * self.config.line_cov_scale
        pose_w, P_pose_w = self.pose, self.pose_cov
        k, bTs = self._node_now()
        cands = self._candidates(z, R, pose_w, P_pose_w)
        pairing: list[int | None] = [None] * len(use)
        if cands:
            P = self._joint_covariance(cands)
            d = P.shape[0]
            z_hat = np.zeros((len(cands), 2))
            H = np.zeros((len(cands), 2, d))
            Minv = local_to_world(-float(pose_w[2]))
            for c, lm in enumerate(cands):
                z_hat[c], H_pose, H_line = line_prediction(pose_w, self._lm_est[lm.id], self.bTs)
                H[c, :, :3] = H_pose @ Minv
                H[c, :, 3 + 2 * c : 5 + 2 * c] = H_line
            allowed = None
            if self.config.extent_margin_m is not None:
                wTs = compose(pose_w, self.bTs)
                allowed = extent_allowed(
                    np.array([self._lm_est[lm.id] for lm in cands]),
                    np.array([[lm.s_min_m, lm.s_max_m] for lm in cands]),
                    np.array([transform_points(wTs, f.endpoints_r) for f in use]),
                    self.config.extent_margin_m,
                )
            pairing = associate(
                AssociationProblem(z, R, z_hat, H, P, allowed), self.config.association
            )
        ids: dict[int, int | None] = {}
        associated: list[tuple[GraphLandmark, LineFeature]] = []
        for i, j in enumerate(pairing):
            if j is None:
                continue
            lm = cands[j]
            self._add_line_factor(k, bTs, lm, use[i])
            associated.append((lm, use[i]))
            self.stats["associated"] += 1
            ids[i] = lm.id
        for i, j in enumerate(pairing):
            if j is None:
                ids[i] = self._new_line((k, bTs), use[i], pose_w, P_pose_w)
        self.timing_s["association"] += time.perf_counter() - ta
        self._update(self.config.extra_iterations if associated else 0)
        for lm, f in associated:
            self._grow_extent(lm, f)
        for i in range(len(use)):
            self.association_log.append((use[i].t, i, ids[i]))
        by_feature = {id(f): ids[i] for i, f in enumerate(use)}
        return [by_feature.get(id(f)) for f in features]

    def _add_line_factor(self, k: int, bTs: FloatArray, lm: GraphLandmark, f: LineFeature) -> None:
        cfg = self.config
        robust = None if cfg.robust is None else {"kernel": cfg.robust, "k": cfg.robust_k}
        self._add_factor(
            _record(
                "LineObservation",
                [X(k), lm.key],
                f.z,
                np.asarray(f.cov) * self.config.line_cov_scale,
                bTs=np.asarray(bTs).tolist(),
                robust=robust,
            )
        )
        lm.n_obs += 1

    def _observation_in_world(
        self, f: LineFeature, pose_w: FloatArray, P_pose_w: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """World line, its covariance and the observation's world end points (2, 2)."""
        wTs = compose(pose_w, self.bTs)
        line_w, G_z, G_sensor = line_frame_to_world(f.z, wTs)
        J_pose, _ = compose_jacobians(pose_w, self.bTs)
        G_pose = G_sensor @ J_pose
        cov_w = G_pose @ P_pose_w @ G_pose.T + G_z @ (self.config.line_cov_scale * f.cov) @ G_z.T
        return line_w, cov_w, transform_points(wTs, f.endpoints_r)

    def _new_line(
        self,
        node: tuple[int, FloatArray],
        f: LineFeature,
        pose_w: FloatArray,
        P_pose_w: FloatArray,
    ) -> int | None:
        """A tentative line, promoted to a landmark with all its observations when seen again."""
        cfg = self.config
        line_w, cov_w, ends_w = self._observation_in_world(f, pose_w, P_pose_w)
        kept = [c for c in self._tentative if f.t - c.t <= cfg.tentative_max_age_s]
        self.stats["tentative_dropped"] += len(self._tentative) - len(kept)
        self._tentative = kept
        gate = self._gate_tentative
        for cand in self._tentative:
            if cfg.side_gate and sonar_side(pose_w, cand.line_w, self.bTs)[0] != cand.side:
                continue
            nu, _ = line_innovation(line_w, cand.line_w)
            if nu @ np.linalg.solve(cov_w + cand.cov_w, nu) <= gate:
                cand.observations.append((node, f))
                cand.ends_w = np.vstack([cand.ends_w, ends_w])
                if len(cand.observations) >= cfg.tentative_observations:
                    self._tentative.remove(cand)
                    return self._promote(line_w, cand.observations, cand.ends_w, pose_w)
                return None
        if cfg.tentative_observations <= 1:
            return self._promote(line_w, [(node, f)], ends_w, pose_w)
        side = float(sonar_side(pose_w, line_w, self.bTs)[0])
        self._tentative.append(_Tentative(f.t, line_w, cov_w, ends_w, [(node, f)], side))
        return None

    def _promote(
        self,
        line_w: FloatArray,
        observations: list[tuple[tuple[int, FloatArray], LineFeature]],
        ends_w: FloatArray,
        pose_w: FloatArray,
    ) -> int:
        side = float(sonar_side(pose_w, line_w, self.bTs)[0])
        # the extent on the landmark's own line: the tentative lines may be in the other
        # representation (rho, theta) ~ (-rho, theta + pi), whose along-line axis is reversed
        s = along_line(line_w, ends_w)
        lm = GraphLandmark(len(self.landmarks), 0, float(s.min()), float(s.max()), side)
        self._pending_values.insert(lm.key, np.asarray(line_w, dtype=np.float64))
        for (k, bTs), f in observations:
            self._add_line_factor(k, bTs, lm, f)
        self.seed_log.extend((f, lm.id) for _, f in observations[:-1])
        self.landmarks.append(lm)
        self._new_landmarks.append(lm.id)
        self._lm_est[lm.id] = np.asarray(line_w, dtype=np.float64).copy()
        self.stats["new_landmarks"] += 1
        return lm.id

    def _grow_extent(self, lm: GraphLandmark, f: LineFeature) -> None:
        self._refresh()
        wTs = compose(self.pose, self.bTs)
        line = self._lm_est[lm.id]
        s = along_line(line, transform_points(wTs, f.endpoints_r))
        lm.s_min_m = min(lm.s_min_m, float(s.min()))
        lm.s_max_m = max(lm.s_max_m, float(s.max()))

    # -- results ---------------------------------------------------------------------------

    def flush(self) -> None:
        """Put every pending factor into iSAM2 (with a node now unless one is just behind)."""
        if self._pending_nodes or self._pending.size():
            if self.t_s - self._last_node_t >= self.config.min_node_gap_s:
                self._add_node()
            self._update()

    def estimate(self) -> gtsam.Values:
        """Current values: the batch optimum after :meth:`optimize_batch`, else iSAM2's."""
        self.flush()
        return self._batch if self._batch is not None else self.isam.calculateEstimate()

    def optimize_batch(self, params: gtsam.LevenbergMarquardtParams | None = None) -> gtsam.Values:
        """A final batch Levenberg-Marquardt on the whole graph from the iSAM2 estimate.

        ``params`` default: GTSAM's, at most 20 iterations.

        The result replaces iSAM2's in :meth:`estimate`, :meth:`smoothed_trajectory`,
        :attr:`pose` and the pose source until the next update (:attr:`pose_cov` stays
        iSAM2's).
        """
        self.flush()
        if params is None:
            params = gtsam.LevenbergMarquardtParams()
            params.setMaxIterations(20)  # from the iSAM2 estimate it is a polish
        values = gtsam.LevenbergMarquardtOptimizer(
            self.graph, self.isam.calculateEstimate(), params
        ).optimize()
        self._batch = values
        self._stale = True
        self._refresh()
        self._refresh_nodes(-np.inf)
        self._anchor_pose = _pose_of(values.atPose2(X(self._n_nodes - 1)))
        self._anchor_xyyaw = tuple(float(v) for v in self._anchor_pose)
        return values

    def node_times(self) -> FloatArray:
        """Times of the optimised nodes ``X(0..n-1)`` (Unix s), shape (n,)."""
        return self._node_t.rows[:, 0].copy()

    def smoothed_trajectory(self, covariances: bool = False) -> Trajectory:
        """The smoothed poses of all nodes, with their marginal covariances if asked.

        Covariances are iSAM2's marginals (or, after :meth:`optimize_batch`, those of
        ``gtsam.Marginals`` at the batch optimum), in ``(x_m, y_m, yaw_rad)``.
        """
        self.flush()
        self._refresh_nodes(-np.inf)
        poses = self._node_pose.rows.copy()
        covs = None
        if covariances:
            marg = gtsam.Marginals(self.graph, self._batch) if self._batch is not None else None
            covs = np.empty((poses.shape[0], 3, 3))
            for k in range(poses.shape[0]):
                C = marg.marginalCovariance(X(k)) if marg else self.isam.marginalCovariance(X(k))
                M = local_to_world(float(poses[k, 2]))
                covs[k] = M @ C @ M.T
        return Trajectory(self.node_times(), poses, covs)

    def map_json(self) -> list[dict[str, Any]]:
        """Per landmark: id, rho, theta, cov, world endpoints, observation count."""
        self._refresh()
        out = []
        marg = gtsam.Marginals(self.graph, self._batch) if self._batch is not None else None
        for lm in self.landmarks:
            raw = self._lm_est[lm.id]
            C = marg.marginalCovariance(lm.key) if marg else self.isam.marginalCovariance(lm.key)
            line, cov = _normalised_landmark(raw, np.asarray(C))
            s_min, s_max = lm.s_min_m, lm.s_max_m
            if raw[0] < 0.0:  # the along-line axis turns with the normal
                s_min, s_max = -s_max, -s_min
            out.append(landmark_record(lm.id, line, cov, s_min, s_max, lm.n_obs))
        return out

    def save(self, path: str | Path) -> None:
        """Write the graph and the current values (:func:`save_graph`; read by :func:`load_graph`)."""
        values = self.estimate()
        meta = {
            "node_times_s": {_key_name(X(k)): float(t) for k, t in enumerate(self.node_times())},
            "bTs": self.bTs.tolist(),
            "config": {
                k: v
                for k, v in self.config.__dict__.items()
                if not isinstance(v, AssociationConfig)
            },
        }
        save_graph(path, self.records, values, meta)


# -- the seam to the front end -----------------------------------------------------------------


def _carry(wTn: FloatArray, o_n: FloatArray, o_t: FloatArray) -> FloatArray:
    """``wTn * inverse(o_n) * o_t`` row by row, shapes (N, 3): a node carried by the odometry."""
    phi = wTn[:, 2] - o_n[:, 2]
    c, s = np.cos(phi), np.sin(phi)
    dx, dy = o_t[:, 0] - o_n[:, 0], o_t[:, 1] - o_n[:, 1]
    out = np.empty_like(o_t)
    out[:, 0] = wTn[:, 0] + c * dx - s * dy
    out[:, 1] = wTn[:, 1] + s * dx + c * dy
    out[:, 2] = wTn[:, 2] + o_t[:, 2] - o_n[:, 2]
    return out


def smoothed_poses(
    t_s: npt.ArrayLike,
    node_t_s: FloatArray,
    node_wTb: FloatArray,
    node_odo: FloatArray,
    chain: FloatArray,
) -> FloatArray:
    """Poses between smoothed nodes, shaped by the odometry (the pose source's rule).

    For ``t`` between nodes ``i`` and ``i + 1`` both nodes are carried to ``t`` by the odometry
    (``N_i * O(t_i)^-1 * O(t)``) and blended linearly in time: the result passes through both
    nodes and follows the odometry in between; if the odometry agrees with the nodes, it *is*
    the odometry. Past the newest node (and before the first) it is that node carried by the
    odometry.

    Parameters
    ----------
    t_s : array_like, shape (M,)
        Query times (Unix s).
    node_t_s : ndarray, shape (N,)
        Increasing node times, ``N >= 1``.
    node_wTb : ndarray, shape (N, 3)
        Smoothed node poses.
    node_odo : ndarray, shape (N, 3)
        Odometry chain ``O`` at the node times, yaw unwrapped.
    chain : ndarray, shape (K, 4)
        Rows ``(t_s, x, y, yaw)`` of the odometry chain in its own frame, yaw unwrapped,
        interpolated linearly (held past its ends).

    Returns
    -------
    ndarray, shape (M, 3)
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    # only the stretch of the chain around the queries (it grows with every record)
    lo, hi = np.searchsorted(chain[:, 0], [t.min(), t.max()])
    part = chain[max(lo - 1, 0) : hi + 1]
    o_t = np.column_stack([np.interp(t, part[:, 0], part[:, c]) for c in (1, 2, 3)])
    n = node_t_s.size
    i = np.clip(np.searchsorted(node_t_s, t, side="right") - 1, 0, n - 1)
    j = np.minimum(i + 1, n - 1)
    a = _carry(node_wTb[i], node_odo[i], o_t)
    b = _carry(node_wTb[j], node_odo[j], o_t)
    span = node_t_s[j] - node_t_s[i]
    w = np.where(span > 0.0, (t - node_t_s[i]) / np.where(span > 0.0, span, 1.0), 0.0)
    w = np.clip(w, 0.0, 1.0)
    out = a.copy()
    out[:, :2] += w[:, None] * (b[:, :2] - a[:, :2])
    out[:, 2] = wrap_angle(a[:, 2] + w * wrap_angle(b[:, 2] - a[:, 2]))
    return out


class SmoothedPoseSource:
    """PoseSource of :class:`LineIsam2`: its smoothed trajectory, densified by the odometry.

    The optimised nodes (their poses refreshed after every iSAM2 update, those within
    ``pose_window_s``; the front end only asks for its stored sector) and the back end's
    odometry chain, through :func:`smoothed_poses`. Past the newest optimised node the pose is
    that node composed with the odometry since it, i.e. :attr:`LineIsam2.pose` at the current
    time.
    """

    def __init__(self, backend: LineIsam2) -> None:
        self.backend = backend

    def poses(self, t_s: npt.ArrayLike) -> FloatArray:
        """Body poses ``wTb`` at ``t_s`` (Unix s), shape (N, 3)."""
        be = self.backend
        be._refresh()
        return smoothed_poses(
            t_s, be._node_t.rows[:, 0], be._node_pose.rows, be._node_odo.rows, be._chain.rows
        )

    def covariance(self, t_s: float) -> FloatArray | None:
        """The filtered covariance at ``t_s``: the current one past the newest optimised node,
        else the iSAM2 marginal of the newest node optimised at or before ``t_s`` as it was
        when it was the newest (not propagated to ``t_s``)."""
        be = self.backend
        if not be._anchor_t or t_s >= be._anchor_t[-1]:
            return be.pose_cov
        i = max(int(np.searchsorted(be._anchor_t, t_s, side="right")) - 1, 0)
        return be._anchor_cov[i]


def pose_source_of(backend: LineIsam2, odometry: Any = None) -> SmoothedPoseSource:
    """``run_closed_loop``'s ``pose_source_of`` for the graph: its smoothed trajectory.

    The driver's anchored odometry is not needed: the back end chains the same relative
    motions (those its :meth:`LineIsam2.predict` returns) itself.
    """
    return backend.pose_source()


def isam2_backend_factory(
    sonar_mounting: Mounting, config: GraphConfig | None = None
) -> Callable[[float, FloatArray, FloatArray], LineIsam2]:
    """``run_closed_loop``'s ``make_backend`` for :class:`LineIsam2`."""
    cfg = config or GraphConfig()

    def make(t0_s: float, wTb0: FloatArray, P0: FloatArray) -> LineIsam2:
        return LineIsam2(t0_s, wTb0, P0, sonar_mounting, cfg)

    return make
