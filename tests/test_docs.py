"""The README's and docs/' generated figures are the rendering of docs/figures.json, and what it
records is what the code gives now (the cheap part re-measured; the closed loops by the digest
of the settings they ran with). ``make readme-figures`` measures and renders them."""

from __future__ import annotations

import importlib.util
import json
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
