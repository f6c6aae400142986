"""The stored sector in the reference frame R of one vote: the motion correction (design.md
step 3, paper 2.3-2.4).

At each vote the newest beam's sonar pose is the reference frame R and every stored beam is
re-referenced to R with the pose of its own time: for beam ``k`` with sonar pose ``wTs_k``,
``rTs_k = inverse(wTR) * wTs_k`` gives the sensor position ``(x_S, y_S)`` in R and the beam
bearing ``theta_S = yaw(rTs_k) + bearing_k``. The poses come from a
:class:`~sonarslam.features.pose_source.PoseSource`: either cached when each beam arrived or, by default,
re-queried for every stored beam time at each vote, so that a smoothing back end's latest
trajectory corrects the whole sector.

:class:`Sector` pairs the sensor-frame ring buffer (:class:`sonarslam.sonar.store.SectorStore`) with the
pose source; :func:`reference_to_newest` is the re-referencing itself.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray, between, compose, wrap_angle
from sonarslam.features.pose_source import (
    PoseSource,
    PoseSpanWarning,
    checked_poses,
    outside_span,
)
from sonarslam.sonar.beam import Mounting, SonarHead
from sonarslam.sonar.segmentation import SegmentedBeam
from sonarslam.sonar.store import SectorStore, StoredSector

__all__ = ["BinsInR", "SectorSnapshot", "Sector", "reference_to_newest"]

IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class BinsInR:
    """Stored bins re-referenced to frame R, one entry per bin.

    Attributes
    ----------
    x_m, y_m : ndarray, shape (N,)
        Position of the sensor of the bin's beam in R (m).
    bearing_rad : ndarray, shape (N,)
        Bearing ``theta_S`` of the bin's beam axis in R (sensor yaw in R + beam bearing),
        in ``[-pi, pi)``.
    range_m : ndarray, shape (N,)
        Range ``rho_S`` of the bin (m).
    beam : ndarray of int64, shape (N,)
        Index of the bin's beam in the snapshot's beam arrays (0 = oldest).
    intensity : ndarray of uint8, shape (N,) or None
        Intensities (final bins only).
    bin_id : ndarray of int64, shape (N,) or None
        Ids for :meth:`Sector.remove_final_bins` (final bins only).
    """

    x_m: FloatArray
    y_m: FloatArray
    bearing_rad: FloatArray
    range_m: FloatArray
    beam: IntArray
    intensity: npt.NDArray[np.uint8] | None = None
    bin_id: IntArray | None = None

    def __len__(self) -> int:
        return int(self.range_m.shape[0])

    def take(self, index: npt.ArrayLike) -> BinsInR:
        """The subset of bins at ``index`` (integer or boolean array)."""
        i = np.asarray(index)
        return BinsInR(
            x_m=self.x_m[i],
            y_m=self.y_m[i],
            bearing_rad=self.bearing_rad[i],
            range_m=self.range_m[i],
            beam=self.beam[i],
            intensity=None if self.intensity is None else self.intensity[i],
            bin_id=None if self.bin_id is None else self.bin_id[i],
        )

    def points_m(self) -> FloatArray:
        """Beam-axis points of the bins in R, shape (N, 2) (m)."""
        return np.stack(
            [
                self.x_m + self.range_m * np.cos(self.bearing_rad),
                self.y_m + self.range_m * np.sin(self.bearing_rad),
            ],
            axis=-1,
        )


@dataclass(frozen=True, eq=False)
class SectorSnapshot:
    """All stored beams and bins in the reference frame R of one vote.

    Attributes
    ----------
    t_ref_s : float
        Time of the newest beam (Unix s).
    wTr : ndarray, shape (3,)
        Sonar pose of the newest beam in the world: frame R.
    beam_t_s : ndarray, shape (B,)
        Times of the stored beams, oldest first (Unix s).
    beam_wTs : ndarray, shape (B, 3)
        Sonar poses of the stored beams in the world.
    beam_x_m, beam_y_m, beam_bearing_rad : ndarray, shape (B,)
        Sensor position (m) and beam-axis bearing (rad, ``[-pi, pi)``) of each beam in R.
    final : BinsInR
        The alive final bins (the voters).
    threshold : BinsInR
        The threshold bins (for the uncertainty step).
    """

    t_ref_s: float
    wTr: FloatArray
    beam_t_s: FloatArray
    beam_wTs: FloatArray
    beam_x_m: FloatArray
    beam_y_m: FloatArray
    beam_bearing_rad: FloatArray
    final: BinsInR
    threshold: BinsInR

    @property
    def n_beams(self) -> int:
        return int(self.beam_t_s.shape[0])


def reference_to_newest(stored: StoredSector, beam_wTs: FloatArray) -> SectorSnapshot:
    """Re-reference every stored bin to the newest beam's sonar pose R (paper 2.3).

    Parameters
    ----------
    stored : StoredSector
        The sensor-frame store's content, oldest beam first.
    beam_wTs : ndarray, shape (B, 3)
        Sonar pose ``wTs`` of each stored beam.
    """
    wTr = beam_wTs[-1].copy()
    rTs = between(wTr, beam_wTs)
    bx, by = rTs[:, 0], rTs[:, 1]
    bbear = wrap_angle(rTs[:, 2] + stored.bearing_rad)
    f, th = stored.final, stored.threshold
    final = BinsInR(
        x_m=bx[f.beam],
        y_m=by[f.beam],
        bearing_rad=bbear[f.beam],
        range_m=f.range_m,
        beam=f.beam,
        intensity=f.intensity,
        bin_id=f.bin_id,
    )
    threshold = BinsInR(
        x_m=bx[th.beam],
        y_m=by[th.beam],
        bearing_rad=bbear[th.beam],
        range_m=th.range_m,
        beam=th.beam,
    )
    return SectorSnapshot(
        t_ref_s=float(stored.t_s[-1]),
        wTr=wTr,
        beam_t_s=stored.t_s,
        beam_wTs=beam_wTs,
        beam_x_m=bx,
        beam_y_m=by,
        beam_bearing_rad=bbear,
        final=final,
        threshold=threshold,
    )


class Sector:
    """The sensor-frame store of the last sector with the pose of each beam.

    Parameters
    ----------
    head : SonarHead
        Head settings (bin size, step, number of bins).
    sonar_mounting : Mounting
        Pose of the sonar in the vehicle body frame, ``bTs``.
    pose_source : PoseSource
        Vehicle poses ``wTb`` at beam times.
    sector_rad : float
        Angular span of the stored beams (rad), see :class:`sonarslam.sonar.store.SectorStore`.
    requery_poses : bool
        Re-query ``pose_source`` for every stored beam time at each snapshot (default); if
        False, use the poses cached when each beam arrived.
    """

    def __init__(
        self,
        head: SonarHead,
        sonar_mounting: Mounting,
        pose_source: PoseSource,
        sector_rad: float = np.pi,
        requery_poses: bool = True,
    ) -> None:
        self.store = SectorStore(head, sector_rad)
        self.bTs = sonar_mounting.as_pose()
        self.pose_source = pose_source
        self.requery_poses = bool(requery_poses)
        self._wTs = np.zeros((self.store.capacity, 3))  # poses cached at arrival, by slot
        self._span_warned = False

    @property
    def capacity(self) -> int:
        return self.store.capacity

    @property
    def is_full(self) -> bool:
        return self.store.is_full

    def __len__(self) -> int:
        return len(self.store)

    def sonar_poses(self, t_s: npt.ArrayLike) -> FloatArray:
        """Sonar poses ``wTs`` at increasing times ``t_s`` from the pose source, shape (N, 3)
        (:func:`sonarslam.features.pose_source.checked_poses`: a ValueError for a yaw in
        degrees; a :class:`~sonarslam.features.pose_source.PoseSpanWarning`, the first time,
        for times outside the source's ``span_s``)."""
        if not self._span_warned:
            missed = outside_span(self.pose_source, t_s)
            if missed is not None:
                self._span_warned = True
                said = (
                    f"{missed} (the beams of the first vote that met any: said once per"
                    " extractor, later votes may hold more)"
                )
                warnings.warn(said, PoseSpanWarning, stacklevel=5)
        return compose(checked_poses(self.pose_source, t_s), self.bTs)

    def add(
        self,
        t_s: float,
        bearing_rad: float,
        segmented: SegmentedBeam,
        bin_size_m: float | None = None,
    ) -> None:
        """Store one segmented beam of its own bin size (m; None: the head's)
        (:meth:`sonarslam.sonar.store.SectorStore.add`)."""
        slot = self.store.add(t_s, bearing_rad, segmented, bin_size_m)
        if not self.requery_poses:
            self._wTs[slot] = self.sonar_poses(t_s)[0]

    def remove_final_bins(self, bin_id: npt.ArrayLike) -> None:
        """Remove final bins (a winner's voters), ids from :attr:`BinsInR.bin_id`."""
        self.store.remove_final_bins(bin_id)

    def snapshot(self) -> SectorSnapshot:
        """All stored beams and bins re-referenced to the newest beam's sonar pose R."""
        stored = self.store.stored()
        wTs = self.sonar_poses(stored.t_s) if self.requery_poses else self._wTs[stored.slot]
        return reference_to_newest(stored, wTs)
