"""What both back ends share to learn their noise online (``learn_noise``): the learner
(:class:`sonarslam.slam.model.noise_learning.NoiseLearner`) fed from the landmark layer's
innovations and, in the factor graph, its revisit registrations, with the derivatives of each
innovation's covariance by the learned parameters.

A line innovation of landmark ``j`` (:class:`sonarslam.slam.mapping.landmarks.Innovation`) is the
pose now against the landmark as its last used observation left it: the walks since then move it
by the relative pose error of :func:`sonarslam.slam.model.noise_learning.walk_sensitivities`
(the path since then), seen through the prediction's Jacobian ``H_pose``; the line scale moves it
by the told covariance ``R``. A revisit registration between scans ``j`` and ``k`` is their
relative pose: the walks between their times, in scan ``j``'s frame; the scan scale moves it by
the registration's covariance. Only the innovations of observations that update the estimate are
used (a skipped re-observation shares its error with the next one).
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from sonarslam.features.geometry import FloatArray
from sonarslam.slam.io.states import NOISE_FILE, write_learned_noise
from sonarslam.slam.mapping.landmarks import LandmarkMap
from sonarslam.slam.model.motion import MotionStep
from sonarslam.slam.model.noise_learning import (
    NoiseLearner,
    PathMoments,
    Snapshot,
    walk_sensitivities,
)

if TYPE_CHECKING:  # base imports LEARN_KINDS from here
    from sonarslam.slam.backends.base import BackendConfig

__all__ = ["LEARN_KINDS", "LearnedNoise"]

#: The kinds of ``learn_noise`` and the parameter each learns.
LEARN_KINDS = {
    "heading": "heading_walk",
    "dvl_scale": "dvl_scale_walk",
    "lines": "line_scale",
    "scans": "scan_scale",
}


class LearnedNoise:
    """A back end's learned noise (module docstring).

    Parameters
    ----------
    kinds : frozenset of str
        What is learned (keys of :data:`LEARN_KINDS`); empty: nothing, every value the
        configured one.
    heading_walk_rad2_per_s : float
        The configured heading walk (its floor).
    heading_walk_start_rad2_per_s : float
        The heading walk the learner starts from when above the floor: before the innovations
        say otherwise, the heading error is taken to walk at least this fast (a map made in the
        first minutes with a heading error the loop was not told of keeps it).
    dvl_scale_walk_start_per_s : float
        The same for the DVL scale's walk (1/s).
    gate_probability : float
        The association gate the line innovations were kept in.
    memory_s : float
    every : int
        :class:`sonarslam.slam.model.noise_learning.NoiseLearner`'s.
    """

    def __init__(
        self,
        kinds: frozenset[str],
        heading_walk_rad2_per_s: float,
        gate_probability: float,
        heading_walk_start_rad2_per_s: float = 0.0,
        dvl_scale_walk_start_per_s: float = 0.0,
        memory_s: float = 300.0,
        every: int = 10,
    ) -> None:
        floors = {
            "heading_walk": heading_walk_rad2_per_s,
            "dvl_scale_walk": 0.0,
            "line_scale": 1.0,
            "scan_scale": 1.0,
        }
        self._configured = floors
        self.learner = (
            NoiseLearner(
                {LEARN_KINDS[k]: floors[LEARN_KINDS[k]] for k in kinds},
                memory_s,
                every,
                2 * every,
            )
            if kinds
            else None
        )
        self._gate = gate_probability
        #: the heading walk's measurement (``"heading"`` learned)
        starts = {
            "heading_walk": heading_walk_start_rad2_per_s,
            "dvl_scale_walk": dvl_scale_walk_start_per_s,
        }
        for name, start in starts.items():
            if self.learner is not None and self.learner.learns(name) and start > floors[name]:
                self.learner.set(0.0, name, start)
        if self.learner is not None:
            self.learner.history.clear()
        self._rate_seen = False
        self.moments = PathMoments()
        self._marks: dict[Hashable, Snapshot] = {}
        self._seen = 0  # innovations of the landmark layer taken so far

    @classmethod
    def of(cls, config: BackendConfig) -> LearnedNoise:
        """A back end's, from its settings (``learn_noise``, ``learn_*``, the configured walk
        and the association gate)."""
        return cls(
            config.learned_kinds,
            math.radians(config.noise.ahrs_bias_walk_deg_per_sqrt_s) ** 2,
            config.association.gate_probability,
            math.radians(config.learn_heading_start_deg_per_sqrt_s) ** 2,
            config.learn_dvl_scale_start_per_sqrt_s**2,
            config.learn_memory_s,
            config.learn_every,
        )

    @property
    def on(self) -> bool:
        return self.learner is not None

    def learns(self, name: str) -> bool:
        return self.learner is not None and self.learner.learns(name)

    def value(self, name: str) -> float:
        """The value in force of a parameter of
        :data:`sonarslam.slam.model.noise_learning.LEARNED` (the configured one when not
        learned)."""
        if self.learner is not None and self.learner.learns(name):
            return self.learner.value(name)
        return self._configured[name]

    def see_step(self, step: MotionStep) -> bool:
        """The loop's first motion step (with an AHRS, not in a gap) says how its heading
        turns: by the AHRS heading's own change (``yaw_rate_source = "heading"``), the heading
        walk is not learned (True: dropped). The walk would then be the prediction's own error
        as well as the AHRS's, with nothing but the lines to tell a heading error from a turn;
        by the gyro, the walk is the AHRS's alone and the gyro holds the heading between the
        lines (docs/research/consistency.md, "Noise learned online": on the marina the walk learned with
        the heading's own change hands the heading to the lines and loses metres)."""
        if self._rate_seen or step.dt_s <= 0.0 or step.var_yaw_gap_rad2 > 0.0:
            return False
        self._rate_seen = True
        if step.gyro_dt_s > 0.0 or not self.learns("heading_walk"):
            return False
        assert self.learner is not None
        self.learner.drop("heading_walk")
        return True

    def advance(self, t_s: float, xy_m: FloatArray) -> None:
        """The estimated path reached ``xy_m`` at ``t_s``."""
        if self.learner is not None:
            self.moments.advance(t_s, xy_m)

    def mark(self, key: Hashable) -> None:
        """Remember the path's moments now under ``key`` (a landmark's or a scan's)."""
        if self.learner is not None:
            self._marks[key] = self.moments.snapshot()

    def take_lines(self, landmarks: LandmarkMap, new_landmarks: list[int]) -> bool:
        """The landmark layer's joint innovations of the votes since the last call into the
        learner (:class:`sonarslam.slam.mapping.landmarks.JointInnovation`: one sample per vote,
        whose cross-covariances tell a walk, which every line of the vote sees alike, from the
        lines' own errors), each landmark marked now; ``new_landmarks`` marked too. True when
        the learned values changed."""
        if self.learner is None:
            return False
        changed = False
        fresh = landmarks.joint_innovations[self._seen :]
        self._seen = len(landmarks.joint_innovations)
        now = self.moments.snapshot()
        for v in fresh:
            m = len(v.landmarks)
            marks = [self._marks.get(("L", j)) for j in v.landmarks]
            for j in v.landmarks:
                self._marks[("L", j)] = now
            if any(mk is None for mk in marks):
                keep = [a for a, mk in enumerate(marks) if mk is not None]
                if not keep:
                    continue
            else:
                keep = list(range(m))
            rows = np.concatenate([[2 * a, 2 * a + 1] for a in keep])
            p_now = self.moments.relative(v.wTb[:2])
            D_h = np.zeros((2 * len(keep),) * 2)
            D_k = np.zeros_like(D_h)
            D_l = np.zeros_like(D_h)
            for x, a in enumerate(keep):
                D_l[2 * x : 2 * x + 2, 2 * x : 2 * x + 2] = v.R[a] / v.line_scale
                for y, b in enumerate(keep[: x + 1]):
                    ma, mb = marks[a], marks[b]
                    assert ma is not None and mb is not None
                    later = ma if ma[0] >= mb[0] else mb  # the walk both relative errors share
                    Dh, Dk = walk_sensitivities(later, now, p_now)
                    blk_h = v.H_pose[a] @ Dh @ v.H_pose[b].T
                    blk_k = v.H_pose[a] @ Dk @ v.H_pose[b].T
                    D_h[2 * x : 2 * x + 2, 2 * y : 2 * y + 2] = blk_h
                    D_h[2 * y : 2 * y + 2, 2 * x : 2 * x + 2] = blk_h.T
                    D_k[2 * x : 2 * x + 2, 2 * y : 2 * y + 2] = blk_k
                    D_k[2 * y : 2 * y + 2, 2 * x : 2 * x + 2] = blk_k.T
            D = {"line_scale": D_l, "heading_walk": D_h, "dvl_scale_walk": D_k}
            S = v.S[np.ix_(rows, rows)]
            changed |= self.learner.add(v.t_s, v.nu[rows], S, D, self._gate)
        for j in new_landmarks:
            self._marks[("L", j)] = now
        return changed

    def add_registration(
        self,
        t_s: float,
        nu: FloatArray,
        S_graph: FloatArray,
        R_told: FloatArray,
        key_then: Hashable,
        key_now: Hashable,
        yaw_then_rad: float,
        p_now_m: FloatArray,
    ) -> bool:
        """A revisit registration's innovation ``nu = z - jTk`` (3,) in scan ``j``'s frame,
        the graph's covariance of the relative pose ``S_graph`` and the registration's as told
        ``R_told`` (the scan scale not applied); the scans marked as ``key_then`` and
        ``key_now`` (:meth:`mark`), scan ``j``'s yaw and scan ``k``'s position (world). True
        when the learned values changed."""
        if self.learner is None:
            return False
        then, now = self._marks.get(key_then), self._marks.get(key_now)
        if then is None or now is None:
            return False
        D_h, D_k = walk_sensitivities(then, now, self.moments.relative(p_now_m))
        c, s = math.cos(yaw_then_rad), math.sin(yaw_then_rad)
        B = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # world -> scan j's frame
        lam = self.value("scan_scale")
        D = {
            "scan_scale": np.asarray(R_told, dtype=np.float64),
            "heading_walk": B @ D_h @ B.T,
            "dvl_scale_walk": B @ D_k @ B.T,
        }
        S = np.asarray(S_graph, dtype=np.float64) + lam * D["scan_scale"]
        return self.learner.add(t_s, nu, S, D, None)

    def metrics(self) -> dict[str, float]:
        """The learner's ``noise_*`` figures (none when nothing is learned)."""
        return {} if self.learner is None else self.learner.metrics()

    def save(self, out_dir: Path) -> list[Path]:
        """``noise.csv`` (:func:`sonarslam.slam.io.states.write_learned_noise`: the heading walk
        in deg/sqrt(s), the DVL scale walk in 1/sqrt(s), the factors) when something is
        learned."""
        if self.learner is None or not self.learner.history:
            return []
        t = np.array([h[0] for h in self.learner.history])
        v = np.array([h[1] for h in self.learner.history])
        v[:, 0] = np.rad2deg(np.sqrt(v[:, 0]))
        v[:, 1] = np.sqrt(v[:, 1])
        return [write_learned_noise(Path(out_dir) / NOISE_FILE, t, v)]
