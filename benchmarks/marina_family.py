"""Every marina figure from a family of runs: the default configuration under small perturbations
of what a user cannot know exactly, per estimate the mean, min and max of the ATE.

python benchmarks/marina_family.py [--source marina] [--backends dr,ekf,isam2] \\
    [--workers 2] [--only NAME,...] [--set SCOPE.FIELD=V ...] [--out out/marina_family]

One run of one dataset cannot rank two settings that differ by less than what a calibration
error of a quarter degree moves it (issue 29: sonar yaw +-0.25 deg moved iSAM2 smoothed between
2.81 and 2.98 m). So each back end is run (``sonarslam run SOURCE --backend B``, a process each,
``--workers`` at a time) with the default configuration and with each perturbation below, one at
a time, and each estimate is reported as the family's mean, minimum and maximum:

* ``sonar_yaw``: the sonar head's mounting yaw ``[mounting.sonar] yaw_deg`` +-0.25 deg (calibrated
  GPS-free from the map's entropy in 0.25 deg steps: its resolution);
* ``sonar_x``: the sonar's lever arm ``[mounting.sonar] x_m`` +-0.2 m (not measured on the marina);
* ``ahrs_yaw``: the AHRS mounting yaw ``[mounting.ahrs] yaw_deg`` +-0.25 deg (calibrated GPS-free
  against the DVL compass; the only perturbation that moves dead reckoning);
* ``sonar_time``: the sonar's clock offset ``[sonar] time_offset_s`` +-0.05 s (calibrated GPS-free;
  a beam is 68 ms);
* ``min_votes``: the Hough vote threshold ``extractor.min_votes`` +-1;
* ``hough_res``: the Hough grid ``extractor.rho_res_m`` and ``extractor.theta_res_rad`` both
  x0.95 and x1.05;
* ``threshold``: the segmentation threshold ``extractor.intensity_threshold`` x0.98 and x1.02;
  only for raw-intensity beams: the marina's beams are a third party's 0/255 masks, where the
  threshold does nothing, and it is left out there (said in the output).

Estimates: ``dr``; ``ekf``; ``isam2`` online, smoothed and batch (``--batch``); ``isam2ls`` (the
iSAM2 back end with ``isam2.constraints=lines,scans``) online, smoothed and batch. Figures per
estimate: the sonar span's ATE mean and max, unaligned and SE(2)-aligned, and the whole run's mean
(``metrics.json``: ``ate_sonar_*``, ``ate_sonar_aligned_*``, ``ate_mean_*``; GPS the ruler only).

Writes ``OUT/family.json`` (every run's figures and the per-estimate statistics) and
``OUT/family.md`` (the table); each run's own outputs stay in ``OUT/runs/<backend>/<name>/``.
``--set`` gives every closed-loop run of the family one more setting (dead reckoning takes none):
two settings are compared by their families, not by two runs.
"""

from __future__ import annotations

import common  # noqa: F401  # first: one BLAS thread  # isort: skip

import argparse
import json
import math
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.errors import DataError
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.run.presets import EXTRACTOR_PRESETS, preset_for

#: Back end -> (its ``sonarslam run`` options, its estimates: label and metrics.json suffix).
BACKENDS: dict[str, tuple[list[str], list[tuple[str, str]]]] = {
    "dr": (["--backend", "dr"], [("dead reckoning", "")]),
    "ekf": (["--backend", "ekf"], [("EKF, lines", "")]),
    "isam2": (
        ["--backend", "isam2", "--batch"],
        [
            ("iSAM2, lines, online", ""),
            ("iSAM2, lines, smoothed", "smoothed"),
            ("iSAM2, lines, batch", "batch"),
            ("iSAM2, lines, offline", "offline"),
        ],
    ),
    "isam2ls": (
        ["--backend", "isam2", "--batch", "--set", "isam2.constraints=lines,scans"],
        [
            ("iSAM2, lines + scans, online", ""),
            ("iSAM2, lines + scans, smoothed", "smoothed"),
            ("iSAM2, lines + scans, batch", "batch"),
            ("iSAM2, lines + scans, offline", "offline"),
        ],
    ),
}

#: The figures of one estimate: label -> metrics.json key for suffix ``s`` ("" or "_smoothed").
FIGURES: dict[str, str] = {
    "sonar_mean_m": "ate_sonar{s}_mean_m",
    "sonar_max_m": "ate_sonar{s}_max_m",
    "sonar_aligned_mean_m": "ate_sonar_aligned{s}_mean_m",
    "sonar_aligned_max_m": "ate_sonar_aligned{s}_max_m",
    "whole_mean_m": "ate_mean{s}_m",
    "half1_mean_m": "ate_sonar_half1{s}_mean_m",
    "half2_mean_m": "ate_sonar_half2{s}_mean_m",
    "half1_aligned_mean_m": "ate_sonar_aligned_half1{s}_mean_m",
    "half2_aligned_mean_m": "ate_sonar_aligned_half2{s}_mean_m",
}


@dataclass(frozen=True)
class Perturbation:
    """One member of the family: ``--set`` settings and dataset-configuration keys.

    Attributes
    ----------
    name : str
    settings : dict of str to str
        ``SCOPE.FIELD`` -> value, as ``sonarslam run --set``.
    config : dict of tuple to float
        ``(table, key)`` of ``sonarslam.toml`` -> the value, written to a ``--config`` file.
    """

    name: str
    settings: dict[str, str] = field(default_factory=dict)
    config: dict[tuple[str, str], float] = field(default_factory=dict)


def perturbations(source: str) -> tuple[list[Perturbation], list[str]]:
    """The default and its perturbations (module docstring) around ``source``'s own calibration
    and extractor preset, minus then plus of each; with the notes on those left out."""
    ds = open_dataset(source)
    cfg = ds.config
    ext = EXTRACTOR_PRESETS[preset_for(ds.beams)]
    sonar_yaw_deg = math.degrees(cfg.sonar_mounting.yaw_rad)
    ahrs_yaw_deg = math.degrees(cfg.ahrs_mounting.yaw_rad)

    def pair(name: str, make: Any) -> list[Perturbation]:
        return [Perturbation(f"{name}{tag}", **make(sign)) for sign, tag in ((-1, "-"), (1, "+"))]

    out = [Perturbation("default")]
    out += pair(
        "sonar_yaw_0.25deg",
        lambda s: {"config": {("mounting.sonar", "yaw_deg"): sonar_yaw_deg + s * 0.25}},
    )
    out += pair(
        "sonar_x_0.2m",
        lambda s: {"config": {("mounting.sonar", "x_m"): cfg.sonar_mounting.x_m + s * 0.2}},
    )
    out += pair(
        "ahrs_yaw_0.25deg",
        lambda s: {"config": {("mounting.ahrs", "yaw_deg"): ahrs_yaw_deg + s * 0.25}},
    )
    out += pair(
        "sonar_time_0.05s",
        lambda s: {"config": {("sonar", "time_offset_s"): cfg.sonar_time_offset_s + s * 0.05}},
    )
    out += pair(
        "min_votes_1", lambda s: {"settings": {"extractor.min_votes": str(ext.min_votes + s)}}
    )
    out += pair(
        "hough_res_5%",
        lambda s: {
            "settings": {
                "extractor.rho_res_m": repr(ext.rho_res_m * (1.0 + s * 0.05)),
                "extractor.theta_res_rad": repr(ext.theta_res_rad * (1.0 + s * 0.05)),
            }
        },
    )
    notes = []
    if ds.beams.thresholded:
        notes.append(
            "threshold: left out, the beams are 0/255 masks (a segmentation threshold does "
            "nothing on them)"
        )
    else:
        out += pair(
            "threshold_2%",
            lambda s: {
                "settings": {
                    "extractor.intensity_threshold": repr(
                        ext.intensity_threshold * (1.0 + s * 0.02)
                    )
                }
            },
        )
    return out, notes


def _config_file(p: Perturbation, path: Path) -> Path | None:
    """The ``--config`` TOML of ``p``'s dataset keys, or None."""
    if not p.config:
        return None
    tables: dict[str, list[str]] = {}
    for (table, key), value in p.config.items():
        tables.setdefault(table, []).append(f"{key} = {value!r}")
    text = "\n\n".join(f"[{t}]\n" + "\n".join(rows) for t, rows in tables.items())
    path.write_text(text + "\n")
    return path


def run_one(
    source: str,
    backend: str,
    p: Perturbation,
    out: Path,
    shared: tuple[str, ...] = (),
    reuse: bool = False,
) -> dict[str, Any]:
    """``sonarslam run`` of one member (with the ``--set`` settings ``shared`` of every
    closed-loop run); its metrics.json, the wall time, or the error. ``reuse``: a run directory
    that already holds a metrics.json is read, not run again (its commit is kept with it)."""
    run_dir = out / "runs" / backend / p.name
    metrics_path = run_dir / "metrics.json"
    if reuse and metrics_path.is_file():
        metrics = json.loads(metrics_path.read_text())
        commit = str(metrics.get("provenance", {}).get("git_commit", "?"))[:10]
        return {"metrics": metrics, "wall_s": float("nan"), "reused": commit}
    run_dir.mkdir(parents=True, exist_ok=True)
    args = [source, "--out", str(run_dir), "--quiet", *BACKENDS[backend][0]]
    for key, value in p.settings.items():
        args += ["--set", f"{key}={value}"]
    if backend != "dr":
        for setting in shared:
            args += ["--set", setting]
    cfg = _config_file(p, run_dir.parent / f"{p.name}.toml")
    if cfg is not None:
        args += ["--config", str(cfg)]
    code = "import sys; from sonarslam.slam.cli.main import main; sys.exit(main(sys.argv[1:]))"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", code, "run", *args], env=env, capture_output=True, text=True
    )
    wall = time.perf_counter() - t0
    if proc.returncode != 0 or not metrics_path.exists():
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        return {"error": f"exit {proc.returncode}: {' / '.join(tail)}", "wall_s": wall}
    return {"metrics": json.loads(metrics_path.read_text()), "wall_s": wall}


def figures(metrics: dict[str, Any], suffix: str) -> dict[str, float]:
    """:data:`FIGURES` of one estimate from a run's metrics.json."""
    s = f"_{suffix}" if suffix else ""
    return {
        label: float(metrics.get(key.format(s=s), float("nan"))) for label, key in FIGURES.items()
    }


def summarise(rows: dict[str, dict[str, float]]) -> dict[str, Any]:
    """Per figure: the default run's value, the family's mean, min, max and range."""
    out: dict[str, Any] = {"members": len(rows)}
    for label in FIGURES:
        values = np.array([r[label] for r in rows.values()])
        out[label] = {
            "default": rows["default"][label] if "default" in rows else float("nan"),
            "mean": float(values.mean()),
            "min": float(values.min()),
            "max": float(values.max()),
            "range": float(values.max() - values.min()),
        }
    return out


def table(summary: dict[str, dict[str, Any]]) -> str:
    """The markdown table: per estimate, default and family mean [min, max] of each figure, and
    the sonar span's two halves (the first where a default may be informed by GPS, the second
    held out: docs/design-decisions.md)."""
    head = (
        "| estimate | runs | sonar span mean: default / family mean [min, max] | sonar span "
        "max: family mean | aligned mean: default / family mean [min, max] | first half / "
        "second half mean (aligned): family mean | whole run mean: family mean |\n"
        "|---|---|---|---|---|---|---|\n"
    )

    def cell(s: dict[str, float]) -> str:
        return f"{s['default']:.2f} / {s['mean']:.2f} [{s['min']:.2f}, {s['max']:.2f}]"

    def halves(s: dict[str, Any]) -> str:
        if not all(math.isfinite(s[k]["mean"]) for k in ("half1_mean_m", "half2_mean_m")):
            return "-"
        return (
            f"{s['half1_mean_m']['mean']:.2f} / {s['half2_mean_m']['mean']:.2f}"
            f" ({s['half1_aligned_mean_m']['mean']:.2f} / {s['half2_aligned_mean_m']['mean']:.2f})"
        )

    lines = [
        f"| {name} | {s['members']} | {cell(s['sonar_mean_m'])} | {s['sonar_max_m']['mean']:.2f} "
        f"| {cell(s['sonar_aligned_mean_m'])} | {halves(s)} | {s['whole_mean_m']['mean']:.2f} |"
        for name, s in summary.items()
    ]
    return head + "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--source", default="marina", help="marina or a dataset directory")
    ap.add_argument("--backends", default="dr,ekf,isam2", help=f"comma list of {sorted(BACKENDS)}")
    ap.add_argument("--workers", type=int, default=2, help="runs at a time (at most 2)")
    ap.add_argument("--only", default=None, help="comma list of member names (default: all)")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SCOPE.FIELD=V",
        help="a setting of every closed-loop run (repeatable)",
    )
    ap.add_argument("--out", type=Path, default=Path("out/marina_family"))
    ap.add_argument(
        "--reuse",
        action="store_true",
        help="read a member's run already in --out (its metrics.json) instead of running it again"
        " (only when nothing that changes its estimates has changed since: family.md names the"
        " commits the reused runs were made at)",
    )
    args = ap.parse_args(argv)
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown or not backends:
        print(
            f"marina_family: --backends must name {sorted(BACKENDS)}, got {unknown}",
            file=sys.stderr,
        )
        return 1
    if not 1 <= args.workers <= 2:
        print(f"marina_family: --workers must be 1 or 2, got {args.workers}", file=sys.stderr)
        return 1
    try:
        family, notes = perturbations(args.source)
    except (DataError, FileNotFoundError, ValueError) as exc:
        print(f"marina_family: {exc}", file=sys.stderr)
        return 1
    if args.only:
        wanted = {n.strip() for n in args.only.split(",")}
        missing = wanted - {p.name for p in family}
        if missing:
            print(f"marina_family: --only names no member {sorted(missing)}", file=sys.stderr)
            return 1
        family = [p for p in family if p.name in wanted]
    args.out.mkdir(parents=True, exist_ok=True)
    # dead reckoning takes no extractor or back-end settings (``sonarslam run`` refuses them):
    # under those members it is the default run, not a member of its own family
    jobs = [(b, p) for b in backends for p in family if not (b == "dr" and p.settings)]
    skipped = sorted({p.name for p in family if p.settings} if "dr" in backends else set())
    if skipped:
        notes.append(f"dead reckoning: {', '.join(skipped)} left out (it takes no such setting)")
    wall0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=args.workers) as pool:
        results = list(
            pool.map(
                lambda job: run_one(
                    args.source, job[0], job[1], args.out, tuple(args.set), args.reuse
                ),
                jobs,
            )
        )
    wall = time.perf_counter() - wall0
    runs: dict[str, dict[str, Any]] = {}
    per_estimate: dict[str, dict[str, dict[str, float]]] = {}
    errors = []
    for (backend, p), res in zip(jobs, results, strict=True):
        runs.setdefault(backend, {})[p.name] = {
            "settings": p.settings,
            "config": {f"[{t}] {k}": v for (t, k), v in p.config.items()},
            "wall_s": res["wall_s"],
            **({"error": res["error"]} if "error" in res else {}),
            **({"reused": res["reused"]} if "reused" in res else {}),
        }
        if "error" in res:
            errors.append(f"{backend} {p.name}: {res['error']}")
            continue
        for label, suffix in BACKENDS[backend][1]:
            f = figures(res["metrics"], suffix)
            runs[backend][p.name][label] = f
            per_estimate.setdefault(label, {})[p.name] = f
    summary = {label: summarise(rows) for label, rows in per_estimate.items()}
    reused = sorted({r["reused"] for b in runs.values() for r in b.values() if "reused" in r})
    if reused:
        n = sum("reused" in r for b in runs.values() for r in b.values())
        notes.append(f"{n} runs reused from {args.out} (made at commits {', '.join(reused)})")
    result = {
        "source": args.source,
        "members": [p.name for p in family],
        "settings": args.set,
        "notes": notes,
        "summary": summary,
        "runs": runs,
        "errors": errors,
        "wall_s": wall,
        "load_average": list(os.getloadavg()),
    }
    (args.out / "family.json").write_text(json.dumps(result, indent=1) + "\n")
    md = (
        f"# {args.source}: {len(family)} runs per back end ({', '.join(p.name for p in family)})\n\n"
        + "".join(f"- {n}\n" for n in notes)
        + "\n"
        + table(summary)
    )
    (args.out / "family.md").write_text(md)
    print(md)
    for e in errors:
        print(f"failed: {e}", file=sys.stderr)
    print(
        f"{len(jobs)} runs in {wall:.0f} s wall (load {os.getloadavg()[0]:.1f}); written {args.out}"
    )
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
