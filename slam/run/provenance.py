"""Where a run's figures come from: ``metrics.json``'s ``provenance`` object.

A figure can be traced back to the code, the settings and the data that made it:

* ``version``: the installed ``sonarslam`` package's version;
* ``git_commit``, ``git_dirty``: the commit of the source tree the package was imported from and
  whether tracked files differ from it (``git status --porcelain --untracked-files=no``); both
  null when the code is not in a git work tree (a wheel install) or git is not there;
* ``settings_sha256``: SHA-256 of the settings that decide the run: the back end, ``--batch``, the dataset
  configuration used (``config_used.toml``'s text) and the closed loop's resolved extractor,
  back-end and scan-matcher settings (:class:`sonarslam.slam.run.presets.RunConfig`), as canonical JSON;
* ``dataset_sha256`` and ``dataset_files``: the SHA-256 of every file the run read
  (:func:`dataset_files`: every file under the dataset's directory; for a single-file source,
  a bag or a Ping Viewer log, the file with its ``sonarslam.toml`` and ``truth.json``; and a
  ``--topics`` file or a Ping360 log's navigation, :attr:`Dataset.inputs`)
  (``dataset_files``: relative path -> digest; a folder of more than :data:`GROUP_OVER` files,
  the marina's keyframes, is one entry ``folder/*`` over its files' names and digests, with
  ``dataset_file_count``), and one digest over them all.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import subprocess
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

__all__ = [
    "GROUP_OVER",
    "dataset_digests",
    "dataset_files",
    "git_state",
    "provenance",
    "settings_digest",
]

#: A folder with more files than this gets one digest over them in ``dataset_files``.
GROUP_OVER = 20

_SOURCE_ROOT = Path(__file__).resolve().parents[2]  # the folder holding slam/


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _package_version() -> str | None:
    try:
        return version("sonarslam")
    except PackageNotFoundError:
        return None


def git_state(root: Path = _SOURCE_ROOT) -> tuple[str | None, bool | None]:
    """``(commit, dirty)`` of the git work tree at ``root``; ``(None, None)`` outside one."""
    if not (root / ".git").exists():  # a directory, or a file in a worktree
        return None, None

    def git(*args: str) -> str | None:
        try:
            out = subprocess.run(
                ["git", "-C", str(root), *args],
                capture_output=True,
                text=True,
                timeout=30,
                check=False,
            )
        except (OSError, subprocess.TimeoutExpired):
            return None
        return out.stdout if out.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    if commit is None:
        return None, None
    status = git("status", "--porcelain", "--untracked-files=no")
    return commit.strip(), None if status is None else bool(status.strip())


def _canonical(obj: Any) -> Any:
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {
            "__type__": type(obj).__name__,
            **{
                f.name: _canonical(getattr(obj, f.name))
                for f in dataclasses.fields(obj)
                if f.compare  # a field that is no setting (RunConfig.dataset) is left out
            },
        }
    if isinstance(obj, dict):
        return {str(k): _canonical(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_canonical(v) for v in obj]
    if isinstance(obj, float | int | str | bool) or obj is None:
        return obj
    return repr(obj)


def settings_digest(
    backend: str, dataset_config_toml: str, run_config: Any | None, batch: bool = False
) -> str:
    """SHA-256 (hex) of the settings that decide a run (module docstring)."""
    doc = {
        "backend": backend,
        "batch": batch,
        "dataset_config": dataset_config_toml,
        "run_config": _canonical(run_config),
    }
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def dataset_files(root: Path, also: Sequence[Path] = ()) -> tuple[Path, list[Path]]:
    """``(base folder, files)`` a run on ``root`` reads: every regular file under a directory;
    a single file (a ROS 1 bag, an MCAP, a Ping Viewer ``.bin``) with the ``sonarslam.toml``
    and ``truth.json`` beside it; then the files of ``also`` (a ``--topics`` file, a Ping360
    log's navigation: files or directories), each once, in sorted order."""
    base = root if root.is_dir() else root.parent
    found: set[Path] = set()
    for p in (root, *also):
        if p.is_dir():
            found.update(q for q in p.rglob("*") if q.is_file())
        elif p.is_file():
            found.add(p)
            if p == root:
                found.update(
                    q for q in (base / "sonarslam.toml", base / "truth.json") if q.is_file()
                )
    return base, sorted(found)


def dataset_digests(root: Path, also: Sequence[Path] = ()) -> tuple[str, dict[str, str], int]:
    """``(digest over all, {relative path or folder/*: digest}, number of files)`` of the
    files a run on ``root`` reads (:func:`dataset_files`; module docstring). A file outside the
    base folder is named by its absolute path."""
    base, files = dataset_files(root, also)

    def name(p: Path) -> str:
        return p.relative_to(base).as_posix() if p.is_relative_to(base) else p.resolve().as_posix()

    digests = {name(p): _sha256_file(p) for p in files}
    by_folder: dict[str, list[str]] = {}
    for rel in digests:
        by_folder.setdefault(rel.rpartition("/")[0], []).append(rel)
    listed: dict[str, str] = {}
    for folder, members in sorted(by_folder.items()):
        if len(members) > GROUP_OVER:
            h = hashlib.sha256()
            for rel in members:
                h.update(f"{rel}\0{digests[rel]}\n".encode())
            listed[f"{folder}/*" if folder else "*"] = h.hexdigest()
        else:
            listed.update({rel: digests[rel] for rel in members})
    total = hashlib.sha256()
    for rel in digests:
        total.update(f"{rel}\0{digests[rel]}\n".encode())
    return total.hexdigest(), listed, len(files)


def provenance(
    backend: str,
    dataset_root: Path,
    dataset_config_toml: str,
    run_config: Any | None,
    batch: bool = False,
    also: Sequence[Path] = (),
) -> dict[str, Any]:
    """The ``provenance`` object of ``metrics.json`` (module docstring); ``also``: files or
    directories the run read besides ``dataset_root`` (:func:`dataset_files`)."""
    commit, dirty = git_state()
    total, listed, count = dataset_digests(dataset_root, also)
    return {
        "version": _package_version(),
        "git_commit": commit,
        "git_dirty": dirty,
        "settings_sha256": settings_digest(backend, dataset_config_toml, run_config, batch),
        "dataset_sha256": total,
        "dataset_file_count": count,
        "dataset_files": listed,
    }
