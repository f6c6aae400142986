"""The estimate made after the run, with hindsight: every revisit and every line decided again
from the whole run, at an estimate that has stopped drifting.

Online, each revisit is proposed, registered and gated from the estimate of the moment, and each
line associated while the trajectory drifts; once decided they stay. After the run the whole
trajectory is known, so :func:`offline_estimate` decides again, in passes, starting from the
run's smoothed estimate (the graph's values):

1. **Scans at the current estimate.** Every scan of the run is built again from the beams,
   motion-corrected with the current estimate (its nodes densified by the odometry,
   :func:`sonarslam.slam.backends.isam2.pose_source.smoothed_poses`); each is carried to its
   nearest node (its reference in the node's frame from the same estimate).
2. **Candidates from the whole run.** For every scan, every scan at least ``revisit_min_gap_s``
   older whose reference is within ``revisit_radius_m`` in the current estimate; at most
   ``revisits_per_scan`` of them, spread over time (the candidates in time order cut into that
   many groups, the nearest of each: :func:`sonarslam.slam.backends.isam2.scans.choose_revisits`).
3. **Registrations with hindsight.** Each pair registered submap to submap, both submaps complete
   and centred on their scan (:meth:`sonarslam.features.scans.matcher.ScanMatcher.register`),
   from the current estimate's relative pose, with several starts spread by its covariance (the
   current graph's joint marginal). With ``yaw_sigma_deg``, the registration's yaw is decoupled
   from its translation at that sigma.
4. **One joint decision on all revisits**: graduated non-convexity with a truncated
   least-squares cost (:func:`sonarslam.slam.backends.isam2.gnc.gnc_tls`), the truncation
   chi2(3) at ``decision_probability``, every other factor a known inlier: the odometry, the
   AHRS headings, the priors and (from the second pass) the lines as last re-decided.
5. **Lines re-decided at that estimate** (:func:`sonarslam.slam.backends.isam2.redecided.redecided_records`):
   the run's line observations at their new sonar poses, cut into stretches of at most
   ``stretch_m`` along their walls, associated again; a landmark that fits a wall only
   piecewise becomes several.
6. **Noise from the data.** The revisits' and the lines' covariance scales estimated from the
   residuals of the consistent set at the optimum (variance components,
   :func:`sonarslam.slam.backends.isam2.variance.variance_component`), never below what the
   front end said; the graph re-optimised with them. The first pass starts the revisits' scale
   from the median of their residuals under a Cauchy kernel, so that the joint decision does
   not judge them with a covariance the data already contradict.

The passes repeat from each optimum until the decisions (the revisits kept, the lines'
partition) stop changing, at most ``max_passes`` times. The online factors of the run's
revisits and scan registrations are not used: they were decided while drifting. The result's
covariance is the final graph's marginals.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import C, R, X
from scipy.stats import chi2

from sonarslam.features.geometry import FloatArray, between
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.scans import ScanConfig, ScanMatcher
from sonarslam.features.scans.icp import Registration
from sonarslam.slam.backends.isam2.config import OfflineConfig
from sonarslam.slam.backends.isam2.gnc import gnc_tls
from sonarslam.slam.backends.isam2.graph_io import (
    FactorKind,
    FactorRecord,
    Robust,
    pose_of,
)
from sonarslam.slam.backends.isam2.pose_source import smoothed_poses
from sonarslam.slam.backends.isam2.redecided import (
    is_line_record,
    optimise_records,
    redecided_records,
)
from sonarslam.slam.backends.isam2.scans import (
    between_nodes,
    choose_revisits,
    relative_pose_covariance,
)
from sonarslam.slam.backends.isam2.variance import variance_component
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.mapping.association import AssociationConfig
from sonarslam.slam.mapping.redecide import RedecideConfig, Redecision
from sonarslam.slam.model.lines import local_to_world
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead

__all__ = ["OfflinePass", "OfflineResult", "NodePoses", "offline_estimate", "base_records"]

#: The revisits' factors are named so in ``graph.json``.
OFFLINE_REVISIT = "offline-revisit"
#: A revisit's covariance scale never goes beyond this (a scale this large says the model is
#: wrong, not that the registrations are noisy).
MAX_SCALE = 1e4
#: Levenberg-Marquardt iterations of each step of the joint decision (warm-started).
GNC_ITERATIONS = 10
#: The revisits' kernel in the final graph by default (the run's scan kernel).
CAUCHY = Robust("cauchy", 1.0)


@dataclass
class OfflinePass:
    """What one pass decided (``offline_*`` in ``metrics.json``; :meth:`OfflineResult.metrics`).

    Attributes
    ----------
    scans : int
    candidates : int
        Revisit pairs proposed (step 2).
    registered : int
        ... that the registration accepted (step 3).
    kept : int
        ... that the joint decision kept (step 4).
    rejected : dict of str to int
        Why the registration refused the others.
    scales : dict of str to float
        The covariance scale of each group of factors (:data:`GROUPS`) at the end of the pass
        (step 6).
    lines : dict of str to int
        The lines' re-decision (observations, kept, dropped, moved, stretches).
    changed : int
        Revisits kept or dropped differently from the previous pass, plus line observations on
        another stretch (a partition's changes); -1 in the first pass.
    decisions : int
        The revisits registered and the line observations decided: what ``changed`` is a share
        of.
    settled : bool
        Fewer than ``settle_share`` of the decisions changed: the last pass.
    moved_m : float
        The largest move of a node's position in the pass (m): how far the pass moved the
        estimate it started from.
    wall_s : float
    timing_s : dict of str to float
        Wall time of each step (s): ``scans``, ``registrations``, ``decision``, ``lines``,
        ``noise``.
    """

    scans: int = 0
    candidates: int = 0
    registered: int = 0
    kept: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    scales: dict[str, float] = field(default_factory=dict)
    lines: dict[str, int] = field(default_factory=dict)
    changed: int = -1
    decisions: int = 0
    settled: bool = False
    moved_m: float = float("nan")
    wall_s: float = 0.0
    timing_s: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class OfflineResult:
    """The offline estimate (:func:`offline_estimate`).

    Attributes
    ----------
    values : gtsam.Values
        The final optimum (poses ``X(k)``, the stretches ``S(j)``, the other variables).
    records : list of FactorRecord
        The final graph (``graph_offline.json``).
    trajectory : Trajectory
        The nodes' poses with their marginal covariances (world ``(x_m, y_m, yaw_rad)``).
    passes : list of OfflinePass
    revisits : list of dict
        The last pass's revisit pairs: scans ``j``, ``k``, their times, whether registered and
        kept, and the registration's relative pose ``z`` and covariance ``cov``.
    """

    values: gtsam.Values
    records: list[FactorRecord]
    trajectory: Trajectory
    passes: list[OfflinePass]
    revisits: list[dict[str, Any]]

    def metrics(self) -> dict[str, float | int | bool]:
        """``offline_*``: the last pass's decisions, the passes made, whether they settled and
        how far the last pass moved the estimate."""
        last = self.passes[-1]
        out: dict[str, float | int | bool] = {
            "offline_passes": len(self.passes),
            "offline_settled": bool(last.settled),
            "offline_moved_m": last.moved_m,
            "offline_changed": last.changed,
            "offline_decisions": last.decisions,
            "offline_scans": last.scans,
            "offline_revisit_candidates": last.candidates,
            "offline_revisits_registered": last.registered,
            "offline_revisits_kept": last.kept,
            **{f"offline_{g}_scale": v for g, v in last.scales.items()},
            "offline_s": float(sum(p.wall_s for p in self.passes)),
        }
        out.update({f"offline_lines_{k}": v for k, v in last.lines.items()})
        out.update({f"offline_rejected_{k.replace(' ', '_')}": v for k, v in last.rejected.items()})
        return out


@dataclass(frozen=True, eq=False)
class NodePoses:
    """An estimate's nodes densified by the odometry: the pose source of a pass
    (:func:`sonarslam.slam.backends.isam2.pose_source.smoothed_poses`).

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Node times (Unix s), increasing.
    wTb : ndarray, shape (N, 3)
        Their poses.
    odometry : PoseSource
        Any trajectory whose relative motion is the odometry's (dead reckoning).
    """

    t_s: FloatArray
    wTb: FloatArray
    odometry: PoseSource

    @property
    def span_s(self) -> tuple[float, float]:
        return float(self.t_s[0]), float(self.t_s[-1])

    def poses(self, t_s: Any) -> FloatArray:
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        odo_n = self.odometry.poses(self.t_s)
        return smoothed_poses(t, self.t_s, self.wTb, odo_n, self.odometry.poses(t))

    def covariance(self, t_s: float) -> FloatArray | None:
        return None


def base_records(records: Sequence[FactorRecord]) -> list[FactorRecord]:
    """The run's factors the offline estimate keeps as they are: every factor but the lines
    (and their equalities) and the scan registrations, which it decides again."""
    return [
        r
        for r in records
        if not is_line_record(r)
        and r.kind is not FactorKind.LINE_EQUALITY
        and not (r.constraint or "").startswith("scan-")
    ]


def _line_records(records: Sequence[FactorRecord]) -> list[FactorRecord]:
    """The run's line observations and their equalities: the first partition to re-decide."""
    return [r for r in records if is_line_record(r) or r.kind is FactorKind.LINE_EQUALITY]


def _node_poses(values: gtsam.Values, n: int) -> FloatArray:
    return np.array([pose_of(values.atPose2(X(k))) for k in range(n)])


def _graph(records: Iterable[FactorRecord]) -> gtsam.NonlinearFactorGraph:
    graph = gtsam.NonlinearFactorGraph()
    for r in records:
        graph.add(r.to_gtsam())
    return graph


#: The groups of factors whose covariance scales are estimated from the data (step 6): the
#: odometry between nodes, the AHRS headings, the revisits and the lines. The priors and the
#: AHRS bias's walk keep theirs.
GROUPS = ("odometry", "heading", "revisit", "line")


def group_of(record: FactorRecord) -> str:
    """The group of :data:`GROUPS` a factor belongs to, or "" (its covariance stays)."""
    if is_line_record(record):
        return "line"
    if record.kind is FactorKind.HEADING_BIAS:
        return "heading"
    if record.constraint == OFFLINE_REVISIT:
        return "revisit"  # plain or calibrated
    if record.kind is FactorKind.DVL_GYRO_ODOMETRY or (
        record.kind is FactorKind.BETWEEN_POSE and record.constraint is None
    ):
        return "odometry"
    return ""


def _scaled(records: Iterable[FactorRecord], scales: dict[str, float]) -> list[FactorRecord]:
    """``records`` with each group's covariance times its scale (``scales`` by group)."""
    out = []
    for r in records:
        scale = scales.get(group_of(r), 1.0)
        out.append(r if scale == 1.0 else replace(r, cov=r.cov * scale))
    return out


def _variance_components(
    records: list[FactorRecord],
    scales: dict[str, float],
    estimated: Sequence[str],
    values: gtsam.Values,
    params: gtsam.LevenbergMarquardtParams,
    iterations: int = 5,
    tolerance: float = 0.05,
) -> tuple[dict[str, float], gtsam.Values]:
    """Step 6: each ``estimated`` group's scale re-estimated at the optimum
    (:func:`sonarslam.slam.backends.isam2.variance.variance_component`) and the graph
    re-optimised with it, until no scale moves by more than ``tolerance`` (relative); scales
    stay within ``[1, MAX_SCALE]``: never more confident than the model said."""
    scales = dict(scales)
    groups = {g: [r for r in records if group_of(r) == g] for g in estimated}
    for _ in range(iterations):
        scaled = _scaled(records, scales)
        marginals = gtsam.Marginals(_graph(scaled), values)
        moved = 0.0
        for g, members in groups.items():
            if not members:
                continue
            vc = variance_component(_scaled(members, scales), values, marginals)
            if not np.isfinite(vc.scale):
                continue
            new = float(np.clip(scales[g] * vc.scale, 1.0, MAX_SCALE))
            moved = max(moved, abs(new / scales[g] - 1.0))
            scales[g] = new
        values = optimise_records(_scaled(records, scales), values, params)
        if moved < tolerance:
            break
    return scales, values


def _decoupled(cov: FloatArray, yaw_sigma_deg: float | None) -> FloatArray:
    """``cov`` with its yaw made independent of its translation, at least ``yaw_sigma_deg``."""
    if yaw_sigma_deg is None:
        return cov
    out = np.array(cov, dtype=np.float64)
    out[:2, 2] = out[2, :2] = 0.0
    out[2, 2] = max(float(cov[2, 2]), np.deg2rad(yaw_sigma_deg) ** 2)
    return out


class _Pairs:
    """Steps 1-3 of a pass: the scans at the estimate, the candidates, their registrations."""

    def __init__(
        self,
        beams: Iterable[SonarBeam],
        head: SonarHead,
        mounting: Mounting,
        scan_config: ScanConfig,
        poses: NodePoses,
        calibration: list[int],
    ) -> None:
        self.poses = poses
        #: the graph's sonar calibration variables (``C(0)``, ``R(0)``) the revisits take, if any
        self.calibration = calibration
        self.bTs = mounting.as_pose()
        t0, t1 = poses.span_s
        self.matcher = ScanMatcher(scan_config, head, mounting, poses)
        for beam in beams:
            if t0 <= beam.t <= t1:
                self.matcher.add(beam)
        self.scans = self.matcher.scans
        self.t_ref = np.array([s.t_ref_s for s in self.scans])
        self.wTref = poses.poses(self.t_ref) if self.scans else np.zeros((0, 3))
        # each scan's node (the nearest) and its reference in that node's frame
        node_t = poses.t_s
        i = np.clip(np.searchsorted(node_t, self.t_ref), 1, node_t.size - 1)
        nearer = np.abs(node_t[i - 1] - self.t_ref) <= np.abs(node_t[i] - self.t_ref)
        self.node = np.where(nearer, i - 1, i) if node_t.size > 1 else np.zeros_like(i)
        self.node_T_ref = np.array(
            [between(poses.wTb[n], p) for n, p in zip(self.node, self.wTref, strict=True)]
        ).reshape(-1, 3)

    def candidates(self, config: OfflineConfig) -> list[tuple[int, int]]:
        """Step 2: ``(j, k)``, ``j`` the older scan."""
        pairs = []
        xy = self.wTref[:, :2]
        for k in range(len(self.scans)):
            older = np.flatnonzero(self.t_ref[:k] <= self.t_ref[k] - config.revisit_min_gap_s)
            if older.size == 0:
                continue
            d = np.hypot(*(xy[older] - xy[k]).T)
            near = d <= config.revisit_radius_m
            pool = [(float(dist), int(j)) for dist, j in zip(d[near], older[near], strict=True)]
            for _, j in choose_revisits(pool, config.revisits_per_scan, 1, "spread"):
                if self.node[j] != self.node[k]:
                    pairs.append((j, k))
        return sorted(pairs)

    def register(
        self, j: int, k: int, relative_cov: Callable[[int, int], FloatArray]
    ) -> Registration:
        """Step 3: submap ``k`` onto submap ``j`` from the estimate's relative pose."""
        guess = between(self.wTref[j], self.wTref[k])
        return self.matcher.register(j, k, guess, relative_cov(j, k))

    def register_all(
        self,
        proposed: list[tuple[int, int]],
        relative_cov: Callable[[int, int], FloatArray],
        config: OfflineConfig,
        robust: Robust | None,
    ) -> tuple[list[tuple[int, int]], list[FactorRecord], list[dict[str, Any]]]:
        """Step 3 for every pair: those the registration accepted, their factors, and a row
        per pair (:attr:`OfflineResult.revisits`)."""
        registered: list[tuple[int, int]] = []
        revisits: list[FactorRecord] = []
        rows: list[dict[str, Any]] = []
        for j, k in proposed:
            reg = self.register(j, k, relative_cov)
            rows.append(
                {
                    "j": j,
                    "k": k,
                    "t_j": float(self.t_ref[j]),
                    "t_k": float(self.t_ref[k]),
                    "registered": bool(reg.accepted),
                    "reason": reg.reason,
                    "kept": False,
                    "z": reg.z.tolist(),
                    "cov": reg.cov.tolist(),
                    "n_constrained": reg.n_constrained,
                    "inlier_share": reg.inlier_share,
                }
            )
            if reg.accepted:
                registered.append((j, k))
                revisits.append(self.record(j, k, reg, config, robust))
        return registered, revisits, rows

    def record(
        self, j: int, k: int, reg: Registration, config: OfflineConfig, robust: Robust | None
    ) -> FactorRecord:
        """The ``BetweenFactorPose2`` of a registration between the scans' nodes."""
        z, cov = between_nodes(
            self.node_T_ref[j],
            reg.z,
            _decoupled(reg.cov, config.yaw_sigma_deg),
            self.node_T_ref[k],
        )
        nodes = [X(int(self.node[j])), X(int(self.node[k]))]
        if self.calibration:  # the run estimated the sonar's calibration: the scans take it
            return FactorRecord.of(
                FactorKind.SCAN_CALIBRATED,
                [*nodes, *self.calibration],
                z,
                0.5 * (cov + cov.T),
                bTs=self.bTs,
                robust=robust,
                constraint=OFFLINE_REVISIT,
            )
        return FactorRecord.of(
            FactorKind.BETWEEN_POSE,
            nodes,
            z,
            0.5 * (cov + cov.T),
            robust=robust,
            constraint=OFFLINE_REVISIT,
        )


def _relative_covariance(
    marginals: gtsam.Marginals, pairs: _Pairs, values: gtsam.Values
) -> Callable[[int, int], FloatArray]:
    """The current graph's covariance of scan ``j``'s reference to scan ``k``'s (the nodes'
    joint marginal, the scans' offsets from their nodes exact)."""

    def cov(j: int, k: int) -> FloatArray:
        nj, nk = int(pairs.node[j]), int(pairs.node[k])
        joint = marginals.jointMarginalCovariance([X(nj), X(nk)])
        P = np.block(
            [
                [np.asarray(joint.at(X(nj), X(nj))), np.asarray(joint.at(X(nj), X(nk)))],
                [np.asarray(joint.at(X(nk), X(nj))), np.asarray(joint.at(X(nk), X(nk)))],
            ]
        )
        wTj, wTk = pose_of(values.atPose2(X(nj))), pose_of(values.atPose2(X(nk)))
        M = np.zeros((6, 6))
        M[:3, :3] = local_to_world(float(wTj[2]))
        M[3:, 3:] = local_to_world(float(wTk[2]))
        S = relative_pose_covariance(wTj, wTk, M @ P @ M.T)
        # the scans' references are near their nodes: the nodes' relative covariance stands
        return 0.5 * (S + S.T)

    return cov


class _Clock:
    """Adds the wall time since the previous call to ``timing_s[step]``."""

    def __init__(self, timing_s: dict[str, float]) -> None:
        self.timing_s = timing_s
        self._t = time.perf_counter()

    def __call__(self, step: str) -> None:
        now = time.perf_counter()
        self.timing_s[step] = self.timing_s.get(step, 0.0) + now - self._t
        self._t = now


def _decision_graph(known: list[FactorRecord], values: gtsam.Values) -> gtsam.NonlinearFactorGraph:
    """The known factors of the joint decision, each AHRS heading ``yaw + b = z`` a native
    prior on the yaw at the bias's current estimate (``PoseRotationPrior2D`` on ``z - b``): a
    bias moves the whole map about the start, which no revisit observes, and a native factor
    costs a tenth of the Python one at each of the decision's many iterations."""
    graph = gtsam.NonlinearFactorGraph()
    for r in known:
        if r.kind is FactorKind.HEADING_BIAS and values.exists(r.keys[1]):
            b = float(values.atVector(r.keys[1])[0])
            noise = gtsam.noiseModel.Isotropic.Sigma(1, float(np.sqrt(r.cov[0, 0])))
            graph.add(
                gtsam.PoseRotationPrior2D(r.keys[0], gtsam.Pose2(0.0, 0.0, r.z[0] - b), noise)
            )
        else:
            graph.add(r.to_gtsam())
    return graph


def _robust_scale(
    known: gtsam.NonlinearFactorGraph, revisits: list[FactorRecord], values: gtsam.Values
) -> float:
    """The revisits' covariance scale from the median of their squared residuals at the
    optimum of the graph with every revisit under a Cauchy kernel (k = 1), against chi2(3)'s
    median; at least 1."""
    if not revisits:
        return 1.0
    graph = gtsam.NonlinearFactorGraph(known)
    for r in revisits:
        graph.add(replace(r, robust=Robust("cauchy", 1.0)).to_gtsam())
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(50)
    optimum = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    plain = [replace(r, robust=None).to_gtsam() for r in revisits]
    r2 = np.array([2.0 * f.error(optimum) for f in plain])
    return float(np.clip(np.median(r2) / chi2.median(3), 1.0, MAX_SCALE))


def _start_values(records: Iterable[FactorRecord], values: gtsam.Values) -> gtsam.Values:
    """``values`` of the variables ``records`` use (the poses and vectors they share)."""
    keys: set[int] = set()
    for r in records:
        keys.update(r.keys)
    out = gtsam.Values()
    for key in keys:
        if not values.exists(key):
            continue
        if gtsam.Symbol(key).chr() == ord("x"):
            out.insert(key, values.atPose2(key))
        else:
            out.insert(key, values.atVector(key))
    return out


def offline_estimate(
    records: Sequence[FactorRecord],
    values: gtsam.Values,
    node_t_s: FloatArray,
    beams: Callable[[], Iterable[SonarBeam]],
    head: SonarHead,
    sonar_mounting: Mounting,
    odometry: PoseSource,
    scan_config: ScanConfig,
    config: OfflineConfig,
    association: AssociationConfig,
    robust: Robust | None = CAUCHY,
) -> OfflineResult:
    """The offline estimate (module docstring).

    Parameters
    ----------
    records : sequence of FactorRecord
        The run's graph (:attr:`sonarslam.slam.backends.isam2.graph.LineIsam2.records` or a
        ``graph.json``'s).
    values : gtsam.Values
        Its smoothed estimate: every variable of ``records``.
    node_t_s : ndarray, shape (N,)
        The time of each node ``X(k)`` (Unix s), increasing.
    beams : callable
        Returns the run's beams, in time order, each time it is called (once a pass).
    head : SonarHead
    sonar_mounting : Mounting
        ``bTs`` of the sonar head.
    odometry : PoseSource
        Dead reckoning (its relative motion shapes the poses between nodes).
    scan_config : ScanConfig
        The scans and their registration.
    config : OfflineConfig
    association : AssociationConfig
        The lines' re-association (the run's).
    robust : Robust or None
        The kernel of the revisits in the final graph.

    Returns
    -------
    OfflineResult
    """
    node_t = np.asarray(node_t_s, dtype=np.float64)
    n = node_t.size
    base = base_records(records)
    calibration = [int(key) for key in (C(0), R(0)) if values.exists(key)]
    first_partition = _line_records(records) if config.lines else []
    redecide_config = RedecideConfig(max_stretch_m=config.stretch_m, association=association)
    lm = gtsam.LevenbergMarquardtParams()
    lm.setMaxIterations(100)
    # GNC's steps each start from the previous step's optimum: a few iterations follow it
    gnc_lm = gtsam.LevenbergMarquardtParams()
    gnc_lm.setMaxIterations(GNC_ITERATIONS)
    c2 = float(chi2.ppf(config.decision_probability, 3))

    current = gtsam.Values(values)
    graph_records: list[FactorRecord] = list(records)  # the graph ``current`` is the optimum of
    if config.start == "odometry":  # the odometry and headings alone: no decision made yet
        graph_records = list(base)
        current = _merge(current, optimise_records(base, current, lm))
    lines: list[FactorRecord] = []
    scales = dict.fromkeys(GROUPS, 1.0)
    passes: list[OfflinePass] = []
    kept_before: set[tuple[int, int]] | None = None
    stretch_before: np.ndarray | None = None
    revisit_rows: list[dict[str, Any]] = []
    for p in range(config.max_passes):
        wall0 = time.perf_counter()
        log = OfflinePass()
        before_xy = _node_poses(current, n)[:, :2]
        clock = _Clock(log.timing_s)
        # steps 1-3
        pairs = _Pairs(
            beams(),
            head,
            sonar_mounting,
            scan_config,
            NodePoses(node_t, _node_poses(current, n), odometry),
            calibration,
        )
        log.scans = len(pairs.scans)
        clock("scans")
        marginals = gtsam.Marginals(_graph(graph_records), _start_values(graph_records, current))
        registered, revisits, revisit_rows = pairs.register_all(
            pairs.candidates(config),
            _relative_covariance(marginals, pairs, current),
            config,
            robust,
        )
        log.candidates = len(revisit_rows)
        log.registered = len(revisits)
        log.rejected = dict(Counter(r["reason"] for r in revisit_rows if not r["registered"]))
        clock("registrations")
        # step 4: the joint decision, the lines of the previous pass known
        known = [*base, *lines]
        start = _start_values([*known, *revisits], current)
        known_graph = _decision_graph(_scaled(known, scales), start)
        if config.noise_scales is not None and p == 0:
            scales["revisit"] = _robust_scale(known_graph, revisits, start)
        decided = gnc_tls(known_graph, _scaled(revisits, scales), start, c2, gnc_lm)
        inliers = [revisits[i] for i in decided.inliers]
        kept = {registered[i] for i in decided.inliers}
        for row in revisit_rows:
            row["kept"] = (row["j"], row["k"]) in kept
        log.kept = len(inliers)
        estimate = _merge(current, decided.values)
        clock("decision")
        # step 5: the lines at that estimate (associated with the lines' scale)
        decision: Redecision | None = None
        line_starts: dict[int, np.ndarray] = {}
        lines = []
        if first_partition:
            out, line_starts, decision = redecided_records(
                _scaled([*base, *first_partition], {"line": scales["line"]}),
                estimate,
                redecide_config,
            )
            lines = [replace(r, cov=r.cov / scales["line"]) for r in out if is_line_record(r)]
            log.lines = decision.counts()
        final = [*base, *inliers, *lines]
        estimate = optimise_records(_scaled(final, scales), estimate, lm, line_starts)
        clock("lines")
        # step 6: the noise scales from the consistent set
        if config.noise_scales is not None:
            groups = GROUPS if config.noise_scales == "all" else ("revisit", "line")
            scales, estimate = _variance_components(final, scales, groups, estimate, lm)
        log.scales = dict(scales)
        clock("noise")
        # did the decisions change?
        stretch = decision.stretch if decision is not None else np.zeros(0, dtype=int)
        if kept_before is not None:
            log.changed = len(kept ^ kept_before) + _partition_changes(stretch_before, stretch)
        kept_before, stretch_before = kept, stretch
        log.decisions = len(registered) + int(stretch.size)
        current = _merge(current, estimate)
        log.moved_m = float(np.max(np.hypot(*(_node_poses(current, n)[:, :2] - before_xy).T)))
        graph_records = _scaled(final, scales)
        log.wall_s = time.perf_counter() - wall0
        passes.append(log)
        log.settled = 0 <= log.changed <= config.settle_share * log.decisions
        if log.settled:
            break
    marginals = gtsam.Marginals(_graph(graph_records), _start_values(graph_records, current))
    poses = _node_poses(current, n)
    covs = np.empty((n, 3, 3))
    for k in range(n):
        M = local_to_world(float(poses[k, 2]))
        covs[k] = M @ marginals.marginalCovariance(X(k)) @ M.T
    result_values = _start_values(graph_records, current)
    return OfflineResult(
        result_values, graph_records, Trajectory(node_t.copy(), poses, covs), passes, revisit_rows
    )


def _merge(values: gtsam.Values, newer: gtsam.Values) -> gtsam.Values:
    """``values`` with every variable ``newer`` holds taken from it (new ones added)."""
    out = gtsam.Values(values)
    for key in newer.keys():
        pose = gtsam.Symbol(key).chr() == ord("x")
        v = newer.atPose2(key) if pose else newer.atVector(key)
        if out.exists(key):
            out.update(key, v)
        else:
            out.insert(key, v)
    return out


def _partition_changes(before: np.ndarray | None, after: np.ndarray) -> int:
    """Observations whose stretch changed between two partitions (labels may differ: two
    observations together in one and apart in the other count; dropped ones by themselves)."""
    if before is None or before.size != after.size:
        return int(after.size)
    if after.size == 0:
        return 0
    # the same partition up to labels: a one-to-one map between the kept observations' labels
    forward: dict[int, set[int]] = {}
    backward: dict[int, set[int]] = {}
    for a, b in zip(before.tolist(), after.tolist(), strict=True):
        if a >= 0 and b >= 0:
            forward.setdefault(a, set()).add(b)
            backward.setdefault(b, set()).add(a)
    bad_a = {a for a, bs in forward.items() if len(bs) > 1}
    bad_b = {b for b, as_ in backward.items() if len(as_) > 1}
    moved = [
        (a < 0) != (b < 0) or a in bad_a or b in bad_b
        for a, b in zip(before.tolist(), after.tolist(), strict=True)
    ]
    return int(np.sum(moved))
