"""The plugin seam of the design card: where the front end gets vehicle poses from.

GPS+AHRS, dead reckoning, the simulator's truth, the EKF and the factor graph all implement
:class:`PoseSource`. The front end (``features``) never imports any of them.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray

__all__ = [
    "MAX_YAW_JUMP_RAD",
    "MAX_YAW_RATE_RADPS",
    "BatchCovariances",
    "PoseSource",
    "PoseSpanWarning",
    "checked_poses",
    "outside_span",
    "pose_covariances",
]

#: No vehicle turns faster than this (one turn a second): a pose source whose yaw turns
#: faster between two beams, by more than :data:`MAX_YAW_JUMP_RAD`, is taken as giving degrees.
MAX_YAW_RATE_RADPS = 2.0 * np.pi
#: ... and the smallest yaw step between two beams taken as a jump (rad, ~29 deg).
MAX_YAW_JUMP_RAD = 0.5


@runtime_checkable
class PoseSource(Protocol):
    """Vehicle pose ``wTb`` (world East-North, yaw CCW from east) at given times.

    Yaw is in radians (any branch: wrapped or unwrapped). A source that knows where it has
    poses gives ``span_s``, ``(t_first_s, t_last_s)``
    (:class:`sonarslam.slam.io.trajectory.Trajectory` does): the front end warns, once, of beams
    outside it (:class:`PoseSpanWarning`), whose poses a trajectory holds from an end.
    """

    def poses(self, t_s: npt.ArrayLike) -> FloatArray:
        """Poses of the vehicle body at times ``t_s``.

        Parameters
        ----------
        t_s : array_like, shape (N,)
            Unix times (s).

        Returns
        -------
        ndarray, shape (N, 3)
            ``(x_m, y_m, yaw_rad)`` per time.
        """
        ...

    def covariance(self, t_s: float) -> FloatArray | None:
        """3x3 covariance of the pose at ``t_s`` (m, m, rad), or None if the source has none."""
        ...


@runtime_checkable
class BatchCovariances(Protocol):
    """A :class:`PoseSource` that also gives the covariances of many times in one call (the
    extractor asks for every stored beam's at each vote): the same values as
    :meth:`PoseSource.covariance` time by time."""

    def covariances(self, t_s: npt.ArrayLike) -> FloatArray | None:
        """Covariances at times ``t_s`` (N,), shape (N, 3, 3), or None if the source has none."""
        ...


class PoseSpanWarning(UserWarning):
    """Beams outside the span of their pose source: placed with a pose held from an end."""


def outside_span(source: PoseSource, t_s: npt.ArrayLike) -> str | None:
    """What is wrong with beams at ``t_s`` (N,) (Unix s) that lie outside ``source``'s
    ``span_s`` (a source without one has no span to miss), naming their times and the span;
    None when all lie inside."""
    span = getattr(source, "span_s", None)
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    if span is None or t.size == 0:
        return None
    t0, t1 = float(span[0]), float(span[1])
    out = t[(t < t0) | (t > t1)]
    if out.size == 0:
        return None
    return (
        f"{out.size} beam time(s) {out.min():.3f}-{out.max():.3f} s (Unix) lie outside the pose"
        f" source's span {t0:.3f}-{t1:.3f} s: their poses are held from an end, a stale frame"
        " for their echoes; give a source that covers the beams, or only the beams inside its"
        " span (BeamSeries.between(t0, t1))"
    )


def checked_poses(source: PoseSource, t_s: npt.ArrayLike) -> FloatArray:
    """``source.poses(t_s)``, shape (N, 3), for beams at increasing times ``t_s`` (N,) (Unix s),
    their yaw checked for degrees.

    Raises
    ------
    ValueError
        The yaw turns by more than :data:`MAX_YAW_JUMP_RAD` between two consecutive times at
        more than :data:`MAX_YAW_RATE_RADPS` (degrees given for radians), naming the two times
        and yaws. A source in degrees that hardly turns passes: the check sees only turns.
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    wTb = np.asarray(source.poses(t), dtype=np.float64).reshape(-1, 3)
    if t.size > 1:
        dt = np.diff(t)
        step = np.abs(np.angle(np.exp(1j * np.diff(wTb[:, 2]))))
        bad = np.flatnonzero(
            (step > MAX_YAW_JUMP_RAD) & (step > MAX_YAW_RATE_RADPS * np.maximum(dt, 0.0))
        )
        if bad.size:
            i = int(bad[0])
            raise ValueError(
                f"the pose source's yaw jumps from {wTb[i, 2]:.4g} to {wTb[i + 1, 2]:.4g} between"
                f" beams at {t[i]:.3f} and {t[i + 1]:.3f} s (Unix), {step[i]:.3g} rad in"
                f" {dt[i]:.3g} s, faster than any vehicle turns ({MAX_YAW_RATE_RADPS:.3g} rad/s):"
                " poses(t_s) must give yaw in radians (degrees?)"
            )
    return wTb


def pose_covariances(source: PoseSource, t_s: npt.ArrayLike) -> FloatArray | None:
    """The pose covariances at times ``t_s`` (N,), shape (N, 3, 3) (m, m, rad), or None when
    the source has none at any of them: in one call where the source can
    (:class:`BatchCovariances`), else time by time.

    Raises
    ------
    ValueError
        A covariance that is not (3, 3), not finite, not symmetric (to 1e-6 of its largest
        entry) or not positive semi-definite (an eigenvalue below -1e-9 of its largest entry),
        naming the source's method, the time and what is expected.
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    if isinstance(source, BatchCovariances):
        batch = source.covariances(t)
        if batch is None:
            return None
        covs = np.asarray(batch, dtype=np.float64)
        if covs.shape != (t.size, 3, 3):
            raise ValueError(
                f"the pose source's covariances(t_s) of {t.size} beam times from {t[0]:.3f} s"
                f" (Unix) must be ({t.size}, 3, 3), one covariance of (x_m, y_m, yaw_rad) per"
                f" time, got shape {covs.shape}"
            )
        _check_covariances(covs, t, "covariances(t_s)")
        return covs
    given = [source.covariance(float(tk)) for tk in t]
    if any(c is None for c in given):
        return None
    for tk, c in zip(t, given, strict=True):
        shape = np.asarray(c).shape
        if shape != (3, 3):
            raise ValueError(
                f"the pose source's covariance(t) at t={tk:.3f} s (Unix) must be (3, 3), the"
                f" covariance of (x_m, y_m, yaw_rad), got shape {shape}"
            )
    covs = np.stack([np.asarray(c, dtype=np.float64) for c in given])
    _check_covariances(covs, t, "covariance(t)")
    return covs


def _check_covariances(covs: FloatArray, t: FloatArray, method: str) -> None:
    """Refuse a pose covariance (N, 3, 3) at times ``t`` (N,) that is not one
    (:func:`pose_covariances`' Raises), naming ``method`` and the first time at fault."""
    finite = np.all(np.isfinite(covs), axis=(1, 2))
    scale = np.maximum(
        np.max(np.abs(np.where(finite[:, None, None], covs, 0.0)), axis=(1, 2)), 1e-300
    )
    asym = np.max(np.abs(covs - np.transpose(covs, (0, 2, 1))), axis=(1, 2))
    sym = 0.5 * (covs + np.transpose(covs, (0, 2, 1)))
    low = np.full(t.size, np.inf)
    low[finite] = np.linalg.eigvalsh(sym[finite])[:, 0]
    why = np.where(
        ~finite,
        "is not finite",
        np.where(
            asym > 1e-6 * scale,
            "is not symmetric",
            np.where(low < -1e-9 * scale, "is not positive semi-definite", ""),
        ),
    )
    bad = np.flatnonzero(why != "")
    if bad.size:
        i = int(bad[0])
        shown = np.array2string(covs[i], precision=4, separator=", ").replace("\n", "")
        eig = f" (least eigenvalue {low[i]:.3g})" if why[i].endswith("definite") else ""
        raise ValueError(
            f"the pose source's {method} at t={t[i]:.3f} s (Unix) {why[i]}{eig}: {shown};"
            " expected the covariance of (x_m, y_m, yaw_rad) (m^2, rad^2): finite, symmetric,"
            " positive semi-definite"
        )
