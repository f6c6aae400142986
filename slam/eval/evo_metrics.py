"""Accuracy through evo's API: APE and RPE of a run's TUM outputs.

* APE on the translation part (``evo.core.metrics.APE``, ``PoseRelation.translation_part``) after
  ``evo.core.sync.associate_trajectories``; no alignment by default (the published protocol has
  none), Umeyama SE(3) alignment (``PoseTrajectory3D.align``) as an option. The default
  association interpolates the denser trajectory at the times of the sparser one (evo's
  ``SyncMethod.interpolation``), so that against GPS the APE is taken at every GPS fix on the
  estimate interpolated there: the same errors as :mod:`sonarslam.slam.eval.ate` (a test checks it);
* RPE per travelled distance (``evo.core.metrics.RPE`` with ``delta_unit=Unit.meters``): the
  translation error of the relative motion between poses ``delta_m`` metres of path apart.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from evo.core import metrics as evo_metrics
from evo.core import sync as evo_sync
from evo.core.sync_method import SyncMethod
from evo.core.trajectory import PoseTrajectory3D
from evo.core.units import Unit

from sonarslam.slam.io.trajectory import GPS_FILE, Trajectory, read_tum, to_evo

__all__ = ["MAX_DIFF_S", "ErrorStats", "evo_ape", "evo_rpe", "evo_metrics_of_run"]

#: Largest time difference (s) of two poses associated by evo (the marina AHRS is ~10 Hz).
MAX_DIFF_S = 0.1


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
    stem: str,
    rpe_delta_m: float = 10.0,
    align: bool = False,
    max_diff_s: float = MAX_DIFF_S,
) -> dict[str, float | int]:
    """evo's APE and RPE of a run directory's ``<stem>.tum`` (``ekf.tum``) against its
    ``gps.tum`` (:mod:`sonarslam.slam.run.outputs`).

    Returns
    -------
    dict
        ``evo_ape_{rmse,mean,median,sd,min,max}_m``, ``evo_ape_n``, and the same for
        ``evo_rpe_{delta}m_...``; the RPE keys are absent when the path is shorter than
        ``rpe_delta_m``.
    """
    run = Path(run_dir)
    ref = read_tum(run / GPS_FILE)
    est = read_tum(run / f"{stem}.tum")
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
