"""The seam between the driver and a SLAM back end: the settings every back end shares and the
typed :class:`Backend` protocol.

A back end estimates the vehicle pose from the motion steps (:class:`sonarslam.slam.model.motion.MotionStep`),
the AHRS headings and the front end's lines, and in return gives the front end the pose of every
beam through a :class:`sonarslam.features.pose_source.PoseSource`. Its landmarks are managed by the shared
landmark layer (:class:`sonarslam.slam.mapping.landmarks.LandmarkMap`), which calls back into the back end
through one call per vote of lines (:meth:`sonarslam.slam.mapping.landmarks.LandmarkMap.vote`: the back
end's belief in, the layer's decision out, :mod:`sonarslam.slam.mapping.vote`). Both back ends here (the EKF,
:mod:`sonarslam.slam.backends.ekf`, and iSAM2, :mod:`sonarslam.slam.backends.isam2`) implement both protocols; a new
back end registers in :mod:`sonarslam.slam.backends.registry`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.config import NoiseConfig
from sonarslam.features.geometry import FloatArray, compose, inverse
from sonarslam.features.line import LineFeature
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.scans import Scan, ScanMatcher
from sonarslam.settings import bounded, one_of
from sonarslam.slam.backends.learned import LEARN_KINDS
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.mapping.landmarks import LandmarkConfig, LandmarkMap
from sonarslam.slam.model.lines import VoteObservations, usable_observations
from sonarslam.slam.model.motion import MotionStep, OdometryChain

__all__ = [
    "BACKEND_NOISE_KEYS",
    "BackendConfig",
    "Backend",
    "ScanBackend",
    "AnchoredOdometry",
    "VoteObservations",
    "vote_observations",
    "ids_of_features",
]


#: The ``[noise]`` keys a back end reads from its configuration's ``noise``
#: (``<backend>.noise.<key>``); the other keys reach every estimator through the dataset's
#: ``[noise]`` (the motion model, the start pose), never through a back end's settings.
BACKEND_NOISE_KEYS = (
    "ahrs_white_sigma_deg",
    "ahrs_bias_sigma_deg",
    "ahrs_bias_walk_deg_per_sqrt_s",
    "gyro_sigma_rad_per_s",
    "dvl_scale_sigma",
)


@dataclass(frozen=True)
class BackendConfig(LandmarkConfig):
    """Settings every back end shares: the landmark layer's (:class:`LandmarkConfig`) and the
    heading and motion models'.

    Attributes
    ----------
    noise : NoiseConfig
        The sensor noise the heading and motion models take: the dataset's ``[noise]``
        (:class:`sonarslam.datasets.config.NoiseConfig`: the AHRS's white noise and bias, the
        bias's walk, the gyro's and the DVL's scale error: :data:`BACKEND_NOISE_KEYS`, the
        keys a back end reads), set by the runner; their ``--set`` names are
        ``<backend>.noise.<key>``. The AHRS bias is modelled so that an estimator
        never believes its heading better than the compass can tell it (a white-noise model
        at 1 Hz would, and would be inconsistent); nothing else observes it: line landmarks,
        DVL and gyro are blind to a rotation of the whole map and trajectory about the start
        position, which is what the bias does. Its walk's changes since a wall was mapped are
        what re-observing the wall corrects.
    ahrs_period_s : float
        An AHRS heading is used at most this often (s); the AHRS errors are not white.
    estimate_misalignment : bool
        Estimate the misalignment ``delta`` of the DVL velocity with the body heading (rad): the
        vehicle moves along ``R(psi + delta) v_b``. Line landmarks make it observable; it
        absorbs the error of a GPS-free DVL/AHRS calibration.
    misalignment_sigma_deg : float
        Its prior 1-sigma (deg).
    estimate_sonar_mount : bool
        Estimate the sonar mounting ``bTs`` ``(x, y, yaw)``, one estimate shared by every
        line (and, in the factor graph, scan) observation
        (:mod:`sonarslam.slam.model.calibration`), with the dataset's mounting as the prior
        mean: the graph's variable ``C(0)``, three states of the EKF. Off by default
        (docs/design-decisions.md, "Sonar calibration as state"; the EKF's: docs/research/calibration.md,
        "The EKF's calibration states").
    sonar_mount_sigma_m : float
        Its prior 1-sigma in x and in y (m): a lever arm a user measures with a tape, or not at
        all.
    sonar_mount_sigma_deg : float
        Its prior 1-sigma in yaw (deg): a yaw calibrated from the sonar's own map (``sonarslam
        calibrate``) is known to a fraction of a degree.
    sonar_yaw_prior : {"body", "dead_reckoning"}
        What the mounting's yaw prior is on, when the mounting and the DVL misalignment are
        both estimated: ``"body"`` (the default), the yaw itself (a yaw measured against the
        hull); ``"dead_reckoning"``, the yaw minus the misalignment (the graph:
        :func:`sonarslam.slam.backends.isam2.factors.mount_prior_dvl_residual`; the EKF: the
        prior covariance of yaw and misalignment that says so): a yaw calibrated from the
        sonar's map drawn with dead-reckoning poses (``sonarslam calibrate --poses dr``) is
        known relative to the DVL's track, and the data see only that difference, so the
        misalignment's own prior alone then decides where the two turn together
        (docs/research/calibration.md, "The sonar/DVL direction").
    range_scale_sigma : float
        Prior 1-sigma of the sonar's range scale ``s`` around 1 (an echo from range ``r`` is
        logged at ``s * r``: a sound-speed error), shared as the mounting (the graph's
        ``R(0)``); 0: not estimated (``s = 1``, the default; docs/design-decisions.md gives the
        sizes these priors are chosen for).
    robust : {None, "huber", "cauchy"}
        Robust kernel on the line observations, so that one bad line cannot drag the pose: the
        factor graph's on the whitened residual (``gtsam.noiseModel.Robust``), the EKF's on the
        innovation's Mahalanobis distance ``d`` (the observation's covariance divided by the
        kernel's weight ``w(d)`` before the update: an innovation gate that bends, not breaks).
    robust_k : float
        The kernel's width (sigmas; Huber 1.345 is 95 % efficient on Gaussian data).
    constraints : str
        What corrects the odometry, comma-separated: ``"lines"`` (line landmarks from the line
        extractor), ``"scans"`` (relative poses from the scan matcher,
        :mod:`sonarslam.features.scans`), or ``"lines,scans"``. A back end that cannot take one says so.
    learn_noise : str
        What the loop learns from its innovations, comma-separated
        (:mod:`sonarslam.slam.model.noise_learning`, :mod:`sonarslam.slam.backends.learned`):
        ``"heading"`` (the heading error's random walk, at least ``ahrs_bias_walk_deg_per_sqrt_s``),
        ``"dvl_scale"`` (a random walk of the DVL's scale error, at least 0), ``"lines"`` (a factor
        on the line covariances, at least 1), ``"scans"`` (a factor on the revisit
        registrations' covariances, at least 1; the factor graph with scans); ``""``: nothing,
        every value as told. The learned values over time are ``noise.csv`` and ``noise_*`` in
        ``metrics.json``.
    learn_heading_start_deg_per_sqrt_s : float
        The heading walk a loop learning it (``"heading"``) starts from, when above the
        configured one: the walk it takes until its innovations say otherwise.
    learn_dvl_scale_start_per_sqrt_s : float
        The DVL scale walk a loop learning it (``"dvl_scale"``) starts from (1/sqrt(s)).
    learn_memory_s : float
        The time the learner remembers (s; its sums forget by ``exp(-dt / learn_memory_s)``).
    learn_every : int
        The learner takes a step every this many innovations.
    """

    noise: NoiseConfig = field(default_factory=NoiseConfig)
    ahrs_period_s: float = bounded(1.0, 1e-3, 3600.0)
    estimate_misalignment: bool = False
    misalignment_sigma_deg: float = bounded(5.0, 1e-3, 90.0)
    estimate_sonar_mount: bool = False
    sonar_mount_sigma_m: float = bounded(0.2, 1e-4, 10.0)
    sonar_mount_sigma_deg: float = bounded(0.5, 1e-3, 90.0)
    sonar_yaw_prior: str = one_of("body", "body", "dead_reckoning")
    range_scale_sigma: float = bounded(0.0, 0.0, 0.5)
    robust: str | None = one_of(None, None, "huber", "cauchy")
    robust_k: float = bounded(1.345, 0.0, math.inf, low_open=True)
    constraints: str = "lines"
    learn_noise: str = ""
    learn_heading_start_deg_per_sqrt_s: float = bounded(0.0, 0.0, 1.0)
    learn_dvl_scale_start_per_sqrt_s: float = bounded(0.0, 0.0, 0.01)
    learn_memory_s: float = bounded(300.0, 1.0, 1e6)
    learn_every: int = bounded(5, 1, 10_000)

    @property
    def learned_kinds(self) -> frozenset[str]:
        """The kinds in :attr:`learn_noise`."""
        return frozenset(c.strip() for c in self.learn_noise.split(",") if c.strip())

    @property
    def calibrated(self) -> bool:
        """Whether the sonar's mounting or range scale is estimated."""
        return self.estimate_sonar_mount or self.range_scale_sigma > 0.0

    @property
    def constraint_kinds(self) -> frozenset[str]:
        """The kinds in :attr:`constraints`."""
        return frozenset(c.strip() for c in self.constraints.split(","))

    def __post_init__(self) -> None:
        super().__post_init__()  # every field's range (sonarslam.settings.check_fields)
        kinds = self.constraint_kinds
        if not kinds or not kinds <= {"lines", "scans"}:
            raise ValueError(
                f"constraints must be 'lines', 'scans' or 'lines,scans', got {self.constraints!r}"
            )
        unknown = self.learned_kinds - set(LEARN_KINDS)
        if unknown:
            raise ValueError(
                f"learn_noise takes a comma list of {', '.join(LEARN_KINDS)}, got"
                f" {self.learn_noise!r} ({', '.join(sorted(unknown))} unknown)"
            )
        if self.sonar_yaw_prior != "body" and not (
            self.estimate_sonar_mount and self.estimate_misalignment
        ):
            raise ValueError(
                f"sonar_yaw_prior {self.sonar_yaw_prior!r} is a prior on the estimated mounting"
                " yaw minus the estimated DVL misalignment: it needs estimate_sonar_mount and"
                " estimate_misalignment both true (alone it would change nothing)"
            )


class Backend(Protocol):
    """What the driver (:func:`sonarslam.slam.run.closed_loop.run_closed_loop`) and the runner need from
    a SLAM back end."""

    @property
    def config(self) -> BackendConfig:
        """Its settings."""
        ...

    @property
    def map(self) -> LandmarkMap:
        """Its landmarks (the shared landmark layer)."""
        ...

    @property
    def pose(self) -> FloatArray:
        """Current body pose ``wTb`` ``(x_m, y_m, yaw_rad)``, shape (3,)."""
        ...

    @property
    def pose_cov(self) -> FloatArray:
        """Its covariance, shape (3, 3)."""
        ...

    @property
    def stats(self) -> dict[str, int]:
        """Counters of the run (the landmark layer's and the back end's own)."""
        ...

    @property
    def vote_wall_s(self) -> list[float]:
        """Wall time of each :meth:`update_lines` (s): the back end's cost per vote of lines."""
        ...

    def predict(self, step: MotionStep) -> FloatArray:
        """Integrate one motion step; returns the relative motion ``bTb'`` it applied (the
        odometry the driver chains for the front end)."""
        ...

    def update_heading(self, t_s: float, yaw_body_rad: float) -> bool:
        """An AHRS body heading; False when skipped (``ahrs_period_s``)."""
        ...

    def update_lines(self, features: list[LineFeature]) -> list[int | None]:
        """The lines of one vote; the landmark id of each (None: not associated)."""
        ...

    def pose_source(self, odometry: AnchoredOdometry) -> PoseSource:
        """The front end's poses: a filter gives the driver's anchored odometry back, a
        smoother its own smoothed trajectory."""
        ...

    def finish(self) -> None:
        """End of the run: everything pending goes into the estimate."""
        ...

    def map_records(self) -> list[dict[str, object]]:
        """``map.json``'s landmarks (:meth:`sonarslam.slam.mapping.landmarks.LandmarkMap.records`)."""
        ...

    def trajectories(self, batch: bool = False) -> dict[str, Trajectory]:
        """Trajectories beside the causal one (a smoother's smoothed one, and with ``batch`` a
        final batch optimisation's), by name; empty for a filter."""
        ...

    def metrics(self) -> dict[str, float | int]:
        """Figures of the run beyond :attr:`stats` (timings), for ``metrics.json``."""
        ...

    def save(self, out_dir: Path) -> list[Path]:
        """Write what the back end has beyond trajectories and map (a graph); the files."""
        ...


@runtime_checkable
class ScanBackend(Protocol):
    """A back end that takes the scan matcher's relative poses (``constraints`` with
    ``"scans"``): the factor graph (:mod:`sonarslam.slam.backends.isam2.scans`)."""

    def update_scan(self, scan: Scan, matcher: ScanMatcher) -> None:
        """A scan the matcher completed (its newest): the back end's node for it and the
        registrations it asks ``matcher`` for (consecutive, revisits)."""
        ...


def vote_observations(
    features: list[LineFeature], config: LandmarkConfig, line_cov_scale: float | None = None
) -> VoteObservations:
    """The lines of one vote the landmark layer may use, the rules of
    :class:`sonarslam.slam.mapping.landmarks.LandmarkConfig` (``min_rho_m``, ``line_cov_scale``
    or the one given, the landmark layer's in force:
    :attr:`sonarslam.slam.mapping.landmarks.LandmarkMap.line_cov_scale`;
    :func:`sonarslam.slam.model.lines.usable_observations`)."""
    scale = config.line_cov_scale if line_cov_scale is None else line_cov_scale
    return usable_observations(features, config.min_rho_m, scale)


def ids_of_features(
    features: list[LineFeature], used: list[LineFeature], ids: list[int | None]
) -> list[int | None]:
    """The landmark id of each of ``features`` from those of the ``used`` ones (None for the
    others)."""
    by_feature = {id(f): ids[i] for i, f in enumerate(used)}
    return [by_feature.get(id(f)) for f in features]


class AnchoredOdometry:
    """PoseSource of a filter: past poses from the odometry chain, anchored at the current estimate.

    ``wTb(t) = wTb_now * inverse(O(t_now)) * O(t)``, where ``O`` chains the relative motions of
    the filter's predictions (:class:`sonarslam.slam.model.motion.OdometryChain`). After a correction the
    whole stored sector moves rigidly with the current estimate, so the motion-distortion
    correction uses the (locally accurate) odometry and the absolute pose comes from the filter.

    :meth:`covariance` is the chain's own position variance accumulated from the DVL noise on
    top of the anchor's covariance: the extractor takes only its differences between beams
    (``ExtractorConfig.pose_uncertainty``), which are the odometry's uncertainty over the sector
    and so grow when the DVL degrades.
    """

    def __init__(self, t0_s: float, wTb0: FloatArray, capacity: int = 4096) -> None:
        self.chain = OdometryChain(t0_s, capacity)
        self._anchor_t = t0_s
        self._anchor = np.asarray(wTb0, dtype=np.float64).copy()
        self._anchor_cov: FloatArray | None = None

    def append(self, t_s: float, bTb_next: FloatArray, var_step_m2: float = 0.0) -> None:
        """Chain one step of relative motion ending at ``t_s``, whose position variance per
        axis is ``var_step_m2``."""
        self.chain.append(t_s, bTb_next, var_step_m2)

    def set_anchor(self, t_s: float, wTb: FloatArray, cov: FloatArray | None = None) -> None:
        """The filter's estimate at ``t_s`` (and its covariance)."""
        self._anchor_t = t_s
        self._anchor = np.asarray(wTb, dtype=np.float64).copy()
        self._anchor_cov = cov

    def poses(self, t_s: npt.ArrayLike) -> FloatArray:
        """Body poses ``wTb`` at ``t_s`` (Unix s), shape (N, 3)."""
        tq = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        chain = self.chain.at(np.append(tq, self._anchor_t))
        o_t, o_now = chain[:-1], chain[-1]
        return compose(compose(self._anchor, inverse(o_now)), o_t)

    def covariance(self, t_s: float) -> FloatArray | None:
        """The anchor's covariance plus the chain's position variance up to ``t_s``."""
        if self._anchor_cov is None:
            return None
        v = self.chain.variance_at(t_s)
        return np.asarray(self._anchor_cov) + np.diag([v, v, 0.0])

    def covariances(self, t_s: npt.ArrayLike) -> FloatArray | None:
        """:meth:`covariance` at many times, shape (N, 3, 3)
        (:class:`sonarslam.features.pose_source.BatchCovariances`)."""
        if self._anchor_cov is None:
            return None
        v = self.chain.variances_at(t_s)
        out = np.repeat(np.asarray(self._anchor_cov, dtype=np.float64)[None], v.size, axis=0)
        out[:, 0, 0] += v
        out[:, 1, 1] += v
        return out
