"""The architecture, enforced: data flows one way (datasets -> sonar -> features -> slam), the
layers inside ``slam`` import only downwards, and no import hides inside a function.

The four packages are the layers of the one import namespace, ``sonarslam.sonar``,
``sonarslam.features``, ``sonarslam.datasets`` and ``sonarslam.slam`` (the folders ``sonar/``,
``features/``, ``datasets/`` and ``slam/``); the rules below name them without the prefix. Every
module of the four is parsed (not imported); every ``import``/``from ... import`` of a project
package is an edge, and a project package is only ever imported through ``sonarslam.``. The
allowed edges:

* ``sonar`` imports nothing of the project but itself;
* ``features`` imports ``sonar`` and itself;
* ``datasets`` imports ``sonar``, ``features.geometry`` and itself;
* the neutral modules at the namespace's root (``sonarslam/settings.py``: typed settings and
  their checks) belong to no layer: every layer may import them, and they import nothing of the
  project;
* nothing outside ``slam`` imports ``slam``;
* inside ``slam``, a module imports its own layer or lower ones, in this order:
  ``io`` < ``model`` < ``mapping`` < ``backends`` < ``eval`` < ``run`` < ``cli``.

An import inside a function hides an edge from the reader: none of a project package is
allowed there; a third-party one only with a comment on its line saying why it is lazy.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("sonar", "features", "datasets", "slam")
SLAM_LAYERS = ("io", "model", "mapping", "backends", "eval", "run", "cli")
#: Modules of ``sonarslam/`` itself that every layer may import (they import no layer).
NEUTRAL = ("settings",)


NAMESPACE = "sonarslam"


def _modules() -> list[tuple[str, Path]]:
    """``(layer-relative module name, path)``: ``slam.run.run`` for ``sonarslam.slam.run.run``."""
    out = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out.append((name, path))
    for name in NEUTRAL:
        out.append((name, ROOT / NAMESPACE / f"{name}.py"))
    return out


def _layer_name(imported: str) -> str | None:
    """The layer-relative name of a ``sonarslam.<layer>...`` import, else None."""
    head, _, rest = imported.partition(".")
    return rest if head == NAMESPACE and rest else None


def _imports(path: Path) -> list[tuple[str, int, bool]]:
    """``(imported module, line, inside a function)`` of every import of the file."""
    tree = ast.parse(path.read_text(), str(path))
    found: list[tuple[str, int, bool]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
            if isinstance(child, ast.Import):
                found.extend((a.name, child.lineno, in_function) for a in child.names)
            elif isinstance(child, ast.ImportFrom) and child.module and child.level == 0:
                found.append((child.module, child.lineno, in_function))
            visit(child, inner)

    visit(tree, False)
    return found


def _allowed(importer: str, imported: str) -> bool:
    top = imported.split(".")[0]
    own = importer.split(".")[0]
    if own in NEUTRAL:
        return False  # a neutral module imports nothing of the project
    if top in NEUTRAL:
        return True
    if top not in PACKAGES:
        return False  # sonarslam.<something that is neither a layer nor neutral>
    if own == "sonar":
        return top == "sonar"
    if own == "features":
        return top in ("sonar", "features")
    if own == "datasets":
        return top in ("sonar", "datasets") or imported == "features.geometry"
    # slam: anything below it, and its own layers downwards
    if top != "slam":
        return True
    parts, target = importer.split("."), imported.split(".")
    if len(parts) < 2 or len(target) < 2:
        return len(target) >= 2  # slam/__init__ may import nothing; nobody imports bare slam
    mine, theirs = parts[1], target[1]
    if mine not in SLAM_LAYERS or theirs not in SLAM_LAYERS:
        return False
    return SLAM_LAYERS.index(theirs) <= SLAM_LAYERS.index(mine)


MODULES = _modules()


def test_every_package_module_is_in_a_layer():
    names = [n for n, _ in MODULES]
    assert len(names) > 60
    slam_modules = [n for n in names if n.startswith("slam.")]
    assert all(n.split(".")[1] in SLAM_LAYERS for n in slam_modules), slam_modules


@pytest.mark.parametrize("name,path", MODULES, ids=[n for n, _ in MODULES])
def test_imports_flow_one_way_and_none_hides_in_a_function(name: str, path: Path):
    lines = path.read_text().splitlines()
    for imported, lineno, in_function in _imports(path):
        where = f"{path.relative_to(ROOT)}:{lineno}"
        bare = imported.split(".")[0] in PACKAGES
        assert not bare, f"{where}: {imported} is imported as sonarslam.{imported}"
        assert imported != NAMESPACE, f"{where}: a layer imports the sonarslam facade"
        layered = _layer_name(imported)
        if layered is not None:
            assert _allowed(name, layered), f"{where}: {name} must not import {imported}"
        if in_function:
            project = layered is not None
            assert not project, f"{where}: import of {imported} inside a function hides an edge"
            assert "#" in lines[lineno - 1], f"{where}: a lazy import says why on its line"


def test_the_rules_catch_a_wrong_edge():
    assert not _allowed("sonar.store", "features.geometry")
    assert not _allowed("features.extractor", "slam.run.presets")
    assert not _allowed("datasets.source", "features.extractor")
    assert not _allowed("slam.model.motion", "slam.backends.ekf")
    assert not _allowed("slam.eval.truth", "slam.run.sources")
    assert _allowed("slam.run.run", "slam.eval.ate")
    assert not _allowed("settings", "datasets.errors")
    assert not _allowed("settings", "sonar.beam")
    assert not _allowed("features.config", "cli")
    for layer in ("sonar.beam", "features.config", "datasets.config", "slam.io.files"):
        assert _allowed(layer, "settings")


def test_the_neutral_modules_import_no_layer():
    """``sonarslam.settings`` is imported by every layer; it imports none (and not the facade)."""
    for name in NEUTRAL:
        path = ROOT / NAMESPACE / f"{name}.py"
        found = [m for m, _, _ in _imports(path) if m.split(".")[0] in (NAMESPACE, *PACKAGES)]
        assert found == [], f"{path.relative_to(ROOT)} imports {found}"


def test_the_landmark_layer_imports_nothing_of_the_back_ends():
    """The landmark layer decides a vote from the back end's belief and hands back a decision
    (:mod:`sonarslam.slam.mapping.vote`): no import of ``slam.backends`` at all, not even for types."""
    assert not _allowed("slam.mapping.landmarks", "slam.backends.base")
    mapping = [(n, p) for n, p in MODULES if n.startswith("slam.mapping")]
    assert len(mapping) >= 4
    for name, path in mapping:
        found = [m for m, _, _ in _imports(path) if m.startswith("sonarslam.slam.backends")]
        assert found == [], f"{name} imports {found}"
