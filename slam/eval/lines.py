"""Line features against the simulator's true walls: matching, errors, NEES and their chi2 band.

A feature ``(rho, theta)`` with covariance ``P`` lives in its frame R (pose ``wTr``). A true wall
is a world segment; its infinite line, expressed in R with
:func:`features.geometry.line_world_to_frame`, is the truth of any feature lying on it.

* Matching (:func:`match_features`): each feature goes to the true wall whose infinite line is
  nearest to the feature's segment, the distance being the larger of the distances of the two
  world endpoints to the line (m); this is sign-free (it does not depend on the normal's
  direction) and treats collinear walls as the same line, as a line feature must. A feature is
  *matched* when that distance is at most ``gate_m`` and the angle between the lines at most
  ``gate_rad``; otherwise it is *false*.
* Error (:func:`line_error_r`): ``e = (rho - rho_true, wrap(theta - theta_true))`` in R, taken
  sign-free: the true line is also written ``(-rho_true, theta_true + pi)`` and the smaller error
  kept (the two differ only for lines through the sensor).
* NEES ``e^T P^-1 e``: for a consistent estimator a chi2 variable with 2 degrees of freedom; the
  mean of ``N`` independent ones lies in ``chi2.ppf([0.025, 0.975], 2 N) / N`` with probability
  0.95 (:func:`mean_nees_band`).

Trials (:func:`pool_trial`, :func:`harbour_trial`) simulate a run in memory, extract its lines
with the true poses (so that only the front end is measured) and compare them with the walls;
``benchmarks/extractor_consistency.py`` and ``tests/test_extraction_stats.py`` use them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import stats

from datasets.simulator import Simulation, make_scenario, simulate_records
from features.extractor import ExtractorConfig, LineExtractor
from features.geometry import FloatArray, line_world_to_frame, normalize_line, wrap_angle
from features.line import LineFeature
from sonar.store import sector_beam_count

__all__ = [
    "Match",
    "wall_lines_world",
    "line_error_r",
    "match_features",
    "nees",
    "mean_nees_band",
    "POOL_GATE_M",
    "HARBOUR_GATE_M",
    "GATE_RAD",
    "TrialResult",
    "pool_config",
    "extract_simulation",
    "pool_trial",
    "harbour_trial",
]


@dataclass(frozen=True)
class Match:
    """A feature against its nearest true wall.

    Attributes
    ----------
    wall : int
        Index of the nearest wall (by line).
    distance_m : float
        Larger distance of the feature's world endpoints to that wall's line (m).
    error : ndarray, shape (2,)
        ``(rho_m, theta_rad)`` error in R, sign-free (:func:`line_error_r`).
    nees : float
        ``error^T cov^-1 error``.
    matched : bool
        Inside the gates of :func:`match_features`.
    """

    wall: int
    distance_m: float
    error: FloatArray
    nees: float
    matched: bool


def wall_lines_world(walls_m: npt.ArrayLike) -> FloatArray:
    """Normalised world lines of wall segments.

    Parameters
    ----------
    walls_m : array_like, shape (S, 2, 2)
        Segments ``[[x0, y0], [x1, y1]]`` (world, m).

    Returns
    -------
    ndarray, shape (S, 2)
        ``(rho_m, theta_rad)`` with ``rho >= 0`` and ``theta`` in ``[-pi, pi)``.
    """
    w = np.asarray(walls_m, dtype=np.float64)
    d = w[:, 1] - w[:, 0]
    normal = np.stack([d[:, 1], -d[:, 0]], axis=-1) / np.linalg.norm(d, axis=-1, keepdims=True)
    rho = np.einsum("ij,ij->i", normal, w[:, 0])
    theta = np.arctan2(normal[:, 1], normal[:, 0])
    rho_n, theta_n = normalize_line(rho, theta)
    return np.stack([rho_n, theta_n], axis=-1)


def line_error_r(feature: LineFeature, line_w: npt.ArrayLike) -> FloatArray:
    """Sign-free error of a feature against a world line, in the feature's frame R.

    Parameters
    ----------
    feature : LineFeature
    line_w : array_like, shape (2,)
        True world line ``(rho_m, theta_rad)``.

    Returns
    -------
    ndarray, shape (2,)
        ``(rho_m, theta_rad)`` error.
    """
    lr = line_world_to_frame(line_w, feature.wTr)[0]
    e1 = np.array([feature.rho_m - lr[0], float(wrap_angle(feature.theta_rad - lr[1]))])
    e2 = np.array([feature.rho_m + lr[0], float(wrap_angle(feature.theta_rad - lr[1] - np.pi))])
    return e1 if abs(e1[0]) + abs(e1[1]) <= abs(e2[0]) + abs(e2[1]) else e2


def nees(error: npt.ArrayLike, cov: npt.ArrayLike) -> float:
    """Normalised estimation error squared ``e^T P^-1 e``."""
    e = np.asarray(error, dtype=np.float64)
    return float(e @ np.linalg.solve(np.asarray(cov, dtype=np.float64), e))


def match_features(
    features: list[LineFeature],
    walls_m: npt.ArrayLike,
    gate_m: float,
    gate_rad: float,
) -> list[Match]:
    """Each feature against the nearest true wall line (module docstring).

    Parameters
    ----------
    features : list of LineFeature
        With world poses ``wTr`` in the frame of ``walls_m``.
    walls_m : array_like, shape (S, 2, 2)
        True wall segments (world, m).
    gate_m : float
        Largest endpoint distance of a matched feature (m).
    gate_rad : float
        Largest angle between a matched feature and its wall (rad).

    Returns
    -------
    list of Match
        One per feature, in order.
    """
    lines_w = wall_lines_world(walls_m)
    normals = np.stack([np.cos(lines_w[:, 1]), np.sin(lines_w[:, 1])], axis=-1)  # (S, 2)
    out: list[Match] = []
    for ft in features:
        ends = ft.endpoints_world()  # (2, 2)
        dist = np.abs(ends @ normals.T - lines_w[None, :, 0]).max(axis=0)  # (S,)
        k = int(np.argmin(dist))
        e = line_error_r(ft, lines_w[k])
        ok = bool(dist[k] <= gate_m and abs(e[1]) <= gate_rad)
        out.append(Match(k, float(dist[k]), e, nees(e, ft.cov), ok))
    return out


def mean_nees_band(n: int, dof: int = 2, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided ``probability`` interval of the mean of ``n`` independent chi2(``dof``) NEES.

    ``chi2.ppf([(1 - p) / 2, (1 + p) / 2], dof n) / n``: at 0.95 and 2 dof, (1.76, 2.25) for
    n = 500.
    """
    if n < 1:
        raise ValueError(f"need at least one NEES, got n={n}")
    a = 0.5 * (1.0 - probability)
    lo, hi = stats.chi2.ppf([a, 1.0 - a], dof * n) / n
    return float(lo), float(hi)


# -- trials on the simulator ---------------------------------------------------------------------

#: Largest endpoint distance (m) and angle (rad) of a matched feature: pool (1.2 cm bins, walls
#: 0.8-2.5 m away) and harbour (10 cm bins, walls up to 50 m away).
POOL_GATE_M = 0.1
HARBOUR_GATE_M = 1.0
GATE_RAD = float(np.deg2rad(5.0))


def pool_config(
    covariance_method: str = "fit", step_rad: float = float(np.deg2rad(0.45))
) -> ExtractorConfig:
    """The seed paper's pool settings (section 3): 270 deg sector, beta 25 deg, min votes 15,
    one vote per full sector (``vote_every_n_beams`` = the sector's beams, 600 at 0.45 deg);
    the rest are the extractor's defaults."""
    sector_deg = 270.0
    return ExtractorConfig(
        sector_deg=sector_deg,
        incidence_beta_rad=float(np.deg2rad(25.0)),
        min_votes=15,
        vote_every_n_beams=sector_beam_count(float(np.deg2rad(sector_deg)), step_rad),
        covariance_method=covariance_method,
    )


def extract_simulation(
    sim: Simulation, config: ExtractorConfig, flush: bool = True
) -> list[LineFeature]:
    """Run the extractor over a simulated run with the true poses (world frame).

    Parameters
    ----------
    sim : Simulation
    config : ExtractorConfig
    flush : bool
        Vote once more on what is stored after the last beam.
    """
    sc = sim.scenario
    ex = LineExtractor(config, sc.head, sc.sonar_mounting, sim.trajectory)
    lines: list[LineFeature] = []
    for beam in sim.beams:
        lines += ex.add(beam)
    return lines + ex.flush() if flush else lines


@dataclass
class TrialResult:
    """Features of one simulated run against its walls.

    Attributes
    ----------
    kind : str
        ``"pool"`` or ``"harbour"``.
    seed : int
    method : str
        Covariance method.
    n_features, n_false : int
        All features; those outside the gates.
    errors : ndarray, shape (K, 2)
        ``(rho_m, theta_rad)`` errors of the K matched features.
    nees : ndarray, shape (K,)
    votes_all_walls : int
        Pool: votes (frames R) in which every wall was matched by some feature.
    n_votes : int
        Votes with at least one feature (pool: all votes made).
    n_duplicates : int
        Pool: features matched to a wall already matched in the same vote.
    """

    kind: str
    seed: int
    method: str
    n_features: int
    n_false: int
    errors: FloatArray
    nees: FloatArray
    votes_all_walls: int = 0
    n_votes: int = 0
    n_duplicates: int = 0


def _result(
    kind: str,
    seed: int,
    method: str,
    features: list[LineFeature],
    matches: list[Match],
    n_walls: int,
    n_votes: int,
) -> TrialResult:
    ok = [m for m in matches if m.matched]
    by_vote: dict[float, list[int]] = {}
    for ft, m in zip(features, matches, strict=True):
        if m.matched:
            by_vote.setdefault(ft.t, []).append(m.wall)
    all_walls = sum(len(set(w)) == n_walls for w in by_vote.values())
    dup = sum(len(w) - len(set(w)) for w in by_vote.values())
    return TrialResult(
        kind=kind,
        seed=seed,
        method=method,
        n_features=len(features),
        n_false=len(features) - len(ok),
        errors=np.array([m.error for m in ok]).reshape(-1, 2),
        nees=np.array([m.nees for m in ok]),
        votes_all_walls=int(all_walls),
        n_votes=n_votes,
        n_duplicates=int(dup),
    )


def pool_trial(
    seed: int,
    methods: tuple[str, ...] = ("fit", "seed"),
    config_changes: dict[str, Any] | None = None,
) -> list[TrialResult]:
    """The seed paper's pool test on ``make_scenario("pool", seed)``, one result per method.

    The 165 s run is four full 270 deg sectors (2400 beams) and 25 beams: one vote per sector,
    no flush, so that every vote sees one fresh 270 deg scan, as in the paper.
    ``config_changes`` replace fields of :func:`pool_config`.
    """
    sim = simulate_records(make_scenario("pool", seed))
    out = []
    for method in methods:
        cfg = pool_config(method, sim.scenario.head.step_rad).replace(**(config_changes or {}))
        feats = extract_simulation(sim, cfg, flush=False)
        matches = match_features(feats, sim.world.walls_m, POOL_GATE_M, GATE_RAD)
        n_votes = len(sim.beams) // cfg.vote_every_n_beams
        out.append(_result("pool", seed, method, feats, matches, len(sim.world.walls_m), n_votes))
    return out


def harbour_trial(
    seed: int,
    methods: tuple[str, ...] = ("fit", "seed"),
    duration_s: float | None = None,
    config_changes: dict[str, Any] | None = None,
) -> list[TrialResult]:
    """The extractor's defaults on ``make_scenario("harbour", seed)`` (a vehicle surveying a
    marina-like harbour at 0.45 m/s, raw beams), with the true poses; one result per method.
    ``config_changes`` replace fields of the default :class:`ExtractorConfig`."""
    sim = simulate_records(make_scenario("harbour", seed, duration_s))
    out = []
    for method in methods:
        cfg = ExtractorConfig(covariance_method=method).replace(**(config_changes or {}))
        feats = extract_simulation(sim, cfg)
        matches = match_features(feats, sim.world.walls_m, HARBOUR_GATE_M, GATE_RAD)
        n_votes = len({ft.t for ft in feats})
        out.append(
            _result("harbour", seed, method, feats, matches, len(sim.world.walls_m), n_votes)
        )
    return out
