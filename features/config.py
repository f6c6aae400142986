"""Settings of the line extractor (:class:`sonarslam.features.extractor.LineExtractor`), with units in
the names, loadable from TOML."""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.settings import bounded, check_fields, one_of, replace_checked

__all__ = ["ExtractorConfig"]

_DEG = float(np.pi / 180.0)


@dataclass(frozen=True)
class ExtractorConfig:
    """Settings of :class:`LineExtractor`, with units in the names.

    Defaults marked *paper* are those of the seed paper (Song et al. 2010, section 3: sector,
    beta, min votes, confidence); the others are this project's choices, stated here. Settings
    for particular sonars and data (the marina's thresholded keyframes, the seed paper's pool)
    are presets, decided in :mod:`sonarslam.slam.run.presets`. Each field's default and range
    are in its definition below.

    Attributes
    ----------
    intensity_threshold : float
        Segmentation (a): threshold bins have intensity ``>=`` this (0-255).
    max_intensity_difference : float
        Segmentation (b): keep bins within this of the beam's strongest (0-255).
    min_distance_m : float
        Segmentation (c): of two kept bins closer than this, drop the weaker (m).
    min_range_m : float
        Near-field dead zone (m).
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
        How eqs. 2-4 cast votes (see :mod:`sonarslam.features.hough`): "arc" (continuous arc, default) or
        "samples" (the ``h x p`` samples literally).
    h_bearings, p_angles : int or None
        Samples of eqs. 2 and 3 for ``vote_model="samples"``; None chooses them from the
        resolution (:func:`~sonarslam.features.hough.auto_h_bearings`, :func:`~sonarslam.features.hough.auto_p_angles`).
    theta_res_rad : float or None
        Voting-space cell in ``theta`` (rad); None takes the head's step (paper 2.4).
    rho_res_m : float or None
        Voting-space cell in ``rho`` (m); None takes the bin size (paper 2.4).
    min_votes : int
        Votes needed by a line: 15 (*paper*, pool test).
    max_lines_per_vote : int
        Most lines per vote.
    suppress_theta_cells, suppress_rho_cells : int
        Half sizes of the window around a winner whose voters are removed with it (cells).
    vote_every_n_beams : int
        Beams between votes once the store holds a full sector.
    requery_poses : bool
        Re-query the pose source for every stored beam at each vote (smoothing back ends).
    covariance_method : {"fit", "seed", "seed-at-fit"}
        :mod:`sonarslam.features.uncertainty` method: "fit" (weighted least squares) or "seed" (the
        paper's overlap-ratio ellipse; its line is the ellipse centre), or "seed-at-fit": the
        seed ellipse's covariance about the least-squares line of the same voters (on thick
        echo bands the ellipse's centre sits inside the band, the fit on its leading edge).
    confidence : float
        Probability of the seed ellipse: 0.95 (*paper*).
    overlap_similarity : float
        Seed: similar cells have an overlap ratio ``>=`` this times the winner's.
    seed_window_theta_cells, seed_window_rho_cells : int
        Seed: half sizes of the searched neighbourhood (cells); the theta one the larger: the
        similar-overlap region of a wall is long in theta (the beam width hides small
        rotations).
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
        (:mod:`sonarslam.features.uncertainty`); None: ``bin_size / sqrt(12)``; 0 leaves it out.
    pose_uncertainty : bool
        Fit: add the relative pose uncertainty from ``PoseSource.covariance``.
    line_sigma_rho_m, line_sigma_theta_rad : float
        Systematic error of a line, added to every line's covariance as
        ``diag(line_sigma_rho_m^2, line_sigma_theta_rad^2)`` (m, rad): what neither the echoes'
        noise nor the poses explain (a wall that is not straight, an echo band's structure, the
        sector's rotation between beams); it does not shrink with the number of voters. A
        dataset calibration (``[noise] line_sigma_rho_m``, ``line_sigma_theta_deg``, GPS-free:
        ``sonarslam calibrate --line-noise``).
    fit_iterations : int
        Fit: Gauss-Newton iterations.
    fit_gate_sigma : float
        Fit: after fitting the winner's voters, the fit is redone on every stored final bin
        whose echo lies within this many sigmas of the line (from a beam that sees it), so
        that the voters' truncation to one rho cell does not bias it; 0 fits the voters only.
    fit_gate_iterations : int
        Fit: rounds of gathering the support and refitting.
    endpoint_trim_fraction : float
        Segment ends are the ``f`` and ``1 - f`` quantiles of the voters along the line.
    remove_on_line_sigma : float
        After a line is found, the stored final bins whose echoes lie within this many sigmas of
        it are removed with its voters, *at any incidence* (from every beam that faces it). A wall
        also returns echoes beyond ``beta``; the sonar model cannot give them to the wall's
        line, so left in the store they vote for spurious lines a few degrees off the wall
        (docs/design-decisions.md). Not in the paper (it removes the
        voters only); 0 disables.
    """

    intensity_threshold: float = bounded(80.0, 0.0, 255.0)
    max_intensity_difference: float = bounded(40.0, 0.0, 255.0)
    min_distance_m: float = bounded(0.5, 0.0, 1e3)
    min_range_m: float = bounded(0.5, 0.0, 1e4)
    max_range_m: float | None = bounded(None, 0.0, 1e4)
    sector_deg: float = bounded(180.0, 0.0, 360.0, low_open=True)
    beam_width_rad: float | None = bounded(None, 1e-4, 0.5 * np.pi)
    incidence_beta_rad: float = bounded(
        25.0 * _DEG, 0.0, 0.5 * np.pi, low_open=True, high_open=True
    )
    vote_model: str = one_of("arc", "arc", "samples")
    h_bearings: int | None = bounded(None, 1, 1000)
    p_angles: int | None = bounded(None, 1, 1000)
    theta_res_rad: float | None = bounded(None, 0.1 * _DEG, 0.125 * np.pi)
    rho_res_m: float | None = bounded(None, 0.01, 10.0)
    min_votes: int = bounded(15, 1, 1e9)
    max_lines_per_vote: int = bounded(16, 1, 1000)
    suppress_theta_cells: int = bounded(1, 0, 1000)
    suppress_rho_cells: int = bounded(1, 0, 1000)
    vote_every_n_beams: int = bounded(10, 1, 1e9)
    requery_poses: bool = True
    covariance_method: str = one_of("fit", "fit", "seed", "seed-at-fit")
    confidence: float = bounded(0.95, 0.0, 1.0, low_open=True, high_open=True)
    overlap_similarity: float = bounded(0.8, 1e-6, 1.0)
    seed_window_theta_cells: int = bounded(20, 0, 1000)
    seed_window_rho_cells: int = bounded(10, 0, 1000)
    return_model: str = one_of("axis", "axis", "first_return")
    range_sigma_m: float | None = bounded(None, 1e-6, 100.0)
    bearing_sigma_rad: float | None = bounded(None, 1e-6, np.pi)
    range_offset_sigma_m: float | None = bounded(None, 0.0, 100.0)
    pose_uncertainty: bool = False
    line_sigma_rho_m: float = bounded(0.0, 0.0, 100.0)
    line_sigma_theta_rad: float = bounded(0.0, 0.0, 0.5 * np.pi)
    fit_iterations: int = bounded(5, 1, 100)
    fit_gate_sigma: float = bounded(3.0, 0.0, 100.0)
    fit_gate_iterations: int = bounded(2, 0, 100)
    endpoint_trim_fraction: float = bounded(0.05, 0.0, 0.5, high_open=True)
    remove_on_line_sigma: float = bounded(3.0, 0.0, 100.0)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.max_range_m is not None and not self.max_range_m > self.min_range_m:
            raise ValueError(
                f"max_range_m must be > min_range_m ({self.min_range_m}), got {self.max_range_m}"
            )

    @classmethod
    def from_dict(cls, values: dict[str, Any], prefix: str = "") -> ExtractorConfig:
        """Config from a mapping of field names over the defaults, each value checked like
        every other setting (:func:`sonarslam.settings.replace_checked`: type, range, known
        name).

        Parameters
        ----------
        values : dict of str to value
            Field names and values; fields left out keep their defaults.
        prefix : str
            Put before a key in error messages (a file and table, say).

        Raises
        ------
        sonarslam.settings.SettingError
            Naming the key (``prefix`` before it).
        """
        return replace_checked(cls(), values, prefix=prefix, parse_strings=False)

    @classmethod
    def from_toml(cls, path: str | Path, table: str | None = "extractor") -> ExtractorConfig:
        """Load from a TOML file: the ``table`` table if present, else the top level.

        Fields left out take their defaults; ``None`` fields are left out to stay None.

        Parameters
        ----------
        path : str or Path
            A TOML file.
        table : str or None
            The table to read (default ``"extractor"``); None: the top level.

        Raises
        ------
        sonarslam.settings.SettingError
            A wrong key or value, naming the file and the key (``sonarslam run --config`` also
            gives its line).
        """
        with open(path, "rb") as f:
            data = tomllib.load(f)
        where = ""
        if table is not None and table in data:
            data, where = data[table], f"[{table}] "
        return cls.from_dict(data, prefix=f"{path}: {where}")

    def to_dict(self) -> dict[str, Any]:
        """All fields, ``None`` ones included (TOML has no null: drop them to write TOML)."""
        return asdict(self)

    def replace(self, **changes: Any) -> ExtractorConfig:
        """A copy with the fields ``changes`` names set to their values, checked as at
        construction: a value out of range is a ``ValueError`` naming the field, an unknown
        field a ``TypeError``."""
        return replace(self, **changes)
