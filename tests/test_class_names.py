"""Two classes of the project never share a name: a reader (or ``import sonarslam``) must not
have to ask which ``Trajectory`` a signature means."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("sonar", "features", "datasets", "slam")


def _classes() -> dict[str, set[str]]:
    """Every class defined anywhere in the layers and the neutral modules, by name."""
    paths = [p for layer in LAYERS for p in (ROOT / layer).rglob("*.py")]
    paths += [p for p in (ROOT / "sonarslam").glob("*.py") if not p.is_symlink()]
    found: dict[str, set[str]] = defaultdict(set)
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.ClassDef):
                found[node.name].add(path.relative_to(ROOT).as_posix())
    return found


def test_no_two_classes_share_a_name():
    classes = _classes()
    assert len(classes) > 100
    shared = {name: where for name, where in classes.items() if len(where) > 1}
    assert shared == {}, f"classes sharing a name: {shared}"
