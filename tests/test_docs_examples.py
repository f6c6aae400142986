"""Every example of the README and of docs/ runs as written, after the quickstart.

An example is a fenced block of ``sh``, ``python`` or ``toml`` (``text`` and unlabelled blocks
are not); a ``toml`` block under ``<!-- file: NAME -->`` is that file, written where the
examples run; a ``python`` block under ``<!-- script: PATH -->`` is the script ``PATH``
(:data:`SCRIPTS`) as it is, checked here and run by ``tests/test_api_examples.py``. Each page
runs in a fresh copy of a layout like a clone beside ``shared/``::

    WORK/clone/                     the working directory: the clone's root (its benchmarks/,
                                    notebooks/, Makefile and .venv are this repository's)
    WORK/shared/datasets/marina/    the first MARINA_WINDOW_S seconds of the real marina

after the quickstart: ``make run`` (the Makefile's ``run`` recipe, ``sonarslam demo --out
out``, read from the Makefile) has written ``out/`` there, and ``SONARSLAM_DATA`` points at
``WORK/shared/datasets`` as the quickstart's ``export SONARSLAM_DATA=$PWD/../shared/datasets``
does. The blocks of a page run in document order. Without the real marina the examples, which
name it, skip with a reason (as every marina test).

How a shell line runs:

* ``sonarslam ARGS``: ``sonarslam.slam.cli.main.main(ARGS)`` in this process (a process per command would
  cost seconds of imports each); it must exit 0;
* ``make TARGET``: ``run`` is the quickstart above (its recipe checked; ``sonarslam demo --out
  out``, the recipe's command, is that same quickstart too); the other targets must
  exist in the Makefile and are not run here (``test`` is this suite; ``venv`` made the
  interpreter running it);
* ``. .venv/bin/activate`` must exist; ``export NAME=VALUE`` sets it (``$PWD``, ``$NAME``
  expanded);
* ``evo_ape`` and ``evo_traj``: evo's own CLI, as a process;
* ``.venv/bin/python benchmarks/NAME.py ARGS``: the script, in this process;
* :data:`SHORTER`: the commands that run shorter here than written (simulations and Monte
  Carlo sweeps of many minutes), by the options set; each is an option of its command.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import runpy
import shlex
import shutil
import subprocess
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from sonarslam.slam.cli.main import build_parser, main
from tests.conftest import marina_root
from tests.fuzz_inputs import marina_window

ROOT = Path(__file__).resolve().parents[1]
#: The pages whose examples run, in this order: the README, then every page under docs/ (the
#: research record in docs/research/ too).
PAGES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").rglob("*.md"))]
#: Length of the marina window the examples run on (s from the start of the navigation logs).
MARINA_WINDOW_S = 150.0
#: Commands run shorter than written: (sonarslam subcommand, a token the command holds) ->
#: the options set (replaced, or added).
SHORTER: dict[tuple[str, str], dict[str, str]] = {
    ("simulate", "harbour"): {"--duration": "120"},  # 600 s by default
    ("simulate", "drift"): {"--duration": "360"},  # 1,800 s by default
    ("simulate", "drawn"): {"--duration": "360"},  # 1,800 s by default
    ("sweep", "harbour"): {"--seeds": "0-1", "--duration": "60", "--scheduler": "synchronous"},
    ("sweep", "drift"): {"--seeds": "0", "--duration": "360", "--scheduler": "synchronous"},
    # the drawn worlds' sweep with --calibrate: 480 s is the shortest whose line-noise
    # calibration finds its 20 pairs (360 s: 19), one seed, two back ends
    ("sweep", ""): {
        "--seeds": "0",
        "--duration": "480",
        "--backend": "dr,ekf",
        "--scheduler": "synchronous",
    },
}
#: What an example must print, by its ``<!-- example: NAME -->`` marker.
EXPECTED: dict[str, Callable[[str], bool]] = {
    "typed_run": lambda out: "{'isam2.robust': 'cauchy'}" in out and "against the truth" in out,
    "load_graph": lambda out: "graph error" in out and "line landmarks" in out,
}
#: The example scripts pages show whole (``<!-- script: PATH -->`` above the block): each block
#: must be the file as it is; ``tests/test_api_examples.py`` runs them and checks their results.
SCRIPTS = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs" / "examples").glob("*.py"))
#: The order docs/api.md shows them in.
SCRIPTS_IN_API_ORDER = [
    f"docs/examples/{n}.py" for n in ("front_end", "isam2_plugin", "ekf_plugin")
]
FENCE = re.compile(r"^```([a-z]*)\s*$")


@dataclass
class Example:
    page: str
    line: int  # of the opening fence
    lang: str
    code: str
    marker: str | None  # the <!-- example: NAME -->, <!-- file: NAME --> or <!-- script: PATH -->

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def examples(page: str) -> list[Example]:
    """The examples of a page, in document order."""
    lines = (ROOT / page).read_text().splitlines()
    out, k = [], 0
    while k < len(lines):
        m = FENCE.match(lines[k])
        if not m:
            k += 1
            continue
        end = next(j for j in range(k + 1, len(lines)) if lines[j].startswith("```"))
        above = next((lines[j] for j in range(k - 1, -1, -1) if lines[j].strip()), "")
        marker = re.fullmatch(r"<!-- (?:example|file|script): (\S+) -->", above.strip())
        if m[1] in ("sh", "python", "toml"):
            code = "\n".join(lines[k + 1 : end]) + "\n"
            out.append(Example(page, k + 1, m[1], code, marker[1] if marker else None))
        k = end + 1
    return out


def shell_commands(code: str) -> list[str]:
    """The commands of a shell block: continuation lines joined, blank lines dropped."""
    joined = code.replace("\\\n", " ")
    return [ln for ln in joined.splitlines() if ln.split("#", 1)[0].strip()]


def makefile_targets() -> dict[str, list[str]]:
    """Target -> recipe lines of the Makefile."""
    targets: dict[str, list[str]] = {}
    current = None
    for ln in (ROOT / "Makefile").read_text().splitlines():
        m = re.match(r"^([A-Za-z][\w.-]*)\s*:(?!=)", ln)
        if m:
            current = m[1]
            targets.setdefault(current, [])
        elif ln.startswith("\t") and current is not None:
            targets[current].append(ln.strip())
        elif ln.strip() and not ln.startswith("#"):
            current = None
    return targets


def make_run_argv() -> list[str]:
    """The ``sonarslam`` arguments of the Makefile's ``run`` recipe."""
    (recipe,) = makefile_targets()["run"]
    words = shlex.split(recipe.replace("$(BIN)/", "").replace("$(OUT)", "out"))
    assert words[0] == "sonarslam", recipe
    return words[1:]


def shorter(argv: list[str]) -> list[str]:
    """``argv`` with the options of :data:`SHORTER` that apply to it."""
    for (command, token), options in SHORTER.items():  # the first that applies
        if argv[:1] == [command] and (token in argv or not token):
            argv = list(argv)
            for opt, value in options.items():
                if opt in argv:
                    argv[argv.index(opt) + 1] = value
                else:
                    argv += [opt, value]
            return argv
    return argv


def _expand(text: str, env: dict[str, str]) -> str:
    return re.sub(r"\$\{?([A-Za-z_]\w*)\}?", lambda m: env.get(m[1], ""), text)


class Shell:
    """Runs the commands of shell and Python blocks (module docstring) in ``cwd``."""

    def __init__(
        self, cwd: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
    ) -> None:
        self.cwd = cwd
        self.capsys = capsys
        self.monkeypatch = monkeypatch
        self.log: list[str] = []

    def fail(self, ex: Example, what: str) -> None:
        tail = "\n".join(self.log[-40:])
        pytest.fail(f"{ex.where}: {what}\n--- output ---\n{tail}", pytrace=False)

    def sonarslam(self, ex: Example, argv: list[str]) -> None:
        code: int | str | None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                code = main(argv)
        except SystemExit as exc:  # --version, --help
            code = exc.code
        out = self.capsys.readouterr()
        self.log += [f"$ sonarslam {shlex.join(argv)}", out.out, out.err]
        if code not in (0, None):
            self.fail(ex, f"sonarslam {shlex.join(argv)} exited {code}")

    def script(self, ex: Example, path: str, args: list[str]) -> None:
        script = (self.cwd / path).resolve()
        old_argv, old_path = sys.argv, list(sys.path)
        sys.argv = [str(script), *args]
        sys.path.insert(0, str(script.parent))
        code: int | str | None = 0
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                runpy.run_path(str(script), run_name="__main__")
        except SystemExit as exc:
            code = exc.code
        finally:
            sys.argv, sys.path[:] = old_argv, old_path
        out = self.capsys.readouterr()
        self.log += [f"$ python {path} {shlex.join(args)}", out.out, out.err]
        if code not in (0, None):
            self.fail(ex, f"{path} exited {code}")

    def line(self, ex: Example, text: str) -> None:
        env = {**os.environ, "PWD": str(self.cwd)}
        words = [_expand(w, env) for w in shlex.split(text, comments=True)]
        head, args = words[0], words[1:]
        if head == "sonarslam":
            if args == make_run_argv():  # the quickstart itself: ran before the page
                assert (self.cwd / "out").is_dir(), "the quickstart wrote no out/"
                return
            self.sonarslam(ex, shorter(args))
        elif head == "make":
            targets = makefile_targets()
            for target in args:
                assert target in targets, f"{ex.where}: no make target {target!r}"
                if target == "run":  # the quickstart: done before the page, into out/
                    assert (self.cwd / "out").is_dir(), "the quickstart wrote no out/"
        elif head in (".", "source"):
            assert (self.cwd / args[0]).is_file(), f"{ex.where}: no {args[0]}"
        elif head == "export":
            for item in args:
                name, _, value = item.partition("=")
                self.monkeypatch.setenv(name, value)
        elif head in ("evo_ape", "evo_traj"):
            exe = Path(sys.executable).parent / head
            out = subprocess.run(
                [str(exe), *args], cwd=self.cwd, capture_output=True, text=True, timeout=300
            )
            self.log += [f"$ {text}", out.stdout, out.stderr]
            if out.returncode != 0:
                self.fail(ex, f"{head} exited {out.returncode}")
        elif head.endswith("/python") and args and args[0].endswith(".py"):
            self.script(ex, args[0], args[1:])
        else:
            self.fail(ex, f"the example runner does not know {head!r}: teach it or rewrite")

    def run(self, ex: Example) -> None:
        if ex.lang == "toml":
            assert ex.marker, f"{ex.where}: a toml example names its file (<!-- file: NAME -->)"
            (self.cwd / ex.marker).write_text(ex.code)
        elif ex.lang == "sh":
            for text in shell_commands(ex.code):
                self.line(ex, text)
        elif ex.marker in SCRIPTS:  # a script the page shows whole: run by test_api_examples
            script = (ROOT / ex.marker).read_text()
            assert ex.code == script, f"{ex.where}: the block is not {ex.marker} as it is"
        else:
            try:
                exec(compile(ex.code, ex.where, "exec"), {"__name__": "__main__"})
            except Exception as exc:  # noqa: BLE001  # the example's own failure, named
                self.fail(ex, f"{type(exc).__name__}: {exc}")
            out = self.capsys.readouterr().out
            self.log.append(out)
            check = EXPECTED.get(ex.marker or "")
            if check is not None and not check(out):
                self.fail(ex, f"example {ex.marker!r} did not print what it says it prints")


def _nav_start_s(marina: Path) -> float:
    dvl = next((marina / "logs").glob("*_DVL.log")).read_text()
    first = next(ln for ln in dvl.splitlines() if ln.strip() and not ln.startswith("%"))
    return float(first.split()[0])


@pytest.fixture(scope="session")
def quickstart(shared_dir: Callable[[str, Callable[[Path], None]], Path]) -> Path:
    """WORK (module docstring) after ``make run`` on the marina window; read only."""
    source = marina_root()
    if source is None:
        pytest.skip("real marina data not found under $SONARSLAM_DATA (the examples name it)")

    def build(work: Path) -> None:
        data = work / "shared" / "datasets"
        t0 = _nav_start_s(source)
        for rel, content in marina_window(source, t0, t0 + MARINA_WINDOW_S).items():
            (data / "marina" / rel).parent.mkdir(parents=True, exist_ok=True)
            (data / "marina" / rel).write_bytes(content)
        clone = work / "clone"
        clone.mkdir()
        for name in ("benchmarks", "notebooks", "docs", "Makefile"):
            (clone / name).symlink_to(ROOT / name)
        (clone / ".venv").symlink_to(Path(sys.prefix))
        old, env = Path.cwd(), dict(os.environ)
        os.chdir(clone)
        os.environ["SONARSLAM_DATA"] = str(data)
        printed = io.StringIO()
        try:
            with contextlib.redirect_stdout(printed), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                assert main([*make_run_argv(), "--quiet"]) == 0
        finally:
            os.chdir(old)
            os.environ.clear()
            os.environ.update(env)
        (work / "make_run.txt").write_text(printed.getvalue())

    return shared_dir("docs-quickstart", build)


def test_examples_are_found() -> None:
    """The runner sees the examples the pages hold (a renamed fence would silently drop one)."""
    found = {p: examples(p) for p in PAGES}
    assert [e.marker for e in found["docs/api.md"]] == [*SCRIPTS_IN_API_ORDER, "typed_run"]
    for ex in found["docs/api.md"][:3]:
        assert ex.code == (ROOT / str(ex.marker)).read_text(), ex.where
    assert "load_graph" in [e.marker for e in found["docs/outputs.md"]]
    readme = found["README.md"]
    assert [e.lang for e in readme].count("sh") >= 4
    assert make_run_argv() == ["demo", "--out", "out"]
    commands = [c for e in readme if e.lang == "sh" for c in shell_commands(e.code)]
    assert any(c.startswith("make run") for c in commands)
    # every option the runner sets is an option of its command
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for (command, _), options in SHORTER.items():
        strings = {s for a in sub.choices[command]._actions for s in a.option_strings}
        assert set(options) <= strings, (command, set(options) - strings)


def test_the_readme_api_example_says_the_warning_it_prints(tmp_path, monkeypatch) -> None:
    """A new user's first API call prints a DataWarning of DVL gaps (the simulator's dropouts):
    the example says so, and the warning is there to be said."""
    (example,) = [e for e in examples("README.md") if e.lang == "python"]
    opening = example.code[: example.code.index("result = ")]
    assert "a warning of DVL gaps is expected" in opening
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        exec(opening, {})
    assert any("gap(s) of the DVL" in str(w.message) for w in caught), caught


def test_quickstart_says_what_it_ran(quickstart: Path) -> None:
    printed = (quickstart / "make_run.txt").read_text()
    assert "on the real marina" in printed and "against GPS" in printed
    assert "isam2 offline: ATE over the sonar span" in printed  # the offline estimate's line
    for backend in ("dr", "ekf", "isam2"):
        assert (quickstart / "clone" / "out" / f"marina-{backend}" / "metrics.json").is_file()


@pytest.mark.parametrize("page", [p for p in PAGES if examples(p)])
def test_page_examples_run_as_written(
    page: str,
    quickstart: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    found = examples(page)
    work = tmp_path / "work"
    shutil.copytree(quickstart, work, symlinks=True)
    clone = work / "clone"
    monkeypatch.chdir(clone)
    monkeypatch.setenv("SONARSLAM_DATA", str(work / "shared" / "datasets"))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    shell = Shell(clone, capsys, monkeypatch)
    for ex in found:
        shell.run(ex)
