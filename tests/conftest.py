"""Shared fixtures: the real marina (skipped with a reason when absent), simulated runs shared
by every test of a session (and by its xdist workers), and small helpers."""

from __future__ import annotations

import fcntl
import gc
import os
import pickle
import shutil
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

# bytecode caches written, whatever PYTHONDONTWRITEBYTECODE says: the suite starts ~40 Python
# processes (2 xdist workers, CLI subprocesses, notebook kernels, Dask workers, evo) and uv
# installs .venv without .pyc files, so each of them compiled the library, numpy, pandas,
# matplotlib, distributed, ... from source again (importing the sweep: 8.5 s of CPU against 3.0 s
# with the caches), and pytest rewrote every test module's assertions in each worker. Set here,
# in the controller, before it starts the workers: they and every subprocess inherit it.
sys.dont_write_bytecode = False
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    # one BLAS thread per worker: the suite runs on 2 workers on 2 cores, where BLAS threads
    # only contend (effective when numpy is not imported yet; the Makefile sets them too)
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

# numba's kernels are compiled at their modules' import (cache=True: into __pycache__, the first
# time in a clone). Imported here, in the process that loads this file first (xdist's controller,
# before it starts the workers), they are compiled once and every worker, CLI subprocess,
# notebook kernel and Dask worker loads them from the cache; imported by each worker at
# collection instead, a fresh clone compiled them in both workers at once (~10 s CPU each).
import sonarslam.features.hough  # noqa: E402, F401
import sonarslam.sonar.segmentation  # noqa: E402, F401
from sonarslam.datasets.simulator import simulate  # noqa: E402
from sonarslam.datasets.simulator.ping360 import ping360_head  # noqa: E402
from sonarslam.datasets.simulator.scenario import make_scenario, simulate_records  # noqa: E402
from sonarslam.datasets.simulator.writer import write_dataset  # noqa: E402
from sonarslam.datasets.source import Dataset, data_root, open_dataset  # noqa: E402

# no wall-clock limit on a property's examples: speed is measured by benchmarks/, and on the
# shared 2-core machine one example of a Jacobian check took 601 ms against hypothesis's
# default 200 ms deadline (a FlakyFailure of test_geometry under load, on main as well)
settings.register_profile("sonarslam", deadline=None)
settings.load_profile("sonarslam")


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
def marina(shared_dir: Callable[[str, Callable[[Path], None]], Path]) -> Dataset:
    """``open_dataset("marina")``, read once per session (pickled by the first xdist worker
    that asks, loaded by the others)."""
    if marina_root() is None:
        pytest.skip("real marina data not found under $SONARSLAM_DATA")

    def build(folder: Path) -> None:
        (folder / "dataset.pickle").write_bytes(pickle.dumps(open_dataset("marina")))

    loaded: Dataset = pickle.loads(
        (shared_dir("opened_marina", build) / "dataset.pickle").read_bytes()
    )
    return loaded


#: The modules of the longest tests (10-35 s each), run first: a long test that starts last
#: decides when the suite ends while the other worker waits (longest first balances the two).
#: Whole modules move, so that their module fixtures are still made once.
LONG_MODULES = (
    "test_docs_examples.py",
    "test_typing.py",
    "test_sweep.py",
    "test_own_data.py",
    "test_notebooks.py",
    "test_namespace.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The modules of :data:`LONG_MODULES` first (the others in their order). Mark every test
    that needs the real marina (its fixture or ``needs_marina``) with ``marina``, so that
    ``pytest -m marina`` runs them and ``-m "not marina"`` leaves them."""

    def rank(item: pytest.Item) -> int:
        name = item.path.name
        return LONG_MODULES.index(name) if name in LONG_MODULES else len(LONG_MODULES)

    items.sort(key=rank)  # stable: each module's own order kept
    for item in items:
        uses_fixture = "marina" in getattr(item, "fixturenames", ())
        skipif = any(
            m.name == "skipif" and "marina" in str(m.kwargs.get("reason", ""))
            for m in item.iter_markers()
        )
        if uses_fixture or skipif:
            item.add_marker(pytest.mark.marina)


def pytest_collection_finish(session: pytest.Session) -> None:
    """After collection (in each xdist worker), the objects alive now (the modules of the
    library, numpy, gtsam, matplotlib, pandas, ... and the collected tests) are moved out of
    the garbage collector's reach: they live to the end, and each full collection walked all of
    them again (gc.freeze halved the collector's CPU time on the run-heavy modules)."""
    gc.collect()
    gc.freeze()


@contextmanager
def _locked(path: Path) -> Iterator[None]:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def shared_dir(
    tmp_path_factory: pytest.TempPathFactory,
) -> Callable[[str, Callable[[Path], None]], Path]:
    """``shared_dir(name, build)``: a folder built once per test session, whichever xdist worker
    asks first (the others wait for it under a file lock), then read by all of them. ``build``
    fills the folder it is given; a build that fails leaves nothing behind. Tests must not write
    into the folder: copy it first."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's folder, shared by the workers
    root = root / "shared"

    def get(name: str, build: Callable[[Path], None]) -> Path:
        folder = root / name
        with _locked(root / f"{name}.lock"):
            if not (folder / ".complete").is_file():
                shutil.rmtree(folder, ignore_errors=True)
                folder.mkdir(parents=True)
                try:
                    build(folder)
                except BaseException:
                    shutil.rmtree(folder, ignore_errors=True)
                    raise
                (folder / ".complete").touch()
        return folder

    return get


@pytest.fixture(scope="session")
def simulated(shared_dir: Callable[[str, Callable[[Path], None]], Path]) -> Callable[..., Path]:
    """``simulated(kind, seed, duration_s, name=None)``: the directory ``sonarslam simulate``
    writes for these arguments (named ``name``, default ``<kind>_<seed>``: the dataset's name in
    reports), simulated once per session and shared by the tests that ask for the same run.
    Read only: a test that changes its files copies it first."""

    def get(kind: str, seed: int, duration_s: float, name: str | None = None) -> Path:
        leaf = name or f"{kind}_{seed}"
        key = f"sim_{kind}_{seed}_{duration_s:g}s_{leaf}"
        folder = shared_dir(key, lambda f: simulate(kind, seed, f / leaf, duration_s=duration_s))
        return folder / leaf

    return get


@pytest.fixture(scope="session")
def opened(
    simulated: Callable[..., Path], shared_dir: Callable[[str, Callable[[Path], None]], Path]
) -> Callable[..., Dataset]:
    """``opened(kind, seed, duration_s)``: ``open_dataset`` of ``simulated(kind, seed,
    duration_s)``, read once per session (the first worker to ask pickles it; loading the pickle
    is cheaper than reading the text logs again: benchmarks/log_reading.py) and returned as a
    fresh copy at each call, so a test may change it. For tests that need the run as input;
    a test of ``open_dataset`` itself calls it."""

    def get(kind: str, seed: int, duration_s: float) -> Dataset:
        source = simulated(kind, seed, duration_s)

        def build(folder: Path) -> None:
            (folder / "dataset.pickle").write_bytes(pickle.dumps(open_dataset(source)))

        folder = shared_dir(f"opened_{kind}_{seed}_{duration_s:g}s", build)
        loaded: Dataset = pickle.loads((folder / "dataset.pickle").read_bytes())
        return loaded

    return get


@pytest.fixture(scope="session")
def ping360_layout(shared_dir: Callable[[str, Callable[[Path], None]], Path]) -> Path:
    """A 150 s harbour (seed 3) with a Ping360-shaped head, in the marina layout (its DVL drops
    out: the rows without lock carry (0, 0), as the simulator writes them): the dive the
    Ping Viewer and navigation-log tests write in each field format. Built once per session;
    read only."""

    def build(folder: Path) -> None:
        scenario = make_scenario("harbour", 3, 150.0)
        scenario = replace(scenario, head=ping360_head(scenario.head))
        write_dataset(simulate_records(scenario), folder / "layout")

    return shared_dir("ping360_harbour_3_150s", build) / "layout"
