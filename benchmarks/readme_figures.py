"""``make readme-figures``: the README's and docs/' figures that the code produces, from one source.

Each generated block of ``README.md`` and ``docs/**/*.md`` sits between ``<!-- figures: NAME -->``
and ``<!-- /figures -->`` and is the rendering (:data:`RENDERERS`) of ``docs/figures.json``,
which this script measures on the marina:

* ``dataset``: what the marina copy holds (rows, beams and spans, the DVL's degraded stretch);
* ``runs``: dead reckoning, the EKF, iSAM2 (online, smoothed, batch), iSAM2 with scans and with
  lines and scans: each run's ATE over the sonar span and the whole run (``metrics.json``'s
  keys), with the digest of the settings it ran with (:func:`sonarslam.slam.run.provenance.settings_digest`).

``python benchmarks/readme_figures.py`` measures (about 1 min) and rewrites the blocks;
``--render`` rewrites the blocks from the recorded ``docs/figures.json`` without measuring;
``--check`` exits 1 naming every block that differs from its rendering. ``tests/test_docs.py``
checks that the blocks are the rendering, and re-measures what is cheap (the dataset's counts,
dead reckoning, the settings' digests: a changed preset makes the recorded figures stale).
"""

from __future__ import annotations

import argparse  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import common  # noqa: F401  # first: one BLAS thread

from sonarslam.datasets.config import dump_dataset_config  # noqa: E402
from sonarslam.datasets.source import Dataset, open_dataset  # noqa: E402
from sonarslam.slam.eval.published import PUBLISHED  # noqa: E402
from sonarslam.slam.run.presets import run_config  # noqa: E402
from sonarslam.slam.run.provenance import git_state, settings_digest  # noqa: E402
from sonarslam.slam.run.run import run_backend  # noqa: E402
from sonarslam.slam.run.sources import dvl_quality, pose_source_by_name  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures.json"
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
BLOCK = re.compile(r"(<!-- figures: ([a-z0-9-]+) -->\n)(.*?)(<!-- /figures -->)", re.S)

#: The runs measured: name -> (back end, --set settings, --batch), and their labels.
RUNS: dict[str, tuple[str, dict[str, str], bool]] = {
    "dr": ("dr", {}, False),
    "ekf": ("ekf", {}, False),
    "isam2": ("isam2", {}, True),
    "isam2_scans": ("isam2", {"isam2.constraints": "scans"}, True),
    "isam2_lines_scans": ("isam2", {"isam2.constraints": "lines,scans"}, True),
}
#: metrics.json keys recorded per run (those present).
RUN_KEYS = (
    "ate_sonar_mean_m",
    "ate_sonar_max_m",
    "ate_mean_m",
    "ate_max_m",
    "ate_n",
    "ate_sonar_n",
    "beams",
    "landmarks",
    "line_features",
    "ate_sonar_smoothed_mean_m",
    "ate_sonar_smoothed_max_m",
    "ate_mean_smoothed_m",
    "ate_max_smoothed_m",
    "ate_sonar_batch_mean_m",
    "ate_sonar_batch_max_m",
    "ate_mean_batch_m",
    "ate_max_batch_m",
    "ate_sonar_aligned_mean_m",
    "ate_sonar_aligned_max_m",
    "ate_sonar_aligned_smoothed_mean_m",
    "ate_sonar_aligned_smoothed_max_m",
    "ate_sonar_aligned_batch_mean_m",
    "ate_sonar_aligned_batch_max_m",
    "ate_sonar_offline_mean_m",
    "ate_sonar_offline_max_m",
    "ate_mean_offline_m",
    "ate_max_offline_m",
    "ate_sonar_aligned_offline_mean_m",
    "ate_sonar_aligned_offline_max_m",
)


def dataset_figures(ds: Dataset) -> dict[str, Any]:
    """What the marina copy holds (``sonarslam info``'s counts)."""
    assert ds.gps is not None
    t0, t1 = ds.nav_span_s
    sonar = ds.sonar_span_s
    assert sonar is not None
    nav = ds.nav_beams()
    gps_span = pose_source_by_name(ds, "gps").span_s
    dq = dvl_quality(ds)
    return {
        "dvl_rows": int(ds.dvl.t.size),
        "ahrs_rows": int(ds.attitude.t.size),
        "gps_fixes": int(ds.gps.t.size),
        "beams": len(ds.beams),
        "beams_nav": len(nav),
        "beams_gps_span": sum(1 for b in nav if gps_span[0] <= b.t <= gps_span[1]),
        "nav_span_s": t1 - t0,
        "sonar_span_s": sonar[1] - sonar[0],
        "sonar_from_s": sonar[0] - t0,
        "sonar_to_s": sonar[1] - t0,
        "dvl_excess_s": dq["dvl_excess_s"],
        "dvl_excess_from_s": dq["dvl_excess_from_s"],
    }


def run_digest(ds: Dataset, name: str) -> str:
    """The settings' digest of a run of :data:`RUNS` on ``ds`` (what ``metrics.json`` records)."""
    backend, settings, batch = RUNS[name]
    config = None if backend == "dr" else run_config(ds.beams, backend, settings, ds.config.noise)
    return settings_digest(backend, dump_dataset_config(ds.config), config, batch)


def measure(names: list[str] | None = None, runs: dict[str, Any] | None = None) -> dict[str, Any]:
    """Open the marina and measure every figure (module docstring); ``names``: only these runs,
    the others kept from ``runs``."""
    ds = open_dataset("marina")
    commit, dirty = git_state()
    runs = dict(runs or {})
    for name in names or list(RUNS):
        backend, settings, batch = RUNS[name]
        print(f"  {name} ...", file=sys.stderr, flush=True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            metrics = run_backend(ds, backend, settings or None, batch=batch).metrics
        runs[name] = {k: metrics[k] for k in RUN_KEYS if k in metrics}
        runs[name]["settings_sha256"] = run_digest(ds, name)
    return {
        "about": "written by `make readme-figures` (benchmarks/readme_figures.py); do not edit",
        "git_commit": commit,
        "git_dirty": dirty,
        "dataset": dataset_figures(ds),
        "runs": runs,
    }


# --- renderers: figures -> Markdown ---------------------------------------------------------


def _mm(run: dict[str, Any], span: str, suffix: str = "") -> str:
    """``mean / max`` of a run's ATE over a span (``"_sonar"`` or ``""``: metrics.json's keys,
    ``ate_sonar_smoothed_mean_m`` and ``ate_mean_smoothed_m`` for another trajectory)."""
    if span:
        mean, top = run.get(f"ate{span}{suffix}_mean_m"), run.get(f"ate{span}{suffix}_max_m")
    else:
        mean, top = run.get(f"ate_mean{suffix}_m"), run.get(f"ate_max{suffix}_m")
    if mean is None:
        return ""
    return f"{mean:.2f} / {top:.2f}" if top is not None else f"{mean:.2f} / –"


def _published(columns: int) -> list[str]:
    pad = " |" * (columns - 2)
    return [
        f"| {p['method']} (published, Mallios 2014) | {p['mean']:.2f} / {p['max']:.2f} |{pad}"
        for p in PUBLISHED
    ]


def render_headline(fig: dict[str, Any]) -> str:
    r = fig["runs"]
    rows = [
        ("iSAM2 offline estimate (decided again after the run: docs/offline.md)", r["isam2"], "_offline", "`sonarslam run marina --backend isam2 --batch --out out/isam2` (`isam2_offline.tum`)"),
        ("iSAM2 with lines and scans, offline estimate", r["isam2_lines_scans"], "_offline", "`... --batch --set isam2.constraints=lines,scans`"),
        ("dead reckoning (ours, GPS-free calibration)", r["dr"], "", "`sonarslam run marina --backend dr --out out/dr`"),
        ("EKF-SLAM with our lines (closed loop, no GPS)", r["ekf"], "", "`sonarslam run marina --backend ekf --out out/ekf`"),
        ("iSAM2 with our lines (online)", r["isam2"], "", "the same run as the offline estimate's"),
        ("iSAM2 with our lines, smoothed", r["isam2"], "_smoothed", "the same run (`ate_*_smoothed_*`)"),
        ("iSAM2 with our lines, batch LM", r["isam2"], "_batch", "the same run (`ate_*_batch_*`)"),
        ("iSAM2 with scans (online)", r["isam2_scans"], "", "`... --batch --set isam2.constraints=scans`"),
        ("iSAM2 with scans, smoothed", r["isam2_scans"], "_smoothed", "the same run"),
        ("iSAM2 with lines and scans (online)", r["isam2_lines_scans"], "", "the same run as its offline estimate's"),
        ("iSAM2 with lines and scans, smoothed", r["isam2_lines_scans"], "_smoothed", "the same run"),
    ]  # fmt: skip
    out = [
        "| method | sonar span mean / max (m) | SE(2)-aligned | whole run mean / max (m) | command |",
        "|---|---|---|---|---|",
    ]
    for label, run, sfx, cmd in rows:
        aligned = _mm(run, "_sonar_aligned", sfx)
        out.append(
            f"| {label} | {_mm(run, '_sonar', sfx)} | {aligned} | {_mm(run, '', sfx)} | {cmd} |"
        )
    return "\n".join(out + _published(5)) + "\n"


def render_constraints(fig: dict[str, Any]) -> str:
    r = fig["runs"]
    rows = [
        ("dead reckoning", r["dr"], False),
        ("EKF, lines", r["ekf"], False),
        ("iSAM2, lines (default)", r["isam2"], True),
        ("iSAM2, scans", r["isam2_scans"], True),
        ("iSAM2, lines + scans", r["isam2_lines_scans"], True),
    ]
    out = [
        "| marina, ATE against GPS (m) | sonar span mean / max | whole run mean / max | iSAM2 smoothed, sonar span |",
        "|---|---|---|---|",
    ]
    for label, run, smoothed in rows:
        sm = _mm(run, "_sonar", "_smoothed") if smoothed else ""
        out.append(f"| {label} | {_mm(run, '_sonar')} | {_mm(run, '')} | {sm} |")
    return "\n".join(out + _published(4)) + "\n"


def render_dataset(fig: dict[str, Any]) -> str:
    d = fig["dataset"]
    return (
        "| what | this copy |\n|---|---|\n"
        f"| DVL rows / AHRS rows / GPS fixes | {d['dvl_rows']:,} / {d['ahrs_rows']:,} / {d['gps_fixes']:,} |\n"
        f"| navigation span (DVL and AHRS both running) | {d['nav_span_s']:,.0f} s |\n"
        f"| sonar beams rebuilt from the keyframes | {d['beams']:,}, of which {d['beams_nav']:,} inside the navigation span and {d['beams_gps_span']:,} inside the GPS fixes' span too (`extract`, `plot-scans --poses gps`) |\n"
        f"| beams a run processes (from the start pose, the first GPS fix; `metrics.json` `beams`) | {fig['runs']['ekf']['beams']:,} |\n"
        f"| sonar span (first to last beam inside the navigation span) | {d['sonar_span_s']:,.0f} s, from {d['sonar_from_s']:,.0f} s to {d['sonar_to_s']:,.0f} s |\n"
        f"| the DVL's scatter above its nominal 0.2 m/s (`metrics.json` `dvl_excess_s`) | {d['dvl_excess_s']:,.0f} s in all, first at {d['dvl_excess_from_s']:,.0f} s |\n"
    )  # fmt: skip


RENDERERS: dict[str, Callable[[dict[str, Any]], str]] = {
    "marina-headline": render_headline,
    "marina-constraints": render_constraints,
    "marina-dataset": render_dataset,
}


def blocks(text: str) -> list[tuple[str, str]]:
    """``(name, content)`` of every generated block of a page."""
    return [(m[2], m[3]) for m in BLOCK.finditer(text)]


def rewrite(text: str, fig: dict[str, Any]) -> str:
    """The page with every generated block rendered from ``fig``."""

    def one(m: re.Match[str]) -> str:
        if m[2] not in RENDERERS:
            raise KeyError(f"unknown generated block {m[2]!r} (known: {sorted(RENDERERS)})")
        return m[1] + RENDERERS[m[2]](fig) + m[4]

    return BLOCK.sub(one, text)


def stale_blocks(fig: dict[str, Any], pages: list[Path] = PAGES) -> list[str]:
    """``page: block`` of every block that differs from its rendering."""
    out = []
    for page in pages:
        text = page.read_text()
        for name, content in blocks(text):
            if content != RENDERERS[name](fig):
                where = page.relative_to(ROOT) if page.is_relative_to(ROOT) else page
                out.append(f"{where}: {name}")
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--render", action="store_true", help="render docs/figures.json, measure nothing"
    )
    g.add_argument("--check", action="store_true", help="exit 1 if a block is not its rendering")
    p.add_argument(
        "--runs",
        help=f"re-measure only these runs (comma-separated, of {', '.join(RUNS)}), keep the others",
    )
    args = p.parse_args()
    if args.check:
        stale = stale_blocks(json.loads(FIGURES.read_text()))
        for s in stale:
            print(f"stale: {s} (make readme-figures)")
        return 1 if stale else 0
    if args.render:
        fig = json.loads(FIGURES.read_text())
    else:
        names = args.runs.split(",") if args.runs else None
        if names and set(names) - set(RUNS):
            p.error(f"--runs: unknown {sorted(set(names) - set(RUNS))}, known {list(RUNS)}")
        fig = measure(names, json.loads(FIGURES.read_text())["runs"] if names else None)
        FIGURES.write_text(json.dumps(fig, indent=1, sort_keys=True) + "\n")
    for page in PAGES:
        text = page.read_text()
        new = rewrite(text, fig)
        if new != text:
            page.write_text(new)
            print(f"rewrote {page.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
