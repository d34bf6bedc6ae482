"""The cache of compiled libraries, bounded: its files listed, its size capped with the least
recently used libraries removed first, and cleared on request (``cmm-dae cache``).

Every library :func:`~.codegen.build_library` builds is a ``cmm_<key>.so`` beside its stamp
``cmm_<key>.so.ok`` in :func:`cache_dir`. A library used by a run is touched (its
modification time set to now) once per process, so the time orders the libraries by their
last use; after each build the cache is trimmed to :func:`limit` bytes, the oldest first,
never the library just built. A library another process is about to load and finds gone
is built again (its check fails first: it is never loaded half-deleted).
"""

from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["DEFAULT_LIMIT_MB", "Entry", "cache_dir", "clear", "entries", "limit", "touch",
           "trim"]

#: The cache's size cap unless ``$CMM_DAE_CACHE_MB`` sets another, MB.
DEFAULT_LIMIT_MB = 500.0

_touched: set[Path] = set()


def cache_dir() -> Path:
    """Where compiled libraries are kept: ``$CMM_DAE_CACHE`` (default, also when it is set
    but empty, ``~/.cache/cmm_dae``)."""
    return Path(os.environ.get("CMM_DAE_CACHE") or Path.home() / ".cache" / "cmm_dae")


def limit() -> float:
    """The cache's size cap, bytes: ``$CMM_DAE_CACHE_MB`` (a number of MB) or
    :data:`DEFAULT_LIMIT_MB`; a value that is not a positive number is ignored."""
    try:
        mb = float(os.environ.get("CMM_DAE_CACHE_MB", ""))
    except ValueError:
        mb = DEFAULT_LIMIT_MB
    return (mb if mb > 0 else DEFAULT_LIMIT_MB) * 2**20


@dataclass(frozen=True)
class Entry:
    """One cached library: its path, size (bytes, the stamp included) and last use (s
    since the epoch)."""

    path: Path
    size: int
    used: float


def entries(directory: Path | None = None) -> list[Entry]:
    """The cached libraries, least recently used first."""
    out = []
    for lib in (directory or cache_dir()).glob("cmm_*.so"):
        try:
            st = lib.stat()
            stamp = lib.with_name(lib.name + ".ok")
            size = st.st_size + (stamp.stat().st_size if stamp.exists() else 0)
            out.append(Entry(lib, size, st.st_mtime))
        except OSError:  # removed meanwhile by another process
            continue
    return sorted(out, key=lambda e: e.used)


def touch(lib: Path) -> None:
    """Mark ``lib`` as used now (once per process)."""
    if lib in _touched:
        return
    _touched.add(lib)
    with contextlib.suppress(OSError):
        os.utime(lib)


def _remove(lib: Path) -> None:
    for f in (lib.with_name(lib.name + ".ok"), lib):  # the stamp first: never a lone stamp
        f.unlink(missing_ok=True)


def trim(keep: Path | None = None, cap: float | None = None) -> list[Path]:
    """Remove the least recently used libraries until the cache holds at most ``cap``
    bytes (:func:`limit`), never ``keep``; the libraries removed."""
    cap = limit() if cap is None else cap
    items = entries()
    total = sum(e.size for e in items)
    removed = []
    for e in items:
        if total <= cap:
            break
        if keep is not None and e.path == keep:
            continue
        _remove(e.path)
        _touched.discard(e.path)
        total -= e.size
        removed.append(e.path)
    return removed


def clear(directory: Path | None = None) -> tuple[int, int]:
    """Remove every cached library, its stamp and any leftover of a build that was cut
    short (``.c``, ``.tmp`` files older than an hour); (libraries removed, bytes freed)."""
    directory = directory or cache_dir()
    n = freed = 0
    for e in entries(directory):
        _remove(e.path)
        _touched.discard(e.path)
        n, freed = n + 1, freed + e.size
    old = time.time() - 3600.0
    for pattern in ("cmm_*.c", "cmm_*.tmp", "cmm_*.so.ok"):
        for f in directory.glob(pattern):
            try:
                if pattern == "cmm_*.so.ok" or f.stat().st_mtime < old:
                    freed += f.stat().st_size
                    f.unlink()
            except OSError:
                continue
    return n, freed
