"""The rolling store of the last sector of beams (design.md steps 2-3, paper 2.2-2.3).

The store holds the last ``n_beams`` segmented beams in a ring buffer of preallocated arrays;
``n_beams`` is the sector size divided by the head's mechanical step (180 deg at 0.9 deg: 200
beams; 180 deg at 1.8 deg: 100). Each beam keeps its time, its bearing in the sonar frame, its
threshold bins (ranges), its final bins (ranges, intensities, alive flags) and the sonar pose
in the world when it arrived. A new beam evicts the oldest.

At each vote, :meth:`SectorStore.snapshot` takes the newest beam's sonar pose as the reference
frame R and re-references every stored beam to R (the motion-distortion correction of paper 2.3):
for beam ``k`` with sonar pose ``wTs_k``, ``rTs_k = inverse(wTR) * wTs_k`` gives the sensor
position ``(x_S, y_S)`` in R and the beam bearing ``theta_S = yaw(rTs_k) + bearing_k``. The sonar
poses are either those cached at arrival or, by default, re-queried from the
:class:`~features.pose_source.PoseSource` for every stored beam time at each vote, so that a
smoothing back end's latest trajectory corrects the whole sector.

Winners' voters are removed with :meth:`SectorStore.remove_final_bins` (paper 2.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from features.geometry import FloatArray, between, compose, wrap_angle
from features.pose_source import PoseSource
from sonar.beam import Mounting, SonarHead
from sonar.segmentation import SegmentedBeam

__all__ = ["BinsInR", "SectorSnapshot", "SectorStore", "sector_beam_count"]

IntArray = npt.NDArray[np.int64]


def sector_beam_count(sector_rad: float, step_rad: float) -> int:
    """Number of beams of a sector: ``round(sector / step)``, at least 1.

    Parameters
    ----------
    sector_rad : float
        Angular span of the stored beams (rad), e.g. pi for 180 deg.
    step_rad : float
        Mechanical step of the head (rad).
    """
    if sector_rad <= 0.0:
        raise ValueError(f"sector must be positive, got {sector_rad} rad")
    return max(int(round(sector_rad / step_rad)), 1)


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
        Ids for :meth:`SectorStore.remove_final_bins` (final bins only).
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


class SectorStore:
    """Ring buffer of the last sector of segmented beams.

    Parameters
    ----------
    head : SonarHead
        Head settings (bin size, step, number of bins).
    sonar_mounting : Mounting
        Pose of the sonar in the vehicle body frame, ``bTs``.
    pose_source : PoseSource
        Vehicle poses ``wTb`` at beam times.
    sector_rad : float
        Angular span of the stored beams (rad); ``pi`` (180 deg) by default, ``1.5 pi`` or
        ``2 pi`` as settings. The capacity is :func:`sector_beam_count`.
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
        self.head = head
        self.bTs = sonar_mounting.as_pose()
        self.pose_source = pose_source
        self.requery_poses = bool(requery_poses)
        self.capacity = sector_beam_count(sector_rad, head.step_rad)
        cap, nb = self.capacity, head.n_bins
        self._t = np.zeros(cap)
        self._bearing = np.zeros(cap)
        self._wTs = np.zeros((cap, 3))
        self._thr_range = np.zeros((cap, nb))
        self._thr_count = np.zeros(cap, dtype=np.int64)
        self._fin_range = np.zeros((cap, nb))
        self._fin_int = np.zeros((cap, nb), dtype=np.uint8)
        self._fin_alive = np.zeros((cap, nb), dtype=bool)
        self._col = np.arange(nb)
        self._next = 0  # slot of the next beam
        self._size = 0
        self.n_added = 0

    def __len__(self) -> int:
        return self._size

    @property
    def is_full(self) -> bool:
        """True once the store holds a full sector of beams."""
        return self._size == self.capacity

    def clear(self) -> None:
        """Forget every stored beam."""
        self._size = 0
        self._next = 0
        self._fin_alive[:] = False
        self._thr_count[:] = 0

    def _sonar_poses(self, t_s: npt.ArrayLike) -> FloatArray:
        wTb = np.asarray(self.pose_source.poses(np.atleast_1d(t_s)), dtype=np.float64)
        return compose(wTb.reshape(-1, 3), self.bTs)

    def add(self, t_s: float, bearing_rad: float, segmented: SegmentedBeam) -> None:
        """Store one segmented beam, evicting the oldest when full.

        Parameters
        ----------
        t_s : float
            Beam time (Unix s).
        bearing_rad : float
            Beam bearing in the sonar frame (rad), ``head.bearing_rad(transducer_angle)``.
        segmented : SegmentedBeam
            Output of :func:`sonar.segmentation.segment_intensities` for this beam.
        """
        k = self._next  # when full, this is the oldest beam's slot: it is overwritten
        self._t[k] = t_s
        self._bearing[k] = bearing_rad
        if not self.requery_poses:
            self._wTs[k] = self._sonar_poses(t_s)[0]
        ranges = self.head.bin_size_m
        thr = segmented.threshold_bins
        self._thr_count[k] = thr.size
        self._thr_range[k, : thr.size] = (thr + 1.0) * ranges
        fin = segmented.final_bins
        self._fin_alive[k] = False
        self._fin_range[k, : fin.size] = (fin + 1.0) * ranges
        self._fin_int[k, : fin.size] = segmented.final_intensities
        self._fin_alive[k, : fin.size] = True
        self._next = (k + 1) % self.capacity
        self._size = min(self._size + 1, self.capacity)
        self.n_added += 1

    def _slots(self) -> IntArray:
        """Slots of the stored beams, oldest first."""
        start = (self._next - self._size) % self.capacity
        return (start + np.arange(self._size)) % self.capacity

    def remove_final_bins(self, bin_id: npt.ArrayLike) -> None:
        """Remove final bins (a winner's voters) from the store.

        Parameters
        ----------
        bin_id : array_like of int, shape (N,)
            Ids from :attr:`BinsInR.bin_id` of a snapshot taken since the last :meth:`add`.
        """
        ids = np.asarray(bin_id, dtype=np.int64)
        self._fin_alive.reshape(-1)[ids] = False

    def snapshot(self) -> SectorSnapshot:
        """All stored beams and bins re-referenced to the newest beam's sonar pose R."""
        if self._size == 0:
            raise ValueError("the sector store is empty")
        slots = self._slots()
        t = self._t[slots]
        wTs = self._sonar_poses(t) if self.requery_poses else self._wTs[slots]
        wTr = wTs[-1].copy()
        rTs = between(wTr, wTs)  # paper 2.3: every stored beam in the reference frame R
        bx, by = rTs[:, 0], rTs[:, 1]
        bbear = wrap_angle(rTs[:, 2] + self._bearing[slots])
        # final bins: alive flags of the stored slots, oldest first
        alive = self._fin_alive[slots]
        kb, col = np.nonzero(alive)
        sl = slots[kb]
        final = BinsInR(
            x_m=bx[kb],
            y_m=by[kb],
            bearing_rad=bbear[kb],
            range_m=self._fin_range[sl, col],
            beam=kb.astype(np.int64),
            intensity=self._fin_int[sl, col],
            bin_id=(sl * self.head.n_bins + col).astype(np.int64),
        )
        has_thr = self._col[None, :] < self._thr_count[slots][:, None]
        tb, tcol = np.nonzero(has_thr)
        threshold = BinsInR(
            x_m=bx[tb],
            y_m=by[tb],
            bearing_rad=bbear[tb],
            range_m=self._thr_range[slots[tb], tcol],
            beam=tb.astype(np.int64),
        )
        return SectorSnapshot(
            t_ref_s=float(t[-1]),
            wTr=wTr,
            beam_t_s=t,
            beam_wTs=wTs,
            beam_x_m=bx,
            beam_y_m=by,
            beam_bearing_rad=bbear,
            final=final,
            threshold=threshold,
        )
