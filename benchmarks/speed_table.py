"""The speed table of docs/speed.md from the JSON that ``make bench`` writes under ``out/``.

Reads ``machine_speed.json`` (the reference workloads of the same run), ``ekf_speed.json``,
``isam2_speed.json``, ``isam2_speed_scans.json`` (lines + scans) and ``extractor_speed.json``,
prints the table as markdown and, with ``--readme PAGE``, puts it between the page's
``<!-- speed -->`` and ``<!-- /speed -->`` lines (``docs/speed.md``). A missing file leaves its row out.

Usage::

    .venv/bin/python benchmarks/speed_table.py --dir out [--readme docs/speed.md]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

BEGIN, END = "<!-- speed -->", "<!-- /speed -->"


def _load(folder: Path, name: str) -> dict[str, Any] | None:
    path = folder / name
    return json.loads(path.read_text()) if path.is_file() else None


def table(folder: Path) -> str:
    """The markdown table (and the machine line above it)."""
    m = _load(folder, "machine_speed.json")
    lines = []
    if m is not None:
        load = m.get("load_avg") or []
        lines.append(
            f"Machine: {m['processor']}, one core (cpu {m['cpu']}), Python {m['python']}, numpy "
            f"{m['numpy']}, load average {', '.join(f'{x:.1f}' for x in load)} at the start. "
            f"Its reference workloads in the same run (`benchmarks/machine_speed.py`, median): "
            f"pure-Python loop {m['python_loop_s_median']:.2f} s, small numpy calls "
            f"{m['numpy_small_s_median']:.2f} s, BLAS {m['numpy_blas_s_median']:.2f} s; divide "
            "a figure by these to compare machines."
        )
        lines.append("")
    lines += [
        "| benchmark | real time | split | latency |",
        "|---|---|---|---|",
    ]
    e = _load(folder, "ekf_speed.json")
    if e is not None:
        lines.append(
            f"| EKF closed loop (`ekf_speed.py`) | {e['realtime_factor']:.0f}× | extractor "
            f"{e['extractor_s']:.1f} s, filter {e['backend_s']:.1f} s of {e['wall_s']:.1f} s | "
            f"vote with lines p50 {e['line_update_ms_p50']:.2f} ms, p99 "
            f"{e['line_update_ms_p99']:.2f} ms |"
        )
    for name, label in (
        ("isam2_speed.json", "iSAM2, lines (`isam2_speed.py`)"),
        ("isam2_speed_scans.json", "iSAM2, lines + scans (`--set isam2.constraints=lines,scans`)"),
    ):
        r = _load(folder, name)
        if r is not None:
            lines.append(
                f"| {label} | {r['realtime_factor']:.0f}× | extractor {r['extractor_s']:.1f} s, "
                f"back end {r['backend_s']:.1f} s of {r['wall_s']:.1f} s | iSAM2 update p50 "
                f"{r['isam_update_ms_p50']:.1f} ms, p99 {r['isam_update_ms_p99']:.1f} ms, max "
                f"{r['isam_update_ms_max']:.0f} ms |"
            )
    x = _load(folder, "extractor_speed.json")
    if x is not None:
        v = x["voting"]
        lines.append(
            f"| extractor, GPS poses (`extractor_speed.py`) | {x['realtime_factor']:.0f}× | "
            f"{x['beams']} beams in {x['wall_s']:.1f} s | per beam p50 "
            f"{x['beam_time_p50_us']:.0f} µs, p99 {x['beam_time_p99_us'] / 1e3:.2f} ms, max "
            f"{x['beam_time_max_us'] / 1e3:.1f} ms |"
        )
        lines.append(
            f"| voting {v['sectors']} sectors: ours against scikit-image `hough_line` | "
            f"{v['ratio_skimage_hough_line_over_ours']:.2f}× as fast | ours "
            f"{v['total_ms']['ours_ms']:.1f} ms, `hough_line` "
            f"{v['total_ms']['skimage_hough_line_ms']:.1f} ms, with `hough_line_peaks` "
            f"{v['total_ms']['skimage_with_peaks_ms']:.1f} ms | |"
        )
    return "\n".join(lines)


def put_in_readme(readme: Path, text: str) -> None:
    """Replace what is between the markers (they must both be there)."""
    s = readme.read_text()
    if BEGIN not in s or END not in s:
        raise SystemExit(f"{readme}: no {BEGIN} ... {END} lines to put the table between")
    head, rest = s.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    readme.write_text(f"{head}{BEGIN}\n{text}\n{END}{tail}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dir", default="out", help="where make bench wrote its JSON")
    parser.add_argument("--readme", help="put the table into this page (docs/speed.md)")
    args = parser.parse_args(argv)
    text = table(Path(args.dir))
    print(text)
    if args.readme:
        put_in_readme(Path(args.readme), text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
