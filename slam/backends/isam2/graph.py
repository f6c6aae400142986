"""Factor-graph SLAM with line landmarks on GTSAM iSAM2: the second back end.

The graph (factors in :mod:`sonarslam.slam.backends.isam2.factors`, records in
:mod:`sonarslam.slam.backends.isam2.graph_io`):

* ``X(k)``: body poses ``wTb`` (``Pose2``) at *nodes*: one at each vote that returns lines and
  one every ``node_period_s`` otherwise;
* odometry between consecutive nodes: the motion model integrated between them with its
  covariance (:class:`sonarslam.slam.backends.isam2.odometry.NodeOdometry`), as a ``BetweenFactorPose2``
  (or, with ``estimate_misalignment`` / ``estimate_gyro_scale`` / ``dvl_scale_sigma``, the same
  motion with its translation rotated by the DVL misalignment ``D(0)`` and scaled by the DVL's
  ``1 + K(0)``, and its heading change scaled by the gyro scale ``G(0)``);
* AHRS heading ``z = yaw + b`` on ``(X(k), B(0))``, ``B(0)`` the constant AHRS bias with a prior
  (as the EKF); with a bias random walk (``ahrs_bias_walk_deg_per_sqrt_s``) one bias ``B(k)``
  per node, tied to the previous node's by ``BetweenFactorVector`` with variance
  ``walk**2 dt``. The AHRS headings taken since the previous node are carried to the node by the
  gyro and averaged into one factor;
* a prior on the start position (``PoseTranslationPrior2D``), and the start heading as an AHRS
  heading factor on ``X(0)`` (the start yaw came from the AHRS, so it carries the bias);
* line observations on ``(X(k), L(j))``, ``L(j)`` a world line ``(rho, theta)``.

Nothing observes the AHRS bias or the start position beyond their priors (a test checks it);
with a random walk, line landmarks observe the bias's changes.

iSAM2 is updated in batches: the factors of every vote with lines go in one update (after the
association), and between votes the pending odometry and heading factors are added at most
every ``update_period_s``. Until then the current pose is the newest optimised node composed
with the odometry since it (:attr:`LineIsam2.pose`, :attr:`LineIsam2.pose_cov`).

Landmarks are managed by the shared landmark layer (:class:`sonarslam.slam.mapping.landmarks.LandmarkMap`);
here its association uses the iSAM2 joint marginal of the newest optimised node and of the
candidate landmarks only (those within a loose gate, :mod:`sonarslam.slam.backends.isam2.candidates`),
propagated to the current time by the odometry. A promoted line enters the graph with all its
observations.

The seam to the front end is :class:`sonarslam.slam.backends.isam2.pose_source.SmoothedPoseSource`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, C, D, G, K, L, R, X
from scipy.stats import chi2

from sonarslam.features.geometry import (
    FloatArray,
    compose,
    compose_jacobians,
    inverse,
    line_difference,
)
from sonarslam.features.line import LineFeature
from sonarslam.features.pose_source import PoseSource
from sonarslam.features.scans import Scan, ScanMatcher
from sonarslam.slam.backends.base import (
    AnchoredOdometry,
    VoteObservations,
    ids_of_features,
    vote_observations,
)
from sonarslam.slam.backends.isam2.candidates import joint_covariance, loose_distances
from sonarslam.slam.backends.isam2.config import GraphConfig
from sonarslam.slam.backends.isam2.gnc import gnc_tls
from sonarslam.slam.backends.isam2.graph_io import (
    FactorKind,
    FactorRecord,
    OdometryTerms,
    Robust,
    key_name,
    pose_of,
    save_graph,
    start_records,
)
from sonarslam.slam.backends.isam2.odometry import NodeOdometry, local_covariance
from sonarslam.slam.backends.isam2.offline import OfflineResult
from sonarslam.slam.backends.isam2.pose_source import NodeTable, SmoothedPoseSource
from sonarslam.slam.backends.isam2.redecided import RedecidedGraph, redecided_graph
from sonarslam.slam.backends.isam2.retest import LineRetest
from sonarslam.slam.backends.isam2.scans import ScanConstraints
from sonarslam.slam.backends.learned import LearnedNoise
from sonarslam.slam.io.states import HEADING_ERROR_FILE, write_heading_error
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.mapping.landmarks import Landmark, LandmarkMap
from sonarslam.slam.mapping.redecide import RedecideConfig
from sonarslam.slam.mapping.vote import (
    AfterVote,
    Belief,
    Decision,
    LandmarkBelief,
    NewLandmark,
    NodeAnchor,
    ViewPair,
)
from sonarslam.slam.model.lines import line_prediction, local_to_world, sonar_side
from sonarslam.slam.model.motion import MotionStep
from sonarslam.sonar.beam import Mounting

__all__ = ["GraphConfig", "LineIsam2", "LINE_EQUALITY_SIGMAS"]

#: The least walk of a bias (rad^2/s) or DVL scale (1/s) per node: a walk learned down to none
#: (its floor, 0) would tie the nodes' variables by variances of 1e-12 and make iSAM2's system
#: indeterminate ("near variable b282", drawn 6 told the marina's noise model). 0.005 deg/sqrt(s)
#: is 0.2 deg over half an hour; 1e-5/sqrt(s), 4e-4 of scale.
MIN_WALK_RAD2_PER_S = float(np.deg2rad(0.005) ** 2)
MIN_SCALE_WALK_PER_S = 1e-10

#: The noise of a ``LineEquality`` factor (rho m, theta rad): two landmarks found to be one wall
#: are the same line.
LINE_EQUALITY_SIGMAS = (1e-3, 1e-5)


class LineIsam2:
    """Line-landmark SLAM on iSAM2; see the module docstring.

    Parameters
    ----------
    t0_s : float
        Start time (Unix s).
    wTb0 : ndarray, shape (3,)
        Start pose (the start yaw is the AHRS's).
    P0 : ndarray, shape (3, 3)
        Its covariance; its position block is used (the start heading is an AHRS heading, with
        ``ahrs_white_sigma_deg`` and the bias).
    sonar_mounting : Mounting
        ``bTs`` of the sonar head.
    config : GraphConfig
    """

    def __init__(
        self,
        t0_s: float,
        wTb0: FloatArray,
        P0: FloatArray,
        sonar_mounting: Mounting,
        config: GraphConfig,
    ) -> None:
        self.config = config
        self.bTs = sonar_mounting.as_pose()
        self.t_s = float(t0_s)
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(config.relinearize_threshold)
        params.relinearizeSkip = config.relinearize_skip
        self.isam = gtsam.ISAM2(params)
        self.graph = gtsam.NonlinearFactorGraph()  # every factor, for batch LM and saving
        self._gnc_stats: dict[str, int] = {}
        self.records: list[FactorRecord] = []
        self.map = LandmarkMap(config, self.bTs)
        self.odometry = NodeOdometry(self.t_s, config.noise.gyro_sigma_rad_per_s, config.dvl_noise)
        self.nodes = NodeTable()
        self._pending = gtsam.NonlinearFactorGraph()
        self._pending_values = gtsam.Values()
        self._pending_nodes: list[tuple[int, float, FloatArray]] = []  # (k, t, chain at t)
        self._pending_records: list[FactorRecord] = []  # the pending factors' records
        #: recent line associations re-tested when a loop closes (``retest_window_s``)
        self.retest = (
            LineRetest(config.retest_window_s, config.association.gate_probability)
            if config.retest_window_s is not None
            else None
        )
        self._vote_pose = (np.zeros(3), np.eye(3))  # the vote's pose and covariance (world)
        self._vote_t_s = -np.inf  # the time of its lines
        self._own_stats = {"ahrs_updates": 0, "pose_nodes": 0, "isam_updates": 0, "factors": 0}
        self.timing_s = {"isam_update": 0.0, "marginals": 0.0, "association": 0.0}
        self.update_log: list[tuple[float, float, int]] = []  # (t, wall s, new factors)
        self.vote_wall_s: list[float] = []  # wall time of each update_lines (s)
        self._after: AfterVote | None = None  # the estimate after the last vote's update
        self._n_nodes = 0
        self._var_walk = np.deg2rad(config.noise.ahrs_bias_walk_deg_per_sqrt_s) ** 2  # rad^2/s
        #: the noise learned from the innovations (``learn_noise``), or the configured one
        self.noise = LearnedNoise.of(config)
        self.noise.advance(t0_s, np.asarray(wTb0))
        self.noise_changes = 0  # steps of the learner that changed a value
        # a bias per node when it walks (told or learned), a DVL scale per node when its walk
        # is learned
        self._walking_bias = self._var_walk > 0.0 or self.noise.learns("heading_walk")
        self._walking_scale = self.noise.learns("dvl_scale_walk")
        self._scaled = config.noise.dvl_scale_sigma > 0.0 or self._walking_scale
        self._bias_estimate = float(np.deg2rad(config.ahrs_bias_prior_deg))  # the newest node's
        self._last_node_t = -np.inf
        self._last_heading_t = -np.inf
        self._last_update_t = -np.inf
        self._vote_t0 = 0.0
        self._lm_est: list[FloatArray] = []  # landmark lines, refreshed after updates
        self._lm_cov: list[FloatArray] = []  # their marginals, cached for the loose gate
        self._new_landmarks: list[int] = []
        self._stale = False
        self._gate_candidates = float(chi2.ppf(config.candidate_gate_probability, 2))
        self._batch: gtsam.Values | None = None
        self._redecided: RedecidedGraph | None = None
        #: The estimate made after the run with hindsight, when the runner made it
        #: (:func:`sonarslam.slam.run.offline.offline_of_run`): its figures join :meth:`metrics`.
        self.offline: OfflineResult | None = None
        # the newest optimised node (the anchor of the current pose) and its marginal
        self._anchor_pose = np.zeros(3)
        self._anchor_xyyaw = (0.0, 0.0, 0.0)
        self._anchor_cov_rows: tuple[tuple[float, ...], ...] = ((0.0,) * 3,) * 3

        self.scans = ScanConstraints(self, config) if "scans" in config.constraint_kinds else None
        self._learned_in_force()
        records, values = start_records(np.asarray(wTb0), np.asarray(P0), config, self.bTs)
        for record in records:
            self._add_factor(record)
        self._pending_values = values
        self._register_node(0, self.t_s)
        self._update()

    # -- state access ----------------------------------------------------------------------

    @property
    def pose(self) -> FloatArray:
        """Current body pose: the newest optimised node composed with the odometry since it."""
        return self.odometry.carried(self._anchor_xyyaw)

    @property
    def pose_cov(self) -> FloatArray:
        """Its covariance in ``(x_m, y_m, yaw_rad)``: the node's iSAM2 marginal, propagated.

        ``J_a S J_a^T + J_b P J_b^T`` of :func:`sonarslam.features.geometry.compose_jacobians`, in floats
        (the driver asks for it at every record).
        """
        return self.odometry.carried_covariance(self._anchor_xyyaw[2], self._anchor_cov_rows)

    @property
    def stats(self) -> dict[str, int]:
        return {**self.map.stats, **self._own_stats}

    @property
    def n_nodes(self) -> int:
        return self._n_nodes

    def landmark_line(self, landmark_id: int) -> FloatArray:
        """Current estimate of a landmark's world line (not normalised), shape (2,)."""
        self.refresh()
        return self._lm_est[landmark_id].copy()

    def pose_source(self, odometry: AnchoredOdometry | None = None) -> PoseSource:
        """The smoothed trajectory as the front end's PoseSource (the driver's odometry is not
        needed: this back end chains the same motion steps itself)."""
        return SmoothedPoseSource(
            self.nodes, self.odometry.chain, self.refresh, lambda: self.pose_cov
        )

    # -- prediction (every record) ---------------------------------------------------------

    def predict(self, step: MotionStep) -> FloatArray:
        """Integrate one motion step; a node (and maybe an update) when one is due.

        Returns the relative motion ``bTb'`` of this step (the odometry the driver chains).
        """
        if step.dt_s <= 0.0:
            return np.zeros(3)
        if self.noise.see_step(step):  # the heading's own change: no learned walk, one bias
            self._walking_bias = self._var_walk > 0.0
        rel = self.odometry.step(step)
        self.t_s = step.t_s
        if self.t_s - self._last_node_t >= self.config.node_period_s:
            self._add_node()
            if self.t_s - self._last_update_t >= self.config.update_period_s:
                self._update()
        return rel

    def update_heading(self, t_s: float, yaw_body_rad: float) -> bool:
        """Take an AHRS heading ``z = yaw + b`` (at most every ``ahrs_period_s``).

        It goes into the heading factor of the next node
        (:class:`sonarslam.slam.backends.isam2.odometry.HeadingMean`).
        """
        if t_s - self._last_heading_t < self.config.ahrs_period_s:
            return False
        self._last_heading_t = t_s
        self.odometry.add_heading(float(yaw_body_rad))
        self._own_stats["ahrs_updates"] += 1
        return True

    # -- nodes and updates -----------------------------------------------------------------

    def _add_factor(self, record: FactorRecord) -> None:
        self._pending.add(record.to_gtsam())
        self.records.append(record)
        self._pending_records.append(record)

    @property
    def revised_ids(self) -> dict[int, int | None]:
        """Observations whose association a re-test revised (``retest_window_s``):
        ``id(feature)`` -> the landmark now (None: none), for the run's associations."""
        return {} if self.retest is None else self.retest.revised

    def _register_node(self, k: int, t_s: float) -> None:
        self._pending_nodes.append((k, t_s, self.odometry.chain.now))
        self._n_nodes = k + 1
        self._last_node_t = t_s
        self.odometry.start_node()
        self._own_stats["pose_nodes"] += 1

    def _bias_key(self, k: int) -> int:
        """The AHRS bias at node ``k``: ``B(k)`` with a random walk (told or learned), else the
        constant ``B(0)``."""
        return int(B(k)) if self._walking_bias else int(B(0))

    def _scale_key(self, k: int) -> int:
        """The DVL scale error over the odometry from node ``k``: ``K(k)`` when its walk is
        learned, else the constant ``K(0)``."""
        return int(K(k)) if self._walking_scale else int(K(0))

    def _learned_in_force(self) -> None:
        """The learned values into what they act on: the landmark layer's line covariance scale
        (the walks and the scan scale are read when their factors are made)."""
        self.map.line_cov_scale = self.config.line_cov_scale * self.noise.value("line_scale")

    def _add_node(self) -> int:
        """A node at the current time: its odometry factor, its AHRS heading factor and, with a
        bias random walk, its bias tied to the previous node's."""
        k = self._n_nodes
        rel = self.odometry.since_node
        cfg = self.config
        dt = self.t_s - self._last_node_t
        if self._walking_bias:
            var = max(self.noise.value("heading_walk"), MIN_WALK_RAD2_PER_S) * max(dt, 1e-3)
            self._add_factor(
                FactorRecord.of(FactorKind.BETWEEN_VECTOR, [B(k - 1), B(k)], [0.0], [[var]])
            )
            self._pending_values.insert(B(k), np.array([self._bias_estimate]))
        if self._walking_scale and k >= 2:
            var = max(self.noise.value("dvl_scale_walk"), MIN_SCALE_WALK_PER_S) * max(dt, 1e-3)
            self._add_factor(
                FactorRecord.of(FactorKind.BETWEEN_VECTOR, [K(k - 2), K(k - 1)], [0.0], [[var]])
            )
            self._pending_values.insert(K(k - 1), np.array([self.odometry.dvl_gain - 1.0]))
        if cfg.estimate_misalignment or cfg.estimate_gyro_scale or self._scaled:
            keys = [X(k - 1), X(k)]
            keys += [D(0)] if cfg.estimate_misalignment else []
            keys += [G(0)] if cfg.estimate_gyro_scale else []
            keys += [self._scale_key(k - 1)] if self._scaled else []
            terms = OdometryTerms(rel.yaw_raw, (rel.jx, rel.jy), self.odometry.node_scale)
            record = FactorRecord.of(
                FactorKind.DVL_GYRO_ODOMETRY, keys, rel.pose, local_covariance(rel), odometry=terms
            )
        else:
            record = FactorRecord.of(
                FactorKind.BETWEEN_POSE, [X(k - 1), X(k)], rel.pose, local_covariance(rel)
            )
        self._add_factor(record)
        n_headings = self.odometry.headings.n
        heading = self.odometry.heading_at_node()
        if heading is not None:
            z, var = heading
            var += np.deg2rad(cfg.noise.ahrs_white_sigma_deg) ** 2 / n_headings
            keys = [X(k), self._bias_key(k)]
            self._add_factor(FactorRecord.of(FactorKind.HEADING_BIAS, keys, [z], [[var]]))
        self._pending_values.insert(X(k), gtsam.Pose2(*self.pose))
        self._register_node(k, self.t_s)
        self.noise.advance(self.t_s, self.pose)
        return k

    def _update(self, extra_iterations: int = 0) -> None:
        """Pending factors into iSAM2; re-anchor the current pose at the newest node.

        The smoothed poses of the recent nodes and the landmarks are refreshed when next asked
        for (:meth:`refresh`).
        """
        t0 = time.perf_counter()
        result = self.isam.update(self._pending, self._pending_values)
        if self.retest is not None:
            self.retest.indexed(self._pending_records, list(result.getNewFactorsIndices()))
        self._pending_records = []
        for _ in range(extra_iterations):
            self.isam.update()
        wall = time.perf_counter() - t0
        self.timing_s["isam_update"] += wall
        self.update_log.append((self.t_s, wall, int(self._pending.size())))
        self._own_stats["isam_updates"] += 1 + extra_iterations
        self._own_stats["factors"] += self._pending.size()
        self.graph.push_back(self._pending)
        self._pending = gtsam.NonlinearFactorGraph()
        self._pending_values = gtsam.Values()
        self._batch = None
        for _k, t, odo in self._pending_nodes:
            self.nodes.add(t, odo)
        self._pending_nodes = []
        self._last_update_t = self.t_s
        if self.retest is not None:
            self._retest()
        # anchor: the newest node, now
        k = self._n_nodes - 1
        t1 = time.perf_counter()
        self._set_anchor(pose_of(self.isam.calculateEstimatePose2(X(k))))
        M = local_to_world(float(self._anchor_pose[2]))
        anchor_cov = M @ self.isam.marginalCovariance(X(k)) @ M.T
        self._anchor_cov_rows = tuple(tuple(float(v) for v in row) for row in anchor_cov)
        self.timing_s["marginals"] += time.perf_counter() - t1
        self.nodes.add_anchor(self._last_node_t, anchor_cov)
        delta = self.odometry.delta_rad
        if self.config.estimate_misalignment:
            delta = float(self.isam.calculateEstimateVector(D(0))[0])
        scale = self.odometry.scale
        if self.config.estimate_gyro_scale:
            scale = float(self.isam.calculateEstimateVector(G(0))[0])
        gain = 1.0
        if self._scaled:
            gain += float(self.isam.calculateEstimateVector(self._scale_key(max(k - 1, 0)))[0])
        self.odometry.re_anchor(delta, scale, gain)
        self._bias_estimate = float(self.isam.calculateEstimateVector(self._bias_key(k))[0])
        self._stale = True
        for j in self._new_landmarks:  # marginals for the loose gate
            self._lm_cov[j] = self.isam.marginalCovariance(L(j))
        self._new_landmarks = []

    def _retest(self) -> None:
        """The recent lines whose vote the estimate moved beyond re-tested, the factors that fail
        removed (:class:`sonarslam.slam.backends.isam2.retest.LineRetest`)."""
        assert self.retest is not None
        t0 = time.perf_counter()
        removed = self.retest.run(self.isam, self.t_s)
        if removed:
            indices = [int(item.index) for item in removed if item.index is not None]
            self.isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), indices)
            for i in indices:
                self.graph.remove(i)
            gone = {id(item.record) for item in removed}
            self.records = [r for r in self.records if id(r) not in gone]
        self.timing_s["retest"] = self.timing_s.get("retest", 0.0) + time.perf_counter() - t0

    def _set_anchor(self, pose: FloatArray) -> None:
        self._anchor_pose = pose
        self._anchor_xyyaw = (float(pose[0]), float(pose[1]), float(pose[2]))

    def _node_pose(self, k: int) -> FloatArray:
        p = (
            self._batch.atPose2(X(k))
            if self._batch is not None
            else self.isam.calculateEstimatePose2(X(k))
        )
        return np.array([p.x(), p.y(), p.theta()])

    def refresh(self, all_nodes: bool = False) -> None:
        """After an update: the smoothed poses of the recent nodes (all with ``all_nodes``) and
        the landmark lines."""
        if all_nodes:
            self.nodes.refresh(-np.inf, self._node_pose)
        if not self._stale:
            return
        if not all_nodes:
            self.nodes.refresh(self.t_s - self.config.pose_window_s, self._node_pose)
        for j in range(len(self._lm_est)):
            self._lm_est[j] = np.asarray(
                self._batch.atVector(L(j))
                if self._batch is not None
                else self.isam.calculateEstimateVector(L(j))
            )
        self._stale = False

    # -- one vote of lines -----------------------------------------------------------------

    def update_lines(self, features: list[LineFeature]) -> list[int | None]:
        """One vote of lines: this graph's belief (JCBB/NN on iSAM2 marginals) to the landmark
        layer, which decides the associations and new landmarks
        (:meth:`sonarslam.slam.mapping.landmarks.LandmarkMap.vote`); the decision applied here as factors
        and variables, then an update. The landmark id of each feature (None: not associated)."""
        wall0 = time.perf_counter()
        obs = vote_observations(features, self.config, self.map.line_cov_scale)
        belief = self._belief(obs)
        decision = self.map.vote(belief)
        if belief.anchor is not None:
            self._apply(decision, belief.anchor)
            if self.noise.on:
                self._learn([new.id for new in decision.new_landmarks])
        self.vote_wall_s.append(time.perf_counter() - wall0)
        return ids_of_features(features, obs.features, decision.ids)

    def _learn(self, new_landmarks: list[int]) -> None:
        """This vote's innovations into the noise learner; the learned values in force from now
        on (new factors take them; those in the graph keep theirs)."""
        self.noise.advance(self.t_s, self.pose)
        if self.noise.take_lines(self.map, new_landmarks):
            self.learned_changed()

    def learned_changed(self) -> None:
        """The learner changed a value: into force."""
        self.noise_changes += 1
        self._learned_in_force()

    def _belief(self, obs: VoteObservations) -> Belief:
        """The vote's node (:meth:`node_now`), the candidate landmarks
        (:func:`sonarslam.slam.backends.isam2.candidates.loose_distances`) and their joint marginal with
        the current pose."""
        anchor = None
        cands: list[int] = []
        if obs.features:
            self._vote_t0 = time.perf_counter()
            k, kTb = self.node_now()
            anchor = NodeAnchor(k, compose(kTb, self.bTs))
        pose_w, P_pose_w = self.pose, self.pose_cov
        self._vote_pose = (pose_w.copy(), np.asarray(P_pose_w).copy())
        self._vote_t_s = float(obs.features[0].t) if obs.features else self.t_s
        active = [lm for lm in self.map.landmarks if lm.merged_into is None]
        if obs.features:
            cands = self._candidates(obs.z, obs.R, pose_w, P_pose_w, active)
        P = self._joint_covariance(cands) if cands else np.zeros((3, 3))
        z_hat = np.zeros((len(cands), 2))
        H = np.zeros((len(cands), 2, P.shape[0]))
        for c, j in enumerate(cands):
            z_hat[c], H_pose, H_line = line_prediction(pose_w, self._lm_est[j], self.bTs)
            H[c, :, :3] = H_pose
            H[c, :, 3 + 2 * c : 5 + 2 * c] = H_line
        return Belief(
            features=obs.features,
            rejected_near=obs.rejected_near,
            z=obs.z,
            R=obs.R,
            wTb=pose_w,
            P_pose=P_pose_w,
            anchor=anchor,
            candidates=cands,
            z_hat=z_hat,
            H=H,
            P=P,
            landmarks=LandmarkBelief({lm.id: self._lm_est[lm.id] for lm in active}),
            seeds_used=True,
            after_previous=self._after,
            view=anchor if self.config.tentative_joint_gate else None,
            view_pairs=self._view_pairs() if obs.features else None,
        )

    def _view_pairs(self) -> dict[object, ViewPair]:
        """:meth:`_view_pair` of every earlier vote a tentative line waits on."""
        if not self.config.tentative_joint_gate:
            return {}
        views = {c.view for c in self.map.tentative if c.view is not None}
        pairs = {v: self._view_pair(v) for v in views}
        return {v: p for v, p in pairs.items() if p is not None}

    def _view_pair(self, view: object) -> ViewPair | None:
        """The sonar's pose now and at an earlier vote anchored at ``view`` (its node smoothed
        now), with their joint covariance: iSAM2's joint marginal of the anchor (the newest
        optimised node) and the view's node, both mapped from the local tangent to the world
        (:func:`sonarslam.slam.model.lines.local_to_world`), the anchor composed with the
        odometry since it (:func:`sonarslam.slam.backends.isam2.candidates.joint_covariance`),
        and each pose composed with its sonar mounting. None when the view's node is not
        optimised yet."""
        if not isinstance(view, NodeAnchor):
            return None
        k_a = self._n_nodes - 1 - len(self._pending_nodes)
        k1 = view.node
        if k1 > k_a:
            return None
        t0 = time.perf_counter()
        if k1 == k_a:
            M = np.asarray(self.isam.marginalCovariance(X(k_a)))
            J_local = np.block([[M, M], [M, M]])
        else:
            joint = self.isam.jointMarginalCovariance([X(k_a), X(k1)])
            keys = [X(k_a), X(k1)]
            J_local = np.block([[np.asarray(joint.at(a, b)) for b in keys] for a in keys])
        self.timing_s["marginals"] += time.perf_counter() - t0
        pose_then = np.asarray(pose_of(self.isam.calculateEstimatePose2(X(k1))), dtype=np.float64)
        A = np.eye(6)
        A[3:, 3:] = local_to_world(float(pose_then[2]))
        cov_b = joint_covariance(A @ J_local @ A.T, self._anchor_pose, self.odometry.since_anchor)
        wTb_now = self.pose
        J = np.zeros((6, 6))
        J[:3, :3] = compose_jacobians(wTb_now, self.bTs)[0]
        J[3:, 3:] = compose_jacobians(pose_then, view.bTs)[0]
        return ViewPair(compose(wTb_now, self.bTs), compose(pose_then, view.bTs), J @ cov_b @ J.T)

    def _apply(self, decision: Decision, anchor: NodeAnchor) -> None:
        """The landmark layer's decision: a ``LineEquality`` factor per merge, a factor per
        used observation, the new landmarks with a factor per observation, an update; then the
        estimate after it for the layer (the next belief's ``after_previous``)."""
        for keep, drop in decision.merges:
            self._merge_landmarks(keep, drop)
        for j, f in decision.updates:
            self._add_line_factor(anchor, f, j)
        for new in decision.new_landmarks:
            self._add_landmark(new)
        self.timing_s["association"] += time.perf_counter() - self._vote_t0
        self._update(self.config.extra_iterations if decision.updates else 0)
        merging = self.config.merge_gate_probability is not None
        if decision.seen or (merging and any(j is not None for j in decision.ids)):
            # the recent nodes' smoothed poses now, not at the pose source's next question:
            # the beams' poses (and the trajectory) depend on when they are refreshed
            self.refresh()
        self._after = AfterVote(self.pose, self._landmark_belief(decision.seen))

    def _landmark_belief(self, seen: list[int]) -> LandmarkBelief:
        """The lines of ``seen``; of every active landmark, with their joint marginal, when the
        landmark layer merges duplicates."""
        if self.config.merge_gate_probability is None:
            return LandmarkBelief({j: self._lm_est[j] for j in seen})
        ids = [lm.id for lm in self.map.landmarks if lm.merged_into is None]
        cov = self.landmark_covariance(ids) if ids else None
        return LandmarkBelief({j: self._lm_est[j] for j in ids}, ids, cov)

    def node_now(self) -> tuple[int, FloatArray]:
        """A node now, or the newest if it is less than ``min_node_gap_s`` old; and the body
        pose now in that node's frame (the odometry since it, or zero)."""
        self.refresh()
        if self.t_s - self._last_node_t < self.config.min_node_gap_s:
            return self._n_nodes - 1, self.odometry.since_node.pose.copy()
        return self._add_node(), np.zeros(3)

    # -- scan constraints (slam.backends.isam2.scans) --------------------------------------

    def update_scan(self, scan: Scan, matcher: ScanMatcher) -> None:
        """A new scan of the scan matcher: its node and constraints
        (:meth:`sonarslam.slam.backends.isam2.scans.ScanConstraints.add_scan`)."""
        if self.scans is None:
            raise ValueError("scans are not among this graph's constraints")
        t0 = time.perf_counter()
        self.scans.add_scan(scan, matcher)
        self.timing_s["scans"] = self.timing_s.get("scans", 0.0) + time.perf_counter() - t0

    def node_estimate(self, k: int) -> FloatArray:
        return self._node_pose(k)

    def add_scan_factor(self, record: FactorRecord) -> None:
        self._add_factor(record)

    def scan_update(self, extra_iterations: int = 0) -> None:
        self._update(extra_iterations)

    def _candidates(
        self,
        z: FloatArray,
        R: FloatArray,
        pose_w: FloatArray,
        P_pose_w: FloatArray,
        landmarks: list[Landmark],
    ) -> list[int]:
        """Ids of the ``landmarks`` individually compatible with some observation under the
        loose gate, on the side of their line they were seen from, nearest first, at most
        ``max_candidates``."""
        if not landmarks:
            return []
        lines = np.array([self._lm_est[lm.id] for lm in landmarks])
        covs = np.array([self._lm_cov[lm.id] for lm in landmarks])
        best = loose_distances(z, R, pose_w, P_pose_w, lines, covs, self.bTs)
        if self.config.side_gate:
            sides = np.array([lm.side for lm in landmarks])
            best = np.where(sonar_side(pose_w, lines, self.bTs) == sides, best, np.inf)
        order = [int(j) for j in np.argsort(best) if best[j] <= self._gate_candidates]
        return [landmarks[j].id for j in order[: self.config.max_candidates]]

    def _joint_covariance(self, cands: list[int]) -> FloatArray:
        """Joint covariance of ``[current pose (x, y, yaw), candidate lines]``
        (:func:`sonarslam.slam.backends.isam2.candidates.joint_covariance`); caches the lines' blocks."""
        t0 = time.perf_counter()
        k_anchor = self._n_nodes - 1 - len(self._pending_nodes)
        keys = [X(k_anchor)] + [L(j) for j in cands]
        J = self.isam.jointMarginalCovariance(keys).fullMatrix()
        self.timing_s["marginals"] += time.perf_counter() - t0
        for c, j in enumerate(cands):
            self._lm_cov[j] = J[3 + 2 * c : 5 + 2 * c, 3 + 2 * c : 5 + 2 * c].copy()
        return joint_covariance(J, self._anchor_pose, self.odometry.since_anchor)

    def calibration_keys(self) -> list[int]:
        """The keys of the sonar's calibration variables: ``C(0)`` (mounting) and ``R(0)``
        (range scale) when estimated."""
        cfg = self.config
        return [int(C(0))] * cfg.estimate_sonar_mount + [int(R(0))] * (cfg.range_scale_sigma > 0)

    def _add_line_factor(self, node: NodeAnchor, f: LineFeature, lm_id: int) -> None:
        k, bTs = node.node, node.bTs
        cfg = self.config
        robust = None if cfg.robust is None else Robust(cfg.robust, cfg.robust_k)
        if cfg.calibrated:
            record = FactorRecord.of(
                FactorKind.LINE_OBSERVATION_CALIBRATED,
                [X(k), L(lm_id), *self.calibration_keys()],
                f.z,
                np.asarray(f.cov) * self.map.line_cov_scale,
                bTs=self.bTs.copy(),
                kTb=compose(np.asarray(bTs, dtype=np.float64), inverse(self.bTs)),
                robust=robust,
            )
        else:
            record = FactorRecord.of(
                FactorKind.LINE_OBSERVATION,
                [X(k), L(lm_id)],
                f.z,
                np.asarray(f.cov) * self.map.line_cov_scale,
                bTs=np.asarray(bTs, dtype=np.float64),
                robust=robust,
            )
        self._add_factor(record)
        if self.retest is not None and f.t >= self._vote_t_s:  # this vote's, not a seed's
            kTb = compose(np.asarray(bTs, dtype=np.float64), inverse(self.bTs))
            self.retest.added(record, k, lm_id, f, kTb, *self._vote_pose)

    def _add_landmark(self, new: NewLandmark) -> None:
        """``L(id)`` at the newest observation's world line, with a factor per observation."""
        j = new.id
        assert j == len(self._lm_est), "landmarks are added in id order"
        self._pending_values.insert(L(j), np.asarray(new.line_w, dtype=np.float64))
        for node, f in new.observations:
            assert node is not None, "the graph anchors every observation at a node"
            self._add_line_factor(node, f, j)
        self._lm_est.append(np.asarray(new.line_w, dtype=np.float64).copy())
        self._lm_cov.append(np.eye(2) * 1e6)
        self._new_landmarks.append(j)

    def landmark_covariance(self, landmark_ids: list[int]) -> FloatArray:
        """iSAM2's joint marginal of these landmarks' lines, shape (2k, 2k)."""
        keys = [L(j) for j in landmark_ids]
        return np.asarray(self.isam.jointMarginalCovariance(keys).fullMatrix())

    def _merge_landmarks(self, keep: int, drop: int) -> None:
        """A stiff ``LineEquality`` factor ties ``L(drop)`` to ``L(keep)`` (next update);
        ``drop`` takes no more observations."""
        _, flipped = line_difference(self._lm_est[drop], self._lm_est[keep])
        record = FactorRecord.of(
            FactorKind.LINE_EQUALITY,
            [L(keep), L(drop)],
            [float(flipped)],
            np.diag(np.square(LINE_EQUALITY_SIGMAS)),
        )
        self._add_factor(record)

    # -- results ---------------------------------------------------------------------------

    def finish(self) -> None:
        """Put every pending factor into iSAM2 (with a node now unless one is just behind)."""
        if self._pending_nodes or self._pending.size():
            if self.t_s - self._last_node_t >= self.config.min_node_gap_s:
                self._add_node()
            self._update()

    def estimate(self) -> gtsam.Values:
        """Current values: the batch optimum after :meth:`optimize_batch`, else iSAM2's."""
        self.finish()
        return self._batch if self._batch is not None else self.isam.calculateEstimate()

    def optimize_batch(self, params: gtsam.LevenbergMarquardtParams | None = None) -> gtsam.Values:
        """A final batch Levenberg-Marquardt on the whole graph from the iSAM2 estimate.

        ``params`` default: GTSAM's, at most 20 iterations.

        The result replaces iSAM2's in :meth:`estimate`, :meth:`smoothed_trajectory`,
        :attr:`pose` and the pose source until the next update (:attr:`pose_cov` stays
        iSAM2's).
        """
        self.finish()
        if params is None:
            params = gtsam.LevenbergMarquardtParams()
            params.setMaxIterations(20)  # from the iSAM2 estimate it is a polish
        if self.config.batch_optimizer == "gnc":
            values = self._optimize_gnc(params)
        else:
            values = gtsam.LevenbergMarquardtOptimizer(
                self.graph, self.isam.calculateEstimate(), params
            ).optimize()
        self._batch = values
        self._stale = True
        self.refresh(all_nodes=True)
        self._set_anchor(pose_of(values.atPose2(X(self._n_nodes - 1))))
        return values

    def _optimize_gnc(self, params: gtsam.LevenbergMarquardtParams) -> gtsam.Values:
        """The revisits chosen jointly by graduated non-convexity with the truncated least
        squares loss (:func:`sonarslam.slam.backends.isam2.gnc.gnc_tls`): every revisit the
        registration accepted, those the compatibility gate kept and those it did not
        (:attr:`ScanConstraints.loose_revisits`); every other factor a known inlier; the
        truncation chi2(3) at ``scan_compatibility_probability`` (the online gate's).
        ``gnc_revisits_*`` in :meth:`metrics`."""
        loose = self.scans.loose_revisits if self.scans is not None else []
        known = gtsam.NonlinearFactorGraph()
        revisits: list[FactorRecord] = []
        for record in [*self.records, *loose]:
            if record.constraint == "scan-revisit":
                revisits.append(record)
            else:
                known.add(record.to_gtsam())
        c2 = float(chi2.ppf(self.config.scan_compatibility_probability, 3))
        found = gnc_tls(known, revisits, self.isam.calculateEstimate(), c2, params)
        weights = found.weights
        n_loose = len(loose)
        self._gnc_stats = {
            "gnc_revisits_candidates": len(revisits),
            "gnc_revisits_inliers": int(np.sum(weights > 0.5)),
            "gnc_revisits_loose_inliers": int(np.sum(weights[len(weights) - n_loose :] > 0.5))
            if n_loose
            else 0,
            "gnc_steps": found.steps,
        }
        return found.values

    def _marginals(self) -> Callable[[int], FloatArray]:
        """Marginal covariance by key: iSAM2's, or ``gtsam.Marginals`` at the batch optimum."""
        if self._batch is None:
            return self.isam.marginalCovariance
        return gtsam.Marginals(self.graph, self._batch).marginalCovariance

    def smoothed_trajectory(self, covariances: bool = False) -> Trajectory:
        """The smoothed poses of all nodes, with their marginal covariances if asked.

        Covariances are iSAM2's marginals (or, after :meth:`optimize_batch`, those of
        ``gtsam.Marginals`` at the batch optimum), in ``(x_m, y_m, yaw_rad)``.
        """
        self.finish()
        self.refresh(all_nodes=True)
        poses = self.nodes.poses.copy()
        covs = None
        if covariances:
            marginal = self._marginals()
            covs = np.empty((poses.shape[0], 3, 3))
            for k in range(poses.shape[0]):
                M = local_to_world(float(poses[k, 2]))
                covs[k] = M @ marginal(X(k)) @ M.T
        return Trajectory(self.nodes.t_s.copy(), poses, covs)

    def map_records(self) -> list[dict[str, object]]:
        """Per landmark: id, rho, theta, cov, world endpoints, observation count."""
        self.refresh()
        marginal = self._marginals()
        return self.map.records(
            {lm.id: (self._lm_est[lm.id], marginal(L(lm.id))) for lm in self.map.active()},
            self._after,
        )

    def redecide_lines(self) -> RedecidedGraph:
        """The graph with its line observations re-decided at iSAM2's smoothed estimate, in
        stretches of at most ``redecide_stretch_m`` (when it is None,
        :class:`sonarslam.slam.mapping.redecide.RedecideConfig`'s default), re-optimised
        (:func:`sonarslam.slam.backends.isam2.redecided.redecided_graph`,
        ``redecide_passes`` passes). The graph and its estimates are left as they are."""
        self.finish()
        cfg = self.config
        config = RedecideConfig(association=cfg.association)
        if cfg.redecide_stretch_m is not None:
            config = replace(config, max_stretch_m=cfg.redecide_stretch_m)
        values = self.isam.calculateEstimate()
        self._redecided = redecided_graph(self.records, values, config, cfg.redecide_passes)
        return self._redecided

    def redecided_trajectory(self) -> Trajectory:
        """The nodes' poses after :meth:`redecide_lines` (run now if it has not been)."""
        found = self._redecided if self._redecided is not None else self.redecide_lines()
        poses = np.array([pose_of(found.values.atPose2(X(k))) for k in range(self._n_nodes)])
        return Trajectory(self.nodes.t_s[: self._n_nodes].copy(), poses)

    def trajectories(self, batch: bool = False) -> dict[str, Trajectory]:
        """The smoothed trajectory (``"smoothed"``), with ``batch`` the one after a final
        batch Levenberg-Marquardt (``"batch"``), and with ``redecide_stretch_m`` set the one
        with the lines re-decided (``"redecided"``, :meth:`redecide_lines`)."""
        out = {"smoothed": self.smoothed_trajectory()}
        if batch:
            self.optimize_batch()
            out["batch"] = self.smoothed_trajectory()
        if self.config.redecide_stretch_m is not None:
            out["redecided"] = self.redecided_trajectory()
        return out

    def metrics(self) -> dict[str, float | int]:
        """iSAM2's time per part (``isam2_*_s``) and per update (p50, p99 in ms)."""
        out: dict[str, float | int] = {f"isam2_{k}_s": float(v) for k, v in self.timing_s.items()}
        if self.scans is not None:
            out.update(self.scans.metrics())
        out.update(self._gnc_stats)
        if self.retest is not None:
            out.update(self.retest.stats)
        if self._redecided is not None:
            out.update(self._redecided.metrics())
        if self.offline is not None:
            out.update(self.offline.metrics())
        update_ms = 1e3 * np.array([wall for _, wall, _ in self.update_log])
        if update_ms.size:
            out["isam2_updates"] = int(update_ms.size)
            out["isam2_update_p50_ms"] = float(np.percentile(update_ms, 50))
            out["isam2_update_p99_ms"] = float(np.percentile(update_ms, 99))
        return out | self._state_metrics() | self.noise.metrics()

    def _state_metrics(self) -> dict[str, float | int]:
        """The final estimates of the vehicle's constants with their sd (``state_*``, as the
        EKF's): the newest node's AHRS bias (deg), the DVL misalignment (deg) and scale ``k``."""
        marginal = self._marginals()
        values = self.estimate()
        out: dict[str, float | int] = {}
        terms = [("ahrs_bias", self._bias_key(self._n_nodes - 1), True)]
        if self.config.estimate_misalignment:
            terms.append(("misalignment", int(D(0)), True))
        if self._scaled:
            terms.append(("dvl_scale", self._scale_key(max(self._n_nodes - 2, 0)), False))
        for name, key, degrees in terms:
            v, sd = float(values.atVector(key)[0]), float(np.sqrt(marginal(key)[0, 0]))
            unit = "_deg" if degrees else ""
            scale = float(np.rad2deg(1.0)) if degrees else 1.0
            out[f"state_{name}{unit}"] = scale * v
            out[f"state_{name}_sd{unit}"] = scale * sd
        if self.config.estimate_sonar_mount:
            c = np.asarray(values.atVector(C(0)))
            sd_c = np.sqrt(np.diag(marginal(C(0))))
            for i, (name, f) in enumerate((("x_m", 1.0), ("y_m", 1.0), ("yaw_deg", 180 / np.pi))):
                base, unit = name.rsplit("_", 1)
                out[f"state_sonar_{base}_{unit}"] = f * float(c[i])
                out[f"state_sonar_{base}_sd_{unit}"] = f * float(sd_c[i])
        if self.config.range_scale_sigma > 0.0:
            out["state_sonar_range_scale"] = float(values.atVector(R(0))[0])
            out["state_sonar_range_scale_sd"] = float(np.sqrt(marginal(R(0))[0, 0]))
        if self.config.estimate_sonar_mount and self.config.estimate_misalignment:
            out["state_sonar_yaw_misalignment_corr"] = self._yaw_misalignment_correlation(values)
        return out

    def _yaw_misalignment_correlation(self, values: gtsam.Values) -> float:
        """The correlation of the sonar mounting's yaw with the DVL misalignment in their joint
        marginal (the whole graph's, at ``values``): a rotation of both by one angle turns the
        track and the map together and leaves the AHRS headings alone, so the data see their
        difference and only the priors their sum (docs/research/calibration.md, "The sonar/DVL
        direction")."""
        keys = gtsam.KeyVector([C(0), D(0)])
        joint = gtsam.Marginals(self.graph, values).jointMarginalCovariance(keys)
        var_yaw = float(np.asarray(joint.at(C(0), C(0)))[2, 2])
        var_d = float(np.asarray(joint.at(D(0), D(0)))[0, 0])
        cross = float(np.asarray(joint.at(C(0), D(0)))[2, 0])
        return cross / float(np.sqrt(var_yaw * var_d))

    def heading_error_track(self) -> tuple[FloatArray, FloatArray, FloatArray] | None:
        """The AHRS heading error ``b`` at every node with its marginal sd, when it walks
        (``ahrs_bias_walk_deg_per_sqrt_s > 0`` or learned: one ``B(k)`` per node); None for a
        constant bias.

        Returns
        -------
        t_s, b_rad, sd_rad : ndarray, shape (N,)
            Node times (Unix s), the estimate and its sd (rad).
        """
        if not self._walking_bias:
            return None
        marginal = self._marginals()
        values = self.estimate()
        n = self._n_nodes
        b = np.array([float(values.atVector(B(k))[0]) for k in range(n)])
        sd = np.sqrt([float(marginal(B(k))[0, 0]) for k in range(n)])
        return self.nodes.t_s[:n].copy(), b, sd

    def save(self, out_dir: Path) -> list[Path]:
        """``graph.json`` (:func:`sonarslam.slam.backends.isam2.graph_io.save_graph`) and, when the
        AHRS heading error walks, its smoothed track ``heading_error.csv``
        (:mod:`sonarslam.slam.io.states`)."""
        path = Path(out_dir) / "graph.json"
        values = self.estimate()
        meta = {
            "node_times_s": {key_name(X(k)): float(t) for k, t in enumerate(self.nodes.t_s)},
            "bTs": self.bTs.tolist(),
            "config": {k: v for k, v in asdict(self.config).items() if k != "association"},
        }
        save_graph(path, self.records, values, meta)
        out = [path, *self.noise.save(Path(out_dir))]
        track = self.heading_error_track()
        if track is not None:
            out.append(write_heading_error(Path(out_dir) / HEADING_ERROR_FILE, *track))
        return out
