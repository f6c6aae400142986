"""The factor-level check with the lines re-decided: does adding a run's line observations to a
graph without them make the graph better, as the loop decided them and as the smoother
re-decides them? A benchmark only: the ruler (GPS on the marina, the simulator's truth on
simulated data) never feeds an estimator.

python benchmarks/redecided_lines.py --run DIR [--reference REF.json] [--stretch-m 80]
    [--passes 1] [--graphs dr+heading,dr+heading+revisits,...] [--out F.json]

DIR is an iSAM2 run directory (its ``graph.json``). For each base combination of factor
families (``--graphs``; the families of :mod:`marina_factor_levels`, whose loading, families,
reference revisits and scores this reuses), it scores against the ruler over the sonar span:

* ``base``: the families alone, Levenberg-Marquardt from the run's saved values;
* ``+ lines``: with the run's line observations as the loop decided them;
* ``+ lines re-decided``: the product's smoothing step
  (:func:`sonarslam.slam.backends.isam2.redecided.redecided_graph`, ``--stretch-m``,
  ``--passes``) on the graph ``base + lines`` at its optimum, as the back end runs it on its
  smoothed estimate.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip
from common import write_result  # isort: skip

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import gtsam
from marina_factor_levels import (
    FAMILIES,
    family_of,
    load_run,
    node_trajectory,
    optimise,
    reference_records,
    ruler_of,
    scores,
)

from sonarslam.datasets.errors import DataError
from sonarslam.slam.backends.isam2.graph_io import FactorRecord
from sonarslam.slam.backends.isam2.redecided import redecided_graph
from sonarslam.slam.mapping.redecide import RedecideConfig
from sonarslam.slam.run.sources import dead_reckoning_trajectory

DEFAULT_GRAPHS = (
    "dr+heading",
    "dr+heading+revisits",
    "dr+heading+revisits+scans",
    "dr+heading+reference",
    "dr+heading+reference+scans",
    "dr+heading+reference+revisits",
)


def check(
    records: list[FactorRecord],
    values: Any,
    node_t: dict[str, float],
    ruler: tuple[Any, Any],
    graphs: list[str],
    config: RedecideConfig,
    passes: int,
) -> dict[str, dict[str, Any]]:
    """The three scores of each base combination the records hold."""
    by_family: dict[str, list[FactorRecord]] = {f: [] for f in FAMILIES}
    for r in records:
        by_family[family_of(r)].append(r)
    out: dict[str, dict[str, Any]] = {}
    for name in graphs:
        parts = name.split("+")
        unknown = [p for p in parts if p not in FAMILIES]
        if unknown:
            raise ValueError(f"--graphs: {name!r}: unknown families {unknown} (of {FAMILIES})")
        if any(not by_family[p] for p in parts) or "lines" in parts:
            continue
        base = [r for p in parts for r in by_family[p]]
        with_lines = base + by_family["lines"]
        est = optimise(base, values)
        out[name] = scores(node_trajectory(est, node_t), *ruler)
        est = optimise(with_lines, values)
        out[f"{name} + lines"] = scores(node_trajectory(est, node_t), *ruler)
        merged = _merged(values, est)
        redecided = redecided_graph(with_lines, merged, config, passes)
        row = scores(node_trajectory(redecided.values, node_t), *ruler)
        row.update(redecided.metrics())
        out[f"{name} + lines re-decided"] = row
    return out


def _merged(values: Any, est: Any) -> Any:
    """``values`` with the variables of ``est`` replaced by its."""
    out = gtsam.Values(values)
    for key in est.keys():
        if gtsam.Symbol(key).chr() == ord("x"):
            out.update(key, est.atPose2(key))
        else:
            out.update(key, est.atVector(key))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--run", type=Path, required=True, help="an iSAM2 run directory")
    ap.add_argument("--reference", type=Path, default=None, help="a reference graph's JSON")
    ap.add_argument("--graphs", default=",".join(DEFAULT_GRAPHS), help="base combinations")
    ap.add_argument("--stretch-m", type=float, default=80.0, help="longest stretch (m)")
    ap.add_argument("--passes", type=int, default=1, help="re-decision passes")
    ap.add_argument("--out", type=Path, default=None, help="JSON of the scores")
    args = ap.parse_args(argv)
    try:
        _, records, values, node_t, ds = load_run(args.run)
        reference = None if args.reference is None else json.loads(args.reference.read_text())
        if reference is not None:
            dr = dead_reckoning_trajectory(ds)
            records = records + reference_records(reference, node_t, dr)
        ruler_name, *ruler = ruler_of(ds)
        config = RedecideConfig(max_stretch_m=args.stretch_m)
        rows = check(
            records,
            values,
            node_t,
            (ruler[0], ruler[1]),
            args.graphs.split(","),
            config,
            args.passes,
        )
    except (OSError, KeyError, ValueError, TypeError, DataError) as exc:
        print(f"redecided_lines: {exc}", file=sys.stderr)
        return 1
    print(f"{args.run}: against {ruler_name}, sonar span, mean / max (m)")
    print("| graph | unaligned | aligned | rigid fit's translation (x, y) |")
    print("|---|---|---|---|")
    for name, s in rows.items():
        print(
            f"| {name} | {s['mean_m']:.2f} / {s['max_m']:.2f} | {s['aligned_mean_m']:.2f} /"
            f" {s['aligned_max_m']:.2f} | ({s['fit_t_x_m']:+.2f}, {s['fit_t_y_m']:+.2f}) |"
        )
    write_result(
        {
            "run": str(args.run),
            "reference": None if args.reference is None else str(args.reference),
            "ruler": ruler_name,
            "stretch_m": args.stretch_m,
            "passes": args.passes,
            "graphs": rows,
        },
        args.out,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
