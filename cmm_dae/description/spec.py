"""The building blocks of the model-file description (:mod:`.schema`): a key of a table
and a table, with their types, units and defaults."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["LAW_KEYS", "MOTION_KEYS", "REQUIRED", "Key", "Table"]


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


_COORD = "rad (revolute) or m (prismatic, contact)"
_RATE = "rad/s or m/s"

#: Extra keys of each law (loads) and each motion (drivers).
LAW_KEYS: dict[str, tuple[str, ...]] = {
    "constant": ("value",),
    "polynomial": ("coefficients",),
    "harmonic": ("mean", "amplitude", "frequency", "phase"),
    "table": ("times", "values"),
    "motor": ("stall", "no_load_speed"),
}
MOTION_KEYS: dict[str, tuple[str, ...]] = {
    "constant_speed": ("initial", "speed"),
    "polynomial": ("coefficients",),
    "harmonic": ("initial", "amplitude", "frequency", "phase"),
    "table": ("times", "values"),
}

_LAW_VALUES: dict[str, Key] = {
    "value": Key("number", "value of a constant law", "N, N m (the load's unit)"),
    "coefficients": Key("numbers", "c0, c1, ...: value = sum c_k t^k", "unit / s^k"),
    "mean": Key("number", "harmonic law: mean value", "the load's unit", default=0.0),
    "amplitude": Key("number", "harmonic law: amplitude", "the load's unit"),
    "frequency": Key("number", "harmonic law: frequency", "Hz", minimum=0.0),
    "phase": Key("number", "harmonic law: phase", "rad", default=0.0),
    "times": Key("numbers", "table law: sample times, strictly increasing from 0 (the value "
                 "is held after the last time)", "s"),
    "values": Key("numbers", "table law: values at `times`, joined by a C2 cubic spline",
                  "the load's unit"),
    "stall": Key("number", "motor law: value at zero rate; value = stall (1 - rate / "
                 "no_load_speed)", "N m or N"),
    "no_load_speed": Key("number", "motor law: rate at which the value reaches zero", _RATE),
}

_DRIVER_VALUES: dict[str, Key] = {
    "initial": Key("number", "coordinate at t = 0 (constant_speed, harmonic)", _COORD),
    "speed": Key("number", "constant_speed: coordinate = initial + speed t", _RATE),
    "coefficients": Key("numbers", "polynomial: coordinate = sum c_k t^k", f"{_COORD} / s^k"),
    "amplitude": Key("number", "harmonic: coordinate = initial + amplitude sin(2 pi f t + "
                     "phase)", _COORD),
    "frequency": Key("number", "harmonic: frequency f", "Hz", minimum=0.0),
    "phase": Key("number", "harmonic: phase", "rad", default=0.0),
    "times": Key("numbers", "table: sample times, strictly increasing from 0", "s"),
    "values": Key("numbers", "table: coordinates at `times`, joined by a C2 cubic spline "
                  "with clamped ends", _COORD),
}
