"""The landmark layer shared by every back end: which lines become landmarks, which observation
goes to which landmark, where each landmark's wall ends, and its ``map.json`` record.

A back end keeps the estimates (the EKF in its state, the factor graph
as variables ``L(j)``); this layer keeps everything else about the landmarks, so that both back
ends manage them by the same rules:

* observations of lines nearer than ``min_rho_m`` are not used;
* each vote's observations are associated with the landmarks by the back end's joint belief
  (:mod:`sonarslam.slam.mapping.association`, JCBB or nearest neighbour), with pairings ruled out when the
  observed segment does not reach the landmark's extent (``extent_margin_m``) or when the sonar
  is on the other side of the landmark's line than when it was first seen (``side_gate``);
* an observation that pairs with no landmark is a *tentative* line; when ``tentative_observations``
  compatible observations (chi2 gate on the two views' world lines with the joint covariance of
  the two sonar poses, :meth:`LandmarkMap.tentative_distance`; same side) arrive within
  ``tentative_max_age_s`` it is promoted to a landmark;
* each landmark's extent along its line grows with the segments of its observations.

The vote itself is :meth:`LandmarkMap.vote`: the back end's :class:`sonarslam.slam.mapping.vote.Belief`
in, a :class:`sonarslam.slam.mapping.vote.Decision` out, which the back end applies; this layer calls
nothing of the back end.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import chi2

from sonarslam.features.geometry import (
    FLIP_RHO,
    FloatArray,
    along_line,
    compose,
    line_difference,
    line_frame_to_world,
    normalize_line_cov,
    segment_on_line,
    transform_points,
)
from sonarslam.features.line import LineFeature
from sonarslam.settings import bounded, check_fields
from sonarslam.slam.mapping.association import (
    AssociationConfig,
    AssociationProblem,
    associate,
    extent_allowed,
)
from sonarslam.slam.mapping.duplicates import duplicate_of
from sonarslam.slam.mapping.vote import (
    AfterVote,
    Anchored,
    Belief,
    Decision,
    LandmarkBelief,
    NewLandmark,
    ViewPair,
)
from sonarslam.slam.model.lines import sonar_side, world_observation

__all__ = [
    "LandmarkConfig",
    "Landmark",
    "Tentative",
    "Innovation",
    "JointInnovation",
    "LandmarkMap",
    "landmark_record",
]


@dataclass(frozen=True)
class LandmarkConfig:
    """Settings of the landmark layer (every back end's configuration extends this). Each
    field's range is in its metadata (:func:`sonarslam.settings.bounded`), checked by
    :func:`sonarslam.settings.check_fields` for this class and every subclass.

    Attributes
    ----------
    association : AssociationConfig
        Method and gate of the association.
    tentative_observations : int
        A new line becomes a landmark when seen this many times, each compatible with the
        first (chi2 gate of ``association.gate_probability`` on the two world lines,
        :meth:`LandmarkMap.tentative_distance`) ...
    tentative_max_age_s : float
        ... within this time (s); older tentative lines are dropped.
    min_rho_m : float
        Observations of lines closer than this to the sonar are not used (sign ambiguity,
        the sonar's near field).
    extent_margin_m : float or None
        A landmark is paired only with observations whose world segment reaches its extent
        within this margin (m), :func:`sonarslam.slam.mapping.association.extent_allowed`; None: no extent
        gate. It keeps a landmark from spanning the gap to a collinear wall further on.
    max_extent_m : float or None
        A landmark is paired only with observations that keep its extent (grown by their
        segment) at most this long (m), :func:`sonarslam.slam.mapping.association.extent_allowed`;
        a longer stretch of the wall becomes another landmark. A wall that is not quite straight
        over its length (or a heading error that depends on the place) makes one infinite line
        for all of it pull the poses seen from its far ends. None: no limit.
    side_gate : bool
        A landmark (or tentative line) is paired only with observations made from the side of
        its line it was first seen from (:func:`sonarslam.slam.model.lines.sonar_side`).
    line_cov_scale : float
        The extractor's line covariances are multiplied by this (1: taken as they are).
    merge_gate_probability : float or None
        Two landmarks seen from the same side whose extents overlap or lie within
        ``extent_margin_m`` are one wall when their lines are jointly compatible at this
        probability (chi2(2) on their difference with the joint covariance): the newer is merged
        into the older (:meth:`LandmarkMap.merge_duplicates`). None: never merged.
    tentative_joint_gate : bool
        The tentative gate uses the joint covariance of the two views' sonar poses (their
        cross-covariance, from the back end's :attr:`Belief.view_pairs`); False: each world line
        holds its own pose's covariance, as if the two poses' errors were independent (the
        common error of two views seconds apart then counts twice).
    reobservation_min_move_m : float or None
        An associated observation of a landmark is used only when the sonar has moved at least
        this far (m) since the landmark's last used observation: observations of one wall from
        nearly the same place share their systematic error (the echo band seen at the same
        incidence and range), which does not average down as independent errors would. None:
        every associated observation is used. The default's measurements are in
        docs/research/marina-accuracy.md.
    """

    association: AssociationConfig = field(default_factory=AssociationConfig)
    tentative_observations: int = bounded(2, 1, 1000)
    tentative_max_age_s: float = bounded(60.0, 1e-3, 1e5)
    min_rho_m: float = bounded(1.0, 0.0, 1e3)
    extent_margin_m: float | None = bounded(10.0, 0.0, 1e4)
    max_extent_m: float | None = bounded(None, 0.0, 1e5, low_open=True)
    side_gate: bool = True
    line_cov_scale: float = bounded(1.0, 1e-2, 1e2)
    merge_gate_probability: float | None = bounded(None, 0.0, 1.0, low_open=True, high_open=True)
    tentative_joint_gate: bool = False
    reobservation_min_move_m: float | None = bounded(5.0, 0.0, 1e4, high_open=True)

    def __post_init__(self) -> None:
        check_fields(self)  # every field's range, a subclass's too (its metadata)


@dataclass
class Landmark:
    """A line landmark: id, how many observations its estimate uses, extent, side.

    The extent ``[s_min_m, s_max_m]`` is along the line's direction ``(-sin theta, cos theta)``
    with ``theta = theta_ref_rad``, the direction when the landmark was created; an estimate in
    the other representation ``(-rho, theta + pi)`` reverses that axis (:meth:`extent_on`).
    ``side`` is the side of the line the sonar saw it from (+1: ``rho_w > n . p_sonar``).
    ``merged_into`` is the landmark it was found to be a duplicate of (None while active).
    """

    id: int
    n_obs: int
    s_min_m: float
    s_max_m: float
    theta_ref_rad: float
    side: float = 1.0
    merged_into: int | None = None
    last_used_xy_m: FloatArray | None = None

    @property
    def active(self) -> bool:
        return self.merged_into is None

    def _reversed(self, line_w: FloatArray) -> bool:
        return bool(np.cos(float(line_w[1]) - self.theta_ref_rad) < 0.0)

    def extent_on(self, line_w: FloatArray) -> tuple[float, float]:
        """The extent along ``line_w``'s own direction (m)."""
        if self._reversed(line_w):
            return -self.s_max_m, -self.s_min_m
        return self.s_min_m, self.s_max_m

    def ends_w(self, line_w: FloatArray) -> FloatArray:
        """The extent's two end points on ``line_w`` (world, m), shape (2, 2)."""
        return segment_on_line(line_w, *self.extent_on(line_w))

    def grow(self, line_w: FloatArray, points_w: FloatArray) -> None:
        """Extend the extent to the projections of world points on ``line_w``."""
        s = along_line(line_w, points_w)
        if self._reversed(line_w):
            s = -s
        self.s_min_m = min(self.s_min_m, float(s.min()))
        self.s_max_m = max(self.s_max_m, float(s.max()))


@dataclass(eq=False)
class Tentative:
    """A line seen but not yet a landmark.

    ``line_w`` and ``cov_w`` are the first view's world line and its covariance (with its own
    pose's); ``observations`` pairs each line with the back end's anchor of it (the factor
    graph's node and mounting; None for the EKF); ``ends_w`` stacks their world end points,
    shape (2n, 2); ``view`` is the back end's token of the first view's pose
    (:attr:`Belief.view`), None when it keeps none.
    """

    t: float
    line_w: FloatArray
    cov_w: FloatArray
    ends_w: FloatArray
    observations: list[Anchored]
    side: float = 1.0
    view: object | None = None


@dataclass(frozen=True, eq=False)
class Innovation:
    """A pairing's innovation: time (Unix s), landmark id, ``nu = z - z_hat`` (2,) sign-free,
    its predicted covariance ``S = H P H^T + R`` (2, 2) and the observation's ``R`` (2, 2) (with
    the line covariance scale in force, :attr:`LandmarkMap.line_cov_scale`, which is
    ``line_scale``); ``H_pose`` (2, 3), the prediction's Jacobian by the body pose ``(x_m, y_m,
    yaw_rad)``; ``wTb`` (3,), the vote's pose; ``used``, whether the observation updated the
    estimate (``reobservation_min_move_m``)."""

    t_s: float
    landmark: int
    nu: FloatArray
    S: FloatArray
    R: FloatArray
    H_pose: FloatArray | None = None
    wTb: FloatArray | None = None
    used: bool = True
    line_scale: float = 1.0


@dataclass(frozen=True, eq=False)
class JointInnovation:
    """The innovations of one vote's used pairings together: time (Unix s), their landmarks
    (m,), ``nu`` (2m,) stacked sign-free, their joint predicted covariance ``S`` (2m, 2m), whose
    off-diagonal blocks ``H_a P H_b^T`` hold the pose's (and shared states') error that every
    pairing of the vote sees, the observations' ``R`` (m, 2, 2) with ``line_scale`` in force,
    the Jacobians by the body pose ``H_pose`` (m, 2, 3) and the vote's pose ``wTb`` (3,)."""

    t_s: float
    landmarks: tuple[int, ...]
    nu: FloatArray
    S: FloatArray
    R: FloatArray
    H_pose: FloatArray
    wTb: FloatArray
    line_scale: float = 1.0


class LandmarkMap:
    """The landmarks of one back end and the rules that make and associate them (module doc).

    Parameters
    ----------
    config : LandmarkConfig
    bTs : ndarray, shape (3,)
        Sonar mounting.
    """

    def __init__(self, config: LandmarkConfig, bTs: FloatArray) -> None:
        self.config = config
        self.bTs = np.asarray(bTs, dtype=np.float64)
        self.landmarks: list[Landmark] = []
        self.tentative: list[Tentative] = []
        self._gate = float(chi2.ppf(config.association.gate_probability, 2))
        self.stats = {
            "observations": 0,
            "associated": 0,
            "new_landmarks": 0,
            "tentative_dropped": 0,
            "rejected_near": 0,
            "merged": 0,
            "reobservations_skipped": 0,
            "unpaired": 0,
            "seed_observations": 0,
            "tentative_dropped_observations": 0,
            "tentative_pending_observations": 0,
        }
        #: (t, observation index in its vote, landmark id or None) of every used observation
        self.association_log: list[tuple[float, int, int | None]] = []
        #: tentative observations of a line that became a landmark, with its id: they seeded it
        self.seed_log: list[tuple[LineFeature, int]] = []
        #: every pairing's innovation (:class:`Innovation`), for the NIS
        self.innovations: list[Innovation] = []
        #: each vote's used pairings' innovations together (:class:`JointInnovation`)
        self.joint_innovations: list[JointInnovation] = []
        # the last vote's segments (landmark id, sonar-frame end points (2, 2)) and landmarks,
        # until the estimate after its update settles them (:meth:`settle`)
        self._growth: list[tuple[int, FloatArray]] = []
        self._touched: list[int] = []
        self._decided_t: float | None = None  # the time of the last vote decided with lines
        #: the factor on every line covariance now: ``line_cov_scale`` times the learned
        #: ``line_scale`` (:mod:`sonarslam.slam.model.noise_learning`), set by the back end
        self.line_cov_scale = float(config.line_cov_scale)

    def __len__(self) -> int:
        return len(self.landmarks)

    def active(self) -> list[Landmark]:
        """The landmarks not merged into another one."""
        return [lm for lm in self.landmarks if lm.active]

    # -- gates -----------------------------------------------------------------------------

    def allowed(
        self,
        landmarks: list[Landmark],
        lines_w: FloatArray,
        wTb: FloatArray,
        observations: list[LineFeature],
    ) -> np.ndarray | None:
        """Pairings ``(observation, landmark)`` the extent and side gates allow, shape (m, k);
        None when neither gate is on.

        Parameters
        ----------
        landmarks : list of Landmark
            The candidates, with ``lines_w`` (k, 2) their current lines (as stored).
        wTb : ndarray, shape (3,)
            The pose of the vote.
        observations : list of LineFeature
        """
        cfg = self.config
        if cfg.extent_margin_m is None and cfg.max_extent_m is None and not cfg.side_gate:
            return None
        m, k = len(observations), len(landmarks)
        out = np.ones((m, k), dtype=bool)
        if k == 0:
            return out
        if cfg.extent_margin_m is not None or cfg.max_extent_m is not None:
            wTs = compose(wTb, self.bTs)
            extents = np.array(
                [lm.extent_on(line) for lm, line in zip(landmarks, lines_w, strict=True)]
            )
            segments = np.array([transform_points(wTs, f.endpoints_r) for f in observations])
            out &= extent_allowed(lines_w, extents, segments, cfg.extent_margin_m, cfg.max_extent_m)
        if cfg.side_gate:
            sides = np.array([lm.side for lm in landmarks])
            out &= (sonar_side(wTb, lines_w, self.bTs) == sides)[None, :]
        return out

    # -- one vote --------------------------------------------------------------------------

    def vote(self, belief: Belief) -> Decision:
        """Decide one vote of lines from the back end's belief before it uses them
        (:mod:`sonarslam.slam.mapping.vote`): settle the previous vote (:meth:`settle`), associate the
        observations with the candidates, pick those to use, keep or promote tentative lines.

        A new line is placed with the pose of the vote; the extents the associated segments add
        wait for the estimate after the update (the next belief's ``after_previous``).
        """
        cfg = self.config
        use = belief.features
        self.stats["rejected_near"] += belief.rejected_near
        if not use:
            return Decision([], [], [], [], [])
        if belief.after_previous is None and self._decided_t is not None:
            raise ValueError(
                f"Belief.after_previous is None, but the vote at t={self._decided_t:.3f} s was"
                " decided before this one: pass the estimate right after applying its decision"
                " (AfterVote); without it that vote's extents and duplicates are never settled"
            )
        self._decided_t = float(use[-1].t)
        merges = self.settle(belief.after_previous)
        self.stats["observations"] += len(use)
        live = [c for c, j in enumerate(belief.candidates) if self.landmarks[j].active]
        candidates = [self.landmarks[belief.candidates[c]] for c in live]
        pairing: list[int | None] = [None] * len(use)
        if candidates:
            lines_w = belief.landmarks.lines_w
            cand_lines = np.array([lines_w[lm.id] for lm in candidates])
            allowed = self.allowed(candidates, cand_lines, belief.wTb, use)
            z_hat, H = belief.z_hat[live], belief.H[live]
            problem = AssociationProblem(belief.z, belief.R, z_hat, H, belief.P, allowed)
            pairing = associate(problem, cfg.association)
        paired = [(candidates[j], use[i]) for i, j in enumerate(pairing) if j is not None]
        ids: list[int | None] = [None if j is None else candidates[j].id for j in pairing]
        self.stats["associated"] += len(paired)
        pairs = self._moved_enough(paired, belief.wTb)
        if candidates:
            used = {id(f) for _, f in pairs}
            self._log_innovations(problem, pairing, candidates, use, belief.wTb, used)
        for lm, _ in pairs:
            lm.n_obs += 1
        new: list[NewLandmark] = []
        for i, j in enumerate(pairing):
            if j is None:
                self.stats["unpaired"] += 1
                ids[i] = self._new_line(belief, use[i], new)
        # observations = associated + unpaired; unpaired = seed + dropped + pending observations
        self.stats["tentative_pending_observations"] = sum(
            len(c.observations) for c in self.tentative
        )
        # a skipped re-observation was still seen: it grows the extent
        self._growth = [(lm.id, f.endpoints_r) for lm, f in paired]
        self._touched = sorted({i for i in ids if i is not None})
        for i, f in enumerate(use):
            self.association_log.append((f.t, i, ids[i]))
        updates = [(lm.id, f) for lm, f in pairs]
        return Decision(ids, merges, updates, new, [lm.id for lm, _ in paired])

    def settle(self, after: AfterVote | None) -> list[tuple[int, int]]:
        """The previous vote's extents, grown along the lines right after its update and placed
        with the pose then; with ``merge_gate_probability``, its landmarks' duplicates merged
        (:meth:`merge_duplicates`). Returns the merges ``(keep, drop)``."""
        growth, touched = self._growth, self._touched
        self._growth, self._touched = [], []
        if after is None:
            return []
        wTs = compose(after.wTb, self.bTs)
        for j, ends_r in growth:
            self.landmarks[j].grow(after.landmarks.lines_w[j], transform_points(wTs, ends_r))
        if self.config.merge_gate_probability is None or not touched:
            return []
        return self.merge_duplicates(after.landmarks, touched)

    def _moved_enough(
        self, pairs: list[tuple[Landmark, LineFeature]], wTb: FloatArray
    ) -> list[tuple[Landmark, LineFeature]]:
        """The pairs to use: all, or (``reobservation_min_move_m``) those whose landmark was last
        used from at least that far; each kept pair's landmark remembers the sonar's place."""
        limit = self.config.reobservation_min_move_m
        if limit is None:
            return pairs
        xy = compose(wTb, self.bTs)[:2]
        kept = []
        for lm, f in pairs:
            if lm.last_used_xy_m is not None and np.hypot(*(xy - lm.last_used_xy_m)) < limit:
                self.stats["reobservations_skipped"] += 1
                continue
            lm.last_used_xy_m = xy.copy()
            kept.append((lm, f))
        return kept

    def _log_innovations(
        self,
        problem: AssociationProblem,
        pairing: list[int | None],
        candidates: list[Landmark],
        use: list[LineFeature],
        wTb: FloatArray,
        used: set[int],
    ) -> None:
        """The innovation of every pairing made, with its predicted covariance (before the
        update): their NIS is chi2(2) when the line covariances and the back end are honest.
        ``used``: the ``id`` of the observations that update the estimate."""
        scale = self.line_cov_scale / self.config.line_cov_scale
        rows: list[tuple[int, FloatArray, FloatArray, FloatArray]] = []  # used: (j, nu, R, H)
        for i, j in enumerate(pairing):
            if j is None:
                continue
            nu, flipped = line_difference(problem.z[i], problem.z_hat[j])
            R = FLIP_RHO @ problem.R[i] @ FLIP_RHO if flipped else problem.R[i]
            H = problem.H[j]
            S = H @ problem.P @ H.T + R
            if id(use[i]) in used:
                rows.append((j, nu, R, H))
            self.innovations.append(
                Innovation(
                    use[i].t,
                    candidates[j].id,
                    nu,
                    S,
                    R,
                    H[:, :3].copy(),
                    np.asarray(wTb, dtype=np.float64).copy(),
                    id(use[i]) in used,
                    scale,
                )
            )
        if rows:
            Hs = np.concatenate([h for _, _, _, h in rows])  # (2m, d)
            S_joint = Hs @ problem.P @ Hs.T
            for a, (_, _, R, _) in enumerate(rows):
                S_joint[2 * a : 2 * a + 2, 2 * a : 2 * a + 2] += R
            self.joint_innovations.append(
                JointInnovation(
                    use[0].t,
                    tuple(candidates[j].id for j, _, _, _ in rows),
                    np.concatenate([nu for _, nu, _, _ in rows]),
                    S_joint,
                    np.array([R for _, _, R, _ in rows]),
                    np.array([h[:, :3] for _, _, _, h in rows]),
                    np.asarray(wTb, dtype=np.float64).copy(),
                    scale,
                )
            )

    def nis(self) -> FloatArray:
        """NIS ``nu^T S^-1 nu`` of every pairing made so far, shape (K,)."""
        return np.array([v.nu @ np.linalg.solve(v.S, v.nu) for v in self.innovations])

    def _new_line(self, belief: Belief, f: LineFeature, new: list[NewLandmark]) -> int | None:
        """A tentative line, promoted to a landmark (appended to ``new``) when seen
        ``tentative_observations`` times."""
        cfg = self.config
        wTb = belief.wTb
        obs = world_observation(f, wTb, belief.P_pose, self.bTs, self.line_cov_scale)
        R = np.asarray(f.cov) * self.line_cov_scale
        kept = [c for c in self.tentative if f.t - c.t <= cfg.tentative_max_age_s]
        self.stats["tentative_dropped"] += len(self.tentative) - len(kept)
        self.stats["tentative_dropped_observations"] += sum(
            len(c.observations) for c in self.tentative if c not in kept
        )
        self.tentative = kept
        for cand in self.tentative:
            if cfg.side_gate and sonar_side(wTb, cand.line_w, self.bTs)[0] != cand.side:
                continue
            pair = None
            if cfg.tentative_joint_gate and belief.view_pairs is not None:
                pair = belief.view_pairs.get(cand.view)
            if pair is not None:
                R1 = cand.observations[0][1].cov * self.line_cov_scale
                d2 = self.tentative_distance(cand.observations[0][1].z, R1, f.z, R, pair)
            else:
                nu, _ = line_difference(obs.line_w, cand.line_w)
                d2 = float(nu @ np.linalg.solve(obs.cov_w + cand.cov_w, nu))
            if d2 <= self._gate:
                cand.observations.append((belief.anchor, f))
                cand.ends_w = np.vstack([cand.ends_w, obs.ends_w])
                if len(cand.observations) >= cfg.tentative_observations:
                    self.tentative.remove(cand)
                    return self._promote(belief, obs.line_w, cand, new)
                return None
        side = float(sonar_side(wTb, obs.line_w, self.bTs)[0])
        cand = Tentative(
            f.t, obs.line_w, obs.cov_w, obs.ends_w, [(belief.anchor, f)], side, belief.view
        )
        if cfg.tentative_observations <= 1:
            return self._promote(belief, obs.line_w, cand, new)
        self.tentative.append(cand)
        return None

    @staticmethod
    def tentative_distance(
        z1: FloatArray, R1: FloatArray, z2: FloatArray, R2: FloatArray, pair: ViewPair
    ) -> float:
        """Squared Mahalanobis distance of two views of a line, ``z1`` (covariance ``R1``, sonar
        frame) from the sonar at ``pair.wTs_then`` and ``z2`` (``R2``) from ``pair.wTs_now``,
        with the joint covariance of the two sonar poses: chi2(2) when both are of one line.

        Each view's world line is ``L_k = g(z_k, S_k)``
        (:func:`sonarslam.features.geometry.line_frame_to_world`, Jacobians ``G_zk`` and
        ``G_sk``), and their difference ``d = L_2 - L_1`` (``L_2`` in ``L_1``'s representation,
        :func:`sonarslam.features.geometry.line_difference`: ``F = FLIP_RHO`` on ``L_2``'s
        terms when flipped, else ``I``) is, to first order in the errors,
        ``d = F (G_z2 e_z2 + G_s2 e_s2) - G_z1 e_z1 - G_s1 e_s1``. The two extractions' errors
        are independent of each other and of the poses, so

        ``C_d = F G_z2 R2 G_z2^T F^T + G_z1 R1 G_z1^T + B Sigma B^T``,
        ``B = [F G_s2, -G_s1]``, ``Sigma = [[P_22, P_21], [P_12, P_11]]`` (``pair.cov``);

        the pose part is ``F G_s2 P_22 G_s2^T F^T + G_s1 P_11 G_s1^T - F G_s2 P_21 G_s1^T -
        G_s1 P_12 G_s2^T F^T``: the covariance of the difference of two estimates with a
        common error is the sum of their covariances *less* their cross-covariances (the
        difference of two correlated track estimates, Bar-Shalom 1981, "On the track-to-track
        correlation problem", IEEE TAC 26(2)).
        Two views seconds apart share most of their pose error (the heading error moves a
        world line's ``rho`` by that error times its distance from the world's origin, in both
        views alike): without ``P_12`` that error counts twice instead of cancelling, and the
        gate lets two parallel walls metres apart pass. ``P_12`` is the back end's: a filter's
        by a stochastic clone of the earlier pose (Roumeliotis & Burdick 2002; Mourikis,
        Roumeliotis & Burdick 2007, the SC-KF): ``Cov(s_t, x_then) = Phi P[s, x_then]`` with
        ``Phi`` the product of every prediction's ``F`` and every update's ``I - K H`` since,
        as the clone's error never changes; a smoother's from the joint marginal of the two
        pose nodes (the current estimates of both).

        Returns
        -------
        float
            ``d^T C_d^-1 d``.
        """
        L1, Gz1, Gs1 = line_frame_to_world(z1, pair.wTs_then)
        L2, Gz2, Gs2 = line_frame_to_world(z2, pair.wTs_now)
        d, flipped = line_difference(L2, L1)
        if flipped:
            Gz2, Gs2 = FLIP_RHO @ Gz2, FLIP_RHO @ Gs2
        B = np.hstack([Gs2, -Gs1])
        C = Gz2 @ R2 @ Gz2.T + Gz1 @ R1 @ Gz1.T + B @ pair.cov @ B.T
        return float(d @ np.linalg.solve(C, d))

    def _promote(
        self, belief: Belief, line_w: FloatArray, cand: Tentative, new: list[NewLandmark]
    ) -> int:
        """A landmark from a tentative line: its estimate is the newest observation's world line
        (the back end's estimate uses all its observations or the newest,
        :attr:`Belief.seeds_used`), its extent all of theirs."""
        wTb = belief.wTb
        s = along_line(line_w, cand.ends_w)
        side = float(sonar_side(wTb, line_w, self.bTs)[0])
        lm = Landmark(
            len(self.landmarks), 0, float(s.min()), float(s.max()), float(line_w[1]), side
        )
        lm.last_used_xy_m = compose(wTb, self.bTs)[:2].copy()
        self.landmarks.append(lm)
        lm.n_obs = len(cand.observations) if belief.seeds_used else 1
        new.append(NewLandmark(lm.id, line_w, cand.observations))
        self.seed_log.extend((f, lm.id) for _, f in cand.observations[:-1])
        self.stats["new_landmarks"] += 1
        self.stats["seed_observations"] += len(cand.observations)
        return lm.id

    # -- duplicates ------------------------------------------------------------------------

    def merge_duplicates(
        self, belief: LandmarkBelief, landmark_ids: list[int]
    ) -> list[tuple[int, int]]:
        """Merge each of these landmarks with another one of the same wall, if any
        (:func:`sonarslam.slam.mapping.duplicates.duplicate_of`): the newer into the older. Returns the
        merges ``(keep, drop)`` made, for the back end to apply."""
        assert self.config.merge_gate_probability is not None
        gate = float(chi2.ppf(self.config.merge_gate_probability, 2))
        merges = []
        for j in landmark_ids:
            if not self.landmarks[j].active:
                continue
            other = duplicate_of(self, belief, j, gate)
            if other is not None:
                keep, drop = sorted((self.landmarks[j], other), key=lambda lm: lm.id)
                self._merge(belief, keep, drop)
                merges.append((keep.id, drop.id))
        return merges

    def _merge(self, belief: LandmarkBelief, keep: Landmark, drop: Landmark) -> None:
        line_keep = belief.lines_w[keep.id]
        keep.grow(line_keep, drop.ends_w(belief.lines_w[drop.id]))
        keep.n_obs += drop.n_obs
        drop.merged_into = keep.id
        self.stats["merged"] += 1

    # -- results ---------------------------------------------------------------------------

    def records(
        self,
        estimates: dict[int, tuple[FloatArray, FloatArray]],
        after: AfterVote | None = None,
    ) -> list[dict[str, Any]]:
        """``map.json``'s landmarks from the back end's estimates of the active ones: id ->
        (line as stored (2,), its covariance (2, 2)), normalised here (:func:`landmark_record`);
        merged landmarks are counted in the one they were merged into. ``after``: the estimate
        after the last vote, which settles its extents first (:meth:`settle`; a duplicate
        found then is not merged: the back end would not apply it)."""
        if after is not None:
            self._touched = []  # the run is over: a duplicate found now would not be merged
            self.settle(after)
        out = []
        for lm in self.active():
            line_n, cov_n = normalize_line_cov(*estimates[lm.id])
            s_min, s_max = lm.extent_on(line_n)
            out.append(landmark_record(lm.id, line_n, cov_n, s_min, s_max, lm.n_obs))
        return out


def landmark_record(
    landmark_id: int,
    line_w: FloatArray,
    cov: FloatArray,
    s_min_m: float,
    s_max_m: float,
    observations: int,
) -> dict[str, Any]:
    """One landmark of ``map.json``: id, ``rho``/``theta`` (world), 2x2 ``cov``, world
    ``endpoints`` of its extent ``[s_min_m, s_max_m]`` along the line, observation count."""
    line = np.asarray(line_w, dtype=np.float64)
    return {
        "id": int(landmark_id),
        "rho": float(line[0]),
        "theta": float(line[1]),
        "cov": np.asarray(cov, dtype=np.float64).tolist(),
        "endpoints": segment_on_line(line, s_min_m, s_max_m).tolist(),
        "observations": int(observations),
    }
