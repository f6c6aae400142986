"""Line observations re-decided at smoothed poses: which observation goes to which landmark, in
stretches of bounded length, once the trajectory has stopped drifting.

The landmark layer (:mod:`sonarslam.slam.mapping.landmarks`) decides online, from an estimate
that drifts: an observation may be paired with the wrong landmark, and a long wall that is not
quite straight (or seen through a heading error that depends on the place) becomes one infinite
line that pulls the poses seen from its far ends. A smoother can decide again once every
factor is in. Given every line observation with its sonar pose at the smoothed estimate (held
fixed) and a first partition of the observations into landmarks (the loop's), one pass
(:func:`redecide`) does:

1. **split**: each landmark's observations, ordered by the foot of the sonar's perpendicular on
   the landmark's line (:func:`sonarslam.features.geometry.along_line` of the sonar position),
   are cut into ``ceil(extent / max_stretch_m)`` stretches of equal length, each at most
   ``max_stretch_m`` long; each stretch is a landmark of its own;
2. **fit**: each stretch's line by Gauss-Newton on its observations at the fixed poses
   (:func:`fit_line`), with its covariance;
3. **associate**: every observation again, one vote at a time (the observations made from one
   sonar pose), with the existing association functions
   (:func:`sonarslam.slam.mapping.association.associate`: JCBB or nearest neighbour under the
   chi2 gate of the configuration) against the stretches it may join: those on whose side of
   the line the sonar is (:func:`sonarslam.slam.model.lines.sonar_side`) and whose extent it
   keeps at most ``max_stretch_m`` long
   (:func:`sonarslam.slam.mapping.association.extent_allowed`). The joint belief is the
   stretches' lines with their fitted covariances, the poses exact. An observation that fits no
   stretch is dropped;
4. **split and fit again**: the new partition cut as in step 1 (an association may have grown a
   stretch), re-fitted; stretches with fewer than ``min_observations`` observations are dropped
   (a line seen once constrains no pose).

The back end re-optimises its graph with the result
(:func:`sonarslam.slam.backends.isam2.redecided.redecided_graph`); this module calls nothing of
it. Poses are the sonar's, ``wTs`` ``(x_m, y_m, yaw_rad)`` in the world; lines are
``(rho_m, theta_rad)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from sonarslam.features.geometry import FloatArray, along_line, line_frame_to_world
from sonarslam.settings import bounded, check_fields
from sonarslam.slam.mapping.association import (
    AssociationConfig,
    AssociationProblem,
    associate,
    extent_allowed,
)
from sonarslam.slam.model.lines import line_prediction, line_residual, sonar_side

__all__ = [
    "RedecideConfig",
    "LineObservations",
    "Stretches",
    "Redecision",
    "fit_line",
    "split_along",
    "redecide",
]

_NO_MOUNT = np.zeros(3)  # poses here are the sonar's own


@dataclass(frozen=True)
class RedecideConfig:
    """How the line observations are re-decided.

    Attributes
    ----------
    max_stretch_m : float
        The longest stretch of a line one landmark stands for (m), along the line.
    association : AssociationConfig
        Method and gate of the re-association (the loop's by default).
    min_observations : int
        A stretch with fewer observations is dropped.
    fit_iterations : int
        Gauss-Newton iterations of each stretch's line fit.
    """

    max_stretch_m: float = bounded(80.0, 0.0, 1e5, low_open=True)
    association: AssociationConfig = field(default_factory=AssociationConfig)
    min_observations: int = bounded(2, 1, 1000)
    fit_iterations: int = bounded(5, 1, 100)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True, eq=False)
class LineObservations:
    """Line observations at fixed sonar poses.

    Attributes
    ----------
    wTs : ndarray, shape (n, 3)
        The sonar's pose at each observation (world).
    z : ndarray, shape (n, 2)
        The observed line in the sonar frame.
    R : ndarray, shape (n, 2, 2)
        Its covariance.
    vote : ndarray of int, shape (n,)
        Observations with one value were made together (one sonar pose, one vote): a landmark
        takes at most one of them.
    """

    wTs: FloatArray
    z: FloatArray
    R: FloatArray
    vote: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.z)
        shapes = {
            "wTs": (np.shape(self.wTs), (n, 3)),
            "z": (np.shape(self.z), (n, 2)),
            "R": (np.shape(self.R), (n, 2, 2)),
            "vote": (np.shape(self.vote), (n,)),
        }
        for name, (got, want) in shapes.items():
            if got != want:
                raise ValueError(f"LineObservations.{name}: shape {want} expected, got {got}")

    def __len__(self) -> int:
        return len(self.z)

    def world_line(self, i: int) -> FloatArray:
        """Observation ``i``'s line in the world, shape (2,)."""
        return line_frame_to_world(self.z[i], self.wTs[i])[0]


@dataclass(frozen=True, eq=False)
class Stretches:
    """Landmarks of bounded length: each with its observations, line, covariance and extent.

    Attributes
    ----------
    members : list of ndarray of int
        Indices of each stretch's observations.
    lines_w : ndarray, shape (k, 2)
    covs : ndarray, shape (k, 2, 2)
    extents_m : ndarray, shape (k, 2)
        ``(s_min, s_max)`` of its observations' sonar feet along its line (m).
    sides : ndarray, shape (k,)
        The side of its line its sonar poses are on (the majority's; +1 or -1).
    """

    members: list[np.ndarray]
    lines_w: FloatArray
    covs: FloatArray
    extents_m: FloatArray
    sides: FloatArray


@dataclass(frozen=True, eq=False)
class Redecision:
    """The result of :func:`redecide`.

    Attributes
    ----------
    stretch : ndarray of int, shape (n,)
        Each observation's stretch (an index into ``stretches``), -1 when dropped.
    stretches : Stretches
    moved : int
        Observations now with observations of another of the first partition's landmarks.
    """

    stretch: np.ndarray
    stretches: Stretches
    moved: int

    @property
    def dropped(self) -> int:
        return int(np.sum(self.stretch < 0))

    def counts(self) -> dict[str, int]:
        """The observations, those kept, dropped and moved to another landmark's stretch, and
        the stretches (``redecided_*`` and ``offline_lines_*`` in ``metrics.json``)."""
        n = int(self.stretch.size)
        return {
            "observations": n,
            "kept": n - self.dropped,
            "dropped": self.dropped,
            "moved": self.moved,
            "stretches": len(self.stretches.members),
        }


def fit_line(
    obs: LineObservations,
    members: np.ndarray,
    line0_w: FloatArray,
    iterations: int = 5,
    cauchy_c2: float | None = None,
) -> tuple[FloatArray, FloatArray]:
    """The world line that best explains the observations ``members`` from their fixed poses
    (Gauss-Newton on ``sum w_i e_i^T R_i^-1 e_i``, ``e_i`` the line factor's residual
    :func:`sonarslam.slam.model.lines.line_residual`), and its covariance
    ``(sum w_i H_i^T R_i^-1 H_i)^-1``.

    Parameters
    ----------
    obs : LineObservations
    members : ndarray of int, shape (m,), m >= 1
    line0_w : ndarray, shape (2,)
        The start (a line near the answer: the landmark's, or an observation's world line).
    iterations : int
    cauchy_c2 : float, optional
        With it, iteratively reweighted: ``w_i = 1 / (1 + d_i^2 / cauchy_c2)`` at the previous
        iterate (Cauchy's kernel on the squared Mahalanobis residual ``d_i^2``), so that an
        observation of another wall among the members does not pull the line off the others;
        without it every ``w_i = 1``.

    Returns
    -------
    line_w : ndarray, shape (2,)
    cov : ndarray, shape (2, 2)
    """
    line = np.asarray(line0_w, dtype=np.float64).copy()
    W = np.linalg.inv(obs.R[members])
    info = np.eye(2)
    for _ in range(iterations):
        e = np.zeros((len(members), 2))
        H = np.zeros((len(members), 2, 2))
        for n, i in enumerate(members):
            e[n], _, H[n] = line_residual(obs.z[i], obs.wTs[i], line, _NO_MOUNT)
        w = np.ones(len(members))
        if cauchy_c2 is not None:
            w = 1.0 / (1.0 + np.einsum("na,nab,nb->n", e, W, e) / cauchy_c2)
        info = np.einsum("n,nca,ncd,ndb->ab", w, H, W, H)
        grad = np.einsum("n,nca,ncd,nd->a", w, H, W, e)
        step = -np.linalg.solve(info, grad)
        line = line + step
        if np.all(np.abs(step) < 1e-9):
            break
    return line, np.asarray(np.linalg.inv(info), dtype=np.float64)


def split_along(s_m: FloatArray, max_stretch_m: float) -> np.ndarray:
    """Stretch labels of positions along a line: ``ceil(extent / max_stretch_m)`` pieces of
    equal length, each at most ``max_stretch_m`` long.

    Parameters
    ----------
    s_m : ndarray, shape (m,)
        Positions along the line (m).
    max_stretch_m : float

    Returns
    -------
    ndarray of int, shape (m,)
        0 .. pieces - 1, increasing with ``s_m``.
    """
    s = np.asarray(s_m, dtype=np.float64)
    if s.size == 0:
        return np.zeros(0, dtype=int)
    lo, extent = float(s.min()), float(s.max() - s.min())
    pieces = max(1, math.ceil(extent / max_stretch_m - 1e-12))
    width = extent / pieces if extent > 0.0 else 1.0
    return np.minimum(((s - lo) / width).astype(int), pieces - 1)


def _feet(obs: LineObservations, members: np.ndarray, line_w: FloatArray) -> FloatArray:
    """The sonar's feet on the line, along it (m)."""
    return along_line(line_w, obs.wTs[members, :2])


def _stretches(
    obs: LineObservations,
    groups: list[np.ndarray],
    starts: list[FloatArray],
    config: RedecideConfig,
    min_observations: int = 1,
) -> Stretches:
    """Each group fitted, cut into stretches (step 1) and each stretch fitted (step 2), both
    robustly (Cauchy's kernel at the association's individual gate)."""
    c2 = float(chi2.ppf(config.association.gate_probability, 2))
    members: list[np.ndarray] = []
    lines: list[FloatArray] = []
    covs: list[FloatArray] = []
    for group, start in zip(groups, starts, strict=True):
        line, _ = fit_line(obs, group, start, config.fit_iterations, c2)
        labels = split_along(_feet(obs, group, line), config.max_stretch_m)
        for piece in range(int(labels.max(initial=-1)) + 1):
            part = group[labels == piece]
            if len(part) < min_observations:
                continue
            fitted, cov = fit_line(obs, part, line, config.fit_iterations, c2)
            members.append(part)
            lines.append(fitted)
            covs.append(cov)
    extents = np.zeros((len(members), 2))
    sides = np.ones(len(members))
    for j, part in enumerate(members):
        s = _feet(obs, part, lines[j])
        extents[j] = (s.min(), s.max())
        side = [sonar_side(obs.wTs[i], lines[j][None, :], _NO_MOUNT)[0] for i in part]
        sides[j] = 1.0 if np.sum(side) >= 0.0 else -1.0
    return Stretches(
        members,
        np.array(lines).reshape(-1, 2),
        np.array(covs).reshape(-1, 2, 2),
        extents,
        sides,
    )


def _allowed(obs: LineObservations, rows: np.ndarray, st: Stretches, max_m: float) -> np.ndarray:
    """(len(rows), k): the stretch keeps its extent at most ``max_m`` with the observation's
    foot, and the sonar is on its side."""
    feet = np.zeros((len(rows), 2, 2))
    feet[:, 0] = obs.wTs[rows, :2]
    feet[:, 1] = obs.wTs[rows, :2]
    # the foot of the perpendicular: along_line of the sonar position (the segment of a point)
    ok = extent_allowed(st.lines_w, st.extents_m, feet, None, max_m)
    for r, i in enumerate(rows):
        ok[r] &= sonar_side(obs.wTs[i], st.lines_w, _NO_MOUNT) == st.sides
    return ok


def _associate(obs: LineObservations, st: Stretches, config: RedecideConfig) -> np.ndarray:
    """Step 3: each vote's observations against the stretches they may join; -1: none."""
    out = -np.ones(len(obs), dtype=int)
    k = len(st.members)
    if k == 0:
        return out
    for vote in np.unique(obs.vote):
        rows = np.flatnonzero(obs.vote == vote)
        allowed = _allowed(obs, rows, st, config.max_stretch_m)
        cands = np.flatnonzero(allowed.any(axis=0))
        if cands.size == 0:
            continue
        wTs = obs.wTs[rows[0]]
        z_hat = np.zeros((cands.size, 2))
        H = np.zeros((cands.size, 2, 2 * cands.size))
        P = np.zeros((2 * cands.size, 2 * cands.size))
        for c, j in enumerate(cands):
            z_hat[c], _, H[c, :, 2 * c : 2 * c + 2] = line_prediction(wTs, st.lines_w[j], _NO_MOUNT)
            P[2 * c : 2 * c + 2, 2 * c : 2 * c + 2] = st.covs[j]
        problem = AssociationProblem(obs.z[rows], obs.R[rows], z_hat, H, P, allowed[:, cands])
        for r, paired in enumerate(associate(problem, config.association)):
            if paired is not None:
                out[rows[r]] = int(cands[paired])
    return out


def redecide(
    obs: LineObservations,
    landmark: np.ndarray,
    config: RedecideConfig,
    lines_w: FloatArray | None = None,
) -> Redecision:
    """One pass of the module docstring's steps 1-4.

    Parameters
    ----------
    obs : LineObservations
        Every line observation, at the poses it is re-decided at.
    landmark : ndarray of int, shape (n,)
        The first partition: each observation's landmark (any labels; negative: none, and it
        joins only if step 3 pairs it).
    config : RedecideConfig
    lines_w : ndarray, shape (L, 2), optional
        The landmarks' lines by label (the start of their fits); default: the world line of
        each landmark's first observation.

    Returns
    -------
    Redecision
    """
    landmark = np.asarray(landmark, dtype=int)
    if landmark.shape != (len(obs),):
        raise ValueError(f"landmark: shape ({len(obs)},) expected, got {landmark.shape}")
    labels = [int(v) for v in np.unique(landmark[landmark >= 0])]
    groups = [np.flatnonzero(landmark == v) for v in labels]
    starts = [
        np.asarray(lines_w[v], dtype=np.float64) if lines_w is not None else obs.world_line(g[0])
        for v, g in zip(labels, groups, strict=True)
    ]
    first = _stretches(obs, groups, starts, config)
    paired = _associate(obs, first, config)
    groups = [np.flatnonzero(paired == j) for j in range(len(first.members))]
    keep = [j for j, g in enumerate(groups) if len(g)]
    final = _stretches(
        obs,
        [groups[j] for j in keep],
        [first.lines_w[j] for j in keep],
        config,
        config.min_observations,
    )
    stretch = -np.ones(len(obs), dtype=int)
    for j, part in enumerate(final.members):
        stretch[part] = j
    # an observation moved when it now shares its stretch with observations of another landmark
    moved = 0
    for part in final.members:
        labelled = landmark[part][landmark[part] >= 0]
        owner = int(np.bincount(labelled).argmax()) if labelled.size else -1
        moved += int(np.sum(landmark[part] != owner))
    return Redecision(stretch, final, moved)
