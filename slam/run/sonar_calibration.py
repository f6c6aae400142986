"""GPS-free calibrations of the sonar's line model: the range offset of the kept echoes and the
systematic error of a line.

* **Range offset** (:func:`calibrate_range_offset`, ``[sonar] range_offset_m``): the extractor
  keeps some bins of each echo (the strongest of a raw echo's run above the threshold, within
  the intensity band; the first of a thresholded run). The wall's face is where the echo rises:
  the echo-band model is that the rising edge crosses half the intensity of the kept bin at the
  face (a pulse's leading edge; the tail behind it is the pulse's length, the beam's vertical
  footprint, a rough face). So the offset of the kept bins is measured on the beams themselves
  as the median of ``r_kept - r_half-rise``: it is the kept bins' offset, not the echo peak's
  (on the drift world, whose echoes peak 0.25 m behind the face, the kept bins sit nearer the
  rise). A thresholded run's first bin is its leading edge: its offset is zero by construction
  (the threshold's own delay cannot be seen in a 0/255 mask). The model assumes an echo that
  starts at the surface (a real sonar's); the default simulated harbour renders a symmetric
  pulse centred on the wall, for which the right offset is 0.
* **Line noise** (:func:`calibrate_line_noise`, ``[noise] line_sigma_rho_m``,
  ``line_sigma_theta_deg``): lines extracted with dead-reckoning poses, and pairs of lines of one
  wall seen 14-30 s apart: at least one full turn of the head (13.6 s on the marina and the
  simulator), so that the two share no echo, and soon enough for dead reckoning to drift little
  (its uncertainty over a scan is in each line's covariance through ``pose_uncertainty``; its
  position random walk between the two and the AHRS bias's walk, as the dataset's ``[noise]``
  states it, are added to the pair's. The DVL's scale error is not: it is one constant of the run,
  the same in every pair, and counting its prior in each pair's covariance swallowed the lines'
  own error on the drift world's seeds). Their sign-free
  difference in the world should be chi2(2)-distributed with the pair's covariance; the
  systematic error ``diag(s_rho^2, s_theta^2)`` added to every line is the one that brings the
  median of the pairs' squared distances to chi2(2)'s median (1.386), with the ratio of the two
  sigmas chosen so that both components are consistent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import tomli_w
from scipy.optimize import brentq
from scipy.stats import chi2

from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.config import ExtractorConfig
from sonarslam.features.extractor import LineExtractor, segment_with
from sonarslam.features.geometry import (
    FLIP_RHO,
    FloatArray,
    along_line,
    line_difference,
    line_frame_to_world,
    line_side,
    line_world_to_frame,
)
from sonarslam.features.line import LineFeature
from sonarslam.slam.io.files import write_text
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.calibration import require_turns
from sonarslam.slam.run.presets import extractor_config, preset_for
from sonarslam.slam.run.sources import dead_reckoning_trajectory
from sonarslam.sonar.beam import beam_bin_size_m

__all__ = [
    "RangeOffsetFit",
    "calibrate_range_offset",
    "LineNoiseFit",
    "calibrate_line_noise",
    "write_sonar_calibration",
]


@dataclass(frozen=True)
class RangeOffsetFit:
    """The kept echoes' range offset (m): median, interquartile range, echoes used, method."""

    offset_m: float
    iqr_m: float
    n: int
    method: str


def calibrate_range_offset(dataset: Dataset, every: int = 1) -> RangeOffsetFit:
    """The range offset of the echoes the extractor keeps (module docstring), GPS-free.

    Parameters
    ----------
    dataset : Dataset
        Its beams inside the navigation span and the extractor preset for them.
    every : int
        Use every ``every``-th beam.
    """
    require_turns(dataset, len(dataset.nav_beams()), "the echo range offset")
    beams = dataset.nav_beams()[::every]
    if beams and all(b.thresholded for b in beams):
        n = sum(int(np.count_nonzero(np.diff(np.r_[0, b.intensities > 0]) == 1)) for b in beams)
        return RangeOffsetFit(0.0, 0.0, n, "thresholded runs: the kept bin is the leading edge")
    cfg = extractor_config(preset_for(beams))
    offsets: list[float] = []
    for b in beams:
        bin_m = beam_bin_size_m(b, dataset.config.sonar)  # a segment's own
        seg = segment_with(cfg, bin_m, b.intensities, thresholded=False)
        intensity = b.intensities.astype(np.float64)
        for k in seg.final_bins:
            half = 0.5 * intensity[k]
            j = int(k)
            while j > 0 and intensity[j - 1] >= half:
                j -= 1
            if j == 0:
                continue  # the rise is not in the beam
            frac = (half - intensity[j - 1]) / (intensity[j] - intensity[j - 1])
            offsets.append((k - (j - 1 + frac)) * bin_m)
    if not offsets:
        raise ValueError(f"{dataset.root}: no echo with its rising edge in the beams")
    o = np.asarray(offsets)
    q25, q50, q75 = np.percentile(o, [25, 50, 75])
    return RangeOffsetFit(float(q50), float(q75 - q25), int(o.size), "raw echoes: peak - half-rise")


@dataclass(frozen=True)
class LineNoiseFit:
    """The systematic error of a line, the pairs used and their NEES before and after it is added.

    Attributes
    ----------
    sigma_rho_m, sigma_theta_rad : float
        The 1-sigma systematic error added to every line's covariance (m, rad); zero when the
        pairs' NEES median is already at or below chi2(2)'s.
    n_lines, n_pairs : int
        Lines extracted, and pairs of lines of one wall compared.
    nees_median_before, nees_median_after : float
        Median NEES (2 dof) of the pairs' differences without and with it.
    outside_99_after : float
        Share of the pairs whose NEES with it is beyond chi2(2)'s 99 % quantile.
    """

    sigma_rho_m: float
    sigma_theta_rad: float
    n_lines: int
    n_pairs: int
    nees_median_before: float
    nees_median_after: float
    outside_99_after: float


@dataclass(frozen=True, eq=False)
class _Seen:
    """A line as extracted: time, frame R, ``z`` and ``R`` in it, and in the world."""

    t_s: float
    wTr: FloatArray
    z: FloatArray
    R: FloatArray
    line_w: FloatArray
    G_z: FloatArray
    ends_w: FloatArray
    P_xy: FloatArray  # dead reckoning's position covariance at t (world), shape (2, 2)


def _position_covariance(poses: Trajectory, t_s: float) -> FloatArray:
    """Dead reckoning's position covariance at ``t_s`` (world, (2, 2)); zero without one."""
    cov = poses.covariance(t_s)
    return np.zeros((2, 2)) if cov is None else np.asarray(cov[:2, :2])


def _pairs(lines: list[_Seen], window_s: tuple[float, float]) -> list[tuple[int, int]]:
    """Pairs of lines of one wall: within the time window, seen from the same side, their
    segments overlapping by 2 m or more, within 3 m and 15 deg of each other in the earlier
    line's frame (a loose gate: the median, not the gate, decides)."""
    out = []
    for i, a in enumerate(lines):
        side_a = line_side(a.line_w, a.wTr[:2])
        s_a = along_line(a.line_w, a.ends_w)
        for j in range(i + 1, len(lines)):
            b = lines[j]
            dt = b.t_s - a.t_s
            if dt > window_s[1]:
                break
            if dt < window_s[0] or line_side(a.line_w, b.wTr[:2]) != side_a:
                continue
            nu = _difference(a, b)[0]
            if abs(nu[0]) > 3.0 or abs(nu[1]) > np.deg2rad(15.0):
                continue
            s_b = along_line(a.line_w, b.ends_w)
            if min(s_a.max(), s_b.max()) - max(s_a.min(), s_b.min()) >= 2.0:
                out.append((i, j))
    return out


def _difference(a: _Seen, b: _Seen) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``b``'s line in ``a``'s frame minus ``a``'s (sign-free), ``d(b in a) / d z_b`` and
    ``d(b in a) / d wTr`` of ``a``'s frame, shape (2, 3)."""
    b_in_a, H_line, H_pose = line_world_to_frame(b.line_w, a.wTr)
    nu, flipped = line_difference(b_in_a, a.z)
    J = H_line @ b.G_z
    if flipped:
        J, H_pose = FLIP_RHO @ J, FLIP_RHO @ H_pose
    return nu, J, H_pose


@dataclass(frozen=True)
class _Drift:
    """What dead reckoning's relative pose between two lines' frames is uncertain by: its
    position random walk and the AHRS bias's walk (rad^2/s) in the heading."""

    walk_var_rad2ps: float = 0.0

    def covariance(self, a: _Seen, b: _Seen) -> FloatArray:
        """Of the pose of ``b``'s frame in the world relative to ``a``'s, (3, 3)."""
        C = np.zeros((3, 3))
        C[:2, :2] = b.P_xy - a.P_xy
        C[2, 2] = self.walk_var_rad2ps * abs(b.t_s - a.t_s)
        return C


def _pair_nees(
    lines: list[_Seen],
    pairs: list[tuple[int, int]],
    sigmas: tuple[float, float],
    drift: _Drift,
) -> FloatArray:
    Q = np.diag(np.square(sigmas))
    out = np.empty(len(pairs))
    for k, (i, j) in enumerate(pairs):
        a, b = lines[i], lines[j]
        nu, J, H_pose = _difference(a, b)
        S = a.R + Q + J @ (b.R + Q) @ J.T + H_pose @ drift.covariance(a, b) @ H_pose.T
        out[k] = nu @ np.linalg.solve(S, nu)
    return out


def calibrate_line_noise(
    dataset: Dataset,
    window_s: tuple[float, float] = (14.0, 30.0),
    config: ExtractorConfig | None = None,
) -> LineNoiseFit:
    """The systematic error of a line (module docstring), GPS-free.

    The lines come from the beams' extractor preset (its ``line_sigma_*`` set to 0) with
    dead-reckoning poses and ``pose_uncertainty`` on. The ratio ``s_rho / s_theta`` is the ratio
    of the robust spreads (median absolute deviations) of the pairs' differences in the earlier
    line's frame; the scale is then found by root finding on the NEES median.
    """
    poses = dead_reckoning_trajectory(dataset)
    t0, t1 = poses.span_s
    beams = dataset.nav_beams().between(t0, t1)
    require_turns(dataset, len(beams), "a line's systematic error")
    cfg = replace(
        config or extractor_config(preset_for(beams)),
        line_sigma_rho_m=0.0,
        line_sigma_theta_rad=0.0,
        pose_uncertainty=True,
    )
    head, mounting = dataset.config.sonar, dataset.config.sonar_mounting
    extractor = LineExtractor(cfg, head, mounting, poses)
    features: list[LineFeature] = []
    for b in beams:
        features += extractor.add(b)
    lines = []
    for f in features:
        line_w, G_z, _ = line_frame_to_world(f.z, f.wTr)
        lines.append(
            _Seen(
                f.t,
                np.asarray(f.wTr),
                f.z,
                np.asarray(f.cov),
                line_w,
                G_z,
                f.endpoints_world(),
                _position_covariance(poses, f.t),
            )
        )
    pairs = _pairs(lines, window_s)
    drift = _Drift(np.deg2rad(dataset.config.noise.ahrs_bias_walk_deg_per_sqrt_s) ** 2)
    if len(pairs) < 20:
        raise ValueError(f"{dataset.root}: {len(pairs)} pairs of lines of one wall: too few")
    before = _pair_nees(lines, pairs, (0.0, 0.0), drift)
    nus = np.array([_difference(lines[i], lines[j])[0] for i, j in pairs])
    mad = 1.4826 * np.median(np.abs(nus), axis=0)
    ratio = float(mad[0] / max(mad[1], 1e-9))
    target = float(chi2.ppf(0.5, 2))
    sig = (0.0, 0.0)
    if np.median(before) > target:

        def excess(s_theta: float) -> float:
            return float(
                np.median(_pair_nees(lines, pairs, (ratio * s_theta, s_theta), drift)) - target
            )

        s_theta = float(brentq(excess, 1e-6, np.deg2rad(30.0), xtol=1e-7))
        sig = (ratio * s_theta, s_theta)
    after = _pair_nees(lines, pairs, sig, drift)
    return LineNoiseFit(
        sigma_rho_m=float(sig[0]),
        sigma_theta_rad=float(sig[1]),
        n_lines=len(lines),
        n_pairs=len(pairs),
        nees_median_before=float(np.median(before)),
        nees_median_after=float(np.median(after)),
        outside_99_after=float(np.mean(after > chi2.ppf(0.99, 2))),
    )


def write_sonar_calibration(source: str | Path, out_path: str | Path) -> Path:
    """Both calibrations of a dataset, GPS-free, as a partial ``sonarslam.toml`` at ``out_path``
    (``[sonar] range_offset_m``, ``[noise] line_sigma_rho_m``, ``line_sigma_theta_deg``) for
    ``open_dataset(source, config_override=out_path)``; the line noise is calibrated with the
    range offset found first. Written atomically (the sweep's workers may race)."""
    dataset = open_dataset(source)
    offset = calibrate_range_offset(dataset)
    sonar = replace(dataset.config.sonar, range_offset_m=offset.offset_m)
    noise = calibrate_line_noise(replace(dataset, config=replace(dataset.config, sonar=sonar)))
    doc = {  # to a micrometre and a microdegree: what a user would type
        "sonar": {"range_offset_m": round(offset.offset_m, 6)},
        "noise": {
            "line_sigma_rho_m": round(noise.sigma_rho_m, 6),
            "line_sigma_theta_deg": round(math.degrees(noise.sigma_theta_rad), 6),
        },
    }
    return write_text(out_path, tomli_w.dumps(doc))
