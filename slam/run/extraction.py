"""Line extraction over a whole dataset, as a plain function the CLI calls (``sonarslam extract``).

``extract(source, poses, out_dir)`` runs :class:`features.extractor.LineExtractor` over the
dataset's beams inside the navigation span with one pose source and writes

* ``lines.jsonl``: one :meth:`features.line.LineFeature.to_json` object per line (``t``, the frame
  R ``x, y, yaw``, ``rho, theta`` and ``cov`` in R, ``votes``, ``n_voters``, world ``endpoints``);
* ``lines_world.png``: every segment with its 95 % band (:func:`segment_band_world`) over the
  density image of the projected threshold bins (intensity at least the extractor's threshold;
  every given bin of thresholded beams);
* ``extract.json``: counts and timings (``features``, ``beams``, ``beam_time_p50_us``,
  ``beam_time_p99_us``, ``wall_s``, ``data_s``, ``realtime_factor``, ...) and the configuration.

The per-beam time is that of one :meth:`LineExtractor.add` call (segmentation, storage, and the
vote when one is due); ``wall_s`` is the whole loop over the beams (reading the logs, building
the pose source and drawing are not counted); ``realtime_factor = data_s / wall_s``.
"""

from __future__ import annotations

import json
import time
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from datasets.source import Dataset, open_dataset
from features.extractor import MARINA_PRESET, ExtractorConfig, LineExtractor
from features.geometry import FloatArray, transform_points
from features.line import LineFeature
from features.pose_source import PoseSource
from features.projection import project_beams
from features.uncertainty import chi2_2dof
from slam.io.plots import plot_lines
from slam.run.run import pose_source_by_name
from sonar.beam import SonarBeam

__all__ = [
    "PRESETS",
    "ExtractionResult",
    "default_preset",
    "extractor_config",
    "extract_lines",
    "segment_band_world",
    "extract",
]

#: Named starting configurations of ``--preset``.
PRESETS: dict[str, ExtractorConfig] = {"marina": MARINA_PRESET, "default": ExtractorConfig()}


@dataclass
class ExtractionResult:
    """What an extraction found, measured and wrote.

    Attributes
    ----------
    lines : list of LineFeature
        In extraction order.
    stats : dict
        The content of ``extract.json``.
    beam_time_s : ndarray, shape (B,)
        Time of each :meth:`LineExtractor.add` call (s).
    out_dir : Path or None
        Where the files were written (None when nothing was written).
    """

    lines: list[LineFeature]
    stats: dict[str, Any]
    beam_time_s: FloatArray
    out_dir: Path | None = None


def default_preset(beams: list[SonarBeam]) -> str:
    """``"marina"`` for thresholded beams (0/255 masks, as the marina keyframes), else
    ``"default"`` (raw intensities)."""
    return "marina" if beams and all(b.thresholded for b in beams) else "default"


def extractor_config(preset: str, config_path: str | Path | None = None) -> ExtractorConfig:
    """A preset, with the fields of a TOML file (``[extractor]`` table or top level) over it.

    Parameters
    ----------
    preset : {"marina", "default"}
    config_path : str or Path, optional
        TOML file; the fields it names replace the preset's (unknown names are an error).
    """
    if preset not in PRESETS:
        raise ValueError(f"--preset must be one of {sorted(PRESETS)}, got {preset!r}")
    base = PRESETS[preset]
    if config_path is None:
        return base
    with open(config_path, "rb") as f:
        data = tomllib.load(f)
    data = data.get("extractor", data)
    unknown = set(data) - {f.name for f in fields(ExtractorConfig)}
    if unknown:
        raise ValueError(f"{config_path}: unknown ExtractorConfig fields: {sorted(unknown)}")
    return base.replace(**data)


def extract_lines(
    beams: list[SonarBeam],
    extractor: LineExtractor,
    progress: bool = False,
) -> tuple[list[LineFeature], FloatArray, float]:
    """Feed every beam to the extractor, timing each call, and flush at the end.

    Parameters
    ----------
    beams : list of SonarBeam
        In time order.
    extractor : LineExtractor
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    lines : list of LineFeature
    beam_time_s : ndarray, shape (len(beams),)
        Time of each :meth:`LineExtractor.add` call (s); the final flush is added to the last.
    wall_s : float
        Time of the whole loop (s).
    """
    lines: list[LineFeature] = []
    dt = np.zeros(len(beams))
    clock = time.perf_counter
    wall0 = clock()
    for k, beam in enumerate(tqdm(beams, desc="extract", unit="beam", disable=not progress)):
        a = clock()
        lines += extractor.add(beam)
        dt[k] = clock() - a
    a = clock()
    lines += extractor.flush()
    if dt.size:
        dt[-1] += clock() - a
    return lines, dt, clock() - wall0


def segment_band_world(
    feature: LineFeature,
    confidence: float = 0.95,
    n_along: int = 25,
    n_boundary: int = 72,
) -> FloatArray:
    """Polygon of the lines within the ``confidence`` ellipse of ``(rho, theta)``, over the segment.

    The ellipse is ``{z : (z - z0)^T cov^-1 (z - z0) <= chi2_2(confidence)}`` in R. Along the
    segment (``n_along`` points ``q(s) = rho n + s t`` between its ends, ``n`` the normal and ``t``
    the tangent), every line ``(rho_k, theta_k)`` of ``n_boundary`` samples of the ellipse's
    boundary meets the normal through ``q(s)`` at the signed offset
    ``lambda_k = (rho_k - q . n_k) / (n . n_k)``; the band is ``[min_k lambda_k, max_k lambda_k]``
    (exact, no linearisation; to first order its half width is
    ``sqrt(chi2 [1, -s] cov [1, -s]^T)``).

    Parameters
    ----------
    feature : LineFeature
    confidence : float
        Probability of the ellipse (0.95: ``chi2_2 = 5.991``).
    n_along, n_boundary : int
        Samples along the segment and on the ellipse boundary.

    Returns
    -------
    ndarray, shape (2 n_along, 2)
        Polygon in the world (m): one side of the band from the first end to the second,
        then the other side back.
    """
    rho, theta = feature.rho_m, feature.theta_rad
    n = np.array([np.cos(theta), np.sin(theta)])
    t = np.array([-n[1], n[0]])
    ends = np.asarray(feature.endpoints_r, dtype=np.float64)
    s = np.linspace(float(ends[0] @ t), float(ends[1] @ t), n_along)
    q = rho * n[None, :] + s[:, None] * t[None, :]  # (A, 2) points of the segment in R
    cov = 0.5 * (feature.cov + feature.cov.T)
    w, v = np.linalg.eigh(cov)
    root = v * np.sqrt(np.clip(w, 0.0, None))[None, :]  # cov = root root^T
    phi = np.linspace(0.0, 2.0 * np.pi, n_boundary, endpoint=False)
    u = np.stack([np.cos(phi), np.sin(phi)])  # (2, K)
    z = np.array([rho, theta])[:, None] + np.sqrt(chi2_2dof(confidence)) * root @ u  # (2, K)
    nk = np.stack([np.cos(z[1]), np.sin(z[1])], axis=-1)  # (K, 2)
    denom = nk @ n  # (K,)
    lam = (z[0][None, :] - q @ nk.T) / denom[None, :]  # (A, K)
    lo, hi = lam.min(axis=1), lam.max(axis=1)
    side_a = q + hi[:, None] * n[None, :]
    side_b = q + lo[:, None] * n[None, :]
    poly_r = np.concatenate([side_a, side_b[::-1]])
    return transform_points(feature.wTr, poly_r)


def _pose_span(pose_source: PoseSource) -> tuple[float, float] | None:
    span = getattr(pose_source, "span_s", None)
    return (float(span[0]), float(span[1])) if span is not None else None


def extract(
    source: str | Path | Dataset,
    poses: str,
    out_dir: str | Path,
    config_path: str | Path | None = None,
    preset: str | None = None,
    progress: bool = True,
) -> ExtractionResult:
    """Extract the lines of a dataset with one pose source; write the three outputs.

    Parameters
    ----------
    source : str, Path or Dataset
        Dataset directory, the named source ``"marina"``, or an opened dataset.
    poses : {"gps", "dr", "truth"}
        Pose source (:data:`slam.run.run.POSE_SOURCES`).
    out_dir : str or Path
        Created if needed; receives ``lines.jsonl``, ``lines_world.png`` and ``extract.json``.
    config_path : str or Path, optional
        TOML of :class:`ExtractorConfig` fields over the preset (:func:`extractor_config`).
    preset : {"marina", "default"}, optional
        Starting configuration; None: :func:`default_preset` of the beams.
    progress : bool
        tqdm progress bar.

    Returns
    -------
    ExtractionResult

    Notes
    -----
    Only the beams inside both the navigation span and the pose source's span are used (a
    trajectory holds its end poses outside its span, which would smear those beams).
    """
    dataset = source if isinstance(source, Dataset) else open_dataset(source)
    pose_source = pose_source_by_name(dataset, poses)
    beams = dataset.nav_beams()
    span = _pose_span(pose_source)
    n_nav = len(beams)
    if span is not None:
        beams = [b for b in beams if span[0] <= b.t <= span[1]]
    if not beams:
        raise ValueError(f"{dataset.root}: no sonar beam inside the span of the {poses} poses")
    preset_name = preset if preset is not None else default_preset(beams)
    config = extractor_config(preset_name, config_path)
    head, mounting = dataset.config.sonar, dataset.config.sonar_mounting
    extractor = LineExtractor(config, head, mounting, pose_source)
    lines, beam_time_s, wall_s = extract_lines(beams, extractor, progress=progress)

    data_s = float(beams[-1].t - beams[0].t)
    stats: dict[str, Any] = {
        "source": str(dataset.root),
        "poses": poses,
        "preset": preset_name,
        "config_file": None if config_path is None else str(config_path),
        "features": len(lines),
        "beams": len(beams),
        "beams_outside_pose_span": n_nav - len(beams),
        "votes": extractor.n_votes,
        "beam_time_p50_us": float(np.percentile(beam_time_s, 50) * 1e6),
        "beam_time_p99_us": float(np.percentile(beam_time_s, 99) * 1e6),
        "beam_time_max_us": float(beam_time_s.max() * 1e6),
        "wall_s": wall_s,
        "data_s": data_s,
        "realtime_factor": data_s / wall_s if wall_s > 0.0 else float("inf"),
        "config": config.to_dict(),
    }
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "lines.jsonl", "w") as f:
        for ln in lines:
            f.write(json.dumps(ln.to_json()) + "\n")
    (out / "extract.json").write_text(json.dumps(stats, indent=2) + "\n")
    # the picture shows the bins the extractor thresholds (raw beams are mostly noise)
    min_intensity = (
        1 if all(b.thresholded for b in beams) else int(np.ceil(config.intensity_threshold))
    )
    points_w, _ = project_beams(beams, head, mounting, pose_source, max(min_intensity, 1))
    plot_lines(
        out / "lines_world.png",
        points_w,
        [ln.endpoints_world() for ln in lines],
        [segment_band_world(ln) for ln in lines],
        f"{dataset.name}: {len(lines)} lines ({preset_name} preset, {poses} poses), 95 % bands",
        {poses: pose_source},
    )
    return ExtractionResult(lines, stats, beam_time_s, out)
