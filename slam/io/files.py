"""Output files written whole or not at all, strict JSON, and output paths checked before work.

* :func:`atomic_path`: every writer of a run's outputs writes to a temporary name beside the
  file (same directory, same suffix, so that matplotlib, numpy and evo pick the right format)
  and the name is moved onto the file only when the writer finished: an interrupted or failed
  run leaves either the old file or the new one, never half of one.
* :func:`write_text`, :func:`write_json`: the same for text, and JSON that is strict (NaN and
  infinities become ``null``, so ``metrics.json`` is always readable by any JSON parser).
* :func:`check_output_dir`, :func:`check_output_file`: an ``--out`` that can be created and
  written, checked without creating anything, so that a command fails before its work and
  leaves nothing behind (its directory is created only when the outputs are written).
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.settings import SettingError

__all__ = [
    "atomic_path",
    "write_atomic",
    "write_files_into",
    "write_text",
    "write_json",
    "json_safe",
    "check_output_dir",
    "check_output_file",
    "make_output_dir",
    "remove_stale_temporaries",
]


#: A temporary of :func:`atomic_path` or :func:`write_files_into`: ``.<name>.<pid>-<random>.part
#: <suffix>`` or ``.part-<pid>-<random>``, with the writing process's id.
_TEMPORARY = re.compile(
    r"\..+\.(?P<pid>[0-9]+)-[0-9a-f]{12}\.part(\.[^.]*)?|\.part-(?P<dpid>[0-9]+)-[0-9a-f]{12}"
)


def _token() -> str:
    return f"{os.getpid()}-{uuid.uuid4().hex[:12]}"


def _alive(pid: int) -> bool:
    """Whether a process of that id runs (on this machine)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def remove_stale_temporaries(folder: str | Path) -> list[Path]:
    """Remove the temporaries in ``folder`` that a killed writer left (its process is gone: a
    SIGKILL or a power cut runs no clean-up); those of a running writer stay. Returns them."""
    removed: list[Path] = []
    p = Path(folder)
    if not p.is_dir():
        return removed
    for f in p.iterdir():
        m = _TEMPORARY.fullmatch(f.name)
        if m is None or _alive(int(m.group("pid") or m.group("dpid"))):
            continue
        if f.is_dir() and not f.is_symlink():
            shutil.rmtree(f, ignore_errors=True)
        else:
            f.unlink(missing_ok=True)
        removed.append(f)
    return removed


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path to write ``path``'s content to; moved onto ``path`` (``os.replace``,
    atomic on one file system) when the block ends, removed when it raises.

    The temporary name is ``.<name>.<pid>-<random>.part<suffix>`` in the same directory (the
    process id tells a later run that its writer is gone: :func:`remove_stale_temporaries`).
    An error of the file system while writing (disk full) names ``path``.
    """
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{_token()}.part{target.suffix}")
    try:
        try:
            yield tmp
            if tmp.exists():  # a writer may decide to write nothing
                os.replace(tmp, target)
        except OSError as exc:
            if exc.filename is None or Path(exc.filename) == tmp:
                raise OSError(exc.errno, exc.strerror or str(exc), str(target)) from exc
            raise
    finally:
        tmp.unlink(missing_ok=True)


def write_atomic(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp)`` and move ``tmp`` onto ``path`` (:func:`atomic_path`); returns
    ``path``. For writers that take a file name (matplotlib, numpy, evo)."""
    with atomic_path(path) as tmp:
        write(tmp)
    return Path(path)


def write_files_into(out: str | Path, write: Callable[[Path], object]) -> list[Path]:
    """Call ``write(folder)`` on a temporary folder inside ``out``, then move each file it
    wrote into ``out`` (atomically, one by one); for writers that choose their own file names
    (a back end's ``save``). Returns the files moved."""
    target = Path(out)
    tmp = target / f".part-{_token()}"
    tmp.mkdir()
    try:
        write(tmp)
        moved = []
        for f in sorted(tmp.iterdir()):
            os.replace(f, target / f.name)
            moved.append(target / f.name)
        return moved
    except OSError as exc:  # a full disk: name where, not only what
        if exc.filename is None:
            raise OSError(exc.errno, exc.strerror or str(exc), str(target)) from exc
        raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns ``path``."""
    target = Path(path)
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return target


def json_safe(value: Any) -> Any:
    """``value`` with NaN and infinities as None, numpy numbers and arrays as plain ones."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    return value


def write_json(path: str | Path, value: Any, indent: int | None = 2) -> Path:
    """Write ``value`` as strict JSON (:func:`json_safe`: null where a number is undefined)
    atomically; returns ``path``."""
    text = json.dumps(json_safe(value), indent=indent, allow_nan=False)
    return write_text(path, text + "\n")


def _first_existing(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_output_dir(path: str | Path, option: str = "--out") -> Path:
    """``path`` if it is a directory that exists or can be created, and can be written;
    :class:`sonarslam.settings.SettingError` naming ``option`` otherwise. Creates nothing."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise SettingError(option, f"{p} exists and is not a directory")
    base = _first_existing(p)
    if not base.is_dir():
        raise SettingError(option, f"{p} cannot be created: {base} is not a directory")
    if not os.access(base, os.W_OK | os.X_OK):
        raise SettingError(option, f"{p} cannot be written: no permission in {base}")
    return p


def check_output_file(path: str | Path, suffix: str, option: str = "--out") -> Path:
    """``path`` if it names a ``suffix`` file whose directory exists or can be created, and can
    be written; :class:`sonarslam.settings.SettingError` naming ``option`` otherwise."""
    p = Path(path)
    if p.suffix.lower() != suffix:
        raise SettingError(option, f"must name a {suffix} file, got {str(path)!r}")
    if p.is_dir():
        raise SettingError(option, f"{p} is a directory, not a {suffix} file")
    if p.exists() and not os.access(p, os.W_OK):
        raise SettingError(option, f"{p} cannot be written: no permission")
    check_output_dir(p.parent, option)
    return p


def make_output_dir(path: str | Path, option: str = "--out") -> Path:
    """Create the output directory (checked first, :func:`check_output_dir`) and remove what
    killed writers left in it (:func:`remove_stale_temporaries`); returns it."""
    p = check_output_dir(path, option)
    p.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(p)
    return p
