"""GPS-free calibrations: the sonar's mounting yaw by map sharpness, the AHRS mounting yaw from the
DVL's own compass, the AHRS heading's deviation from the sonar lines of closed loops.

The sonar's yaw in the body frame is the one that makes the projected scans sharpest: the sum,
over time windows short enough for dead reckoning to drift little, of the Shannon entropy of the
2D histogram of the projected bins. The same search with GPS poses is a diagnostic only; the
default is dead reckoning, so the ground truth is not used to calibrate.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from sonarslam.datasets.config import MAX_TIME_OFFSET_S
from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import Dataset
from sonarslam.features.geometry import FloatArray, compose, wrap_angle
from sonarslam.features.line import LineFeature
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.projection import beam_points
from sonarslam.slam.backends.registry import backend_spec
from sonarslam.slam.eval.health import HealthConfig, travel_judgement
from sonarslam.slam.eval.sharpness import map_entropy, map_entropy_variance
from sonarslam.slam.model.motion import body_yaw
from sonarslam.slam.run.closed_loop import ClosedLoopResult, run_closed_loop
from sonarslam.slam.run.presets import map_min_intensity, run_config
from sonarslam.slam.run.sources import dvl_body_velocities

__all__ = [
    "YawSearch",
    "map_entropy",
    "scan_entropy",
    "calibrate_sonar_yaw",
    "MAX_YAW_CHANGE_DEG",
    "yaw_change_doubt",
    "ClockSearch",
    "calibrate_time_offset",
    "sonar_clock_doubt",
    "CLOCK_DOUBT_S",
    "CompassFit",
    "calibrate_ahrs_yaw",
    "heading_deviation_from_lines",
    "ekf_closed_loop",
    "calibrate_ahrs_deviation",
]


#: A sonar yaw is taken only when the objective's minimum lies this many noise units (robust
#: spread of the coarse grid's entropies) below their median: a flat objective has no minimum
#: to trust (:attr:`YawSearch.decisive`).
MIN_YAW_DEPTH = 6.0
#: ... and this many noise units below the lowest entropy outside its own basin
#: (:data:`YAW_BASIN_DEG` either side): two basins of about equal depth are an ambiguity.
MIN_YAW_MARGIN = 3.0
#: Half width (deg) of the best yaw's basin, left out when the second-best basin is looked for.
YAW_BASIN_DEG = 30.0


@dataclass(frozen=True)
class YawSearch:
    """Result of :func:`calibrate_sonar_yaw`.

    Attributes
    ----------
    best_yaw_rad : float
        The yaw of least entropy (rad).
    yaw_grid_rad : ndarray, shape (N,)
        The yaws searched, sorted (rad).
    entropy : ndarray, shape (N,)
        The summed windowed entropy at each (nats).
    noise : float
        The objective's noise unit (nats): 1.4826 x the median absolute deviation of the coarse
        grid's entropies from their median.
    depth : float
        Median minus least coarse entropy, in noise units.
    second_yaw_rad : float
        The least-entropy yaw more than :data:`YAW_BASIN_DEG` from the best (rad).
    margin : float
        Its entropy minus the best's, in noise units.
    """

    best_yaw_rad: float
    yaw_grid_rad: FloatArray
    entropy: FloatArray
    noise: float
    depth: float
    second_yaw_rad: float
    margin: float

    @property
    def decisive(self) -> bool:
        """True when the minimum stands out: depth >= :data:`MIN_YAW_DEPTH` and margin >=
        :data:`MIN_YAW_MARGIN` (a flat or two-basin objective gives no yaw to trust)."""
        return self.depth >= MIN_YAW_DEPTH and self.margin >= MIN_YAW_MARGIN

    def verdict(self) -> str:
        """The contrast in words: ``depth ... and margin ... noise units (needs ...)``."""
        return (
            f"minimum {self.depth:.1f} noise units below the median (needs {MIN_YAW_DEPTH:g}),"
            f" {self.margin:.1f} below the second basin at"
            f" {np.degrees(self.second_yaw_rad):.0f} deg (needs {MIN_YAW_MARGIN:g})"
        )


#: A sonar calibration needs this many full turns of the head inside the navigation span: the
#: map-sharpness search over fewer has almost no overlapping views of a wall to sharpen
#: (docs/design-decisions.md).
MIN_CALIBRATION_TURNS = 10


def require_turns(dataset: Dataset, n_beams: int, what: str) -> None:
    """A :class:`sonarslam.datasets.errors.DataError` when ``n_beams`` are fewer than
    :data:`MIN_CALIBRATION_TURNS` turns of the head: too few to calibrate ``what`` by."""
    per_turn = int(round(2.0 * np.pi / dataset.config.sonar.step_rad))
    need = MIN_CALIBRATION_TURNS * per_turn
    if n_beams < need:
        t0, t1 = dataset.nav_span_s
        raise DataError(
            dataset.root,
            None,
            f"{n_beams} sonar beams inside the navigation span ({t1 - t0:.1f} s) are too few to"
            f" calibrate {what}: it needs {MIN_CALIBRATION_TURNS} turns of the head ({need}"
            " beams)",
        )


def _windowed_points(
    dataset: Dataset, pose_source: PoseSource, window_s: float, shift_margin_s: float = 0.0
) -> Callable[[float, float], list[FloatArray]]:
    """``(sonar yaw (rad), clock shift (s)) -> world points (M, 2) per window``: the dataset's
    echoes (the bins a map draws, :func:`sonarslam.slam.run.presets.map_min_intensity`: raw
    beams' background noise fills every cell whatever the yaw) projected with ``pose_source``
    at their beams' times plus the shift (the mounting's x, y kept), split into windows of
    ``window_s`` by the beams' own times (a shift moves no echo to another window). The beams
    within ``shift_margin_s`` of the navigation span's ends are left out, so that a shift up to
    that margin finds poses for every beam."""
    beams = dataset.nav_beams()
    if shift_margin_s > 0.0:
        t0, t1 = dataset.nav_span_s
        beams = beams.between(t0 + shift_margin_s, t1 - shift_margin_s)
    bi, r, bearing = beam_points(beams, dataset.config.sonar, map_min_intensity(beams))
    t_beam = np.array([b.t for b in beams])
    t = t_beam[bi]
    mount0 = replace(dataset.config.sonar_mounting, yaw_rad=0.0).as_pose()
    wTs0 = compose(pose_source.poses(t_beam), mount0)[bi]
    window = np.floor((t - t[0]) / window_s).astype(np.int64)
    splits = np.flatnonzero(np.diff(window)) + 1

    def points(yaw: float, shift_s: float = 0.0) -> list[FloatArray]:
        wTs = wTs0 if shift_s == 0.0 else compose(pose_source.poses(t_beam + shift_s), mount0)[bi]
        ang = wTs[:, 2] + yaw + bearing
        pts = np.column_stack([wTs[:, 0] + r * np.cos(ang), wTs[:, 1] + r * np.sin(ang)])
        return np.split(pts, splits)

    return points


def _windowed_entropy(
    dataset: Dataset, pose_source: PoseSource, window_s: float, cell_m: float
) -> Callable[[float], float]:
    """``sonar yaw (rad) -> summed entropy (nats)`` of :func:`_windowed_points` over
    ``window_s`` windows."""
    points = _windowed_points(dataset, pose_source, window_s)

    def cost(yaw: float) -> float:
        return sum(map_entropy(chunk, cell_m) for chunk in points(yaw, 0.0))

    return cost


def scan_entropy(
    dataset: Dataset, pose_source: PoseSource, window_s: float = 60.0, cell_m: float = 0.5
) -> float:
    """Summed windowed map entropy (nats) with the configured sonar mounting: the sharpness
    criterion of the sonar clock offset and the keyframes' scan direction (lower is sharper;
    compare values of one dataset with one pose source and one window only)."""
    return _windowed_entropy(dataset, pose_source, window_s, cell_m)(
        dataset.config.sonar_mounting.yaw_rad
    )


def calibrate_sonar_yaw(
    dataset: Dataset,
    pose_source: PoseSource,
    window_s: float = 120.0,
    cell_m: float = 0.5,
    coarse_step_deg: float = 2.0,
    fine_step_deg: float = 0.25,
) -> YawSearch:
    """Search the sonar mounting yaw that minimises the summed windowed map entropy.

    Parameters
    ----------
    dataset : Dataset
        Beams, head and the current mounting (its x, y are kept).
    pose_source : PoseSource
        Vehicle poses (dead reckoning for a GPS-free calibration).
    window_s : float
        Length of each time window (s).
    cell_m : float
        Histogram cell (m).
    coarse_step_deg, fine_step_deg : float
        Grid over 360 deg, then refined +-2 coarse steps around the best.

    Returns
    -------
    YawSearch
        The best yaw and the objective's contrast: take the yaw only when
        :attr:`YawSearch.decisive` (a flat objective's minimum is noise).
    """
    require_turns(dataset, len(dataset.nav_beams()), "the sonar yaw")
    cost = _windowed_entropy(dataset, pose_source, window_s, cell_m)
    coarse = np.deg2rad(np.arange(-180.0, 180.0, coarse_step_deg))
    costs = np.array([cost(y) for y in coarse])
    best = coarse[int(np.argmin(costs))]
    span = np.deg2rad(2 * coarse_step_deg)
    fine = best + np.arange(-span, span + 1e-9, np.deg2rad(fine_step_deg))
    fine_costs = np.array([cost(y) for y in fine])
    grid = np.concatenate([coarse, fine])
    ent = np.concatenate([costs, fine_costs])
    order = np.argsort(grid)
    median = float(np.median(costs))
    noise = max(1.4826 * float(np.median(np.abs(costs - median))), 1e-12)
    away = np.abs(wrap_angle(coarse - best)) > np.deg2rad(YAW_BASIN_DEG)
    second = int(np.argmin(np.where(away, costs, np.inf)))
    return YawSearch(
        float(wrap_angle(fine[int(np.argmin(fine_costs))])),
        grid[order],
        ent[order],
        noise,
        (median - float(costs.min())) / noise,
        float(coarse[second]),
        (float(costs[second]) - float(costs.min())) / noise,
    )


#: The largest change (deg) from a configured sonar yaw that ``sonarslam calibrate`` writes
#: without ``--accept-large-yaw`` (:func:`yaw_change_doubt`): halfway to a mounting the wrong
#: way round (a multiple of 90 deg), the same limit as the run's odometry check's. The search
#: finds the sonar's yaw relative to dead reckoning's motion, so a DVL mounting given the wrong
#: way round moves its minimum by as much.
MAX_YAW_CHANGE_DEG = 45.0


def yaw_change_doubt(dataset: Dataset, yaw_rad: float) -> str | None:
    """Why a sonar yaw found by map sharpness may be another sensor's mounting, in words, or
    None when it is within :data:`MAX_YAW_CHANGE_DEG` of the configured one.

    Map sharpness over dead-reckoning poses measures the sonar's yaw relative to dead
    reckoning's motion: a DVL mounting off by ``d`` turns that motion by ``d`` and moves the
    sharpest map's sonar yaw by ``d`` too, and an AHRS mounting off turns the whole run about
    its start, which no map sees. The words name those mountings, the ones nobody gave
    (:attr:`sonarslam.sonar.beam.Mounting.assumed`), and which way dead reckoning moves the
    vehicle in its own frame (:func:`sonarslam.slam.eval.health.travel_direction`: a vehicle
    travels bow first).
    """
    cfg = dataset.config
    current = cfg.sonar_mounting.yaw_rad
    change = math.degrees(float(wrap_angle(yaw_rad - current)))
    if abs(change) <= MAX_YAW_CHANGE_DEG:
        return None
    given = (
        "the identity assumed for the sonar (nothing gave its mounting)"
        if cfg.sonar_mounting.assumed
        else f"the configured {math.degrees(current):.2f} deg ({cfg.sonar_mounting.source})"
    )
    angle, share, judged, off_bow = travel_judgement(dvl_body_velocities(dataset), HealthConfig())
    bow_first = judged and not off_bow
    if cfg.sonar_mounting.assumed:
        verdict = "it is the sonar's yaw only if the DVL's mounting is right"
    elif bow_first:
        verdict = (
            "dead reckoning moves the vehicle bow first, so the DVL's mounting looks right and"
            " the sonar's configured yaw is the likely one at fault"
        )
    else:
        verdict = "a rotation this large is more likely one of those than the sonar's"
    out = (
        f"the sonar yaw found, {math.degrees(yaw_rad):.2f} deg, is {change:+.0f} deg from {given}:"
        " map sharpness over dead-reckoning poses measures the sonar's yaw relative to dead"
        " reckoning's motion, so a DVL mounting off by an angle ([mounting.dvl] yaw_deg, or its"
        " axes' signs) moves it by as much, and an AHRS mounting off ([mounting.ahrs] yaw_deg)"
        f" turns the whole run about its start, which no map sees; {verdict}"
    )
    assumed = [m for m in ("dvl", "ahrs") if getattr(cfg, f"{m}_mounting").assumed]
    if assumed:
        out += (
            f"; the {' and '.join(m.upper() for m in assumed)} mounting(s) are assumed (the"
            f" identity, never given): {math.degrees(yaw_rad):.2f} deg may be the DVL's"
            " mounting, not the sonar's"
        )
    if math.isfinite(angle):
        out += (
            f"; dead reckoning moves the vehicle {math.degrees(angle):+.0f} deg off its bow"
            f" ({share:.2f} of its travel one way in its own frame)"
        )
        if off_bow:
            out += ": a vehicle travels bow first, so the DVL's mounting is likely turned by that"
    return out


#: A sonar clock offset is taken only when the objective's coarse minimum lies this many noise
#: units (the summed entropy's sampling spread at the minimum,
#: :func:`sonarslam.slam.eval.sharpness.map_entropy_variance`) below the coarse grid's median:
#: a flat objective has no minimum to trust (:attr:`ClockSearch.decisive`; the measured
#: contrasts are in docs/research/calibration.md).
MIN_CLOCK_DEPTH = 2.5
#: ... and the least entropy more than :data:`CLOCK_BASIN_S` from it this many noise units above.
MIN_CLOCK_MARGIN = 2.0
#: Half width (s) of the best offset's basin, left out when the margin is looked for.
CLOCK_BASIN_S = 1.0


@dataclass(frozen=True)
class ClockSearch:
    """Result of :func:`calibrate_time_offset` (offsets in s: ``[sonar] time_offset_s``, added
    to the sonar's log times to put them on the navigation clock).

    Attributes
    ----------
    best_offset_s : float
        The offset of least entropy: the vertex of a parabola fitted to the fine grid's
        entropies (the fine grid's own least when the fit is not convex or its vertex lies
        outside the fine grid).
    configured_offset_s : float
        The dataset's offset the search is centred on.
    offset_grid_s : ndarray, shape (N,)
        The offsets searched, sorted.
    entropy : ndarray, shape (N,)
        The summed windowed entropy at each (nats).
    noise : float
        The objective's noise unit (nats): the sampling standard deviation of the summed
        entropy at the coarse minimum (the windows' variances summed).
    depth : float
        Median minus least coarse entropy, in noise units.
    second_offset_s : float
        The least-entropy coarse offset more than :data:`CLOCK_BASIN_S` from the best.
    margin : float
        Its entropy minus the least coarse entropy, in noise units.
    at_edge : bool
        The least coarse entropy is at an end of the searched range: the objective may go on
        falling beyond it, so the offset may lie outside the range.
    """

    best_offset_s: float
    configured_offset_s: float
    offset_grid_s: FloatArray
    entropy: FloatArray
    noise: float
    depth: float
    second_offset_s: float
    margin: float
    at_edge: bool = False

    @property
    def decisive(self) -> bool:
        """True when the minimum stands out and is one: depth >= :data:`MIN_CLOCK_DEPTH`,
        margin >= :data:`MIN_CLOCK_MARGIN` and not :attr:`at_edge`."""
        return (
            self.depth >= MIN_CLOCK_DEPTH and self.margin >= MIN_CLOCK_MARGIN and not self.at_edge
        )

    def verdict(self) -> str:
        """The contrast in words: ``depth ... and margin ... noise units (needs ...)``."""
        return (
            f"minimum {self.depth:.1f} noise units below the median (needs {MIN_CLOCK_DEPTH:g}),"
            f" {self.margin:.1f} below the best offset more than {CLOCK_BASIN_S:g} s away, at"
            f" {self.second_offset_s:+.2f} s (needs {MIN_CLOCK_MARGIN:g})"
        )


def calibrate_time_offset(
    dataset: Dataset,
    pose_source: PoseSource,
    window_s: float = 60.0,
    cell_m: float = 0.5,
    half_range_s: float = 3.0,
    coarse_step_s: float = 0.25,
    fine_step_s: float | None = None,
) -> ClockSearch:
    """Search the sonar clock offset that minimises the summed windowed map entropy.

    A wrong offset places each beam with the pose of another time: the walls smear by the
    vehicle's turn and change of velocity over the offset (a steady translation moves every
    echo alike and is not seen). The echoes are projected with ``pose_source`` at their beams'
    times shifted by each offset less the configured one (:func:`_windowed_points`, the same
    objective as :func:`calibrate_sonar_yaw` with the configured mounting yaw).

    Parameters
    ----------
    dataset : Dataset
        Beams on the navigation clock with the configured ``[sonar] time_offset_s``.
    pose_source : PoseSource
        Vehicle poses (dead reckoning for a GPS-free calibration).
    window_s : float
        Length of each time window (s).
    cell_m : float
        Histogram cell (m).
    half_range_s : float
        The coarse grid spans the configured offset +- this (s), clipped to
        +- :data:`sonarslam.datasets.config.MAX_TIME_OFFSET_S`.
    coarse_step_s : float
        Step of the coarse grid (s).
    fine_step_s : float, optional
        Step of the fine grid over +- 2 coarse steps around the coarse best (s); default half
        the median interval between beams.

    Returns
    -------
    ClockSearch
        The best offset and the objective's contrast: take it only when
        :attr:`ClockSearch.decisive`.
    """
    require_turns(dataset, len(dataset.nav_beams()), "the sonar clock offset")
    configured = dataset.config.sonar_time_offset_s
    low = max(-half_range_s, -MAX_TIME_OFFSET_S - configured)
    high = min(half_range_s, MAX_TIME_OFFSET_S - configured)
    points = _windowed_points(
        dataset, pose_source, window_s, shift_margin_s=max(-low, high) + 2 * coarse_step_s
    )
    yaw = dataset.config.sonar_mounting.yaw_rad

    def cost(shift_s: float) -> float:
        return sum(map_entropy(chunk, cell_m) for chunk in points(yaw, shift_s))

    coarse = np.arange(low, high + 1e-9, coarse_step_s)
    costs = np.array([cost(x) for x in coarse])
    k = int(np.argmin(costs))
    if fine_step_s is None:
        fine_step_s = 0.5 * float(np.median(np.diff(dataset.nav_beams().t_s)))
    span = 2 * coarse_step_s
    fine = coarse[k] + np.arange(-span, span + 1e-9, fine_step_s)
    fine = fine[(fine >= low) & (fine <= high)]
    fine_costs = np.array([cost(x) for x in fine])
    best = float(fine[int(np.argmin(fine_costs))])
    curvature, slope, _ = np.polyfit(fine - coarse[k], fine_costs, 2)
    if curvature > 0.0:
        vertex = float(coarse[k] - slope / (2.0 * curvature))
        if fine[0] <= vertex <= fine[-1]:
            best = vertex
    chunks = points(yaw, float(coarse[k]))
    noise = max(math.sqrt(sum(map_entropy_variance(c, cell_m) for c in chunks)), 1e-12)
    median = float(np.median(costs))
    away = np.abs(coarse - coarse[k]) > CLOCK_BASIN_S
    second = int(np.argmin(np.where(away, costs, np.inf))) if away.any() else k
    grid = np.concatenate([coarse, fine])
    ent = np.concatenate([costs, fine_costs])
    order = np.argsort(grid, kind="stable")
    return ClockSearch(
        configured + best,
        configured,
        configured + grid[order],
        ent[order],
        noise,
        (median - float(costs[k])) / noise,
        configured + float(coarse[second]),
        (float(costs[second]) - float(costs[k])) / noise,
        at_edge=k in (0, coarse.size - 1),
    )


#: A run (:func:`sonar_clock_doubt`) searches the sonar clock offset over the configured one +-
#: this (s): a clock late by under a second is inside, and the marina's search costs 5 s of CPU
#: (its whole +-3 s, 12 s).
CLOCK_CHECK_HALF_RANGE_S = 1.5
#: ... and warns when the sharpest map's offset lies this far (s) from ``[sonar] time_offset_s``:
#: the search finds the simulated clocks within -0.03 to +0.10 s, and the marina's bottom is
#: flat within 0.12 s of its best (docs/research/calibration.md).
CLOCK_DOUBT_S = 0.3
#: ... with a minimum this many noise units below the median of the +-1.5 s grid (not
#: ``calibrate``'s 2.5 over +-3 s: the narrower grid's median lies nearer the bottom, and a
#: correct 300 s harbour's minimum stood 2.1-2.5 units deep, its offset within 0.2 s of the
#: truth) and ``calibrate``'s margin.
CLOCK_CHECK_MIN_DEPTH = 1.5


def sonar_clock_doubt(dataset: Dataset, pose_source: PoseSource) -> str | None:
    """Why ``[sonar] time_offset_s`` looks wrong, in words, or None (GPS-free).

    :func:`calibrate_time_offset` over +- :data:`CLOCK_CHECK_HALF_RANGE_S` with ``pose_source``
    (dead reckoning): a minimum that stands out (depth :data:`CLOCK_CHECK_MIN_DEPTH`, the margin
    ``calibrate`` requires) more than :data:`CLOCK_DOUBT_S` from the configured offset, or at an
    end of the range (the clock may be off by more). None when the sonar span
    is too short to search, or the objective is too flat to say (a sonar that sees no walls)."""
    try:
        found = calibrate_time_offset(dataset, pose_source, half_range_s=CLOCK_CHECK_HALF_RANGE_S)
    except DataError:
        return None  # fewer than ten turns of the head
    if found.depth < CLOCK_CHECK_MIN_DEPTH:
        return None
    configured = found.configured_offset_s
    if found.at_edge:
        edge = configured + (1 if found.best_offset_s > configured else -1) * (
            CLOCK_CHECK_HALF_RANGE_S
        )
        return (
            f"the map is sharpest at the end of the offsets searched ({edge:+.2f} s, the"
            f" configured [sonar] time_offset_s = {configured:g} s +- {CLOCK_CHECK_HALF_RANGE_S:g}"
            " s): the sonar's clock may be off by more; `sonarslam calibrate SOURCE"
            " --time-offset` with [sonar] time_offset_s set near that end finds it"
        )
    if found.margin < MIN_CLOCK_MARGIN or abs(found.best_offset_s - configured) <= CLOCK_DOUBT_S:
        return None
    late = "late" if found.best_offset_s < configured else "earl"
    return (
        f"the map is sharpest with the sonar's clock at [sonar] time_offset_s ="
        f" {found.best_offset_s:+.2f} s, not the configured {configured:g} s (the sonar's clock"
        f" {abs(found.best_offset_s - configured):.2f} s {late}r than that says; the minimum"
        f" {found.depth:.1f} noise units below the median, {found.margin:.1f} below the best"
        f" offset more than {CLOCK_BASIN_S:g} s away): set it, or"
        " check it with `sonarslam calibrate SOURCE --time-offset`; every estimate places each"
        " echo with the pose of another time"
    )


@dataclass(frozen=True)
class CompassFit:
    """Result of :func:`calibrate_ahrs_yaw` (angles in rad).

    Attributes
    ----------
    ahrs_yaw_rad : float
        The AHRS mounting yaw (``body yaw = AHRS yaw - ahrs_yaw``).
    offset_rad : float
        Constant term of (DVL compass - AHRS yaw) over heading.
    time_mean_rad : float
        Plain circular mean of (DVL compass - AHRS yaw) over the run, for comparison.
    harmonics_rad : ndarray, shape (2 * n,)
        ``sin k psi``, ``cos k psi`` coefficients, ``k = 1..n`` (the compasses' deviation).
    residual_sd_rad : float
    residual_change_rad : dict of float to float
        RMS change of the residual over a lag (s) -> (rad): a heading bias that walks (in either
        compass) grows it as ``sqrt(lag)``; a level curve says the bias does not walk (the
        back ends' ``ahrs_bias_walk_deg_per_sqrt_s``; a disturbance both compasses share, such
        as the field of a steel wall, cancels in the difference and is not seen here).
    """

    ahrs_yaw_rad: float
    offset_rad: float
    time_mean_rad: float
    harmonics_rad: FloatArray
    residual_sd_rad: float
    residual_change_rad: dict[float, float]


#: Lags (s) of :attr:`CompassFit.residual_change_rad`.
COMPASS_LAGS_S = (10.0, 30.0, 100.0, 300.0, 1000.0)


def _rms_change(t_s: FloatArray, r: FloatArray, lags_s: tuple[float, ...]) -> dict[float, float]:
    """RMS of ``r(t + lag) - r(t)`` over the samples, ``r`` interpolated at ``t + lag``; NaN
    for a lag longer than the series."""
    out = {}
    for lag in lags_s:
        later = t_s + lag
        ok = later <= t_s[-1]
        out[lag] = (
            float(np.sqrt(np.mean((np.interp(later[ok], t_s, r) - r[ok]) ** 2)))
            if ok.any()
            else float("nan")
        )
    return out


#: ``calibrate_ahrs_yaw`` needs at least this many DVL rows with a compass heading.
MIN_COMPASS_ROWS = 10


def calibrate_ahrs_yaw(dataset: Dataset, harmonics: int = 1) -> CompassFit:
    """The AHRS mounting yaw from the DVL's own compass, GPS-free.

    The DVL compass reads the heading of the DVL frame, whose yaw in the body is the DVL
    mounting's; so ``DVL compass - AHRS yaw`` is a constant (the AHRS mounting) plus the two
    compasses' deviations. A magnetic compass deflected by the vehicle's own (hard-iron) field
    errs by ``B sin psi + C cos psi`` around the heading ``psi``, which averages to zero over
    *all headings*, not over the run's time (a run spends unequal time at each heading). So the
    constant is fitted together with ``harmonics`` harmonics of the AHRS heading, least
    squares over every DVL row (the marina's figures: docs/research/calibration.md).

    Parameters
    ----------
    dataset : Dataset
        DVL rows with compass headings and the AHRS series; the DVL mounting is used.
    harmonics : int
        Harmonics of the heading fitted with the constant (0: the time mean).

    Raises
    ------
    ValueError
        Naming the DVL's file when fewer than :data:`MIN_COMPASS_ROWS` of its rows hold a
        compass heading (a bag's or a navigation CSV's DVL carries none).
    """
    dvl, att = dataset.dvl, dataset.attitude
    has = np.isfinite(dvl.heading_rad)
    if int(has.sum()) < max(MIN_COMPASS_ROWS, 1 + 2 * harmonics):
        raise ValueError(
            f"{dvl.path or dataset.root}: {int(has.sum())} of the DVL's {dvl.t.size} rows hold a"
            " compass heading (a ROS bag's DVL message, or a navigation CSV, carries none; the"
            " marina layout's *_DVL.log has its heading column), so --ahrs cannot find the"
            " AHRS mounting yaw from the DVL's compass: set [mounting.ahrs] yaw_deg in"
            " sonarslam.toml (on a bag, its /tf or the driver's frame convention gives it)"
        )
    t_dvl, heading = dvl.t[has], dvl.heading_rad[has]
    yaw = np.interp(t_dvl, att.t, np.unwrap(att.yaw_rad))
    diff = wrap_angle(heading - yaw)
    mean = float(np.angle(np.mean(np.exp(1j * diff))))
    r = wrap_angle(diff - mean)
    cols = [np.ones_like(yaw)]
    for k in range(1, harmonics + 1):
        cols += [np.sin(k * yaw), np.cos(k * yaw)]
    A = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(A, r, rcond=None)
    offset = float(wrap_angle(mean + coef[0]))
    # DVL compass = yaw of the DVL frame = body yaw + dvl yaw = AHRS yaw - ahrs yaw + dvl yaw
    ahrs_yaw = float(wrap_angle(dataset.config.dvl_mounting.yaw_rad - offset))
    residual = r - A @ coef
    return CompassFit(
        ahrs_yaw,
        offset,
        mean,
        np.asarray(coef[1:], dtype=np.float64),
        float(np.std(residual)),
        _rms_change(np.asarray(t_dvl, dtype=np.float64), residual, COMPASS_LAGS_S),
    )


def heading_deviation_from_lines(
    dataset: Dataset,
    features: list[LineFeature],
    feature_landmarks: list[int | None],
    min_observations: int = 4,
) -> tuple[FloatArray, int]:
    """The AHRS yaw's heading-dependent error seen by the sonar, GPS-free.

    A wall keeps its direction whatever the vehicle's heading, and the sonar is fixed to the
    vehicle: the world direction of an observed line, ``theta_sonar + psi_AHRS + sonar yaw``,
    differs from its landmark's mean direction by the AHRS error at that heading, ``e(psi)``,
    less the landmark's mean of it. Over the landmarks seen at least ``min_observations``
    times, the residuals are fitted (weighted by the lines' theta variances) with
    ``e(psi) = B sin psi + C cos psi``, the hard-iron deviation of a compass; its constant part
    is not observable this way (nor any other way without an absolute reference).

    Parameters
    ----------
    dataset : Dataset
        The dataset of the run (its AHRS series and configuration: the current deviation is
        applied, so the result is what is left of it).
    features, feature_landmarks : list
        A closed-loop run's lines and the landmark each was associated with
        (:class:`sonarslam.slam.run.closed_loop.ClosedLoopResult`).
    min_observations : int
        Landmarks seen fewer times are left out.

    Returns
    -------
    coef_rad : ndarray, shape (2,)
        ``(B, C)`` (rad) of the residual deviation.
    n : int
        Lines used.
    """
    cfg = dataset.config
    att = dataset.attitude
    yaw_unwrapped = np.unwrap(att.yaw_rad)
    pairs = [(f, lm) for f, lm in zip(features, feature_landmarks, strict=True) if lm is not None]
    if not pairs:
        return np.zeros(2), 0
    t = np.array([f.t for f, _ in pairs])
    psi = body_yaw(np.interp(t, att.t, yaw_unwrapped), cfg.ahrs_mounting, cfg.ahrs_deviation_rad)
    theta_w = np.array([f.z[1] for f, _ in pairs]) + psi
    var = np.array([f.cov[1, 1] for f, _ in pairs])
    lm = np.array([lm for _, lm in pairs])
    w = 1.0 / var
    A = np.column_stack([np.sin(psi), np.cos(psi)])
    res = np.zeros(t.size)
    keep = np.zeros(t.size, dtype=bool)
    for k in np.unique(lm):
        m = lm == k
        if m.sum() < min_observations:
            continue
        # a line's direction is defined modulo pi (rho's sign): compare doubled angles
        mean = np.angle(np.mean(np.exp(2j * theta_w[m]))) / 2.0
        r = wrap_angle(2.0 * (theta_w[m] - mean)) / 2.0
        # each landmark's own unknown direction: take its weighted mean off the residuals and
        # off the regressors alike (fixed effects), or a landmark seen over a narrow range of
        # headings would absorb part of the deviation
        wm = w[m] / w[m].sum()
        res[m] = r - wm @ r
        A[m] -= wm @ A[m]
        keep |= m
    if keep.sum() < 3:
        return np.zeros(2), int(keep.sum())
    sw = np.sqrt(w[keep])
    coef, *_ = np.linalg.lstsq(A[keep] * sw[:, None], res[keep] * sw, rcond=None)
    return coef, int(keep.sum())


def ekf_closed_loop(dataset: Dataset, label: str | None = None) -> ClosedLoopResult:
    """The EKF closed loop with its default settings and the beams' extractor preset (what
    :func:`calibrate_ahrs_deviation` iterates); GPS gives only the start position. ``label``:
    a progress bar of that name."""
    config = run_config(dataset.beams, "ekf", noise=dataset.config.noise)
    spec = backend_spec("ekf")
    mounting = dataset.config.sonar_mounting
    return run_closed_loop(
        dataset,
        lambda t0, pose0, cov0: spec.make(t0, pose0, cov0, mounting, config.backend),
        config.extractor,
        progress=label is not None,
        label=label or "ekf",
    )


def calibrate_ahrs_deviation(
    dataset: Dataset,
    run: Callable[[Dataset], ClosedLoopResult] = ekf_closed_loop,
    iterations: int = 4,
    progress: Callable[[int, int], None] | None = None,
) -> list[tuple[FloatArray, int]]:
    """Self-calibrate the AHRS deviation ``(B, C)`` with closed loops, GPS-free.

    Each iteration runs ``run(dataset)`` (a closed loop returning a
    :class:`sonarslam.slam.run.closed_loop.ClosedLoopResult`) with the deviation found so far, fits what is
    left of it (:func:`heading_deviation_from_lines`) and adds it. The associations improve as
    the heading does, hence the iterations. ``progress(k, iterations)`` is called before each.

    Returns
    -------
    list of (ndarray, int)
        Per iteration, the deviation ``(B, C)`` (rad) found so far after it, and the lines used.
    """
    out: list[tuple[FloatArray, int]] = []
    total = np.asarray(dataset.config.ahrs_deviation_rad, dtype=np.float64)
    for k in range(iterations):
        if progress is not None:
            progress(k + 1, iterations)
        ds = replace(
            dataset,
            config=replace(dataset.config, ahrs_deviation_rad=(float(total[0]), float(total[1]))),
        )
        result = run(ds)
        coef, n = heading_deviation_from_lines(ds, result.features, result.feature_landmarks)
        total = total + coef
        out.append((total.copy(), n))
    return out
