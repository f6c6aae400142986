"""Docstrings and comments state contracts: history and a run's measured figures live in docs/
(docs/design-decisions.md) or in benchmark outputs. ``benchmarks/docstring_audit.py`` finds the
markers; here its strong set holds at zero on the tree, and it is shown to find planted ones and
to leave contract prose alone."""

from __future__ import annotations

import importlib.util
import io
import sys
import tokenize
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _audit_module() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "docstring_audit", ROOT / "benchmarks" / "docstring_audit.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("docstring_audit", module)  # dataclasses look the module up
    spec.loader.exec_module(module)
    return module


audit = _audit_module()


def test_the_layers_docstrings_and_comments_carry_no_history_markers():
    paths = audit.modules()
    assert len(paths) > 100  # the four layers were found, not an empty walk
    hits = audit.audit(audit.STRONG)
    listing = "\n".join(f"{h.path}:{h.line}: [{h.marker}] {h.text}" for h in hits)
    assert hits == [], "move these to docs/design-decisions.md or a benchmark's output:\n" + listing


PLANTED = '''"""A module. Off by default for now (issue 29)."""

X = 1  # the marina's MTi: -0.66 deg/s


class C:
    """It was the closed loops' preset until the line-quality benchmark found its lines inside
    the echo band; with "white" the variance is ~20x too small."""

    def f(self):
        """Before the refusal, iSAM2 spun away: ATE 97 m (commit 1a2b3c4d, 2026-12-01)."""
'''


def test_the_detector_finds_planted_markers_in_docstrings_and_comments():
    hits = audit.find(PLANTED, audit.STRONG)
    found = {(h.line, h.kind, h.marker) for h in hits}
    assert {
        (1, "docstring", "issue"),
        (1, "docstring", "for now"),
        (3, "comment", "dataset figure"),
        (7, "docstring", "was the default"),
        (7, "docstring", "until found"),
        (7, "docstring", "benchmark found"),
        (7, "docstring", "x too"),
        (11, "docstring", "before a change"),
        (11, "docstring", "ate figure"),
        (11, "docstring", "commit"),
        (11, "docstring", "date"),
    } <= found, found


@pytest.mark.parametrize(
    "text",
    [
        "the error is measured minus predicted",
        "the beam was received before the previous one",
        "the newest node as it was when it was the newest",
        "its last sample at or before the fix",
        "the deviation found so far",
        "A line seen but not yet a landmark.",
        "bin 500 of the marina's 0.1 m bins is at 50.0 m",
        "chosen on the drawn tuning worlds; see docs/design-decisions.md",
        "an extent no longer than the longer of the two",
        "the layout read at ping-viewer commit 1ed4508",
        "a start such as ``2024-05-02T10:31:07``",
    ],
)
def test_contract_prose_is_not_a_marker(text: str):
    assert audit.find(f'"""{text}"""\n', audit.STRONG) == []
    assert audit.find(f"x = 1  # {text}\n", audit.STRONG) == []


def test_code_is_not_read_as_prose():
    """Strings that are not docstrings (messages, data) and code are not passages."""
    source = 'def f():\n    return "issue 29: ATE 97 m"\n\n\nY = "it was the default"\n'
    assert audit.passages(source) == []


def test_the_fast_comment_scan_finds_what_tokenize_finds():
    """The audit reads comments with one regular expression; on a module with comments in and
    beside strings it finds exactly the comments :mod:`tokenize` finds."""
    source = (
        'S = "a # not a comment"  # one\n'
        "T = '''\n# not a comment either\n'''  # two\n"
        'U = f"{1}#"  #: three\n'
        "# four\n"
    )
    tokens = tokenize.generate_tokens(io.StringIO(source).readline)
    expected = [
        (t.start[0], t.string.lstrip("#:").strip()) for t in tokens if t.type == tokenize.COMMENT
    ]
    assert audit.comments(source) == expected == [(1, "one"), (4, "two"), (5, "three"), (6, "four")]


def test_the_public_api_has_well_formed_numpydoc():
    """Every name of ``sonarslam.__all__`` (read from the source): section headers underlined to
    their length, each parameter documented, each dataclass field in Attributes."""
    assert audit.public_api_problems() == []


def test_the_numpydoc_check_finds_planted_faults(tmp_path: Path):
    (tmp_path / "sonarslam").mkdir()
    (tmp_path / "sonarslam" / "__init__.py").write_text(
        '_HOMES: dict[str, str] = {"f": "sonarslam.m", "C": "sonarslam.m"}\n'
    )
    (tmp_path / "m.py").write_text(
        "from dataclasses import dataclass\n\n\n"
        "def f(a, b, *, c=1):\n"
        '    """Do.\n\n    Parameters\n    ---------\n    a : float\n    z : int\n    """\n\n\n'
        "@dataclass\n"
        "class C:\n"
        '    """Data.\n\n    Attributes\n    ----------\n    x : float\n    """\n\n'
        "    x: float\n"
        "    y: float\n\n"
        "    def g(self, q):\n"
        '        """Nothing about it."""\n'
    )
    assert sorted(audit.public_api_problems(tmp_path)) == [
        "C.g: ['q'] not described (no Parameters section)",
        "C: fields not in Attributes ['y']",
        "f: Parameters lacks ['b', 'c']",
        "f: Parameters names ['z'], not in the signature",
        "f: the underline of 'Parameters' is 9 long, not 10",
    ]
