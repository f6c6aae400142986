"""Noise of the navigation sensors as the estimators model it: the DVL velocity (held between
samples, inflated when its own scatter rises) and the AHRS heading.

Used by the motion model (:mod:`sonarslam.slam.model.motion`), hence by dead reckoning, the EKF, the
factor graph's odometry and the front end's odometry chain alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np
import numpy.typing as npt

from sonarslam.datasets.config import NoiseConfig
from sonarslam.features.geometry import FloatArray

__all__ = [
    "MotionNoise",
    "held_velocity_variance_step",
    "held_velocity_variance_step_float",
    "dvl_scatter",
    "dvl_sample_sigma",
    "ROBUST_KERNELS",
    "robust_kernel",
]

ROBUST_KERNELS = ("huber", "cauchy")
"""Robust kernels of the line observations (GTSAM's ``noiseModel.mEstimator``)."""


@dataclass(frozen=True)
class MotionNoise:
    """Noise of the motion model, in the units the model integrates: built from a dataset's
    ``[noise]`` (:meth:`from_config`), whose :class:`sonarslam.datasets.config.NoiseConfig` is
    the one place of each value; no defaults of its own.

    Attributes
    ----------
    dvl_sigma_mps : float
        1-sigma of a valid DVL velocity, per axis (m/s).
    ahrs_sigma_rad : float
        1-sigma of the AHRS heading (rad).
    dvl_max_gap_s : float
        A DVL dropout up to this long holds the last valid velocity; longer, the velocity is
        taken as zero with ``gap_sigma_mps``.
    gap_sigma_mps : float
        Velocity 1-sigma added during a dropout (grows linearly to this at ``dvl_max_gap_s``).
    dvl_scatter_window_s : float
        Window (s) of the DVL's own scatter (:func:`dvl_scatter`); 0 turns the excess-scatter
        noise off.
    dvl_nominal_scatter_mps : float
        The scatter of the DVL when it works as usual (m/s): its excess over this is white
        velocity noise added to ``dvl_sigma_mps`` (:func:`dvl_sample_sigma`).
    gap_yaw_rate_sigma_rad_per_s : float
        The vehicle's yaw rate nobody measures while the AHRS is silent, as a 1-sigma (rad/s).
    dvl_stale_s : float
        A valid DVL sample older than this (s) is stale: the DVL is in a gap (no rows, or rows
        without lock), handled as a dropout (:func:`sonarslam.slam.model.motion.velocity_input`).
        The dataset's DVL gap threshold (:mod:`sonarslam.datasets.gates`); infinite: only rows
        without bottom lock make a dropout.
    ahrs_stale_s : float
        An AHRS sample older than this (s) is stale: the AHRS is in a gap; the heading is held
        (dead reckoning) or not turned (closed loops), and its variance grows at
        ``gap_yaw_rate_sigma_rad_per_s``.
    """

    dvl_sigma_mps: float
    ahrs_sigma_rad: float
    dvl_max_gap_s: float
    gap_sigma_mps: float
    dvl_scatter_window_s: float
    dvl_nominal_scatter_mps: float
    gap_yaw_rate_sigma_rad_per_s: float
    dvl_stale_s: float = float("inf")
    ahrs_stale_s: float = float("inf")

    @classmethod
    def from_config(
        cls, noise: NoiseConfig, dvl_stale_s: float = math.inf, ahrs_stale_s: float = math.inf
    ) -> MotionNoise:
        """The motion model's noise from a dataset's ``[noise]``; ``dvl_stale_s`` and
        ``ahrs_stale_s`` are the dataset's gap thresholds (s; infinite: no gaps)."""
        return cls(
            dvl_sigma_mps=noise.dvl_sigma_mps,
            ahrs_sigma_rad=float(np.deg2rad(noise.ahrs_sigma_deg)),
            dvl_max_gap_s=noise.dvl_max_gap_s,
            gap_sigma_mps=noise.dvl_gap_sigma_mps,
            dvl_scatter_window_s=noise.dvl_scatter_window_s,
            dvl_nominal_scatter_mps=noise.dvl_nominal_scatter_mps,
            gap_yaw_rate_sigma_rad_per_s=float(np.deg2rad(noise.ahrs_gap_yaw_rate_sigma_deg_per_s)),
            dvl_stale_s=dvl_stale_s,
            ahrs_stale_s=ahrs_stale_s,
        )

    def ahrs_gap_variance(self, t_prev_s: float, t_s: float, t_ahrs_s: float) -> float:
        """Heading variance (rad^2) a step from ``t_prev_s`` to ``t_s`` adds when the newest
        AHRS sample is from ``t_ahrs_s``: the growth of :meth:`gap_heading_variance`."""
        stale = t_prev_s - t_ahrs_s - self.ahrs_stale_s
        if stale + t_s - t_prev_s <= 0.0:  # not stale by the step's end: both terms are 0
            return 0.0
        grown = self.gap_heading_variance(stale + t_s - t_prev_s)
        return float(grown - self.gap_heading_variance(stale))

    def gap_heading_variance(self, stale_for_s: npt.ArrayLike) -> FloatArray:
        """Heading variance (rad^2) added after an AHRS sample has been held ``stale_for_s``
        seconds past :attr:`ahrs_stale_s` (0 before)."""
        over = np.maximum(np.asarray(stale_for_s, dtype=np.float64), 0.0)
        return np.asarray((self.gap_yaw_rate_sigma_rad_per_s * over) ** 2)


def held_velocity_variance_step(
    held_s: npt.ArrayLike, dt_s: npt.ArrayLike, sigma_mps: npt.ArrayLike
) -> FloatArray:
    """Position variance (m^2, per axis) added by one step while one DVL sample is held.

    The error of a held velocity sample is the same at every step of the hold, so the position
    error over a hold of ``T`` seconds is ``T * sigma`` (variance ``T^2 sigma^2``), not
    ``sqrt(sum dt^2) * sigma``. A step of ``dt`` that ends ``held_s`` after the sample adds
    ``(held_s^2 - (held_s - dt)^2) sigma^2 = (2 held_s - dt) dt sigma^2``.
    """
    T = np.asarray(held_s, dtype=np.float64)
    dt = np.asarray(dt_s, dtype=np.float64)
    return np.asarray((2.0 * T - dt) * dt * np.asarray(sigma_mps, dtype=np.float64) ** 2)


def held_velocity_variance_step_float(held_s: float, dt_s: float, sigma_mps: float) -> float:
    """:func:`held_velocity_variance_step` of one step in plain floats (every record makes
    one): the same operations in the same order (numpy's ``** 2`` is ``x * x``), so the same
    value."""
    return (2.0 * held_s - dt_s) * dt_s * (sigma_mps * sigma_mps)


def dvl_scatter(t_s: FloatArray, v_mps: FloatArray, window_s: float) -> FloatArray:
    """Causal scatter of DVL velocities (m/s, per axis) at each sample: the root mean square of
    ``|v_k - v_{k-1}| / 2`` over the samples of the last ``window_s`` seconds.

    For white noise of 1-sigma ``s`` per axis, ``E |v_k - v_{k-1}|^2 = 4 s^2``, so this
    estimates ``s`` (the Allan deviation at one sample); the vehicle's own accelerations add
    little at ~1 Hz. The first sample has no difference and takes the second's value.

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        Times of the valid samples (s), increasing.
    v_mps : ndarray, shape (N, 2)
        Their velocities (m/s).
    window_s : float
        Averaging window (s), > 0.

    Returns
    -------
    ndarray, shape (N,)
    """
    n = t_s.size
    if n < 2:
        return np.zeros(n)
    d2 = np.concatenate([[np.nan], 0.25 * np.sum(np.diff(v_mps, axis=0) ** 2, axis=1)])
    d2[0] = d2[1]
    csum = np.concatenate([[0.0], np.cumsum(d2)])
    first = np.searchsorted(t_s, t_s - window_s, side="right")
    count = np.arange(1, n + 1) - first
    return np.asarray(np.sqrt((csum[1:] - csum[first]) / count))


def dvl_sample_sigma(t_s: FloatArray, v_mps: FloatArray, noise: MotionNoise) -> FloatArray:
    """1-sigma (m/s, per axis) of each valid DVL sample: ``dvl_sigma_mps``, plus the excess of
    the DVL's own scatter over its nominal scatter taken as white noise,
    ``sqrt(dvl_sigma^2 + max(0, scatter^2 - nominal^2))``.

    ``dvl_sigma_mps`` is the error that accumulates into drift when the DVL works as usual; its
    scatter then is mostly the vehicle's real wobble, which integrates to nothing. When the
    scatter rises above that (the DVL near a bottom it barely locks on), the excess does
    integrate, and the estimators must know.
    """
    base = np.full(t_s.size, noise.dvl_sigma_mps)
    if noise.dvl_scatter_window_s <= 0.0:
        return base
    s = dvl_scatter(t_s, v_mps, noise.dvl_scatter_window_s)
    excess = np.maximum(s**2 - noise.dvl_nominal_scatter_mps**2, 0.0)
    return np.asarray(np.sqrt(base**2 + excess))


def robust_kernel(
    name: str | None, k: float
) -> gtsam.noiseModel.mEstimator.Huber | gtsam.noiseModel.mEstimator.Cauchy | None:
    """GTSAM's m-estimator ``name`` of width ``k`` (sigmas), None for none: the one definition of
    the kernels, for the factor graph's noise models and the EKF's weighted updates
    (``weight(d)`` of a Mahalanobis distance ``d``)."""
    if name is None:
        return None
    if name == "huber":
        return gtsam.noiseModel.mEstimator.Huber.Create(k)
    if name == "cauchy":
        return gtsam.noiseModel.mEstimator.Cauchy.Create(k)
    raise ValueError(f"robust must be None or one of {ROBUST_KERNELS}, got {name!r}")
