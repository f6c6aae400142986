"""``metrics.json`` typed: :class:`RunMetrics` and the records it is made of, one per part of a
run that measures something (the trajectories against GPS and truth, the data, the closed loop,
the health monitor, the provenance).

:meth:`RunMetrics.to_json` writes the one flat object of ``metrics.json``, its keys in the order
of the records; each record's ``KEYS`` are the keys it writes as docs/outputs.md's table names
them (``*``, ``<name>`` and ``{a,b}`` as patterns), and a test checks the table against
:meth:`RunMetrics.key_patterns` both ways.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from sonarslam.datasets.source import Dataset
from sonarslam.slam.eval.ate import (
    AteResult,
    HeadingResult,
    ate_against_gps,
    ate_against_truth,
    ate_errors,
    ate_of_errors,
    half_split_s,
    halves,
    heading_against_truth,
)
from sonarslam.slam.eval.consistency import (
    COMPONENTS,
    NeesSeries,
    chi2_band,
    gps_position_nees,
    nees_series,
)
from sonarslam.slam.eval.loops import Loop, LoopError, LoopSearch, OdometryCheck
from sonarslam.slam.eval.sharpness import trajectory_sharpness
from sonarslam.slam.eval.truth import AssociationScores, association_against_truth, truth_trajectory
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.closed_loop import ClosedLoopResult
from sonarslam.slam.run.presets import RunConfig, map_min_intensity

__all__ = [
    "JsonValue",
    "TrajectoryFigures",
    "DataFigures",
    "ClosedLoopFigures",
    "LoopFigures",
    "RunMetrics",
    "trajectory_figures",
    "closed_loop_figures",
]

#: A value of ``metrics.json`` (JSON's own types).
JsonValue = str | int | float | bool | None | list["JsonValue"] | dict[str, "JsonValue"]


@dataclass(frozen=True)
class TrajectoryFigures:
    """A trajectory's ATE figures: the run's own (``name`` ""), or another one of the back end
    (``"smoothed"``, ``"batch"``: keys with ``_<name>``, of the whole run its mean and max only).

    Attributes
    ----------
    name : str
    ate, ate_aligned : AteResult
        Against every GPS fix of the run, as it is and after a rigid SE(2) fit.
    sonar_span_s : (float, float) or None
        The sonar span (Unix s) when GPS fixes lie inside it, with ``ate_sonar`` and
        ``ate_sonar_aligned`` over them.
    ate_truth, ate_truth_aligned : AteResult or None
        Simulated data: against the truth.
    heading_truth : HeadingResult or None
        Simulated data: the heading error against the truth (as it is).
    map_entropy_nats : float or None
        The map's entropy projected with the trajectory (:mod:`sonarslam.slam.eval.sharpness`).
    nees : dict of str to NeesSeries
        Simulated data, a trajectory with covariances: its NEES against the truth by block
        (``pose``, ``position``, ``heading``;
        :func:`sonarslam.slam.eval.consistency.nees_series`).
    nees_gps : NeesSeries or None
        A trajectory with covariances and GPS fixes inside it: its position NEES at the fixes,
        the GPS sigma (``[noise] gps_sigma_m``) added
        (:func:`sonarslam.slam.eval.consistency.gps_position_nees`; GPS errors are correlated in
        time, so read it as a summary, not a test).
    """

    KEYS: ClassVar[tuple[str, ...]] = (
        "ate_mean_m",
        "ate_sd_m",
        "ate_min_m",
        "ate_max_m",
        "ate_rmse_m",
        "ate_n",
        "sonar_span_s",
        "ate_sonar_*",
        "ate_aligned_*",
        "ate_sonar_aligned_*",
        "sonar_half_split_s",
        "ate_sonar{,_aligned}_half{1,2}{,_<name>}_{mean,max}_m",
        "map_entropy_nats",
        "map_entropy_<name>_nats",
        "ate_truth_*",
        "ate_truth_aligned_*",
        "heading_truth_mean_deg",
        "heading_truth_max_deg",
        "heading_truth_<name>_{mean,max}_deg",
        "ate_mean_<name>_m",
        "ate_max_<name>_m",
        "ate_aligned_mean_<name>_m",
        "ate_aligned_max_<name>_m",
        "ate_sonar_<name>_*",
        "ate_sonar_aligned_<name>_*",
        "ate_truth_<name>_*",
        "ate_truth_aligned_<name>_*",
        "nees_{pose,position,heading}_mean",
        "nees_{pose,position,heading}_in_band_fraction",
        "nees_{pose,position,heading}_band",
        "nees_{pose,position,heading}_<name>_{mean,in_band_fraction,band}",
        "nees_gps_position_{mean,in_band_fraction}",
        "nees_gps_position_<name>_{mean,in_band_fraction}",
    )

    name: str
    ate: AteResult | None
    ate_aligned: AteResult | None
    sonar_span_s: tuple[float, float] | None = None
    ate_sonar: AteResult | None = None
    ate_sonar_aligned: AteResult | None = None
    #: the sonar span's two halves (:func:`sonarslam.slam.eval.ate.half_split_s`): unaligned
    #: first and second, then aligned (the whole span's fit) first and second
    sonar_halves: tuple[AteResult, AteResult, AteResult, AteResult] | None = None
    ate_truth: AteResult | None = None
    ate_truth_aligned: AteResult | None = None
    heading_truth: HeadingResult | None = None
    map_entropy_nats: float | None = None
    nees: Mapping[str, NeesSeries] = field(default_factory=dict)
    nees_gps: NeesSeries | None = None

    def nees_json(self) -> dict[str, JsonValue]:
        """Each NEES block's mean over the trajectory's samples, the share of samples inside
        the two-sided 95 % band of chi2(dof) and that band (a consistent estimate's mean is
        dof); against GPS, the mean and the share in band (suffix ``_<name>``)."""
        suffix = f"_{self.name}" if self.name else ""
        out: dict[str, JsonValue] = {}
        for block, series in self.nees.items():
            lo, hi = chi2_band(series.dof)
            out[f"nees_{block}{suffix}_mean"] = _finite(series.mean)
            out[f"nees_{block}{suffix}_in_band_fraction"] = series.in_band_fraction()
            out[f"nees_{block}{suffix}_band"] = [lo, hi]
        if self.nees_gps is not None and self.nees_gps.nees.size:
            out[f"nees_gps_position{suffix}_mean"] = _finite(self.nees_gps.mean)
            out[f"nees_gps_position{suffix}_in_band_fraction"] = self.nees_gps.in_band_fraction()
        return out

    def whole_json(self) -> dict[str, JsonValue]:
        """The whole run's ATE: every figure for the run's own trajectory, mean and max for
        another one; nothing without GPS."""
        if self.ate is None or self.ate_aligned is None:
            return {}
        if not self.name:
            return {**self.ate.as_dict(), **self.ate_aligned.as_dict("ate_aligned")}
        n = self.name
        return {
            f"ate_mean_{n}_m": self.ate.ate_mean_m,
            f"ate_max_{n}_m": self.ate.ate_max_m,
            f"ate_aligned_mean_{n}_m": self.ate_aligned.ate_mean_m,
            f"ate_aligned_max_{n}_m": self.ate_aligned.ate_max_m,
        }

    def span_json(self) -> dict[str, JsonValue]:
        """The sonar span's and the truth's figures (``suffix`` ``_<name>``)."""
        suffix = f"_{self.name}" if self.name else ""
        out: dict[str, JsonValue] = {}
        if self.ate_sonar is not None and self.ate_sonar_aligned is not None:
            if not suffix and self.sonar_span_s is not None:
                out["sonar_span_s"] = [self.sonar_span_s[0], self.sonar_span_s[1]]
            out.update(self.ate_sonar.as_dict(f"ate_sonar{suffix}"))
            out.update(self.ate_sonar_aligned.as_dict(f"ate_sonar_aligned{suffix}"))
        if self.sonar_halves is not None and self.sonar_span_s is not None:
            if not suffix:
                out["sonar_half_split_s"] = half_split_s(self.sonar_span_s)
            names = (
                "ate_sonar_half1",
                "ate_sonar_half2",
                "ate_sonar_aligned_half1",
                "ate_sonar_aligned_half2",
            )
            for name, ate in zip(names, self.sonar_halves, strict=True):
                out[f"{name}{suffix}_mean_m"] = ate.ate_mean_m
                out[f"{name}{suffix}_max_m"] = ate.ate_max_m
        if self.ate_truth is not None and self.ate_truth_aligned is not None:
            out.update(self.ate_truth.as_dict(f"ate_truth{suffix}"))
            out.update(self.ate_truth_aligned.as_dict(f"ate_truth_aligned{suffix}"))
        if self.heading_truth is not None:
            out[f"heading_truth{suffix}_mean_deg"] = self.heading_truth.mean_deg
            out[f"heading_truth{suffix}_max_deg"] = self.heading_truth.max_deg
        return out

    def entropy_json(self) -> dict[str, JsonValue]:
        if self.map_entropy_nats is None:
            return {}
        suffix = f"_{self.name}" if self.name else ""
        return {f"map_entropy{suffix}_nats": self.map_entropy_nats}


@dataclass(frozen=True)
class DataFigures:
    """The run's time and its data: the estimation's wall time and the data's span (s), the DVL's
    rows and quality (:func:`sonarslam.slam.run.sources.dvl_quality`), the GPS's coverage and the sensor
    gates' faults and gaps (:meth:`sonarslam.datasets.gates.GateReport.metrics`)."""

    KEYS: ClassVar[tuple[str, ...]] = (
        "wall_s",
        "data_s",
        "realtime_factor",
        "dvl_rows",
        "dvl_invalid_rows",
        "dvl_speed_p{50,90}_mps",
        "dvl_scatter_p{10,50,90,99}_mps",
        "dvl_excess_s",
        "dvl_excess_from_s",
        "gps_uncovered_s",
        "fault_<sensor>_<kind>",
        "gap_<sensor>_{count,total_s,longest_s}",
        "gap_spans_s",
        "beams_outside_nav",
    )

    wall_s: float
    data_s: float
    dvl_rows: int
    dvl_invalid_rows: int
    dvl_quality: Mapping[str, float]
    gps_uncovered_s: float | None  # None without GPS
    faults_and_gaps: Mapping[str, JsonValue]

    @property
    def realtime_factor(self) -> float:
        return self.data_s / self.wall_s if self.wall_s > 0 else float("inf")

    def to_json(self) -> dict[str, JsonValue]:
        return {
            "wall_s": self.wall_s,
            "data_s": self.data_s,
            "realtime_factor": self.realtime_factor,
            "dvl_rows": self.dvl_rows,
            "dvl_invalid_rows": self.dvl_invalid_rows,
            **self.dvl_quality,
            **({} if self.gps_uncovered_s is None else {"gps_uncovered_s": self.gps_uncovered_s}),
            **self.faults_and_gaps,
        }


@dataclass(frozen=True)
class ClosedLoopFigures:
    """A closed loop's figures: its settings, map, counters and timings, the back end's own
    (``state_*``, ``isam2_*``, ``scan_*``), the line NIS, the cost per vote, on simulated data the
    associations against the truth, and the health monitor's verdict (``odometry``: the odometry
    check it judged, which the loop figures report; not a key of its own)."""

    KEYS: ClassVar[tuple[str, ...]] = (
        "settings",
        "extractor_preset",
        "landmarks",
        "line_features",
        "assoc_*",
        "beams",
        "extractor_s",
        "backend_s",
        "scan_matcher_s",
        "line_updates",
        "line_update_p50_ms",
        "line_update_p99_ms",
        "isam2_*",
        "state_ahrs_bias{,_sd}_deg",
        "state_misalignment{,_sd}_deg",
        "state_dvl_scale{,_sd}",
        "state_gyro_bias{,_sd}_deg_per_s",
        "state_sonar_x{,_sd}_m",
        "state_sonar_y{,_sd}_m",
        "state_sonar_yaw{,_sd}_deg",
        "state_sonar_range_scale{,_sd}",
        "state_sonar_yaw_misalignment_corr",
        "noise_learner_steps",
        "noise_heading_walk_deg_per_sqrt_s_{final,max}",
        "noise_dvl_scale_walk_per_sqrt_s_{final,max}",
        "noise_line_scale_{final,max}",
        "noise_scan_scale_{final,max}",
        "scans",
        "scan_consecutive_tried",
        "scan_consecutive_accepted",
        "scan_revisit_tried",
        "scan_revisit_accepted",
        "scan_revisit_nis_median",
        "redecided_observations",
        "redecided_kept",
        "redecided_dropped",
        "redecided_moved",
        "redecided_stretches",
        "redecided_passes",
        "retest_{runs,factors,removed}",
        "offline_passes",
        "offline_settled",
        "offline_moved_m",
        "offline_changed",
        "offline_decisions",
        "offline_scans",
        "offline_revisit_candidates",
        "offline_revisits_registered",
        "offline_revisits_kept",
        "offline_rejected_<reason>",
        "offline_{odometry,heading,revisit,line}_scale",
        "offline_lines_{observations,kept,dropped,moved,stretches}",
        "offline_s",
        "scan_revisit_incompatible",
        "truth_precision",
        "truth_recall",
        "truth_associations",
        "truth_reobservations",
        "truth_seeds",
        "truth_seed_precision",
        "truth_spurious_features",
        "health_ok",
        "health_issues",
        "health_flagged",
        "health_first_issue",
        "health_line",
        "health_<check>_windows",
        "health_<check>_flagged",
        "health_<check>_underconfident",
        "health_underconfident",
        "health_first_finding",
        "health_false_alarm",
    )

    settings: Mapping[str, JsonValue]
    extractor_preset: str
    landmarks: int
    line_features: int
    counters: Mapping[str, int]
    extractor_s: float
    backend_s: float
    scan_matcher_s: float
    beams: int
    backend: Mapping[str, float | int]
    nis_median: float | None = None
    nis_mean: float | None = None
    vote_ms: tuple[float, float, int] | None = None  # p50, p99, votes
    truth: AssociationScores | None = None
    health: Mapping[str, JsonValue] = field(default_factory=dict)
    health_line: str = ""
    #: the odometry check the health monitor judged (every closed loop, with GPS or without),
    #: for the loop figures
    odometry: OdometryCheck | None = None

    def to_json(self) -> dict[str, JsonValue]:
        out: dict[str, JsonValue] = {
            "settings": dict(self.settings),
            "extractor_preset": self.extractor_preset,
            "landmarks": self.landmarks,
            "line_features": self.line_features,
            **{f"assoc_{k}": v for k, v in self.counters.items()},
            "extractor_s": self.extractor_s,
            "backend_s": self.backend_s,
            "scan_matcher_s": self.scan_matcher_s,
            "beams": self.beams,
            **self.backend,
        }
        if self.nis_median is not None and self.nis_mean is not None:
            out["assoc_nis_median"] = self.nis_median
            out["assoc_nis_mean"] = self.nis_mean
        if self.vote_ms is not None:
            p50, p99, n = self.vote_ms
            out["line_updates"] = n
            out["line_update_p50_ms"] = p50
            out["line_update_p99_ms"] = p99
        if self.truth is not None:
            s = self.truth
            out["truth_precision"] = s.precision
            out["truth_recall"] = s.recall
            out["truth_associations"] = s.n_associated
            out["truth_reobservations"] = s.n_true_pairs
            out["truth_seeds"] = s.n_seeds
            out["truth_seed_precision"] = s.seed_precision
            out["truth_spurious_features"] = s.n_spurious
        out.update(self.health)
        out["health_line"] = self.health_line
        return out


@dataclass
class LoopFigures:
    """The loop-closure errors of a run (:mod:`sonarslam.slam.eval.loops`): the loops stated and
    found, and each estimate's error at them (``""`` the run's own, ``"dr"`` dead reckoning,
    the back end's others by name).

    Attributes
    ----------
    radius_m : float
        How near a return must come to be searched (m).
    loops : list of Loop
    errors : dict of str to list of LoopError
        One error per loop for each estimate.
    searched : bool
        Whether loops were searched for (runs without GPS) besides the stated ones.
    odometry : OdometryCheck or None
        Dead reckoning's motion against the sonar's between nearby scans (runs without GPS).
    search : LoopSearch or None
        What the search for loops tried (runs without GPS).
    """

    KEYS: ClassVar[tuple[str, ...]] = (
        "loops_stated",
        "loops_found",
        "loop_search_tried",
        "loop_search_too_far",
        "loop_search_path_m",
        "loop_radius_m",
        "loop_reference_sigma_m",
        "loops_with_free_direction",
        "loop_error_mean_m",
        "loop_error_max_m",
        "loop_error_<name>_mean_m",
        "loop_error_<name>_max_m",
        "loops",
        "odometry_check_pairs",
        "odometry_check_accepted",
        "odometry_check_heading_deg",
        "odometry_check_scale",
        "odometry_check_heading_se_deg",
        "odometry_check_scale_se",
        "odometry_check_starts",
        "odometry_check_skipped_still",
        "odometry_check_skipped_sparse",
        "odometry_check_step_m",
        "odometry_check_lateral_gain",
        "odometry_check_lateral_gain_se",
    )

    radius_m: float
    loops: list[Loop]
    errors: dict[str, list[LoopError]]
    searched: bool
    odometry: OdometryCheck | None = None
    search: LoopSearch | None = None

    def to_json(self) -> dict[str, JsonValue]:
        out: dict[str, JsonValue] = {
            "loops_stated": sum(loop.how == "stated" for loop in self.loops),
            "loops_found": sum(loop.how == "found" for loop in self.loops)
            if self.searched
            else None,
            "loop_radius_m": self.radius_m,
            # the found loops' references' own accuracy: a floor under every loop error
            "loop_reference_sigma_m": _finite(
                float(np.mean(sigmas))
                if (sigmas := [x.sigma_m for x in self.loops if np.isfinite(x.sigma_m)])
                else math.nan
            ),
            "loops_with_free_direction": sum(x.free_directions > 0 for x in self.loops),
        }
        for name, errors in self.errors.items():
            tag = f"_{name}" if name else ""
            values = [e.position_m for e in errors]
            out[f"loop_error{tag}_mean_m"] = float(np.mean(values)) if values else None
            out[f"loop_error{tag}_max_m"] = float(np.max(values)) if values else None
        out["loops"] = [
            {
                "t0_s": loop.t0_s,
                "t1_s": loop.t1_s,
                "how": loop.how,
                "t0Tt1": [_finite(v) for v in loop.t0Tt1],
                "reference_sigma_m": _finite(loop.sigma_m),
                "reference_free_directions": loop.free_directions,
                "error_m": {
                    name or "run": errors[k].position_m for name, errors in self.errors.items()
                },
                "error_heading_deg": {
                    name or "run": _finite(errors[k].heading_deg)
                    for name, errors in self.errors.items()
                },
            }
            for k, loop in enumerate(self.loops)
        ]
        if self.search is not None:
            out["loop_search_tried"] = self.search.tried
            out["loop_search_too_far"] = self.search.too_far
            out["loop_search_path_m"] = self.search.path_m
        if self.odometry is not None:
            out["odometry_check_pairs"] = self.odometry.pairs
            out["odometry_check_accepted"] = self.odometry.accepted
            out["odometry_check_heading_deg"] = _finite(self.odometry.heading_deg)
            out["odometry_check_scale"] = _finite(self.odometry.scale)
            out["odometry_check_heading_se_deg"] = _finite(self.odometry.heading_se_deg)
            out["odometry_check_scale_se"] = _finite(self.odometry.scale_se)
            out["odometry_check_starts"] = self.odometry.starts
            out["odometry_check_skipped_still"] = self.odometry.skipped_still
            out["odometry_check_skipped_sparse"] = self.odometry.skipped_sparse
            out["odometry_check_step_m"] = _finite(self.odometry.step_m)
            out["odometry_check_lateral_gain"] = _finite(self.odometry.lateral_gain)
            out["odometry_check_lateral_gain_se"] = _finite(self.odometry.lateral_gain_se)
        return out


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


@dataclass
class RunMetrics:
    """Everything a run measured: ``metrics.json`` (:meth:`to_json`).

    Attributes
    ----------
    source : str
        The dataset directory.
    backend : str
    trajectory : TrajectoryFigures
        The run's own trajectory.
    data : DataFigures
    closed_loop : ClosedLoopFigures or None
        None for a baseline (``dr``, ``gps``).
    others : list of TrajectoryFigures
        The back end's other trajectories (``smoothed``, ``batch``).
    provenance : dict or None
        Where the figures come from (:func:`sonarslam.slam.run.provenance.provenance`), added when the
        run is written.
    """

    KEYS: ClassVar[tuple[str, ...]] = (
        "source",
        "backend",
        "calibration",
        "evaluation",
        "start_pose",
        "provenance",
    )

    source: str
    backend: str
    trajectory: TrajectoryFigures
    data: DataFigures
    closed_loop: ClosedLoopFigures | None = None
    others: list[TrajectoryFigures] = field(default_factory=list)
    provenance: dict[str, JsonValue] | None = None
    #: where the dataset's calibration came from (:attr:`sonarslam.datasets.source.Dataset.calibration`)
    calibration: str = ""
    #: what the run is measured against: "gps", "gps and truth", or "no GPS: ..."
    evaluation: str = ""
    #: where the start pose came from (:func:`sonarslam.slam.run.sources.start_pose_origin`)
    start_pose: str = ""
    #: the loop-closure errors (runs without GPS, or with loops stated)
    loops: LoopFigures | None = None

    def to_json(self) -> dict[str, JsonValue]:
        """The one flat object of ``metrics.json``."""
        out: dict[str, JsonValue] = {
            "source": self.source,
            "backend": self.backend,
            "calibration": self.calibration,
            "evaluation": self.evaluation,
            "start_pose": self.start_pose,
            **self.trajectory.whole_json(),
            **self.trajectory.span_json(),
            **self.trajectory.nees_json(),
            **self.data.to_json(),
        }
        if self.closed_loop is not None:
            out.update(self.closed_loop.to_json())
        out.update(self.trajectory.entropy_json())
        for other in self.others:
            out.update(other.entropy_json())
            out.update(other.whole_json())
            out.update(other.span_json())
            out.update(other.nees_json())
        if self.loops is not None:
            out.update(self.loops.to_json())
        if self.provenance is not None:
            out["provenance"] = self.provenance
        return out

    @classmethod
    def key_patterns(cls) -> set[str]:
        """Every key (or key pattern) ``metrics.json`` may hold, as docs/outputs.md names them."""
        records = (cls, TrajectoryFigures, DataFigures, ClosedLoopFigures, LoopFigures)
        return {key for record in records for key in record.KEYS}


def _sharpness(dataset: Dataset, trajectory: Trajectory) -> float | None:
    """The entropy (nats) of the whole sonar span's map projected with the trajectory
    (:func:`sonarslam.slam.eval.sharpness.trajectory_sharpness`, 0.5 m cells; GPS-free, lower is
    sharper); None without beams inside the trajectory's span."""
    span = dataset.sonar_span_s
    if span is None:
        return None
    t0, t1 = max(span[0], trajectory.span_s[0]), min(span[1], trajectory.span_s[1])
    if t1 <= t0:
        return None
    level = map_min_intensity(dataset.beams)
    return trajectory_sharpness(dataset, trajectory, (t0, t1), level)


def trajectory_figures(dataset: Dataset, trajectory: Trajectory, name: str) -> TrajectoryFigures:
    """A trajectory's figures (:class:`TrajectoryFigures`): its ATE against the GPS over the whole run and over the sonar span (where
    GPS fixes lie inside it), each also rigidly aligned; on simulated data against the truth
    over the whole run; and its map's entropy. ``name``: "" for the run's own trajectory, else
    the back end's name of it (``"smoothed"``)."""
    gps = dataset.gps
    span = dataset.sonar_span_s
    inside = (
        gps is not None and span is not None and bool(np.any(_in(gps.t, span, trajectory.span_s)))
    )
    sonar: tuple[AteResult | None, AteResult | None] = (None, None)
    halves_found = None
    if gps is not None and span is not None and inside:
        t, e = ate_errors(trajectory, gps, span)
        _, e_aligned = ate_errors(trajectory, gps, span, align=True)
        sonar = (ate_of_errors(e), ate_of_errors(e_aligned))
        split = half_split_s(span)
        if np.any(t <= split) and np.any(t > split):
            halves_found = (*halves(t, e, split), *halves(t, e_aligned, split))
    truth_figures: tuple[AteResult | None, AteResult | None] = (None, None)
    nees: dict[str, NeesSeries] = {}
    heading = None
    if dataset.truth is not None:
        truth = truth_trajectory(dataset)
        truth_figures = (
            ate_against_truth(trajectory, truth),
            ate_against_truth(trajectory, truth, align=True),
        )
        heading = heading_against_truth(trajectory, truth)
        if trajectory.covs is not None:
            nees = {block: nees_series(trajectory, truth, block) for block in COMPONENTS}
    nees_gps = None
    if gps is not None and trajectory.covs is not None and dataset.truth is None:
        nees_gps = gps_position_nees(
            trajectory, gps.t, gps.en_m, float(dataset.config.noise.gps_sigma_m)
        )
    return TrajectoryFigures(
        name=name,
        ate=ate_against_gps(trajectory, gps) if gps is not None else None,
        ate_aligned=ate_against_gps(trajectory, gps, align=True) if gps is not None else None,
        sonar_span_s=(span[0], span[1]) if span is not None and inside else None,
        ate_sonar=sonar[0],
        ate_sonar_aligned=sonar[1],
        sonar_halves=halves_found,
        ate_truth=truth_figures[0],
        ate_truth_aligned=truth_figures[1],
        heading_truth=heading,
        map_entropy_nats=_sharpness(dataset, trajectory),
        nees=nees,
        nees_gps=nees_gps,
    )


def _in(t_s: np.ndarray, *spans: tuple[float, float]) -> np.ndarray:
    keep = np.ones(t_s.shape, dtype=bool)
    for a, b in spans:
        keep &= (t_s >= a) & (t_s <= b)
    return keep


def closed_loop_figures(
    dataset: Dataset,
    result: ClosedLoopResult,
    config: RunConfig,
    health: dict[str, JsonValue],
    health_line: str,
    odometry: OdometryCheck | None = None,
) -> ClosedLoopFigures:
    backend = result.backend
    nis = backend.map.nis()
    vote_ms = 1e3 * np.asarray(backend.vote_wall_s)
    truth = None
    if dataset.truth is not None and "walls_m" in dataset.truth:
        truth = association_against_truth(
            dataset, result.features, result.feature_landmarks, result.feature_seeds
        )
    return ClosedLoopFigures(
        settings=dict(config.settings),
        extractor_preset=config.preset,
        landmarks=len(backend.map.active()),
        line_features=len(result.features),
        counters=backend.stats,
        extractor_s=result.extractor_s,
        backend_s=result.backend_s,
        scan_matcher_s=result.scan_matcher_s,
        beams=result.counts.get("beams", 0),
        backend=backend.metrics(),
        nis_median=float(np.median(nis)) if nis.size else None,
        nis_mean=float(np.mean(nis)) if nis.size else None,
        vote_ms=(
            (float(np.percentile(vote_ms, 50)), float(np.percentile(vote_ms, 99)), vote_ms.size)
            if vote_ms.size
            else None
        ),
        truth=truth,
        health=health,
        health_line=health_line,
        odometry=odometry,
    )
