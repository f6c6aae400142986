"""Statistics of the extractor on the simulator, with truth poses: the fast version of
``benchmarks/extractor_consistency.py`` (fewer seeds; the benchmark gives the figures).

The pool is the seed paper's test (section 3): 2 m x 4 m, 6 m range, 0.45 deg step, 270 deg sector,
beta 25 deg, min votes 15, four votes per run. The harbour is a 300 s survey at 0.45 m/s with the
extractor's defaults.
"""

from __future__ import annotations

import numpy as np
import pytest

from sonarslam.features.sector import BinsInR
from sonarslam.features.uncertainty import LineEstimate, fit_line
from sonarslam.slam.eval.consistency import mean_nees_band
from sonarslam.slam.run.line_trials import TrialResult, harbour_trial, pool_trial

POOL_SEEDS = range(4)  # the benchmark runs 50; four already give 64 lines per method
RMS_RHO_MAX_M = 0.05  # the pool test's requirement
RMS_THETA_MAX_RAD = float(np.deg2rad(1.0))
# An honest covariance may be conservative, but by at most this factor in variance (mean NEES
# down to the band's lower end / 1.5); it must not be optimistic (mean NEES above the band).
PESSIMISM_FACTOR_MAX = 1.5


@pytest.fixture(scope="module")
def pool() -> dict[str, list[TrialResult]]:
    out: dict[str, list[TrialResult]] = {"fit": [], "seed": []}
    for seed in POOL_SEEDS:
        for r in pool_trial(seed):
            out[r.method].append(r)
    return out


@pytest.fixture(scope="module")
def harbour() -> dict[str, TrialResult]:
    return {r.method: r for r in harbour_trial(0, duration_s=300.0)}


def _nees(results: list[TrialResult]) -> np.ndarray:
    return np.concatenate([r.nees for r in results])


@pytest.mark.parametrize("method", ["fit", "seed"])
def test_pool_every_vote_finds_the_four_walls_and_nothing_else(
    pool: dict[str, list[TrialResult]], method: str
) -> None:
    for r in pool[method]:
        assert r.n_votes == 4
        assert r.votes_all_walls == r.n_votes, f"seed {r.seed}"
    if method == "fit":
        assert sum(r.n_false + r.n_duplicates for r in pool[method]) == 0
        assert sum(r.n_features for r in pool[method]) == 16 * len(POOL_SEEDS)


def test_pool_rms_errors_against_the_true_walls(pool: dict[str, list[TrialResult]]) -> None:
    errors = np.concatenate([r.errors for r in pool["fit"]])
    assert np.sqrt(np.mean(errors[:, 0] ** 2)) < RMS_RHO_MAX_M
    assert np.sqrt(np.mean(errors[:, 1] ** 2)) < RMS_THETA_MAX_RAD


def test_removing_echoes_on_found_lines_prevents_duplicates() -> None:
    """The pool's walls return echoes beyond beta (up to ~60 deg); left in the store they vote for
    spurious lines degrees off the walls. ``remove_on_line_sigma=0`` shows them."""
    off = [pool_trial(s, ("fit",), {"remove_on_line_sigma": 0.0})[0] for s in range(2)]
    assert sum(r.n_false + r.n_duplicates for r in off) >= 4
    errors = np.concatenate([r.errors for r in off])
    assert np.sqrt(np.mean(errors[:, 1] ** 2)) > RMS_THETA_MAX_RAD


def test_fit_covariance_is_honest_on_pool_and_harbour(
    pool: dict[str, list[TrialResult]], harbour: dict[str, TrialResult]
) -> None:
    for nees in (_nees(pool["fit"]), harbour["fit"].nees):
        assert nees.size >= 40
        lo, hi = mean_nees_band(nees.size, 2)
        assert lo / PESSIMISM_FACTOR_MAX < nees.mean() < hi


def test_fit_without_the_common_range_offset_is_optimistic() -> None:
    """The bias of the peak bin is shared by all voters and does not average down: without the
    common-mode term the pool's mean NEES is far above the band."""
    nees = _nees([pool_trial(s, ("fit",), {"range_offset_sigma_m": 0.0})[0] for s in range(2)])
    lo, hi = mean_nees_band(nees.size, 2)
    assert nees.mean() > 2.0 * hi


def test_seed_covariance_is_pessimistic(
    pool: dict[str, list[TrialResult]], harbour: dict[str, TrialResult]
) -> None:
    """The paper's similar-overlap ellipse is wider than the error of its centre."""
    for nees in (_nees(pool["seed"]), harbour["seed"].nees):
        lo, _ = mean_nees_band(nees.size, 2)
        assert nees.mean() < lo


def test_mean_nees_band_covers_95_percent() -> None:
    rng = np.random.default_rng(2010)
    n, trials = 50, 4000
    means = rng.chisquare(2, size=(trials, n)).mean(axis=1)
    lo, hi = mean_nees_band(n, 2)
    inside = np.mean((means >= lo) & (means <= hi))
    assert inside == pytest.approx(0.95, abs=0.012)  # ~3.5 sd of a binomial over 4000 trials
    assert lo < 2.0 < hi
    with pytest.raises(ValueError):
        mean_nees_band(0, 2)


def test_common_range_offset_term_is_the_fit_s_numerical_sensitivity() -> None:
    """``P + sigma_c^2 g g^T``: ``g`` is the change of the fitted line per metre of a range offset
    shared by all the bins, checked by refitting with every range shifted (bins on the line, so
    that the first-order sensitivity is exact)."""
    rng = np.random.default_rng(11)
    n = 60
    rho_true, theta_true = 9.0, 0.3
    bearing = theta_true + rng.uniform(-0.4, 0.4, n)
    x_s, y_s = rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n)
    along = rho_true - x_s * np.cos(theta_true) - y_s * np.sin(theta_true)
    r = along / np.cos(bearing - theta_true)  # on the line: no residual terms in the sensitivity
    kw = dict(
        beam_width_rad=np.deg2rad(3.0), range_sigma_m=0.03, bearing_sigma_rad=0.015, n_iter=20
    )

    def fit(dr: float, sigma_c: float = 0.0) -> LineEstimate:
        bins = BinsInR(x_s, y_s, bearing, r + dr, np.arange(n, dtype=np.int64))
        return fit_line(bins, rho_true, theta_true, range_offset_sigma_m=sigma_c, **kw)

    eps = 1e-6
    g = (
        np.array([fit(eps).rho_m, fit(eps).theta_rad]) - [fit(-eps).rho_m, fit(-eps).theta_rad]
    ) / (2 * eps)
    sigma_c = 0.05
    added = fit(0.0, sigma_c).cov - fit(0.0).cov
    np.testing.assert_allclose(added, sigma_c**2 * np.outer(g, g), rtol=1e-5, atol=1e-14)
    assert g[0] == pytest.approx(1.0, abs=0.05)  # the line moves by about the offset
