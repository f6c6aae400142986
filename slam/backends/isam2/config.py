"""Settings of the factor-graph back end (:class:`sonarslam.slam.backends.isam2.graph.LineIsam2`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from sonarslam.settings import bounded, check_fields, one_of
from sonarslam.slam.backends.base import BackendConfig

__all__ = ["GraphConfig", "OfflineConfig"]


@dataclass(frozen=True)
class OfflineConfig:
    """The estimate made after the run with hindsight
    (:func:`sonarslam.slam.backends.isam2.offline.offline_estimate`): every revisit and line
    decided again from the whole run.

    Attributes
    ----------
    enabled : bool
        Made after every iSAM2 run (``--set isam2.offline=false``: not made).
    max_passes : int
        Candidates, registrations, the joint decision, the lines and the noise scales are
        decided again at each pass's optimum until the decisions stop changing, at most this
        many times.
    start : {"smoothed", "odometry"}
        The first pass's estimate: the run's smoothed one, or the optimum of the odometry and
        headings alone (no revisit or line decided while drifting shapes the first scans).
    revisit_radius_m : float
        Two scans whose reference positions in the current estimate are this close are a
        revisit candidate (m).
    revisit_min_gap_s : float
        ... when at least this far apart in time (s).
    revisits_per_scan : int
        At most this many per scan, spread over time: the candidates in time order cut into
        this many groups, the nearest of each.
    yaw_sigma_deg : float or None
        A registration's yaw decoupled from its translation with this sigma (deg): the same walls
        seen from another pass turn a registration's yaw more than its Hessian says, and the
        AHRS observes the heading. None: the registration's own covariance.
    decision_probability : float
        The joint decision's truncation (graduated non-convexity with a truncated least-squares
        cost): a revisit whose squared Mahalanobis residual exceeds chi2(3) at this
        probability is an outlier.
    noise_scales : {"measurements", "all", None}
        Which covariance scales are estimated from the residuals of the consistent set
        (variance components), each at least 1 (never more confident than the model says):
        ``"measurements"``, the revisits' and the lines'; ``"all"``, the odometry's and the
        AHRS headings' too; None (``none``): as configured.
    settle_share : float
        The decisions have settled when fewer than this share of them (revisits kept or
        dropped, line observations on another stretch) changed in a pass.
    lines : bool
        The line observations re-decided at each pass's estimate and kept in the graph;
        False: a pose graph of odometry, headings and revisits.
    stretch_m : float
        The longest stretch of a wall one re-decided landmark stands for (m)
        (:class:`sonarslam.slam.mapping.redecide.RedecideConfig`).
    """

    enabled: bool = True
    max_passes: int = bounded(4, 1, 20)
    start: str = one_of("smoothed", "smoothed", "odometry")
    revisit_radius_m: float = bounded(10.0, 0.0, 1e4, low_open=True)
    revisit_min_gap_s: float = bounded(60.0, 0.0, 1e6)
    revisits_per_scan: int = bounded(4, 1, 100)
    yaw_sigma_deg: float | None = bounded(None, 0.0, 180.0, low_open=True)
    decision_probability: float = bounded(0.99, 0.0, 1.0, low_open=True, high_open=True)
    noise_scales: str | None = one_of("measurements", "measurements", "all", None)
    settle_share: float = bounded(0.02, 0.0, 1.0)
    lines: bool = True
    stretch_m: float = bounded(80.0, 0.0, 1e5, low_open=True)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class GraphConfig(BackendConfig):
    """Settings of the factor graph: those of :class:`sonarslam.slam.backends.base.BackendConfig`
    (the sonar's calibration as state among them: ``C(0)`` the mounting, ``R(0)`` the range
    scale, shared by every line and scan observation) and the following. With the sonar's
    mounting a variable, estimate the DVL's misalignment too
    (``estimate_misalignment``): it takes the crab a DVL's lateral bias puts on the odometry,
    which the mounting's yaw would otherwise absorb (docs/research/calibration.md, "Calibration as state:
    the three together").

    Attributes
    ----------
    ahrs_bias_prior_deg : float
        Prior mean of the constant AHRS bias ``B(0)`` (deg).
    dvl_noise : {"hold", "white"}
        How the velocity noise adds up. ``"hold"``: the error of a held DVL sample is one draw
        for the whole hold (:func:`sonarslam.slam.model.noise.held_velocity_variance_step`, the EKF's
        model). ``"white"``: independent per motion step, ``(dt * sigma)**2`` each: a held
        sample's one error counted as a new one at every step, which understates the position
        variance by about the number of steps per hold (docs/design-decisions.md).
    node_period_s : float
        A pose node at least this often (s); votes with lines add theirs.
    min_node_gap_s : float
        An observation this close (s) after the newest node goes on that node, carried by the
        odometry since it (:meth:`LineIsam2.node_now`), instead of on a new node.
    update_period_s : float
        Pending odometry and heading factors go into iSAM2 at most this often (s) between
        votes with lines (which always update).
    estimate_gyro_scale : bool
        Estimate the scale ``G(0)`` of the gyro's yaw rate: the odometry's heading change is
        ``s`` times the gyro's integral. The AHRS headings make it observable.
    gyro_scale_sigma : float
        Prior 1-sigma of ``s`` around 1.
    scan_calibration : bool
        The scan constraints take the mounting and range scale too
        (``ScanRegistrationCalibrated``); False (the default): they stay ``BetweenFactorPose2``
        on the body nodes.
    robust : {None, "huber", "cauchy"}
        As :class:`sonarslam.slam.backends.base.BackendConfig`; Huber by default here (heavy-tailed line
        errors on thick echo bands).
    relinearize_threshold : float
        iSAM2 relinearises a variable whose delta exceeds this (m, rad). GTSAM's default: a
        lower threshold relinearises most of the graph when line loops pull the trajectory by
        metres, at many times the cost.
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

    Scan constraints (``constraints`` with ``"scans"``, :mod:`sonarslam.slam.backends.isam2.scans`):

    scan_robust : {None, "huber", "cauchy"}
        Robust kernel of the scan constraints (``BetweenFactorPose2``).
    scan_robust_k : float
        Its width (sigmas).
    scan_consecutive : bool
        Each scan registered onto the one before it.
    start : {"smoothed", "odometry"}
        The first pass's estimate: the run's smoothed one, or the optimum of the odometry and
        headings alone (no revisit or line decided while drifting shapes the first scans).
    revisit_radius_m : float
        Two scans whose reference positions are this close see the same walls (m): a property
        of the sonar's range and the place, not the gate; the gate is on the relative pose.
    revisit_gate_probability : float
        An older scan is a revisit candidate when the distance of the two scans' positions
        minus ``revisit_radius_m``, in sigmas of the graph's marginal of their relative
        position along that direction, is inside this chi2(1) quantile.
    revisit_min_gap_s : float
        Revisits only between scans at least this far apart in time (s); closer ones are the
        consecutive chain.
    revisit_candidates : int
        At most this many candidates (nearest by that distance under the loose gate, with
        cached marginals and no cross-covariance) get the joint marginal and the exact gate.
    revisits_per_scan : int
        At most this many revisit registrations per new scan (from older scans at least a
        submap apart).
    revisit_choice : {"nearest", "spread"}
        Which candidates and revisits are taken
        (:func:`sonarslam.slam.backends.isam2.scans.choose_revisits`): the nearest in metres, or
        the nearest in each of as many groups of the candidates in time order (spread over the
        passes).
    revisit_spacing_scans : int or None
        The revisits of one scan are at least this many scans apart in the older scans (the
        candidates too): None, ``submap_scans`` (their submaps share no scan: one revisit per
        earlier pass); 1, neighbouring scans of one pass too.
    revisit_lag_scans : int
        A scan's revisits are proposed when this many scans after it have arrived: with
        ``submap_scans // 2`` its submap is complete, centred on it and frozen as the older
        scans' are (0: at once, its submap the newest scans, shifted back). The last
        ``revisit_lag_scans`` scans of a run get no revisits.
    revisit_gate : {"registration", "graph"}
        ``"registration"`` (the default): every registration the matcher accepts (its inliers,
        residual and ambiguity tests) goes in, under the scan kernel (``scan_robust``), which
        re-weights it against every other factor at each relinearisation; ``"graph"``: a
        revisit registration is kept only when its relative pose is compatible with the graph's
        prediction (``scan_compatibility_probability``), which rejects the revisits that would
        correct the drift once the estimate has drifted beyond its marginals
        (docs/design-decisions.md, "Revisits: every registration the matcher accepts").
    scan_compatibility_probability : float
        A revisit registration is compatible with the graph's prediction when chi2(3) of the
        difference with the sum of both covariances is within this (the ``"graph"`` gate, and
        the batch's GNC threshold).
    batch_optimizer : {"lm", "gnc"}
        The final batch pass (``--batch``): Levenberg-Marquardt on the graph as the loop built
        it, or graduated non-convexity choosing the revisits jointly among every one the
        registration accepted, the compatibility gate's rejects included
        (:meth:`sonarslam.slam.backends.isam2.graph.LineIsam2.optimize_batch`).
    redecide_stretch_m : float or None
        After the run, the line observations re-decided at the smoothed estimate in stretches
        of at most this (m) along each line and the graph re-optimised: the estimate
        ``redecided`` (:meth:`sonarslam.slam.backends.isam2.graph.LineIsam2.redecide_lines`).
        None: not made.
    redecide_passes : int
        Re-decisions, each at the previous one's optimum.
    retest_window_s : float or None
        When an update moves the newest optimised node beyond the chi2(3) 0.99 gate of its own
        marginal before it (a loop closed), the line factors of this recent past (s) are tested
        again at the new estimate with their node's and landmark's joint marginal, and those
        beyond the association gate removed (:mod:`sonarslam.slam.backends.isam2.retest`).
        None: never.
    offline : OfflineConfig
        The estimate made after the run with hindsight (``isam2_offline.tum``); on by default,
        ``--set isam2.offline=false`` turns it off, ``--set isam2.offline.FIELD=V`` sets it.
    """

    ahrs_bias_prior_deg: float = bounded(0.0, -180.0, 180.0)
    dvl_noise: str = one_of("hold", "hold", "white")
    node_period_s: float = bounded(5.0, 0.1, 3600.0)
    min_node_gap_s: float = bounded(0.1, 0.0, 60.0)
    update_period_s: float = bounded(5.0, 0.0, 3600.0)
    estimate_gyro_scale: bool = False
    gyro_scale_sigma: float = bounded(0.2, 1e-4, 10.0)
    scan_calibration: bool = False
    robust: str | None = one_of("huber", None, "huber", "cauchy")
    robust_k: float = bounded(1.345, 1e-3, 100.0)
    relinearize_threshold: float = bounded(0.1, 1e-4, 10.0)
    relinearize_skip: int = bounded(10, 1, 1000)
    extra_iterations: int = bounded(1, 0, 100)
    candidate_gate_probability: float = bounded(0.9999, 1e-6, 1.0 - 1e-12)
    max_candidates: int = bounded(8, 1, 1000)
    pose_window_s: float = bounded(30.0, 0.0, 1e5)
    scan_robust: str | None = one_of("cauchy", None, "huber", "cauchy")
    scan_robust_k: float = bounded(1.0, 0.0, math.inf, low_open=True)
    scan_consecutive: bool = True
    revisit_radius_m: float = bounded(10.0, 0.0, math.inf)
    revisit_gate_probability: float = bounded(0.99, 0.0, 1.0, low_open=True, high_open=True)
    revisit_min_gap_s: float = bounded(60.0, 0.0, math.inf)
    revisit_candidates: int = bounded(4, 0, math.inf)
    revisits_per_scan: int = bounded(2, 0, math.inf)
    revisit_choice: str = one_of("nearest", "nearest", "spread")
    revisit_spacing_scans: int | None = bounded(None, 1, 1000)
    revisit_lag_scans: int = bounded(0, 0, 100)
    revisit_gate: str = one_of("registration", "graph", "registration")
    scan_compatibility_probability: float = bounded(0.999, 0.0, 1.0, low_open=True, high_open=True)
    batch_optimizer: str = one_of("lm", "lm", "gnc")
    redecide_stretch_m: float | None = bounded(None, 0.0, 1e5, low_open=True)
    redecide_passes: int = bounded(1, 1, 10)
    retest_window_s: float | None = bounded(None, 0.0, 1e5, low_open=True)
    offline: OfflineConfig = field(default_factory=OfflineConfig)
