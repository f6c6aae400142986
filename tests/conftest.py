"""Shared fixtures: the real marina (skipped with a reason when absent) and small helpers."""

from __future__ import annotations

from pathlib import Path

import pytest

from datasets.source import Dataset, data_root, open_dataset


def marina_root() -> Path | None:
    root = data_root()
    if root is None or not (root / "marina").is_dir():
        return None
    return root / "marina"


needs_marina = pytest.mark.skipif(
    marina_root() is None,
    reason="real marina data not found: set SONARSLAM_DATA to a folder holding marina/ (make does "
    "this when ../shared/datasets exists)",
)


@pytest.fixture(scope="session")
def marina() -> Dataset:
    if marina_root() is None:
        pytest.skip("real marina data not found under $SONARSLAM_DATA")
    return open_dataset("marina")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark every test that needs the real marina (its fixture or ``needs_marina``) with
    ``marina``, so that ``pytest -m marina`` runs them and ``-m "not marina"`` leaves them."""
    for item in items:
        uses_fixture = "marina" in getattr(item, "fixturenames", ())
        skipif = any(
            m.name == "skipif" and "marina" in str(m.kwargs.get("reason", ""))
            for m in item.iter_markers()
        )
        if uses_fixture or skipif:
            item.add_marker(pytest.mark.marina)
