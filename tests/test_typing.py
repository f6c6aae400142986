"""The type check (mypy, configured in pyproject.toml's [tool.mypy]) as a test: ``make test``
runs it inside the suite, where it shares the two cores with the other tests, instead of alone
before them (``make lint`` still runs it on its own)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_mypy_finds_no_type_errors() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("Success: no issues found"), done.stdout
