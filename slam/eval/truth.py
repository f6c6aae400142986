"""The simulator's truth for evaluation: true poses, true walls and their lines, and the
association scores and landmark extents of a closed loop against them.

The readers put every dataset in the local frame of its first GPS fix; the simulator's truth is
in its own world frame, so everything here is shifted by ``first_fix_enu_m`` (``truth.json``).
Without GPS the run's frame has its origin where the run starts (the start of the navigation
span, or the pose a user gave): the truth is shifted so that its position there is that origin
(its headings are East-referenced in both frames, so no rotation). A still head (no navigation)
is the exception: its whole pose, heading too, is the one given (``--start``), so it is compared
with the truth as ``truth.json`` has it (the simulator's world frame, in which ``--start`` is
given), never moved onto the start: a wrong start shows as its distance and heading error.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.source import Dataset
from sonarslam.features.geometry import (
    FloatArray,
    compose,
    line_difference,
    line_world_to_frame,
    normalize_line,
    wrap_angle,
)
from sonarslam.features.line import LineFeature
from sonarslam.slam.io.trajectory import Trajectory

__all__ = [
    "truth_trajectory",
    "truth_walls",
    "true_sonar",
    "true_calibration",
    "CALIBRATION_SD_KEYS",
    "calibration_sigmas",
    "wall_lines_world",
    "wall_lines",
    "SAME_LINE_RHO_M",
    "SAME_LINE_THETA_RAD",
    "truth_units",
    "AssociationScores",
    "association_scores",
    "association_against_truth",
    "landmark_overshoot_m",
]


def truth_trajectory(dataset: Dataset) -> Trajectory:
    """The simulator's true body poses, shifted into the readers' local frame (first GPS fix;
    see the module's docstring for a run without GPS and a still head)."""
    if dataset.truth is None:
        raise ValueError(f"{dataset.root}: no truth.json (only simulated datasets have one)")
    truth = dataset.truth
    poses = np.asarray(truth["body_poses"]["rows"], dtype=np.float64)  # t, x, y, yaw (world frame)
    t0, t1 = dataset.nav_span_s
    if poses.shape[0] == 0 or poses[-1, 0] < t0 or poses[0, 0] > t1:
        span = f"{poses[0, 0]:.3f}-{poses[-1, 0]:.3f} s" if poses.shape[0] else "no pose"
        raise ValueError(
            f"{dataset.root}: truth.json's body poses ({span}, Unix) do not meet the"
            f" navigation's {t0:.3f}-{t1:.3f} s: the truth is on another clock than the logs (a"
            " bag recorded with simulated time, or another run's truth.json)"
        )
    xy = poses[:, 1:3] - _offset(dataset)
    return Trajectory(poses[:, 0].copy(), np.column_stack([xy, wrap_angle(poses[:, 3])]))


def truth_heading_error(dataset: Dataset) -> tuple[FloatArray, FloatArray] | None:
    """The simulated AHRS's true heading error in the estimators' sense (the AHRS measures
    ``yaw + b``): ``b = -(constant bias + walk and place field)``, the logged heading being
    clockwise. ``(t_s, b_deg)``, shapes (N,); None for a dataset without truth. (The deviation
    with heading, zero in the simulator's worlds, is left out.)"""
    truth = dataset.truth
    if truth is None:
        return None
    bias = float(truth.get("noise", {}).get("ahrs_bias_deg", 0.0))
    walk = truth.get("ahrs_heading_walk")
    if walk is None:
        t = np.asarray(truth["body_poses"]["rows"], dtype=np.float64)[:, 0]
        return t, np.full(t.size, -bias)
    rows = np.asarray(walk["rows"], dtype=np.float64)
    return rows[:, 0].copy(), -(bias + rows[:, 1])


def truth_walls(dataset: Dataset) -> FloatArray:
    """The simulator's wall segments (W, 2, 2) in the readers' frame (world minus the first fix)."""
    if dataset.truth is None or "walls_m" not in dataset.truth:
        raise ValueError(
            f"{dataset.root}: no walls in truth.json (only simulated datasets have them)"
        )
    return np.asarray(dataset.truth["walls_m"], dtype=np.float64) - _offset(dataset)


def true_sonar(dataset: Dataset) -> tuple[FloatArray, float]:
    """The simulated sonar's true mounting ``bTs`` (3,) (m, m, rad) and range scale (an echo
    from range ``r`` logged at ``scale r``), from ``truth.json``; a world without drawn
    calibration errors has the told mounting and scale 1."""
    truth = dataset.truth or {}
    told = dataset.config.sonar_mounting.as_pose()
    m = truth.get("mountings", {}).get("sonar")
    bTs = told if m is None else np.array([m["x_m"], m["y_m"], m["yaw_rad"]], dtype=np.float64)
    return bTs, float(truth.get("errors", {}).get("sonar_range_scale", 1.0))


def true_calibration(dataset: Dataset, t_end_s: float) -> dict[str, float]:
    """The simulator's true values of the calibration estimates a run writes to
    ``metrics.json``, under the same keys; empty for a dataset without truth.

    ``state_sonar_{x,y}_m``, ``state_sonar_yaw_deg`` and ``state_sonar_range_scale``: the true
    mounting and range scale (:func:`true_sonar`). ``state_ahrs_bias_deg``: the true heading
    error ``b`` at ``t_end_s`` (s; :func:`truth_heading_error`). ``state_dvl_scale``: the
    estimators' ``k_e`` (the vehicle moves ``1 + k_e`` times the DVL's velocity) that undoes the
    DVL's own error, which measures ``(1 + k) v`` (``dvl_scale_factor``): ``1 + k_e = 1 / (1 +
    k)``. ``dvl_scale_in_sonar_map``: the ``k_e`` that agrees with a map the sonar draws at
    ``s`` times the true distances (``sonar_range_scale``), ``1 + k_e = s / (1 + k)``: an
    estimator without a range-scale state lies between the two.
    """
    truth = dataset.truth
    if truth is None:
        return {}
    bTs, scale = true_sonar(dataset)
    k = float(truth.get("errors", {}).get("dvl_scale_factor", 0.0))
    out = {
        "state_sonar_x_m": float(bTs[0]),
        "state_sonar_y_m": float(bTs[1]),
        "state_sonar_yaw_deg": float(np.rad2deg(bTs[2])),
        "state_sonar_range_scale": scale,
        "state_dvl_scale": 1.0 / (1.0 + k) - 1.0,
        "dvl_scale_in_sonar_map": scale / (1.0 + k) - 1.0,
    }
    heading = truth_heading_error(dataset)
    if heading is not None:
        t, b_deg = heading
        out["state_ahrs_bias_deg"] = float(np.interp(t_end_s, t, b_deg))
    return out


#: The calibration estimates of ``metrics.json`` that :func:`true_calibration` gives the truth
#: of: the estimate's key -> its sd's key.
CALIBRATION_SD_KEYS = {
    "state_sonar_x_m": "state_sonar_x_sd_m",
    "state_sonar_y_m": "state_sonar_y_sd_m",
    "state_sonar_yaw_deg": "state_sonar_yaw_sd_deg",
    "state_sonar_range_scale": "state_sonar_range_scale_sd",
    "state_ahrs_bias_deg": "state_ahrs_bias_sd_deg",
    "state_dvl_scale": "state_dvl_scale_sd",
}


def calibration_sigmas(
    metrics: dict[str, Any], truth: dict[str, float], key: str, truth_key: str | None = None
) -> float:
    """The error of the estimate ``metrics[key]`` against ``truth[truth_key or key]``
    (:func:`true_calibration`) in sigmas of its own sd (``CALIBRATION_SD_KEYS``); angles
    (``_deg``) wrapped; ``inf`` for a zero sd."""
    error = float(metrics[key]) - truth[truth_key or key]
    if key.endswith("_deg"):
        error = float(np.rad2deg(wrap_angle(np.deg2rad(error))))
    sd = float(metrics[CALIBRATION_SD_KEYS[key]])
    return error / sd if sd > 0 else float("inf")


def _offset(dataset: Dataset) -> FloatArray:
    """World minus the readers' frame (m): the first GPS fix's world position; a still head's
    none (its pose is given in the world frame, see the module's docstring); without GPS, the
    true position at the navigation's start minus the start position given (or the origin)."""
    assert dataset.truth is not None
    if dataset.gps is not None:
        return np.asarray(dataset.truth.get("first_fix_enu_m", [0.0, 0.0]), dtype=np.float64)
    if dataset.still:
        return np.zeros(2)
    rows = np.asarray(dataset.truth["body_poses"]["rows"], dtype=np.float64)
    t0 = dataset.nav_span_s[0]
    at = np.array([np.interp(t0, rows[:, 0], rows[:, 1]), np.interp(t0, rows[:, 0], rows[:, 2])])
    given = np.zeros(2) if dataset.start_enu is None else np.asarray(dataset.start_enu[:2])
    return at - given


def wall_lines_world(walls_m: npt.ArrayLike) -> FloatArray:
    """Normalised world lines of wall segments.

    Parameters
    ----------
    walls_m : array_like, shape (S, 2, 2)
        Segments ``[[x0, y0], [x1, y1]]`` (world, m).

    Returns
    -------
    ndarray, shape (S, 2)
        ``(rho_m, theta_rad)`` with ``rho >= 0`` and ``theta`` in ``[-pi, pi)``.
    """
    w = np.asarray(walls_m, dtype=np.float64)
    d = w[:, 1] - w[:, 0]
    normal = np.stack([d[:, 1], -d[:, 0]], axis=-1) / np.linalg.norm(d, axis=-1, keepdims=True)
    rho = np.einsum("ij,ij->i", normal, w[:, 0])
    theta = np.arctan2(normal[:, 1], normal[:, 0])
    rho_n, theta_n = normalize_line(rho, theta)
    return np.stack([rho_n, theta_n], axis=-1)


def wall_lines(
    walls_w: FloatArray, rho_tol_m: float = 1e-3, theta_tol_rad: float = 1e-4
) -> tuple[FloatArray, np.ndarray]:
    """The distinct lines ``(rho, theta)`` of wall segments and each wall's line index.

    Parameters
    ----------
    walls_w : ndarray, shape (W, 2, 2)
        Wall segments (m).
    rho_tol_m, theta_tol_rad : float
        Two walls are on one line when their normalised lines differ by less than these.

    Returns
    -------
    lines : ndarray, shape (K, 2)
        Distinct lines (m, rad), normalised (:func:`sonarslam.features.geometry.normalize_line`).
    line_of_wall : ndarray of int, shape (W,)
    """
    lines: list[FloatArray] = []
    line_of_wall = []
    for line in wall_lines_world(walls_w):
        same = [
            k
            for k, other in enumerate(lines)
            if abs(other[0] - line[0]) < rho_tol_m
            and abs(float(wrap_angle(other[1] - line[1]))) < theta_tol_rad
        ]
        if same:
            line_of_wall.append(same[0])
        else:
            line_of_wall.append(len(lines))
            lines.append(line)
    return np.array(lines).reshape(-1, 2), np.array(line_of_wall, dtype=np.int64)


#: Two walls' lines closer than this near the walls (m) ...
SAME_LINE_RHO_M = 0.1
#: ... and at an angle below this (rad) are one truth unit for the association scores: one
#: range bin of the simulated head (0.1 m), below one sigma of an extracted line's own systematic
#: error (calibrated 0.06-0.19 m and 0.5-1.1 deg on the drawn worlds, GPS-free): no gate tells
#: such lines apart, and pairing an observation of one with the other's landmark moves the
#: estimate by less than one line's error (docs/research/consistency.md).
SAME_LINE_THETA_RAD = float(np.deg2rad(0.5))


def truth_units(
    walls_w: FloatArray,
    wall_curve: npt.ArrayLike | None = None,
    same_line_rho_m: float = SAME_LINE_RHO_M,
    same_line_theta_rad: float = SAME_LINE_THETA_RAD,
) -> tuple[FloatArray, np.ndarray, np.ndarray]:
    """The distinct lines of wall segments and the truth unit of each
    (:class:`AssociationScores`).

    Parameters
    ----------
    walls_w : ndarray, shape (W, 2, 2)
        Wall segments (m).
    wall_curve : array_like of int, shape (W,), optional
        The curved stretch each wall is a facet of (-1: straight): a curve's facets are one unit.
    same_line_rho_m, same_line_theta_rad : float
        Lines at an angle below ``same_line_theta_rad`` whose walls' end points lie within
        ``same_line_rho_m`` of the other line are one unit (collinear walls); the defaults'
        reasons at :data:`SAME_LINE_RHO_M`.

    Returns
    -------
    lines : ndarray, shape (K, 2)
        Distinct lines (:func:`wall_lines`).
    unit : ndarray of int, shape (K,)
        The truth unit of each line.
    line_of_wall : ndarray of int, shape (W,)
    """
    walls = np.asarray(walls_w, dtype=np.float64).reshape(-1, 2, 2)
    lines, line_of_wall = wall_lines(walls)
    n = len(lines)
    parent = list(range(n))

    def root(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    if wall_curve is not None:
        curve = np.asarray(wall_curve, dtype=np.int64)
        first: dict[int, int] = {}
        for k in range(n):
            of = curve[line_of_wall == k]
            if of.size and np.all(of >= 0) and np.all(of == of[0]):
                c = int(of[0])
                parent[root(k)] = root(first.setdefault(c, k))
    ends = [walls[line_of_wall == k].reshape(-1, 2) for k in range(n)]
    for a in range(n):
        for b in range(a + 1, n):
            if abs(float(wrap_angle(lines[a, 1] - lines[b, 1]))) > same_line_theta_rad and (
                abs(float(wrap_angle(lines[a, 1] - lines[b, 1] - np.pi))) > same_line_theta_rad
            ):
                continue
            if max(_distances(lines[b], ends[a]).max(), _distances(lines[a], ends[b]).max()) <= (
                same_line_rho_m
            ):
                parent[root(a)] = root(b)
    roots = [root(k) for k in range(n)]
    relabel = {r: i for i, r in enumerate(dict.fromkeys(roots))}
    return lines, np.array([relabel[r] for r in roots], dtype=np.int64), line_of_wall


def _distances(line: FloatArray, points: FloatArray) -> FloatArray:
    """Unsigned distances (m) of points (N, 2) from a line ``(rho, theta)``."""
    return np.abs(points @ np.array([np.cos(line[1]), np.sin(line[1])]) - line[0])


@dataclass(frozen=True)
class AssociationScores:
    """Association quality against the simulator's walls.

    The truth unit is a wall's *line*: collinear wall segments (two quays on one line) are one
    line, because a line landmark ``(rho, theta)`` is the infinite line and pairing both with it
    is right; "collinear" within :data:`SAME_LINE_RHO_M` and :data:`SAME_LINE_THETA_RAD`
    (:func:`truth_units`). An observation's true line is the one it matches within ``gate_rho_m`` and
    ``gate_theta_rad`` in its own frame, with the true pose; observations matching none are
    spurious. A landmark's line is the true line most of its observations come from. The facets
    of a curved stretch (a drawn world's rounded corners and coves) are one unit together: a
    line fitted to a curve is none of its facets' lines.

    ``precision``: of the observations associated with a landmark, the fraction whose true line
    is the landmark's. ``recall``: of the observations of a line that has a landmark, excluding
    the ones that seeded a landmark as tentative lines (the creation rule, not an association
    decision), the fraction associated with a landmark of that line. ``seed_precision``: of the
    seeding observations, the fraction whose line is their landmark's.
    """

    precision: float
    recall: float
    n_associated: int
    n_true_pairs: int
    n_spurious: int
    n_seeds: int = 0
    seed_precision: float = float("nan")


def association_scores(
    features: list[LineFeature],
    feature_landmarks: list[int | None],
    walls_w: FloatArray,
    truth: Trajectory,
    bTs: FloatArray,
    gate_rho_m: float = 1.0,
    gate_theta_rad: float = float(np.deg2rad(5.0)),
    feature_seeds: list[int | None] | None = None,
    wall_curve: npt.ArrayLike | None = None,
    range_scale: float = 1.0,
    same_line_rho_m: float = SAME_LINE_RHO_M,
    same_line_theta_rad: float = SAME_LINE_THETA_RAD,
) -> AssociationScores:
    """Precision and recall of a run's associations (see :class:`AssociationScores`).

    Parameters
    ----------
    features, feature_landmarks : list
        The run's line features and the landmark id each was associated with (None: not).
    walls_w : ndarray, shape (W, 2, 2)
        True wall segments in the run's frame (reader frame: world minus ``first_fix_enu_m``).
    truth : Trajectory
        True body poses.
    bTs : ndarray, shape (3,)
        Sonar mounting (the true one).
    gate_rho_m, gate_theta_rad : float
        How close (m, rad) an observation must be to a true line to be of it.
    feature_seeds : list, optional
        The landmark each feature seeded as a tentative line (None: none), as
        :attr:`sonarslam.slam.run.closed_loop.ClosedLoopResult.feature_seeds`.
    wall_curve : array_like of int, shape (W,), optional
        The curved stretch each wall is a facet of (-1: straight; a drawn world's
        ``truth.json`` ``walls.curve``): the facets of one curve are one truth unit, as
        the lines of its facets are not walls of their own.
    range_scale : float
        The sonar's true range scale: a line at distance ``rho`` is observed at
        ``range_scale rho`` (:func:`true_sonar`).
    same_line_rho_m, same_line_theta_rad : float
        Collinear walls within these are one unit (:func:`truth_units`); ``1e-3`` and ``1e-4``
        count only exactly collinear walls as one, as the scores did before.
    """
    lines, unit, _ = truth_units(walls_w, wall_curve, same_line_rho_m, same_line_theta_rad)
    seeds = feature_seeds if feature_seeds is not None else [None] * len(features)
    true_line: list[int | None] = []
    for f in features:
        wTs = compose(truth.poses([f.t])[0], bTs)
        best: int | None = None
        best_cost = np.inf
        for k, lw in enumerate(lines):
            line_s = line_world_to_frame(lw, wTs)[0] * np.array([range_scale, 1.0])
            nu, _ = line_difference(f.z, line_s)
            if abs(nu[0]) <= gate_rho_m and abs(nu[1]) <= gate_theta_rad:
                cost = abs(nu[0]) / gate_rho_m + abs(nu[1]) / gate_theta_rad
                if cost < best_cost:
                    best, best_cost = int(unit[k]), cost
        true_line.append(best)
    by_landmark: dict[int, Counter[int | None]] = {}
    for w, lm, sd in zip(true_line, feature_landmarks, seeds, strict=True):
        owner = lm if lm is not None else sd
        if owner is not None:
            by_landmark.setdefault(owner, Counter())[w] += 1
    line_of = {lm: c.most_common(1)[0][0] for lm, c in by_landmark.items()}
    mapped = {w for w in line_of.values() if w is not None}
    associated = [
        (w, lm) for w, lm in zip(true_line, feature_landmarks, strict=True) if lm is not None
    ]
    correct = sum(1 for w, lm in associated if w is not None and line_of[lm] == w)
    of_mapped = [
        (w, lm)
        for w, lm, sd in zip(true_line, feature_landmarks, seeds, strict=True)
        if w in mapped and sd is None
    ]
    found = sum(1 for w, lm in of_mapped if lm is not None and line_of[lm] == w)
    seeding = [(w, sd) for w, sd in zip(true_line, seeds, strict=True) if sd is not None]
    return AssociationScores(
        precision=correct / len(associated) if associated else float("nan"),
        recall=found / len(of_mapped) if of_mapped else float("nan"),
        n_associated=len(associated),
        n_true_pairs=len(of_mapped),
        n_spurious=sum(1 for w in true_line if w is None),
        n_seeds=len(seeding),
        seed_precision=(
            sum(1 for w, sd in seeding if w is not None and line_of[sd] == w) / len(seeding)
            if seeding
            else float("nan")
        ),
    )


def association_against_truth(
    dataset: Dataset,
    features: list[LineFeature],
    feature_landmarks: list[int | None],
    feature_seeds: list[int | None],
) -> AssociationScores:
    """:func:`association_scores` of a closed-loop run on a simulated dataset: its features,
    pairings and seeds (:class:`sonarslam.slam.run.closed_loop.ClosedLoopResult`) against the true walls
    and poses, seen with the true sonar (:func:`true_sonar`: a drawn world's mounting and range
    scale are not the told ones, and a far wall's lines would otherwise miss the gate)."""
    walls = (dataset.truth or {}).get("walls") or {}
    bTs, scale = true_sonar(dataset)
    return association_scores(
        features,
        feature_landmarks,
        truth_walls(dataset),
        truth_trajectory(dataset),
        bTs,
        feature_seeds=feature_seeds,
        wall_curve=walls.get("curve"),
        range_scale=scale,
    )


def landmark_overshoot_m(landmarks: list[dict[str, Any]], walls_w: FloatArray) -> FloatArray:
    """How far each landmark's end points lie from the nearest true wall segment (m).

    Parameters
    ----------
    landmarks : list of dict
        ``map.json`` records (``endpoints``: two world points).
    walls_w : ndarray, shape (W, 2, 2)
        True wall segments in the run's frame (m).

    Returns
    -------
    ndarray, shape (L,)
        Per landmark, the larger of its two end points' distances to the walls.
    """
    w = np.asarray(walls_w, dtype=np.float64)
    a, d = w[:, 0], w[:, 1] - w[:, 0]
    out = []
    for lm in landmarks:
        worst = 0.0
        for p in np.asarray(lm["endpoints"], dtype=np.float64):
            t = np.clip(np.einsum("wi,wi->w", p - a, d) / np.einsum("wi,wi->w", d, d), 0.0, 1.0)
            worst = max(worst, float(np.min(np.linalg.norm(a + t[:, None] * d - p, axis=1))))
        out.append(worst)
    return np.array(out)
