"""Values computed once per owner (a model) and key, kept on the owner: what depends on the
model and the given inputs alone (a start's assembly, the structure analysis, a
configuration's event functions) is not computed again by the next run of the same model
(a sweep or a study runs one model many times)."""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Any

__all__ = ["once", "recent"]


def once(owner: Any, key: Hashable, compute: Callable[[], Any]) -> Any:
    """``compute()`` the first time ``owner`` is asked for ``key``; the same value after."""
    cache = owner.__dict__.setdefault("_once", {})
    if key not in cache:
        cache[key] = compute()
    return cache[key]


def recent(owner: Any, kind: str, key: Hashable, compute: Callable[[], Any],
           keep: int = 4) -> Any:
    """``compute()`` unless ``key`` is one of the last ``keep`` keys of ``kind`` that
    ``owner`` was asked for: for values keyed by a state (a run's start), which a sweep
    over starts would otherwise pile up without bound."""
    cache = owner.__dict__.setdefault("_recent", {}).setdefault(kind, {})
    if key in cache:
        cache[key] = cache.pop(key)  # (the most recent last)
        return cache[key]
    value = cache[key] = compute()
    while len(cache) > keep:
        del cache[next(iter(cache))]
    return value
