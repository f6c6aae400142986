"""The factor graph with its line observations re-decided at a smoothed estimate: the lines
a smoother decides once the revisits (or the lines themselves) have corrected the drift.

:func:`redecided_graph` takes a graph's factor records and an estimate of its variables and,
for ``passes`` passes:

1. puts every line observation at its sonar pose in the estimate (the node's pose composed with
   the record's ``bTs``; a calibrated record's with its ``kTb`` and the estimated mounting
   ``C(0)``, its range scale left out of the decision) and the loop's landmarks as the first
   partition (landmarks tied by a ``LineEquality`` are one);
2. re-decides them (:func:`sonarslam.slam.mapping.redecide.redecide`: stretches of at most
   ``max_stretch_m`` along each line, every observation associated again, those that fit
   nothing dropped);
3. builds the graph again: every factor that is not a line's as it is (odometry, headings,
   priors, scan registrations and revisits, whatever the graph holds), a line observation per
   kept observation on its stretch's landmark ``S(j)`` (its measurement, covariance and kernel
   as the loop made it), no line equality;
4. re-optimises it by Levenberg-Marquardt from the estimate, with each ``S(j)`` at its fitted
   line.

Each pass starts again from the loop's landmarks (an observation dropped in one pass may be
kept in the next) at the previous pass's optimum.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import gtsam
import numpy as np
from gtsam.symbol_shorthand import C, S

from sonarslam.features.geometry import compose
from sonarslam.slam.backends.isam2.graph_io import FactorKind, FactorRecord, pose_of
from sonarslam.slam.mapping.redecide import (
    LineObservations,
    RedecideConfig,
    Redecision,
    redecide,
)

__all__ = [
    "RedecidedGraph",
    "redecided_graph",
    "redecided_records",
    "line_observations",
    "optimise_records",
    "is_line_record",
]

_LINE_KINDS = (FactorKind.LINE_OBSERVATION, FactorKind.LINE_OBSERVATION_CALIBRATED)


def is_line_record(record: FactorRecord) -> bool:
    """A line observation (plain or calibrated)."""
    return record.kind in _LINE_KINDS


@dataclass(frozen=True, eq=False)
class RedecidedGraph:
    """The result of :func:`redecided_graph`.

    Attributes
    ----------
    values : gtsam.Values
        The optimum of the last pass (the graph's poses and other variables, the stretches
        ``S(j)``; the loop's landmarks ``L(j)`` left out).
    records : list of FactorRecord
        The last pass's graph.
    decisions : list of Redecision
        Each pass's decision.
    """

    values: gtsam.Values
    records: list[FactorRecord]
    decisions: list[Redecision]

    def metrics(self) -> dict[str, int]:
        """The last pass's counts (``redecided_*``): observations, kept, dropped, moved to
        another landmark's stretch, stretches."""
        counts = {f"redecided_{k}": v for k, v in self.decisions[-1].counts().items()}
        return {**counts, "redecided_passes": len(self.decisions)}


def line_observations(
    records: list[FactorRecord], values: gtsam.Values
) -> tuple[list[int], LineObservations, np.ndarray]:
    """The graph's line observations at the estimate ``values`` (step 1).

    Returns
    -------
    rows : list of int
        Indices into ``records`` of the line observations, in order.
    obs : LineObservations
        Their sonar poses, measurements and covariances; one vote per (node, ``bTs``).
    landmark : ndarray of int, shape (n,)
        The loop's landmark of each (a ``LineEquality``'s two landmarks share the older's key).
    """
    parent: dict[int, int] = {}

    def root(key: int) -> int:
        while parent.get(key, key) != key:
            key = parent[key]
        return key

    for r in records:
        if r.kind is FactorKind.LINE_EQUALITY:
            a, b = root(r.keys[0]), root(r.keys[1])
            if a != b:
                parent[max(a, b)] = min(a, b)
    mount = np.asarray(values.atVector(C(0))) if values.exists(C(0)) else None
    rows: list[int] = []
    wTs, z, R, votes, owners = [], [], [], [], []
    vote_of: dict[tuple[int, bytes], int] = {}
    for i, r in enumerate(records):
        if r.kind not in _LINE_KINDS:
            continue
        assert r.bTs is not None, "a line observation has its mounting"
        wTk = pose_of(values.atPose2(r.keys[0]))
        if r.kind is FactorKind.LINE_OBSERVATION_CALIBRATED:
            assert r.kTb is not None, "a calibrated line observation has its kTb"
            kTs = compose(r.kTb, r.bTs if mount is None else mount)
        else:
            kTs = r.bTs
        rows.append(i)
        wTs.append(compose(wTk, kTs))
        z.append(r.z)
        R.append(r.cov)
        key = (r.keys[0], np.asarray(kTs).tobytes())
        votes.append(vote_of.setdefault(key, len(vote_of)))
        owners.append(root(r.keys[1]))
    obs = LineObservations(
        np.array(wTs).reshape(-1, 3),
        np.array(z).reshape(-1, 2),
        np.array(R).reshape(-1, 2, 2),
        np.array(votes, dtype=int),
    )
    _, landmark = np.unique(np.array(owners, dtype=np.int64), return_inverse=True)
    return rows, obs, landmark.reshape(-1).astype(int)


def redecided_records(
    records: list[FactorRecord], values: gtsam.Values, config: RedecideConfig
) -> tuple[list[FactorRecord], dict[int, np.ndarray], Redecision]:
    """Steps 1-3: the graph's records with its line observations re-decided at ``values``.

    Returns
    -------
    records : list of FactorRecord
        Every factor that is not a line's as it is, a line observation per kept observation on
        its stretch's landmark ``S(j)``, no line equality.
    lines : dict of int to ndarray
        Each stretch's fitted world line ``(rho_m, theta_rad)`` by its key ``S(j)``: the start
        of its variable.
    decision : Redecision
    """
    rows, obs, landmark = line_observations(records, values)
    decision = redecide(obs, landmark, config)
    row_of = {row: n for n, row in enumerate(rows)}
    out: list[FactorRecord] = []
    for i, r in enumerate(records):
        if r.kind is FactorKind.LINE_EQUALITY:
            continue
        if r.kind in _LINE_KINDS:
            j = int(decision.stretch[row_of[i]])
            if j >= 0:
                out.append(replace(r, keys=(r.keys[0], int(S(j)), *r.keys[2:])))
            continue
        out.append(r)
    lines = {int(S(j)): np.asarray(v) for j, v in enumerate(decision.stretches.lines_w)}
    return out, lines, decision


def _pass(
    records: list[FactorRecord],
    values: gtsam.Values,
    config: RedecideConfig,
    params: gtsam.LevenbergMarquardtParams,
) -> tuple[gtsam.Values, list[FactorRecord], Redecision]:
    """Steps 1-4 once."""
    out, lines, decision = redecided_records(records, values, config)
    return optimise_records(out, values, params, lines), out, decision


def optimise_records(
    records: list[FactorRecord],
    values: gtsam.Values,
    params: gtsam.LevenbergMarquardtParams,
    more: dict[int, np.ndarray] | None = None,
) -> gtsam.Values:
    """Levenberg-Marquardt on ``records`` from ``values`` (their variables only) and ``more``
    (vector variables ``values`` lacks)."""
    graph = gtsam.NonlinearFactorGraph()
    keys: set[int] = set()
    for r in records:
        graph.add(r.to_gtsam())
        keys.update(r.keys)
    start = gtsam.Values()
    for key, vector in (more or {}).items():
        start.insert(key, np.asarray(vector, dtype=np.float64))
    for key in keys - set(more or {}):
        if gtsam.Symbol(key).chr() == ord("x"):
            start.insert(key, values.atPose2(key))
        else:
            start.insert(key, values.atVector(key))
    return gtsam.LevenbergMarquardtOptimizer(graph, start, params).optimize()


def redecided_graph(
    records: list[FactorRecord],
    values: gtsam.Values,
    config: RedecideConfig,
    passes: int = 1,
    params: gtsam.LevenbergMarquardtParams | None = None,
) -> RedecidedGraph:
    """The graph's line observations re-decided at ``values`` and the graph re-optimised
    (module docstring), ``passes`` times.

    Parameters
    ----------
    records : list of FactorRecord
        Every factor of the graph (:attr:`sonarslam.slam.backends.isam2.graph.LineIsam2.records`
        or a ``graph.json``'s).
    values : gtsam.Values
        The estimate to decide at (the smoothed one); every variable of ``records``.
    config : RedecideConfig
    passes : int
        At least 1.
    params : gtsam.LevenbergMarquardtParams, optional
        Default: GTSAM's, at most 50 iterations.

    Returns
    -------
    RedecidedGraph
    """
    if passes < 1:
        raise ValueError(f"passes must be at least 1, got {passes}")
    if params is None:
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(50)
    decisions: list[Redecision] = []
    out = list(records)
    current = values
    for _ in range(passes):
        optimum, out, decision = _pass(records, current, config, params)
        decisions.append(decision)
        current = _merged(values, optimum)  # the loop's landmarks stay where they were
    return RedecidedGraph(optimum, out, decisions)


def _merged(values: gtsam.Values, optimum: gtsam.Values) -> gtsam.Values:
    """``values`` with those of its variables ``optimum`` holds replaced by its."""
    merged = gtsam.Values(values)
    for key in optimum.keys():
        if not merged.exists(key):
            continue
        if gtsam.Symbol(key).chr() == ord("x"):
            merged.update(key, optimum.atPose2(key))
        else:
            merged.update(key, optimum.atVector(key))
    return merged
