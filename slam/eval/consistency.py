"""Evaluation of a run beside the GPS ATE protocol: evo's APE and RPE, and the filter consistency.

Accuracy, through evo's API on the TUM outputs (``trajectory.tum`` against ``ground_truth.tum``):

* APE on the translation part (``evo.core.metrics.APE``, ``PoseRelation.translation_part``) after
  ``evo.core.sync.associate_trajectories``; no alignment by default (the published protocol has
  none), Umeyama SE(3) alignment (``PoseTrajectory3D.align``) as an option. The default
  association interpolates the denser trajectory at the times of the sparser one (evo's
  ``SyncMethod.interpolation``), so that against GPS the APE is taken at every GPS fix on the
  estimate interpolated there: the same errors as :mod:`slam.eval.ate` (a test checks it);
* RPE per travelled distance (``evo.core.metrics.RPE`` with ``delta_unit=Unit.meters``): the
  translation error of the relative motion between poses ``delta_m`` metres of path apart.

Consistency, on simulated runs (the truth is known), from the trajectory covariances:

* pose NEES ``e_k^T P_k^-1 e_k``, ``e_k = (x - x_true, y - y_true, wrap(psi - psi_true))``
  (:func:`features.geometry.wrap_angle`), chi2 with 3 degrees of freedom when consistent (2 for
  the position only, 1 for the heading only);
* NIS of the innovations when a back end logs them (:func:`nis`);
* ANEES over N Monte Carlo runs: at each time the mean of the N NEES, whose two-sided 95 %
  band is ``chi2.ppf([0.025, 0.975], N dof) / N`` (Bar-Shalom, Li, Kirubarajan 2001, 5.4.2).

Pose covariances are stored beside ``trajectory.tum`` in ``trajectory_cov.npz`` (``t_s``,
``covs``), written by :func:`write_trajectory_covariances`.
"""

from __future__ import annotations

import copy
import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from evo.core import metrics as evo_metrics
from evo.core import sync as evo_sync
from evo.core.sync_method import SyncMethod
from evo.core.trajectory import PoseTrajectory3D
from evo.core.units import Unit
from scipy import stats

from features.geometry import FloatArray, wrap_angle
from slam.io.trajectory import Trajectory, read_tum

__all__ = [
    "COV_FILE",
    "NEES_PROBABILITY",
    "COMPONENTS",
    "ErrorStats",
    "NeesSeries",
    "AneesResult",
    "to_evo",
    "evo_ape",
    "evo_rpe",
    "evo_metrics_of_run",
    "write_trajectory_covariances",
    "read_trajectory_covariances",
    "with_covariances",
    "load_run_trajectory",
    "pose_errors",
    "nees",
    "nees_series",
    "nis",
    "chi2_band",
    "mean_nees_band",
    "nees_on_grid",
    "anees",
]

#: File of the pose covariances beside ``trajectory.tum``.
COV_FILE = "trajectory_cov.npz"

#: Probability of the two-sided consistency bands.
NEES_PROBABILITY = 0.95

#: The pose components of a NEES: indices into ``(x_m, y_m, yaw_rad)``.
COMPONENTS: dict[str, tuple[int, ...]] = {"pose": (0, 1, 2), "position": (0, 1), "heading": (2,)}

#: Largest time difference (s) of two poses associated by evo (the marina AHRS is ~10 Hz).
MAX_DIFF_S = 0.1

# -- accuracy through evo -------------------------------------------------------------------------


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of an evo error (m), over ``n`` values."""

    rmse_m: float
    mean_m: float
    median_m: float
    sd_m: float
    min_m: float
    max_m: float
    n: int

    def as_dict(self, prefix: str) -> dict[str, float | int]:
        """Flat ``{prefix}_rmse_m`` ... ``{prefix}_n``."""
        return {f"{prefix}_{k}": v for k, v in asdict(self).items()}


def to_evo(trajectory: Trajectory) -> PoseTrajectory3D:
    """The planar trajectory as an evo ``PoseTrajectory3D`` (z = 0, yaw about z)."""
    yaw = trajectory.poses_wTb[:, 2]
    zeros = np.zeros_like(yaw)
    quat_wxyz = np.stack([np.cos(yaw / 2), zeros, zeros, np.sin(yaw / 2)], axis=1)
    xyz = np.column_stack([trajectory.poses_wTb[:, :2], zeros])
    return PoseTrajectory3D(
        positions_xyz=xyz, orientations_quat_wxyz=quat_wxyz, timestamps=trajectory.t_s.copy()
    )


def _as_evo(trajectory: Trajectory | PoseTrajectory3D) -> PoseTrajectory3D:
    if isinstance(trajectory, Trajectory):
        return to_evo(trajectory)
    return copy.deepcopy(trajectory)


def _stats(metric: evo_metrics.PE) -> ErrorStats:
    s = metric.get_all_statistics()
    return ErrorStats(
        rmse_m=float(s["rmse"]),
        mean_m=float(s["mean"]),
        median_m=float(s["median"]),
        sd_m=float(s["std"]),
        min_m=float(s["min"]),
        max_m=float(s["max"]),
        n=int(np.asarray(metric.error).size),
    )


def _synced(
    reference: Trajectory | PoseTrajectory3D,
    estimate: Trajectory | PoseTrajectory3D,
    max_diff_s: float,
    sync: str,
    align: bool,
    correct_scale: bool,
) -> tuple[PoseTrajectory3D, PoseTrajectory3D]:
    methods = {"interpolation": SyncMethod.interpolation, "nearest": SyncMethod.nearest_time}
    if sync not in methods:
        raise ValueError(f"sync must be one of {sorted(methods)}, got {sync!r}")
    ref, est = evo_sync.associate_trajectories(
        _as_evo(reference), _as_evo(estimate), sync_method=methods[sync], max_diff=max_diff_s
    )
    if align or correct_scale:
        est.align(ref, correct_scale=correct_scale)
    return ref, est


def evo_ape(
    reference: Trajectory | PoseTrajectory3D,
    estimate: Trajectory | PoseTrajectory3D,
    max_diff_s: float = MAX_DIFF_S,
    sync: str = "interpolation",
    align: bool = False,
    correct_scale: bool = False,
) -> ErrorStats:
    """Absolute position error (m) of ``estimate`` against ``reference`` with evo.

    Parameters
    ----------
    reference, estimate : Trajectory or evo PoseTrajectory3D
        Not modified.
    max_diff_s : float
        Largest time difference of associated poses (s): a pose of the sparser trajectory with
        no pose of the other this close is dropped (evo associates first, then interpolates).
    sync : {"interpolation", "nearest"}
        evo's association: interpolate the denser trajectory at the sparser one's times, or take
        the nearest pose in time.
    align : bool
        Umeyama SE(3) alignment of the estimate onto the reference first (default: none).
    correct_scale : bool
        Also a scale (Sim(3)); implies an alignment.

    Returns
    -------
    ErrorStats
    """
    ref, est = _synced(reference, estimate, max_diff_s, sync, align, correct_scale)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    return _stats(ape)


def evo_rpe(
    reference: Trajectory | PoseTrajectory3D,
    estimate: Trajectory | PoseTrajectory3D,
    delta_m: float = 10.0,
    rel_delta_tol: float = 0.1,
    pairs_from_reference: bool = False,
    max_diff_s: float = MAX_DIFF_S,
    sync: str = "interpolation",
    align: bool = False,
) -> ErrorStats:
    """Relative position error (m) per ``delta_m`` metres travelled, with evo.

    The pairs of poses ``delta_m`` (within ``rel_delta_tol`` of it) apart along the path are
    found on the estimate's path by default (evo's default: GPS noise lengthens the path of the
    reference), on the reference's with ``pairs_from_reference``; consecutive pairs, not all.
    See :func:`evo_ape` for the other parameters.
    """
    ref, est = _synced(reference, estimate, max_diff_s, sync, align, False)
    rpe = evo_metrics.RPE(
        evo_metrics.PoseRelation.translation_part,
        delta=delta_m,
        delta_unit=Unit.meters,
        rel_delta_tol=rel_delta_tol,
        all_pairs=False,
        pairs_from_reference=pairs_from_reference,
    )
    rpe.process_data((ref, est))
    return _stats(rpe)


def evo_metrics_of_run(
    run_dir: str | Path,
    rpe_delta_m: float = 10.0,
    align: bool = False,
    max_diff_s: float = MAX_DIFF_S,
) -> dict[str, float | int]:
    """evo's APE and RPE of a run directory's ``trajectory.tum`` against its ``ground_truth.tum``.

    Returns
    -------
    dict
        ``evo_ape_{rmse,mean,median,sd,min,max}_m``, ``evo_ape_n``, and the same for
        ``evo_rpe_{delta}m_...``; the RPE keys are absent when the path is shorter than
        ``rpe_delta_m``.
    """
    run = Path(run_dir)
    ref = read_tum(run / "ground_truth.tum")
    est = read_tum(run / "trajectory.tum")
    out: dict[str, float | int] = dict(
        evo_ape(ref, est, max_diff_s=max_diff_s, align=align).as_dict("evo_ape")
    )
    try:
        rpe = evo_rpe(ref, est, delta_m=rpe_delta_m, max_diff_s=max_diff_s, align=align)
    except Exception as exc:  # evo's FilterException: no pair that far apart
        if "empty index list" not in str(exc):
            raise
    else:
        out.update(rpe.as_dict(f"evo_rpe_{rpe_delta_m:g}m"))
    return out


# -- covariances beside the TUM file --------------------------------------------------------------


def write_trajectory_covariances(path: str | Path, trajectory: Trajectory) -> Path | None:
    """Write ``t_s`` (N,) and ``covs`` (N, 3, 3) of a trajectory to an ``.npz``.

    Returns the path, or None (nothing written) when the trajectory has no covariances.
    """
    if trajectory.covs is None:
        return None
    out = Path(path)
    np.savez_compressed(
        out,
        t_s=np.asarray(trajectory.t_s, dtype=np.float64),
        covs=np.asarray(trajectory.covs, dtype=np.float64),
    )
    return out


def read_trajectory_covariances(path: str | Path) -> tuple[FloatArray, FloatArray]:
    """``t_s`` (N,) (Unix s) and ``covs`` (N, 3, 3) from :func:`write_trajectory_covariances`."""
    with np.load(path) as data:
        t_s, covs = np.asarray(data["t_s"]), np.asarray(data["covs"])
    if covs.shape != (t_s.size, 3, 3):
        raise ValueError(f"{path}: covs (N, 3, 3) expected for {t_s.size} times, got {covs.shape}")
    return t_s, covs


def with_covariances(
    trajectory: Trajectory, t_s: FloatArray, covs: FloatArray, tol_s: float = 1e-6
) -> Trajectory:
    """``trajectory`` with the covariances of the same times attached.

    Raises ValueError when a pose has no covariance within ``tol_s`` of its time.
    """
    i = np.clip(np.searchsorted(t_s, trajectory.t_s), 1, max(t_s.size - 1, 1))
    i = np.where(np.abs(t_s[i - 1] - trajectory.t_s) <= np.abs(t_s[i] - trajectory.t_s), i - 1, i)
    if t_s.size == 0 or np.any(np.abs(t_s[i] - trajectory.t_s) > tol_s):
        raise ValueError("the covariances' times do not match the trajectory's")
    return Trajectory(trajectory.t_s, trajectory.poses_wTb, covs[i])


def load_run_trajectory(run_dir: str | Path) -> Trajectory:
    """``trajectory.tum`` of a run, with its ``trajectory_cov.npz`` covariances when present."""
    run = Path(run_dir)
    tr = read_tum(run / "trajectory.tum")
    cov_path = run / COV_FILE
    if cov_path.is_file():
        tr = with_covariances(tr, *read_trajectory_covariances(cov_path))
    return tr


# -- consistency ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class NeesSeries:
    """NEES (or NIS) values against time.

    Attributes
    ----------
    t_s : ndarray, shape (K,)
        Unix times (s).
    nees : ndarray, shape (K,)
        Normalised errors squared.
    dof : int
        Degrees of freedom of each value (chi2 when consistent).
    """

    t_s: FloatArray
    nees: FloatArray
    dof: int

    @property
    def mean(self) -> float:
        return float(np.mean(self.nees)) if self.nees.size else float("nan")

    def in_band_fraction(self, probability: float = NEES_PROBABILITY) -> float:
        """Fraction of the values inside the two-sided ``probability`` band of chi2(dof)."""
        lo, hi = chi2_band(self.dof, probability)
        return float(np.mean((self.nees >= lo) & (self.nees <= hi))) if self.nees.size else 0.0


def pose_errors(estimate: Trajectory, truth: Trajectory, t_s: npt.ArrayLike) -> FloatArray:
    """``estimate - truth`` at ``t_s`` (both interpolated), yaw wrapped; shape (K, 3) (m, m, rad)."""
    e = estimate.poses(t_s) - truth.poses(t_s)
    e[:, 2] = wrap_angle(e[:, 2])
    return e


def nees(errors: npt.ArrayLike, covs: npt.ArrayLike) -> FloatArray:
    """``e_k^T P_k^-1 e_k`` of errors (K, d) with covariances (K, d, d); shape (K,)."""
    e = np.asarray(errors, dtype=np.float64)
    P = np.asarray(covs, dtype=np.float64)
    return np.einsum("ki,ki->k", e, np.linalg.solve(P, e[:, :, None])[:, :, 0])


def nees_series(
    estimate: Trajectory,
    truth: Trajectory,
    components: str = "pose",
    period_s: float | None = None,
) -> NeesSeries:
    """NEES of an estimate's own samples against the truth.

    Parameters
    ----------
    estimate : Trajectory
        With covariances.
    truth : Trajectory
        Interpolated at the estimate's times (only those inside its span are used).
    components : {"pose", "position", "heading"}
        Which block of ``(x, y, yaw)`` (3, 2 or 1 degrees of freedom).
    period_s : float, optional
        Keep one sample per ``period_s`` (the last at or before each multiple of it after the
        start); default every sample.

    Returns
    -------
    NeesSeries
    """
    if estimate.covs is None:
        raise ValueError("NEES needs the trajectory covariances (trajectory_cov.npz)")
    if components not in COMPONENTS:
        raise ValueError(f"components must be one of {sorted(COMPONENTS)}, got {components!r}")
    idx = np.asarray(COMPONENTS[components])
    t = estimate.t_s
    keep = np.flatnonzero((t >= truth.t_s[0]) & (t <= truth.t_s[-1]))
    if period_s is not None and keep.size:
        grid = np.arange(t[keep[0]], t[keep[-1]] + 0.5 * period_s, period_s)
        pick = np.searchsorted(t[keep], grid, side="right") - 1
        keep = keep[np.unique(pick[pick >= 0])]
    e = pose_errors(estimate, truth, t[keep])[:, idx]
    P = np.asarray(estimate.covs)[keep][:, idx[:, None], idx[None, :]]
    return NeesSeries(t[keep].copy(), nees(e, P), int(idx.size))


def nis(
    t_s: npt.ArrayLike, innovations: npt.ArrayLike, innovation_covs: npt.ArrayLike
) -> NeesSeries:
    """NIS ``nu^T S^-1 nu`` of logged innovations (K, d) and their covariances (K, d, d).

    For back ends that log their innovations (line observations: ``d = 2``); none does yet.
    """
    nu = np.asarray(innovations, dtype=np.float64)
    return NeesSeries(np.asarray(t_s, dtype=np.float64), nees(nu, innovation_covs), nu.shape[1])


def chi2_band(dof: int, probability: float = NEES_PROBABILITY) -> tuple[float, float]:
    """Two-sided ``probability`` interval of one chi2(``dof``) value."""
    return mean_nees_band(1, dof, probability)


def mean_nees_band(
    n_runs: int, dof: int, probability: float = NEES_PROBABILITY
) -> tuple[float, float]:
    """Two-sided ``probability`` interval of the mean of ``n_runs`` independent chi2(``dof``).

    ``chi2.ppf([(1 - p) / 2, (1 + p) / 2], n_runs dof) / n_runs``; at 0.95 and 3 dof: (0.216,
    9.348) for one run, (2.360, 3.716) for 50.
    """
    if n_runs < 1 or dof < 1:
        raise ValueError(f"need n_runs >= 1 and dof >= 1, got {n_runs}, {dof}")
    a = 0.5 * (1.0 - probability)
    lo, hi = stats.chi2.ppf([a, 1.0 - a], n_runs * dof) / n_runs
    return float(lo), float(hi)


def nees_on_grid(series: NeesSeries, t0_s: float, grid_rel_s: npt.ArrayLike) -> FloatArray:
    """The series' value at each time ``t0_s + grid_rel_s`` (the last at or before it; NaN
    before the first and more than one grid step after the last), shape (K,)."""
    g = t0_s + np.asarray(grid_rel_s, dtype=np.float64)
    out = np.full(g.size, np.nan)
    if series.t_s.size == 0:
        return out
    step = float(np.median(np.diff(g))) if g.size > 1 else np.inf
    i = np.searchsorted(series.t_s, g, side="right") - 1
    ok = (i >= 0) & (g - series.t_s[np.clip(i, 0, None)] <= step)
    out[ok] = series.nees[i[ok]]
    return out


@dataclass(frozen=True)
class AneesResult:
    """ANEES over Monte Carlo runs on a common time grid.

    Attributes
    ----------
    t_rel_s : ndarray, shape (K,)
        Time since the start of the runs (s).
    anees : ndarray, shape (K,)
        Mean NEES over the runs that have a value at each time.
    n_runs : ndarray of int, shape (K,)
        Runs averaged at each time.
    dof : int
    band_lo, band_hi : ndarray, shape (K,)
        Two-sided band of the mean of ``n_runs`` chi2(dof) at each time.
    """

    t_rel_s: FloatArray
    anees: FloatArray
    n_runs: npt.NDArray[np.int64]
    dof: int
    band_lo: FloatArray
    band_hi: FloatArray
    probability: float = NEES_PROBABILITY

    @property
    def mean(self) -> float:
        """ANEES averaged over time."""
        ok = np.isfinite(self.anees)
        return float(np.mean(self.anees[ok])) if ok.any() else float("nan")

    @property
    def in_band_fraction(self) -> float:
        """Fraction of the times whose ANEES is inside its band (~``probability`` if consistent)."""
        ok = np.isfinite(self.anees)
        inside = (self.anees >= self.band_lo) & (self.anees <= self.band_hi)
        return float(np.mean(inside[ok])) if ok.any() else 0.0

    def summary(self) -> dict[str, Any]:
        """``anees``, ``anees_in_band_fraction``, ``anees_runs`` (most), ``anees_band_lo/hi`` (for
        that many runs), ``anees_dof``."""
        n = int(self.n_runs.max()) if self.n_runs.size else 0
        lo, hi = mean_nees_band(n, self.dof, self.probability) if n else (np.nan, np.nan)
        return {
            "anees": self.mean,
            "anees_in_band_fraction": self.in_band_fraction,
            "anees_runs": n,
            "anees_band_lo": lo,
            "anees_band_hi": hi,
            "anees_dof": self.dof,
        }

    def to_json(self) -> str:
        return json.dumps(
            {
                "t_rel_s": self.t_rel_s.tolist(),
                "anees": [None if not np.isfinite(v) else float(v) for v in self.anees],
                "n_runs": self.n_runs.tolist(),
                "dof": self.dof,
                **{k: v for k, v in self.summary().items() if k != "anees_dof"},
            }
        )


def anees(
    nees_runs: npt.ArrayLike,
    dof: int,
    t_rel_s: npt.ArrayLike | None = None,
    probability: float = NEES_PROBABILITY,
) -> AneesResult:
    """ANEES of Monte Carlo runs.

    Parameters
    ----------
    nees_runs : array_like, shape (N, K)
        NEES of run ``i`` at grid time ``k``; NaN where a run has no value.
    dof : int
        Degrees of freedom of one NEES.
    t_rel_s : array_like, shape (K,), optional
        The grid (s); default ``0, 1, ..., K - 1``.
    probability : float
        Of the two-sided band, ``chi2.ppf([(1-p)/2, (1+p)/2], n dof) / n`` at each time.
    """
    X = np.atleast_2d(np.asarray(nees_runs, dtype=np.float64))
    n = np.sum(np.isfinite(X), axis=0).astype(np.int64)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, np.nansum(X, axis=0) / np.maximum(n, 1), np.nan)
    lo = np.full(X.shape[1], np.nan)
    hi = np.full(X.shape[1], np.nan)
    for m in np.unique(n[n > 0]):
        lo[n == m], hi[n == m] = mean_nees_band(int(m), dof, probability)
    grid = np.arange(X.shape[1], dtype=np.float64) if t_rel_s is None else np.asarray(t_rel_s)
    return AneesResult(grid, mean, n, dof, lo, hi, probability)


@dataclass(frozen=True)
class AssociationScores:
    """Association quality against the simulator's walls.

    The truth unit is a wall's *line*: collinear wall segments (two quays on one line) are one
    line, because a line landmark ``(rho, theta)`` is the infinite line and pairing both with it
    is right. An observation's true line is the one it matches within ``gate_rho_m`` and
    ``gate_theta_rad`` in its own frame, with the true pose; observations matching none are
    spurious. A landmark's line is the true line most of its observations come from.

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
        Distinct lines (m, rad), normalised (:func:`features.geometry.normalize_line`).
    line_of_wall : ndarray of int, shape (W,)
    """
    from features.geometry import wrap_angle
    from slam.eval.lines import wall_lines_world

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


def truth_walls(dataset: Any) -> FloatArray:
    """The simulator's wall segments (W, 2, 2) in the readers' frame (world minus the first fix)."""
    if dataset.truth is None or "walls_m" not in dataset.truth:
        raise ValueError(
            f"{dataset.root}: no walls in truth.json (only simulated datasets have them)"
        )
    offset = np.asarray(dataset.truth.get("first_fix_enu_m", [0.0, 0.0]), dtype=np.float64)
    return np.asarray(dataset.truth["walls_m"], dtype=np.float64) - offset


def association_against_truth(dataset: Any, result: Any) -> AssociationScores:
    """:func:`association_scores` of a closed-loop run (``ClosedLoopResult``) on a simulated
    dataset: its features, pairings and seeds against the true walls and poses."""
    from slam.run.sources import truth_trajectory

    return association_scores(
        result.features,
        result.feature_landmarks,
        truth_walls(dataset),
        truth_trajectory(dataset),
        dataset.config.sonar_mounting.as_pose(),
        feature_seeds=result.feature_seeds,
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


def association_scores(
    features: list[Any],
    feature_landmarks: list[int | None],
    walls_w: FloatArray,
    truth: Trajectory,
    bTs: FloatArray,
    gate_rho_m: float = 1.0,
    gate_theta_rad: float = float(np.deg2rad(5.0)),
    feature_seeds: list[int | None] | None = None,
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
        Sonar mounting.
    gate_rho_m, gate_theta_rad : float
        How close (m, rad) an observation must be to a true line to be of it.
    feature_seeds : list, optional
        The landmark each feature seeded as a tentative line (None: none), as
        :attr:`slam.run.closed_loop.ClosedLoopResult.feature_seeds`.
    """
    from collections import Counter

    from features.geometry import compose, line_world_to_frame
    from slam.mapping.association import line_innovation

    lines, _ = wall_lines(walls_w)
    seeds = feature_seeds if feature_seeds is not None else [None] * len(features)
    true_line: list[int | None] = []
    for f in features:
        wTs = compose(truth.poses([f.t])[0], bTs)
        best, best_cost = None, np.inf
        for w, lw in enumerate(lines):
            nu, _ = line_innovation(f.z, line_world_to_frame(lw, wTs)[0])
            if abs(nu[0]) <= gate_rho_m and abs(nu[1]) <= gate_theta_rad:
                cost = abs(nu[0]) / gate_rho_m + abs(nu[1]) / gate_theta_rad
                if cost < best_cost:
                    best, best_cost = w, cost
        true_line.append(best)
    by_landmark: dict[int, Counter[int | None]] = {}
    for w, lm, sd in zip(true_line, feature_landmarks, seeds, strict=True):
        if lm is not None or sd is not None:
            by_landmark.setdefault(lm if lm is not None else sd, Counter())[w] += 1  # type: ignore[arg-type]
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
