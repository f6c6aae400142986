"""The loop-closure error without GPS: where the vehicle returns near a place it has been.

A *loop* is a pair of times ``(t0, t1)`` at which the vehicle was near one place, and the
relative pose ``t0Tt1`` it truly had between them:

* **stated** by the user (``sonarslam run --loop T0,T1``, seconds from the start of the
  navigation): the vehicle was at the same place at both times (a dock, a mooring, a marked
  spot): the true relative position is zero, the heading is not stated;
* **found** from an estimate and the map: every :data:`SAMPLE_S` the estimate is sampled;
  a sample within ``radius_m`` of an earlier one that lies at least ``min_gap_s`` and
  ``min_path_m`` of path before it is a candidate (the nearest such earlier sample; then the
  search moves ``min_gap_s`` on); the sonar scan (one turn of the head, motion-corrected with
  the estimate, :class:`sonarslam.features.scans.scan.ScanBuilder`) ending at each time is
  registered onto the other (:func:`sonarslam.features.scans.icp.register_from`, from the
  estimate's relative pose with a guess covariance of ``radius_m`` and 10 deg); an accepted
  registration is the map's measure of the true ``t0Tt1`` in the directions it constrains (in
  one it leaves free, along a single wall, it keeps its start: the guess, dead reckoning's, or
  one of the starts around it), independent
  of the drift between the two times (the motion correction within one turn is the odometry's,
  locally right). A registration whose position lands more than ``radius_m`` from the guess is
  rejected (*too far*): the search proposed the pair because the estimate came back within
  ``radius_m``, i.e. it trusts the estimate's relative position to that radius (the same radius
  beyond which ``run`` warns of a loop-closure error); a registration beyond it contradicts the
  premise that proposed it and is, far more likely than a drift that large, a slide along
  repeated structure (two parallel faces of a breakwater, a row of piers) from one of the
  starts ``starts_sigma`` radii away. The guess covariance is the spread of those starts, not a model
  of the estimate's drift, so a chi-squared gate on it would pass such a slide.

The loops of a run are found along dead reckoning (:func:`sonarslam.slam.run.run.loop_figures`),
not along the estimate being judged: every run of one dataset is then measured at the same loops
against the same references, and an estimate does not help build its own ruler.

The error of an estimate at a loop is the distance between its own relative position
``between(wTb(t0), wTb(t1))[:2]`` and the loop's (zero for a stated loop), and for a found loop
the heading difference too. Dead reckoning and every SLAM estimate are measured at the same
loops, so that their errors compare. No GPS enters: without GPS this is the run's ruler beside
the map's entropy; with GPS it is still computed only when loops are stated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.source import Dataset
from sonarslam.features.geometry import FloatArray, between, wrap_angle
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.scans.config import ScanConfig
from sonarslam.features.scans.icp import reference_lines, register, register_from
from sonarslam.features.scans.scan import Scan, ScanBuilder

__all__ = [
    "LOOP_CAUSES",
    "Loop",
    "LoopError",
    "SAMPLE_S",
    "stated_loops",
    "search_loops",
    "LoopSearch",
    "loop_errors",
    "ODOMETRY_CAUSES",
    "ODOMETRY_MAX_ANGLE_DEG",
    "ODOMETRY_MIN_PAIRS",
    "OdometryCheck",
    "OdometryPair",
    "odometry_pairs",
    "odometry_check",
    "lateral_gain",
    "LATERAL_GAIN_SIGMAS",
    "LATERAL_GAIN_MAX_SE",
]

#: Where a loop-closure error, or a map that does not re-find its walls, can come from (the
#: warnings of ``run`` and of the health monitor's landmark check name them).
LOOP_CAUSES = (
    "a wrong mounting or calibration (`sonarslam calibrate`), the sonar's angle sense ([sonar]"
    " angle_sense), a clock offset ([sonar] time_offset_s), the IMU's frame convention (an"
    " orientation and gyro both in NED instead of REP-103's ENU turn the vehicle the wrong"
    " way, and no check refuses them), a diverged run"
)

#: The sonar and dead reckoning disagree when the mean angle between their motions exceeds this
#: (deg) over at least :data:`ODOMETRY_MIN_PAIRS` registrations (:attr:`OdometryCheck.turned`):
#: halfway to a mounting the wrong way round (a multiple of 90 deg).
ODOMETRY_MAX_ANGLE_DEG = 45.0
ODOMETRY_MIN_PAIRS = 3
#: Where a wrong direction of motion can come from, named in the odometry check's warnings.
ODOMETRY_CAUSES = (
    "the sonar's mounting yaw ([mounting.sonar] yaw_deg: it turns every registration, hence the"
    " motion the sonar measures; `sonarslam calibrate` estimates it), the DVL's mounting yaw"
    " ([mounting.dvl] yaw_deg) or its axes' signs, or the sonar's angle sense ([sonar]"
    " angle_sense: a mirror turns the motion only where the head's zero is not along the"
    " travel)"
)

#: The lateral gain (:func:`lateral_gain`) says a mirror when it is below 0 and this many of its
#: standard errors below 1 ...
LATERAL_GAIN_SIGMAS = 4.0
#: ... with a standard error under this (over 0.5 the pairs' sideways motion is within the
#: registrations' noise: a vehicle that never crabs, whose mirror changes little).
LATERAL_GAIN_MAX_SE = 0.5
#: Added in quadrature to a registration's position sigma in :func:`lateral_gain` (m): dead
#: reckoning's own error over a pair and the scans' motion correction.
LATERAL_GAIN_FLOOR_M = 0.05

#: The estimate is searched for returns at this step (s).
SAMPLE_S = 2.0
#: A scan with fewer returns than this is not registered.
MIN_SCAN_POINTS = 10
#: A loop's two ends are at least this far apart in time (s) and along the estimate's path (m).
LOOP_MIN_GAP_S = 60.0
LOOP_MIN_PATH_M = 30.0
#: A found loop's guess covariance of the heading (deg, 1 sigma).
GUESS_YAW_SIGMA_DEG = 10.0


@dataclass(frozen=True)
class Loop:
    """Two times at one place and the true relative pose between them.

    Attributes
    ----------
    t0_s, t1_s : float
        The two times (Unix s), ``t0_s < t1_s``.
    how : str
        ``"stated"`` or ``"found"``.
    t0Tt1 : ndarray, shape (3,)
        The relative body pose ``(x_m, y_m, yaw_rad)`` of the map's registration (found), or
        ``(0, 0, nan)`` (stated: the same place, the heading not stated).
    sigma_m : float
        The reference's own accuracy as its registration states it: ``sqrt`` of the trace of
        its position covariance (m); NaN for a stated loop (the user's word) and for a
        registration that left a direction free.
    free_directions : int
        Directions of ``(x, y, yaw)`` the registration left free (0-2): there the reference
        is the guess, dead reckoning's relative pose.
    """

    t0_s: float
    t1_s: float
    how: str
    t0Tt1: FloatArray
    sigma_m: float = math.nan
    free_directions: int = 0


@dataclass(frozen=True)
class LoopError:
    """An estimate's error at one loop: ``position_m`` (m) and ``heading_deg`` (deg, NaN for a
    stated loop)."""

    loop: Loop
    position_m: float
    heading_deg: float


def stated_loops(pairs_rel_s: npt.ArrayLike, t_start_s: float) -> list[Loop]:
    """Loops the user states: ``pairs_rel_s`` (K, 2) seconds from ``t_start_s`` (the start of
    the navigation), each pair at one place."""
    pairs = np.asarray(pairs_rel_s, dtype=np.float64).reshape(-1, 2)
    return [
        Loop(t_start_s + float(a), t_start_s + float(b), "stated", np.array([0.0, 0.0, np.nan]))
        for a, b in pairs
    ]


def _scan_ending(
    dataset: Dataset, t_s: float, source: PoseSource, config: ScanConfig
) -> Scan | None:
    """The scan of the turn of the head whose last beam is the last at or before ``t_s``."""
    head = dataset.config.sonar
    builder = ScanBuilder(config, head, dataset.config.sonar_mounting, source)
    last = int(np.searchsorted(dataset.beams.t_s, t_s, side="right"))
    first = last - builder.n_beams
    if first < 0:
        return None
    scan = None
    for i in range(first, last):
        scan = builder.add(dataset.beams[i])
    return scan


@dataclass(frozen=True)
class LoopSearch:
    """What :func:`search_loops` found and why it found no more.

    Attributes
    ----------
    loops : list of Loop
        The loops found and confirmed.
    tried : int
        Returns within the radius (after ``min_gap_s`` and ``min_path_m``) whose scans were
        registered.
    path_m : float
        The estimate's path over the sonar span (m).
    radius_m, min_gap_s, min_path_m : float
        The search's radius (m), least time (s) and least path (m) between a loop's two ends.
    too_far : int
        Registrations accepted by their own tests and rejected because their position lay more
        than ``radius_m`` from the guess (module docstring).
    """

    loops: list[Loop]
    tried: int
    path_m: float
    radius_m: float
    min_gap_s: float
    min_path_m: float
    too_far: int = 0

    def why_none(self) -> str:
        """Why no loop was found, in words ("" when one was)."""
        if self.loops:
            return ""
        if self.tried:
            far = (
                f", {self.too_far} of them rejected as more than {self.radius_m:.0f} m from dead"
                " reckoning's guess (a slide along repeated structure)"
                if self.too_far
                else ""
            )
            return (
                f"{self.tried} return(s) within {self.radius_m:.0f} m registered, none accepted"
                f" (scans that do not overlap, or a single wall in view){far}"
            )
        if self.path_m < self.min_path_m:
            return (
                f"dead reckoning's whole path is {self.path_m:.1f} m, under the"
                f" {self.min_path_m:.0f} m a loop needs: a vehicle that hardly moves, or a DVL's"
                " velocities in another unit (`sonarslam info` gives its speed)"
            )
        return (
            f"dead reckoning ({self.path_m:.0f} m of path) never came back within"
            f" {self.radius_m:.0f} m of where it was {self.min_gap_s:.0f} s and"
            f" {self.min_path_m:.0f} m of path before"
        )


def search_loops(
    dataset: Dataset,
    estimate: PoseSource,
    radius_m: float,
    min_gap_s: float = LOOP_MIN_GAP_S,
    min_path_m: float = LOOP_MIN_PATH_M,
    config: ScanConfig | None = None,
) -> LoopSearch:
    """The loops found along ``estimate`` and confirmed by registering their scans (module
    docstring; only accepted registrations are loops), with what the search tried
    (:class:`LoopSearch`)."""
    span = dataset.sonar_span_s
    nothing = LoopSearch([], 0, 0.0, radius_m, min_gap_s, min_path_m)
    if span is None:
        return nothing
    config = config or ScanConfig()
    t = np.arange(span[0] + SAMPLE_S, span[1], SAMPLE_S)
    if t.size < 2:
        return nothing
    p = np.asarray(estimate.poses(t))
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p[:, :2], axis=0).T))])
    loops: list[Loop] = []
    tried = too_far = 0
    j, resume_s = 0, -math.inf
    while j < t.size:
        if t[j] < resume_s:
            j += 1
            continue
        earlier = np.flatnonzero((t[j] - t >= min_gap_s) & (path[j] - path >= min_path_m))
        if earlier.size:
            d = np.hypot(*(p[earlier, :2] - p[j, :2]).T)
            k = int(np.argmin(d))
            if d[k] <= radius_m:
                tried += 1
                loop, far = _confirm(
                    dataset, estimate, float(t[earlier[k]]), float(t[j]), radius_m, config
                )
                too_far += far
                if loop is not None:
                    loops.append(loop)
                    resume_s = t[j] + min_gap_s
        j += 1
    return LoopSearch(loops, tried, float(path[-1]), radius_m, min_gap_s, min_path_m, too_far)


def _confirm(
    dataset: Dataset,
    estimate: PoseSource,
    t0_s: float,
    t1_s: float,
    radius_m: float,
    config: ScanConfig,
) -> tuple[Loop | None, bool]:
    """The loop the scans ending at ``t0_s`` and ``t1_s`` confirm, or None; and whether an
    accepted registration was rejected as more than ``radius_m`` from the guess (module
    docstring)."""
    a = _scan_ending(dataset, t0_s, estimate, config)
    b = _scan_ending(dataset, t1_s, estimate, config)
    if a is None or b is None or min(len(a.points_b), len(b.points_b)) < MIN_SCAN_POINTS:
        return None, False
    guess = between(a.wTb_ref, b.wTb_ref)
    cov = np.diag([radius_m**2, radius_m**2, math.radians(GUESS_YAW_SIGMA_DEG) ** 2])
    reg = register_from(reference_lines(a.points_b, config), b.points_b, guess, cov, config)
    if not reg.accepted:
        return None, False
    z = np.asarray(reg.z, dtype=np.float64)
    if math.hypot(*(z[:2] - guess[:2])) > radius_m:
        return None, True
    # a direction the scans leave free (along a single wall) keeps its start, the guess or one
    # near it: such a reference states no accuracy of its own
    free = 3 - int(reg.constrained.shape[1])
    cov = np.asarray(reg.cov, dtype=np.float64)
    sigma_m = math.sqrt(max(float(np.trace(cov[:2, :2])), 0.0)) if free == 0 else math.nan
    return Loop(a.t_ref_s, b.t_ref_s, "found", z, sigma_m, free), False


def loop_errors(estimate: PoseSource, loops: list[Loop]) -> list[LoopError]:
    """``estimate``'s error at each loop (module docstring)."""
    out = []
    for loop in loops:
        poses = np.asarray(estimate.poses(np.array([loop.t0_s, loop.t1_s])))
        rel = between(poses[0], poses[1])
        position = float(np.hypot(*(rel[:2] - loop.t0Tt1[:2])))
        heading = (
            math.degrees(abs(float(wrap_angle(rel[2] - loop.t0Tt1[2]))))
            if np.isfinite(loop.t0Tt1[2])
            else math.nan
        )
        out.append(LoopError(loop, position, heading))
    return out


@dataclass(frozen=True)
class OdometryCheck:
    """How the sonar sees the vehicle move between two nearby scans, against dead reckoning.

    Attributes
    ----------
    pairs : int
        Pairs of scans registered.
    accepted : int
        Registrations accepted with every direction constrained.
    heading_deg : float
        The circular mean over the accepted pairs of the angle from dead reckoning's
        translation between the two scans to the registration's (deg, counter-clockwise in the
        first scan's body frame); NaN without an accepted pair.
    scale : float
        The median of the registration's translation length over dead reckoning's (the sonar's
        range scale over the DVL's, 1 when both are right); NaN without an accepted pair.
    heading_se_deg : float
        The standard error of :attr:`heading_deg`: the angles' circular standard deviation
        over the square root of the accepted pairs (deg); NaN below two.
    scale_se : float
        The standard error of :attr:`scale`: ``sqrt(pi / 2)`` (the median's against the mean's
        for Gaussian samples) times the ratios' robust standard deviation (``1.4826`` times
        their median absolute deviation: one pair's wrong registration does not inflate it)
        over the square root of the accepted pairs; NaN below two.
    starts : int
        Starts tried (each a first scan; a start gives a pair or is skipped).
    skipped_still : int
        Starts skipped because dead reckoning moved less than ``step_m`` within five turns of
        the head after them, or less than half of it between the two scans.
    skipped_sparse : int
        Starts skipped because a scan held fewer than :data:`MIN_SCAN_POINTS` returns.
    step_m : float
        The distance along dead reckoning between the two scans of a pair (m).
    lateral_gain : float
        What the sonar says the body's lateral velocity is to be multiplied by
        (:func:`lateral_gain`): 1 when the DVL's lateral axis is right, -1 when it is mirrored;
        NaN when not fitted (no mirrored dead reckoning given, or fewer than
        :data:`ODOMETRY_MIN_PAIRS` registrations).
    lateral_gain_se : float
        Its standard error; large when the vehicle hardly moves sideways (nothing to tell a
        mirror by).
    """

    pairs: int
    accepted: int
    heading_deg: float
    scale: float
    heading_se_deg: float = math.nan
    scale_se: float = math.nan
    starts: int = 0
    skipped_still: int = 0
    skipped_sparse: int = 0
    step_m: float = math.nan
    lateral_gain: float = math.nan
    lateral_gain_se: float = math.nan

    def why_none(self) -> str:
        """Why no registration was accepted, in words ("" when one was)."""
        if self.accepted:
            return ""
        parts = []
        if self.skipped_still:
            parts.append(
                f"at {self.skipped_still} of {self.starts} starts dead reckoning moved less than"
                f" {self.step_m:g} m within five turns of the head: a vehicle that hardly"
                " moves, or a DVL's velocities in another unit (`sonarslam info` gives its"
                " speed)"
            )
        if self.skipped_sparse:
            parts.append(
                f"at {self.skipped_sparse} a scan held fewer than {MIN_SCAN_POINTS} returns:"
                " is the sonar's range or the extractor's intensity_threshold right?"
            )
        if self.pairs:
            parts.append(
                f"{self.pairs} pair(s) registered, none accepted with every direction"
                " constrained (a single wall in view, or scans that do not overlap)"
            )
        if not parts:
            parts.append("the sonar span is shorter than three turns of the head")
        return "; ".join(parts)

    @property
    def mirrored(self) -> bool:
        """True when the sonar says the body's lateral velocity has the wrong sign: the lateral
        gain below 0 and more than :data:`LATERAL_GAIN_SIGMAS` standard errors from 1, with a
        standard error under :data:`LATERAL_GAIN_MAX_SE` (a vehicle that moves sideways enough
        to tell), over at least :data:`ODOMETRY_MIN_PAIRS` registrations."""
        g, se = self.lateral_gain, self.lateral_gain_se
        return (
            self.accepted >= ODOMETRY_MIN_PAIRS
            and math.isfinite(g)
            and se < LATERAL_GAIN_MAX_SE
            and g < 0.0
            and 1.0 - g > LATERAL_GAIN_SIGMAS * se
        )

    @property
    def turned(self) -> bool:
        """True when the sonar sees the vehicle move more than :data:`ODOMETRY_MAX_ANGLE_DEG`
        away from dead reckoning over at least :data:`ODOMETRY_MIN_PAIRS` registrations: a
        sensor mounted the wrong way round (:data:`ODOMETRY_CAUSES`)."""
        return (
            self.accepted >= ODOMETRY_MIN_PAIRS
            and math.isfinite(self.heading_deg)
            and abs(self.heading_deg) > ODOMETRY_MAX_ANGLE_DEG
        )


@dataclass(frozen=True)
class OdometryPair:
    """One pair of scans of :func:`odometry_pairs`: dead reckoning's relative pose and the
    sonar's.

    Attributes
    ----------
    t0_s, t1_s : float
        The two scans' reference times (s, the navigation clock).
    dead_reckoning : FloatArray
        (3,) dead reckoning's relative pose ``b0Tb1`` ``(x_m, y_m, yaw_rad)`` (first scan's
        body frame).
    sonar : FloatArray or None
        (3,) the registration's relative pose in the same frame (the scans put in the body
        frame through the configured mounting), None when no start gave an accepted
        registration that constrains every direction.
    cov : FloatArray or None
        (3, 3) the registration's covariance (m², rad²), None with ``sonar``.
    """

    t0_s: float
    t1_s: float
    dead_reckoning: FloatArray
    sonar: FloatArray | None
    cov: FloatArray | None

    @property
    def angle_rad(self) -> float:
        """The angle from dead reckoning's translation to the sonar's (rad, counter-clockwise in
        the first scan's body frame, in ``[-pi, pi)``); NaN without a registration."""
        if self.sonar is None:
            return math.nan
        return float(
            wrap_angle(
                math.atan2(self.sonar[1], self.sonar[0])
                - math.atan2(self.dead_reckoning[1], self.dead_reckoning[0])
            )
        )

    @property
    def angle_sd_rad(self) -> float:
        """1-sigma of :attr:`angle_rad` from the registration's covariance across its
        translation (rad); NaN without a registration."""
        if self.sonar is None or self.cov is None:
            return math.nan
        length = math.hypot(self.sonar[0], self.sonar[1])
        across = np.array([-self.sonar[1], self.sonar[0]]) / length
        return math.sqrt(max(float(across @ self.cov[:2, :2] @ across), 0.0)) / length

    @property
    def scale(self) -> float:
        """The sonar's translation length over dead reckoning's; NaN without a registration."""
        if self.sonar is None:
            return math.nan
        return math.hypot(self.sonar[0], self.sonar[1]) / math.hypot(
            self.dead_reckoning[0], self.dead_reckoning[1]
        )


def odometry_pairs(
    dataset: Dataset,
    dead_reckoning: PoseSource,
    step_m: float,
    n_pairs: int = 12,
    config: ScanConfig | None = None,
) -> list[OdometryPair]:
    """Register pairs of scans ``step_m`` apart along dead reckoning's path (GPS-free): every
    pair registered, with its registration where one was accepted.

    ``n_pairs`` first scans spread evenly over the sonar span; each is paired with the scan that
    ends where dead reckoning has moved ``step_m`` further, at least one turn of the head later
    (the two share no beam) and at most five; a pair whose dead-reckoning translation is under
    ``step_m / 2`` is skipped. The second scan is registered onto the first from dead
    reckoning's relative pose and from the same with its translation turned by 90, 180 and 270
    deg (:func:`sonarslam.features.scans.icp.register`, one start each), and the accepted
    result that constrains every direction with the most weight kept: the sonar, not the guess,
    then says which way the vehicle went. The scans are motion-corrected with dead reckoning
    within their own turn only, and put in the body frame through the configured sonar
    mounting: a mounting yaw off by ``e`` turns the sonar's translation by ``-e``, a DVL whose
    velocity is turned by ``-delta`` (a misalignment, or a lateral bias ``delta * speed``) turns
    dead reckoning's by ``-delta``, so :attr:`OdometryPair.angle_rad` measures ``delta - e``;
    a constant heading error cancels in both relative poses. A mirrored sonar (``[sonar]
    angle_sense`` flipped) mirrors each scan about the head's zero direction: when that zero
    lies along the direction of travel the mirrored motion is the same, and no pair sees it.
    """
    return _odometry_pairs(dataset, dead_reckoning, step_m, n_pairs, config)[0]


def _odometry_pairs(
    dataset: Dataset,
    dead_reckoning: PoseSource,
    step_m: float,
    n_pairs: int,
    config: ScanConfig | None,
) -> tuple[list[OdometryPair], dict[str, int]]:
    """:func:`odometry_pairs` and the count of starts tried and skipped, by why: ``starts``,
    ``still`` (dead reckoning moved under ``step_m`` within five turns, or under half of it
    between the scans), ``sparse`` (a scan of fewer than :data:`MIN_SCAN_POINTS` returns)."""
    config = config or ScanConfig()
    span = dataset.sonar_span_s
    t_beams = dataset.beams.t_s
    counts = {"starts": 0, "still": 0, "sparse": 0}
    if span is None or t_beams.size < 2:
        return [], counts
    n_turn = ScanBuilder(
        config, dataset.config.sonar, dataset.config.sonar_mounting, dead_reckoning
    ).n_beams
    turn_s = float(np.median(np.diff(t_beams))) * n_turn
    t = np.arange(span[0], span[1], min(1.0, turn_s / 4.0))
    if t.size < 2:
        return [], counts
    p = np.asarray(dead_reckoning.poses(t))
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p[:, :2], axis=0).T))])
    out: list[OdometryPair] = []
    for t0 in np.linspace(span[0] + turn_s, span[1] - 2.0 * turn_s, n_pairs):
        counts["starts"] += 1
        i0 = min(int(np.searchsorted(t, t0)), t.size - 1)
        far = np.flatnonzero((path >= path[i0] + step_m) & (t >= t0 + turn_s))
        if far.size == 0 or t[far[0]] > t0 + 5.0 * turn_s:
            counts["still"] += 1  # the vehicle hardly moves here
            continue
        a = _scan_ending(dataset, float(t0), dead_reckoning, config)
        b = _scan_ending(dataset, float(t[far[0]]), dead_reckoning, config)
        if (
            a is None
            or b is None
            or len(a.points_b) < MIN_SCAN_POINTS
            or len(b.points_b) < MIN_SCAN_POINTS
        ):
            counts["sparse"] += 1
            continue
        guess = between(a.wTb_ref, b.wTb_ref)
        if math.hypot(guess[0], guess[1]) < 0.5 * step_m:
            counts["still"] += 1
            continue
        ref = reference_lines(a.points_b, config)
        best = None
        for turn in (0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi):
            c, s = math.cos(turn), math.sin(turn)
            start = np.array([c * guess[0] - s * guess[1], s * guess[0] + c * guess[1], guess[2]])
            reg = register(ref, b.points_b, start, config)
            if reg.accepted and reg.constrained.shape[1] == 3:
                if best is None or reg.weight > best.weight:
                    best = reg
        sonar = None if best is None else np.asarray(best.z, dtype=np.float64)
        cov = None if best is None else np.asarray(best.cov, dtype=np.float64)
        out.append(OdometryPair(a.t_ref_s, b.t_ref_s, np.asarray(guess), sonar, cov))
    return out, counts


def lateral_gain(pairs: list[OdometryPair], mirrored: PoseSource) -> tuple[float, float]:
    """The gain on the body's lateral velocity that makes dead reckoning move as the sonar sees
    it, and its standard error (GPS-free).

    ``mirrored`` is dead reckoning with the body's lateral velocity negated. Between a pair's
    two scans dead reckoning's translation is ``A + B`` and the mirrored one's ``A - B``: ``A``
    the integral of the forward velocity, ``B`` of the lateral one, both turned by the heading.
    The sonar's translation is fitted as ``s A + g B`` over the registered pairs, weighted by
    each registration's position covariance (plus :data:`LATERAL_GAIN_FLOOR_M`), a pair whose
    residual is beyond the 99.9 % chi-square bound of two dimensions dropped once; ``g`` is 1
    when the lateral axis is right and -1 when it is mirrored (``s`` is the range scale's
    ratio, which :attr:`OdometryCheck.scale` gives robustly). The standard error is the fit's,
    inflated by the residuals' chi-square per degree of freedom when above 1. NaN, inf with
    fewer than :data:`ODOMETRY_MIN_PAIRS` registrations.
    """
    done = [p for p in pairs if p.sonar is not None and p.cov is not None]
    if len(done) < ODOMETRY_MIN_PAIRS:
        return math.nan, math.inf
    rows_a, rows_b, z, w = [], [], [], []
    for p in done:
        assert p.sonar is not None and p.cov is not None  # for the type checker: done's
        m = np.asarray(mirrored.poses(np.array([p.t0_s, p.t1_s])))
        t_m = between(m[0], m[1])[:2]
        t_d = np.asarray(p.dead_reckoning[:2])
        rows_a.append(0.5 * (t_d + t_m))
        rows_b.append(0.5 * (t_d - t_m))
        z.append(np.asarray(p.sonar[:2]))
        cov = np.asarray(p.cov, dtype=np.float64)[:2, :2] + LATERAL_GAIN_FLOOR_M**2 * np.eye(2)
        w.append(np.linalg.inv(cov))
    a, b, zz, ww = map(np.asarray, (rows_a, rows_b, z, w))
    design = np.stack([a, b], axis=2)  # (n, 2, 2): columns s, g
    keep = np.ones(len(done), dtype=bool)
    for _ in range(2):
        info = np.einsum("nji,njk,nkl->il", design[keep], ww[keep], design[keep])
        rhs = np.einsum("nji,njk,nk->i", design[keep], ww[keep], zz[keep])
        if np.linalg.cond(info) > 1e12:
            return math.nan, math.inf
        x = np.linalg.solve(info, rhs)
        r = zz - np.einsum("nij,j->ni", design, x)
        chi2 = np.einsum("ni,nij,nj->n", r, ww, r)
        drop = chi2 > 13.8  # chi2.ppf(0.999, 2)
        if drop.sum() == 0 or keep.sum() - drop.sum() < ODOMETRY_MIN_PAIRS:
            break
        keep = ~drop
    dof = max(2 * int(keep.sum()) - 2, 1)
    inflate = max(float(chi2[keep].sum()) / dof, 1.0)
    se = math.sqrt(float(np.linalg.inv(info)[1, 1]) * inflate)
    return float(x[1]), se


def odometry_check(
    dataset: Dataset,
    dead_reckoning: PoseSource,
    step_m: float,
    n_pairs: int = 12,
    config: ScanConfig | None = None,
    mirrored: PoseSource | None = None,
) -> OdometryCheck:
    """Register pairs of scans ``step_m`` apart along dead reckoning's path and compare the
    sonar's relative pose with dead reckoning's (GPS-free): :func:`odometry_pairs` summed up.

    A DVL mounted the wrong way round, or a sonar mounted at another yaw than ``[mounting.sonar]
    yaw_deg`` says, turns :attr:`OdometryCheck.heading_deg` from 0 by that angle (a mirrored
    sonar need not: :func:`odometry_pairs`); the sonar's range scale against the DVL's moves
    :attr:`OdometryCheck.scale` from 1. The standard errors are the pairs' spread over the
    square root of their number (the scale's from their median absolute deviation). With
    ``mirrored`` (dead reckoning with the body's lateral velocity negated) the lateral gain is
    fitted too (:func:`lateral_gain`): a DVL lateral axis of the wrong sign.
    """
    pairs, counts = _odometry_pairs(dataset, dead_reckoning, step_m, n_pairs, config)
    tried = {
        "starts": counts["starts"],
        "skipped_still": counts["still"],
        "skipped_sparse": counts["sparse"],
    }
    done = [p for p in pairs if p.sonar is not None]
    if not done:
        return OdometryCheck(len(pairs), 0, math.nan, math.nan, step_m=step_m, **tried)
    angles = [p.angle_rad for p in done]
    mean = math.atan2(float(np.mean(np.sin(angles))), float(np.mean(np.cos(angles))))
    accepted = len(done)
    ratios = [p.scale for p in done]
    heading_se = scale_se = math.nan
    if accepted >= 2:
        spread = wrap_angle(np.asarray(angles) - mean)
        heading_se = math.degrees(float(np.std(spread, ddof=1)) / math.sqrt(accepted))
        mad = float(np.median(np.abs(np.asarray(ratios) - np.median(ratios))))
        scale_se = math.sqrt(math.pi / 2.0) * 1.4826 * mad / math.sqrt(accepted)
    gain, gain_se = lateral_gain(pairs, mirrored) if mirrored is not None else (math.nan, math.nan)
    return OdometryCheck(
        len(pairs),
        accepted,
        math.degrees(mean),
        float(np.median(ratios)),
        heading_se,
        scale_se,
        step_m=step_m,
        lateral_gain=gain,
        lateral_gain_se=gain_se,
        **tried,
    )
