"""Offline-estimate settings compared on saved factor-graph runs: each run's offline estimate
made again under each ``--variant`` (:func:`sonarslam.offline_from_saved`), GPS the ruler.

python benchmarks/offline_variants.py --runs out/family/runs/isam2 \\
    --variant default= --variant nolines=lines=false [--source marina] [--out DIR]

``--runs`` is a folder of ``sonarslam run SOURCE --backend isam2`` directories (such as
``benchmarks/marina_family.py``'s ``runs/isam2``: a family of perturbed calibrations); each is
taken up with its dataset opened with that run's own ``config_used.toml`` (the family's
perturbations are configurations). Per variant (``NAME=FIELD=V,FIELD=V``, fields of
:class:`sonarslam.OfflineConfig`; ``NAME=`` alone: the defaults): each run's sonar-span mean ATE
against GPS, unaligned and aligned, and its two halves (the first, fixes up to the split of
``sonar_half_split_s``, where a default may be informed by GPS; the second held out), then the
mean [min, max] over the runs, and per variant after the first how many runs it is no worse on
than the first. Writes ``DIR/offline_variants.json``; prints the table.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip

import argparse
import json
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam import OfflineConfig, offline_from_saved, open_dataset
from sonarslam.datasets.errors import DataWarning
from sonarslam.settings import parse_text
from sonarslam.slam.run.metrics import trajectory_figures

#: The figures of one estimate: label -> ``span_json`` key.
FIGURES = {
    "sonar": "ate_sonar_offline_mean_m",
    "aligned": "ate_sonar_aligned_offline_mean_m",
    "half1": "ate_sonar_half1_offline_mean_m",
    "half2": "ate_sonar_half2_offline_mean_m",
}


def parse_variant(text: str) -> tuple[str, dict[str, Any]]:
    """``NAME=FIELD=V,FIELD=V`` -> (name, fields); ``NAME=``: the defaults."""
    name, _, rest = text.partition("=")
    if not name:
        raise ValueError(f"--variant {text!r}: give NAME=FIELD=V,... or NAME=")
    fields: dict[str, Any] = {}
    for item in filter(None, rest.split(",")):
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--variant {text!r}: {item!r} is not FIELD=VALUE")
        fields[key.strip()] = parse_text(value.strip())
    return name, fields


def _figures(span: dict[str, Any]) -> dict[str, float]:
    """:data:`FIGURES` of one offline estimate's ``span_json``."""
    out = {}
    for label, key in FIGURES.items():
        value = span[key]
        if not isinstance(value, (int, float)):
            raise ValueError(f"{key} is {value!r}: the dataset has no GPS inside the sonar span")
        out[label] = float(value)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--runs", type=Path, required=True, help="folder of isam2 run directories")
    ap.add_argument("--source", default="marina", help="the runs' dataset (default marina)")
    ap.add_argument("--variant", action="append", required=True, metavar="NAME=[FIELD=V,...]")
    ap.add_argument("--out", type=Path, default=Path("out/offline_variants"))
    args = ap.parse_args(argv)
    try:
        variants = [parse_variant(v) for v in args.variant]
        configs = {name: OfflineConfig(**fields) for name, fields in variants}
    except (ValueError, TypeError) as exc:
        print(f"offline_variants: {exc}", file=sys.stderr)
        return 1
    runs = sorted(p for p in args.runs.iterdir() if (p / "graph.json").is_file())
    if not runs:
        print(f"offline_variants: {args.runs} holds no run with a graph.json", file=sys.stderr)
        return 1
    rows: dict[str, dict[str, dict[str, float]]] = {}
    cpu: dict[str, float] = dict.fromkeys(configs, 0.0)
    for run in runs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            dataset = open_dataset(args.source, config_override=run / "config_used.toml")
            rows[run.name] = {}
            for name, config in configs.items():
                t0 = time.process_time()
                found = offline_from_saved(run, dataset, offline=config)
                cpu[name] += time.process_time() - t0
                span = trajectory_figures(dataset, found.trajectory, "offline").span_json()
                rows[run.name][name] = _figures(span)
        print(run.name, {n: round(f["sonar"], 3) for n, f in rows[run.name].items()}, flush=True)
    first = variants[0][0]
    summary: dict[str, Any] = {}
    lines = [
        f"| variant | runs | sonar span mean [min, max] | aligned mean [min, max] | first / second"
        f" half mean | no worse than {first} | CPU s per run |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in configs:
        values = {k: np.array([rows[r][name][k] for r in rows]) for k in FIGURES}
        base = np.array([rows[r][first]["sonar"] for r in rows])
        summary[name] = {
            k: {"mean": float(v.mean()), "min": float(v.min()), "max": float(v.max())}
            for k, v in values.items()
        }
        summary[name]["no_worse_than_first"] = int(np.sum(values["sonar"] <= base + 1e-9))
        s, a = summary[name]["sonar"], summary[name]["aligned"]
        lines.append(
            f"| {name} | {len(rows)} | {s['mean']:.2f} [{s['min']:.2f}, {s['max']:.2f}]"
            f" | {a['mean']:.2f} [{a['min']:.2f}, {a['max']:.2f}]"
            f" | {summary[name]['half1']['mean']:.2f} / {summary[name]['half2']['mean']:.2f}"
            f" | {summary[name]['no_worse_than_first']} of {len(rows)}"
            f" | {cpu[name] / len(rows):.1f} |"
        )
    table = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "offline_variants.json").write_text(
        json.dumps({"runs": rows, "summary": summary, "variants": args.variant}, indent=1) + "\n"
    )
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
