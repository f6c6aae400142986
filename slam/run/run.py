"""One runner for the CLI, the sweep, the notebooks and the benchmarks.

:func:`run_backend` runs a back end on an opened dataset and measures it, writing nothing;
:func:`run` opens a dataset, runs, and writes the run directory (:mod:`sonarslam.slam.run.outputs`). A
back end is a baseline that needs no estimator (``dr``, ``gps``: :mod:`sonarslam.slam.run.sources`) or a
closed loop (:data:`sonarslam.slam.backends.registry.BACKENDS`), whose settings come from
:mod:`sonarslam.slam.run.presets`.

The ATE protocol (:mod:`sonarslam.slam.eval.ate`): the start pose is the first GPS fix with the heading
sensor; the ATE is taken at every GPS fix inside the trajectory's span, with no alignment.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, is_dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sonarslam.datasets.config import dump_dataset_config
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.ping360 import is_ping360_log
from sonarslam.datasets.rosbag import is_bag
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.settings import SettingError
from sonarslam.slam.backends.isam2.graph import LineIsam2
from sonarslam.slam.backends.registry import BACKENDS, backend_spec
from sonarslam.slam.eval.health import HealthConfig, travel_cause
from sonarslam.slam.eval.loops import (
    LOOP_CAUSES,
    LOOP_MIN_GAP_S,
    LOOP_MIN_PATH_M,
    ODOMETRY_CAUSES,
    ODOMETRY_MIN_PAIRS,
    LoopError,
    LoopSearch,
    OdometryCheck,
    loop_errors,
    odometry_check,
    search_loops,
    stated_loops,
)
from sonarslam.slam.io.files import check_output_dir
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.calibration import sonar_clock_doubt
from sonarslam.slam.run.closed_loop import ClosedLoopResult, run_closed_loop
from sonarslam.slam.run.health import monitor_run
from sonarslam.slam.run.metrics import (
    ClosedLoopFigures,
    DataFigures,
    LoopFigures,
    RunMetrics,
    closed_loop_figures,
    trajectory_figures,
)
from sonarslam.slam.run.offline import offline_of_run, wants_offline
from sonarslam.slam.run.outputs import write_run
from sonarslam.slam.run.presets import (
    RunConfig,
    check_combination,
    check_settings,
    run_config,
)
from sonarslam.slam.run.provenance import provenance
from sonarslam.slam.run.sources import (
    POSE_SOURCES,
    dead_reckoning_trajectory,
    dvl_body_velocities,
    dvl_quality,
    lateral_mirror_trajectory,
    mounting_yaw_said,
    start_pose_origin,
    warn_dvl_lever_arm,
    warn_dvl_sigma,
)

__all__ = [
    "BASELINES",
    "RunResult",
    "backend_names",
    "run_backend",
    "run",
    "summary_line",
    "smoothed_lines",
    "results_table",
    "odometry_line",
]

#: Back ends that are pose sources, not estimators with settings.
BASELINES = ("dr", "gps")


def backend_names() -> list[str]:
    """Every ``--backend``: the baselines, then the closed loops of the registry."""
    return [*BASELINES, *BACKENDS]


@dataclass
class RunResult:
    """What a run estimated and measured.

    Attributes
    ----------
    backend : str
    trajectory : Trajectory
        The run's trajectory (a closed loop's is causal: the filtered pose at every AHRS record).
    metrics : dict
        The content of ``metrics.json`` (``figures.to_json()``).
    closed_loop : ClosedLoopResult or None
        The closed loop's lines, landmarks and back end (None for a baseline).
    config : RunConfig or None
        The closed loop's settings.
    trajectories : dict of str to Trajectory
        The back end's other trajectories (``smoothed``, ``batch``).
    out_dir : Path or None
        Where the files were written (None: nothing written).
    files : list of Path
        The files this run wrote there.
    notes : list of str
        Lines for the terminal about what the files hold (``graph.g2o``: what the format cannot
        hold, expected of it).
    figures : RunMetrics or None
        The typed figures ``metrics`` is written from (None for a result made elsewhere).
    """

    backend: str
    trajectory: Trajectory
    metrics: dict[str, Any]
    closed_loop: ClosedLoopResult | None = None
    config: RunConfig | None = None
    trajectories: dict[str, Trajectory] = field(default_factory=dict)
    out_dir: Path | None = None
    files: list[Path] = field(default_factory=list)
    figures: RunMetrics | None = None
    notes: list[str] = field(default_factory=list)


def run_backend(
    dataset: Dataset,
    backend: str,
    settings: dict[str, Any] | None = None,
    t_end_s: float | None = None,
    progress: bool = False,
    batch: bool = False,
    *,
    config: RunConfig | None = None,
) -> RunResult:
    """Run one back end on a dataset and measure it; no file is written.

    Parameters
    ----------
    dataset : Dataset
        With GPS, the start pose is the first fix and the ATE is taken against GPS; without
        it, the start is the origin with the AHRS heading and no ATE is given.
    backend : str
        One of :func:`backend_names`.
    settings : dict, optional
        ``SCOPE.FIELD`` -> value (:mod:`sonarslam.slam.run.presets`); closed loops only.
        Give either this or ``config``.
    t_end_s : float, optional
        Stop at this time (Unix s).
    progress : bool
        Progress bar of the closed loop.
    batch : bool
        Back ends that smooth: also a final batch optimisation (``trajectories["batch"]``).
    config : RunConfig, optional
        The typed settings of a closed loop (:meth:`RunConfig.for_dataset` changed with
        :func:`dataclasses.replace`); its back-end configuration must be ``backend``'s type.
        ``metrics.json``'s ``settings`` are then its fields that differ from
        :meth:`RunConfig.for_dataset`'s, by dotted name.

    Returns
    -------
    RunResult
        ``metrics`` has ``source``, ``backend``, the ATE fields over the whole navigation span
        (``ate_*``) and over the sonar span (``ate_sonar_*``, ``sonar_span_s``), each also after
        a rigid SE(2) fit onto the GPS (``ate_aligned_*``, ``ate_sonar_aligned_*``), on simulated
        data against the truth too (``ate_truth_*``, ``ate_truth_aligned_*``), ``wall_s`` (the estimation),
        ``data_s``, ``realtime_factor``, the DVL's quality and, for closed loops, the settings,
        the extractor preset, ``landmarks``, ``line_features``, ``assoc_*``, ``extractor_s``,
        ``backend_s``, ``beams``, the back end's own figures, the ATE of its other
        trajectories (``ate_mean_smoothed_m``, ...) and, on simulated data, the association
        scores against the true walls (``truth_*``).
    """
    if backend not in backend_names():
        raise SettingError("--backend", f"must be one of {backend_names()}, got {backend!r}")
    loop: ClosedLoopFigures | None = None
    result: ClosedLoopResult | None = None
    trajectories: dict[str, Trajectory] = {}
    if dataset.still and backend != "dr":
        raise SettingError(
            "--backend",
            f"{dataset.root} has no navigation, so it is read as a still head: --backend dr"
            f" runs on it (the still pose); {backend} needs a DVL and an AHRS: --nav FILE (a ROS"
            " bag, the navigation CSV, or the vehicle's own logs: a QGroundControl .tlog, an"
            " ArduSub dataflash .bin, a Water Linked A50 JSON log, a QGroundControl CSV export;"
            " repeat it to take the DVL from one and the heading from another)",
        )
    if config is not None:
        config = replace(config, settings=_typed_settings(dataset, backend, config, settings))
    quality = dvl_quality(dataset)
    if backend != "gps" and not dataset.still:  # the DVL, its dvl_sigma_mps and lever arm
        warn_dvl_sigma(dataset, quality)
        warn_dvl_lever_arm(dataset)
    wall0 = time.perf_counter()
    offline_s = 0.0
    if backend in BASELINES:
        if settings:
            raise SettingError(
                "--set", f"back end {backend!r} has no settings, got {sorted(settings)}"
            )
        if batch:
            raise SettingError("--batch", f"back end {backend!r} does not smooth")
        if backend == "gps" and dataset.gps is None:
            raise SettingError(
                "--backend",
                f"gps needs a GPS, and {dataset.root} has none (*_DGPS.log or a NavSatFix"
                " topic): take --backend dr",
            )
        trajectory = POSE_SOURCES[backend](dataset)
        if backend == "dr" and not dataset.still:  # no health monitor: the travel check is
            _warn_travel(dataset)  # the one that sees a DVL turned round when the sonar was
            # calibrated on it
    else:
        result, config, trajectories, loop, offline_s = _closed_loop(
            dataset, backend, settings, t_end_s, progress, batch, config
        )
        trajectory = result.trajectory
    # the loop's own time: the offline estimate after it is timed apart (offline_s)
    wall_s = time.perf_counter() - wall0 - offline_s
    if t_end_s is not None and trajectory.t_s[-1] > t_end_s:
        trajectory = trajectory.clip(trajectory.t_s[0], t_end_s)
    for tr in (trajectory, *trajectories.values()):
        _check_finite(dataset, backend, tr)
    figures = RunMetrics(
        source=str(dataset.root),
        backend=backend,
        trajectory=trajectory_figures(dataset, trajectory, ""),
        data=_data_figures(dataset, trajectory, wall_s, quality),
        closed_loop=loop,
        others=[trajectory_figures(dataset, tr, name) for name, tr in trajectories.items()],
        calibration=dataset.calibration,
        evaluation=evaluation(dataset),
        start_pose=start_pose_origin(dataset),
    )
    return RunResult(
        backend, trajectory, figures.to_json(), result, config, trajectories, figures=figures
    )


def _warn_travel(dataset: Dataset) -> None:
    """Dead reckoning's own ``travel`` check (:func:`sonarslam.slam.eval.health.travel_cause`),
    warned: a closed loop's health monitor judges it; a ``dr`` run has none."""
    cause, _ = travel_cause(dvl_body_velocities(dataset), HealthConfig())
    if cause is not None:
        warnings.warn(
            f"{dataset.root}: {cause} (now:"
            f" {mounting_yaw_said('dvl', dataset.config.dvl_mounting)})",
            DataWarning,
            stacklevel=3,
        )


def _closed_loop(
    dataset: Dataset,
    backend: str,
    settings: dict[str, Any] | None,
    t_end_s: float | None,
    progress: bool,
    batch: bool,
    typed: RunConfig | None = None,
) -> tuple[ClosedLoopResult, RunConfig, dict[str, Trajectory], ClosedLoopFigures, float]:
    """A closed loop of ``backend`` on the dataset (:func:`run_backend`): its result, its
    configuration (``typed``, or made from ``settings``), the back end's other trajectories (the
    factor graph's offline estimate among them), the loop's figures with the health monitor's
    verdict (which warns here) and the offline estimate's wall time (s)."""
    spec = backend_spec(backend)
    if batch and not spec.smoother:
        raise SettingError("--batch", f"back end {backend!r} does not smooth")
    _require_beams(dataset)
    check_combination(dataset, backend)
    config = (
        typed
        if typed is not None
        else run_config(dataset.beams, backend, settings, dataset.config.noise)
    )
    mounting = dataset.config.sonar_mounting
    cfg = config.backend
    result = run_closed_loop(
        dataset,
        lambda t0, pose0, cov0: spec.make(t0, pose0, cov0, mounting, cfg),
        config.extractor,
        progress=progress,
        t_end_s=t_end_s,
        label=backend,
        scan_config=config.scans,
    )
    result.backend.finish()
    trajectories = result.backend.trajectories(batch)
    offline_s = 0.0
    if wants_offline(config.backend):
        assert isinstance(result.backend, LineIsam2), "the offline estimate is the graph's"
        wall0 = time.perf_counter()
        result.backend.offline = offline_of_run(dataset, result.backend, config.scans)
        trajectories["offline"] = result.backend.offline.trajectory
        offline_s = time.perf_counter() - wall0
    # the sonar's motion against dead reckoning's is a check of the run too (GPS-free)
    odometry = dataset_odometry_check(dataset)
    health = monitor_run(dataset, result, odometry=odometry)  # GPS-free: against its own model
    loop = closed_loop_figures(dataset, result, config, health.metrics(), health.line(), odometry)
    health.warn()
    return result, config, trajectories, loop, offline_s


def _typed_settings(
    dataset: Dataset, backend: str, config: RunConfig, settings: dict[str, Any] | None
) -> dict[str, Any]:
    """The dotted settings a typed ``config`` stands for: its fields that differ from
    :meth:`RunConfig.for_dataset`'s (refused with ``settings`` too, on a baseline, or with
    another back end's configuration type)."""
    if settings:
        raise SettingError("settings", "give either settings or config, not both")
    if backend in BASELINES:
        raise SettingError("config", f"back end {backend!r} has no settings")
    want = backend_spec(backend).config_type
    if type(config.backend) is not want:
        raise SettingError(
            "config.backend",
            f"back end {backend!r} takes a {want.__name__}, got {type(config.backend).__name__}",
        )
    default = RunConfig.for_dataset(dataset, backend)
    _check_made_for(config, default)
    return {
        **_differences(default.extractor, config.extractor, "extractor."),
        **_differences(default.backend, config.backend, f"{backend}."),
        **_differences(default.scans, config.scans, "scans."),
    }


def _check_made_for(config: RunConfig, default: RunConfig) -> None:
    """Refuse a configuration made for another dataset (``config.dataset``) whose extractor
    preset or ``[noise]`` calibration differ from this one's (``default``, its
    :meth:`RunConfig.for_dataset`): the run would take the other's silently."""
    if config.dataset is None or config.dataset == default.dataset:
        return
    differ = []
    if config.preset != default.preset:
        differ.append(f"extractor preset ({config.preset!r}, here {default.preset!r})")
    if config.backend.noise != default.backend.noise:
        changed = _differences(default.backend.noise, config.backend.noise, "")
        differ.append(f"[noise] ({', '.join(sorted(changed))})")
    if differ:
        raise SettingError(
            "config.dataset",
            f"the RunConfig was made for {config.dataset} (RunConfig.for_dataset) and is run on"
            f" {default.dataset}, whose {' and '.join(differ)} differ: it would run with the"
            " other's. Make it with RunConfig.for_dataset(this dataset, backend), or give"
            " replace(config, dataset=None) to run it as it is",
        )


def _differences(default: Any, given: Any, prefix: str) -> dict[str, Any]:
    """``prefix + FIELD`` -> value of the fields of dataclass ``given`` that differ from
    ``default``'s, nested dataclasses by dots."""
    out: dict[str, Any] = {}
    for f in fields(given):
        a, b = getattr(default, f.name), getattr(given, f.name)
        if is_dataclass(b) and type(a) is type(b):
            out.update(_differences(a, b, f"{prefix}{f.name}."))
        elif a != b:
            out[prefix + f.name] = b
    return out


def _data_figures(
    dataset: Dataset, trajectory: Trajectory, wall_s: float, quality: dict[str, float]
) -> DataFigures:
    """The run's wall time and its data's span, the DVL's rows and quality, the GPS's
    coverage and the gates' faults and gaps over the trajectory's span; ``quality`` is
    :func:`sonarslam.slam.run.sources.dvl_quality`'s."""
    t0, t1 = trajectory.span_s
    return DataFigures(
        wall_s=wall_s,
        data_s=t1 - t0,
        dvl_rows=int(dataset.dvl.t.size),
        dvl_invalid_rows=int((~dataset.dvl.valid).sum()),
        dvl_quality=quality,
        gps_uncovered_s=_gps_uncovered_s(dataset, trajectory),
        faults_and_gaps=dataset.report.metrics((t0, t1)),
    )


def _span(span: tuple[float, float]) -> str:
    return f"{span[0]:.3f}-{span[1]:.3f} s"


def _require_beams(dataset: Dataset) -> None:
    """A closed loop without a beam inside the navigation span would be dead reckoning."""
    if dataset.sonar_span_s is not None:
        return
    beams = _span((dataset.beams[0].t, dataset.beams[-1].t)) if dataset.beams else "none"
    raise DataError(
        dataset.root,
        None,
        f"no sonar beam inside the navigation span {_span(dataset.nav_span_s)} (the"
        f" {len(dataset.beams)} beams: {beams}; [sonar] time_offset_s?): a closed loop would"
        " be dead reckoning",
    )


def _check_finite(dataset: Dataset, backend: str, trajectory: Trajectory) -> None:
    """The last guard: a trajectory with a pose or covariance that is not finite is an error
    (a fault the gates let through), never numbers written as if they were."""
    bad = ~np.all(np.isfinite(trajectory.poses_wTb), axis=1)
    if trajectory.covs is not None:
        bad |= ~np.all(np.isfinite(trajectory.covs), axis=(1, 2))
    if bad.any():
        t = float(trajectory.t_s[np.flatnonzero(bad)[0]])
        raise DataError(
            dataset.root, None, f"the {backend} estimate is not finite from t={t:.3f} s on"
        )


def evaluation(dataset: Dataset) -> str:
    """What a run of ``dataset`` is measured against (``metrics.json evaluation``): GPS (the
    ruler, never an input), the simulator's truth, or without either the loop-closure error
    (``loop_*``), the map's entropy (``map_entropy_nats``, lower is sharper) and the pictures."""
    if dataset.gps is not None:
        return "gps and truth" if dataset.truth is not None else "gps"
    if dataset.still:
        still = "a still head (no navigation)"
        if dataset.truth is not None:
            return f"truth; {still}"
        # one head turn's map moved rigidly: its entropy changes only with where the cells fall
        return (
            f"{still}: no ATE, no loops; the pictures (map_entropy_nats does not judge a still"
            " head's pose)"
        )
    if dataset.truth is not None:
        return "truth and loops (no GPS)"
    return (
        "no GPS: no ATE; the loop-closure error (loop_*), the map's entropy (map_entropy_nats)"
        " and the pictures"
    )


def _gps_uncovered_s(dataset: Dataset, trajectory: Trajectory) -> float | None:
    """How much of the run the GPS covers (``gps_uncovered_s``: the run's time before the
    first and after the last fix), with a warning naming the span when a gap of the GPS's
    threshold is left uncovered: the ATE is then over the covered part only. None without
    GPS."""
    if dataset.gps is None:
        return None
    t0, t1 = trajectory.span_s
    g = dataset.gps.t
    inside = g[(g >= t0) & (g <= t1)]
    first, last = (float(inside[0]), float(inside[-1])) if inside.size else (t1, t1)
    uncovered = max(first - t0, 0.0) + max(t1 - last, 0.0)
    gaps = dataset.report.gaps.get("gps")
    threshold = gaps.threshold_s if gaps is not None else 0.0
    if uncovered > threshold:
        warnings.warn(
            f"{dataset.gps.path or dataset.root}: the GPS covers {_span((first, last))} of the"
            f" run's {_span((t0, t1))}: the ATE is over its {inside.size} fixes only",
            DataWarning,
            stacklevel=3,
        )
    return uncovered


def run(
    source: str | Path,
    backend: str,
    out_dir: str | Path,
    progress: bool = True,
    batch: bool = False,
    config: str | Path | None = None,
    settings: dict[str, Any] | None = None,
    start_enu: tuple[float, float, float] | None = None,
    topics_file: str | Path | None = None,
    loops_rel_s: list[tuple[float, float]] | None = None,
    nav: str | Path | Sequence[str | Path] | None = None,
    span_s: tuple[float, float] | None = None,
) -> RunResult:
    """Open a dataset, run a back end on it (:func:`run_backend`) and write the run directory
    (:func:`sonarslam.slam.run.outputs.write_run`).

    ``loops_rel_s``: pairs of times (s from the start of the navigation) at which the vehicle
    was at one place; with them, or without GPS, the run measures the loop-closure error
    (:func:`loop_figures`). ``span_s``: only the part of the source from ``T0`` to ``T1`` (s
    from the start of its navigation; :func:`sonarslam.datasets.dataset.dataset_span`), whose
    start the loops' times then count from.

    ``config``: a ``sonarslam.toml``-format file whose keys replace the dataset's calibration
    (:func:`sonarslam.datasets.source.open_dataset`); the configuration used is written to
    ``config_used.toml``. ``settings``: extractor and back-end settings
    (``{"isam2.robust": "cauchy"}``, :mod:`sonarslam.slam.run.presets`), recorded in ``metrics.json``,
    with the run's provenance (``provenance``: the package version, the git commit and whether
    the tree was dirty, the settings' digest and the dataset's file digests;
    :mod:`sonarslam.slam.run.provenance`).
    """
    # everything that can be checked before reading is checked first, and the output
    # directory is created only when the run has results to write
    check_output_dir(out_dir)
    if backend not in backend_names():
        raise SettingError("--backend", f"must be one of {backend_names()}, got {backend!r}")
    if settings and backend in BASELINES:
        raise SettingError("--set", f"back end {backend!r} has no settings, got {sorted(settings)}")
    if settings:
        check_settings(backend, settings)
    if batch and (backend in BASELINES or not backend_spec(backend).smoother):
        raise SettingError("--batch", f"back end {backend!r} does not smooth")
    dataset = open_dataset(
        source, config_override=config, topics_file=topics_file, nav=nav, span_s=span_s
    )
    if start_enu is not None:
        dataset = replace(dataset, start_enu=start_enu)
    result = run_backend(dataset, backend, settings, progress=progress, batch=batch)
    assert result.figures is not None
    if dataset.still and loops_rel_s:
        raise SettingError("--loop", f"{dataset.root} is a still head (no navigation): no loop")
    if (loops_rel_s or dataset.gps is None) and not dataset.still:  # a still head has none
        result.figures.loops = loop_figures(dataset, result, loops_rel_s or [])
    elif backend != "gps" and not dataset.still:  # with GPS: a mirror, a range scale no ATE names
        _check_odometry(dataset, result)
    if backend != "gps" and not dataset.still and dataset.sonar_span_s is not None:
        _check_sonar_clock(dataset)  # a still head's map is the same at any clock
    result.figures.provenance = provenance(
        backend,
        dataset.root,
        dump_dataset_config(dataset.config),
        result.config,
        batch,
        also=dataset.inputs,
    )
    if span_s is not None:  # part of the source: said where the figures come from
        result.figures.provenance["span_s"] = [float(span_s[0]), float(span_s[1])]
    result.metrics = result.figures.to_json()
    result.files = write_run(
        Path(out_dir),
        dataset,
        result.backend,
        result.trajectory,
        result.metrics,
        result.closed_loop,
        result.trajectories,
        result.notes,
    )
    result.out_dir = Path(out_dir)
    return result


#: A found loop is a return within this share of the sonar's range (the scans overlap).
LOOP_RADIUS_SHARE = 0.4
#: Without GPS, scans this share of the sonar's range apart along dead reckoning (within 1-5 m)
#: check its direction of motion against the sonar's (:func:`sonarslam.slam.eval.loops.odometry_check`).
ODOMETRY_STEP_SHARE = 0.1
#: Pairs of scans the run's odometry check registers: 24, not the function's 12, so that the
#: lateral gain (a mirrored DVL lateral axis) is decided on a 300 s harbour whose crab is +-4
#: deg (12 pairs: standard errors 0.18-0.50, one mirror of three missed; 24: 0.13-0.22, each
#: found; 0.2 s more of CPU).
ODOMETRY_PAIRS = 24
#: The softer level: a mean angle beyond this (deg), or a length ratio further from 1 than
#: :func:`odometry_scale_tolerance`, each also beyond :data:`ODOMETRY_SOFT_SE` of its own
#: standard errors, over at least :data:`ODOMETRY_SOFT_MIN_PAIRS` registrations (docs/outputs.md
#: gives the spread measured on correct simulated runs).
ODOMETRY_SOFT_ANGLE_DEG = 4.0
ODOMETRY_SOFT_SCALE = 0.03
ODOMETRY_SOFT_SE = 3.0
ODOMETRY_SOFT_MIN_PAIRS = 4


def odometry_scale_tolerance(dataset: Dataset) -> float:
    """How far from 1 the odometry check's length ratio may lie before the softer warning:
    :data:`ODOMETRY_SOFT_SCALE` and three of the DVL scale error's sd the dataset states
    (``[noise] dvl_scale_sigma``: a scale error told, which the run estimates), added in
    quadrature."""
    told = float(dataset.config.noise.dvl_scale_sigma)
    return math.hypot(ODOMETRY_SOFT_SCALE, 3.0 * told)


def range_setting(dataset: Dataset) -> str:
    """The setting that gives the sonar's range scale on ``dataset``, in words: a Ping Viewer
    log's bin size is the speed of sound times its sample period, a bag's is its messages' range
    over their bins (no setting overrides it), other sources' is ``[sonar] bin_size_m``."""
    if is_ping360_log(dataset.root):
        return (
            "[ping360] speed_of_sound_mps: a Ping360's bin size is the speed of sound times its"
            " sample period, so a speed of sound some per cent off scales every range by as much"
        )
    if is_bag(dataset.root):
        return (
            "the bag's sonar messages give it, their range over their bins: the driver's range"
            " and speed of sound settings, which no sonarslam setting overrides"
        )
    return "[sonar] bin_size_m"


def _warn_odometry(dataset: Dataset, check: OdometryCheck, in_health: bool = False) -> None:
    """Warn when the sonar sees the vehicle move another way than dead reckoning does: without
    GPS nothing else would show a DVL or sonar mounted the wrong way round (the estimate
    follows it and stays consistent with itself). Two levels: beyond
    :data:`sonarslam.slam.eval.loops.ODOMETRY_MAX_ANGLE_DEG` (a mounting the wrong way round),
    and the softer one (:data:`ODOMETRY_SOFT_ANGLE_DEG`, :func:`odometry_scale_tolerance`, each
    beyond :data:`ODOMETRY_SOFT_SE` standard errors: a mounting some degrees off, a range or DVL
    scale some per cent off). ``in_health``: the health monitor judged this check (a closed
    loop's run), and its ``odometry`` issue warns of the first level."""
    if check.starts and check.skipped_still == check.starts:
        warnings.warn(
            f"{dataset.root}: the sonar cannot check dead reckoning: {check.why_none()}",
            UserWarning,
            stacklevel=3,
        )
        return
    if check.accepted < ODOMETRY_MIN_PAIRS or not math.isfinite(check.heading_deg):
        return
    seen = (
        f"({check.accepted} registrations of scans a few metres apart, standard error"
        f" {check.heading_se_deg:.1f} deg)"
    )
    if check.turned:
        if in_health:
            return
        warnings.warn(
            f"{dataset.root}: the sonar sees the vehicle move {check.heading_deg:+.0f} deg away"
            f" from where dead reckoning moves it {seen}: one of {ODOMETRY_CAUSES} is likely wrong;"
            " every estimate of this run follows dead reckoning's motion",
            UserWarning,
            stacklevel=3,
        )
        return
    if check.mirrored:
        warnings.warn(
            f"{dataset.root}: the sonar sees the vehicle move sideways the other way from dead"
            f" reckoning: the DVL's lateral velocity fits x{check.lateral_gain:+.2f} ±"
            f" {check.lateral_gain_se:.2f} ({check.accepted} registrations of scans a few metres"
            " apart; +1 when right, -1 when mirrored): the DVL's lateral axis has the wrong sign"
            " (its y negated in the log, or a y-right DVL read as y-left). [mounting.dvl]"
            " yaw_deg cannot undo a mirror: negate the DVL's y where its velocities are written"
            " (the log's column, the CSV's dvl_vy, the driver's frame)",
            DataWarning,
            stacklevel=3,
        )
    if check.accepted < ODOMETRY_SOFT_MIN_PAIRS:
        return
    found = []
    angle, se = check.heading_deg, check.heading_se_deg
    if abs(angle) > ODOMETRY_SOFT_ANGLE_DEG and abs(angle) > ODOMETRY_SOFT_SE * se:
        found.append(
            f"the sonar sees the vehicle move {angle:+.1f} ± {se:.1f} deg away from where dead"
            f" reckoning moves it: check {ODOMETRY_CAUSES}"
        )
    scale, scale_se = check.scale, check.scale_se
    if (
        math.isfinite(scale)
        and abs(scale - 1.0) > odometry_scale_tolerance(dataset)
        and abs(scale - 1.0) > ODOMETRY_SOFT_SE * scale_se
    ):
        found.append(
            f"the sonar's lengths are x{scale:.3f} ± {scale_se:.3f} dead reckoning's: check the"
            f" sonar's range ({range_setting(dataset)}; isam2.range_scale_sigma estimates its"
            " scale)"
            " and the DVL's scale ([noise] dvl_scale_sigma lets the run estimate it; allowed"
            f" here: {odometry_scale_tolerance(dataset):.3f})"
        )
    if found:
        warnings.warn(
            f"{dataset.root}: dead reckoning against the sonar ({check.accepted} registrations"
            f" of scans a few metres apart): {'; '.join(found)}",
            UserWarning,
            stacklevel=3,
        )


def dataset_odometry_check(dataset: Dataset, dr: Trajectory | None = None) -> OdometryCheck:
    """The odometry check of a run (:func:`sonarslam.slam.eval.loops.odometry_check`): scans
    :data:`ODOMETRY_STEP_SHARE` of the sonar's range apart (within 1-5 m) along dead reckoning
    (``dr``, made when not given), with the lateral gain against dead reckoning with the DVL's
    lateral velocity mirrored (:func:`sonarslam.slam.run.sources.lateral_mirror_trajectory`)."""
    head = dataset.config.sonar
    range_m = head.n_bins * head.bin_size_m
    dr = dr if dr is not None else dead_reckoning_trajectory(dataset)
    step_m = min(max(ODOMETRY_STEP_SHARE * range_m, 1.0), 5.0)
    return odometry_check(
        dataset, dr, step_m, ODOMETRY_PAIRS, mirrored=lateral_mirror_trajectory(dataset)
    )


def _check_sonar_clock(dataset: Dataset) -> None:
    """Warn when the sonar clock offset of the sharpest map (dead reckoning's poses, GPS-free)
    is not ``[sonar] time_offset_s`` (:func:`sonarslam.slam.run.calibration.sonar_clock_doubt`):
    a clock late by under a second runs every estimate silently worse."""
    doubt = sonar_clock_doubt(dataset, dead_reckoning_trajectory(dataset))
    if doubt:
        warnings.warn(f"{dataset.root}: {doubt}", DataWarning, stacklevel=3)


def _check_odometry(dataset: Dataset, result: RunResult) -> None:
    """The odometry check's warnings on a run whose loops are not measured (it has GPS): the
    closed loop's check, which its health monitor judged, or one made here."""
    closed = result.figures.closed_loop if result.figures is not None else None
    judged = closed.odometry if closed is not None else None
    odometry = judged if judged is not None else dataset_odometry_check(dataset)
    _warn_odometry(dataset, odometry, in_health=judged is not None)


def loop_figures(
    dataset: Dataset, result: RunResult, loops_rel_s: list[tuple[float, float]]
) -> LoopFigures:
    """The loop-closure errors of a run (:mod:`sonarslam.slam.eval.loops`): the loops stated,
    and without GPS those found along dead reckoning within :data:`LOOP_RADIUS_SHARE` of the
    sonar's range, confirmed by scan registration (the same loops and references for every run
    of the dataset, whatever its back end); at each, the error of the run's estimate, of its
    other estimates and of dead reckoning. An error beyond the search radius is warned of: the
    estimate disagrees with the map by more than a return was searched within (a wrong
    mounting, a diverged run)."""
    head = dataset.config.sonar
    radius_m = LOOP_RADIUS_SHARE * head.n_bins * head.bin_size_m
    loops = stated_loops(loops_rel_s, dataset.nav_span_s[0])
    dr = dead_reckoning_trajectory(dataset)
    searched = dataset.gps is None
    odometry = search = None
    if searched:
        search = search_loops(dataset, dr, radius_m)
        loops += search.loops
        # a closed loop's run checked it already, and its health monitor judged it
        closed = result.figures.closed_loop if result.figures is not None else None
        judged = closed.odometry if closed is not None else None
        odometry = judged if judged is not None else dataset_odometry_check(dataset, dr)
        _warn_odometry(dataset, odometry, in_health=judged is not None)
    estimates: dict[str, Trajectory] = {"": result.trajectory, **result.trajectories}
    if result.backend != "dr":
        estimates["dr"] = dr
    errors = {name: loop_errors(tr, loops) for name, tr in estimates.items()}
    figures = LoopFigures(radius_m, loops, errors, searched, odometry, search)
    _warn_loops(dataset, result.backend, errors, radius_m)
    return figures


def _warn_loops(
    dataset: Dataset, backend: str, errors: dict[str, list[LoopError]], radius_m: float
) -> None:
    """One warning for the loops at which estimates disagree with the sonar's map by more than
    ``radius_m``, naming every such estimate (the run's, its other ones, dead reckoning)."""
    t0 = dataset.nav_span_s[0]
    over = []
    for name, errs in errors.items():
        worst = max(errs, key=lambda e: e.position_m, default=None)
        if worst is not None and worst.position_m > radius_m:
            own = name or backend  # the run's own estimate has no name
            label = "dead reckoning" if own == "dr" else f"{backend} {name}" if name else backend
            over.append(
                f"{label}'s {worst.position_m:.1f} m at the loop {worst.loop.t0_s - t0:.0f} s -"
                f" {worst.loop.t1_s - t0:.0f} s"
            )
    if over:
        warnings.warn(
            f"{dataset.root}: loop-closure error beyond the {radius_m:.0f} m the loops were"
            f" searched within: {'; '.join(over)}: the estimate disagrees with the sonar's map"
            f" there ({LOOP_CAUSES})",
            UserWarning,
            stacklevel=3,
        )


def loop_line(metrics: dict[str, Any]) -> str:
    """One line of a run's loop-closure errors (``metrics.json`` ``loop_*``)."""
    m = metrics
    found = m.get("loops_found")
    far = m.get("loop_search_too_far") or 0  # older runs do not count them
    head = f"loops: {m['loops_stated']} stated" + (
        f", {found} found (returns within {m['loop_radius_m']:.0f} m, confirmed by scan"
        " registration"
        + (
            f"; {far} registration(s) rejected as more than {m['loop_radius_m']:.0f} m from"
            " dead reckoning's guess"
            if far
            else ""
        )
        + ")"
        if found is not None
        else ""
    )
    if not m["loops"]:
        why = ""
        if found == 0 and "loop_search_tried" in m:  # older runs do not say why
            why = LoopSearch(
                [],
                m["loop_search_tried"],
                m["loop_search_path_m"],
                m["loop_radius_m"],
                LOOP_MIN_GAP_S,
                LOOP_MIN_PATH_M,
                m.get("loop_search_too_far") or 0,
            ).why_none()
        return head + ": no loop-closure error" + (f": {why}" if why else "") + _odometry_part(m)
    parts = [
        f"{'dead reckoning' if key == 'loop_error_dr_mean_m' else 'run' if key == 'loop_error_mean_m' else key[11:-7]}"
        f" mean {m[key]:.2f} m, max {m[key.replace('_mean_', '_max_')]:.2f}"
        for key in sorted(k for k in m if k.startswith("loop_error") and k.endswith("_mean_m"))
    ]
    sigma = m.get("loop_reference_sigma_m")
    free = m.get("loops_with_free_direction") or 0
    floor = ""
    if found:
        own = (
            f"their own 1-sigma {sigma:.2f} m on average, a floor under these figures"
            if sigma is not None
            else "none states an accuracy of its own"
        )
        floor = (
            f" (references: scan registrations along dead reckoning, the same for every run of"
            f" the dataset; {own}; {free} of {found} leave a direction free, dead reckoning's"
            " there; made with the sonar as calibrated, so that a range-scale or mounting error"
            " biases them as it biases the lines: no independent ruler)"
        )
    return f"{head}; loop-closure error{floor}: {'; '.join(parts)}{_odometry_part(m)}"


def _odometry_part(metrics: dict[str, Any]) -> str:
    line = odometry_line(metrics)
    return f"; {line}" if line else ""


def odometry_line(metrics: dict[str, Any]) -> str:
    """The odometry check of a run without GPS (``metrics.json`` ``odometry_check_*``), or ""."""
    accepted = metrics.get("odometry_check_accepted")
    if accepted is None:
        return ""
    pairs = metrics["odometry_check_pairs"]
    if not accepted:
        why = ""
        if "odometry_check_starts" in metrics:  # older runs do not say why
            why = OdometryCheck(
                pairs,
                0,
                math.nan,
                math.nan,
                starts=metrics["odometry_check_starts"],
                skipped_still=metrics["odometry_check_skipped_still"],
                skipped_sparse=metrics["odometry_check_skipped_sparse"],
                step_m=metrics["odometry_check_step_m"] or math.nan,
            ).why_none()
        return f"dead reckoning against the sonar: no registration of {pairs} accepted" + (
            f": {why}" if why else ""
        )
    return (
        f"dead reckoning against the sonar ({accepted} of {pairs} registrations of scans a"
        " few metres apart): its"
        f" motion {metrics['odometry_check_heading_deg']:+.1f}{_se(metrics, 'heading_se_deg', 1)}"
        f" deg off the sonar's, lengths x{metrics['odometry_check_scale']:.3f}"
        f"{_se(metrics, 'scale_se', 3)}"
    )


def _se(metrics: dict[str, Any], key: str, digits: int) -> str:
    """`` ± <standard error>`` of an odometry-check figure, or "" (older runs, one pair)."""
    v = metrics.get(f"odometry_check_{key}")
    return "" if v is None else f" ± {v:.{digits}f}"


def summary_line(metrics: dict[str, Any]) -> str:
    """One line of a run's figures for the terminal: against the truth (simulated runs), then
    against GPS over the sonar span and over the whole run."""
    m = metrics
    sonar = ""
    if "ate_sonar_mean_m" in m:
        sonar = (
            f"ATE over the sonar span mean {m['ate_sonar_mean_m']:.2f} m, max "
            f"{m['ate_sonar_max_m']:.2f} ({m['ate_sonar_n']} fixes); whole run "
        )
    truth = ""
    if "ate_truth_mean_m" in m:
        truth = (
            f"against the truth ATE mean {m['ate_truth_mean_m']:.2f} m, max "
            f"{m['ate_truth_max_m']:.2f} (rigidly aligned {m['ate_truth_aligned_mean_m']:.2f})"
        )
        if "heading_truth_mean_deg" in m:
            truth += (
                f", heading mean {m['heading_truth_mean_deg']:.1f} deg, max"
                f" {m['heading_truth_max_deg']:.1f}"
            )
        truth += "; against the simulated GPS: "
    if "ate_mean_m" not in m:
        entropy = m.get("map_entropy_nats")
        sharp = f"map entropy {entropy:.3f} nats" if entropy is not None else "no map"
        truth = truth.replace("against the simulated GPS: ", "")
        return (
            f"{m['backend']}: {truth}{m['evaluation']}: {sharp}; {m['data_s']:.0f} s of data in"
            f" {m['wall_s']:.2f} s ({m['realtime_factor']:.0f}x real time)"
        )
    return (
        f"{m['backend']}: {truth}{sonar}ATE mean {m['ate_mean_m']:.2f} m, sd {m['ate_sd_m']:.2f}, "
        f"min {m['ate_min_m']:.2f}, max {m['ate_max_m']:.2f}, rmse {m['ate_rmse_m']:.2f} "
        f"over {m['ate_n']} fixes; {m['data_s']:.0f} s of data in {m['wall_s']:.2f} s "
        f"({m['realtime_factor']:.0f}x real time)"
    )


def smoothed_lines(metrics: dict[str, Any]) -> list[str]:
    """A line each for a factor graph's other trajectories (smoothed, ``--batch``, lines
    re-decided, offline) in :func:`summary_line`'s terms: against the truth (simulated runs),
    against GPS over the sonar span and the whole run; none for a run without them. The
    offline estimate's line ends with its decisions."""
    lines = []
    for name in ("smoothed", "batch", "redecided", "offline"):
        f = _row_figures(metrics, name)
        parts = []
        if np.isfinite(f["truth"]):
            parts.append(
                f"against the truth ATE mean {f['truth']:.2f} m, max {f['truth_max']:.2f}"
                f" (rigidly aligned {f['truth_aligned']:.2f})"
            )
        gps = []
        if np.isfinite(f["sonar"]):
            gps.append(f"ATE over the sonar span mean {f['sonar']:.2f} m, max {f['sonar_max']:.2f}")
        if np.isfinite(f["whole"]):
            gps.append(f"whole run ATE mean {f['whole']:.2f} m, max {f['whole_max']:.2f}")
        if gps:
            against = "against the simulated GPS: " if parts else ""
            parts.append(against + "; ".join(gps))
        if parts and name == "offline" and "offline_passes" in metrics:
            parts.append(offline_words(metrics))
        if parts:
            lines.append(f"{metrics['backend']} {name}: " + "; ".join(parts))
    return lines


def offline_words(m: dict[str, Any]) -> str:
    """What the offline estimate decided and how long it took, in a run's words
    (``metrics.json``'s ``offline_*``)."""
    passes = m["offline_passes"]
    if m["offline_settled"]:
        settled = f"settled after {passes} passes"
    else:
        moved = m.get("offline_moved_m")
        by = f", which moved a node by at most {moved:.2f} m" if moved is not None else ""
        settled = (
            f"still changing after {passes} passes ({m['offline_changed']} of"
            f" {m['offline_decisions']} decisions in the last{by}; a valid estimate, another"
            " pass would move it: isam2.offline.max_passes)"
        )
    return (
        f"{m['offline_revisits_kept']} of {m['offline_revisits_registered']} registered"
        f" revisits kept, {m.get('offline_lines_stretches', 0)} wall stretches, {settled};"
        f" decided in {m['offline_s']:.1f} s after the run"
    )


def _row_figures(m: dict[str, Any], name: str | None) -> dict[str, float]:
    """The ATE figures of one trajectory of a run (``name``: ``smoothed``, ``batch`` or None for
    the run's own) from its ``metrics.json``: against GPS over the sonar span and the whole run,
    and against the truth (simulated runs; ``truth*``), each also rigidly aligned."""
    s = "" if name is None else f"_{name}"
    keys = {
        "sonar": f"ate_sonar{s}_mean_m",
        "sonar_max": f"ate_sonar{s}_max_m",
        "sonar_aligned": f"ate_sonar_aligned{s}_mean_m",
        "sonar_aligned_max": f"ate_sonar_aligned{s}_max_m",
        "whole": f"ate_mean{s}_m",
        "whole_max": f"ate_max{s}_m",
        "whole_aligned": f"ate_aligned_mean{s}_m",
        "truth": f"ate_truth{s}_mean_m",
        "truth_max": f"ate_truth{s}_max_m",
        "truth_aligned": f"ate_truth_aligned{s}_mean_m",
        "truth_aligned_max": f"ate_truth_aligned{s}_max_m",
    }
    return {k: float(m.get(v, float("nan"))) for k, v in keys.items()}


def results_table(results: list[RunResult]) -> str:
    """A Markdown table of the runs' ATE, one row per trajectory (a factor graph's online,
    smoothed, batch and offline estimates), as the published protocol takes it (no alignment) and after
    a rigid SE(2) fit (``evo_ape -a``): against GPS over the sonar span and the whole run; on
    simulated runs against the simulator's truth first, then against its simulated GPS over the
    whole run."""

    def pair(a: float, b: float) -> str:
        return "" if not np.isfinite(a) else f"{a:.2f} / {b:.2f}"

    def one(a: float) -> str:
        return "" if not np.isfinite(a) else f"{a:.2f}"

    simulated = bool(results) and all("ate_truth_mean_m" in r.metrics for r in results)
    rows = []
    for r in results:
        names: list[str | None] = [None, *r.trajectories]
        for name in names:
            f = _row_figures(r.metrics, name)
            label = r.backend if name is None else f"{r.backend} {name}"
            if name is None and r.trajectories:
                label = f"{r.backend} online"
            if simulated:
                rows.append(
                    {
                        "trajectory": label,
                        "truth mean / max (m)": pair(f["truth"], f["truth_max"]),
                        "aligned": pair(f["truth_aligned"], f["truth_aligned_max"]),
                        "simulated GPS mean / max (m)": pair(f["whole"], f["whole_max"]),
                        "aligned mean": one(f["whole_aligned"]),
                    }
                )
                continue
            rows.append(
                {
                    "trajectory": label,
                    "sonar span mean / max (m)": pair(f["sonar"], f["sonar_max"]),
                    "aligned": pair(f["sonar_aligned"], f["sonar_aligned_max"]),
                    "whole run mean / max (m)": pair(f["whole"], f["whole_max"]),
                    "aligned mean": one(f["whole_aligned"]),
                }
            )
    frame = pd.DataFrame(rows)
    return str(frame.to_markdown(index=False, disable_numparse=True))
