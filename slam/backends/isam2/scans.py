"""Scan constraints in the factor graph: a pose node per scan, relative poses between them.

The scan matcher (:class:`sonarslam.features.scans.matcher.ScanMatcher`, the front end) gives each new
scan. Here (MSISpIC's pose graph, Mallios et al. 2014, in iSAM2):

1. **A node** at the scan's reference time (the newest node when one is less than
   ``min_node_gap_s`` old; the odometry since it is then composed onto the measurement).
2. **Consecutive**: the scan registered onto the one before it, a ``BetweenFactorPose2``.
3. **Revisits proposed by the graph's own marginals**, not by a fixed radius: an older scan
   ``j`` is a candidate when the distance ``|d|`` of the two scans' estimated positions minus
   ``revisit_radius_m`` (how close two scans must be to see the same walls), in sigmas of the
   marginal of their relative position along ``d``, is inside the chi2(1) gate
   ``revisit_gate_probability``: ``max(|d| - r, 0)^2 / (u^T S u) <= chi2_1(p)`` with
   ``u = d / |d|``. A loose pass uses each node's cached marginal and no cross-covariance
   (conservative: the cross-covariance of two poses of one trajectory is positive); the nearest
   ``revisit_candidates`` then get the joint marginal ``(X(j), X(k))`` and the exact gate.
   ``revisits_per_scan`` of them (``revisit_choice``: the nearest, or spread over the passes,
   :func:`choose_revisits`; at least ``revisit_spacing_scans`` apart) are registered (submaps
   of ``submap_scans`` scans; with ``revisit_lag_scans``, once that many newer scans have
   arrived, so that the new scan's submap is complete and centred) from the graph's relative
   pose, and kept (``revisit_gate = "registration"``, the default) whenever the registration's
   own tests accept them, or (``"graph"``) only when compatible with the graph's prediction
   (chi2(3) of the difference with both covariances; the directions the registration leaves
   free carry no information).
4. Every scan factor has a robust kernel (``scan_robust``, Cauchy by default) and is a record
   of :mod:`sonarslam.slam.backends.isam2.graph_io` (``BetweenFactorPose2`` with ``"robust"`` and
   ``"constraint"``: ``"scan-consecutive"`` or ``"scan-revisit"``), so ``graph.json`` holds
   it and ``graph.g2o`` writes it as ``EDGE_SE2``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X
from scipy.stats import chi2

from sonarslam.features.geometry import (
    FloatArray,
    between,
    compose,
    compose_jacobians,
    inverse,
    wrap_angle,
)
from sonarslam.features.scans.icp import Registration
from sonarslam.features.scans.matcher import ScanMatcher
from sonarslam.features.scans.scan import Scan
from sonarslam.slam.backends.isam2.config import GraphConfig
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord, Robust
from sonarslam.slam.backends.learned import LearnedNoise
from sonarslam.slam.model.lines import local_to_world

__all__ = [
    "ScanGraph",
    "ScanLog",
    "ScanConstraints",
    "relative_pose_covariance",
    "between_nodes",
    "radial_gate_distance",
    "choose_revisits",
]


class ScanGraph(Protocol):
    """What the scan constraints need of the graph (:class:`sonarslam.slam.backends.isam2.graph.LineIsam2`)."""

    @property
    def isam(self) -> gtsam.ISAM2: ...

    @property
    def bTs(self) -> FloatArray:
        """The sonar mounting the front end assumed (the scans' points are in the body frame
        through it)."""
        ...

    def calibration_keys(self) -> list[int]:
        """The keys of the sonar's calibration variables (none when not estimated)."""
        ...

    def node_now(self) -> tuple[int, FloatArray]:
        """A node now (or the newest) and the body pose now in its frame."""
        ...

    def node_estimate(self, k: int) -> FloatArray:
        """The current estimate of node ``k``, ``(x_m, y_m, yaw_rad)``."""
        ...

    def add_scan_factor(self, record: FactorRecord) -> None:
        """A factor record for the next update."""
        ...

    def scan_update(self, extra_iterations: int = 0) -> None:
        """Pending factors into iSAM2."""
        ...

    @property
    def noise(self) -> LearnedNoise:
        """The graph's learned noise (the revisits' covariance scale among it)."""
        ...

    def learned_changed(self) -> None:
        """The learner changed a value: into force."""
        ...


def relative_pose_covariance(wTa: FloatArray, wTb: FloatArray, P: FloatArray) -> FloatArray:
    """Covariance of ``aTb = inverse(wTa) * wTb`` in ``(x_m, y_m, yaw_rad)``.

    Parameters
    ----------
    wTa, wTb : ndarray, shape (3,)
    P : ndarray, shape (6, 6)
        Joint covariance of ``(wTa, wTb)`` in plain world ``(x, y, yaw)``.
    """
    aTw = inverse(wTa)
    J_inv_a, J_w = compose_jacobians(aTw, wTb)
    # d inverse(wTa) / d wTa
    c, s = np.cos(wTa[2]), np.sin(wTa[2])
    x, y = wTa[0], wTa[1]
    J_inv = np.array([[-c, -s, s * x - c * y], [s, -c, c * x + s * y], [0.0, 0.0, -1.0]])
    J = np.hstack([J_inv_a @ J_inv, J_w])
    return J @ P @ J.T


def between_nodes(
    jn_T_j: FloatArray, z_jk: FloatArray, cov_jk: FloatArray, kn_T_k: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """A relative pose of two scans' references moved onto their nodes: the measurement and
    covariance of the ``BetweenFactorPose2`` between the nodes.

    Parameters
    ----------
    jn_T_j, kn_T_k : ndarray, shape (3,)
        Each scan's reference in its node's frame.
    z_jk : ndarray, shape (3,)
        ``jTk``, the registration.
    cov_jk : ndarray, shape (3, 3)
        Its covariance in plain ``(x_m, y_m, yaw_rad)``.

    Returns
    -------
    z : ndarray, shape (3,)
        ``jnTkn = jnTj * jTk * inverse(knTk)``.
    cov : ndarray, shape (3, 3)
        Its covariance in the measurement's local tangent (GTSAM's).
    """
    a = compose(jn_T_j, z_jk)
    z = compose(a, inverse(kn_T_k))
    _, J1_z = compose_jacobians(jn_T_j, z_jk)
    J2_a, _ = compose_jacobians(a, inverse(kn_T_k))
    J = J2_a @ J1_z
    cov = J @ cov_jk @ J.T
    A = local_to_world(-float(z[2]))  # plain -> the measurement's local tangent
    return z, A @ cov @ A.T


def radial_gate_distance(d_xy: FloatArray, S_xy: FloatArray, radius_m: float) -> float:
    """``max(|d| - r, 0)^2 / (u^T S u)``, ``u = d / |d|``: how many sigmas (squared) of the
    relative position's uncertainty along ``d`` separate the two positions from being within
    ``r`` of each other (0 inside)."""
    dist = float(np.hypot(d_xy[0], d_xy[1]))
    if dist <= radius_m:
        return 0.0
    u = np.asarray(d_xy) / dist
    return (dist - radius_m) ** 2 / max(float(u @ S_xy @ u), 1e-12)


def choose_revisits(
    candidates: list[tuple[float, int]], n: int, spacing: int, rule: str
) -> list[tuple[float, int]]:
    """At most ``n`` of ``(distance_m, scan j)`` revisit candidates, each at least ``spacing``
    scans from the others chosen (a revisit of one place from several passes, not one pass's
    neighbouring scans).

    ``rule``: ``"nearest"``, the nearest in metres first (the most overlap); ``"spread"``, the
    candidates in time order split into ``n`` groups of equal count and the nearest of each
    group (the oldest passes as well as the newest: a revisit's information about the drift
    grows with the time between its two scans, and one pass's revisits share their errors),
    then the nearest of the rest while fewer than ``n`` are chosen.
    """
    if n <= 0 or not candidates:
        return []
    chosen: list[tuple[float, int]] = []

    def take(pool: list[tuple[float, int]]) -> None:
        for g, j in sorted(pool):
            if len(chosen) >= n:
                return
            if all(abs(j - c) >= spacing for _, c in chosen):
                chosen.append((g, j))
                return

    if rule == "spread":
        by_time = sorted(candidates, key=lambda c: c[1])
        for group in np.array_split(np.arange(len(by_time)), min(n, len(by_time))):
            take([by_time[i] for i in group])
    for g, j in sorted(candidates):
        if len(chosen) >= n:
            break
        if (g, j) not in chosen and all(abs(j - c) >= spacing for _, c in chosen):
            chosen.append((g, j))
    return chosen


@dataclass
class ScanLog:
    """What the scan constraints did, for ``metrics.json`` and the registration benchmark.

    Attributes
    ----------
    nodes : dict of int to tuple
        Scan index -> ``(node k, kTref)``: its node and the scan's reference in the node frame.
    pairs : list of dict
        Every registration: ``kind`` (``consecutive`` / ``revisit``), scans ``j``, ``k``,
        ``accepted``, ``reason``, ``z``, ``guess``, ``cov``, ``n_constrained``, ``inlier_share``,
        ``nis`` (revisits: chi2(3) of the difference with the graph's prediction).
    """

    nodes: dict[int, tuple[int, FloatArray]] = field(default_factory=dict)
    pairs: list[dict[str, Any]] = field(default_factory=list)

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {"scans": len(self.nodes)}
        for kind in ("consecutive", "revisit"):
            rows = [p for p in self.pairs if p["kind"] == kind]
            out[f"scan_{kind}_tried"] = len(rows)
            out[f"scan_{kind}_accepted"] = sum(bool(p["accepted"]) for p in rows)
        return out


class ScanConstraints:
    """The graph's scan constraints (module docstring).

    Parameters
    ----------
    graph : ScanGraph
        The graph they go into (:class:`sonarslam.slam.backends.isam2.graph.LineIsam2`).
    config : GraphConfig
    """

    def __init__(self, graph: ScanGraph, config: GraphConfig) -> None:
        self.graph = graph
        self.config = config
        self.log = ScanLog()
        #: Revisits the registration accepted and the graph's compatibility gate did not: the
        #: loose candidates a joint inlier choice may still take (``batch_optimizer = "gnc"``).
        self.loose_revisits: list[FactorRecord] = []
        self._t: list[float] = []  # reference time of each scan
        self._cov: list[FloatArray] = []  # cached marginal (world) of each scan's node
        self._gate = float(chi2.ppf(config.revisit_gate_probability, 1))
        self._compat = float(chi2.ppf(config.scan_compatibility_probability, 3))

    def _robust(self) -> Robust | None:
        cfg = self.config
        return None if cfg.scan_robust is None else Robust(cfg.scan_robust, cfg.scan_robust_k)

    def _add_between(self, j: int, k: int, reg: Registration, kind: str) -> None:
        """``BetweenFactorPose2`` between the nodes of scans ``j`` and ``k`` from ``jTk``,
        into the graph."""
        self.graph.add_scan_factor(self._record(j, k, reg, kind))

    def _record(self, j: int, k: int, reg: Registration, kind: str) -> FactorRecord:
        """The ``BetweenFactorPose2`` record between the nodes of scans ``j`` and ``k``; a
        revisit's covariance times the learned scan scale
        (:class:`sonarslam.slam.backends.learned.LearnedNoise`)."""
        (nj, jn_T_j), (nk, kn_T_k) = self.log.nodes[j], self.log.nodes[k]
        z, cov = between_nodes(jn_T_j, reg.z, reg.cov, kn_T_k)
        if kind == "revisit":
            cov = self.graph.noise.value("scan_scale") * cov
        calibration = self.graph.calibration_keys() if self.config.scan_calibration else []
        if calibration:
            return FactorRecord.of(
                FactorKind.SCAN_CALIBRATED,
                [X(nj), X(nk), *calibration],
                z,
                cov,
                bTs=np.asarray(self.graph.bTs, dtype=np.float64).copy(),
                robust=self._robust(),
                constraint=f"scan-{kind}",
            )
        return FactorRecord.of(
            FactorKind.BETWEEN_POSE,
            [X(nj), X(nk)],
            z,
            cov,
            robust=self._robust(),
            constraint=f"scan-{kind}",
        )

    def add_scan(self, scan: Scan, matcher: ScanMatcher) -> None:
        """A new scan (the newest of ``matcher``): its node, the consecutive constraint, the
        revisits; one iSAM2 update."""
        cfg = self.config
        node, kTref = self.graph.node_now()
        k = scan.index
        self.log.nodes[k] = (node, kTref)
        self.graph.noise.mark(("S", k))
        self._t.append(scan.t_ref_s)
        self._cov.append(np.full((3, 3), np.inf))
        if cfg.scan_consecutive and k >= 1 and (k - 1) in self.log.nodes:
            reg = matcher.consecutive(k)
            if reg is not None:
                self._log(reg, "consecutive", k - 1, k)
                if reg.accepted:
                    self._add_between(k - 1, k, reg, "consecutive")
        self.graph.scan_update()
        self._cov[k] = self._marginal(k)
        c = k - cfg.revisit_lag_scans  # the scan whose revisits are proposed now
        if cfg.revisits_per_scan > 0 and c >= 0 and c in self.log.nodes:
            if c != k:
                self._cov[c] = self._marginal(c)
            self._revisits(c, matcher)

    def _log(self, reg: Registration, kind: str, j: int, k: int, nis: float | None = None) -> None:
        self.log.pairs.append(
            {
                "kind": kind,
                "j": j,
                "k": k,
                "t_j": self._t[j],
                "t_k": self._t[k],
                "accepted": reg.accepted,
                "reason": reg.reason,
                "z": reg.z.tolist(),
                "guess": reg.guess.tolist(),
                "cov": reg.cov.tolist(),
                "n_constrained": reg.n_constrained,
                "inlier_share": reg.inlier_share,
                "nis": nis,
            }
        )

    def _pose(self, j: int) -> FloatArray:
        """The current estimate of scan ``j``'s reference body pose."""
        node, kTref = self.log.nodes[j]
        return compose(self.graph.node_estimate(node), kTref)

    def _marginal(self, j: int) -> FloatArray:
        """iSAM2 marginal of scan ``j``'s node in plain world ``(x, y, yaw)``."""
        node = self.log.nodes[j][0]
        M = local_to_world(float(self.graph.node_estimate(node)[2]))
        return M @ self.graph.isam.marginalCovariance(X(node)) @ M.T

    def _joint(self, j: int, k: int) -> FloatArray:
        """Joint marginal of the nodes of scans ``j`` and ``k`` in plain world coordinates."""
        nj, nk = self.log.nodes[j][0], self.log.nodes[k][0]
        J = self.graph.isam.jointMarginalCovariance([X(nj), X(nk)]).fullMatrix()
        M = np.zeros((6, 6))
        M[:3, :3] = local_to_world(float(self.graph.node_estimate(nj)[2]))
        M[3:, 3:] = local_to_world(float(self.graph.node_estimate(nk)[2]))
        return M @ J @ M.T

    def _loose(self, k: int, pose_k: FloatArray, spread: int) -> list[tuple[float, int]]:
        """Older scans under the loose gate, at most ``revisit_candidates``
        (:func:`choose_revisits`, ``revisit_choice``)."""
        cfg = self.config
        out = []
        for j in range(k):
            if self._t[k] - self._t[j] < cfg.revisit_min_gap_s or j not in self.log.nodes:
                continue
            d = self._pose(j)[:2] - pose_k[:2]
            S = self._cov[j][:2, :2] + self._cov[k][:2, :2]
            if radial_gate_distance(d, S, cfg.revisit_radius_m) <= self._gate:
                out.append((float(np.hypot(d[0], d[1])), j))
        return choose_revisits(out, cfg.revisit_candidates, spread, cfg.revisit_choice)

    def _revisits(self, k: int, matcher: ScanMatcher) -> None:
        cfg = self.config
        pose_k = self._pose(k)
        gated: list[tuple[float, int, FloatArray, FloatArray]] = []
        spacing = cfg.revisit_spacing_scans or matcher.config.submap_scans
        for _, j in self._loose(k, pose_k, spacing):
            pose_j = self._pose(j)
            S = relative_pose_covariance(pose_j, pose_k, self._joint(j, k))
            jTk = between(pose_j, pose_k)
            # the gate in scan j's frame: d and S of the relative position
            if radial_gate_distance(-jTk[:2], S[:2, :2], cfg.revisit_radius_m) <= self._gate:
                gated.append((float(np.hypot(jTk[0], jTk[1])), j, jTk, S))
        picked = {
            j
            for _, j in choose_revisits(
                [(g[0], g[1]) for g in gated], cfg.revisits_per_scan, spacing, cfg.revisit_choice
            )
        }
        added = False
        for _, j, jTk, S in sorted(gated, key=lambda c: c[0]):
            if j not in picked:
                continue
            reg = matcher.register(j, k, jTk, S)
            nis = None
            if reg.accepted:
                nu = np.array([*(reg.z[:2] - jTk[:2]), wrap_angle(reg.z[2] - jTk[2])])
                scale = self.graph.noise.value("scan_scale")
                nis = float(nu @ np.linalg.solve(S + scale * reg.cov, nu))
                yaw_j = float(self._pose(j)[2])
                if self.graph.noise.add_registration(
                    self._t[k], nu, S, reg.cov, ("S", j), ("S", k), yaw_j, pose_k[:2]
                ):
                    self.graph.learned_changed()
            ok = reg.accepted and (
                cfg.revisit_gate == "registration" or (nis or 0.0) <= self._compat
            )
            self._log(reg, "revisit", j, k, nis)
            self.log.pairs[-1]["accepted"] = ok
            if not ok and reg.accepted:
                self.log.pairs[-1]["reason"] = "incompatible with the graph"
                self.loose_revisits.append(self._record(j, k, reg, "revisit"))
            if ok:
                self._add_between(j, k, reg, "revisit")
                added = True
        if added:
            self.graph.scan_update(self.config.extra_iterations)
            self._cov[k] = self._marginal(k)

    def metrics(self) -> dict[str, float | int]:
        out: dict[str, float | int] = dict(self.log.counts())
        nis = [p["nis"] for p in self.log.pairs if p["nis"] is not None and p["accepted"]]
        if nis:
            out["scan_revisit_nis_median"] = float(np.median(nis))
        # registrations the graph's gate rejects (``revisit_gate = "graph"``) or would reject
        out["scan_revisit_incompatible"] = sum(
            p["kind"] == "revisit" and p["nis"] is not None and p["nis"] > self._compat
            for p in self.log.pairs
        )
        return out
