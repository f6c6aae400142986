"""The closed loop and the baselines, as plain functions the CLI calls."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from datasets.config import dump_dataset_config
from datasets.source import Dataset, open_dataset
from features.extractor import MARINA_PRESET, ExtractorConfig
from slam.eval.ate import ate_against_gps, ate_errors
from slam.eval.consistency import COV_FILE, write_trajectory_covariances
from slam.io.plots import plot_trajectories
from slam.io.trajectory import Trajectory, write_tum
from slam.run.presets import apply_overrides, split_settings
from slam.run.sources import (
    dead_reckoning_trajectory,
    dvl_quality,
    gps_ahrs_trajectory,
    truth_trajectory,
)

__all__ = ["RunResult", "BACKENDS", "run", "pose_source_by_name", "POSE_SOURCES", "summary_line"]


@dataclass
class RunResult:
    """What a run wrote and measured."""

    out_dir: Path
    trajectory: Trajectory
    metrics: dict[str, Any]
    extras: dict[str, Any] = field(default_factory=dict)


def _baseline(
    factory: Callable[[Dataset], Trajectory],
) -> Callable[..., tuple[Trajectory, dict[str, Any]]]:
    def go(
        dataset: Dataset, out_dir: Path, progress: bool = True
    ) -> tuple[Trajectory, dict[str, Any]]:
        return factory(dataset), {}

    return go


def default_extractor_config(dataset: Dataset) -> ExtractorConfig:
    """The extractor settings a closed-loop run uses.

    Raw intensity beams: the seed's defaults. Thresholded beams (the marina keyframes): the
    marina preset with a 360 deg sector, 15 votes and the seed's covariance. Measured on the real
    marina (GPS-free, dead-reckoning poses): repeated lines of one wall scatter by ~5 deg and
    ~0.5 m because the walls' echo bands are metres thick; the "fit" covariance is ~30x too
    small against that (median pair d2 55), the seed's ellipse is consistent (median 0.91);
    longer segments (360 deg) scatter less. The odometry's uncertainty over the sector is added
    (``pose_uncertainty``): it matters when the DVL degrades (the marina's last ~700 s, where its
    relative error over one 13.6 s scan reaches ~1 m).
    """
    if dataset.beams and dataset.beams[0].thresholded:
        return MARINA_PRESET.replace(
            covariance_method="seed", sector_deg=360.0, min_votes=15, pose_uncertainty=True
        )
    return ExtractorConfig()


def map_min_intensity(dataset: Dataset) -> int:
    """Smallest intensity drawn in maps: every given bin of thresholded beams, else the bins
    above the extractor's intensity threshold (raw beams are mostly background noise)."""
    if dataset.beams and dataset.beams[0].thresholded:
        return 1
    return int(np.ceil(default_extractor_config(dataset).intensity_threshold))


def _configs(
    dataset: Dataset, backend: str, default: Any, settings: dict[str, Any] | None
) -> tuple[ExtractorConfig, Any]:
    """The extractor and back-end configurations of a run, with ``--set`` settings applied."""
    ext, own = split_settings(settings or {}, backend)
    return apply_overrides(default_extractor_config(dataset), ext), apply_overrides(default, own)


def _ekf(
    dataset: Dataset,
    out_dir: Path,
    progress: bool = True,
    settings: dict[str, Any] | None = None,
) -> tuple[Trajectory, dict[str, Any]]:
    from slam.backends.ekf import EkfConfig, LineEkf
    from slam.run.closed_loop import run_closed_loop

    extractor, config = _configs(dataset, "ekf", EkfConfig(), settings)
    result = run_closed_loop(
        dataset,
        lambda t0, pose0, cov0: LineEkf(t0, pose0, cov0, dataset.config.sonar_mounting, config),
        extractor,
        progress=progress,
    )
    return result.trajectory, _closed_loop_outputs(
        dataset, out_dir, result, result.backend.map_json()
    )


def _isam2(
    dataset: Dataset,
    out_dir: Path,
    progress: bool = True,
    batch: bool = False,
    settings: dict[str, Any] | None = None,
) -> tuple[Trajectory, dict[str, Any]]:
    """The GTSAM back end: the causal (online) trajectory is the run's; the smoothed one (and the
    batch Levenberg-Marquardt one, with ``batch``) are written beside it and measured too."""
    from slam.backends.isam2.graph import GraphConfig, isam2_backend_factory, pose_source_of
    from slam.run.closed_loop import run_closed_loop

    extractor, config = _configs(dataset, "isam2", GraphConfig(), settings)
    result = run_closed_loop(
        dataset,
        isam2_backend_factory(dataset.config.sonar_mounting, config),
        extractor,
        pose_source_of=pose_source_of,
        progress=progress,
    )
    backend = result.backend
    extras = _closed_loop_outputs(dataset, out_dir, result, backend.map_json())
    assert dataset.gps is not None
    smoothed = backend.smoothed_trajectory()
    write_tum(out_dir / "trajectory_smoothed.tum", smoothed)
    ate_smoothed = ate_against_gps(smoothed, dataset.gps)
    extras["metrics"]["ate_mean_smoothed_m"] = ate_smoothed.ate_mean_m
    extras["metrics"]["ate_max_smoothed_m"] = ate_smoothed.ate_max_m
    if batch:
        backend.optimize_batch()
        optimised = backend.smoothed_trajectory()
        write_tum(out_dir / "trajectory_batch.tum", optimised)
        ate = ate_against_gps(optimised, dataset.gps)
        extras["metrics"]["ate_mean_batch_m"] = ate.ate_mean_m
        extras["metrics"]["ate_max_batch_m"] = ate.ate_max_m
    backend.save(out_dir / "graph.json")
    extras["metrics"].update({f"isam2_{k}_s": float(v) for k, v in backend.timing_s.items()})
    update_ms = 1e3 * np.array([wall for _, wall, _ in backend.update_log])
    if update_ms.size:
        extras["metrics"]["isam2_updates"] = int(update_ms.size)
        extras["metrics"]["isam2_update_p50_ms"] = float(np.percentile(update_ms, 50))
        extras["metrics"]["isam2_update_p99_ms"] = float(np.percentile(update_ms, 99))
    return result.trajectory, extras


def _closed_loop_outputs(
    dataset: Dataset, out_dir: Path, result: Any, landmarks: list[dict[str, Any]]
) -> dict[str, Any]:
    """map.json, lines.jsonl and map.png of a closed-loop run; the extra metrics."""
    from features.projection import project_beams
    from slam.io.plots import plot_scans

    (out_dir / "map.json").write_text(json.dumps({"landmarks": landmarks}, indent=1) + "\n")
    with (out_dir / "lines.jsonl").open("w") as fh:
        for f, lm in zip(result.features, result.feature_landmarks, strict=True):
            fh.write(json.dumps({**f.to_json(), "landmark": lm}) + "\n")
    beams = [
        b
        for b in dataset.nav_beams()
        if result.trajectory.span_s[0] <= b.t <= result.trajectory.span_s[1]
    ]
    points, _ = project_beams(
        beams, dataset.config.sonar, dataset.config.sonar_mounting, result.trajectory
    )
    plot_scans(
        out_dir / "map.png",
        points,
        {"gps": gps_ahrs_trajectory(dataset), "est": result.trajectory},
        f"{dataset.name}: map and trajectory, sonar bins projected with the estimate",
        [np.asarray(lm["endpoints"]) for lm in landmarks],
    )
    stats = dict(getattr(result.backend, "stats", {}))
    return {
        "metrics": {
            "landmarks": len(landmarks),
            "line_features": len(result.features),
            **{f"assoc_{k}": v for k, v in stats.items()},
            "extractor_s": result.extractor_s,
            "backend_s": result.backend_s,
            "beams": result.counts.get("beams", 0),
        }
    }


def _load_backends() -> dict[str, Callable[..., tuple[Trajectory, dict[str, Any]]]]:
    backends: dict[str, Callable[..., tuple[Trajectory, dict[str, Any]]]] = {
        "dr": _baseline(dead_reckoning_trajectory),
        "gps": _baseline(gps_ahrs_trajectory),
        "ekf": _ekf,
        "isam2": _isam2,
    }
    return backends


BACKENDS = ("dr", "gps", "ekf", "isam2")

POSE_SOURCES: dict[str, Callable[[Dataset], Trajectory]] = {
    "gps": gps_ahrs_trajectory,
    "dr": dead_reckoning_trajectory,
    "truth": truth_trajectory,
}


def pose_source_by_name(dataset: Dataset, name: str) -> Trajectory:
    """One of :data:`POSE_SOURCES` built on ``dataset``."""
    if name not in POSE_SOURCES:
        raise ValueError(f"--poses must be one of {sorted(POSE_SOURCES)}, got {name!r}")
    return POSE_SOURCES[name](dataset)


def run(
    source: str | Path,
    backend: str,
    out_dir: str | Path,
    progress: bool = True,
    batch: bool = False,
    config: str | Path | None = None,
    settings: dict[str, Any] | None = None,
) -> RunResult:
    """Run a back end on a dataset and write ``trajectory.tum``, ``ground_truth.tum``,
    ``metrics.json`` and ``report.png`` into ``out_dir``.

    The ATE protocol: the start pose is the first GPS fix and the heading sensor; the ATE is
    taken at every GPS fix inside the trajectory's span, with no alignment (:mod:`slam.eval.ate`).
    ``config``: a ``sonarslam.toml``-format file whose keys replace the dataset's calibration
    (:func:`datasets.source.open_dataset`); the configuration used is written to
    ``config_used.toml``. ``settings``: extractor and back-end settings
    (``{"isam2.robust": "cauchy"}``, :mod:`slam.run.presets`), recorded in ``metrics.json``.
    """
    backends = _load_backends()
    if backend not in backends:
        raise ValueError(f"--backend must be one of {sorted(backends)}, got {backend!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dataset = open_dataset(source, config_override=config)
    if dataset.gps is None:
        raise ValueError(
            f"{dataset.root}: runs need *_DGPS.log for the start pose and the evaluation"
        )
    wall0 = time.perf_counter()
    options: dict[str, Any] = {"batch": True} if batch and backend == "isam2" else {}
    if settings:
        if backend not in ("ekf", "isam2"):
            raise ValueError(f"--set: back end {backend!r} has no settings")
        options["settings"] = settings
    trajectory, extras = backends[backend](dataset, out, progress=progress, **options)
    wall_s = time.perf_counter() - wall0
    t0, t1 = trajectory.span_s
    data_s = t1 - t0
    ate = ate_against_gps(trajectory, dataset.gps)
    gps_tr = gps_ahrs_trajectory(dataset)
    metrics: dict[str, Any] = {
        "source": str(dataset.root),
        "backend": backend,
        **ate.as_dict(),
        "wall_s": wall_s,
        "data_s": data_s,
        "realtime_factor": data_s / wall_s if wall_s > 0 else float("inf"),
        "dvl_rows": int(dataset.dvl.t.size),
        "dvl_invalid_rows": int((~dataset.dvl.valid).sum()),
        **dvl_quality(dataset),
        "settings": dict(settings or {}),
        **extras.pop("metrics", {}),
    }
    (out / "config_used.toml").write_text(dump_dataset_config(dataset.config))
    write_tum(out / "trajectory.tum", trajectory)
    write_trajectory_covariances(out / COV_FILE, trajectory)  # no-op without covariances
    gps_in = (dataset.gps.t >= t0) & (dataset.gps.t <= t1)
    # the raw fixes (the ATE reference), with the AHRS heading for a full pose
    gps_pose = np.column_stack(
        [dataset.gps.en_m[gps_in], gps_tr.poses(dataset.gps.t[gps_in])[:, 2]]
    )
    write_tum(out / "ground_truth.tum", Trajectory(dataset.gps.t[gps_in], gps_pose))
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    drawn = {"gps": gps_tr, backend: trajectory}
    if backend != "dr":  # dead reckoning beside every other back end, as the reference
        drawn["dr"] = dead_reckoning_trajectory(dataset)
    errors = {name: ate_errors(tr, dataset.gps) for name, tr in drawn.items() if name != "gps"}
    plot_trajectories(
        out / "report.png",
        drawn,
        errors,
        f"{dataset.name}: {backend}, ATE mean {ate.ate_mean_m:.2f} m, max {ate.ate_max_m:.2f} m",
    )
    return RunResult(out, trajectory, metrics, extras)


def summary_line(metrics: dict[str, Any]) -> str:
    """One line of a run's figures for the terminal."""
    return (
        f"{metrics['backend']}: ATE mean {metrics['ate_mean_m']:.2f} m, sd {metrics['ate_sd_m']:.2f}, "
        f"min {metrics['ate_min_m']:.2f}, max {metrics['ate_max_m']:.2f}, rmse {metrics['ate_rmse_m']:.2f} "
        f"over {metrics['ate_n']} fixes; {metrics['data_s']:.0f} s of data in {metrics['wall_s']:.2f} s "
        f"({metrics['realtime_factor']:.0f}x real time)"
    )


def main_job(out_dir: str | Path, progress: bool = True) -> list[RunResult]:
    """What ``make run`` does: both closed loops next to dead reckoning on the real marina when
    ``$SONARSLAM_DATA`` holds it, otherwise on a freshly simulated harbour; plus the scan map.

    Returns the run results (dead reckoning first).
    """
    from datasets.source import data_root

    out = Path(out_dir)
    root = data_root()
    if root is not None and (root / "marina").is_dir():
        source: str | Path = "marina"
        name = "marina"
    else:
        from datasets.simulator import simulate

        source = simulate("harbour", seed=0, out_dir=out / "sim_harbour_0")
        name = "sim_harbour_0"
    results = [
        run(source, backend, out / f"{name}-{backend}", progress=progress)
        for backend in ("dr", "ekf", "isam2")
    ]
    from features.projection import project_beams
    from slam.io.plots import plot_scans

    dataset = open_dataset(source)
    gps = gps_ahrs_trajectory(dataset)
    points, _ = project_beams(
        dataset.nav_beams(),
        dataset.config.sonar,
        dataset.config.sonar_mounting,
        gps,
        map_min_intensity(dataset),
    )
    plot_scans(
        out / f"{name}_scans_gps.png",
        points,
        {"gps": gps},
        f"{name}: sonar bins projected with GPS poses",
    )
    return results
