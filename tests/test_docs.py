"""The README's and docs/' generated figures are the rendering of docs/figures.json, and what it
records is what the code gives now (the cheap part re-measured; the closed loops by the digest
of the settings they ran with). ``make readme-figures`` measures and renders them."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path
from types import ModuleType

import pytest

from sonarslam.datasets.source import Dataset
from sonarslam.slam.eval.ate import ate_against_gps
from sonarslam.slam.run.sources import dead_reckoning_trajectory

ROOT = Path(__file__).resolve().parents[1]


def _figures_module() -> ModuleType:
    sys.path.insert(0, str(ROOT / "benchmarks"))  # the script imports benchmarks/common.py
    spec = importlib.util.spec_from_file_location(
        "readme_figures", ROOT / "benchmarks" / "readme_figures.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


rf = _figures_module()


def _recorded() -> dict:
    return json.loads(rf.FIGURES.read_text())


def test_generated_blocks_are_the_rendering_of_the_recorded_figures():
    """No generated figure is edited by hand: each block is its renderer's output."""
    fig = _recorded()
    names = [name for page in rf.PAGES for name, _ in rf.blocks(page.read_text())]
    assert {"marina-headline", "marina-dataset"} <= set(names)
    assert set(names) <= set(rf.RENDERERS), set(names) - set(rf.RENDERERS)
    assert rf.stale_blocks(fig) == [], "run `make readme-figures` (or its --render)"
    # the README's headline numbers are the recorded runs' metrics.json values
    readme = (ROOT / "README.md").read_text()
    dr = fig["runs"]["dr"]
    row = (
        f"{dr['ate_sonar_mean_m']:.2f} / {dr['ate_sonar_max_m']:.2f}"
        f" | {dr['ate_sonar_aligned_mean_m']:.2f} / {dr['ate_sonar_aligned_max_m']:.2f}"
        f" | {dr['ate_mean_m']:.2f} / {dr['ate_max_m']:.2f}"
    )
    assert row in readme


def test_a_hand_edit_is_found(tmp_path):
    fig = _recorded()
    page = tmp_path / "page.md"
    page.write_text(rf.rewrite("x\n<!-- figures: marina-headline -->\n<!-- /figures -->\n", fig))
    assert rf.stale_blocks(fig, [page]) == []
    text = page.read_text()
    ekf = f"{fig['runs']['ekf']['ate_mean_m']:.2f}"
    assert ekf in text
    page.write_text(text.replace(ekf, "0.01", 1))
    assert rf.stale_blocks(fig, [page]) == [f"{page}: marina-headline"]


def test_recorded_figures_are_what_the_code_gives(marina: Dataset):
    """The dataset's counts and dead reckoning re-measured; every recorded run's settings
    digest is the one its configuration has now (a changed preset or calibration makes the
    closed loops' figures stale: `make readme-figures`)."""
    fig = _recorded()
    assert rf.dataset_figures(marina) == pytest.approx(fig["dataset"], rel=1e-9)
    ate = ate_against_gps(dead_reckoning_trajectory(marina), marina.gps)
    dr = fig["runs"]["dr"]
    assert (ate.ate_mean_m, ate.ate_max_m) == pytest.approx(
        (dr["ate_mean_m"], dr["ate_max_m"]), rel=1e-9
    )
    for name in rf.RUNS:
        assert fig["runs"][name]["settings_sha256"] == rf.run_digest(marina, name), (
            f"{name}: its settings changed since docs/figures.json was measured: make readme-figures"
        )


#: The pages whose relative links are checked: the README and every page under docs/.
LINKED_PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
_FENCED = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.S | re.M)
_CODE_SPAN = re.compile(r"(`+)[^`].*?\1", re.S)
_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def _prose(text: str) -> str:
    """``text`` without its fenced blocks and code spans (a link there is an example)."""
    return _CODE_SPAN.sub("", _FENCED.sub("", text))


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a heading: its text (links and code as their words), lowercase,
    every character but letters, digits, spaces, '-' and '_' removed, spaces to '-'."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip())
    text = re.sub(r"[^\w\- ]", "", text.lower())
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every heading anchor of a markdown page (a repeated heading's as GitHub numbers it)."""
    seen: dict[str, int] = {}
    out = set()
    for line in _FENCED.sub("", page.read_text(encoding="utf-8")).splitlines():
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        anchor = github_anchor(m[1])
        out.add(anchor if anchor not in seen else f"{anchor}-{seen[anchor]}")
        seen[anchor] = seen.get(anchor, 0) + 1
    return out


def broken_links(pages: list[Path], root: Path = ROOT) -> list[str]:
    """``page: target`` (the page relative to ``root``) for every relative link of ``pages``
    whose file, or heading, is missing; web and mail links are not followed."""
    broken = []
    for page in pages:
        for target in _LINK.findall(_prose(page.read_text(encoding="utf-8"))):
            if re.match(r"(https?|mailto):", target):
                continue
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            if not dest.exists():
                broken.append(f"{page.relative_to(root)}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                broken.append(f"{page.relative_to(root)}: {target} (no such heading)")
    return broken


def test_github_anchor_rule():
    assert github_anchor("Ping Viewer logs (a BlueROV2 with a Ping360 and an A50)") == (
        "ping-viewer-logs-a-bluerov2-with-a-ping360-and-an-a50"
    )
    assert (
        github_anchor("A Girona-style rig: the caves preset")
        == "a-girona-style-rig-the-caves-preset"
    )
    assert github_anchor("The `marina-seed` preset") == "the-marina-seed-preset"
    assert github_anchor("Revisits at the reference's pairs (issue 29)") == (
        "revisits-at-the-references-pairs-issue-29"
    )


def test_a_broken_link_is_found(tmp_path):
    (tmp_path / "b.md").write_text("# Some heading: here\n")
    page = tmp_path / "a.md"
    page.write_text(
        "[ok](b.md) [ok](b.md#some-heading-here) [web](https://x.org/y.md) `[code](no.md)`\n"
        "[gone](c.md) [bad anchor](b.md#nowhere) [self](#nowhere-either)\n"
        "```sh\n[in a block](no.md)\n```\n"
    )
    assert broken_links([page], root=tmp_path) == [
        "a.md: c.md (no such file)",
        "a.md: b.md#nowhere (no such heading)",
        "a.md: #nowhere-either (no such heading)",
    ]


def test_every_relative_link_of_the_docs_resolves():
    """Every relative link of README.md and docs/ names a file that exists, and a heading of it
    where it gives one (a moved or renamed page breaks no link)."""
    assert broken_links(LINKED_PAGES) == []


def test_the_readme_is_short_and_answers_first():
    """README.md is a user's (issue 43): at most 160 lines, and its first 80 give the
    quickstart, the marina result, bringing one's own data and calling the library."""
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 160, f"README.md has {len(lines)} lines: keep it at most 160"
    head = "\n".join(lines[:80])
    for what, needle in [
        ("the quickstart", "make run"),
        ("the marina result", "<!-- figures: marina-headline -->"),
        ("own data", "docs/data.md"),
        ("the API", "docs/api.md"),
    ]:
        assert needle in head, f"README.md's first 80 lines lack {what} ({needle!r})"
