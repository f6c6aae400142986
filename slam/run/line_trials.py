"""Trials of the line extractor on the simulator with the true poses: only the front end is
measured. A trial simulates a run in memory, extracts its lines and matches them against the
true walls (:mod:`sonarslam.slam.eval.lines`); ``benchmarks/extractor_consistency.py`` and
``tests/test_extraction_stats.py`` use them.
"""

from __future__ import annotations

import tempfile
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.simulator import Simulation, make_scenario, simulate, simulate_records
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.config import ExtractorConfig
from sonarslam.features.extractor import LineExtractor
from sonarslam.features.geometry import FloatArray
from sonarslam.features.line import LineFeature
from sonarslam.slam.eval.lines import GATE_RAD, HARBOUR_GATE_M, POOL_GATE_M, Match, match_features
from sonarslam.slam.eval.truth import truth_trajectory, truth_walls
from sonarslam.slam.run.presets import EXTRACTOR_PRESETS, pool_preset
from sonarslam.slam.run.sonar_calibration import calibrate_line_noise, calibrate_range_offset

__all__ = ["TrialResult", "extract_simulation", "pool_trial", "harbour_trial", "drift_trial"]


def extract_simulation(
    sim: Simulation, config: ExtractorConfig, flush: bool = True
) -> list[LineFeature]:
    """Run the extractor over a simulated run with the true poses (world frame).

    Parameters
    ----------
    sim : Simulation
    config : ExtractorConfig
    flush : bool
        Vote once more on what is stored after the last beam.
    """
    sc = sim.scenario
    ex = LineExtractor(config, sc.head, sc.sonar_mounting, sim.trajectory)
    lines: list[LineFeature] = []
    for beam in sim.beams:
        lines += ex.add(beam)
    return lines + ex.flush() if flush else lines


@dataclass
class TrialResult:
    """Features of one simulated run against its walls.

    Attributes
    ----------
    kind : str
        ``"pool"``, ``"harbour"`` or ``"drift"``.
    seed : int
    method : str
        Covariance method (drift: ``"raw"`` or ``"calibrated"``).
    n_features, n_false : int
        All features; those outside the gates.
    errors : ndarray, shape (K, 2)
        ``(rho_m, theta_rad)`` errors of the K matched features.
    nees : ndarray, shape (K,)
    votes_all_walls : int
        Pool: votes (frames R) in which every wall was matched by some feature.
    n_votes : int
        Votes with at least one feature (pool: all votes made).
    n_duplicates : int
        Pool: features matched to a wall already matched in the same vote.
    """

    kind: str
    seed: int
    method: str
    n_features: int
    n_false: int
    errors: FloatArray
    nees: FloatArray
    votes_all_walls: int = 0
    n_votes: int = 0
    n_duplicates: int = 0


def _result(
    kind: str,
    seed: int,
    method: str,
    features: list[LineFeature],
    matches: list[Match],
    n_walls: int,
    n_votes: int,
) -> TrialResult:
    ok = [m for m in matches if m.matched]
    by_vote: dict[float, list[int]] = {}
    for ft, m in zip(features, matches, strict=True):
        if m.matched:
            by_vote.setdefault(ft.t, []).append(m.wall)
    all_walls = sum(len(set(w)) == n_walls for w in by_vote.values())
    dup = sum(len(w) - len(set(w)) for w in by_vote.values())
    return TrialResult(
        kind=kind,
        seed=seed,
        method=method,
        n_features=len(features),
        n_false=len(features) - len(ok),
        errors=np.array([m.error for m in ok]).reshape(-1, 2),
        nees=np.array([m.nees for m in ok]),
        votes_all_walls=int(all_walls),
        n_votes=n_votes,
        n_duplicates=int(dup),
    )


def pool_trial(
    seed: int,
    methods: tuple[str, ...] = ("fit", "seed"),
    config_changes: dict[str, Any] | None = None,
) -> list[TrialResult]:
    """The seed paper's pool test on ``make_scenario("pool", seed)``, one result per method.

    The 165 s run is four full 270 deg sectors (2400 beams) and 25 beams: one vote per sector,
    no flush, so that every vote sees one fresh 270 deg scan, as in the paper.
    ``config_changes`` replace fields of :func:`sonarslam.slam.run.presets.pool_preset`.
    """
    sim = simulate_records(make_scenario("pool", seed))
    out = []
    for method in methods:
        cfg = pool_preset(sim.scenario.head.step_rad, method).replace(**(config_changes or {}))
        feats = extract_simulation(sim, cfg, flush=False)
        matches = match_features(feats, sim.world.walls_m, POOL_GATE_M, GATE_RAD)
        n_votes = len(sim.beams) // cfg.vote_every_n_beams
        out.append(_result("pool", seed, method, feats, matches, len(sim.world.walls_m), n_votes))
    return out


def harbour_trial(
    seed: int,
    methods: tuple[str, ...] = ("fit", "seed"),
    duration_s: float | None = None,
    config_changes: dict[str, Any] | None = None,
) -> list[TrialResult]:
    """The extractor's defaults on ``make_scenario("harbour", seed)`` (a vehicle surveying a
    marina-like harbour at 0.45 m/s, raw beams), with the true poses; one result per method.
    ``config_changes`` replace fields of the default :class:`ExtractorConfig`."""
    sim = simulate_records(make_scenario("harbour", seed, duration_s))
    out = []
    for method in methods:
        cfg = EXTRACTOR_PRESETS["default"].replace(covariance_method=method)
        cfg = cfg.replace(**(config_changes or {}))
        feats = extract_simulation(sim, cfg)
        matches = match_features(feats, sim.world.walls_m, HARBOUR_GATE_M, GATE_RAD)
        n_votes = len({ft.t for ft in feats})
        out.append(
            _result("harbour", seed, method, feats, matches, len(sim.world.walls_m), n_votes)
        )
    return out


def _dataset_lines(ds: Dataset, config: ExtractorConfig) -> list[LineFeature]:
    ex = LineExtractor(config, ds.config.sonar, ds.config.sonar_mounting, truth_trajectory(ds))
    lines: list[LineFeature] = []
    for beam in ds.nav_beams():
        lines += ex.add(beam)
    return lines + ex.flush()


def drift_trial(seed: int, duration_s: float | None = None) -> list[TrialResult]:
    """The drift world (its echoes peak 0.25 m behind the walls), the extractor's defaults with
    the true poses, before (``"raw"``) and after (``"calibrated"``) the GPS-free sonar
    calibration that ``sweep --calibrate`` applies: :func:`calibrate_range_offset` then
    :func:`calibrate_line_noise`, both with dead reckoning's poses."""
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)  # the simulated DVL's dropouts, as expected
        ds = open_dataset(simulate("drift", seed=seed, out_dir=Path(tmp), duration_s=duration_s))
        offset = calibrate_range_offset(ds).offset_m
        sonar = replace(ds.config.sonar, range_offset_m=offset)
        ds_cal = replace(ds, config=replace(ds.config, sonar=sonar))
        noise = calibrate_line_noise(ds_cal)
        cfg = EXTRACTOR_PRESETS["default"]
        runs = {
            "raw": (ds, cfg),
            "calibrated": (
                ds_cal,
                cfg.replace(
                    line_sigma_rho_m=noise.sigma_rho_m, line_sigma_theta_rad=noise.sigma_theta_rad
                ),
            ),
        }
        walls = truth_walls(ds)
        out = []
        for method, (d, c) in runs.items():
            feats = _dataset_lines(d, c)
            matches = match_features(feats, walls, HARBOUR_GATE_M, GATE_RAD)
            n_votes = len({ft.t for ft in feats})
            out.append(_result("drift", seed, method, feats, matches, len(walls), n_votes))
        return out
