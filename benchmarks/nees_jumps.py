"""The cause of every NEES jump of the closed loops on drawn worlds, found with the truth.

For each seed of ``--seeds`` (drawn worlds, simulated and calibrated GPS-free once into
``--cache`` as ``sonarslam sweep --calibrate`` does) and each back end of ``--backends``, one run
with the back end's defaults (or ``--set``), instrumented at the landmark layer
(:meth:`sonarslam.slam.mapping.landmarks.LandmarkMap.vote`: every vote's pose, its new landmarks
and the observations it used). A run *jumps* when its mean pose NEES against the truth exceeds
``--threshold`` (10, as issue 31 counts them); its jump time is the first time its pose NEES
(1 s samples) stays above the threshold for ``--hold-s`` seconds (else the first sample above
it), and its window the ``--window-s`` seconds before that time (and 5 s after it). In the window
the benchmark gathers, with the simulator's truth:

* the start: the start pose's error against the covariance it was given (the first GPS fix
  and the AHRS heading): the gauge, which no sensor observes, so that an error beyond the prior
  stays in every later pose;
* wrong associations: observations used on a landmark whose true wall (the truth unit of
  :class:`sonarslam.slam.eval.truth.AssociationScores`) is not the observation's own, with the
  pair of walls, their separation in the sonar frame, the pairing's Mahalanobis distance against
  the gate and whether the extent gate was on; landmarks used in the window that took a wrong
  observation earlier count too (a corrupted landmark);
* landmarks initialised badly: a landmark used in the window whose first estimate (the newest
  seeding observation placed with the vote's pose) is off its true line beyond the 99 % chi2(2)
  gate of its own covariance, and how many views seeded it;
* revisit outliers: a right pairing with a landmark unused for ``--revisit-s`` seconds whose
  observation, placed with the true pose, is off its true line beyond the 99.9 % gate of its
  covariance;
* drawn sensor faults: a DVL dropout (``truth.json`` ``dvl_dropouts_s``) ending within 30 s
  before the jump;
* the heading: the NEES of the heading alone and of the position alone over the 30 s after the
  jump, and the filter's heading sigma against the heading error;
* the model gap: the share of the window's used observations off their true line (with the
  true pose and the told mounting) beyond the 99 % gate.

Each jumping run gets one primary cause, the first of: the start (its NEES beyond the 99 %
gate of chi2(3), or the jump within the first minute), wrong association, bad landmark
initialisation, revisit outlier, sensor fault, heading (linearisation: a heading NEES beyond the
99.9 % gate of chi2(1) with none of the above), model gap (the rest); the evidence of every
check is in the JSON. ``--oracle`` re-runs each jumping run with the wrong observations left
unused (the truth vetoes them), and says whether the jump goes: the counterfactual test of the
association cause, which then decides the run's cause (:func:`final_cause`): the first jump's
evidence sees one window, the veto the whole run. ``--table J`` prints the table of a results
JSON.

Serial, one process (the machine is shared)::

    nice -n 10 .venv/bin/python benchmarks/nees_jumps.py --seeds 10000-10049 \
        --backends ekf,isam2 --cache /tmp/nees31/cache --out out/nees_jumps.json
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.geometry import FloatArray, line_difference, wrap_angle
from sonarslam.features.line import LineFeature
from sonarslam.slam.eval.consistency import chi2_gate, nees_series, pose_errors
from sonarslam.slam.eval.truth import (
    SAME_LINE_RHO_M,
    SAME_LINE_THETA_RAD,
    true_sonar,
    truth_trajectory,
    truth_units,
    truth_walls,
)
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.mapping.landmarks import LandmarkMap
from sonarslam.slam.mapping.vote import Belief, Decision
from sonarslam.slam.model.lines import world_observation
from sonarslam.slam.run.run import run_backend
from sonarslam.slam.run.sweep import calibrate_cached, parse_seeds, simulate_cached

CAUSES = (
    "covariance not positive definite",
    "start pose outside its prior",
    "wrong association",
    "landmark initialised badly",
    "revisit outlier",
    "sensor fault (DVL dropout)",
    "heading (linearisation)",
    "model gap",
)
GATE_RHO_M = 1.0  # an observation is of a true line within these (as association_scores)
GATE_THETA_RAD = float(np.deg2rad(5.0))
INIT_GATE = chi2_gate(2, 0.99)
OUTLIER_GATE = chi2_gate(2, 0.999)
HEADING_GATE = chi2_gate(1, 0.999)
START_GATE = chi2_gate(3, 0.99)  # the start pose's error against the prior it was given
#: the truth units' collinearity tolerances, as the runs' association scores take them
#: (:func:`sonarslam.slam.eval.truth.truth_units`)
SAME_LINE = [SAME_LINE_RHO_M, SAME_LINE_THETA_RAD]
START_WINDOW_S = 60.0  # a jump this soon after the start is the start's
AFTER_JUMP_S = 30.0


# -- the truth of each observation ---------------------------------------------------------


@dataclass(frozen=True)
class WorldTruth:
    """A simulated dataset's true lines in the readers' frame and their truth units."""

    lines: FloatArray  # (K, 2)
    unit: np.ndarray  # (K,) truth unit of each line (curves: one unit per curve)
    truth: Trajectory
    bTs: FloatArray  # the true sonar mounting
    range_scale: float  # the true sonar range scale

    @classmethod
    def of(cls, ds: Dataset) -> WorldTruth:
        curve = (ds.truth or {}).get("walls", {}).get("curve")
        lines, unit, _ = truth_units(truth_walls(ds), curve, *SAME_LINE)
        return cls(lines, unit, truth_trajectory(ds), *true_sonar(ds))

    def nearest(self, z: FloatArray, wTb: FloatArray) -> tuple[int | None, int | None]:
        """The truth unit and line index of an observation ``z`` (sonar frame) from body pose
        ``wTb`` (None: spurious), as :func:`sonarslam.slam.eval.truth.association_scores`
        (with the true sonar mounting and range scale)."""
        c, s = np.cos(wTb[2]), np.sin(wTb[2])
        xs = wTb[0] + c * self.bTs[0] - s * self.bTs[1]
        ys = wTb[1] + s * self.bTs[0] + c * self.bTs[1]
        psi = wTb[2] + self.bTs[2]
        ct, st = np.cos(self.lines[:, 1]), np.sin(self.lines[:, 1])
        rho_r = (self.lines[:, 0] - xs * ct - ys * st) * self.range_scale
        th_r = self.lines[:, 1] - psi
        d_rho_a = np.abs(z[0] - rho_r)
        d_th_a = np.abs(wrap_angle(z[1] - th_r))
        d_rho_b = np.abs(z[0] + rho_r)
        d_th_b = np.abs(wrap_angle(z[1] - th_r - np.pi))
        cost_a = np.where(
            (d_rho_a <= GATE_RHO_M) & (d_th_a <= GATE_THETA_RAD),
            d_rho_a / GATE_RHO_M + d_th_a / GATE_THETA_RAD,
            np.inf,
        )
        cost_b = np.where(
            (d_rho_b <= GATE_RHO_M) & (d_th_b <= GATE_THETA_RAD),
            d_rho_b / GATE_RHO_M + d_th_b / GATE_THETA_RAD,
            np.inf,
        )
        cost = np.minimum(cost_a, cost_b)
        k = int(np.argmin(cost))
        if not np.isfinite(cost[k]):
            return None, None
        return int(self.unit[k]), k

    def true_pose(self, t: float) -> FloatArray:
        return self.truth.poses([t])[0]

    def feature_unit(self, f: LineFeature) -> tuple[int | None, int | None]:
        return self.nearest(np.asarray(f.z, dtype=np.float64), self.true_pose(f.t))

    def line_nees(self, line_w: FloatArray, cov_w: FloatArray, k: int) -> float:
        nu, _ = line_difference(line_w, self.lines[k])
        return float(nu @ np.linalg.solve(cov_w, nu))


# -- the instrumented landmark layer -------------------------------------------------------


@dataclass
class Recorder:
    """Every vote's pose, new landmarks and used observations; optionally the truth's veto of
    the wrong ones (``oracle``)."""

    world: WorldTruth | None = None
    oracle: bool = False
    votes: list[dict[str, Any]] = field(default_factory=list)
    landmark_unit: dict[int, int | None] = field(default_factory=dict)
    vetoed: int = 0


RECORDER: Recorder | None = None
_VOTE = LandmarkMap.vote


def _recording_vote(self: LandmarkMap, belief: Belief) -> Decision:
    decision = _VOTE(self, belief)
    rec = RECORDER
    if rec is None or not belief.features:
        return decision
    updates = decision.updates
    if rec.oracle and rec.world is not None:
        for new in decision.new_landmarks:
            rec.landmark_unit[new.id] = rec.world.feature_unit(new.observations[-1][1])[0]
        keep = []
        for j, f in updates:
            u = rec.world.feature_unit(f)[0]
            if u is not None and u == rec.landmark_unit.get(j):
                keep.append((j, f))
            else:
                rec.vetoed += 1
        updates = keep
        decision = replace(decision, updates=updates)
    rec.votes.append(
        {
            "t": float(belief.features[-1].t),
            "wTb": np.array(belief.wTb, dtype=np.float64),
            "P_pose": np.array(belief.P_pose, dtype=np.float64),
            "new": [
                (n.id, n.observations[-1][1], len(n.observations)) for n in decision.new_landmarks
            ],
            "updates": list(updates),
            "scale": self.config.line_cov_scale,
            "bTs": self.bTs,
            "extent_gate": self.config.extent_margin_m is not None,
        }
    )
    return decision


LandmarkMap.vote = _recording_vote  # type: ignore[method-assign]


# -- one run -------------------------------------------------------------------------------


def _dataset(seed: int, cache: Path) -> Dataset:
    folder = simulate_cached("drawn", seed, None, cache)
    cal = calibrate_cached(folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return open_dataset(folder, cal)


def _run(ds: Dataset, backend: str, settings: dict[str, Any], rec: Recorder) -> Any:
    global RECORDER
    RECORDER = rec
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return run_backend(ds, backend, settings)
    finally:
        RECORDER = None


def jump_time(t: FloatArray, nees: FloatArray, threshold: float, hold_s: float) -> float | None:
    """The first time the NEES (samples ``t``) stays above ``threshold`` for ``hold_s`` seconds;
    the first sample above it when it never does; None when none is."""
    above = nees > threshold
    if not above.any():
        return None
    start = None
    for i in range(t.size):
        if above[i]:
            if start is None:
                start = i
            if t[i] - t[start] >= hold_s:
                return float(t[start])
        else:
            start = None
    return float(t[int(np.argmax(above))])


def _evidence(
    ds: Dataset,
    world: WorldTruth,
    run: Any,
    rec: Recorder,
    t_jump: float,
    window_s: float,
    revisit_s: float,
) -> dict[str, Any]:
    """Every check's findings in the window before the jump (module docstring)."""
    cl = run.closed_loop
    lm_obs: dict[int, Counter[int | None]] = {}
    for f, lm, sd in zip(cl.features, cl.feature_landmarks, cl.feature_seeds, strict=True):
        owner = lm if lm is not None else sd
        if owner is not None:
            lm_obs.setdefault(owner, Counter())[world.feature_unit(f)[0]] += 1
    lm_unit = {j: c.most_common(1)[0][0] for j, c in lm_obs.items()}
    lo, hi = t_jump - window_s, t_jump + 5.0
    init: dict[int, dict[str, Any]] = {}
    last_used: dict[int, float] = {}
    wrong_before: dict[int, int] = Counter()
    wrong, used, outliers, gap_off, gap_n = [], set(), [], 0, 0
    earlier: list[dict[str, Any]] = []
    every: list[dict[str, Any]] = []  # every wrong observation used in the run
    for v in rec.votes:
        for j, f, n_views in v["new"]:
            u, k = world.feature_unit(f)
            obs = world_observation(f, v["wTb"], v["P_pose"], v["bTs"], v["scale"])
            entry: dict[str, Any] = {"t": v["t"], "views": n_views, "unit": u}
            if k is not None and world.unit[k] == k:  # a straight wall: its line is the truth
                entry["nees"] = world.line_nees(obs.line_w, obs.cov_w, k)
                o_true = world_observation(f, world.true_pose(f.t), np.zeros((3, 3)), v["bTs"])
                entry["obs_only_nees"] = world.line_nees(o_true.line_w, obs.cov_w, k)
            init[j] = entry
            last_used[j] = v["t"]  # its newest seeding view placed it
        for j, f in v["updates"]:
            u, k = world.feature_unit(f)
            right = u is not None and u == lm_unit.get(j)
            in_window = lo <= f.t <= hi
            if in_window:
                used.add(j)
            if not right:
                w = {"t": f.t, "landmark": j, "landmark_unit": lm_unit.get(j), "obs_unit": u}
                every.append(w)
                if in_window:
                    wrong.append(w)
                elif f.t < lo:
                    wrong_before[j] += 1
                    earlier.append(w)
            elif k is not None and in_window:
                R = np.asarray(f.cov) * v["scale"]
                wTs_true = world.true_pose(f.t)
                o = world_observation(f, wTs_true, np.zeros((3, 3)), v["bTs"])
                # the observation's own error against its true line, in the sonar frame
                nu, _ = line_difference(
                    np.asarray(f.z),
                    _line_in_sonar(world.lines[k], wTs_true, v["bTs"]),
                )
                d2 = float(nu @ np.linalg.solve(R, nu))
                gap_n += 1
                gap_off += d2 > INIT_GATE
                gap = f.t - last_used.get(j, -np.inf)
                if gap >= revisit_s and d2 > OUTLIER_GATE:
                    outliers.append({"t": f.t, "landmark": j, "unit": u, "d2": d2, "unused_s": gap})
                del o
            last_used[j] = f.t
    # the pairings' Mahalanobis distances and the walls' separation for the wrong ones
    gate = chi2_gate(2, run.config.backend.association.gate_probability)
    innov = {(round(i.t_s, 6), i.landmark): i for i in cl.backend.map.innovations}
    corrupted = sorted(j for j in used if wrong_before.get(j))
    earlier = [w for w in earlier if w["landmark"] in corrupted]
    for w in every:
        i = innov.get((round(w["t"], 6), w["landmark"]))
        if i is not None:
            w["d2"] = float(i.nu @ np.linalg.solve(i.S, i.nu))
            w["gate"] = gate
        w["separation"] = _separation(
            world, w["landmark_unit"], w["obs_unit"], world.true_pose(w["t"])
        )
    bad_init = sorted(j for j in used if j in init and init[j].get("nees", 0.0) > INIT_GATE)
    spurious_init = sorted(j for j in used if j in init and init[j]["unit"] is None)
    faults = [
        d
        for d in (ds.truth or {}).get("dvl_dropouts_s", [])
        if t_jump - 30.0 <= d[1] <= t_jump + 5.0
    ]
    return {
        "wrong_in_window": wrong,
        "corrupted_landmarks_used": corrupted,
        "wrong_earlier_on_used": earlier,
        "wrong_in_run": every,
        "landmarks_used": len(used),
        "bad_init_landmarks": [{"id": j, **init[j]} for j in bad_init],
        "spurious_init_landmarks": spurious_init,
        "revisit_outliers": outliers,
        "dvl_dropouts": faults,
        "observations_checked": gap_n,
        "observations_off_99": int(gap_off),
    }


def wrong_pairings(world: WorldTruth, run: Any) -> list[dict[str, Any]]:
    """Every associated observation of a run (used or skipped by the landmark layer) whose
    truth unit is not its landmark's (the landmark's unit: the most common of its
    observations', as :func:`sonarslam.slam.eval.truth.association_scores` counts them), with
    what the gates saw: the pairing's squared Mahalanobis distance (its innovation log), the
    observation's offset from the landmark's true line and from its own nearest one (sonar
    frame, true pose: beyond 1 m or 5 deg from every line an observation is *spurious*), how
    many observations the landmark had taken and how old it was, and the walls' separation."""
    cl = run.closed_loop
    units = [world.feature_unit(f) for f in cl.features]
    lm_obs: dict[int, Counter[int | None]] = {}
    for (u, _), lm, sd in zip(units, cl.feature_landmarks, cl.feature_seeds, strict=True):
        owner = lm if lm is not None else sd
        if owner is not None:
            lm_obs.setdefault(owner, Counter())[u] += 1
    lm_unit = {j: c.most_common(1)[0][0] for j, c in lm_obs.items()}
    innov = {(round(i.t_s, 6), i.landmark): i for i in cl.backend.map.innovations}
    first_t: dict[int, float] = {}
    seed_units: dict[int, Counter[int | None]] = {}
    for f, (u, _), sd in zip(cl.features, units, cl.feature_seeds, strict=True):
        if sd is not None:
            first_t.setdefault(sd, f.t)
            seed_units.setdefault(sd, Counter())[u] += 1
    taken: Counter[int] = Counter()
    out: list[dict[str, Any]] = []
    for f, (u, _), lm in zip(cl.features, units, cl.feature_landmarks, strict=True):
        if lm is None:
            continue
        first_t.setdefault(lm, f.t)
        taken[lm] += 1
        if u is not None and u == lm_unit.get(lm):
            continue
        wTb = world.true_pose(f.t)
        row: dict[str, Any] = {
            "t": float(f.t),
            "landmark": lm,
            "landmark_unit": lm_unit.get(lm),
            "obs_unit": u,
            "obs_z": [float(f.z[0]), float(np.rad2deg(f.z[1]))],
            "landmark_taken": taken[lm] - 1,
            "landmark_age_s": float(f.t - first_t[lm]),
            "offset_own_line": _offset(world, f, wTb, None),
            "offset_landmark_line": _offset(world, f, wTb, lm_unit.get(lm)),
            "separation": _separation(world, lm_unit.get(lm), u, wTb),
            "landmark_seed_units": dict(seed_units.get(lm, {})),
        }
        i = innov.get((round(f.t, 6), lm))
        if i is not None:
            row["d2"] = float(i.nu @ np.linalg.solve(i.S, i.nu))
            row["nu"] = [float(i.nu[0]), float(np.rad2deg(i.nu[1]))]
            row["sd_rho_m"] = float(np.sqrt(i.S[0, 0]))
            row["sd_theta_deg"] = float(np.rad2deg(np.sqrt(i.S[1, 1])))
        out.append(row)
    return out


def _offset(
    world: WorldTruth, f: LineFeature, wTb: FloatArray, unit: int | None
) -> dict[str, float] | None:
    """The observation's smallest offset (m, deg) from the true lines of ``unit`` (None: from
    every true line) in the sonar frame, with the true pose and sonar."""
    ks = np.arange(len(world.lines)) if unit is None else np.flatnonzero(world.unit == unit)
    best: dict[str, float] | None = None
    for k in ks:
        line = _line_in_sonar(world.lines[k], wTb, world.bTs) * np.array([world.range_scale, 1.0])
        nu, _ = line_difference(np.asarray(f.z, dtype=np.float64), line)
        d = {"rho_m": float(abs(nu[0])), "theta_deg": float(np.rad2deg(abs(nu[1])))}
        if best is None or d["rho_m"] + d["theta_deg"] / 5 < best["rho_m"] + best["theta_deg"] / 5:
            best = d
    return best


def _line_in_sonar(line_w: FloatArray, wTb: FloatArray, bTs: FloatArray) -> FloatArray:
    c, s = np.cos(wTb[2]), np.sin(wTb[2])
    xs = wTb[0] + c * bTs[0] - s * bTs[1]
    ys = wTb[1] + s * bTs[0] + c * bTs[1]
    ct, st = np.cos(line_w[1]), np.sin(line_w[1])
    return np.array([line_w[0] - xs * ct - ys * st, line_w[1] - wTb[2] - bTs[2]])


def _separation(
    world: WorldTruth, unit_a: int | None, unit_b: int | None, wTb: FloatArray
) -> dict[str, float] | None:
    """The smallest difference (m, deg) between two truth units' lines in the sonar frame."""
    if unit_a is None or unit_b is None:
        return None
    best: dict[str, float] | None = None
    for ka in np.flatnonzero(world.unit == unit_a):
        for kb in np.flatnonzero(world.unit == unit_b):
            la = _line_in_sonar(world.lines[ka], wTb, world.bTs)
            lb = _line_in_sonar(world.lines[kb], wTb, world.bTs)
            nu, _ = line_difference(la, lb)
            d = {"rho_m": float(abs(nu[0])), "theta_deg": float(np.rad2deg(abs(nu[1])))}
            if (
                best is None
                or d["rho_m"] + d["theta_deg"] / 5 < best["rho_m"] + best["theta_deg"] / 5
            ):
                best = d
    return best


def primary_cause(
    ev: dict[str, Any], start_nees: float, t_jump_rel_s: float, heading_nees: float
) -> str:
    """The first cause whose evidence holds, in the order of :data:`CAUSES` (the first, the
    covariance's loss of positive definiteness, is decided by the caller)."""
    if start_nees > START_GATE or t_jump_rel_s <= START_WINDOW_S:
        return CAUSES[1]
    if ev["wrong_in_window"] or ev["corrupted_landmarks_used"] or ev["spurious_init_landmarks"]:
        return CAUSES[2]
    if ev["bad_init_landmarks"]:
        return CAUSES[3]
    if ev["revisit_outliers"]:
        return CAUSES[4]
    if ev["dvl_dropouts"]:
        return CAUSES[5]
    if heading_nees > HEADING_GATE:
        return CAUSES[6]
    return CAUSES[7]


def diagnose(
    seed: int,
    backend: str,
    settings: dict[str, Any],
    cache: Path,
    threshold: float,
    hold_s: float,
    window_s: float,
    revisit_s: float,
    oracle: bool,
    pairings: bool = False,
) -> dict[str, Any]:
    """One run of one back end on one drawn world, and its jump's evidence if it jumps."""
    ds = _dataset(seed, cache)
    world = WorldTruth.of(ds)
    rec = Recorder(world)
    wall0 = time.perf_counter()
    run = _run(ds, backend, settings, rec)
    pose = nees_series(run.trajectory, world.truth, "pose")
    m = run.metrics
    row: dict[str, Any] = {
        "seed": seed,
        "backend": backend,
        "settings": settings,
        "wall_s": time.perf_counter() - wall0,
        "nees_mean": pose.mean,
        "nees_median": float(np.median(pose.nees)),
        "ate_m": m.get("ate_truth_mean_m"),
        "ate_aligned_m": m.get("ate_truth_aligned_mean_m"),
        "precision": m.get("truth_precision"),
        "recall": m.get("truth_recall"),
        "associated": m.get("truth_associations"),
        "true_pairs": m.get("truth_reobservations"),
        "health_ok": m.get("health_ok"),
        "health_flagged": m.get("health_flagged"),
        "health_first_issue": m.get("health_first_issue"),
        "smoothed_ate_m": m.get("ate_truth_smoothed_mean_m"),
        "smoothed_ate_aligned_m": m.get("ate_truth_aligned_smoothed_mean_m"),
    }
    heading = getattr(run.closed_loop.backend, "heading_innovations", None)
    if heading:
        h = np.asarray(heading, dtype=np.float64)
        nis = h[:, 1] ** 2 / h[:, 2]
        groups = [nis[i : i + 40] for i in range(0, nis.size, 40)]
        row["heading_nis_median"] = float(np.median(nis))
        row["heading_nis_window_medians"] = [round(float(np.median(g)), 3) for g in groups]
    if pairings:
        row["wrong_pairings"] = wrong_pairings(world, run)
    per_s = nees_series(run.trajectory, world.truth, "pose", period_s=1.0)
    row["nees_10s"] = per_s.nees[::10].round(2).tolist()
    e0 = pose_errors(run.trajectory, world.truth, run.trajectory.t_s[:1])[0]
    P0 = np.asarray(run.trajectory.covs)[0]
    row["start_error"] = [float(e0[0]), float(e0[1]), float(np.rad2deg(e0[2]))]
    row["start_sd"] = np.sqrt(np.diag(P0)).tolist()
    row["start_nees"] = float(e0 @ np.linalg.solve(P0, e0))
    row["start_heading_nees"] = float(e0[2] ** 2 / P0[2, 2])
    t_jump = jump_time(per_s.t_s, per_s.nees, threshold, hold_s)
    covs = np.asarray(run.trajectory.covs)
    not_pd = np.flatnonzero(np.linalg.eigvalsh(covs)[:, 0] <= 0.0)
    row["t_cov_not_pd_s"] = (
        float(run.trajectory.t_s[not_pd[0]] - run.trajectory.t_s[0]) if not_pd.size else None
    )
    row["jumps"] = bool(not 0.0 <= pose.mean <= threshold)
    row["t_first_above_s"] = None if t_jump is None else t_jump - float(per_s.t_s[0])
    if row["jumps"] and row["t_cov_not_pd_s"] is not None:
        row["cause"] = CAUSES[0]
        if t_jump is None or t_jump - float(per_s.t_s[0]) > row["t_cov_not_pd_s"]:
            t_jump = float(run.trajectory.t_s[not_pd[0]])
    if not row["jumps"] or t_jump is None:
        return row
    after = (per_s.t_s >= t_jump) & (per_s.t_s <= t_jump + AFTER_JUMP_S)
    head = nees_series(run.trajectory, world.truth, "heading", period_s=1.0)
    posn = nees_series(run.trajectory, world.truth, "position", period_s=1.0)
    h = float(np.median(head.nees[(head.t_s >= t_jump) & (head.t_s <= t_jump + AFTER_JUMP_S)]))
    p = float(np.median(posn.nees[(posn.t_s >= t_jump) & (posn.t_s <= t_jump + AFTER_JUMP_S)]))
    ev = _evidence(ds, world, run, rec, t_jump, window_s, revisit_s)
    row.update(
        {
            "nees_after_jump": float(np.median(per_s.nees[after])),
            "heading_nees_after_jump": h,
            "position_nees_after_jump": p,
            "evidence": ev,
            "cause": row.get("cause")
            or primary_cause(ev, row["start_nees"], t_jump - float(per_s.t_s[0]), h),
        }
    )
    if oracle:
        rec2 = Recorder(world, oracle=True)
        run2 = _run(ds, backend, settings, rec2)
        pose2 = nees_series(run2.trajectory, world.truth, "pose")
        row["oracle"] = {
            "nees_mean": pose2.mean,
            "vetoed": rec2.vetoed,
            "jump_gone": bool(pose2.mean <= threshold),
            "ate_aligned_m": run2.metrics.get("ate_truth_aligned_mean_m"),
        }
    return row


def _json_default(o: Any) -> Any:
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def final_cause(row: dict[str, Any]) -> str | None:
    """A jumping run's cause: wrong association when the truth's veto of the wrong pairings
    (``--oracle``) brings its mean NEES under the threshold, whatever its first jump's evidence
    said (the counterfactual decides); else the evidence's primary cause."""
    if not row["jumps"]:
        return None
    if row.get("cause") != CAUSES[0] and row.get("oracle", {}).get("jump_gone"):
        return CAUSES[2]
    return row.get("cause")


def table(rows: list[dict[str, Any]], backends: list[str]) -> str:
    """The markdown table of causes per back end (:func:`final_cause`)."""
    lines = ["| cause | " + " | ".join(backends) + " |", "|---|" + "---|" * len(backends)]
    for cause in CAUSES:
        counts = [
            sum(1 for r in rows if r["backend"] == b and final_cause(r) == cause) for b in backends
        ]
        lines.append(f"| {cause} | " + " | ".join(str(c) for c in counts) + " |")
    tot = [sum(1 for r in rows if r["backend"] == b and r["jumps"]) for b in backends]
    n = [sum(1 for r in rows if r["backend"] == b) for b in backends]
    lines.append(
        "| **runs with mean pose NEES > 10** | "
        + " | ".join(f"{t} of {k}" for t, k in zip(tot, n, strict=True))
        + " |"
    )
    return "\n".join(lines)


#: The kinds of wrong pairing :func:`pairing_kind` tells apart, in its order.
PAIRING_KINDS = (
    "at a tentative line's promotion",
    "spurious",
    "one line (0-0.14 m, < 0.5 deg)",
    "adjacent walls at an angle (>= 0.5 deg)",
    "parallel, a step (> 0.14 m)",
)


def pairing_kind(p: dict[str, Any]) -> str:
    """What a wrong pairing of ``--pairings`` is: the promoting observation of a tentative line
    (its landmark had taken none), a spurious line on either side, or by the two walls'
    separation (sonar frame): on one line, at an angle, or parallel and apart."""
    if p.get("landmark_unit") is None or p.get("obs_unit") is None:
        return PAIRING_KINDS[1]
    if p.get("landmark_taken") == 0:
        return PAIRING_KINDS[0]
    sep = p.get("separation") or {}
    if abs(float(sep.get("theta_deg", 0.0))) >= 0.5:
        return PAIRING_KINDS[3]
    if abs(float(sep.get("rho_m", 0.0))) <= 0.14:
        return PAIRING_KINDS[2]
    return PAIRING_KINDS[4]


def summary(rows: list[dict[str, Any]], dr: dict[str, list[float]] | None = None) -> str:
    """Per back end and seed range (the seeds' thousands): worlds, pose ANEES (median of the
    runs' means), runs above the threshold (health-flagged), pooled association precision and
    recall, mean ATE unaligned / aligned (iSAM2's smoothed after a semicolon), and with ``dr``
    (seed -> dead reckoning's ``[ATE, aligned ATE]``) how many runs beat it and the worst loss;
    then the wrong pairings by kind (:func:`pairing_kind`)."""
    out = [
        "| back end, seeds | worlds | ANEES (median) | runs > 10 (flagged) | precision / recall"
        " | ATE unaligned / aligned (m) | beats DR unaligned / aligned | worst vs DR |",
        "|---|---|---|---|---|---|---|---|",
    ]
    kinds: dict[str, Counter[str]] = {}
    groups: dict[tuple[str, int], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["backend"], int(r["seed"]) // 10000), []).append(r)
    for (b, _range), rs in sorted(groups.items()):
        n = len(rs)
        nees = [float(r["nees_mean"]) for r in rs]
        above = [r for r in rs if not 0.0 <= float(r["nees_mean"]) <= 10.0]
        flagged = sum(1 for r in above if not r["health_ok"])
        a = sum(r["associated"] for r in rs)
        right = sum(r["precision"] * r["associated"] for r in rs)
        t = sum(r["true_pairs"] for r in rs)
        ate = float(np.mean([r["ate_m"] for r in rs]))
        ate_al = float(np.mean([r["ate_aligned_m"] for r in rs]))
        ates = f"{ate:.2f} / {ate_al:.2f}"
        if all(r.get("smoothed_ate_m") is not None for r in rs):
            sm = float(np.mean([r["smoothed_ate_m"] for r in rs]))
            sm_al = float(np.mean([r["smoothed_ate_aligned_m"] for r in rs]))
            ates += f"; {sm:.2f} / {sm_al:.2f}"
        seeds = f"{min(r['seed'] for r in rs)}-{max(r['seed'] for r in rs)}"
        line = (
            f"| {b}, {seeds} | {n} | {np.mean(nees):.2f} ({np.median(nees):.2f}) |"
            f" {len(above)} ({flagged}) | {100 * right / a:.2f} % / {100 * right / t:.2f} % |"
            f" {ates} |"
        )
        if dr is not None and all(str(r["seed"]) in dr for r in rs):
            d = [dr[str(r["seed"])] for r in rs]
            beat = sum(1 for r, x in zip(rs, d, strict=True) if r["ate_m"] < x[0])
            beat_al = sum(1 for r, x in zip(rs, d, strict=True) if r["ate_aligned_m"] < x[1])
            worst = max(r["ate_m"] / x[0] - 1.0 for r, x in zip(rs, d, strict=True))
            worst_al = max(r["ate_aligned_m"] / x[1] - 1.0 for r, x in zip(rs, d, strict=True))
            line += (
                f" {beat}/{n} / {beat_al}/{n} | {100 * worst:+.0f} % / {100 * worst_al:+.0f} % |"
            )
        else:
            line += " - | - |"
        out.append(line)
        for r in rs:
            for p in r.get("wrong_pairings") or []:
                kinds.setdefault(b, Counter())[pairing_kind(p)] += 1
    if kinds:
        out += ["", "| wrong pairings | " + " | ".join(kinds) + " |"]
        out.append("|---|" + "---|" * len(kinds))
        for k in PAIRING_KINDS:
            out.append(f"| {k} | " + " | ".join(str(c[k]) for c in kinds.values()) + " |")
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--backends", default="ekf,isam2")
    ap.add_argument("--cache", default="out/sim-drawn")
    ap.add_argument("--set", action="append", default=[], metavar="SCOPE.FIELD=V")
    ap.add_argument("--threshold", type=float, default=10.0)
    ap.add_argument("--hold-s", type=float, default=10.0)
    ap.add_argument("--window-s", type=float, default=60.0)
    ap.add_argument("--revisit-s", type=float, default=120.0)
    ap.add_argument(
        "--oracle", action="store_true", help="re-run jumping runs, wrong pairings vetoed"
    )
    ap.add_argument("--pairings", action="store_true", help="list every wrong pairing of every run")
    ap.add_argument("--out", default=None, help="results JSON (rewritten after every run)")
    ap.add_argument("--table", default=None, help="only print the table of this results JSON")
    ap.add_argument(
        "--summary", default=None, help="only print the figures per back end and seed range"
    )
    ap.add_argument(
        "--dr", default=None, help="with --summary: JSON of seed -> DR's [ATE, aligned ATE]"
    )
    args = ap.parse_args()
    if args.table:
        done = json.loads(Path(args.table).read_text())
        print(table(done, list(dict.fromkeys(r["backend"] for r in done))))
        return 0
    if args.summary:
        dr = json.loads(Path(args.dr).read_text()) if args.dr else None
        print(summary(json.loads(Path(args.summary).read_text()), dr))
        return 0
    settings: dict[str, Any] = {}
    for s in args.set:
        key, _, value = s.partition("=")
        settings[key] = json.loads(value) if value not in ("", None) else value
    backends = args.backends.split(",")
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    for seed in parse_seeds(args.seeds):
        for b in backends:
            r = diagnose(
                seed,
                b,
                {k: v for k, v in settings.items() if k.startswith(b + ".") or "." not in k},
                Path(args.cache),
                args.threshold,
                args.hold_s,
                args.window_s,
                args.revisit_s,
                args.oracle,
                args.pairings,
            )
            rows.append(r)
            extra = f" cause: {r['cause']}" if r.get("cause") else ""
            if "oracle" in r:
                extra += f" (oracle NEES {r['oracle']['nees_mean']:.1f})"
            print(
                f"{seed} {b}: NEES mean {r['nees_mean']:.2f} median {r['nees_median']:.2f}"
                f" health_ok {r['health_ok']}{extra} ({r['wall_s']:.0f} s)",
                flush=True,
            )
            if args.out:
                Path(args.out).write_text(json.dumps(rows, indent=1, default=_json_default))
    print(f"\nseeds {args.seeds}, {time.perf_counter() - t0:.0f} s wall\n")
    print(table(rows, backends))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
