"""A run directory read back for ``sonarslam report`` (:mod:`sonarslam.slam.run.report`): its
``metrics.json``, its trajectory ``<backend>.tum`` (with ``<backend>_cov.npz``), ``gps.tum``,
``map.json``, and the run's dataset when it can still be opened (GPS fixes, beams, truth)."""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.slam.eval.consistency import nees_series
from sonarslam.slam.eval.evo_metrics import evo_metrics_of_run
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.trajectory import (
    GPS_FILE,
    Trajectory,
    cov_file,
    load_run_trajectory,
    read_tum,
    trajectory_stem,
)

__all__ = ["DISPLAY_NAMES", "RunData", "load_run", "evaluate_run"]

#: Names of the back ends in the tables.
DISPLAY_NAMES = {"dr": "dead reckoning", "gps": "GPS + AHRS", "ekf": "EKF-SLAM", "isam2": "iSAM2"}


@dataclass
class RunData:
    """One run directory, read.

    Attributes
    ----------
    run_dir : Path
    metrics : dict
        ``metrics.json``.
    trajectory : Trajectory
        ``<backend>.tum``, with the covariances of ``<backend>_cov.npz`` when present.
    gps : Trajectory
        ``gps.tum`` (the GPS fixes inside the run, with the AHRS heading).
    landmarks : list of dict or None
        ``map.json``'s landmarks (closed loops).
    dataset : Dataset or None
        The run's dataset, when its ``source`` can still be opened.
    truth : Trajectory or None
        The simulator's truth (simulated datasets).
    notes : list of str
        What the report could not do for this run, and why.
    """

    run_dir: Path
    metrics: dict[str, Any]
    trajectory: Trajectory
    gps: Trajectory
    landmarks: list[dict[str, Any]] | None = None
    dataset: Dataset | None = None
    truth: Trajectory | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def backend(self) -> str:
        return str(self.metrics.get("backend", self.run_dir.name))

    @property
    def stem(self) -> str:
        """File stem of the run's trajectory (``ekf``)."""
        return trajectory_stem(self.backend)

    @property
    def source(self) -> str:
        """The run's dataset as ``metrics.json`` names it (its path): runs of one source are
        comparable, runs of two sources with one file name are not."""
        return str(self.metrics.get("source", "unknown"))

    @property
    def dataset_name(self) -> str:
        return Path(self.source).name

    @property
    def name(self) -> str:
        return self.run_dir.name


def safe_name(name: str) -> str:
    """``name`` made a file name's part: runs of other characters than letters, digits, ``_``,
    ``.`` and ``-`` (a section's ``day1/run.bag``) become one ``_``."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def source_key(source: str) -> str:
    """One key for one dataset however its path was typed: the path made absolute (against the
    working directory) and normalised, so that ``../d/run.bag`` and ``/tmp/d/run.bag`` are one."""
    return os.path.normpath(os.path.abspath(source))


def source_labels(sources: Iterable[str]) -> dict[str, str]:
    """A name per source for the report's sections: its file name, or as many of its last path
    parts as tell it from the other sources' (``day1/run.bag``, ``day2/run.bag``)."""
    given = list(sources)
    unique = sorted({source_key(s) for s in given})
    parts = {s: Path(s).parts or (s,) for s in unique}
    labels = {}
    for s in unique:
        k = 1
        while k < len(parts[s]) and any(o != s and parts[o][-k:] == parts[s][-k:] for o in unique):
            k += 1
        labels[s] = "/".join(parts[s][-k:])
    return {s: labels[source_key(s)] for s in given}


def load_run(run_dir: str | Path, open_source: bool = True) -> RunData:
    """Read a run directory; open its dataset unless ``open_source`` is False (or it is gone)."""
    run = Path(run_dir)
    if not (run / "metrics.json").is_file():
        raise FileNotFoundError(f"{run}: no metrics.json (not a run directory of sonarslam run)")
    metrics = json.loads((run / "metrics.json").read_text())
    stem = trajectory_stem(str(metrics.get("backend", "")))
    if not (run / GPS_FILE).is_file() and "ate_mean_m" not in metrics:
        raise ValueError(
            f"{run}: a run without GPS ({metrics.get('evaluation', 'no ATE')}): report compares"
            " runs against gps.tum; see the run's own report.png, map.png and metrics.json"
            " map_entropy_nats"
        )
    for name in (f"{stem}.tum", GPS_FILE):
        if not (run / name).is_file():
            raise FileNotFoundError(f"{run}: no {name} (not a run directory of sonarslam run)")
    data = RunData(run, metrics, load_run_trajectory(run, stem), read_tum(run / GPS_FILE))
    if (run / "map.json").is_file():
        data.landmarks = json.loads((run / "map.json").read_text()).get("landmarks", [])
    if data.trajectory.covs is None:
        data.notes.append(f"no {cov_file(stem)}: no covariance bounds nor NEES")
    source = metrics.get("source")
    if open_source and source:
        try:
            data.dataset = open_dataset(source)
        except (DataError, OSError) as exc:
            data.notes.append(f"dataset not opened ({exc}): no reprojected map, GPS from gps.tum")
    if data.dataset is not None and data.dataset.truth is not None:
        data.truth = truth_trajectory(data.dataset)
    return data


def evaluate_run(run: RunData, rpe_delta_m: float = 10.0, align: bool = False) -> dict[str, Any]:
    """evo's APE/RPE on the run's TUM files and, with truth and covariances, the NEES.

    Returns
    -------
    dict
        :func:`sonarslam.slam.eval.evo_metrics.evo_metrics_of_run`'s keys, and ``nees_mean``,
        ``nees_in_band_fraction`` (pose, 3 dof), ``nees_position_mean`` when available: the
        run's own ``metrics.json`` figures, computed from the files only for a run without them.
    """
    out: dict[str, Any] = dict(evo_metrics_of_run(run.run_dir, run.stem, rpe_delta_m, align=align))
    m = run.metrics
    if m.get("nees_pose_mean") is not None:  # the run's own: one figure in every output
        out["nees_mean"] = m["nees_pose_mean"]
        out["nees_in_band_fraction"] = m.get("nees_pose_in_band_fraction")
        out["nees_position_mean"] = m.get("nees_position_mean")
    elif run.truth is not None and run.trajectory.covs is not None:  # a run from before them
        pose = nees_series(run.trajectory, run.truth, "pose")
        out["nees_mean"] = pose.mean
        out["nees_in_band_fraction"] = pose.in_band_fraction()
        out["nees_position_mean"] = nees_series(run.trajectory, run.truth, "position").mean
    return out
