"""Monte Carlo runs and parameter grids on Dask (``sonarslam sweep``).

A sweep is the product of seeds, back ends and the grid axes that apply to each back end. Every
seed's world is simulated once (a Dask task; the folder is cached on disk, so back ends and later
sweeps share it) and each (seed, back end, parameters) is one task that runs the back end
through the one runner (:func:`sonarslam.slam.run.run.run_backend`) and returns one flat row: the seed,
back end and parameters, the run's metrics (the ATE against the truth, as it is and rigidly
aligned, beside the GPS protocol's; association scores against the true walls; timings), the
pose NEES against the simulator's truth (:mod:`sonarslam.slam.eval.consistency`). The rows make one table
(``sweep.csv``), each run paired with dead reckoning on its seed; the NEES of every run on a
common 1 s grid (``nees.npz``) give the ANEES of each configuration with its 95 % band. The
scores against the truth and dead reckoning are :mod:`sonarslam.slam.run.sweep_summary`'s (``summary.csv``,
``sweep.png``, and the spread across seeds with the worst seeds' worlds: ``spread.md``,
``worlds.png``). The default world is ``drawn``: a harbour and route drawn per seed; seeds from
:data:`sonarslam.datasets.simulator.HELD_BACK_SEED_MIN` on are the held-back ones that results count on.

Grid axes are ``<scope>.<field>=v1,v2,...`` (:mod:`sonarslam.slam.run.presets`): ``extractor.<field>``
applies to every closed-loop back end; ``<backend>.<field>[.<field>]`` to that back end. The
baselines (``dr``, ``gps``) take none.
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import re
import shutil
import tempfile
import time
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from tqdm import tqdm

from sonarslam.datasets.errors import DataError, DataWarning, MissingExtraError
from sonarslam.datasets.simulator import HELD_BACK_SEED_MIN, simulate
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.datasets.toml import read_toml
from sonarslam.features.geometry import compose, inverse
from sonarslam.settings import SettingError
from sonarslam.slam.backends.registry import BACKENDS
from sonarslam.slam.eval.ate import ate_against_truth
from sonarslam.slam.eval.consistency import NeesSeries, anees, nees_on_grid, nees_series
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.files import make_output_dir, write_atomic, write_text
from sonarslam.slam.io.plots import plot_anees, plot_sweep, plot_worlds
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.presets import check_settings, parse_value
from sonarslam.slam.run.run import backend_names, run_backend
from sonarslam.slam.run.sonar_calibration import write_sonar_calibration
from sonarslam.slam.run.sources import start_pose
from sonarslam.slam.run.sweep_summary import (
    config_columns,
    config_labels,
    format_spread,
    format_summary,
    held_back_note,
    pair_with_baseline,
    summarise,
    world_columns,
    worst_seeds,
)

if TYPE_CHECKING:
    from dask.distributed import Client, LocalCluster

__all__ = [
    "SweepTask",
    "SweepResult",
    "parse_seeds",
    "parse_grid",
    "load_grid_toml",
    "axis_applies",
    "expand_tasks",
    "simulate_cached",
    "calibrate_cached",
    "gauge_ate_m",
    "run_task",
    "config_labels",
    "format_summary",
    "pair_with_baseline",
    "summarise",
    "sweep",
]

#: Step (s) of the common time grid of the NEES series.
NEES_PERIOD_S = 1.0


def parse_seeds(text: str) -> list[int]:
    """Seeds from ``"0-49"``, ``"3"`` or ``"0,2,5-7"`` (ranges inclusive), in order, unique."""
    seeds: list[int] = []
    for part in text.split(","):
        part = part.strip()
        m = re.fullmatch(r"(\d+)\s*-\s*(\d+)", part)
        if m:
            a, b = int(m.group(1)), int(m.group(2))
            if b < a:
                raise SettingError("--seeds", f"empty range {part!r}")
            seeds.extend(range(a, b + 1))
        elif re.fullmatch(r"\d+", part):
            seeds.append(int(part))
        else:
            raise SettingError("--seeds", f"expected N, A-B or a comma list of them, got {text!r}")
    return list(dict.fromkeys(seeds))


def parse_grid(specs: Iterable[str]) -> dict[str, list[Any]]:
    """Grid axes from ``["ekf.association=jcbb,nn", "extractor.min_votes=10,15"]``."""
    grid: dict[str, list[Any]] = {}
    for spec in specs:
        name, sep, values = spec.partition("=")
        name = name.strip()
        if not sep or "." not in name or not values.strip():
            raise SettingError("--grid", f"expected SCOPE.FIELD=V1,V2,..., got {spec!r}")
        grid[name] = [parse_value(v) for v in values.split(",")]
    return grid


def load_grid_toml(path: str | Path) -> dict[str, list[Any]]:
    """Grid axes from a TOML file: a ``[grid]`` table (or the top level) of arrays, flat
    (``"ekf.association" = ["jcbb", "nn"]``) or nested (``[grid.extractor] min_votes = [10]``)."""
    data = read_toml(path)[0]
    data = data.get("grid", data)
    if not isinstance(data, dict):
        raise DataError(path, None, f"[grid] must be a table, got {data!r}")
    grid: dict[str, list[Any]] = {}

    def walk(prefix: str, node: dict[str, Any]) -> None:
        for k, v in node.items():
            name = f"{prefix}.{k}" if prefix else k
            if isinstance(v, dict):
                walk(name, v)
            else:
                grid[name] = list(v) if isinstance(v, list) else [v]

    walk("", data)
    for name in grid:
        if "." not in name:
            raise DataError(path, None, f"grid axis {name!r} needs a scope (extractor., ekf., ...)")
    return grid


@dataclass(frozen=True)
class SweepTask:
    """One run: a seed, a back end and its parameter values (sorted ``(axis, value)`` pairs)."""

    seed: int
    backend: str
    params: tuple[tuple[str, Any], ...] = ()

    @property
    def params_dict(self) -> dict[str, Any]:
        return dict(self.params)


def axis_applies(backend: str, axis: str) -> bool:
    """Whether a grid axis changes ``backend`` (``extractor.*``: every closed loop)."""
    scope = axis.split(".", 1)[0]
    return backend in BACKENDS and scope in ("extractor", backend)


def expand_tasks(
    seeds: Sequence[int], backends: Sequence[str], grid: dict[str, list[Any]]
) -> list[SweepTask]:
    """Seeds x back ends x the product of the axes that apply to each back end.

    Raises ValueError for an unknown back end, an axis no back end uses, or an axis on a back
    end run by the pipeline (no settings).
    """
    known = backend_names()
    for b in backends:
        if b not in known:
            raise SettingError("--backend", f"unknown {b!r}; one of {known}")
    loops = BACKENDS
    for axis in grid:
        scope = axis.split(".", 1)[0]
        if scope != "extractor" and scope not in loops:
            if scope in known:
                raise SettingError(
                    f"--grid {axis}", f"back end {scope!r} has no settings a sweep can change"
                )
            raise SettingError(
                f"--grid {axis}", f"unknown scope {scope!r}; extractor or one of {list(loops)}"
            )
        if not any(axis_applies(b, axis) for b in backends):
            raise SettingError(f"--grid {axis}", f"no back end of {list(backends)} uses it")
        for b in backends:  # every value checked against its field before anything runs
            if axis_applies(b, axis):
                for value in grid[axis]:
                    check_settings(b, {axis: value})
    tasks: list[SweepTask] = []
    for seed in seeds:
        for b in backends:
            axes = sorted(a for a in grid if axis_applies(b, a))
            for values in itertools.product(*(grid[a] for a in axes)):
                tasks.append(SweepTask(int(seed), b, tuple(zip(axes, values, strict=True))))
    return tasks


def simulate_cached(world: str, seed: int, duration_s: float | None, cache_dir: str | Path) -> str:
    """The folder of a simulated world and seed, simulated once (atomically) and then reused."""
    tag = "default" if duration_s is None else f"{duration_s:g}s"
    folder = Path(cache_dir) / f"{world}_{seed}_{tag}"
    if (folder / "truth.json").is_file():
        return str(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}-", dir=folder.parent))
    try:
        simulate(world, seed=seed, out_dir=tmp, duration_s=duration_s)
        try:
            os.rename(tmp, folder)  # atomic; fails when another process was first
        except OSError:
            if not (folder / "truth.json").is_file():
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return str(folder)


def calibrate_cached(folder: str) -> str:
    """The GPS-free sonar calibration of a simulated folder (range offset, a line's systematic
    error: :func:`sonarslam.slam.run.sonar_calibration.write_sonar_calibration`), written once beside its
    logs as ``calibration.toml``; returns its path."""
    path = Path(folder) / "calibration.toml"
    if not path.is_file():
        with warnings.catch_warnings():  # the runs report the data's warnings
            warnings.simplefilter("ignore", DataWarning)
            write_sonar_calibration(folder, path)
    return str(path)


def _nees_grid(
    trajectory: Trajectory, truth: Trajectory, period_s: float
) -> dict[str, tuple[NeesSeries, np.ndarray]]:
    t0, t1 = trajectory.span_s
    grid = np.arange(0.0, t1 - t0 + 1e-9, period_s)
    out = {}
    for comp in ("pose", "position"):
        s = nees_series(trajectory, truth, comp)
        out[comp] = (s, nees_on_grid(s, t0, grid))
    return out


def run_task(
    task: SweepTask,
    source: str,
    world: str | None = None,
    duration_s: float | None = None,
    nees_period_s: float = NEES_PERIOD_S,
    config_override: str | None = None,
) -> dict[str, Any]:
    """Run one task on a simulated folder (with a partial ``sonarslam.toml`` over its own, e.g.
    its calibration); a failed run is a row with its ``error``.

    Returns
    -------
    dict
        ``row``: the flat row (``seed``, ``backend``, the parameters by axis name, ``world``,
        ``duration_s``, the ATE fields, ``nees_mean``, ``nees_in_band_fraction``,
        ``nees_position_mean``, the association counts, ``wall_s``, ..., ``warnings`` (how
        many different data warnings, the first in ``warning_first``), ``error``);
        ``nees_pose`` and ``nees_position``: NEES on the grid ``0, period, ...`` s after the
        start (NaN where missing).
    """
    row: dict[str, Any] = {
        "seed": task.seed,
        "backend": task.backend,
        **task.params_dict,
        "world": world,
        "duration_s": duration_s,
        "calibrated": config_override is not None,
    }
    # the data's warnings go into the row, not to the worker's stderr
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always", DataWarning)
        row["error"], nees_pose, nees_position = _run_into(
            row, task, source, config_override, nees_period_s
        )
    messages = list(dict.fromkeys(str(w.message) for w in seen))
    row["warnings"] = len(messages)
    row["warning_first"] = messages[0] if messages else ""
    return {"row": row, "nees_pose": nees_pose, "nees_position": nees_position}


def _run_into(
    row: dict[str, Any],
    task: SweepTask,
    source: str,
    config_override: str | None,
    nees_period_s: float,
) -> tuple[str, np.ndarray, np.ndarray]:
    """Run a task, its metrics into ``row``; ``(error, pose NEES, position NEES)`` on the grid
    (the error ``""`` when it ran)."""
    empty = np.zeros(0)
    try:
        dataset = open_dataset(source, config_override)
        row.update(world_columns(dataset.truth))
        if dataset.truth is not None:
            row["gauge_ate_m"] = gauge_ate_m(dataset)
        run = run_backend(dataset, task.backend, task.params_dict)
        row.update(
            {
                k: v
                for k, v in run.metrics.items()
                if k not in ("source", "backend", "settings", "gap_spans_s")
            }
        )
        if dataset.truth is None or run.trajectory.covs is None:
            return "", empty, empty
        grid = _nees_grid(run.trajectory, truth_trajectory(dataset), nees_period_s)
        s_pose, nees_pose = grid["pose"]
        s_pos, nees_position = grid["position"]
        row["nees_mean"] = s_pose.mean
        row["nees_in_band_fraction"] = s_pose.in_band_fraction()
        row["nees_position_mean"] = s_pos.mean
        return "", nees_pose, nees_position
    except Exception as exc:  # one failed run must not stop a 50-seed sweep
        return f"{type(exc).__name__}: {exc}", empty, empty


def gauge_ate_m(dataset: Dataset) -> float:
    """The ATE against the truth (m) of the truth itself moved rigidly onto the estimators'
    start pose (the first GPS fix and the AHRS heading there, :func:`start_pose`): what no
    GPS-free estimator can correct, since nothing it measures sees where the whole run sits or
    how it is turned. A run whose ATE is at this floor has nothing left to gain unaligned."""
    t0, pose0, _ = start_pose(dataset)
    truth = truth_trajectory(dataset)
    moved = compose(compose(pose0, inverse(truth.poses([t0])[0])), truth.poses(truth.t_s))
    return float(ate_against_truth(Trajectory(truth.t_s, moved), truth).ate_mean_m)


def _pad(rows: Sequence[np.ndarray]) -> np.ndarray:
    k = max((r.size for r in rows), default=0)
    out = np.full((len(rows), k), np.nan)
    for i, r in enumerate(rows):
        out[i, : r.size] = r
    return out


def _ordered(table: pd.DataFrame) -> pd.DataFrame:
    """Columns: seed, backend, the parameters, the rest, error last."""
    if table.empty:
        return table
    first = ["seed"] + config_columns(table)
    rest = [c for c in table.columns if c not in first and c != "error"]
    return table[first + rest + (["error"] if "error" in table else [])]


@dataclass
class SweepResult:
    """The sweep's table, summary and files."""

    table: pd.DataFrame
    summary: pd.DataFrame
    nees_pose: np.ndarray
    nees_position: np.ndarray
    out_dir: Path
    files: dict[str, Path]
    wall_s: float
    spread: str = ""


def _distributed() -> ModuleType:
    """``dask.distributed``, or the error naming the extra that installs it."""
    try:
        import dask.distributed  # lazy: the 'sweep' extra, needed by a Dask scheduler only
    except ModuleNotFoundError as missing:
        raise MissingExtraError("sweep", "a sweep on Dask", missing) from None
    return dask.distributed


def _client(
    distributed: ModuleType, scheduler: str | None, n_workers: int
) -> tuple[Client, LocalCluster | None]:
    if scheduler:
        return distributed.Client(scheduler), None
    cluster = distributed.LocalCluster(
        n_workers=n_workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # a free port: several clusters may run at once
        silence_logs=logging.ERROR,
    )
    return distributed.Client(cluster), cluster


def _world_picture(
    path: Path, table: pd.DataFrame, summary: pd.DataFrame, folders: dict[int, str], title: str
) -> Path:
    """``worlds.png``: the worlds of the three seeds where the last closed loop (its smoothed
    trajectory if it has one) gains least over dead reckoning, and of the first three others."""
    seeds = list(folders)
    worst: list[int] = []
    scored = summary[summary["dr_pairs"].notna()] if "dr_pairs" in summary else summary.iloc[0:0]
    if len(scored):
        main = str(scored.iloc[-1]["config"])
        ranked = worst_seeds(table, main, 3)
        worst = [int(s) for s in ranked["seed"]] if "seed" in ranked else []
    else:
        main = ""
    chosen = worst + [s for s in seeds if s not in worst][: 6 - len(worst)]
    worlds = []
    for seed in chosen:
        truth = json.loads((Path(folders[seed]) / "truth.json").read_text(encoding="utf-8"))
        walls = np.asarray(truth["walls_m"], dtype=np.float64)
        curve = truth.get("walls", {}).get("curve")
        poses = np.asarray(truth["body_poses"]["rows"], dtype=np.float64)[:, 1:3]
        lay = truth.get("layout")
        name = f"seed {seed}"
        if lay is not None:
            name += f": {len(lay['basins'])} basin(s), lap {lay['lap_s'] / 60:.0f} min"
        if seed in worst:
            name += f" ({main}: worst {worst.index(seed) + 1})"
        worlds.append((name, walls, None if curve is None else np.asarray(curve), poses))
    return plot_worlds(path, worlds, f"{title}: worlds and true routes")


def _write(
    out: Path,
    table: pd.DataFrame,
    summary: pd.DataFrame,
    nees_pose: np.ndarray,
    nees_position: np.ndarray,
    t_rel_s: np.ndarray,
    title: str,
    folders: dict[int, str],
    spread: str,
) -> dict[str, Path]:
    """The sweep's files (:func:`sweep`), by role."""
    files = {
        "table": out / "sweep.csv",
        "summary": out / "summary.csv",
        "spread": out / "spread.md",
        "nees": out / "nees.npz",
        "plot": out / "sweep.png",
        "anees_plot": out / "anees.png",
        "worlds": out / "worlds.png",
    }
    write_text(files["spread"], spread)
    if folders:
        write_atomic(files["worlds"], lambda p: _world_picture(p, table, summary, folders, title))
    else:
        files.pop("worlds")
    write_atomic(files["table"], lambda p: table.to_csv(p, index=False))
    try:
        import pyarrow  # noqa: F401  # optional, not a dependency: parquet only when installed
    except ImportError:
        pass
    else:
        files["parquet"] = out / "sweep.parquet"
        write_atomic(files["parquet"], table.to_parquet)
    write_atomic(files["summary"], lambda p: summary.to_csv(p, index=False))
    write_atomic(
        files["nees"],
        lambda p: np.savez_compressed(p, pose=nees_pose, position=nees_position, t_rel_s=t_rel_s),
    )
    labels = config_labels(table)
    beats = {}
    for _, rec in summary.iterrows():
        if rec.get("dr_pairs", 0) > 0:  # iterrows makes every number a float
            beats[rec["config"]] = (
                f"beats DR on {int(rec['beats_dr_seeds'])}/{int(rec['dr_pairs'])} seeds"
            )
    write_atomic(files["plot"], lambda p: plot_sweep(p, table, labels, title, beats))
    curves = {}
    for label in dict.fromkeys(labels):
        rows = np.flatnonzero((labels == label) & (table["error"].fillna("") == "").to_numpy())
        X = nees_pose[rows] if nees_pose.size else np.zeros((0, 0))
        if X.size and np.isfinite(X).any():
            curves[label] = anees(X, 3, t_rel_s)
    write_atomic(
        files["anees_plot"],
        lambda p: plot_anees(p, curves, f"pose ANEES (3 dof) over the runs: {title}"),
    )
    return files


def sweep(
    seeds: Sequence[int],
    backends: Sequence[str],
    out_dir: str | Path,
    grid: dict[str, list[Any]] | None = None,
    world: str = "drawn",
    duration_s: float | None = None,
    cache_dir: str | Path | None = None,
    scheduler: str | None = None,
    n_workers: int = 2,
    progress: bool = True,
    nees_period_s: float = NEES_PERIOD_S,
    calibrate: bool = False,
) -> SweepResult:
    """Run a Monte Carlo sweep on Dask and write its table, summary and plot.

    Parameters
    ----------
    seeds : sequence of int
    backends : sequence of str
        Names of :func:`sonarslam.slam.run.run.backend_names`.
    out_dir : str or Path
        Receives ``sweep.csv`` (one row per run, paired with dead reckoning on its seed:
        :func:`pair_with_baseline`), ``summary.csv`` (one per configuration, :func:`summarise`),
        ``nees.npz`` (``pose`` (R, K), ``position`` (R, K), ``t_rel_s`` (K,): row ``i`` is
        ``sweep.csv``'s), ``anees.png``, ``sweep.png``, ``spread.md``
        (:func:`sonarslam.slam.run.sweep_summary.format_spread`: the spread of the gain over dead
        reckoning across seeds, the worst seeds with their worlds, the ANEES against its band,
        the association scores, whether the seeds are held back) and ``worlds.png`` (six of the
        worlds with their true routes, the worst seeds first).
    grid : dict of str to list, optional
        Axes (see the module docstring).
    world : {"drawn", "drift", "harbour", "random", "pool"}
        Simulated world (:data:`sonarslam.datasets.simulator.KINDS`); ``drawn``: a harbour drawn per seed.
    duration_s : float, optional
        Simulated length (s); default the world's (600 s for the harbours, 1,800 s for drift and
        the drawn worlds).
    cache_dir : str or Path, optional
        Simulated folders, one per world, seed and length; default ``out_dir/sim``.
    scheduler : str, optional
        Address of a running Dask scheduler; default a ``LocalCluster`` of ``n_workers``
        processes of one thread; ``"synchronous"`` runs the tasks here, one after another.
    n_workers : int
        Workers of the local cluster.
    progress : bool
        A progress bar over the finished tasks.
    nees_period_s : float
        Step of the NEES grid (s).
    calibrate : bool
        Calibrate each seed's sonar GPS-free first (:func:`calibrate_cached`: the echoes' range
        offset and a line's systematic error, as ``sonarslam calibrate --range-offset`` and
        ``--line-noise``) and run with it, as a user would on a new dataset.
    """
    wall0 = time.perf_counter()
    grid = dict(grid or {})
    tasks = expand_tasks(seeds, backends, grid)
    if n_workers < 1:
        raise SettingError("--workers", f"must be at least 1, got {n_workers}")
    distributed = None if scheduler == "synchronous" else _distributed()
    out = make_output_dir(out_dir)
    cache = Path(cache_dir) if cache_dir is not None else out / "sim"
    results: list[dict[str, Any] | None] = [None] * len(tasks)
    bar = tqdm(total=len(tasks), desc="sweep", unit="run", disable=not progress)
    folders: dict[int, str] = {}
    if distributed is None:  # synchronous
        sims = {s: simulate_cached(world, s, duration_s, cache) for s in dict.fromkeys(seeds)}
        folders = dict(sims)
        cals = {s: calibrate_cached(f) if calibrate else None for s, f in sims.items()}
        for i, task in enumerate(tasks):
            results[i] = run_task(
                task, sims[task.seed], world, duration_s, nees_period_s, cals[task.seed]
            )
            bar.update()
    else:
        client, cluster = _client(distributed, scheduler, n_workers)
        try:
            sim_futures = {
                s: client.submit(
                    simulate_cached, world, s, duration_s, str(cache.resolve()), pure=False
                )
                for s in dict.fromkeys(seeds)
            }
            cal_futures = {
                s: client.submit(calibrate_cached, f, pure=False) if calibrate else None
                for s, f in sim_futures.items()
            }
            futures = {
                client.submit(
                    run_task,
                    task,
                    sim_futures[task.seed],
                    world,
                    duration_s,
                    nees_period_s,
                    cal_futures[task.seed],
                    pure=False,
                ): i
                for i, task in enumerate(tasks)
            }
            for fut in distributed.as_completed(futures):
                results[futures[fut]] = fut.result()
                bar.update()
            folders = {s: str(f.result()) for s, f in sim_futures.items()}
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    bar.close()
    done = [r for r in results if r is not None]
    table = pair_with_baseline(_ordered(pd.DataFrame([r["row"] for r in done])))
    nees_pose = _pad([r["nees_pose"] for r in done])
    nees_position = _pad([r["nees_position"] for r in done])
    t_rel_s = np.arange(nees_pose.shape[1]) * nees_period_s
    summary = summarise(table, nees_pose, nees_position)
    unique = list(dict.fromkeys(int(s) for s in seeds))
    title = f"{world}, {len(unique)} seeds ({_seed_text(unique)})" + (
        "" if duration_s is None else f", {duration_s:g} s"
    )
    note = held_back_note(unique, HELD_BACK_SEED_MIN)
    if calibrate:
        note += " Each seed's sonar calibrated GPS-free first (--calibrate)."
    spread = format_spread(summary, table, title, note)
    files = _write(out, table, summary, nees_pose, nees_position, t_rel_s, title, folders, spread)
    return SweepResult(
        table,
        summary,
        nees_pose,
        nees_position,
        out,
        files,
        time.perf_counter() - wall0,
        spread,
    )


def _seed_text(seeds: list[int]) -> str:
    """``"10000-10049"`` for a run of consecutive seeds, else the first ones."""
    if seeds and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}-{seeds[-1]}" if len(seeds) > 1 else str(seeds[0])
    return ", ".join(map(str, seeds[:5])) + (", ..." if len(seeds) > 5 else "")
