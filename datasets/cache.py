"""A versioned cache of parsed inputs: NumPy ``.npz`` files, rebuilt when the source changes.

Parsing the marina's 230 keyframe PCDs (26 MB of ASCII) takes seconds; their beams as arrays
load in milliseconds. A cache file holds the arrays and a signature: :data:`CACHE_VERSION`
(raised when the format or the parse changes), the bytes of every source file (a BLAKE2
digest, so a changed file of the same size and time is seen) and the settings the parse used.
A file whose signature differs, that cannot be read, or that is not a cache of this kind is
ignored and written anew: the cache can only cost time, never change a result.

Where: beside the data (``.sonarslam-<name>.npz`` in its folder) when that folder can be
written and has a write bit (root may write a folder laid read-only; it is not written), else in ``$SONARSLAM_CACHE`` or ``$XDG_CACHE_HOME/sonarslam`` (``~/.cache/sonarslam``),
named by the folder's path (the shared datasets are read-only). ``SONARSLAM_CACHE=off`` turns
the cache off.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.logfile import open_regular

__all__ = ["CACHE_VERSION", "ENV_VAR", "cache_file", "load_cached", "save_cached"]

#: Raised whenever what a cache holds, or how it is parsed, changes.
CACHE_VERSION = 1
ENV_VAR = "SONARSLAM_CACHE"
_CHUNK = 1 << 20


def _enabled() -> bool:
    return os.environ.get(ENV_VAR, "").strip().lower() not in ("off", "0", "no", "false")


def _writable(folder: Path) -> bool:
    """Whether the data's folder is meant to be written: its mode has a write bit and we may
    write it (root may write anything: a folder without write bits, as the shared datasets
    are laid, is read-only all the same)."""
    try:
        mode = folder.stat().st_mode
    except OSError:
        return False
    bits = stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH
    return bool(mode & bits) and os.access(folder, os.W_OK | os.X_OK)


def cache_file(folder: Path, name: str) -> Path:
    """Where the cache ``name`` of the data in ``folder`` lives (module docstring)."""
    if _writable(folder):
        return folder / f".sonarslam-{name}.npz"
    base = os.environ.get(ENV_VAR) or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "sonarslam"
    )
    tag = hashlib.blake2b(str(folder.resolve()).encode(), digest_size=8).hexdigest()
    return Path(base) / f"{name}-{tag}.npz"


def _signature(sources: Sequence[Path], key: Mapping[str, Any]) -> str:
    h = hashlib.blake2b(digest_size=20)
    h.update(f"sonarslam-cache/{CACHE_VERSION}".encode())
    for path in sources:
        h.update(path.name.encode() + b"\0")
        with open_regular(path) as fh:
            while chunk := fh.read(_CHUNK):
                h.update(chunk)
        h.update(b"\0")
    for k in sorted(key):
        v = key[k]
        h.update(k.encode() + b"=")
        if isinstance(v, np.ndarray):
            h.update(str(v.dtype).encode() + str(v.shape).encode() + np.ascontiguousarray(v).data)
        else:
            h.update(json.dumps(v, sort_keys=True).encode())
    return h.hexdigest()


def load_cached(
    folder: Path, name: str, sources: Sequence[Path], key: Mapping[str, Any]
) -> dict[str, np.ndarray] | None:
    """The arrays of the cache ``name`` when its signature is that of ``sources`` and ``key``
    now; None otherwise (no cache, another signature, a file that is not one)."""
    if not _enabled():
        return None
    path = cache_file(folder, name)
    try:
        if not path.is_file():
            return None
        signature = _signature(sources, key)
        with np.load(path, allow_pickle=False) as npz:
            if str(npz["signature"]) != signature:
                return None
            return {k: npz[k] for k in npz.files if k != "signature"}
    except Exception:  # a damaged or foreign file is no cache: it is rebuilt
        return None


def save_cached(
    folder: Path,
    name: str,
    sources: Sequence[Path],
    key: Mapping[str, Any],
    arrays: Mapping[str, np.ndarray],
) -> Path | None:
    """Write the cache ``name`` (whole or not at all: a temporary renamed); None when it
    cannot be written (a read-only place, a full disk: the next run parses again)."""
    if not _enabled():
        return None
    path = cache_file(folder, name)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:12]}.part.npz")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        signature = np.array(_signature(sources, key))
        np.savez_compressed(tmp, signature=signature, **dict(arrays))  # type: ignore[arg-type]
        os.replace(tmp, path)
        return path
    except OSError:
        return None
    finally:
        tmp.unlink(missing_ok=True)
