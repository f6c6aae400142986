"""Noise learned online from the innovations: the process noise of the heading error and of the
DVL's scale, and the scales of the line and scan-registration covariances.

A closed loop is told its sensors' noise (``[noise]``) and the extractor's and matcher's
covariances; a real vehicle errs in ways nobody told it (a heading error that walks or depends on
the place, a DVL scale that drifts, a range scale, an echo band thicker than modelled). Its
innovations then exceed what it predicted, which the health monitor
(:mod:`sonarslam.slam.eval.health`) flags. :class:`NoiseLearner` corrects it, GPS-free, by
windowed maximum-likelihood covariance matching (Mehra 1972, "Approaches to adaptive filtering",
IEEE TAC 17(5), the maximum-likelihood method; Maybeck 1982, *Stochastic Models, Estimation and
Control*, vol. 2, ch. 10): the parameters

=====================  ==========================================================  ========
``heading_walk``       the heading error's random walk ``q_psi`` (rad^2/s)          process
``dvl_scale_walk``     the DVL scale error's random walk ``q_k`` (1/s)              process
``line_scale``         the factor ``lambda_L`` on every line's covariance ``R``     measure
``scan_scale``         the factor ``lambda_S`` on a revisit registration's          measure
=====================  ==========================================================  ========

each bounded below by the configured value (a learner never believes its sensors better than it
was told), enter each innovation's predicted covariance ``S(theta)``; an innovation ``nu`` (d,)
with ``S`` as the loop predicted it (with the values in force then) and the derivatives
``D_p = dS / dtheta_p`` adds to the score and the Fisher information of the window

    ``g_p = 1/2 tr(S^-1 D_p S^-1 (nu nu^T / c - S))``,  ``F_pq = 1/2 tr(S^-1 D_p S^-1 D_q)``

(the Gaussian log-likelihood's; Harville 1977, "Maximum likelihood approaches to variance
component estimation", JASA 72, eq. 4.4 and 4.5: the same iteration estimates variance components
of residuals), and every ``every`` innovations one Fisher-scoring step ``theta <- theta +
F^-1 g`` is taken within the bounds (a bounded least-squares step in units of each parameter's
reference size, a value at most ``growth`` times larger or smaller per step). The sums forget with a memory of
``memory_s`` seconds (their weights fall by ``exp(-dt / memory_s)``: the channels' rates differ,
an AHRS heading a second, a line a few), and after a step the score is carried to the new values
to first order
(``g <- g - F dtheta``), so that it is the score of the remembered innovations at the values now
in force. The fixed point is where the innovations match their predicted covariance in every
direction some ``D_p`` spans: which parameter takes an excess is decided by the shapes of the
``D_p``; their size only sets the step.

``c`` corrects for the association gate: an innovation kept only inside a chi2(d) gate ``G`` (the
line associations') has ``E[nu nu^T] = c S`` with ``c = F_{d+2}(G) / F_d(G)`` (``F_k`` the
chi2(k) distribution function); an ungated one (a registration) is winsorised at the 0.999
quantile and ``c`` is the winsorised expectation.

The derivatives of a relative pose error by the walks (:func:`walk_sensitivities`): with the
heading error walking at ``q`` from ``t_0``, the position error at ``t_1`` is
``int e(u) R90 v(u) du`` and, by parts, ``int R90 (p_1 - p(u)) de(u)``: its covariance is
``q int a a^T du`` with ``a(u) = R90 (p_1 - p(u))``, its cross-covariance with the heading error
``q int a du``, the heading error's ``q (t_1 - t_0)``. A DVL scale error walking at ``q`` moves
the position by ``int (p_1 - p(u)) dk(u)``: covariance ``q int (p_1 - p)(p_1 - p)^T du``. Both
from the running moments of the estimated path (:class:`PathMoments`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear
from scipy.stats import chi2

from sonarslam.features.geometry import FloatArray

__all__ = [
    "LEARNED",
    "LEARNED_UNITS",
    "REFERENCE",
    "UPPER",
    "WINSOR_PROBABILITY",
    "expected_factor",
    "PathMoments",
    "Snapshot",
    "walk_sensitivities",
    "NoiseLearner",
]

#: The learned parameters, in the order of :attr:`NoiseLearner.history`'s columns.
LEARNED = ("heading_walk", "dvl_scale_walk", "line_scale", "scan_scale")
#: Their units (``metrics.json``, ``noise.csv``).
LEARNED_UNITS = {
    "heading_walk": "rad^2/s",
    "dvl_scale_walk": "1/s",
    "line_scale": "",
    "scan_scale": "",
}
#: A reference size of each (the unit of a step, the largest step up from 0): a heading walk of
#: 0.1 deg/sqrt(s), a DVL scale walk of 0.1 %/sqrt(s), a covariance as told.
REFERENCE = {
    "heading_walk": math.radians(0.1) ** 2,
    "dvl_scale_walk": 1e-3**2,
    "line_scale": 1.0,
    "scan_scale": 1.0,
}
#: The largest value each may take: a heading walk of 1 deg/sqrt(s), a DVL scale walk of
#: 1 %/sqrt(s), a covariance 100 times the told one (``line_cov_scale``'s own bound).
UPPER = {
    "heading_walk": math.radians(1.0) ** 2,
    "dvl_scale_walk": 1e-2**2,
    "line_scale": 100.0,
    "scan_scale": 100.0,
}
#: An innovation without a gate is winsorised at this chi2 quantile (a wrong registration must
#: not teach the learner that every registration is that bad).
WINSOR_PROBABILITY = 0.999


def expected_factor(dof: int, gate_probability: float | None) -> tuple[float, float]:
    """``(c, w)``: ``E[nu nu^T] = c S`` of an innovation of ``dof`` values kept inside the chi2
    gate of ``gate_probability`` (truncated; None: winsorised at :data:`WINSOR_PROBABILITY`),
    and the squared Mahalanobis distance ``w`` at which it is winsorised (module docstring)."""
    if gate_probability is not None:
        g = float(chi2.ppf(gate_probability, dof))
        return float(chi2.cdf(g, dof + 2) / chi2.cdf(g, dof)), g
    w = float(chi2.ppf(WINSOR_PROBABILITY, dof))
    return float(chi2.cdf(w, dof + 2) + w / dof * chi2.sf(w, dof)), w


class PathMoments:
    """Running moments of the estimated path, ``int 1, int p, int p p^T`` over time (trapezoids
    between the positions given to :meth:`advance`), from which :func:`walk_sensitivities` takes
    any interval's. Times relative to the first, positions to the first position (their
    magnitudes stay small).

    A snapshot (:meth:`snapshot`) is ``(t_s, m1 (2,), m2 (2, 2), p (2,))``: the moments from the
    start up to ``t_s`` (relative) and the position then.
    """

    def __init__(self) -> None:
        self._t0: float | None = None
        self._p0 = np.zeros(2)
        self._t = 0.0
        self._p = np.zeros(2)
        self._m1 = np.zeros(2)
        self._m2 = np.zeros((2, 2))

    def advance(self, t_s: float, xy_m: FloatArray) -> None:
        """The path reached ``xy_m`` (world, m) at ``t_s`` (Unix s)."""
        if self._t0 is None:
            self._t0, self._p0 = float(t_s), np.asarray(xy_m, dtype=np.float64)[:2].copy()
            return
        t = float(t_s) - self._t0
        p = np.asarray(xy_m, dtype=np.float64)[:2] - self._p0
        dt = t - self._t
        if dt <= 0.0:
            self._p = p
            return
        a, b = self._p, p
        self._m1 += 0.5 * dt * (a + b)
        # int of (a + s (b - a))(a + s (b - a))^T over s in [0, 1], times dt
        self._m2 += (
            dt
            / 6.0
            * (2.0 * np.outer(a, a) + np.outer(a, b) + np.outer(b, a) + 2.0 * np.outer(b, b))
        )
        self._t, self._p = t, p

    def snapshot(self) -> Snapshot:
        """The moments now (relative time, ``int p``, ``int p p^T``, the position)."""
        return self._t, self._m1.copy(), self._m2.copy(), self._p.copy()

    def relative(self, xy_m: FloatArray) -> FloatArray:
        """A world position in the moments' frame."""
        return np.asarray(xy_m, dtype=np.float64)[:2] - self._p0


_R90 = np.array([[0.0, -1.0], [1.0, 0.0]])

#: :meth:`PathMoments.snapshot`: (relative time s, int p (2,), int p p^T (2, 2), p (2,)).
Snapshot = tuple[float, FloatArray, FloatArray, FloatArray]


def walk_sensitivities(
    then: Snapshot, now: Snapshot, p_now: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The covariance of the pose error ``(x_m, y_m, yaw_rad)`` at ``now`` relative to
    ``then`` per unit walk (module docstring): ``(D_heading, D_scale)``, shapes (3, 3), for a
    heading error walking at 1 rad^2/s and a DVL scale error walking at 1/s since the start of
    the moments. A heading error the two times share turns the path and the map together and
    moves nothing between them: only its walk between them counts. A scale error they share
    stretches the path between them: its walk before ``then`` counts too, by ``t_then dp
    dp^T`` (``dp`` the displacement between them).

    Parameters
    ----------
    then, now : tuple
        :meth:`PathMoments.snapshot` at the two times.
    p_now : ndarray, shape (2,)
        The position now in the moments' frame (:meth:`PathMoments.relative`).
    """
    T = max(now[0] - then[0], 0.0)
    m1 = now[1] - then[1]
    m2 = now[2] - then[2]
    p = np.asarray(p_now, dtype=np.float64)
    inner = T * np.outer(p, p) - np.outer(p, m1) - np.outer(m1, p) + m2  # int (p - p(u))(..)^T
    inner = 0.5 * (inner + inner.T)
    lever = T * p - m1  # int (p - p(u)) du
    D_h = np.zeros((3, 3))
    D_h[:2, :2] = _R90 @ inner @ _R90.T
    D_h[:2, 2] = D_h[2, :2] = _R90 @ lever
    D_h[2, 2] = T
    D_k = np.zeros((3, 3))
    dp = p - then[3]
    D_k[:2, :2] = inner + max(then[0], 0.0) * np.outer(dp, dp)
    return D_h, D_k


@dataclass
class _Parameter:
    value: float
    floor: float


class NoiseLearner:
    """The learned noise of one closed loop (module docstring).

    Parameters
    ----------
    floors : dict of str to float
        The parameters learned (names of :data:`LEARNED`), each with its configured value: its
        start and lower bound.
    memory_s : float
        The time the score and information remember (s; their weights fall by
        ``exp(-dt / memory_s)``).
    every : int
        A scoring step every this many innovations.
    min_innovations : int
        No step before this many innovations.
    growth : float
        A step takes a value at most this many times up (or from 0 at most this many reference
        sizes) or down.
    """

    def __init__(
        self,
        floors: dict[str, float],
        memory_s: float = 300.0,
        every: int = 10,
        min_innovations: int = 20,
        growth: float = 2.0,
    ) -> None:
        unknown = set(floors) - set(LEARNED)
        if unknown:
            raise ValueError(
                f"NoiseLearner: unknown parameters {sorted(unknown)}, expected {LEARNED}"
            )
        self._params = {k: _Parameter(float(v), float(v)) for k, v in floors.items()}
        self._names = [k for k in LEARNED if k in self._params]
        n = len(self._names)
        self._g = np.zeros(n)
        self._F = np.zeros((n, n))
        self._memory_s = float(memory_s)
        self._t_last: float | None = None
        self._every = every
        self._min = min_innovations
        self._growth = float(growth)
        self._count = 0
        self._since_step = 0
        #: ``(t_s, values in the order of LEARNED, NaN for one not learned)`` at the start and
        #: after every step
        self.history: list[tuple[float, tuple[float, ...]]] = []
        self._factors: dict[tuple[int, float | None], tuple[float, float]] = {}

    @property
    def names(self) -> list[str]:
        """The parameters learned."""
        return list(self._names)

    def learns(self, name: str) -> bool:
        return name in self._params

    def drop(self, name: str) -> None:
        """Learn ``name`` no more: it leaves the learner (its value is then the configured
        one, :meth:`learns` is False)."""
        if name not in self._params:
            return
        i = self._names.index(name)
        keep = [j for j in range(len(self._names)) if j != i]
        self._g = self._g[keep]
        self._F = self._F[np.ix_(keep, keep)]
        del self._params[name]
        self._names.pop(i)

    def set(self, t_s: float, name: str, value: float) -> bool:
        """A parameter's value set (within its bounds), as a start above its floor; True when
        it changed."""
        par = self._params[name]
        new = float(min(max(value, par.floor), UPPER[name]))
        if not self.history:
            self.history.append((float(t_s), self.values()))
        if new == par.value:
            return False
        par.value = new
        self.history.append((float(t_s), self.values()))
        return True

    def value(self, name: str) -> float:
        """The value in force (the configured one for a parameter not learned: KeyError)."""
        return self._params[name].value

    def values(self) -> tuple[float, ...]:
        """Every value of :data:`LEARNED` (NaN for those not learned)."""
        return tuple(self._params[k].value if k in self._params else math.nan for k in LEARNED)

    def add(
        self,
        t_s: float,
        nu: FloatArray,
        S: FloatArray,
        D: dict[str, FloatArray],
        gate_probability: float | None = None,
    ) -> bool:
        """One innovation ``nu`` (d,) with its predicted covariance ``S`` (d, d) and the
        derivatives ``D`` (name -> (d, d); a parameter left out does not enter ``S``); kept
        inside a chi2(d) gate of ``gate_probability`` (None: none). True when a step was taken
        (the values changed)."""
        if not self.history:
            self.history.append((float(t_s), self.values()))
        nu = np.asarray(nu, dtype=np.float64)
        d = nu.size
        key = (d, gate_probability)
        if key not in self._factors:
            self._factors[key] = expected_factor(d, gate_probability)
        c, w = self._factors[key]
        try:
            Si = np.linalg.inv(np.asarray(S, dtype=np.float64))
        except np.linalg.LinAlgError:
            return False
        m2 = float(nu @ Si @ nu)
        if not math.isfinite(m2):
            return False
        if m2 > w:  # winsorised (a gated innovation never is)
            nu = nu * math.sqrt(w / m2)
        a = Si @ nu
        A = [Si @ D[k] if k in D else None for k in self._names]
        g = np.zeros(len(self._names))
        F = np.zeros((len(self._names),) * 2)
        for p, Ap in enumerate(A):
            if Ap is None:
                continue
            # tr(S^-1 D S^-1 nu nu^T) = a^T D a ; tr(S^-1 D S^-1 S) = tr(S^-1 D)
            g[p] = 0.5 * (float(a @ D[self._names[p]] @ a) / c - float(np.trace(Ap)))
            for q in range(p + 1):
                Aq = A[q]
                if Aq is not None:
                    F[p, q] = F[q, p] = 0.5 * float(np.sum(Ap * Aq.T))
        forget = 1.0
        if self._t_last is not None:
            forget = math.exp(-max(float(t_s) - self._t_last, 0.0) / self._memory_s)
        self._t_last = float(t_s)
        self._g = forget * self._g + g
        self._F = forget * self._F + F
        self._count += 1
        self._since_step += 1
        if self._count < self._min or self._since_step < self._every:
            return False
        self._since_step = 0
        return self._step(float(t_s))

    def _step(self, t_s: float) -> bool:
        """One bounded Fisher-scoring step (module docstring)."""
        names = self._names
        ref = np.array([REFERENCE[k] for k in names])
        theta = np.array([self._params[k].value for k in names])
        floor = np.array([self._params[k].floor for k in names])
        excited = np.diag(self._F) * ref**2 > 1e-9
        if not np.any(excited):
            return False
        idx = np.flatnonzero(excited)
        Fn = self._F[np.ix_(idx, idx)] * np.outer(ref[idx], ref[idx])
        gn = self._g[idx] * ref[idx]
        Fn = Fn + 1e-9 * np.eye(idx.size) * max(float(np.trace(Fn)), 1e-12)
        try:
            L = np.linalg.cholesky(Fn)
        except np.linalg.LinAlgError:
            return False
        u = theta[idx] / ref[idx]
        grow = self._growth
        lo = np.maximum(floor[idx] / ref[idx], u / grow) - u
        top = np.array([UPPER[names[i]] for i in idx]) / ref[idx]
        hi = np.minimum(top, np.maximum(grow * u, u + grow - 1.0)) - u
        lo = np.minimum(lo, 0.0)
        hi = np.maximum(hi, 0.0)
        step = lsq_linear(L.T, np.linalg.solve(L, gn), bounds=(lo, hi)).x
        if not np.all(np.isfinite(step)):
            return False
        dtheta = np.zeros(len(names))
        dtheta[idx] = step * ref[idx]
        self._g = self._g - self._F @ dtheta
        changed = False
        for i, k in enumerate(names):
            new = float(max(theta[i] + dtheta[i], floor[i]))
            changed |= new != self._params[k].value
            self._params[k].value = new
        self.history.append((t_s, self.values()))
        return changed

    def metrics(self) -> dict[str, float]:
        """``noise_<name>_{final,max}`` of every learned parameter (``metrics.json``), the heading
        walk as ``deg/sqrt(s)`` and the DVL scale walk as ``1/sqrt(s)`` (the configuration's
        units), and the number of steps taken."""
        out: dict[str, float] = {"noise_learner_steps": float(len(self.history) - 1)}
        if not self.history:
            return {}
        rows = np.array([v for _, v in self.history])
        for i, k in enumerate(LEARNED):
            if k not in self._params:
                continue
            col = rows[:, i]
            if k == "heading_walk":
                col, name = np.rad2deg(np.sqrt(col)), "noise_heading_walk_deg_per_sqrt_s"
            elif k == "dvl_scale_walk":
                col, name = np.sqrt(col), "noise_dvl_scale_walk_per_sqrt_s"
            else:
                name = f"noise_{k}"
            out[f"{name}_final"] = float(col[-1])
            out[f"{name}_max"] = float(col.max())
        return out
