"""The building blocks of the model-file description (:mod:`.schema`): a key of a table
and a table, with their types, units and defaults."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["REQUIRED", "Key", "Table"]


class _Required:
    def __repr__(self) -> str:
        return "required"


#: Marks a key without a default.
REQUIRED: Any = _Required()


@dataclass(frozen=True)
class Key:
    """One key of a table.

    ``kind`` is one of ``number``, ``string``, ``choice``, ``vector2``, ``vector3``,
    ``numbers`` (a list of any length), ``boolean``, ``pair`` (two ``"body.point"`` strings),
    ``paths`` (``"position"`` or a list of strings), ``table`` (an inline sub-table with
    ``keys``), ``map`` (names of the user's choosing to ``of`` values).
    """

    kind: str
    doc: str
    unit: str = ""
    default: Any = REQUIRED
    choices: tuple[str, ...] = ()
    keys: dict[str, Key] = field(default_factory=dict)
    of: str = "number"
    minimum: float | None = None
    example: str = ""


@dataclass(frozen=True)
class Table:
    """A table of the file: fixed ``keys``, or (``named``) one sub-table per user name.

    ``variants`` names a discriminating key and, for each of its values, the extra keys that
    value admits (a driver's ``motion``, a load's ``law``).
    """

    doc: str
    keys: dict[str, Key]
    named: bool = False
    variants: tuple[str, dict[str, tuple[str, ...]]] | None = None
    example: str = ""
