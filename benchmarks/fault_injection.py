"""End-to-end sensor faults and command-line misuse: what each does now (issue 14's lists).

python benchmarks/fault_injection.py [--seconds 300] [--backends dr,ekf] [--out FILE.md]

On the first ``--seconds`` of the marina's navigation (its logs, keyframes and timestamps cut to
that window; a simulated harbour of that length when the marina is absent), each fault is put
into a copy of the logs (or a ``--config`` file) and ``sonarslam run`` is called in-process for
each back end. A row gives the exit code, the ATE mean / max (m) when the run completed, whether
every output number is finite and ``metrics.json`` strict JSON, and the first thing the run
said (warning or error, abbreviated). A fault is handled when it completes with a warning naming
it and finite outputs, or stops with a one-line error.

The second table calls the CLI with the misuse the issue lists and reports the exit code, the
number of stderr lines and whether anything was left at ``--out``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the fuzzer's slicing helper

from sonarslam.datasets.simulator import simulate  # noqa: E402
from sonarslam.datasets.source import data_root  # noqa: E402
from sonarslam.slam.cli.main import main  # noqa: E402
from sonarslam.slam.io.trajectory import read_tum, trajectory_stem  # noqa: E402
from tests.fuzz_inputs import edit_log_rows, marina_window  # noqa: E402

Edit = Callable[[Path], list[str]]


def build_window(folder: Path, seconds: float) -> str:
    """The first ``seconds`` of the marina's navigation in ``folder``; returns a label."""
    root = data_root()
    if root is not None and (root / "marina").is_dir():
        marina = root / "marina"
        mti = next((marina / "logs").glob("*_MTi.log"))
        first = next(
            float(ln.split()[0])
            for ln in mti.read_text(encoding="latin-1").splitlines()
            if ln.strip() and not ln.startswith("%")
        )
        for rel, content in marina_window(marina, first, first + seconds).items():
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / rel).write_bytes(content)
        return f"marina, first {seconds:g} s"
    simulate("harbour", seed=1, out_dir=folder, duration_s=seconds)
    return f"simulated harbour seed 1, {seconds:g} s (the marina was not found)"


def _log(folder: Path, suffix: str) -> Path:
    return next(folder.rglob(f"*_{suffix}.log"))


def _drop(suffix: str, a: float, b: float) -> Edit:
    def edit(folder: Path) -> list[str]:
        edit_log_rows(_log(folder, suffix), lambda t, f: [] if a <= t <= b else [f])
        return []

    return edit


def _set_once(suffix: str, at_s: float, changes: dict[int, str]) -> Edit:
    def edit(folder: Path) -> list[str]:
        done = [False]

        def change(t: float, f: list[str]) -> list[list[str]]:
            if t >= at_s and not done[0]:
                done[0] = True
                f = [changes.get(i, v) for i, v in enumerate(f)]
            return [f]

        edit_log_rows(_log(folder, suffix), change)
        return []

    return edit


def _mti_jump_duplicates(folder: Path) -> list[str]:
    def dup(t: float, f: list[str]) -> list[list[str]]:
        if 100.0 <= t <= 110.0:
            jumped = list(f)
            jumped[3] = f"{(float(f[3]) + 90.0 + 180.0) % 360.0 - 180.0:.3f}"
            return [f, jumped]
        return [f]

    edit_log_rows(_log(folder, "MTi"), dup)
    return []


def _config(text: str) -> Edit:
    def edit(folder: Path) -> list[str]:
        path = folder.parent / f"{folder.name}.toml"
        path.write_text(text)
        return ["--config", str(path)]

    return edit


def _every(suffix: str, fn: Callable[[float, list[str]], list[list[str]]]) -> Edit:
    def edit(folder: Path) -> list[str]:
        edit_log_rows(_log(folder, suffix), fn)
        return []

    return edit


#: The issue's end-to-end faults: (name, how it is put into the logs).
FAULTS: list[tuple[str, Edit]] = [
    ("none (baseline)", lambda folder: []),
    ("DVL rows missing for 60 s", _drop("DVL", 100.0, 160.0)),
    ("MTi gap of 60 s", _drop("MTi", 100.0, 160.0)),
    ("one DVL spike of 1e308 cm/s", _set_once("DVL", 100.0, {11: "1e308"})),
    ("one DVL spike of 5,000 cm/s", _set_once("DVL", 100.0, {11: "5000.00"})),
    ("one GPS fix at 0/0", _set_once("DGPS", 100.0, {1: "0.0", 2: "0.0"})),
    ("MTi stamps duplicated with a 90 deg jump (10 s)", _mti_jump_duplicates),
    ("one MTi heading set to 0 (~120 deg off)", _set_once("MTi", 100.0, {3: "0.000"})),
    ("one GPS fix 500 m off (lat + 0.27')", _set_once("DGPS", 100.0, {1: "4212.5"})),
    ("[noise] dvl_sigma_mps = 1e300", _config("[noise]\ndvl_sigma_mps = 1e300\n")),
    ("[sonar] time_offset_s = 1e9", _config("[sonar]\ntime_offset_s = 1e9\n")),
    ("[sonar] time_offset_s = 150 (150 ms meant)", _config("[sonar]\ntime_offset_s = 150\n")),
    ("GPS ending early (first 100 s only)", _drop("DGPS", 100.0, 1e9)),
    ("every GPS fix twice", _every("DGPS", lambda t, f: [f, f])),
    ("every DVL row without bottom lock", _every("DVL", lambda t, f: [[*f[:14], "0", *f[15:]]])),
]


def _strict_json(path: Path) -> bool:
    def bad(name: str) -> float:
        raise ValueError(name)

    try:
        json.loads(path.read_text(), parse_constant=bad)
    except (ValueError, OSError):
        return False
    return True


def _call(args: list[str]) -> tuple[int, list[str]]:
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = main(args)
        except SystemExit as exc:  # argparse's usage errors
            code = int(exc.code or 0)
    return code, [ln for ln in err.getvalue().splitlines() if ln.strip()]


def run_fault(name: str, edit: Edit, base: Path, work: Path, backend: str) -> dict[str, object]:
    folder = work / f"case{abs(hash((name, backend))) % 10**8}"
    shutil.copytree(base, folder)
    extra = edit(folder)
    out = work / f"out-{folder.name}"
    code, said = _call(
        ["run", str(folder), "--backend", backend, "--out", str(out), "--quiet", *extra]
    )
    row: dict[str, object] = {"fault": name, "backend": backend, "exit": code, "said": said}
    metrics = out / "metrics.json"
    if code == 0 and metrics.is_file():
        m = json.loads(metrics.read_text())
        tr = read_tum(out / f"{trajectory_stem(backend)}.tum")
        row["ate"] = f"{m['ate_mean_m']:.2f} / {m['ate_max_m']:.2f}"
        row["finite"] = bool(np.all(np.isfinite(tr.poses_wTb))) and _strict_json(metrics)
        row["counters"] = {
            k: v
            for k, v in m.items()
            if (k.startswith(("fault_", "gap_")) and v and k != "gap_spans_s")
        }
    shutil.rmtree(folder, ignore_errors=True)
    shutil.rmtree(out, ignore_errors=True)
    return row


def cli_cases(base: Path, work: Path) -> list[dict[str, object]]:
    """The issue's command-line misuse: exit code, stderr lines, what was left at --out."""
    a_file = work / "a_file"
    a_file.write_text("x")
    src = str(base)
    cases: list[tuple[str, list[str], Path | None]] = [
        ("run --out FILE", ["run", src, "--out", str(a_file)], None),
        ("run --out FILE/below", ["run", src, "--out", str(a_file / "below")], None),
        ("run --out /proc/... (unwritable)", ["run", src, "--out", "/proc/sonarslam-out"], None),
        (
            "run --set extractor.min_votes=abc",
            ["run", src, "--backend", "ekf", "--set", "extractor.min_votes=abc"],
            work / "o1",
        ),
        (
            "run --set extractor.rho_res_m=0",
            ["run", src, "--backend", "ekf", "--set", "extractor.rho_res_m=0"],
            work / "o2",
        ),
        (
            "run --set ekf.ahrs_period_s=0",
            ["run", src, "--backend", "ekf", "--set", "ekf.ahrs_period_s=0"],
            work / "o3",
        ),
        (
            "run --set extractor.max_range_m=nan",
            ["run", src, "--backend", "ekf", "--set", "extractor.max_range_m=nan"],
            work / "o4",
        ),
        (
            "run --set extractor.min_votes=1.5",
            ["run", src, "--backend", "ekf", "--set", "extractor.min_votes=1.5"],
            work / "o5",
        ),
        ("run SOURCE missing", ["run", str(work / "nowhere")], work / "o6"),
        ("run SOURCE with a bad log", ["run", str(work / "bad")], work / "o7"),
        ("sweep --workers 0", ["sweep", "--seeds", "0", "--workers", "0"], work / "o8"),
        ("calibrate --window 0", ["calibrate", src, "--window", "0"], None),
        ("calibrate --window nan", ["calibrate", src, "--window", "nan"], None),
        ("plot-scans --out DIR (existing)", ["plot-scans", src, "--out", str(work)], None),
        (
            "plot-scans --out DIR (no .png)",
            ["plot-scans", src, "--out", str(work / "pics")],
            work / "pics",
        ),
    ]
    bad = work / "bad"
    shutil.copytree(base, bad)
    _set_once("MTi", 50.0, {3: "12x.5"})(bad)
    rows = []
    for name, args, out in cases:
        if out is not None and "--out" not in args:
            args = [*args, "--out", str(out)]
        before = {p for p in work.iterdir()}
        code, said = _call(args)
        left = sorted(p.name for p in set(work.iterdir()) - before)
        rows.append(
            {"case": name, "exit": code, "lines": len(said), "said": said[:1], "left": left}
        )
    return rows


def _md_said(said: list[str], width: int = 150) -> str:
    text = " / ".join(s.replace("|", "/") for s in said[:2])
    text = text.replace(str(Path(tempfile.gettempdir())), "$TMP")
    return text if len(text) <= width else text[: width - 3] + "..."


def main_() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=300.0)
    parser.add_argument("--backends", default="dr,ekf")
    parser.add_argument("--out", default=None, help="write the tables to this markdown file")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="faults_"))
    base = work / "base"
    base.mkdir()
    label = build_window(base, args.seconds)
    lines = [
        f"End-to-end faults on {label}",
        "",
        "| fault | back end | exit | ATE mean / max (m) | finite, strict JSON | counted | said |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, edit in FAULTS:
        for backend in args.backends.split(","):
            r = run_fault(name, edit, base, work, backend)
            counted = ", ".join(
                f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                for k, v in dict(r.get("counters", {})).items()
            )
            lines.append(
                f"| {name} | {backend} | {r['exit']} | {r.get('ate', '-')} | "
                f"{r.get('finite', '-')} | {counted or '-'} | {_md_said(list(r['said']))} |"
            )
            print(lines[-1], flush=True)
    lines += [
        "",
        "Command-line misuse",
        "",
        "| case | exit | stderr lines | left at --out | said |",
        "|---|---|---|---|---|",
    ]
    for r in cli_cases(base, work):
        lines.append(
            f"| {r['case']} | {r['exit']} | {r['lines']} | {', '.join(r['left']) or 'nothing'} | {_md_said(list(r['said']))} |"
        )
        print(lines[-1], flush=True)
    if args.out:
        Path(args.out).write_text("\n".join(lines) + "\n")
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main_()
