"""The line feature extractor: the seed paper's method end to end, streaming (design.md 1-7).

``beam -> segmentation [2.1] -> sector store [2.2] -> every n beams: snapshot in R [2.3] ->
votes [2.4-2.5] -> winners, voters removed [2.5] -> uncertainty [2.6] -> LineFeature``.

Poses come only through a :class:`~sonarslam.features.pose_source.PoseSource` (the plugin seam).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from sonarslam.features.config import ExtractorConfig
from sonarslam.features.geometry import FloatArray
from sonarslam.features.hough import (
    HoughGrid,
    Votes,
    auto_h_bearings,
    auto_p_angles,
    find_winners,
    vote_arc_compiled,
    vote_samples,
)
from sonarslam.features.line import LineFeature
from sonarslam.features.pose_source import PoseSource, pose_covariances
from sonarslam.features.sector import BinsInR, Sector, SectorSnapshot
from sonarslam.features.uncertainty import (
    LineEstimate,
    effective_bearings,
    fit_line,
    relative_pose_covariances,
    seed_ellipse,
    support_mask,
)
from sonarslam.settings import SettingError
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead, beam_bin_size_m, bin_range_m
from sonarslam.sonar.segmentation import SegmentedBeam, segment_intensities

__all__ = ["LineExtractor", "segment_with"]

_DEG = float(np.pi / 180.0)

#: Raw beams: an ``intensity_threshold`` that more than this fraction of the in-range bins pass
#: (over the beams before the first vote) is refused: it does not tell echoes from background
#: (a 0/255 mask's threshold, 1, as the marina presets' on intensities passes nearly every bin).
MAX_THRESHOLD_PASS_FRACTION = 0.5


def segment_with(
    config: ExtractorConfig, bin_size_m: float, intensities: npt.ArrayLike, thresholded: bool
) -> SegmentedBeam:
    """One beam segmented with the extractor's settings (paper 2.1): the bins it keeps.

    Parameters
    ----------
    config : ExtractorConfig
    bin_size_m : float
        Range step between bins (m).
    intensities : array_like, shape (n_bins,)
    thresholded : bool
        A 0/255 mask (:attr:`sonarslam.sonar.beam.SonarBeam.thresholded`).
    """
    return segment_intensities(
        intensities,
        bin_size_m,
        intensity_threshold=config.intensity_threshold,
        max_intensity_difference=config.max_intensity_difference,
        min_distance_m=config.min_distance_m,
        min_range_m=config.min_range_m,
        thresholded=thresholded,
        max_range_m=config.max_range_m,
    )


def _trimmed_extent(t: FloatArray, frac: float) -> tuple[float, float]:
    if t.size == 0:
        return 0.0, 0.0
    lo, hi = np.quantile(t, [frac, 1.0 - frac])
    return float(lo), float(hi)


class LineExtractor:
    """Streaming line extraction from MSIS beams (design.md steps 1-7).

    Parameters
    ----------
    config : ExtractorConfig
    head : SonarHead
        Head settings: bins, bin size, step, beam width, angle sense.
    sonar_mounting : Mounting
        Pose of the sonar in the vehicle body frame, ``bTs``.
    pose_source : PoseSource
        Vehicle poses ``wTb`` at beam times (GPS+AHRS, dead reckoning, EKF, factor graph...).

    Notes
    -----
    :meth:`add` segments a beam and stores it; once the store holds a full sector it votes
    every ``vote_every_n_beams`` beams and returns the lines found. :meth:`flush` votes on what
    is stored now (the end of a stream).

    Raw beams (``beam.thresholded`` False) are checked once, at the first vote: if more than
    :data:`MAX_THRESHOLD_PASS_FRACTION` of their in-range bins pass ``intensity_threshold``,
    the threshold is a mask's (a preset for thresholded keyframes, ``marina*``, on intensities)
    or below the background, and the vote is refused with a
    :class:`~sonarslam.settings.SettingError` naming it. Masks are not checked: their threshold
    is the third party's (:mod:`sonarslam.sonar.segmentation`).

    Each :class:`~sonarslam.features.line.LineFeature` has ``t`` the newest beam's time, ``wTr`` its sonar
    pose (frame R), ``(rho_m, theta_rad)`` and ``cov`` in R, ``votes`` of the winning cell,
    ``n_voters`` the bins the line rests on (the winner's voters for "seed"; the fit's gated
    support for "fit"), all removed from the store, and ``endpoints_r`` the trimmed extent of
    their echoes along the line.
    """

    def __init__(
        self,
        config: ExtractorConfig,
        head: SonarHead,
        sonar_mounting: Mounting,
        pose_source: PoseSource,
    ) -> None:
        self.config = config
        self.head = head
        self.mounting = sonar_mounting
        self.pose_source = pose_source
        cfg = config
        self.beam_width_rad = (
            float(cfg.beam_width_rad) if cfg.beam_width_rad is not None else head.beam_width_rad
        )
        self.max_range_m = (
            head.range_max_m
            if cfg.max_range_m is None
            else min(float(cfg.max_range_m), head.range_max_m)
        )
        self.sector = Sector(
            head,
            sonar_mounting,
            pose_source,
            sector_rad=cfg.sector_deg * _DEG,
            requery_poses=cfg.requery_poses,
        )
        theta_res = cfg.theta_res_rad if cfg.theta_res_rad is not None else head.step_rad
        rho_res = cfg.rho_res_m if cfg.rho_res_m is not None else head.bin_size_m
        self.grid = HoughGrid.from_resolution(theta_res, rho_res, head.range_max_m)
        self.h_bearings = (
            cfg.h_bearings
            if cfg.h_bearings is not None
            else auto_h_bearings(
                self.beam_width_rad, cfg.incidence_beta_rad, rho_res, head.range_max_m
            )
        )
        self.p_angles = (
            cfg.p_angles
            if cfg.p_angles is not None
            else auto_p_angles(cfg.incidence_beta_rad, self.grid.theta_res_rad)
        )
        self.range_sigma_m = (
            cfg.range_sigma_m if cfg.range_sigma_m is not None else head.bin_size_m / np.sqrt(12)
        )
        self.range_offset_sigma_m = (
            cfg.range_offset_sigma_m
            if cfg.range_offset_sigma_m is not None
            else head.bin_size_m / np.sqrt(12)
        )
        self.bearing_sigma_rad = (
            cfg.bearing_sigma_rad
            if cfg.bearing_sigma_rad is not None
            else self.beam_width_rad / np.sqrt(12)
        )
        #: the systematic part of every line's covariance (``line_sigma_*``)
        self.line_systematic_cov = np.diag([cfg.line_sigma_rho_m, cfg.line_sigma_theta_rad]) ** 2
        self._since_vote = 0
        self.n_votes = 0
        #: bins a threshold is applied to, per beam of a bin size, and the raw beams' counts
        #: before the check
        self._bins_in_range: dict[float, int] = {}
        self._raw_bins_seen = 0
        self._raw_bins_passed = 0
        self._threshold_checked = False
        self._n_added = 0
        self._last_t_s = -np.inf

    # -- streaming -------------------------------------------------------------------------

    def add(self, beam: SonarBeam) -> list[LineFeature]:
        """Segment and store one beam; vote when due.

        Parameters
        ----------
        beam : SonarBeam
            Its ``t`` (Unix s) not earlier than the previous beam's (a repeated stamp is
            taken), its ``transducer_angle_rad`` finite and within 2 pi of zero.

        Returns
        -------
        list of LineFeature
            Lines of the vote made after this beam (empty if no vote was due).

        Raises
        ------
        SettingError
            Naming ``beam.t`` (a beam earlier than the one before: beams out of order, or
            reversed) or ``beam.transducer_angle_rad`` (NaN, or beyond 2 pi: degrees or
            gradians), with the beam's index among those added and its time.
        """
        self._check_beam(beam)
        cfg = self.config
        bin_m = beam_bin_size_m(beam, self.head)
        seg = segment_with(cfg, bin_m, beam.intensities, beam.thresholded)
        if not beam.thresholded and not self._threshold_checked:
            self._raw_bins_seen += self._in_range(bin_m)
            self._raw_bins_passed += int(seg.threshold_bins.size)
        bearing = float(self.head.angle_sense * beam.transducer_angle_rad)
        self.sector.add(float(beam.t), bearing, seg, beam.bin_size_m)
        self._since_vote += 1
        if self.sector.is_full and self._since_vote >= cfg.vote_every_n_beams:
            return self.vote()
        return []

    def _in_range(self, bin_size_m: float) -> int:
        """The bins of a beam of ``bin_size_m`` (m) that a threshold is applied to."""
        n = self._bins_in_range.get(bin_size_m)
        if n is None:
            ranges_m = bin_range_m(np.arange(self.head.n_bins), bin_size_m)
            inside = (ranges_m >= self.config.min_range_m) & (ranges_m <= self.max_range_m)
            n = self._bins_in_range[bin_size_m] = int(np.count_nonzero(inside))
        return n

    def _check_beam(self, beam: SonarBeam) -> None:
        """Refuse a beam earlier than the one before or with an angle that is not radians
        (:meth:`add`'s Raises); count it."""
        k, t = self._n_added, float(beam.t)
        if not t >= self._last_t_s:  # NaN too
            raise SettingError(
                "beam.t",
                f"beam {k} at {t:.3f} s (Unix) is earlier than beam {k - 1} at"
                f" {self._last_t_s:.3f} s: beams must be added in time order (shuffled or"
                " reversed beams give poses of the wrong time); sort them by time",
            )
        angle = float(beam.transducer_angle_rad)
        if not abs(angle) <= 2.0 * np.pi:
            why = (
                "is not a number"
                if np.isnan(angle)
                else "is beyond 2 pi rad: degrees or gradians? (np.radians, gradians * pi / 200)"
            )
            raise SettingError(
                "beam.transducer_angle_rad", f"beam {k} at {t:.3f} s (Unix): {angle:g} {why}"
            )
        self._n_added = k + 1
        self._last_t_s = t

    def flush(self) -> list[LineFeature]:
        """Vote on the stored beams if any arrived since the last vote (end of a stream)."""
        if self._since_vote == 0 or len(self.sector) == 0:
            return []
        return self.vote()

    # -- one vote --------------------------------------------------------------------------

    def cast_votes(self, bins: BinsInR) -> Votes:
        """Votes of the given bins in the grid (eqs. 2-4, :mod:`sonarslam.features.hough`)."""
        cfg = self.config
        if cfg.vote_model == "arc":  # compiled; the same votes as vote_arc's
            return vote_arc_compiled(
                bins.x_m,
                bins.y_m,
                bins.bearing_rad,
                bins.range_m,
                self.grid,
                self.beam_width_rad,
                cfg.incidence_beta_rad,
            )
        return vote_samples(
            bins.x_m,
            bins.y_m,
            bins.bearing_rad,
            bins.range_m,
            self.grid,
            self.beam_width_rad,
            cfg.incidence_beta_rad,
            self.h_bearings,
            self.p_angles,
        )

    def vote(self) -> list[LineFeature]:
        """Vote on the stored sector now: lines in the newest beam's sonar frame R."""
        cfg = self.config
        self._check_threshold()
        self._since_vote = 0
        self.n_votes += 1
        snap = self.sector.snapshot()  # paper 2.3: every stored bin in R
        fin = snap.final
        if len(fin) < cfg.min_votes:
            return []
        votes = self.cast_votes(fin)  # paper 2.4-2.5
        winners, _ = find_winners(
            votes,
            self.grid,
            cfg.min_votes,
            max_winners=cfg.max_lines_per_vote,
            suppress_theta_cells=cfg.suppress_theta_cells,
            suppress_rho_cells=cfg.suppress_rho_cells,
        )
        if not winners:
            return []
        pose_cov = self._pose_covariances(snap) if cfg.pose_uncertainty else None
        taken = np.zeros(len(fin), dtype=bool)  # bins used by this vote's earlier lines
        lines: list[LineFeature] = []
        for w in winners:
            assert fin.bin_id is not None
            if np.count_nonzero(taken[w.voters]) > 0.5 * w.voters.size:
                # most of its voters rest on a line of this vote already: the same wall
                self.sector.remove_final_bins(fin.bin_id[w.removed])
                taken[w.removed] = True
                continue
            est = self._estimate(w.cell, w.rho_m, w.theta_rad, fin.take(w.voters), snap, pose_cov)
            support = w.voters
            if cfg.covariance_method == "fit" and cfg.fit_gate_sigma > 0.0:
                est, support = self._refit_on_support(est, w.voters, fin, taken, pose_cov)
            used = fin.take(support)
            lines.append(
                LineFeature(
                    t=snap.t_ref_s,
                    wTr=snap.wTr.copy(),
                    rho_m=est.rho_m,
                    theta_rad=est.theta_rad,
                    cov=est.cov + self.line_systematic_cov,
                    votes=w.votes,
                    endpoints_r=self._endpoints(used, est.rho_m, est.theta_rad),
                    n_voters=int(support.size),
                    bTs=self.sector.bTs.copy(),
                )
            )
            gone = np.union1d(w.removed, support)
            if cfg.remove_on_line_sigma > 0.0:
                gone = np.union1d(gone, self._echoes_on_line(est, fin, taken))
            taken[gone] = True
            self.sector.remove_final_bins(fin.bin_id[gone])  # paper 2.5
        return lines

    def _check_threshold(self) -> None:
        """Refuse, once, an ``intensity_threshold`` that most in-range bins of the raw beams
        stored so far pass (the class's Notes)."""
        if self._threshold_checked:
            return
        self._threshold_checked = True
        if self._raw_bins_seen == 0:
            return
        fraction = self._raw_bins_passed / self._raw_bins_seen
        if fraction > MAX_THRESHOLD_PASS_FRACTION:
            raise SettingError(
                "extractor.intensity_threshold",
                f"{self.config.intensity_threshold:g} passes {100.0 * fraction:.0f} % of the"
                " in-range bins of these raw (unthresholded) intensity beams: it cannot tell"
                " echoes from background. A threshold for 0/255 masks (the marina presets',"
                " meant for thresholded keyframes) was given for intensities: use the"
                " 'default' preset (extractor_preset('default'), or the dataset's,"
                " extractor_preset(dataset)) or a threshold above the background",
            )

    def _refit_on_support(
        self,
        est: LineEstimate,
        voters: npt.NDArray[np.int64],
        fin: BinsInR,
        taken: npt.NDArray[np.bool_],
        pose_cov: FloatArray | None,
    ) -> tuple[LineEstimate, npt.NDArray[np.int64]]:
        """Refit on the bins within the gate of the line (see ``fit_gate_sigma``)."""
        cfg = self.config
        support = voters
        for _ in range(max(cfg.fit_gate_iterations, 1)):
            mask = ~taken & support_mask(
                fin,
                est.rho_m,
                est.theta_rad,
                beam_width_rad=self.beam_width_rad,
                incidence_beta_rad=cfg.incidence_beta_rad,
                range_sigma_m=self.range_sigma_m,
                bearing_sigma_rad=self.bearing_sigma_rad,
                return_model=cfg.return_model,
                gate_sigma=cfg.fit_gate_sigma,
            )
            idx = np.flatnonzero(mask)
            if idx.size < 3 or np.array_equal(idx, support):
                break
            support = idx
            est = self._fit(fin.take(support), est.rho_m, est.theta_rad, pose_cov)
        return est, support

    def _echoes_on_line(
        self, est: LineEstimate, fin: BinsInR, taken: npt.NDArray[np.bool_]
    ) -> npt.NDArray[np.int64]:
        """Untaken bins whose echoes lie on the line, from any beam facing it (see
        ``remove_on_line_sigma``)."""
        facing = 0.5 * np.pi - 0.5 * self.beam_width_rad  # incidence up to 90 deg
        mask = ~taken & support_mask(
            fin,
            est.rho_m,
            est.theta_rad,
            beam_width_rad=self.beam_width_rad,
            incidence_beta_rad=facing,
            range_sigma_m=self.range_sigma_m,
            bearing_sigma_rad=self.bearing_sigma_rad,
            return_model=self.config.return_model,
            gate_sigma=self.config.remove_on_line_sigma,
        )
        return np.flatnonzero(mask)

    def _pose_covariances(self, snap: SectorSnapshot) -> FloatArray | None:
        covs = pose_covariances(self.pose_source, snap.beam_t_s)
        if covs is None:
            return None
        return relative_pose_covariances(snap, covs, self.sector.bTs)

    def _estimate(
        self,
        cell: int,
        rho_m: float,
        theta_rad: float,
        voters: BinsInR,
        snap: SectorSnapshot,
        pose_cov: FloatArray | None,
    ) -> LineEstimate:
        cfg = self.config
        if cfg.covariance_method in ("seed", "seed-at-fit"):
            seed = seed_ellipse(
                cell,
                self.grid,
                snap,
                beam_width_rad=self.beam_width_rad,
                incidence_beta_rad=cfg.incidence_beta_rad,
                min_range_m=cfg.min_range_m,
                max_range_m=self.max_range_m,
                tol_m=0.5 * max(self.head.bin_size_m, self.grid.rho_res_m),
                confidence=cfg.confidence,
                similarity=cfg.overlap_similarity,
                window_theta_cells=cfg.seed_window_theta_cells,
                window_rho_cells=cfg.seed_window_rho_cells,
            )
            if pose_cov is None and cfg.covariance_method == "seed":
                return seed
            fit = self._fit(voters, seed.rho_m, seed.theta_rad, pose_cov)
            if cfg.covariance_method == "seed-at-fit":
                seed = replace(seed, rho_m=fit.rho_m, theta_rad=fit.theta_rad)
            if pose_cov is None:
                return seed
            # the ellipse knows nothing of the poses: add the fit's first-order pose term
            assert fit.pose_term is not None
            return replace(seed, cov=seed.cov + fit.pose_term)
        return self._fit(voters, rho_m, theta_rad, pose_cov)

    def _fit(
        self, bins: BinsInR, rho_m: float, theta_rad: float, pose_cov: FloatArray | None
    ) -> LineEstimate:
        return fit_line(
            bins,
            rho_m,
            theta_rad,
            beam_width_rad=self.beam_width_rad,
            range_sigma_m=self.range_sigma_m,
            bearing_sigma_rad=self.bearing_sigma_rad,
            return_model=self.config.return_model,
            n_iter=self.config.fit_iterations,
            pose_cov_r=pose_cov,
            range_offset_sigma_m=self.range_offset_sigma_m,
        )

    def _endpoints(self, voters: BinsInR, rho_m: float, theta_rad: float) -> FloatArray:
        """Ends of the segment: voters' echoes projected on the line, trimmed quantiles."""
        b = effective_bearings(
            voters, rho_m, theta_rad, self.beam_width_rad, self.config.return_model
        )
        px = voters.x_m + voters.range_m * np.cos(b)
        py = voters.y_m + voters.range_m * np.sin(b)
        n = np.array([np.cos(theta_rad), np.sin(theta_rad)])
        tangent = np.array([-n[1], n[0]])
        along = px * tangent[0] + py * tangent[1]
        lo, hi = _trimmed_extent(along, self.config.endpoint_trim_fraction)
        foot = rho_m * n
        return np.stack([foot + lo * tangent, foot + hi * tangent])
