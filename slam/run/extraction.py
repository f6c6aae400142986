"""Line extraction over a whole dataset, as a plain function the CLI calls (``sonarslam extract``).

``extract(source, poses, out_dir)`` runs :class:`sonarslam.features.extractor.LineExtractor` over the
dataset's beams inside the navigation span with one pose source and writes

* ``lines.jsonl``: one :meth:`sonarslam.features.line.LineFeature.to_json` object per line (``t``, the frame
  R ``x, y, yaw``, ``rho, theta`` and ``cov`` in R, ``votes``, ``n_voters``, world ``endpoints``);
* ``lines_world.png``: every segment with its 95 % band (:func:`sonarslam.slam.io.maps.segment_band_world`) over the
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
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.extractor import LineExtractor
from sonarslam.features.geometry import FloatArray
from sonarslam.features.line import LineFeature
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.projection import project_beams
from sonarslam.slam.eval.truth import truth_walls
from sonarslam.slam.io.files import (
    check_output_dir,
    json_safe,
    make_output_dir,
    write_atomic,
    write_json,
    write_text,
)
from sonarslam.slam.io.maps import MapLayers, plot_lines, segment_band_world
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.presets import extractor_config, map_min_intensity, preset_for
from sonarslam.slam.run.sources import pose_source_by_name
from sonarslam.sonar.beam import SonarBeam

__all__ = [
    "ExtractionResult",
    "extract_lines",
    "extract",
]


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


def extract_lines(
    beams: Sequence[SonarBeam],
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
        Pose source (:data:`sonarslam.slam.run.run.POSE_SOURCES`).
    out_dir : str or Path
        Created if needed; receives ``lines.jsonl``, ``lines_world.png`` and ``extract.json``.
    config_path : str or Path, optional
        TOML of :class:`ExtractorConfig` fields over the preset
        (:func:`sonarslam.slam.run.presets.extractor_config`).
    preset : str, optional
        A name of :data:`sonarslam.slam.run.presets.EXTRACTOR_PRESETS`; None: the one for the beams
        (:func:`sonarslam.slam.run.presets.preset_for`, as the closed loops use it).
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
    check_output_dir(out_dir)  # before any work; created only to write the outputs
    if config_path is not None:  # the file's errors before the dataset is read
        extractor_config(preset or "default", config_path)
    dataset = source if isinstance(source, Dataset) else open_dataset(source)
    pose_source = pose_source_by_name(dataset, poses)
    beams = dataset.nav_beams()
    span = _pose_span(pose_source)
    n_nav = len(beams)
    if span is not None:
        beams = beams.between(span[0], span[1])
    if not beams:
        raise ValueError(f"{dataset.root}: no sonar beam inside the span of the {poses} poses")
    preset_name = preset if preset is not None else preset_for(beams)
    config = extractor_config(preset_name, config_path, noise=dataset.config.noise)
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
    out = make_output_dir(out_dir)
    write_text(
        out / "lines.jsonl",
        "".join(json.dumps(json_safe(ln.to_json()), allow_nan=False) + "\n" for ln in lines),
    )
    write_json(out / "extract.json", stats)
    # the picture shows the bins the extractor thresholds (raw beams are mostly noise)
    points_w, _ = project_beams(
        beams, head, mounting, pose_source, map_min_intensity(beams, config)
    )
    title = f"{dataset.name}: {len(lines)} lines ({preset_name} preset, {poses} poses), 95 % bands"
    write_atomic(
        out / "lines_world.png",
        lambda p: _draw(p, dataset, lines, points_w, {poses: pose_source}, title),
    )
    return ExtractionResult(lines, stats, beam_time_s, out)


def _draw(
    path: Path,
    dataset: Dataset,
    lines: list[LineFeature],
    points_w: FloatArray,
    trajectories: dict[str, Trajectory],
    title: str,
) -> None:
    """lines_world.png: the lines with their 95 % bands over the bins (the true walls of a
    simulated dataset)."""
    walls = truth_walls(dataset) if dataset.truth and "walls_m" in dataset.truth else None
    layers = MapLayers(
        points_w,
        trajectories,
        [ln.endpoints_world() for ln in lines],
        [segment_band_world(ln) for ln in lines],
        walls,
        segment_label="line",
    )
    plot_lines(path, layers, title)
