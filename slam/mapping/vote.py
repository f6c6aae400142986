"""What a back end and the landmark layer exchange for one vote of lines: data, both ways.

A back end hands :meth:`sonarslam.slam.mapping.landmarks.LandmarkMap.vote` one :class:`Belief` (the vote's
observations, the pose it was made from, the landmarks' lines as stored and the prediction of the
candidate landmarks with their joint covariance) and gets back one :class:`Decision` (which
observation pairs with which landmark and is used, which tentative lines became landmarks, which
landmarks are one wall). The landmark layer calls nothing of the back end; the back end applies
the decision to its estimate (the EKF's updates and augmentations, the factor graph's factors and
variables) in the order the decision's fields are listed.

What the layer needs of the estimate *after* a vote's update (the extents grow along the updated
lines, placed with the updated pose; duplicates are found on the updated lines) comes with the
next belief, as :class:`AfterVote`: the layer settles the previous vote first, and the map's
records settle the last one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from sonarslam.features.geometry import FloatArray
from sonarslam.features.line import LineFeature

__all__ = [
    "NodeAnchor",
    "Anchored",
    "LandmarkBelief",
    "AfterVote",
    "ViewPair",
    "Belief",
    "NewLandmark",
    "Decision",
]


@dataclass(frozen=True, eq=False)
class NodeAnchor:
    """The factor graph's anchor of a vote's observations: the pose node ``X(node)`` they are
    taken from and the sonar mounting to use with it, ``bTs`` (3,) (the odometry since the node
    folded in). A filter has none (None)."""

    node: int
    bTs: FloatArray


#: An observation with the back end's anchor of it (kept with tentative lines until promoted).
Anchored = tuple[NodeAnchor | None, LineFeature]


@dataclass(frozen=True, eq=False)
class LandmarkBelief:
    """The back end's current lines of the active landmarks, as stored (may be unnormalised).

    Attributes
    ----------
    lines_w : dict of int to ndarray, shape (2,)
        Landmark id -> world line ``(rho_m, theta_rad)``, every active landmark.
    cov_ids : list of int
        The landmarks :attr:`cov` covers, in its order (empty when not asked for).
    cov : ndarray, shape (2k, 2k), optional
        Joint covariance of those lines; given only when the landmark layer merges duplicates
        (``merge_gate_probability``).
    """

    lines_w: dict[int, FloatArray]
    cov_ids: list[int] = field(default_factory=list)
    cov: FloatArray | None = None


@dataclass(frozen=True, eq=False)
class AfterVote:
    """The back end's estimate right after it applied a vote's decision.

    Attributes
    ----------
    wTb : ndarray, shape (3,)
        The body pose then.
    landmarks : LandmarkBelief
        The lines of the landmarks that vote saw (:attr:`Decision.seen`); of every active one,
        with their joint covariance, when the layer merges duplicates.
    """

    wTb: FloatArray
    landmarks: LandmarkBelief


@dataclass(frozen=True, eq=False)
class ViewPair:
    """The sonar's pose at the current vote and at an earlier one, as the back end estimates them
    now, with their joint covariance: what a tentative line's gate needs to compare two views
    (:meth:`sonarslam.slam.mapping.landmarks.LandmarkMap.tentative_distance`).

    Attributes
    ----------
    wTs_now : ndarray, shape (3,)
        The sonar's pose at the current vote ``(x_m, y_m, yaw_rad)``.
    wTs_then : ndarray, shape (3,)
        The sonar's pose at the earlier vote, as the back end estimates it now (a filter: as it
        estimated it then; a smoother: smoothed).
    cov : ndarray, shape (6, 6)
        Joint covariance of ``[wTs_now, wTs_then]`` in ``(x, y, yaw)``, cross-covariance included.
    """

    wTs_now: FloatArray
    wTs_then: FloatArray
    cov: FloatArray


@dataclass(frozen=True, eq=False)
class Belief:
    """One vote as the back end sees it before using it.

    Attributes
    ----------
    features : list of LineFeature
        The vote's observations the landmark layer may use (those at ``rho_m >= min_rho_m``).
    rejected_near : int
        How many of the vote's observations were nearer than ``min_rho_m``.
    z : ndarray, shape (m, 2)
        The observations in the sonar frame.
    R : ndarray, shape (m, 2, 2)
        Their covariances (scaled by ``line_cov_scale``).
    wTb : ndarray, shape (3,)
        The body pose of the vote.
    P_pose : ndarray, shape (3, 3)
        Its covariance in ``(x_m, y_m, yaw_rad)``.
    anchor : NodeAnchor or None
        The back end's anchor of this vote's observations.
    candidates : list of int
        Landmark ids the observations may be associated with.
    z_hat : ndarray, shape (k, 2)
        The candidates' predicted observations.
    H : ndarray, shape (k, 2, d)
        Their Jacobians with respect to the belief's vector ``s``.
    P : ndarray, shape (d, d)
        The covariance of ``s`` (:mod:`sonarslam.slam.mapping.association`).
    landmarks : LandmarkBelief
        Every active landmark's line (the extent and side gates, the extents, the merges).
    seeds_used : bool
        A promoted line's estimate uses all its tentative observations (the factor graph), or
        only the newest (the EKF).
    after_previous : AfterVote or None
        The estimate right after the back end applied the previous vote with observations.
    view : object or None
        The back end's token of this vote's pose (kept with a tentative line first seen in it);
        None: the back end keeps no joint covariance of its poses.
    view_pairs : dict of object to ViewPair, optional
        For the token of each earlier vote a tentative line was first seen in (the landmark
        layer's ``tentative``), this vote's sonar pose and that vote's with their joint
        covariance. A tentative line whose token is missing (or None here) has its two views
        compared as independent (each world line holding its own pose's covariance).
    """

    features: list[LineFeature]
    rejected_near: int
    z: FloatArray
    R: FloatArray
    wTb: FloatArray
    P_pose: FloatArray
    anchor: NodeAnchor | None
    candidates: list[int]
    z_hat: FloatArray
    H: FloatArray
    P: FloatArray
    landmarks: LandmarkBelief
    seeds_used: bool
    after_previous: AfterVote | None
    view: object | None = None
    view_pairs: dict[object, ViewPair] | None = None


@dataclass(frozen=True, eq=False)
class NewLandmark:
    """A tentative line promoted to a landmark: its id, its world line (the newest observation's,
    at the vote's pose) and its observations with their anchors, the newest last."""

    id: int
    line_w: FloatArray
    observations: list[Anchored]


@dataclass(frozen=True, eq=False)
class Decision:
    """What the landmark layer decided for one vote, applied by the back end: the merges first,
    then the updates, then the new landmarks.

    Attributes
    ----------
    ids : list of int or None
        The landmark of each of the belief's features (None: not associated, or tentative).
    updates : list of (int, LineFeature)
        The associated observations to use, each with its landmark id, in order.
    new_landmarks : list of NewLandmark
        Promoted lines, in id order.
    merges : list of (int, int)
        ``(keep, drop)``: landmark ``drop`` is the same wall as ``keep`` (found on the estimate
        after the previous vote); tie their estimates, and use only ``keep`` from now on.
    seen : list of int
        The landmarks associated in this vote, used or not (their extents grew).
    """

    ids: list[int | None]
    merges: list[tuple[int, int]]
    updates: list[tuple[int, LineFeature]]
    new_landmarks: list[NewLandmark]
    seen: list[int]
