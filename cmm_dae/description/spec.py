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


def _json(k: Key) -> dict:
    num = {"type": "number"}
    s: dict[str, Any]
    if k.kind == "number":
        s = dict(num)
        if k.minimum is not None:
            s["minimum"] = k.minimum
    elif k.kind == "string":
        s = {"type": "string"}
    elif k.kind == "boolean":
        s = {"type": "boolean"}
    elif k.kind == "choice":
        s = {"type": "string", "enum": list(k.choices)}
    elif k.kind in ("vector2", "vector3"):
        n = int(k.kind[-1])
        s = {"type": "array", "items": num, "minItems": n, "maxItems": n}
    elif k.kind == "vector23":
        s = {"type": "array", "items": num, "minItems": 2, "maxItems": 3}
    elif k.kind == "inertia":
        s = {"oneOf": [{"type": "number", "minimum": 0.0},
                       {"type": "array", "items": num, "minItems": 3, "maxItems": 3},
                       {"type": "array", "items": num, "minItems": 6, "maxItems": 6}]}
    elif k.kind == "axis":
        s = {"oneOf": [_json(Key("vector2", "")), _json(Key("strings2", ""))]}
    elif k.kind == "guess":
        s = {"oneOf": [_json(Key("vector3", "")), {
            "type": "object", "additionalProperties": False,
            "properties": {k: _json(Key("vector3", "")) for k in (
                "position", "rotation", "velocity", "angular_velocity")}}]}
    elif k.kind == "numbers":
        s = {"type": "array", "items": num}
    elif k.kind == "points":
        s = {"type": "array", "items": {"type": "array", "items": num, "minItems": 2,
                                        "maxItems": 2}}
    elif k.kind == "strings2":
        s = {"type": "array", "items": {"type": "string"}, "minItems": 2, "maxItems": 2}
    elif k.kind == "pair":
        s = {"type": "array", "items": {"type": "string", "pattern": r"^[^.]+\..+$"},
             "minItems": 2, "maxItems": 2}
    elif k.kind == "paths":
        s = {"oneOf": [{"const": "position"},
                       {"type": "array", "items": {"type": "string"}}]}
    elif k.kind == "table":
        s = _object(k.keys)
    elif k.kind == "map":
        s = {"type": "object", "additionalProperties": _json(Key(k.of, ""))}
    else:  # pragma: no cover - a programming error in SPEC
        raise ValueError(k.kind)
    desc = k.doc + (f" [{k.unit}]" if k.unit else "")
    s["description"] = desc
    if k.default is not REQUIRED and k.default is not None and k.kind != "string":
        s["default"] = k.default
    return s


def _object(keys: dict[str, Key], only: tuple[str, ...] | None = None) -> dict:
    names = [n for n in keys if only is None or n in only]
    return {"type": "object", "properties": {n: _json(keys[n]) for n in names},
            "required": [n for n in names if keys[n].default is REQUIRED],
            "additionalProperties": False}


def _table_json(t: Table) -> dict:
    if t.variants is None:
        entry = _object(t.keys)
    else:
        # Each value of the discriminating key admits the common keys plus its own.
        disc, extra = t.variants
        own = {k for ks in extra.values() for k in ks}
        common = tuple(k for k in t.keys if k not in own)
        entry = {"type": "object", "required": [disc], "oneOf": []}
        for value, ks in extra.items():
            o = _object(t.keys, common + ks)
            o["properties"][disc] = {"const": value}
            entry["oneOf"].append(o)
    entry["description"] = t.doc
    if t.named:
        return {"type": "object", "description": t.doc, "additionalProperties": entry}
    return entry
