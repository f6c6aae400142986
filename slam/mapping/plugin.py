"""The landmark layer for a SLAM of your own: line observations in, association decisions out.

Your estimator (a filterpy EKF, a GTSAM graph, anything) keeps the estimates: the body pose
``wTb`` and one world line ``(rho_m, theta_rad)`` per landmark. :class:`LandmarkAssociation`
keeps everything else (which lines became landmarks, their extents, the tentative lines) by the
rules every back end here uses (:mod:`sonarslam.slam.mapping.landmarks`). For each vote of
lines of the extractor:

1. describe your estimate at the vote as a :class:`WorldBelief` (your EKF's mean and covariance,
   or :func:`gtsam_belief` of your ``ISAM2`` / ``Values`` and marginals);
2. :meth:`LandmarkAssociation.decide` returns a :class:`sonarslam.slam.mapping.vote.Decision`:
   the merges, then which observation updates which landmark, then the new landmarks
   (ids ``0, 1, 2, ...`` in order of creation, each with its world line and observations);
3. apply it to your estimate, in that order;
4. :meth:`LandmarkAssociation.applied` with your estimate right after: the extents of the
   landmarks grow along the updated lines, and duplicates are found on them.

Step 4 cannot be skipped: :meth:`~LandmarkAssociation.decide` refuses to decide a vote before
the previous decision was reported applied, and a belief whose landmarks are not those the
association made (a new landmark left out) is refused, naming the parameter. Nor can the
landmarks be in another order than the association's ids: :func:`gtsam_belief` reads landmark
``j`` at ``line_key(j)`` (``L``), and :meth:`~LandmarkAssociation.decide` and
:meth:`~LandmarkAssociation.applied` refuse a belief whose line ``j`` moved, since the last
decision, beyond any update a consistent estimator can make (:data:`MOVE_TAIL_PROBABILITY`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray, line_difference
from sonarslam.features.line import LineFeature, check_mounting
from sonarslam.slam.mapping.landmarks import LandmarkConfig, LandmarkMap
from sonarslam.slam.mapping.vote import AfterVote, Belief, Decision, LandmarkBelief, NodeAnchor
from sonarslam.slam.model.lines import (
    check_mounting_pose,
    check_pose_radians,
    line_predictions,
    local_to_world_covariance,
    usable_observations,
    world_observation,
)

__all__ = ["WorldBelief", "LandmarkAssociation", "gtsam_belief", "MOVE_TAIL_PROBABILITY"]

#: How improbable a landmark line's move must be to be refused as not the same landmark (a
#: belief's lines in another order than the association's ids). Between two estimates of a
#: consistent Gaussian estimator, landmark ``j``'s mean moves by ``d ~ N(0, P_then - P_now)``,
#: whatever was added in between (this vote's observations, a loop closure), so
#: ``d^T P_then^-1 d`` is stochastically at most chi-square with 2 degrees of freedom, whose
#: tail beyond ``q`` is ``exp(-q / 2)``: the gate is ``q = -2 ln p`` (55.3 for 1e-12, 7.4
#: sigma), a consistent estimator's line refused once in 1e12 tests. ``P_then`` is the
#: landmark's marginal at the previous :meth:`LandmarkAssociation.decide` (a new landmark's:
#: its newest observation's world covariance, ``world_observation``).
MOVE_TAIL_PROBABILITY = 1e-12


@dataclass(frozen=True, eq=False)
class WorldBelief:
    """Your estimate at one instant, in world coordinates (local East-North, yaw CCW from East).

    Attributes
    ----------
    wTb : ndarray, shape (3,)
        Body pose ``(x_m, y_m, yaw_rad)``; a yaw beyond ``2 pi`` in magnitude is refused
        (degrees given for radians).
    lines_w : ndarray, shape (k, 2)
        World line ``(rho_m, theta_rad)`` of every landmark the association made, row ``j``
        landmark ``j`` (merged ones too: their rows are not read); need not be normalised, but
        a theta beyond ``2 pi`` in magnitude is refused.
    cov : ndarray, shape (3 + 2k, 3 + 2k), optional
        Joint covariance of ``[x_m, y_m, yaw_rad, rho_0, theta_0, ..., rho_k-1, theta_k-1]``
        (m, rad), with the pose in world coordinates (a GTSAM ``Pose2`` marginal is in the
        body frame: :func:`sonarslam.slam.model.lines.local_to_world_covariance`). Needed by
        :meth:`LandmarkAssociation.decide`; by :meth:`LandmarkAssociation.applied` only when
        duplicates are merged (``merge_gate_probability``).
    """

    wTb: FloatArray
    lines_w: FloatArray
    cov: FloatArray | None = None

    def __post_init__(self) -> None:
        wTb = check_pose_radians(self.wTb, "WorldBelief.wTb", "degrees? or wrap an unwrapped yaw")
        lines = np.asarray(self.lines_w, dtype=np.float64).reshape(-1, 2)
        object.__setattr__(self, "wTb", wTb)
        object.__setattr__(self, "lines_w", lines)
        if not np.all(np.isfinite(lines)):
            raise ValueError("WorldBelief.lines_w holds a line that is not finite")
        if lines.size and np.max(np.abs(lines[:, 1])) > 2.0 * np.pi:
            j = int(np.argmax(np.abs(lines[:, 1])))
            raise ValueError(
                f"WorldBelief.lines_w's theta must be in radians within [-2 pi, 2 pi], got"
                f" {float(lines[j, 1])} at row {j} (degrees?)"
            )
        if self.cov is not None:
            cov = np.asarray(self.cov, dtype=np.float64)
            n = 3 + 2 * lines.shape[0]
            if cov.shape != (n, n):
                raise ValueError(
                    f"WorldBelief.cov must be ({n}, {n}) for {lines.shape[0]} landmark lines,"
                    f" got {cov.shape}"
                )
            if not np.all(np.isfinite(cov)):
                raise ValueError("WorldBelief.cov is not finite")
            scale = max(float(np.max(np.abs(cov))), 1e-300)
            if np.max(np.abs(cov - cov.T)) > 1e-6 * scale or np.any(np.diag(cov) < 0.0):
                raise ValueError(
                    "WorldBelief.cov must be a covariance: symmetric (to 1e-6 of its largest"
                    " entry) with a non-negative diagonal"
                )
            object.__setattr__(self, "cov", cov)

    @property
    def k(self) -> int:
        """How many landmark lines it holds."""
        return int(self.lines_w.shape[0])


def gtsam_belief(
    estimate: Any,
    pose_key: int,
    line_key: Callable[[int], int],
    association: LandmarkAssociation,
    marginals: Any | None = None,
) -> WorldBelief:
    """A :class:`WorldBelief` from a GTSAM estimate: the ``Pose2`` at ``pose_key``, the 2-vector
    line of every landmark the association made, landmark ``j``'s at ``line_key(j)``, and, with
    ``marginals``, their joint marginal covariance with the pose block converted from GTSAM's
    local (body) frame to world ``(x, y, yaw)``
    (:func:`sonarslam.slam.model.lines.local_to_world_covariance`).

    Parameters
    ----------
    estimate : gtsam.Values
        ``isam.calculateEstimate()`` or a batch optimum.
    pose_key : int
        Key of the body pose of the vote, a ``Pose2``.
    line_key : callable, int -> int
        The key of landmark ``j``'s line (a 2-vector ``(rho_m, theta_rad)`` in the world):
        ``gtsam.symbol_shorthand.L``. A function of the id, so that the lines are in the
        association's order whatever order the keys were made in; a sequence of keys is
        refused (TypeError).
    association : LandmarkAssociation
        Whose landmarks (ids ``0 .. len(association.map.landmarks) - 1``) the belief holds.
    marginals : gtsam.ISAM2 or gtsam.Marginals, optional
        Anything with ``jointMarginalCovariance(keys)``; None: no covariance (enough for
        :meth:`LandmarkAssociation.applied` without merging).
    """
    if not callable(line_key):
        raise TypeError(
            f"gtsam_belief(line_key=...) must be the function from a landmark id to its key"
            f" (gtsam.symbol_shorthand.L), got {type(line_key).__name__}: the association's"
            " ids fix the order"
        )
    if not isinstance(association, LandmarkAssociation):
        raise TypeError(
            "gtsam_belief(association=...) must be the LandmarkAssociation whose landmarks the"
            f" belief holds, got {type(association).__name__}"
        )
    line_keys = [line_key(j) for j in range(len(association.map.landmarks))]
    p = estimate.atPose2(pose_key)
    wTb = np.array([p.x(), p.y(), p.theta()])
    lines = np.array([np.asarray(estimate.atVector(key)) for key in line_keys]).reshape(-1, 2)
    if marginals is None:
        return WorldBelief(wTb, lines)
    keys = [pose_key, *line_keys]
    joint = marginals.jointMarginalCovariance(keys)
    sizes = [3] + [2] * len(line_keys)
    starts = np.concatenate([[0], np.cumsum(sizes)])
    cov_local = np.zeros((starts[-1], starts[-1]))
    for a, ka in enumerate(keys):  # by key: whatever order GTSAM keeps the blocks in
        for b, kb in enumerate(keys):
            block = np.asarray(joint.at(ka, kb))
            cov_local[starts[a] : starts[a + 1], starts[b] : starts[b + 1]] = block
    return WorldBelief(wTb, lines, local_to_world_covariance(wTb, cov_local))


class LandmarkAssociation:
    """Which line observation is of which landmark, for your own estimator (module doc).

    Parameters
    ----------
    bTs : array_like, shape (3,)
        Sonar mounting ``(x_m, y_m, yaw_rad)`` in the body frame (``Mounting.as_pose()``): the
        extractor's; :meth:`decide` refuses lines extracted with another
        (:attr:`sonarslam.features.line.LineFeature.bTs`).
    config : LandmarkConfig, optional
        The landmark layer's rules (association method and gate, tentative lines, extents,
        merges); the back ends' defaults when not given.
    seeds_used : bool
        Whether your estimate of a new landmark uses all its tentative observations (a factor
        graph adds a factor for each of ``NewLandmark.observations``) or only the newest (a
        filter initialises it from ``NewLandmark.line_w``): the observation counts of
        :attr:`map` follow it.

    Attributes
    ----------
    map : LandmarkMap
        The landmarks (extents, sides, counts) and their statistics.
    """

    def __init__(
        self, bTs: npt.ArrayLike, config: LandmarkConfig | None = None, *, seeds_used: bool
    ) -> None:
        self.bTs = check_mounting_pose(bTs, "LandmarkAssociation(bTs=...)")
        self.config = config if config is not None else LandmarkConfig()
        self.seeds_used = seeds_used
        self.map = LandmarkMap(self.config, self.bTs)
        self._pending: Decision | None = None
        self._after: AfterVote | None = None
        #: landmark id -> its line and 2x2 covariance when last decided on (module doc)
        self._then: dict[int, tuple[FloatArray, FloatArray]] = {}

    def decide(
        self, lines: Sequence[LineFeature], belief: WorldBelief, pose_key: int | None = None
    ) -> Decision:
        """Decide one vote of lines from your estimate at the vote.

        Parameters
        ----------
        lines : sequence of LineFeature
            The lines of one vote (what :meth:`sonarslam.features.extractor.LineExtractor.add`
            returned), in the sonar frame of the vote; those nearer than ``min_rho_m`` are not
            used (``Decision.ids`` is over the used ones). Lines extracted with another
            mounting than ``bTs`` are refused (ValueError naming it).
        belief : WorldBelief
            Your estimate at the vote (its time: the lines' ``t``), with its covariance, over
            every landmark made so far, row ``j`` landmark ``j``: a line that moved since the
            last decision beyond any update of a consistent estimator
            (:data:`MOVE_TAIL_PROBABILITY`) is refused (ValueError naming the row), as lines in
            another order than the ids.
        pose_key : int, optional
            Your key of the pose of this vote (a graph's ``X(k)``): the new landmarks'
            observations come back with it (``NodeAnchor.node``) so that you can add their
            factors to the poses they were made from.

        Returns
        -------
        Decision
            Apply its ``merges``, then its ``updates`` (landmark id, observation), then its
            ``new_landmarks`` (id, world line, observations with their anchors); then call
            :meth:`applied`.
        """
        if self._pending is not None:
            raise RuntimeError(
                "LandmarkAssociation.decide: the previous decision was not reported applied:"
                " call applied(belief) with your estimate right after applying it first"
            )
        n = len(self.map.landmarks)
        if belief.k != n:
            raise ValueError(
                f"belief.lines_w holds {belief.k} landmark lines, but the association made {n}"
                " (ids 0..n-1, merged ones too): add each decision's new_landmarks to your"
                " estimate"
            )
        if belief.cov is None:
            raise ValueError("belief.cov is None: decide needs the joint covariance")
        check_mounting(lines, self.bTs, "LandmarkAssociation(bTs=...)")
        self._check_same_landmarks(belief, "decide")
        cfg = self.config
        obs = usable_observations(list(lines), cfg.min_rho_m, cfg.line_cov_scale)
        active = [lm.id for lm in self.map.active()]
        z_hat, H_pose, H_line = line_predictions(belief.wTb, belief.lines_w, self.bTs)
        H = np.zeros((n, 2, 3 + 2 * n))
        H[:, :, :3] = H_pose
        for j in range(n):
            H[j, :, 3 + 2 * j : 5 + 2 * j] = H_line[j]
        anchor = NodeAnchor(pose_key, self.bTs) if pose_key is not None else None
        decision = self.map.vote(
            Belief(
                features=obs.features,
                rejected_near=obs.rejected_near,
                z=obs.z,
                R=obs.R,
                wTb=belief.wTb,
                P_pose=belief.cov[:3, :3],
                anchor=anchor,
                candidates=list(range(n)),
                z_hat=z_hat.reshape(-1, 2),
                H=H,
                P=belief.cov,
                landmarks=LandmarkBelief({j: belief.lines_w[j] for j in active}),
                seeds_used=self.seeds_used,
                after_previous=self._after,
            )
        )
        self._pending = decision
        self._then = {
            j: (
                belief.lines_w[j].copy(),
                belief.cov[3 + 2 * j : 5 + 2 * j, 3 + 2 * j : 5 + 2 * j].copy(),
            )
            for j in active
        }
        for new in decision.new_landmarks:  # the newest observation's world line and covariance
            seen = world_observation(
                new.observations[-1][1],
                belief.wTb,
                belief.cov[:3, :3],
                self.bTs,
                cfg.line_cov_scale,
            )
            self._then[new.id] = (np.asarray(new.line_w, dtype=np.float64), seen.cov_w)
        return decision

    def _check_same_landmarks(self, belief: WorldBelief, method: str) -> None:
        """Refuse a belief whose line ``j`` moved since the last :meth:`decide` beyond any update
        of a consistent estimator (:data:`MOVE_TAIL_PROBABILITY`): it is not landmark ``j``."""
        gate = -2.0 * math.log(MOVE_TAIL_PROBABILITY)
        active = {lm.id for lm in self.map.active()}
        for j, (line_then, P_then) in self._then.items():
            if j not in active:
                continue
            d = line_difference(belief.lines_w[j], line_then)[0]
            q = float(d @ np.linalg.pinv(P_then) @ d)
            if q > gate:
                now = np.array2string(belief.lines_w[j], precision=3, separator=", ")
                then = np.array2string(line_then, precision=3, separator=", ")
                raise ValueError(
                    f"LandmarkAssociation.{method}: belief.lines_w row {j} {now} is not landmark"
                    f" {j}, {then} at the last decide: it moved {math.sqrt(q):.0f} standard"
                    f" deviations, beyond any update of a consistent estimator (tail probability"
                    f" {MOVE_TAIL_PROBABILITY:g}). Are your landmark lines in another order than"
                    " the association's ids? Row j must be landmark j (gtsam_belief(estimate,"
                    " pose_key, L, association) reads them in its order)"
                )

    def applied(self, belief: WorldBelief) -> None:
        """Report your estimate right after applying the last decision (its new landmarks
        included): the pose and the lines (and, when duplicates are merged, their joint
        covariance) that the next :meth:`decide` settles the extents and looks for duplicates
        with.

        Parameters
        ----------
        belief : WorldBelief
            Your estimate after the update, in world coordinates, with one line per landmark
            the association has made (``belief.k == len(self.map.landmarks)``); its ``cov``
            is needed when duplicates are merged (``merge_gate_probability``).

        Raises
        ------
        RuntimeError
            No decision is waiting to be reported (call :meth:`decide` first).
        ValueError
            ``belief`` holds another number of landmarks than the association made (the
            decision's new landmarks were not added), a line that is not the landmark of its
            row (moved beyond :data:`MOVE_TAIL_PROBABILITY` since :meth:`decide`: another
            order), or ``belief.cov`` is None when duplicates are merged.
        """
        decision = self._pending
        if decision is None:
            raise RuntimeError("LandmarkAssociation.applied: no decision to report (decide first)")
        n = len(self.map.landmarks)
        if belief.k != n:
            raise ValueError(
                f"belief.lines_w holds {belief.k} landmark lines, but the association made {n}:"
                " add the decision's new_landmarks to your estimate before applied"
            )
        self._check_same_landmarks(belief, "applied")
        self._pending = None
        if not decision.ids:  # a vote without usable lines: the earlier estimate still counts
            return
        active = [lm.id for lm in self.map.active()]
        if self.config.merge_gate_probability is None:
            lines = LandmarkBelief({j: belief.lines_w[j] for j in decision.seen})
        else:
            if belief.cov is None:
                raise ValueError(
                    "belief.cov is None: applied needs the lines' joint covariance when"
                    " duplicates are merged (merge_gate_probability)"
                )
            idx = np.concatenate([[3 + 2 * j, 4 + 2 * j] for j in active]).astype(int)
            cov = belief.cov[np.ix_(idx, idx)] if active else None
            lines = LandmarkBelief({j: belief.lines_w[j] for j in active}, active, cov)
        self._after = AfterVote(belief.wTb, lines)
