"""One import namespace: the wheel installs exactly one top-level package, ``sonarslam``, so it
sits beside packages whose names its layers share (Hugging Face ``datasets`` above all: both
used to ship ``datasets/config.py``), and no module of the project imports a layer by its bare
folder name."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("sonar", "features", "datasets", "slam")
#: the Hugging Face release installed beside ours (pinned: the test must not move by itself)
HF_DATASETS = "datasets==5.2.0"


def _build_wheel(out: Path) -> Path:
    """The wheel, built from a copy of the sources: an in-tree build would leave ``build/`` in
    the clone, whose stale copies of moved modules the next wheel would carry."""
    src = out.parent / "src"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    for folder in ("sonarslam", *LAYERS):
        shutil.copytree(ROOT / folder, src / folder, symlinks=True, ignore=ignore)
    # uv where the dev venv has it: the same isolated PEP 517 build as pip's, with the build
    # backend from uv's cache (pip wheel: ~4 s of CPU, mostly installing setuptools again)
    uv = Path(sys.executable).parent / "uv"
    if uv.is_file():
        build = [str(uv), "build", "--wheel", "-q", "-o", str(out), str(src)]
    else:
        build = [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(src)]
    subprocess.run(build, check=True, capture_output=True, text=True)
    (wheel,) = out.glob("sonarslam-*.whl")
    return wheel


def _fresh_env(where: Path, *requirements: str) -> Path:
    """A new virtual environment with ``requirements`` installed under requirements.lock's pins;
    uv where the dev venv has it (as the Makefile installs it), else venv and pip."""
    uv = Path(sys.executable).parent / "uv"
    python = where / "bin" / "python"
    if uv.is_file():
        subprocess.run([str(uv), "venv", "-q", "-p", sys.executable, str(where)], check=True)
        install = [str(uv), "pip", "install", "-q", "--python", str(python)]
    else:
        subprocess.run([sys.executable, "-m", "venv", str(where)], check=True)
        install = [str(python), "-m", "pip", "install", "-q", "--disable-pip-version-check"]
    lock = ["-c", str(ROOT / "requirements.lock")]
    subprocess.run([*install, *lock, *requirements], check=True, capture_output=True, text=True)
    return python


@pytest.mark.slow
def test_the_wheel_installs_one_package_beside_hugging_face_datasets(tmp_path: Path) -> None:
    wheel = _build_wheel(tmp_path / "dist")
    with zipfile.ZipFile(wheel) as archive:
        tops = {name.split("/")[0] for name in archive.namelist()}
    assert tops == {
        "sonarslam",
        wheel.name.split("-")[0] + "-" + wheel.name.split("-")[1] + ".dist-info",
    }
    python = _fresh_env(tmp_path / "venv", str(wheel), HF_DATASETS)
    probe = (
        "import datasets, sonarslam, sonarslam.datasets.marina as marina, sonarslam.sonar.beam\n"
        "print(datasets.__version__)\n"
        "print(hasattr(datasets, 'load_dataset'), marina.__name__)\n"
    )
    out = subprocess.run(  # away from the source tree, whose folders would shadow both
        [str(python), "-c", probe], cwd=tmp_path, check=True, capture_output=True, text=True
    )
    version, second = out.stdout.split("\n")[:2]
    assert version == HF_DATASETS.split("==")[1]
    assert second == "True sonarslam.datasets.marina"


def _project_files() -> list[Path]:
    folders = [*LAYERS, "sonarslam", "tests", "benchmarks"]
    files = [p for f in folders if (ROOT / f).is_dir() and not (ROOT / f).is_symlink()
             for p in sorted((ROOT / f).rglob("*.py"))]  # fmt: skip
    return files


def test_no_module_imports_a_layer_by_its_bare_name() -> None:
    """``import slam`` would load a second copy of a layer from a source tree and nothing from
    an installed wheel: every import of the project goes through ``sonarslam.``."""
    files = _project_files()
    assert len(files) > 150
    bare = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            bare += [f"{path}:{node.lineno}: {n}" for n in names if n.split(".")[0] in LAYERS]
    assert bare == [], "import these as sonarslam.<layer>: " + "; ".join(bare)
