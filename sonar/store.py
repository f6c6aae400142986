"""The rolling store of the last sector of beams, in the sensor's own frame (design.md step 2,
paper 2.2).

The store holds the last ``capacity`` segmented beams in a ring buffer of preallocated arrays;
``capacity`` is the sector size divided by the head's mechanical step (180 deg at 0.9 deg: 200
beams; 180 deg at 1.8 deg: 100). Each beam keeps its time, its bearing in the sonar frame, its
threshold bins (ranges) and its final bins (ranges, intensities, alive flags). A new beam evicts
the oldest. The store knows nothing of poses: putting the beams in one frame (the motion
correction, paper 2.3) is the front end's job (:mod:`sonarslam.features.sector`).

Winners' voters are removed with :meth:`SectorStore.remove_final_bins` (paper 2.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sonarslam.sonar.beam import FloatArray, SonarHead
from sonarslam.sonar.segmentation import SegmentedBeam

__all__ = ["StoredBins", "StoredSector", "SectorStore", "sector_beam_count"]

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
class StoredBins:
    """Bins of the stored beams, one entry per bin, in the sonar frame of their own beam.

    Attributes
    ----------
    beam : ndarray of int64, shape (N,)
        Index of the bin's beam among the stored beams (0 = oldest).
    range_m : ndarray, shape (N,)
        Range of the bin (m).
    intensity : ndarray of uint8, shape (N,) or None
        Intensities (final bins only).
    bin_id : ndarray of int64, shape (N,) or None
        Ids for :meth:`SectorStore.remove_final_bins` (final bins only).
    """

    beam: IntArray
    range_m: FloatArray
    intensity: npt.NDArray[np.uint8] | None = None
    bin_id: IntArray | None = None


@dataclass(frozen=True, eq=False)
class StoredSector:
    """The stored beams, oldest first, and their bins.

    Attributes
    ----------
    t_s : ndarray, shape (B,)
        Beam times (Unix s).
    bearing_rad : ndarray, shape (B,)
        Beam bearings in the sonar frame (rad), ``head.bearing_rad(transducer_angle)``.
    slot : ndarray of int64, shape (B,)
        Ring-buffer slot of each beam: its id while it is stored.
    final : StoredBins
        The alive final bins (the voters).
    threshold : StoredBins
        The threshold bins (for the uncertainty step).
    """

    t_s: FloatArray
    bearing_rad: FloatArray
    slot: IntArray
    final: StoredBins
    threshold: StoredBins


class SectorStore:
    """Ring buffer of the last sector of segmented beams.

    Parameters
    ----------
    head : SonarHead
        Head settings (bin size, step, number of bins).
    sector_rad : float
        Angular span of the stored beams (rad); ``pi`` (180 deg) by default, ``1.5 pi`` or
        ``2 pi`` as settings. The capacity is :func:`sector_beam_count`.
    """

    def __init__(self, head: SonarHead, sector_rad: float = np.pi) -> None:
        self.head = head
        self.capacity = sector_beam_count(sector_rad, head.step_rad)
        cap, nb = self.capacity, head.n_bins
        self._t = np.zeros(cap)
        self._bearing = np.zeros(cap)
        self._thr_range = np.zeros((cap, nb))
        self._thr_count = np.zeros(cap, dtype=np.int64)
        self._fin_range = np.zeros((cap, nb))
        self._fin_int = np.zeros((cap, nb), dtype=np.uint8)
        self._fin_alive = np.zeros((cap, nb), dtype=bool)
        # final bins fill the first columns of their row: stored() scans only up to the most
        self._fin_count = np.zeros(cap, dtype=np.int64)
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
        self._fin_count[:] = 0
        self._thr_count[:] = 0

    def add(
        self,
        t_s: float,
        bearing_rad: float,
        segmented: SegmentedBeam,
        bin_size_m: float | None = None,
    ) -> int:
        """Store one segmented beam, evicting the oldest when full; returns its slot.

        Parameters
        ----------
        t_s : float
            Beam time (Unix s).
        bearing_rad : float
            Beam bearing in the sonar frame (rad), ``head.bearing_rad(transducer_angle)``.
        segmented : SegmentedBeam
            Output of :func:`sonarslam.sonar.segmentation.segment_intensities` for this beam.
        bin_size_m : float, optional
            The beam's own range step between bins (m,
            :func:`sonarslam.sonar.beam.beam_bin_size_m`); None: the head's. Its bins must
            fit the head's ``n_bins``.
        """
        k = self._next  # when full, this is the oldest beam's slot: it is overwritten
        self._t[k] = t_s
        self._bearing[k] = bearing_rad
        thr = segmented.threshold_bins
        self._thr_count[k] = thr.size
        self._thr_range[k, : thr.size] = self.head.bin_range_m(thr, bin_size_m)
        fin = segmented.final_bins
        self._fin_alive[k] = False
        self._fin_range[k, : fin.size] = self.head.bin_range_m(fin, bin_size_m)
        self._fin_int[k, : fin.size] = segmented.final_intensities
        self._fin_alive[k, : fin.size] = True
        self._fin_count[k] = fin.size
        self._next = (k + 1) % self.capacity
        self._size = min(self._size + 1, self.capacity)
        self.n_added += 1
        return k

    def _slots(self) -> IntArray:
        """Slots of the stored beams, oldest first."""
        start = (self._next - self._size) % self.capacity
        return (start + np.arange(self._size)) % self.capacity

    def remove_final_bins(self, bin_id: npt.ArrayLike) -> None:
        """Remove final bins (a winner's voters) from the store.

        Parameters
        ----------
        bin_id : array_like of int, shape (N,)
            Ids from :attr:`StoredBins.bin_id` of a :meth:`stored` view taken since the last
            :meth:`add`.
        """
        ids = np.asarray(bin_id, dtype=np.int64)
        self._fin_alive.reshape(-1)[ids] = False

    def stored(self) -> StoredSector:
        """The stored beams, oldest first, with their alive final bins and threshold bins."""
        if self._size == 0:
            raise ValueError("the sector store is empty")
        slots = self._slots()
        # the alive flags past a row's final bins are all False: nonzero over the first
        # columns only gives the same bins in the same (row-major) order
        width = int(self._fin_count[slots].max())
        kb, col = np.nonzero(self._fin_alive[slots, :width])
        sl = slots[kb]
        final = StoredBins(
            beam=kb.astype(np.int64),
            range_m=self._fin_range[sl, col],
            intensity=self._fin_int[sl, col],
            bin_id=(sl * self.head.n_bins + col).astype(np.int64),
        )
        # threshold bins: the first count columns of each row, beam by beam
        counts = self._thr_count[slots]
        tb = np.repeat(np.arange(slots.size, dtype=np.int64), counts)
        tcol = np.arange(tb.size, dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
        threshold = StoredBins(beam=tb, range_m=self._thr_range[slots[tb], tcol])
        return StoredSector(
            t_s=self._t[slots],
            bearing_rad=self._bearing[slots],
            slot=slots.astype(np.int64),
            final=final,
            threshold=threshold,
        )
