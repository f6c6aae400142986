"""Peak memory (RSS) of ``sonarslam run --backend dr`` against the size of its sonar input.

Builds, from the marina (``$SONARSLAM_DATA/marina``), datasets whose sonar is
  * the marina's keyframes as they are (with and without the keyframe cache);
  * a raw ``_IS.log`` of the marina's beams (~50 MB), and one of ``--scale`` times as many
    beams over the same time (each beam repeated at evenly spread times; ~500 MB at 10x);
  * the keyframes with one PCD of ``--pcd-points`` points (10 million: ~245 MB);
and runs ``/usr/bin/time -v sonarslam run DIR --backend dr`` on each, printing the peak RSS
and the wall time. The navigation logs are the marina's (symlinked). Run under
``nice -n 10``; one core: ``taskset -c 0 .venv/bin/python benchmarks/memory.py``.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from sonarslam.datasets.source import open_dataset

SONARSLAM = str(Path(sys.executable).with_name("sonarslam"))


def _link_logs(src: Path, dst: Path, with_keyframes: bool) -> None:
    dst.mkdir(parents=True)
    logs = src / "logs"
    for f in logs.iterdir():
        if f.name.endswith(("_DVL.log", "_MTi.log", "_DGPS.log", "_SETUP.log")):
            (dst / f.name).symlink_to(f)
        if with_keyframes and f.name.endswith("_IS_timestamps.log"):
            (dst / f.name).symlink_to(f)


def write_is_log(marina: Path, dst: Path, scale: int) -> Path:
    """A raw IS log of the marina's beams, each repeated ``scale`` times over its interval."""
    ds = open_dataset(marina)
    beams = ds.beams
    t = beams.t_s - ds.config.sonar_time_offset_s  # back to the log's clock
    dt = np.diff(t, append=t[-1] + np.median(np.diff(t)))
    path = dst / "_scaled_IS.log"
    with path.open("w", encoding="ascii") as fh:
        fh.write("% sonarslam memory benchmark\n" * 7)
        for i in range(len(beams)):
            bins = " ".join(map(str, beams.intensities[i].tolist()))
            a = f"{beams.transducer_angle_rad[i]:.6f}"
            for j in range(scale):
                tj = t[i] + dt[i] * j / scale
                fh.write(f"{tj:.4f}\t{int(round((tj % 86400.0) * 1000.0))}\t{a}\t{bins}\n")
    return path


def write_big_pcd(marina: Path, dst: Path, n_points: int) -> Path:
    """The keyframes, the first PCD replaced by ``n_points`` points of its own repeated."""
    kf = dst / "keyframes"
    kf.mkdir()
    src = marina / "keyframes"
    for f in src.iterdir():
        (kf / f.name).symlink_to(f)
    first = sorted(src.glob("pclKeyFrame*.pcd"), key=lambda p: int(p.stem[11:]))[0]
    lines = first.read_text(encoding="ascii").splitlines()
    data_at = next(i for i, line in enumerate(lines) if line.startswith("DATA")) + 1
    points = lines[data_at:]
    header = [re.sub(r"^(POINTS|WIDTH) .*", rf"\1 {n_points}", line) for line in lines[:data_at]]
    (kf / first.name).unlink()
    with (kf / first.name).open("w", encoding="ascii") as fh:
        fh.write("\n".join(header) + "\n")
        block = "\n".join(points) + "\n"
        for _ in range(n_points // len(points)):
            fh.write(block)
        fh.write("".join(p + "\n" for p in points[: n_points % len(points)]))
    return kf / first.name


def peak_rss(source: Path, out: Path, cache: bool) -> tuple[float, float, int]:
    """``(peak RSS in MB, wall s, exit status)`` of ``sonarslam run SOURCE --backend dr``."""
    env = dict(os.environ, SONARSLAM_CACHE="" if cache else "off", MPLBACKEND="Agg")
    cmd = ["/usr/bin/time", "-v", SONARSLAM, "run", str(source), "--backend", "dr"]
    proc = subprocess.run(
        [*cmd, "--out", str(out), "--quiet"], env=env, capture_output=True, text=True
    )
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", proc.stderr)
    if proc.returncode:
        print(proc.stderr.strip().splitlines()[-25:], file=sys.stderr)
    parts = [float(x) for x in wall.group(1).split(":")] if wall else [float("nan")]
    seconds = sum(v * 60.0**k for k, v in enumerate(reversed(parts)))
    return (int(rss.group(1)) / 1024.0 if rss else float("nan")), seconds, proc.returncode


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=int, default=10, help="beams per marina beam (default 10)")
    ap.add_argument("--pcd-points", type=int, default=10_000_000)
    ap.add_argument("--work", default=None, help="folder for the datasets (default: a temp)")
    ap.add_argument("--keep", action="store_true", help="keep the datasets")
    args = ap.parse_args()
    root = os.environ.get("SONARSLAM_DATA")
    if not root or not (Path(root) / "marina").is_dir():
        print("needs $SONARSLAM_DATA/marina", file=sys.stderr)
        return 1
    marina = Path(root) / "marina"
    work = Path(args.work or tempfile.mkdtemp(prefix="sonarslam-memory-"))
    rows = []
    try:
        rows.append(("marina keyframes, no cache", *peak_rss(marina, work / "o1", cache=False)))
        peak_rss(marina, work / "o2", cache=True)  # builds the cache
        rows.append(("marina keyframes, cached", *peak_rss(marina, work / "o3", cache=True)))
        for scale in (1, args.scale):
            d = work / f"is{scale}"
            _link_logs(marina, d, with_keyframes=False)
            size = write_is_log(marina, d, scale).stat().st_size
            label = f"IS log {scale}x ({size / 1e6:.0f} MB)"
            rows.append((label, *peak_rss(d, work / f"o-is{scale}", cache=False)))
            shutil.rmtree(d) if not args.keep else None
        d = work / "pcd"
        _link_logs(marina, d, with_keyframes=True)
        size = write_big_pcd(marina, d, args.pcd_points).stat().st_size
        label = f"PCD of {args.pcd_points:,} points ({size / 1e6:.0f} MB)"
        rows.append((label, *peak_rss(d, work / "o-pcd", cache=False)))
    finally:
        if not args.keep and args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    print(f"{'input':<40} {'peak RSS (MB)':>14} {'wall (s)':>9} {'exit':>5}")
    for label, rss, wall, code in rows:
        print(f"{label:<40} {rss:>14.0f} {wall:>9.1f} {code:>5}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
