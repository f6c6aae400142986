"""Statistics of line errors against references: bias, scatter, claimed sigmas and the NEES.

For ``N`` lines with errors ``e = (rho - rho_ref, theta - theta_ref)`` in their frames R and
covariances ``P`` (:mod:`sonarslam.slam.eval.line_quality`):

* bias (mean), median, scatter (standard deviation) and RMS of ``e_rho`` (m) and ``e_theta``
  (deg), beside the sigmas the covariances claim (median of their square roots);
* NEES ``e^T P^-1 e`` (:func:`sonarslam.slam.eval.consistency.nees`): chi2 with 2 degrees of freedom if
  ``(rho, theta)`` and ``P`` are honest; its median is then 1.386, its mean 2, and 1 % of it
  lies beyond the 99 % gate (:func:`sonarslam.slam.eval.consistency.chi2_gate`, 9.21);
* over several walls, the *per-wall scatter*: the pooled within-wall standard deviation (each
  line about its wall's mean error), what a landmark of that wall sees (:func:`pooled_sd`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from sonarslam.features.geometry import FloatArray
from sonarslam.slam.eval.consistency import chi2_gate

__all__ = ["GATE_PROBABILITY", "NEES_QUANTILES", "error_stats", "pooled_sd"]

_MAD_TO_SIGMA = 1.4826  # a normal variable's standard deviation per median absolute deviation

#: Probability of the NEES gate whose exceedances are counted (chi2 with 2 dof: 9.21).
GATE_PROBABILITY = 0.99

#: Quantiles of the NEES that the statistics give.
NEES_QUANTILES = (0.1, 0.25, 0.5, 0.75, 0.9)


def error_stats(
    errors: npt.ArrayLike, nees_values: npt.ArrayLike, covs: npt.ArrayLike
) -> dict[str, Any]:
    """Statistics of a set of lines (module docstring).

    Parameters
    ----------
    errors : array_like, shape (N, 2)
        ``(rho_m, theta_rad)`` errors in R.
    nees_values : array_like, shape (N,)
    covs : array_like, shape (N, 2, 2)
        The lines' covariances.

    Returns
    -------
    dict
        ``n``; ``rho_bias_m``, ``rho_median_m``, ``rho_sd_m``, ``rho_rms_m``,
        ``rho_robust_sd_m`` (1.4826 MAD: the scatter without the tails); the same for
        ``theta`` in degrees; ``claimed_sigma_rho_m``, ``claimed_sigma_theta_deg`` (medians of
        the covariances' square roots); ``nees_mean``, ``nees_q10`` ... ``nees_q90``
        (``nees_median`` = ``nees_q50``), ``outside_gate`` (share beyond the 99 % chi2(2) gate).
        NaN (``n`` = 0) without lines; standard deviations NaN below two lines.
    """
    e = np.asarray(errors, dtype=np.float64).reshape(-1, 2)
    q = np.asarray(nees_values, dtype=np.float64).reshape(-1)
    P = np.asarray(covs, dtype=np.float64).reshape(-1, 2, 2)
    n = int(e.shape[0])
    out: dict[str, Any] = {"n": n}
    for name, col, scale in (("rho", 0, 1.0), ("theta", 1, float(np.rad2deg(1.0)))):
        unit = "m" if name == "rho" else "deg"
        x = e[:, col] * scale
        out[f"{name}_bias_{unit}"] = float(np.mean(x)) if n else float("nan")
        out[f"{name}_median_{unit}"] = float(np.median(x)) if n else float("nan")
        out[f"{name}_sd_{unit}"] = float(np.std(x, ddof=1)) if n > 1 else float("nan")
        out[f"{name}_rms_{unit}"] = float(np.sqrt(np.mean(x**2))) if n else float("nan")
        mad = np.median(np.abs(x - np.median(x))) if n else float("nan")
        out[f"{name}_robust_sd_{unit}"] = float(_MAD_TO_SIGMA * mad)
        claimed = np.sqrt(P[:, col, col]) * scale
        out[f"claimed_sigma_{name}_{unit}"] = float(np.median(claimed)) if n else float("nan")
    out["nees_mean"] = float(np.mean(q)) if n else float("nan")
    for p in NEES_QUANTILES:
        out[f"nees_q{round(100 * p)}"] = float(np.quantile(q, p)) if n else float("nan")
    out["nees_median"] = out["nees_q50"]
    gate = chi2_gate(2, GATE_PROBABILITY)
    out["outside_gate"] = float(np.mean(q > gate)) if n else float("nan")
    return out


def pooled_sd(errors: FloatArray, groups: npt.NDArray[np.int64]) -> FloatArray:
    """Pooled within-group standard deviation of each column of ``errors`` (N, 2)."""
    resid = []
    n_groups = 0
    for g in np.unique(groups):
        x = errors[groups == g]
        if x.shape[0] >= 2:
            resid.append(x - x.mean(axis=0))
            n_groups += 1
    if not resid:
        return np.full(2, np.nan)
    r = np.concatenate(resid)
    return np.asarray(np.sqrt(np.sum(r**2, axis=0) / (r.shape[0] - n_groups)))
