"""The notebooks run top to bottom (nbclient), are stored without outputs, and print the numbers
of the library they demonstrate."""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import nbformat
import pytest
from jupyter_core.utils import run_sync
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).resolve().parent.parent / "notebooks"
TIMEOUT_S = 300


@pytest.fixture(scope="module")
def kernel() -> Iterator[dict[str, Any]]:
    """One kernel for the module's notebooks (``{"km": its manager}`` once the first started
    it): a kernel's start and its first imports of the library cost ~5 s of CPU each. Each
    notebook still runs in an empty namespace (``%reset -f``) with its own environment and
    working directory, set by :func:`execute`."""
    holder: dict[str, Any] = {"env": dict(os.environ)}
    yield holder
    if holder.get("km") is not None:
        run_sync(holder["km"].shutdown_kernel)(now=True)


def execute(
    name: str, tmp_path: Path, kernel: dict[str, Any], env: dict[str, str] | None = None
) -> str:
    """Run a notebook in ``tmp_path`` (its files go to ``tmp_path/out``) on the module's
    ``kernel``; all its text output. A first cell, added here, empties the kernel's namespace
    (a name the notebook uses without defining it fails as in a fresh kernel; imported modules
    stay loaded) and sets the environment (the test process's, with ``env``) and folder."""
    book = nbformat.read(NOTEBOOKS / name, as_version=4)
    nb_env = {**kernel["env"], "SONARSLAM_NB_OUT": str(tmp_path / "out"), "MPLBACKEND": "Agg"}
    nb_env.update(env or {})
    setup = (
        "get_ipython().run_line_magic('reset', '-f')\n"
        "import os as _os\n"
        f"_os.environ.clear()\n_os.environ.update({nb_env!r})\n_os.chdir({str(tmp_path)!r})\n"
        "del _os\n"
    )
    book.cells.insert(0, nbformat.v4.new_code_cell(setup))
    client = NotebookClient(
        book,
        km=kernel.get("km"),
        timeout=TIMEOUT_S,
        kernel_name="python3",
        resources={"metadata": {"path": str(tmp_path)}},
    )
    try:
        client.execute(cleanup_kc=False)  # the kernel stays up for the next notebook
    finally:
        kernel["km"] = client.km
        if client.kc is not None:
            client.kc.stop_channels()
    text = []
    for cell in book.cells:
        for out in cell.get("outputs", []):
            if out.get("output_type") == "stream":
                text.append(out["text"])
            elif out.get("output_type") == "error":
                text.append(f"{out['ename']}: {out['evalue']}")
    return "".join(text)


@pytest.mark.parametrize("path", sorted(NOTEBOOKS.glob("*.ipynb")), ids=lambda p: p.stem)
def test_notebooks_are_stored_without_outputs(path):
    book = nbformat.read(path, as_version=4)
    for cell in book.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None


def test_line_extraction_notebook_finds_the_pool_walls(tmp_path, kernel):
    # the marina cells on its first 100 s (the notebook's own default is 300 s)
    text = execute("01_line_extraction.ipynb", tmp_path, kernel, {"SONARSLAM_NB_MARINA_S": "100"})
    m = re.search(r"(\d+) lines from (\d+) beams; (\d+) on a true wall", text)
    assert m, text
    n_lines, n_beams, n_ok = map(int, m.groups())
    assert n_beams == 2425  # 165 s at 14.7 Hz: four 270 deg sectors and 25 beams
    assert n_ok >= 16 and n_ok >= 0.8 * n_lines  # four votes, four walls each
    nees = float(re.search(r"NEES mean ([0-9.]+)", text).group(1))
    assert 0.5 < nees < 8.0
    assert "marina found" in text or "skipped: no marina" in text
    assert (tmp_path / "out" / "pool_lines.png").stat().st_size > 10_000


def test_ekf_vs_isam2_notebook_scores_every_backend(tmp_path, kernel):
    text = execute("02_ekf_vs_isam2.ipynb", tmp_path, kernel, {"SONARSLAM_NB_WINDOW_S": "120"})
    assert "Error" not in text, text
    rows = re.findall(
        r"^(\w+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+\d+$", text, re.M
    )
    names = [r[0] for r in rows]
    assert "dr" in names and "ekf" in names, text
    for _, ate_mean, _sd, ate_max, _ape, _rpe in rows:
        assert 0.0 < float(ate_mean) <= float(ate_max) < 50.0
    for name in names:
        assert (tmp_path / "out" / f"errors_{name}.png").is_file()


def test_consistency_notebook_gives_the_anees_of_each_backend(tmp_path, kernel):
    text = execute(
        "03_consistency_monte_carlo.ipynb",
        tmp_path,
        kernel,
        # the runs in the kernel, one after another: the local Dask cluster, the notebook's
        # default, is tested by tests/test_sweep.py (its start costs seconds of imports)
        {
            "SONARSLAM_NB_SEEDS": "2",
            "SONARSLAM_NB_DURATION_S": "60",
            "SONARSLAM_NB_SCHEDULER": "synchronous",
        },
    )
    assert "Error" not in text, text
    assert re.search(r"\d+ runs in [0-9.]+ s", text)
    # two runs per configuration: the band of the mean of 2 chi2(3) is (0.619, 7.224)
    assert re.search(r"^\s*ekf\s+2\s+[0-9.]+\s+[0-9.]+\s+0\.619\s+7\.22", text, re.M), text
    assert (tmp_path / "out" / "sweep" / "sweep.csv").is_file()
