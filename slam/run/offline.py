"""The offline estimate of a factor-graph run, from the run itself or from its saved graph and
its data (:func:`sonarslam.slam.backends.isam2.offline.offline_estimate` decides; here it gets
its inputs).

* :func:`offline_of_run`: after ``sonarslam run SOURCE --backend isam2`` (on by default,
  ``--set isam2.offline=false`` turns it off): the back end's graph, its smoothed estimate and
  node times, the dataset's beams and dead reckoning.
* :func:`offline_from_saved`: the same from a run directory's ``graph.json`` and the dataset it
  was run on (the API for a run made before, or with the estimate off).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

from sonarslam.datasets.config import config_tables, load_dataset_config
from sonarslam.datasets.dataset import Dataset
from sonarslam.features.scans import ScanConfig
from sonarslam.settings import SettingError
from sonarslam.slam.backends.isam2.config import GraphConfig, OfflineConfig
from sonarslam.slam.backends.isam2.graph import LineIsam2
from sonarslam.slam.backends.isam2.graph_io import FactorRecord, Robust, values_from_json
from sonarslam.slam.backends.isam2.offline import OfflineResult, offline_estimate
from sonarslam.slam.run.presets import SCAN_PRESETS, apply_overrides, preset_for
from sonarslam.slam.run.provenance import dataset_digests
from sonarslam.slam.run.sources import dead_reckoning_trajectory
from sonarslam.sonar.beam import SonarBeam

__all__ = ["offline_of_run", "offline_from_saved", "wants_offline"]


def wants_offline(backend_config: Any) -> bool:
    """Whether a run with this back-end configuration makes the offline estimate."""
    return isinstance(backend_config, GraphConfig) and backend_config.offline.enabled


def _beams(dataset: Dataset, t0_s: float, t1_s: float) -> Iterator[SonarBeam]:
    for record in dataset.stream(t0_s, t1_s):
        if isinstance(record, SonarBeam):
            yield record


def _estimate(
    dataset: Dataset,
    records: list[FactorRecord],
    values: gtsam.Values,
    node_t_s: np.ndarray,
    graph: GraphConfig,
    scans: ScanConfig,
    offline: OfflineConfig | None = None,
) -> OfflineResult:
    cfg = dataset.config
    t0, t1 = float(node_t_s[0]), float(node_t_s[-1])
    _check_covers(dataset, t0, t1)
    robust = None if graph.scan_robust is None else Robust(graph.scan_robust, graph.scan_robust_k)
    return offline_estimate(
        records,
        values,
        node_t_s,
        lambda: _beams(dataset, t0, t1),
        cfg.sonar,
        cfg.sonar_mounting,
        dead_reckoning_trajectory(dataset),
        scans,
        offline or graph.offline,
        graph.association,
        robust,
    )


#: The run's nodes may start or end this far (s) outside the dataset's navigation (its start
#: pose is the first GPS fix inside it; its last node the last record).
SPAN_TOLERANCE_S = 1.0


def _check_covers(dataset: Dataset, t0_s: float, t1_s: float) -> None:
    """Refuse a dataset that is not the run's: its navigation must cover the run's nodes
    (``t0_s`` to ``t1_s``, Unix s) and its sonar must have beams among them."""
    n0, n1 = dataset.nav_span_s
    beams = np.asarray(dataset.beams.t_s)
    inside = int(np.count_nonzero((beams >= t0_s) & (beams <= t1_s)))
    if t0_s < n0 - SPAN_TOLERANCE_S or t1_s > n1 + SPAN_TOLERANCE_S or inside == 0:
        raise SettingError(
            "dataset",
            f"{dataset.root} is not the run's dataset: the run's nodes span {t0_s:.3f} to"
            f" {t1_s:.3f} s (Unix), its navigation {n0:.3f} to {n1:.3f} s, with {inside} sonar"
            " beams among the nodes (give the dataset the run was made on, with the same"
            " --config and --span)",
        )


def offline_of_run(dataset: Dataset, backend: LineIsam2, scans: ScanConfig) -> OfflineResult:
    """The offline estimate after a run of the factor graph ``backend`` on ``dataset``, with the
    run's scan settings ``scans`` (:attr:`sonarslam.slam.run.presets.RunConfig.scans`); from
    iSAM2's smoothed estimate (not a batch pass's)."""
    backend.finish()
    n = backend.n_nodes
    return _estimate(
        dataset,
        list(backend.records),
        backend.isam.calculateEstimate(),
        np.asarray(backend.nodes.t_s[:n], dtype=np.float64),
        backend.config,
        scans,
    )


def offline_from_saved(
    run_dir: str | Path,
    dataset: Dataset,
    offline: OfflineConfig | None = None,
    scans: ScanConfig | None = None,
    check_dataset: bool = True,
) -> OfflineResult:
    """The offline estimate of a saved factor-graph run: its ``graph.json`` (records, values,
    node times and settings) and the dataset it was run on.

    Parameters
    ----------
    run_dir : str or Path
        A ``sonarslam run ... --backend isam2`` output directory.
    dataset : Dataset
        The dataset of that run (:func:`sonarslam.datasets.source.open_dataset`).
    offline : OfflineConfig, optional
        Default: the run's own (``graph.json``'s settings).
    scans : ScanConfig, optional
        Default: the scan preset of the dataset's beams with the run's ``scans.*`` settings
        (``metrics.json``), as the run took them.
    check_dataset : bool
        Refuse a dataset whose files' digest is not the run's (``metrics.json``
        ``provenance.dataset_sha256``): another dataset, or this one's files changed since; and
        one opened with another configuration than the run's (``config_used.toml``: the sonar,
        the mountings, the noise and the motion model, which the scans and dead reckoning are
        rebuilt with). Open it with the run's: ``open_dataset(SOURCE,
        config_override=run_dir / "config_used.toml")``.

    Raises
    ------
    SettingError
        ``run_dir`` is no directory, holds no factor graph (``graph.json``), or ``dataset``
        does not cover the run's nodes (another dataset than the run's).
    """
    run = Path(run_dir)
    path = run / "graph.json"
    if not run.is_dir():
        raise SettingError("run_dir", f"{run}: no such run directory")
    if not path.is_file():
        raise SettingError("run_dir", f"{run} has no graph.json: not a factor-graph run")
    doc = json.loads(path.read_text())
    records = [
        FactorRecord.from_json(item, f"{path}: factor {i}") for i, item in enumerate(doc["factors"])
    ]
    values = values_from_json(doc["values"])
    node_times = doc["meta"]["node_times_s"]
    n = len(node_times)
    node_t = np.array([node_times[f"x{k}"] for k in range(n)], dtype=np.float64)
    if not all(values.exists(X(k)) for k in range(n)):
        raise SettingError("run_dir", f"{path}: its values lack some of its {n} nodes")
    saved = _saved_metrics(run)
    if check_dataset:
        _check_digest(run, saved, dataset)
        _check_config(run, dataset)
    found = saved.get("settings", {})
    settings = dict(found) if isinstance(found, dict) else {}
    graph = _graph_config(doc["meta"].get("config", {}))
    if scans is None:
        scan_settings = {
            k.partition(".")[2]: v for k, v in settings.items() if k.startswith("scans.")
        }
        preset = SCAN_PRESETS.get(preset_for(dataset.beams), SCAN_PRESETS["default"])
        scans = apply_overrides(preset, scan_settings, prefix="scans.")
    return _estimate(dataset, records, values, node_t, graph, scans, offline)


def _saved_metrics(run: Path) -> dict[str, Any]:
    metrics = run / "metrics.json"
    found = json.loads(metrics.read_text()) if metrics.is_file() else {}
    return dict(found) if isinstance(found, dict) else {}


def _check_digest(run: Path, metrics: dict[str, Any], dataset: Dataset) -> None:
    """Refuse ``dataset`` when the run recorded the digest of the files it read
    (``provenance.dataset_sha256``) and this dataset's differ."""
    recorded = (metrics.get("provenance") or {}).get("dataset_sha256")
    if not recorded:
        return
    digest = dataset_digests(Path(dataset.root), dataset.inputs)[0]
    if digest != recorded:
        raise SettingError(
            "dataset",
            f"{dataset.root} is not the dataset {run} was run on: its files' SHA-256"
            f" {digest[:12]}... is not the run's {recorded[:12]}... (metrics.json provenance:"
            f" {metrics.get('source')}); give that dataset, or check_dataset=False if its files"
            " changed on purpose",
        )


#: The tables of ``config_used.toml`` the offline estimate rebuilds its scans and dead
#: reckoning with, as :func:`sonarslam.datasets.config.config_tables` names them.
CONFIG_TABLES = (
    "sonar",
    "mounting.sonar",
    "mounting.dvl",
    "mounting.ahrs",
    "noise",
    "motion",
)


def _check_config(run: Path, dataset: Dataset) -> None:
    """Refuse ``dataset`` when its configuration differs from the run's ``config_used.toml``
    (read as a run reads a ``--config``, over the dataset's own) in a value the offline estimate
    reads (:data:`CONFIG_TABLES`; a run whose directory has no such file is not checked)."""
    path = run / "config_used.toml"
    if not path.is_file():
        return
    used = config_tables(load_dataset_config(path, base=dataset.config))
    ours = config_tables(dataset.config)
    differ = [
        f"[{name}] {key} = {theirs!r} in the run, {ours[name].get(key)!r} here"
        for name in CONFIG_TABLES
        for key, theirs in used[name].items()
        if key != "source" and not _same(ours[name].get(key), theirs)
    ]
    if differ:
        raise SettingError(
            "dataset",
            f"{dataset.root} was opened with another configuration than {run}'s"
            f" ({path}): {'; '.join(differ[:4])}{' ...' if len(differ) > 4 else ''}; the"
            " offline estimate rebuilds the scans and dead reckoning with it: open the dataset"
            f" with the run's, open_dataset(SOURCE, config_override={str(path)!r})",
        )


def _same(a: Any, b: Any) -> bool:
    """Two configuration values alike (numbers to 1e-9 relative, lists element by element)."""
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    return bool(a == b)


def _graph_config(saved: dict[str, Any]) -> GraphConfig:
    """The run's :class:`GraphConfig` from ``graph.json``'s settings (the fields the offline
    estimate reads; the rest stay the defaults)."""
    config = GraphConfig()
    offline = saved.get("offline")
    changes: dict[str, Any] = {}
    if isinstance(offline, dict):  # the fields this version knows (a newer run's may differ)
        known = {f.name for f in fields(OfflineConfig)}
        changes["offline"] = OfflineConfig(**{k: v for k, v in offline.items() if k in known})
    for key in ("scan_robust", "scan_robust_k"):
        if key in saved:
            changes[key] = saved[key]
    return replace(config, **changes)
