"""Typed access to the tables of a parsed model file, recording each problem with its table
and key instead of raising (the loader reports them all at once)."""

from __future__ import annotations

import difflib
import math
import reprlib
from typing import Any

from ..core.errors import Problem

__all__ = ["Reader", "short"]

_REQUIRED = object()


def short(v: Any) -> str:
    """repr of a value, cut short (a huge or deeply nested value must not flood a message)."""
    return reprlib.repr(v)


class Reader:
    """Typed access to a TOML table that records problems instead of raising."""

    def __init__(self) -> None:
        self.problems: list[Problem] = []

    def bad(self, table: str, key: str, msg: str) -> None:
        self.problems.append(Problem(table, key, msg))

    def keys(self, table: str, d: Any, allowed: tuple[str, ...]) -> dict:
        if not isinstance(d, dict):
            self.bad(table, "", f"expected a table, got {type(d).__name__} {short(d)}")
            return {}
        for k in d:
            if k not in allowed:
                close = difflib.get_close_matches(k, allowed, n=1)
                hint = f"; did you mean '{close[0]}'?" if close else \
                    f" (allowed: {', '.join(allowed)})"
                self.bad(table, k, f"unknown key{hint}")
        return d

    def num(self, table: str, d: dict, key: str, default: Any = _REQUIRED) -> float:
        if key not in d:
            if default is _REQUIRED:
                self.bad(table, key, "missing (expected a number)")
                return math.nan
            return default
        return self._num(table, key, d[key])

    def _num(self, table: str, key: str, v: Any) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float):
            self.bad(table, key, f"expected a number, got {type(v).__name__} {short(v)}")
            return math.nan
        if not math.isfinite(v):
            self.bad(table, key, f"expected a finite number, got {v}")
            return math.nan
        return float(v)

    def vec(self, table: str, d: dict, key: str, n: int | None, default: Any = _REQUIRED
            ) -> tuple[float, ...]:
        if key not in d:
            if default is _REQUIRED:
                self.bad(table, key, f"missing (expected a list of {n or 'some'} numbers)")
                return tuple([math.nan] * (n or 0))
            return default
        v = d[key]
        if not isinstance(v, list) or (n is not None and len(v) != n):
            self.bad(table, key, f"expected a list of {n or 'some'} numbers, got {short(v)}")
            return tuple([math.nan] * (n or 0))
        out = []
        for i, x in enumerate(v):
            out.append(self._num(table, f"{key}[{i}]", x))
        return tuple(out)

    def string(self, table: str, d: dict, key: str, default: Any = _REQUIRED) -> str:
        if key not in d:
            if default is _REQUIRED:
                self.bad(table, key, "missing (expected a string)")
                return ""
            return default
        v = d[key]
        if not isinstance(v, str):
            self.bad(table, key, f"expected a string, got {type(v).__name__} {short(v)}")
            return ""
        return v

    def choice(self, table: str, d: dict, key: str, options: tuple[str, ...]) -> str | None:
        """A string that must be one of ``options`` (None, with the problem noted, else)."""
        v = self.string(table, d, key)
        if v in options:
            return v
        if v:
            close = difflib.get_close_matches(v, options, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            self.bad(table, key, f"expected one of {', '.join(options)}, got {v!r}{hint}")
        return None

    def sub(self, table: str, d: dict, key: str) -> dict:
        v = d.get(key, {})
        if not isinstance(v, dict):
            self.bad(table, key, f"expected a table, got {type(v).__name__} {short(v)}")
            return {}
        return v
