"""The factor-level check of a run's graph: the same graph re-optimised in batch with factor
families dropped or swapped, each scored against the ruler. A benchmark only: the ruler (GPS on
the marina, the simulator's truth on simulated data) never feeds an estimator.

python benchmarks/marina_factor_levels.py --run DIR \\
    [--reference ../shared/reference/marina-posegraph/factors-revisits-only.json] \\
    [--graphs dr+heading,dr+heading+lines,...] [--out out/factor_levels.json]

DIR is an iSAM2 run directory (``sonarslam run marina --backend isam2 --out DIR``; its
``graph.json`` holds every factor and the nodes' times). The benchmark

1. reads the graph's factors (:meth:`sonarslam.slam.backends.isam2.graph_io.FactorRecord.from_json`)
   and sorts them into families: ``dr`` (the start prior, the priors on vectors and the odometry
   between consecutive nodes), ``heading`` (the AHRS heading factors and the bias chain),
   ``lines`` (line observations and equalities), ``scans`` (consecutive scan registrations),
   ``revisits`` (the product's revisit registrations);
2. optionally adds the family ``reference``: a reference pose graph's revisits (its ``rev``:
   nodes ``i``, ``j`` at ``t_nodes``, ``T = inverse(wTi) * wTj``, ``cov``, ``robust``) moved onto
   the product's nodes nearest the reference's node times, with dead reckoning's relative motion
   between each reference time and its node time composed in
   (``z = between(DR(t_a), DR(t_i)) * T * between(DR(t_j), DR(t_b))``), the reference's
   covariance and kernel; with ``--reference-pairs``, the family ``refpairs``: the product's own
   registrations at the reference's pairs (``benchmarks/marina_reference_pairs.py --out``),
   moved the same way, with their covariance and the product's revisit kernel;
3. re-optimises each requested combination of families (``--graphs``, ``+``-joined family names,
   comma-separated; ``product`` is every factor of the run) with Levenberg-Marquardt from the
   run's saved values (the variables no factor of the combination touches are left out);
4. with ``--cut-m M1,M2``, scores each combination with lines again with every landmark's
   observations cut into stretches of ``M`` m along its line (by the foot of the sonar's
   perpendicular on the line, at the run's saved estimate: GPS-free), each stretch its own
   landmark (:func:`cut_lines`): how a landmark model of bounded length would do;
   with ``--variants``, each combination with lines again with the line observations changed
   one way at a time (:data:`LINE_VARIANTS`: covariance x2 or x4, σθ x2, σρ x2, θ shifted by
   ∓0.52° (the issue's mean θ residual), only ρ < 30 m, no robust kernel): the tests of a
   systematic error of the lines or of their covariance;
5. scores each against the ruler over the sonar span: ATE mean / max unaligned, after a rigid
   SE(2) fit (mean / max), and the fit's shift (the mean displacement of the estimate's positions
   at the fixes, (x, y) in m: the opposite of where the estimate sits against the ruler).
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip
from common import write_result  # isort: skip

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import gtsam
import numpy as np
from evo.core.geometry import GeometryException, umeyama_alignment

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import Dataset, open_dataset
from sonarslam.features.geometry import between, compose, compose_jacobians
from sonarslam.slam.backends.isam2.graph_io import (
    FactorKind,
    FactorRecord,
    Robust,
    key_of,
    pose_of,
)
from sonarslam.slam.backends.isam2.redecided import optimise_records
from sonarslam.slam.eval.truth import truth_trajectory
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.model.lines import local_to_world
from sonarslam.slam.run.sources import dead_reckoning_trajectory

FAMILIES = ("dr", "heading", "lines", "scans", "revisits", "reference", "refpairs")

#: The combinations scored by default (those whose families the graph holds).
DEFAULT_GRAPHS = (
    "product",
    "dr+heading",
    "dr+heading+lines",
    "dr+heading+revisits",
    "dr+heading+revisits+lines",
    "dr+heading+revisits+scans",
    "dr+heading+revisits+scans+lines",
    "dr+heading+reference",
    "dr+heading+reference+lines",
    "dr+heading+reference+scans",
    "dr+heading+reference+scans+lines",
    "dr+heading+reference+revisits",
    "dr+heading+reference+revisits+lines",
    "dr+heading+refpairs",
    "dr+heading+refpairs+lines",
)


def family_of(record: FactorRecord) -> str:
    """The family of a factor (step 1)."""
    kind = record.kind
    if kind in (FactorKind.LINE_OBSERVATION, FactorKind.LINE_OBSERVATION_CALIBRATED):
        return "lines"
    if kind is FactorKind.LINE_EQUALITY:
        return "lines"
    if kind in (FactorKind.HEADING_BIAS, FactorKind.BETWEEN_VECTOR):
        return "heading"
    if record.constraint is not None:
        if record.constraint.startswith("reference"):
            return "reference"
        if record.constraint.startswith("refpairs"):
            return "refpairs"
        if "revisit" in record.constraint:
            return "revisits"
        if "consecutive" in record.constraint:
            return "scans"
    return "dr"


def reference_records(
    reference: dict[str, Any], node_t: dict[str, float], dr: Trajectory
) -> list[FactorRecord]:
    """The reference's revisits moved onto the product's nodes (step 2); a pair whose two
    times fall on one node is left out."""
    names = sorted(node_t, key=lambda n: node_t[n])
    t = np.array([node_t[n] for n in names])
    t_ref = np.asarray(reference["t_nodes"], dtype=np.float64)
    out = []
    for pair in reference["rev"]:
        ti, tj = float(t_ref[pair["i"]]), float(t_ref[pair["j"]])
        a, b = int(np.argmin(np.abs(t - ti))), int(np.argmin(np.abs(t - tj)))
        if a == b:
            continue
        Pa, Pi, Pj, Pb = dr.poses(np.array([t[a], ti, tj, t[b]]))
        z = compose(
            compose(between(Pa, Pi), np.asarray(pair["T"], dtype=np.float64)), between(Pj, Pb)
        )
        robust = None
        name = str(pair.get("robust") or "")
        for kernel in ("cauchy", "huber"):
            if name.startswith(kernel):
                robust = Robust(kernel, float(name[len(kernel) :] or 1.0))
        out.append(
            FactorRecord.of(
                FactorKind.BETWEEN_POSE,
                [key_of(names[a]), key_of(names[b])],
                z,
                pair["cov"],
                robust=robust,
                constraint="reference-revisit",
            )
        )
    return out


def reference_pair_records(
    pairs: dict[str, Any],
    reference: dict[str, Any],
    node_t: dict[str, float],
    dr: Trajectory,
    robust: Robust | None,
) -> list[FactorRecord]:
    """The product's own registrations at the reference's pairs (``pairs``: the JSON of
    ``benchmarks/marina_reference_pairs.py --out``, its rows' ``z_nodes`` and ``cov_nodes``
    between the reference's node times), those its registration accepted, moved onto the
    product's nearest nodes as :func:`reference_records` moves the reference's, with the
    product's kernel (``robust``): the family ``refpairs``."""
    names = sorted(node_t, key=lambda n: node_t[n])
    t = np.array([node_t[n] for n in names])
    t_ref = np.asarray(reference["t_nodes"], dtype=np.float64)
    out = []
    for row in pairs["rows"]:
        if not row["accepted"]:
            continue
        ti, tj = float(t_ref[row["i"]]), float(t_ref[row["j"]])
        a, b = int(np.argmin(np.abs(t - ti))), int(np.argmin(np.abs(t - tj)))
        if a == b:
            continue
        Pa, Pi, Pj, Pb = dr.poses(np.array([t[a], ti, tj, t[b]]))
        iTj = np.asarray(row["z_nodes"], dtype=np.float64)
        aTj = compose(between(Pa, Pi), iTj)
        z = compose(aTj, between(Pj, Pb))
        _, J1 = compose_jacobians(between(Pa, Pi), iTj)
        J2, _ = compose_jacobians(aTj, between(Pj, Pb))
        J = local_to_world(-float(z[2])) @ J2 @ J1  # plain iTj -> the tangent at z
        cov = J @ np.asarray(row["cov_nodes"], dtype=np.float64) @ J.T
        out.append(
            FactorRecord.of(
                FactorKind.BETWEEN_POSE,
                [key_of(names[a]), key_of(names[b])],
                z,
                0.5 * (cov + cov.T),
                robust=robust,
                constraint="refpairs-revisit",
            )
        )
    return out


def optimise(records: Sequence[FactorRecord], values: gtsam.Values) -> gtsam.Values:
    """Levenberg-Marquardt on the records from ``values`` (those of their keys only), at most
    100 iterations (the product's :func:`optimise_records`)."""
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    return optimise_records(list(records), values, params)


def node_trajectory(values: gtsam.Values, node_t: dict[str, float]) -> Trajectory:
    """The nodes' poses in time order."""
    names = sorted((n for n in node_t if values.exists(key_of(n))), key=lambda n: node_t[n])
    poses = np.array(
        [[p.x(), p.y(), p.theta()] for p in (values.atPose2(key_of(n)) for n in names)]
    )
    return Trajectory(np.array([node_t[n] for n in names]), poses)


def scores(tr: Trajectory, ruler_t: np.ndarray, ruler_xy: np.ndarray) -> dict[str, float]:
    """ATE (m) at the ruler's positions inside the trajectory's span: mean, max, aligned mean,
    aligned max, the rigid fit's shift (step 5) and its translation (``fit_t``, the rotation about
    the origin of the local frame)."""
    keep = (ruler_t >= tr.span_s[0]) & (ruler_t <= tr.span_s[1])
    est = tr.poses(ruler_t[keep])[:, :2]
    ref = ruler_xy[keep]
    err = np.hypot(*(est - ref).T)
    try:
        rot, shift, _ = umeyama_alignment(est.T, ref.T, False)
        fit = (rot @ est.T).T + shift
        fit_t = shift
    except GeometryException:
        fit = est - est.mean(axis=0) + ref.mean(axis=0)
        fit_t = ref.mean(axis=0) - est.mean(axis=0)
    err_a = np.hypot(*(fit - ref).T)
    d = (fit - est).mean(axis=0)
    return {
        "mean_m": float(err.mean()),
        "max_m": float(err.max()),
        "aligned_mean_m": float(err_a.mean()),
        "aligned_max_m": float(err_a.max()),
        "shift_x_m": float(d[0]),
        "shift_y_m": float(d[1]),
        "fit_t_x_m": float(fit_t[0]),
        "fit_t_y_m": float(fit_t[1]),
    }


def ruler_of(ds: Dataset) -> tuple[str, np.ndarray, np.ndarray]:
    """The ruler's name, times (s) and positions (N, 2) over the sonar span."""
    t0, t1 = ds.sonar_span_s
    if ds.truth is not None:
        truth = truth_trajectory(ds)
        keep = (truth.t_s >= t0) & (truth.t_s <= t1)
        return "truth", truth.t_s[keep], truth.poses_wTb[keep, :2]
    assert ds.gps is not None
    keep = (ds.gps.t >= t0) & (ds.gps.t <= t1)
    return "gps", ds.gps.t[keep], ds.gps.en_m[keep]


def load_run(
    run: Path,
) -> tuple[dict[str, Any], list[FactorRecord], gtsam.Values, dict[str, float], Dataset]:
    """A run's ``graph.json`` document, its factors, saved values and node times, and its
    dataset (from ``metrics.json``'s ``source``)."""
    path = run / "graph.json"
    doc = json.loads(path.read_text())
    ds = open_dataset(json.loads((run / "metrics.json").read_text())["source"])
    records = [
        FactorRecord.from_json(f, f"{path}: factor {i}") for i, f in enumerate(doc["factors"])
    ]
    values = gtsam.Values()
    for name, item in doc["values"].items():
        v = np.asarray(item["value"], dtype=np.float64)
        values.insert(key_of(name), gtsam.Pose2(*v) if item["type"] == "Pose2" else v.reshape(-1))
    node_t = {k: float(v) for k, v in doc["meta"]["node_times_s"].items()}
    return doc, records, values, node_t, ds


def _scaled(r: FactorRecord, a: float, b: float) -> FactorRecord:
    d = np.diag([a, b])
    return replace(r, cov=d @ r.cov @ d)


def _theta_shifted(r: FactorRecord, deg: float) -> FactorRecord:
    return replace(r, z=r.z - np.array([0.0, np.deg2rad(deg)]))


#: One change of the line observations at a time (step 4's ``--variants``); None drops one.
LINE_VARIANTS: dict[str, Callable[[FactorRecord], FactorRecord | None]] = {
    "covariance x2": lambda r: _scaled(r, 2**0.5, 2**0.5),
    "covariance x4": lambda r: _scaled(r, 2.0, 2.0),
    "sigma theta x2": lambda r: _scaled(r, 1.0, 2.0),
    "sigma rho x2": lambda r: _scaled(r, 2.0, 1.0),
    "theta -0.52 deg": lambda r: _theta_shifted(r, 0.52),
    "theta +0.52 deg": lambda r: _theta_shifted(r, -0.52),
    "rho < 30 m": lambda r: r if abs(float(r.z[0])) < 30.0 else None,
    "no robust kernel": lambda r: replace(r, robust=None),
}


def line_variant(
    records: Sequence[FactorRecord], change: Callable[[FactorRecord], FactorRecord | None]
) -> list[FactorRecord]:
    """The records with ``change`` applied to every line observation (None drops it)."""
    out = []
    for r in records:
        if r.kind is FactorKind.LINE_OBSERVATION:
            changed = change(r)
            if changed is not None:
                out.append(changed)
        else:
            out.append(r)
    return out


def cut_lines(
    records: Sequence[FactorRecord], values: gtsam.Values, stretch_m: float
) -> tuple[list[FactorRecord], gtsam.Values]:
    """The records with each line observation moved to a landmark per ``stretch_m`` of its
    landmark's line (step 4), and values with those landmarks (at their landmark's saved
    line); the other records as they are. Line equalities are dropped."""
    out_values = gtsam.Values(values)
    out: list[FactorRecord] = []
    stretches: dict[tuple[int, int], int] = {}
    for r in records:
        if r.kind is FactorKind.LINE_EQUALITY:
            continue
        if r.kind is not FactorKind.LINE_OBSERVATION:
            out.append(r)
            continue
        assert r.bTs is not None, "a line observation has its mounting"
        line = np.asarray(values.atVector(r.keys[1]))
        wTs = compose(pose_of(values.atPose2(r.keys[0])), r.bTs)
        along = -wTs[0] * np.sin(line[1]) + wTs[1] * np.cos(line[1])
        which = (r.keys[1], int(np.floor(along / stretch_m)))
        if which not in stretches:
            stretches[which] = int(gtsam.Symbol("l", 100000 + len(stretches)).key())
            out_values.insert(stretches[which], line)
        out.append(replace(r, keys=(r.keys[0], stretches[which])))
    return out, out_values


def factor_levels(
    records: Sequence[FactorRecord],
    values: gtsam.Values,
    node_t: dict[str, float],
    ruler: tuple[np.ndarray, np.ndarray],
    graphs: Sequence[str],
) -> dict[str, dict[str, Any]]:
    """The scores of each combination (``graphs``) whose families the records hold."""
    by_family: dict[str, list[FactorRecord]] = {f: [] for f in FAMILIES}
    for r in records:
        by_family[family_of(r)].append(r)
    out: dict[str, dict[str, Any]] = {}
    for name in graphs:
        parts = list(FAMILIES) if name == "product" else name.split("+")
        unknown = [p for p in parts if p not in FAMILIES]
        if unknown:
            raise ValueError(f"--graphs: {name!r}: unknown families {unknown} (of {FAMILIES})")
        if name == "product":
            parts = [p for p in parts if p not in ("reference", "refpairs")]
        elif any(not by_family[p] for p in parts):
            continue
        chosen = [r for p in parts for r in by_family[p]]
        est = optimise(chosen, values)
        row: dict[str, Any] = {"factors": {p: len(by_family[p]) for p in parts}}
        row.update(scores(node_trajectory(est, node_t), *ruler))
        out[name] = row
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--run", type=Path, required=True, help="an iSAM2 run directory")
    ap.add_argument("--reference", type=Path, default=None, help="a reference graph's JSON")
    ap.add_argument(
        "--reference-pairs",
        type=Path,
        default=None,
        help="the JSON of benchmarks/marina_reference_pairs.py --out (the family refpairs)",
    )
    ap.add_argument("--graphs", default=",".join(DEFAULT_GRAPHS), help="combinations to score")
    ap.add_argument("--cut-m", default="", help="stretch lengths M1,M2 (m) to cut lines into")
    ap.add_argument("--variants", action="store_true", help="the line variants too (step 4)")
    ap.add_argument("--out", type=Path, default=None, help="JSON of the scores")
    args = ap.parse_args(argv)
    try:
        doc, records, values, node_t, ds = load_run(args.run)
        reference = None if args.reference is None else json.loads(args.reference.read_text())
    except (OSError, KeyError, ValueError, DataError) as exc:
        print(f"marina_factor_levels: {exc}", file=sys.stderr)
        return 1
    if reference is not None:
        try:
            records = records + reference_records(reference, node_t, dead_reckoning_trajectory(ds))
        except (KeyError, ValueError, TypeError) as exc:
            print(f"marina_factor_levels: {args.reference}: {exc!r}", file=sys.stderr)
            return 1
    if args.reference_pairs is not None:
        try:
            if reference is None:
                raise ValueError("--reference-pairs needs --reference (its node times)")
            pairs = json.loads(args.reference_pairs.read_text())
            cfg = doc["meta"]["config"]
            kernel = cfg.get("scan_robust")
            robust = None if kernel is None else Robust(kernel, float(cfg["scan_robust_k"]))
            records = records + reference_pair_records(
                pairs, reference, node_t, dead_reckoning_trajectory(ds), robust
            )
        except (OSError, KeyError, ValueError, TypeError) as exc:
            print(f"marina_factor_levels: {args.reference_pairs}: {exc!r}", file=sys.stderr)
            return 1
    ruler_name, *ruler = ruler_of(ds)
    try:
        graphs = args.graphs.split(",")
        rows = factor_levels(records, values, node_t, (ruler[0], ruler[1]), graphs)
        for stretch in (float(v) for v in args.cut_m.split(",") if v):
            cut, cut_values = cut_lines(records, values, stretch)
            with_lines = [g for g in graphs if g == "product" or "lines" in g.split("+")]
            more = factor_levels(cut, cut_values, node_t, (ruler[0], ruler[1]), with_lines)
            rows.update({f"{k}, lines cut every {stretch:g} m": v for k, v in more.items()})
        for label, change in LINE_VARIANTS.items() if args.variants else ():
            with_lines = [g for g in graphs if g != "product" and "lines" in g.split("+")]
            changed = line_variant(records, change)
            more = factor_levels(changed, values, node_t, (ruler[0], ruler[1]), with_lines)
            rows.update({f"{k}, {label}": v for k, v in more.items()})
    except ValueError as exc:
        print(f"marina_factor_levels: {exc}", file=sys.stderr)
        return 1
    print(f"{args.run}: against {ruler_name}, sonar span, mean / max (m)")
    print(
        "| graph | unaligned | aligned | rigid fit's translation (x, y) | centroid shift (x, y) |"
    )
    print("|---|---|---|---|---|")
    for name, s in rows.items():
        print(
            f"| {name} | {s['mean_m']:.2f} / {s['max_m']:.2f} | {s['aligned_mean_m']:.2f} /"
            f" {s['aligned_max_m']:.2f} | ({s['fit_t_x_m']:+.2f}, {s['fit_t_y_m']:+.2f}) |"
            f" ({s['shift_x_m']:+.2f}, {s['shift_y_m']:+.2f}) |"
        )
    write_result(
        {
            "run": str(args.run),
            "reference": None if args.reference is None else str(args.reference),
            "ruler": ruler_name,
            "graphs": rows,
        },
        args.out,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
