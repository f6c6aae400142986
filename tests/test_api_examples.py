"""The three examples of docs/api.md (scripts in docs/examples/, shown whole on the page:
``tests/test_docs_examples.py`` checks the page holds them as they are) run, and what they find
is checked against the simulator's truth."""

from __future__ import annotations

import runpy
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sonarslam.features.geometry import line_difference, line_world_to_frame
from sonarslam.slam.eval.truth import truth_trajectory, truth_walls, wall_lines_world

EXAMPLES = Path(__file__).resolve().parents[1] / "docs" / "examples"


def _run(name: str, where: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """The script's globals after it ran in ``where``."""
    monkeypatch.chdir(where)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the simulated DVL's dropout warns, as it should
        return runpy.run_path(str(EXAMPLES / f"{name}.py"), run_name="__main__")


def _nearest_wall(z: np.ndarray, walls_z: list[np.ndarray]) -> tuple[int, np.ndarray]:
    """The wall (index) whose line is nearest ``z`` (both in one frame), and the difference."""
    diffs = [line_difference(z, w)[0] for w in walls_z]
    i = int(np.argmin([abs(d[0]) + 10.0 * abs(d[1]) for d in diffs]))  # 10 m per rad
    return i, diffs[i]


def test_the_front_end_alone_finds_the_true_walls(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    g = _run("front_end", tmp_path, monkeypatch)
    printed = [ln for ln in capsys.readouterr().out.splitlines() if "rho" in ln]
    lines, sim = g["lines"], g["sim"]
    assert len(printed) == len(lines) >= 8
    walls_w = wall_lines_world(sim.world.walls_m)
    found = set()
    for line in lines:  # the pose source is the truth: wTr is the true sonar pose
        i, d = _nearest_wall(line.z, [line_world_to_frame(w, line.wTr)[0] for w in walls_w])
        assert abs(d[0]) < 0.1 and abs(d[1]) < np.deg2rad(1.0), (line, d)
        assert np.all(np.abs(d) < 4.0 * np.sqrt(np.diag(line.cov))), (line, d)
        found.add(i)
    assert len(found) >= 3


def _map_against_truth(g: dict[str, Any], final: Any) -> None:
    """Every landmark, seen from the final pose, is a true wall seen from the true pose (the map
    relative to the vehicle: the start pose's error and the AHRS bias, which nothing here
    observes, cancel), each wall once."""
    ds = g["ds"]
    true_pose = truth_trajectory(ds).poses(g["t_k"])[0]
    walls_z = [line_world_to_frame(w, true_pose)[0] for w in wall_lines_world(truth_walls(ds))]
    assert final.k >= 3
    found = []
    for line_w in final.lines_w:
        i, d = _nearest_wall(line_world_to_frame(line_w, final.wTb)[0], walls_z)
        assert abs(d[0]) < 0.3 and abs(d[1]) < np.deg2rad(1.5), (line_w, d)
        found.append(i)
    assert len(set(found)) == len(found), f"a wall is two landmarks: {found}"
    stats = g["association"].map.stats
    assert stats["associated"] >= 2 * final.k  # re-observed, not only made


def test_the_plugin_examples_map_the_true_walls_alike(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    graph = _run("isam2_plugin", tmp_path, monkeypatch)
    _map_against_truth(graph, graph["final"])
    assert graph["k"] >= 10  # a pose node per vote
    ekf = _run("ekf_plugin", tmp_path, monkeypatch)
    _map_against_truth(ekf, ekf["final"])
    # the same decisions, and the two estimators' landmarks alike
    assert ekf["final"].k == graph["final"].k
    for a, b in zip(ekf["final"].lines_w, graph["final"].lines_w, strict=True):
        d = line_difference(a, b)[0]
        assert abs(d[0]) < 0.3 and abs(d[1]) < np.deg2rad(1.0), (a, b)
