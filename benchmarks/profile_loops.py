"""cProfile tables of the closed-loop speed benchmarks: where the time of each loop goes.

Runs ``benchmarks/ekf_speed.py`` and ``benchmarks/isam2_speed.py`` (the lines, and lines +
scans) under :mod:`cProfile`, each in its own process pinned to one core, and writes per run
the 25 functions with the most own time (``tottime``) and the most time with callees
(``cumtime``) as text: ``benchmarks/profiles/<label>_<run>.txt``. ``--repo`` profiles another
checkout's benchmarks with this interpreter's ``sys.path`` set to it (``/work/main`` for the
"before" tables), so that both are measured the same way.

Usage::

    .venv/bin/python benchmarks/profile_loops.py --label after
    /work/main/.venv/bin/python benchmarks/profile_loops.py --repo /work/main --label before
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import runpy
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
RUNS = {
    "ekf": ("ekf_speed.py", []),
    "isam2_lines": ("isam2_speed.py", []),
    "isam2_lines_scans": ("isam2_speed.py", ["--set", "isam2.constraints=lines,scans"]),
}
TOP = 25


def profile_one(repo: Path, script: str, args: list[str], out_json: Path) -> str:
    """The two tables of one benchmark run in this process, as text."""
    bench = repo / "benchmarks"
    sys.path[:0] = [str(bench), str(repo)]
    os.chdir(repo)
    sys.argv = [str(bench / script), *args, "--out", str(out_json)]
    prof = cProfile.Profile()
    prof.enable()
    try:
        runpy.run_path(str(bench / script), run_name="__main__")
    except SystemExit:
        pass
    prof.disable()
    buf = io.StringIO()
    stats = pstats.Stats(prof, stream=buf).strip_dirs()
    for key in ("tottime", "cumtime"):
        buf.write(f"\n=== top {TOP} by {key} ===\n")
        stats.sort_stats(key).print_stats(TOP)
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repo", default=str(HERE.parent), help="checkout to profile")
    parser.add_argument("--label", default="after", help="file name prefix (before, after)")
    parser.add_argument("--only", choices=sorted(RUNS), help="one run (default: all)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    repo = Path(args.repo).resolve()
    out_dir = HERE / "profiles"
    if args.child:  # one run in this (fresh) process
        script, extra = RUNS[args.child]
        text = profile_one(repo, script, extra, out_dir / f"{args.label}_{args.child}.json")
        head = f"# {args.label}: {script} {' '.join(extra)} in {repo}, one core, cProfile\n"
        (out_dir / f"{args.label}_{args.child}.txt").write_text(head + text)
        return 0
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in [args.only] if args.only else list(RUNS):
        cmd = [sys.executable, __file__, "--repo", str(repo), "--label", args.label]
        rc = subprocess.call([*cmd, "--child", name])
        if rc:
            return rc
        (out_dir / f"{args.label}_{name}.json").unlink(missing_ok=True)
        print(f"written {out_dir / f'{args.label}_{name}.txt'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
