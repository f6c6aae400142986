"""The line feature extractor: the seed paper's method end to end, streaming (design.md 1-7).

``beam -> segmentation [2.1] -> sector store [2.2] -> every n beams: snapshot in R [2.3] ->
votes [2.4-2.5] -> winners, voters removed [2.5] -> uncertainty [2.6] -> LineFeature``.

Poses come only through a :class:`~features.pose_source.PoseSource` (the plugin seam).
"""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from features.geometry import FloatArray
from features.hough import (
    HoughGrid,
    Votes,
    auto_h_bearings,
    auto_p_angles,
    find_winners,
    vote_arc,
    vote_samples,
)
from features.line import LineFeature
from features.pose_source import PoseSource
from features.sector import BinsInR, Sector, SectorSnapshot
from features.uncertainty import (
    LineEstimate,
    effective_bearings,
    fit_line,
    relative_pose_covariances,
    seed_ellipse,
    support_mask,
)
from sonar.beam import Mounting, SonarBeam, SonarHead
from sonar.segmentation import segment_intensities

__all__ = ["ExtractorConfig", "MARINA_PRESET", "LineExtractor"]

_DEG = float(np.pi / 180.0)


@dataclass(frozen=True)
class ExtractorConfig:
    """Settings of :class:`LineExtractor`, with units in the names.

    Defaults marked *paper* are those of the seed paper (Song et al. 2010, section 3: sector,
    beta, min votes, confidence); the others are this project's choices, stated here.

    Attributes
    ----------
    intensity_threshold : float
        Segmentation (a): threshold bins have intensity ``>=`` this (0-255). 80.
    max_intensity_difference : float
        Segmentation (b): keep bins within this of the beam's strongest (0-255). 40.
    min_distance_m : float
        Segmentation (c): of two kept bins closer than this, drop the weaker (m). 0.5.
    min_range_m : float
        Near-field dead zone (m). 0.5.
    max_range_m : float or None
        Bins beyond this range (m) take no part (None: the head's range). On thick echo bands
        a wall seen far off and at a slant gives a line metres off the wall.
    sector_deg : float
        Angular span of the stored beams (deg): 180 (*paper*); 270 and 360 are settings.
    beam_width_rad : float or None
        Horizontal beam width ``alpha`` (rad); None takes the head's.
    incidence_beta_rad : float
        Largest incidence that still returns, ``beta`` (rad): 25 deg (*paper*).
    vote_model : {"arc", "samples"}
        How eqs. 2-4 cast votes (see :mod:`features.hough`): "arc" (continuous arc, default) or
        "samples" (the ``h x p`` samples literally).
    h_bearings, p_angles : int or None
        Samples of eqs. 2 and 3 for ``vote_model="samples"``; None chooses them from the
        resolution (:func:`~features.hough.auto_h_bearings`, :func:`~features.hough.auto_p_angles`).
    theta_res_rad : float or None
        Voting-space cell in ``theta`` (rad); None takes the head's step (paper 2.4).
    rho_res_m : float or None
        Voting-space cell in ``rho`` (m); None takes the bin size (paper 2.4).
    min_votes : int
        Votes needed by a line: 15 (*paper*, pool test).
    max_lines_per_vote : int
        Most lines per vote. 16.
    suppress_theta_cells, suppress_rho_cells : int
        Half sizes of the window around a winner whose voters are removed with it (cells). 1, 1.
    vote_every_n_beams : int
        Beams between votes once the store holds a full sector. 10.
    requery_poses : bool
        Re-query the pose source for every stored beam at each vote (smoothing back ends). True.
    covariance_method : {"fit", "seed"}
        :mod:`features.uncertainty` method: "fit" (weighted least squares) or "seed" (the
        paper's overlap-ratio ellipse; its line is the ellipse centre).
    confidence : float
        Probability of the seed ellipse: 0.95 (*paper*).
    overlap_similarity : float
        Seed: similar cells have an overlap ratio ``>=`` this times the winner's. 0.8.
    seed_window_theta_cells, seed_window_rho_cells : int
        Seed: half sizes of the searched neighbourhood (cells). 20, 10: the similar-overlap
        region of a wall is long in theta (the beam width hides small rotations).
    return_model : {"axis", "first_return"}
        Fit: where in the beam a final bin's echo comes from. "axis" for raw intensities (the
        strongest bin), "first_return" for thresholded masks (the nearest bin of a run).
    range_sigma_m : float or None
        Fit: range noise of a bin (m); None: ``bin_size / sqrt(12)``.
    bearing_sigma_rad : float or None
        Fit: bearing noise across the beam (rad); None: ``beam_width / sqrt(12)``.
    range_offset_sigma_m : float or None
        Fit: range error common to all the bins (m): where the wall is inside the bin of an
        echo's peak or first return, which does not average down with the number of voters
        (:mod:`features.uncertainty`); None: ``bin_size / sqrt(12)``; 0 leaves it out.
    pose_uncertainty : bool
        Fit: add the relative pose uncertainty from ``PoseSource.covariance``. False.
    fit_iterations : int
        Fit: Gauss-Newton iterations. 5.
    fit_gate_sigma : float
        Fit: after fitting the winner's voters, the fit is redone on every stored final bin
        whose echo lies within this many sigmas of the line (from a beam that sees it), so
        that the voters' truncation to one rho cell does not bias it; 0 fits the voters only. 3.
    fit_gate_iterations : int
        Fit: rounds of gathering the support and refitting. 2.
    endpoint_trim_fraction : float
        Segment ends are the ``f`` and ``1 - f`` quantiles of the voters along the line. 0.05.
    remove_on_line_sigma : float
        After a line is found, the stored final bins whose echoes lie within this many sigmas of
        it are removed with its voters, *at any incidence* (from every beam that faces it). A wall
        also returns echoes beyond ``beta`` (the simulator's walls return up to ~60 deg); the
        sonar model cannot give them to the wall's line, so left in the store they voted for
        spurious lines a few degrees off the wall (3-4 per 270 deg pool scan, 3-30 deg off).
        Not in the paper (it removes the voters only); 0 disables. 3.
    """

    intensity_threshold: float = 80.0
    max_intensity_difference: float = 40.0
    min_distance_m: float = 0.5
    min_range_m: float = 0.5
    max_range_m: float | None = None
    sector_deg: float = 180.0
    beam_width_rad: float | None = None
    incidence_beta_rad: float = 25.0 * _DEG
    vote_model: str = "arc"
    h_bearings: int | None = None
    p_angles: int | None = None
    theta_res_rad: float | None = None
    rho_res_m: float | None = None
    min_votes: int = 15
    max_lines_per_vote: int = 16
    suppress_theta_cells: int = 1
    suppress_rho_cells: int = 1
    vote_every_n_beams: int = 10
    requery_poses: bool = True
    covariance_method: str = "fit"
    confidence: float = 0.95
    overlap_similarity: float = 0.8
    seed_window_theta_cells: int = 20
    seed_window_rho_cells: int = 10
    return_model: str = "axis"
    range_sigma_m: float | None = None
    bearing_sigma_rad: float | None = None
    range_offset_sigma_m: float | None = None
    pose_uncertainty: bool = False
    fit_iterations: int = 5
    fit_gate_sigma: float = 3.0
    fit_gate_iterations: int = 2
    endpoint_trim_fraction: float = 0.05
    remove_on_line_sigma: float = 3.0

    def __post_init__(self) -> None:
        if self.vote_model not in ("arc", "samples"):
            raise ValueError(f"vote_model must be 'arc' or 'samples', got {self.vote_model!r}")
        if self.covariance_method not in ("fit", "seed"):
            raise ValueError(
                f"covariance_method must be 'fit' or 'seed', got {self.covariance_method!r}"
            )
        if self.return_model not in ("axis", "first_return"):
            raise ValueError(
                f"return_model must be 'axis' or 'first_return', got {self.return_model!r}"
            )
        if not 0.0 < self.sector_deg <= 360.0:
            raise ValueError(f"sector_deg must be in (0, 360], got {self.sector_deg}")
        if self.vote_every_n_beams < 1 or self.min_votes < 1:
            raise ValueError("vote_every_n_beams and min_votes must be >= 1")
        if not 0.0 < self.confidence < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence}")
        if not 0.0 <= self.endpoint_trim_fraction < 0.5:
            raise ValueError("endpoint_trim_fraction must be in [0, 0.5)")
        if not 0.0 < self.incidence_beta_rad < 0.5 * np.pi:
            raise ValueError("incidence_beta_rad must be in (0, pi/2)")
        if self.remove_on_line_sigma < 0.0:
            raise ValueError("remove_on_line_sigma must be >= 0")
        if self.max_range_m is not None and not self.max_range_m > self.min_range_m:
            raise ValueError(
                f"max_range_m must be > min_range_m ({self.min_range_m}), got {self.max_range_m}"
            )
        if self.range_offset_sigma_m is not None and self.range_offset_sigma_m < 0.0:
            raise ValueError("range_offset_sigma_m must be >= 0 (or None)")

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> ExtractorConfig:
        """Config from a mapping of field names (unknown names are an error)."""
        known = {f.name for f in fields(cls)}
        unknown = set(values) - known
        if unknown:
            raise ValueError(f"unknown ExtractorConfig fields: {sorted(unknown)}")
        return cls(**values)

    @classmethod
    def from_toml(cls, path: str | Path, table: str | None = "extractor") -> ExtractorConfig:
        """Load from a TOML file: the ``[extractor]`` table if present, else the top level.

        Fields left out take their defaults; ``None`` fields are left out to stay None.
        """
        with open(path, "rb") as f:
            data = tomllib.load(f)
        if table is not None and table in data:
            data = data[table]
        return cls.from_dict(data)

    def to_dict(self) -> dict[str, Any]:
        """All fields, ``None`` ones included (TOML has no null: drop them to write TOML)."""
        return asdict(self)

    def replace(self, **changes: Any) -> ExtractorConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)


MARINA_PRESET = ExtractorConfig(
    # The marina keyframes (datasets/marina/README.md): Miniking, 1.8 deg step, 0.1 m bins,
    # 50 m range, 3 deg beam; beams are 0/255 masks (a third party's threshold, first 10 bins
    # dropped), with ~0.7 echo runs of ~3 m per beam. Untested on the real data here: a preset
    # to start from, not a calibration.
    intensity_threshold=1.0,  # unused for masks: every given bin is a threshold bin
    max_intensity_difference=0.0,  # masks: all bins equal, all kept
    min_distance_m=1.0,  # keep the first return of each run (runs are ~3 m thick)
    min_range_m=1.0,  # the keyframes drop the bins below 1 m anyway
    sector_deg=180.0,  # 100 beams
    incidence_beta_rad=25.0 * _DEG,
    theta_res_rad=1.8 * _DEG,  # the head step
    rho_res_m=0.3,  # 3 bins: the first bin of a smoothed echo jitters by a few bins
    min_votes=10,  # walls 10-50 m away give ~0.7 first returns per beam; a wall at 30 m
    # subtends the arc-model window (2 beta + alpha = 53 deg, ~29 beams) only in part
    suppress_theta_cells=1,
    suppress_rho_cells=2,
    vote_every_n_beams=20,  # 36 deg of scan between votes: >= 200x real time
    return_model="first_return",  # the nearest bin of each run of a mask
    range_sigma_m=0.15,
    requery_poses=True,
    covariance_method="fit",
)
"""Preset for the marina keyframes (see the comments in the source)."""


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

    Each :class:`~features.line.LineFeature` has ``t`` the newest beam's time, ``wTr`` its sonar
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
        self._since_vote = 0
        self.n_votes = 0

    # -- streaming -------------------------------------------------------------------------

    def add(self, beam: SonarBeam) -> list[LineFeature]:
        """Segment and store one beam; vote when due.

        Parameters
        ----------
        beam : SonarBeam

        Returns
        -------
        list of LineFeature
            Lines of the vote made after this beam (empty if no vote was due).
        """
        cfg = self.config
        seg = segment_intensities(
            beam.intensities,
            self.head.bin_size_m,
            intensity_threshold=cfg.intensity_threshold,
            max_intensity_difference=cfg.max_intensity_difference,
            min_distance_m=cfg.min_distance_m,
            min_range_m=cfg.min_range_m,
            thresholded=beam.thresholded,
            max_range_m=cfg.max_range_m,
        )
        bearing = float(self.head.angle_sense * beam.transducer_angle_rad)
        self.sector.add(float(beam.t), bearing, seg)
        self._since_vote += 1
        if self.sector.is_full and self._since_vote >= cfg.vote_every_n_beams:
            return self.vote()
        return []

    def flush(self) -> list[LineFeature]:
        """Vote on the stored beams if any arrived since the last vote (end of a stream)."""
        if self._since_vote == 0 or len(self.sector) == 0:
            return []
        return self.vote()

    # -- one vote --------------------------------------------------------------------------

    def cast_votes(self, bins: BinsInR) -> Votes:
        """Votes of the given bins in the grid (eqs. 2-4, :mod:`features.hough`)."""
        cfg = self.config
        if cfg.vote_model == "arc":
            return vote_arc(
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
                    cov=est.cov,
                    votes=w.votes,
                    endpoints_r=self._endpoints(used, est.rho_m, est.theta_rad),
                    n_voters=int(support.size),
                )
            )
            gone = np.union1d(w.removed, support)
            if cfg.remove_on_line_sigma > 0.0:
                gone = np.union1d(gone, self._echoes_on_line(est, fin, taken))
            taken[gone] = True
            self.sector.remove_final_bins(fin.bin_id[gone])  # paper 2.5
        return lines

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
        covs = [self.pose_source.covariance(float(t)) for t in snap.beam_t_s]
        if any(c is None for c in covs):
            return None
        return relative_pose_covariances(
            snap, np.stack([np.asarray(c, dtype=np.float64) for c in covs]), self.sector.bTs
        )

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
        if cfg.covariance_method == "seed":
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
            if pose_cov is None:
                return seed
            # the ellipse knows nothing of the poses: add the fit's first-order pose term
            term = self._fit(voters, seed.rho_m, seed.theta_rad, pose_cov).pose_term
            assert term is not None
            return replace(seed, cov=seed.cov + term)
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
