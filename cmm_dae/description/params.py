"""Scalar model parameters named by dotted paths (``joints.D.spring.stiffness``): which
paths exist and have an effect, their values, and a mechanism with some of them changed.
Sweeps, the equilibrium start and design studies all name parameters this way."""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from ..core.errors import ModelError, Problem
from .mechanism import (
    GROUND,
    Damper,
    Initial,
    Limits,
    Mechanism,
    Spring,
    _frozen,
    require_mechanism,
)
from .schema import LAW_KEYS

_SUB = {"spring": Spring, "damper": Damper, "limits": Limits}
#: the tables a dotted path may start with (besides ``initial`` and ``gravity``)
_TABLES = ("bodies", "joints", "drivers", "elements", "gears")


#: Scalar numeric fields a dotted path may set, per table (sub-tables as "spring.rest").
_FIELDS = {
    "bodies": ("mass", "inertia"),
    "joints": ("angle", "restitution", "spring.stiffness", "spring.rest", "damper.damping",
               "limits.lower", "limits.upper", "friction.static", "friction.kinetic",
               "friction.mu_static", "friction.mu_kinetic", "friction.radius",
               "curve.radius"),
    "drivers": ("initial", "speed", "amplitude", "frequency", "phase"),
    "elements": ("stiffness", "rest", "damping", "preload"),
    "gears": ("ratio",),
}


#: Law fields a load's dotted path may set (``loads.NAME.FIELD``), per law kind: the
#: schema's keys of each law but its lists.
_LAW_USES = {kind: tuple(k for k in keys if k not in ("coefficients", "times", "values"))
             for kind, keys in LAW_KEYS.items()}
_LAW_FIELDS = tuple(dict.fromkeys(k for keys in _LAW_USES.values() for k in keys))

#: Driver fields each motion law reads.
_DRIVER_USES = {"constant_speed": ("initial", "speed"), "polynomial": (),
                "harmonic": ("initial", "amplitude", "frequency", "phase"), "table": ()}


def _no_effect(mech: Mechanism, parts: list[str]) -> str | None:
    """Why setting this (existing, numeric) path would change nothing, or None."""
    table, name, fld = parts[0], parts[1], ".".join(parts[2:])
    if table == "joints":
        j = mech.joints[name]
        if fld == "angle" and j.type != "prismatic":
            return f"joint '{name}' is {j.type}: 'angle' is read for prismatic joints only"
        if fld == "restitution" and j.stops is None:
            return f"joint '{name}' has no limits for a restitution to act at"
        if fld == "curve.radius" and (j.curve is None or j.curve.kind != "circle"):
            return f"joint '{name}' has no circle for a radius to act on"
        if fld == "spring.rest" and j.spring is None:
            return (f"joint '{name}' has no spring: set joints.{name}.spring.stiffness to "
                    "give it one")
        if fld.startswith("limits.") and getattr(j.limits, fld[7:], None) is None:
            return f"joint '{name}' has no {fld[7:]} limit"
        if fld.startswith("friction.") and j.friction is None:
            return f"joint '{name}' has no friction"
    if table == "loads":
        law = mech.loads[name].law
        if law.func is not None:
            return f"load '{name}' is a Python callable: it reads none of its fields"
        if fld not in _LAW_USES[law.kind]:
            uses = ", ".join(_LAW_USES[law.kind]) or "only its lists"
            return f"load '{name}' follows the '{law.kind}' law, which reads {uses}"
    if table == "drivers":
        d = mech.drivers[name]
        if fld not in _DRIVER_USES[d.motion]:
            uses = ", ".join(_DRIVER_USES[d.motion]) or "only its lists"
            return f"driver '{name}' moves by '{d.motion}', which reads {uses}"
    return None


def _point_ref(mech: Mechanism, parts: list[str]) -> str | None:
    """``"body.point"`` of a point-coordinate path (``bodies.B.points.P.x``,
    ``ground.points.P.y``) naming an existing point, else None."""
    if len(parts) == 5 and parts[0] == "bodies" and parts[2] == "points" \
            and parts[1] in mech.bodies and parts[3] in mech.bodies[parts[1]].points \
            and parts[4] in _axes(mech):
        return f"{parts[1]}.{parts[3]}"
    if len(parts) == 4 and parts[0] == GROUND and parts[1] == "points" \
            and parts[2] in mech.ground and parts[3] in _axes(mech):
        return f"{GROUND}.{parts[2]}"
    return None


def _axes(mech: Mechanism) -> tuple[str, ...]:
    """The coordinates a point or the gravity has: x, y (and z in space)."""
    return ("x", "y", "z") if mech.spatial else ("x", "y")


#: the entries of a spatial body's inertia tensor a path may set (``bodies.B.inertia.xx``)
_TENSOR = ("xx", "yy", "zz", "xy", "xz", "yz")


def _tensor_entry(mech: Mechanism, parts: list[str]) -> int | None:
    """The index of a spatial body's inertia entry a path names, else None."""
    if mech.spatial and len(parts) == 4 and parts[0] == "bodies" and parts[1] in mech.bodies \
            and parts[2] == "inertia" and parts[3] in _TENSOR:
        k = _TENSOR.index(parts[3])
        return k if k < len(mech.bodies[parts[1]].inertia) else None
    return None


def _point_used(mech: Mechanism, ref: str) -> bool:
    """Whether a joint, force element or point load is attached at ``ref``."""
    body, pt = ref.split(".", 1)
    return any(ref in (j.first, j.second) for j in mech.joints.values()) \
        or any(ref in (e.first, e.second) for e in mech.elements.values()) \
        or any(ld.body == body and ld.point == pt for ld in mech.loads.values())


def _parts(mech: Mechanism, path: str) -> list[str]:
    """A dotted path's parts; a gear pair's, which a model file writes as a ``[joints]``
    entry (``joints.Z.ratio``), as ``gears.Z.ratio``."""
    parts = path.split(".")
    if len(parts) > 1 and parts[0] == "joints" and parts[1] in mech.gears \
            and parts[1] not in mech.joints:
        parts[0] = "gears"
    return parts


def path_problem(mech: Mechanism, path: str) -> Problem | None:
    """Why a dotted path is not a parameter that can be set (None when it is)."""
    parts = _parts(mech, path)
    ref = _point_ref(mech, parts)
    if ref is not None:
        return None if _point_used(mech, ref) else Problem(
            "parameters", path, f"has no effect: no joint, force element or load is attached at "
            f"point '{ref}'")
    if _tensor_entry(mech, parts) is not None:
        return None
    if mech.spatial and parts[:1] == ["bodies"] and parts[2:3] == ["inertia"] \
            and parts[1] in mech.bodies:
        return Problem("parameters", path, "a spatial body's inertia is a tensor: name one "
                       "entry, bodies.NAME.inertia.xx|yy|zz (principal moments) or "
                       ".xy|xz|yz (products, where six are given)")
    tables = {k: getattr(mech, k) for k in _TABLES}
    if parts[0] in tables and len(parts) in (3, 4) and parts[1] in tables[parts[0]] \
            and ".".join(parts[2:]) in _FIELDS[parts[0]]:
        why = _no_effect(mech, parts)
        return None if why is None else Problem("parameters", path, f"has no effect: {why}")
    if parts[0] == "loads" and len(parts) == 3 and parts[1] in mech.loads \
            and parts[2] in _LAW_FIELDS:
        why = _no_effect(mech, parts)
        return None if why is None else Problem("parameters", path, f"has no effect: {why}")
    if (parts[0] == "initial" and len(parts) == 3 and parts[1] in ("joints", "velocities")
            and parts[2] in mech.joints) or (parts[0] == "gravity" and len(parts) == 2
                                             and parts[1] in _axes(mech)):
        return None
    return Problem("parameters", path, f"not a parameter of the mechanism{_hint(mech, parts)}; "
                   f"e.g. {', '.join(examples(mech))}")


def examples(mech: Mechanism, n: int = 6) -> list[str]:
    """A few dotted paths that are parameters of this mechanism (for messages)."""
    out = [f"bodies.{b}.mass" for b in list(mech.bodies)[:1]]
    out += [f"joints.{j}.spring.stiffness" for j, x in mech.joints.items() if x.spring][:1]
    out += [f"joints.{j}.limits.{'upper' if x.limits.upper is not None else 'lower'}"
            for j, x in mech.joints.items() if x.limits][:1]
    out += [f"drivers.{d}.{_DRIVER_USES[x.motion][-1]}" for d, x in mech.drivers.items()
            if _DRIVER_USES[x.motion]][:1]
    out += [f"loads.{k}.{_LAW_USES[x.law.kind][0]}" for k, x in mech.loads.items()
            if x.law.func is None and _LAW_USES[x.law.kind]][:1]
    j = next(iter(mech.joints.values()), None)
    if j is not None:
        body, pt = j.second.split(".", 1)
        out.append(f"bodies.{body}.points.{pt}.x" if body != GROUND
                   else f"ground.points.{pt}.x")
    out.append("gravity.y")
    return out[:n]


def _hint(mech: Mechanism, parts: list[str]) -> str:
    """' (did you mean ...?)' for a misspelt table or name, else ''."""
    names = {"bodies": mech.bodies, "joints": mech.joints, "drivers": mech.drivers,
             "elements": mech.elements, "loads": mech.loads, "gears": mech.gears}
    tables = [*names, "initial", "gravity", GROUND]
    if parts[0] not in tables:
        near = difflib.get_close_matches(parts[0], tables, n=1)
        return f" (no table '{parts[0]}'" + (f": did you mean '{near[0]}'?)" if near else ")")
    if parts[0] in names and len(parts) > 1 and parts[1] not in names[parts[0]]:
        near = difflib.get_close_matches(parts[1], list(names[parts[0]]), n=1)
        return (f" (no {'body' if parts[0] == 'bodies' else parts[0][:-1]} '{parts[1]}'"
                + (f": did you mean '{near[0]}'?)" if near else ")"))
    return ""


def param_value(mech: Mechanism, path: str) -> float:
    """The current value of a dotted model path (see :func:`with_params`); a spring,
    damper or limit that does not exist reads as 0 (stiffness, damping) or NaN."""
    parts = _parts(mech, path)
    bad = path_problem(mech, path)
    if bad is not None:
        raise ModelError(bad, mech.source)
    if parts[0] == "gravity":
        return mech.gravity["xyz".index(parts[1])]
    ref = _point_ref(mech, parts)
    if ref is not None:
        return float(mech.point(ref)["xyz".index(parts[-1])])
    k = _tensor_entry(mech, parts)
    if k is not None:
        return float(mech.bodies[parts[1]].inertia[k])
    if parts[0] == "initial":
        table = mech.initial.joints if parts[1] == "joints" else mech.initial.velocities
        return float(table.get(parts[2], math.nan))
    obj = getattr(mech, parts[0])[parts[1]]
    if parts[0] == "loads":
        obj = obj.law
    for name in parts[2:]:
        obj = getattr(obj, name) if obj is not None else None
    return float(obj) if obj is not None else (0.0 if parts[-1] in ("stiffness", "damping")
                                                 else math.nan)


def with_params(mech: Mechanism, values: Mapping[str, float]) -> Mechanism:
    """A copy of ``mech`` with dotted-path values replaced, validated again.

    Paths: ``bodies.NAME.mass|inertia``, ``joints.NAME.restitution|angle``,
    ``joints.NAME.spring.stiffness|rest``, ``joints.NAME.damper.damping``,
    ``joints.NAME.limits.lower|upper``,
    ``joints.NAME.friction.static|kinetic|mu_static|mu_kinetic|radius``,
    ``drivers.JOINT.speed|initial|amplitude|...``,
    ``elements.NAME.stiffness|rest|damping|preload``, ``gears.NAME.ratio``,
    ``initial.joints.NAME``,
    ``initial.velocities.NAME``, ``gravity.x|y``, a load's law
    ``loads.NAME.value|mean|amplitude|frequency|phase|stall|no_load_speed`` (as its law
    reads them), point coordinates in their frame
    (link lengths, pivot positions) ``bodies.NAME.points.POINT.x|y`` and
    ``ground.points.POINT.x|y``, m. In a spatial mechanism points and gravity have ``z``
    too, and a body's inertia is set entry by entry:
    ``bodies.NAME.inertia.xx|yy|zz|xy|xz|yz`` (kg m^2).

    Raises
    ------
    ModelError
        A path that is not a numeric parameter of the mechanism, a value that is not a
        number, or a path whose value the mechanism never reads (e.g. the amplitude of a
        constant-speed driver), each named.
    """
    require_mechanism(mech, "with_params")
    problems = []
    for path, value in values.items():
        if isinstance(value, bool) or not isinstance(value, int | float | np.number):
            problems.append(Problem("parameters", path, f"expected a number, got {value!r}"))
            continue
        bad = path_problem(mech, str(path))
        if bad is not None:
            problems.append(bad)
    if problems:
        raise ModelError(problems, mech.source)
    return _replaced(mech, {str(k): float(v) for k, v in values.items()}, check=True)


def symbolic(mech: Mechanism, values: Mapping[str, object]) -> Mechanism:
    """A copy of ``mech`` (not validated) whose fields at the given (checked) dotted
    paths hold other objects: CasADi symbols, from which the model's equations are built
    as functions of those parameters (sensitivities)."""
    return _replaced(mech, values, check=False)


def _replaced(mech: Mechanism, values: Mapping[str, object], check: bool) -> Mechanism:
    tables = {k: dict(getattr(mech, k)) for k in _TABLES}
    loads = dict(mech.loads)
    ini_j, ini_v = dict(mech.initial.joints), dict(mech.initial.velocities)
    gravity = list(mech.gravity)
    ground = dict(mech.ground)
    points: dict[str, dict] = {}  # body -> its points, where some changed
    for path, value in values.items():
        parts = _parts(mech, path)
        if _point_ref(mech, parts) is not None:
            pts = ground if parts[0] == GROUND else points.setdefault(
                parts[1], dict(mech.bodies[parts[1]].points))
            name = parts[-2]
            xy = list(pts[name])
            xy["xyz".index(parts[-1])] = value
            pts[name] = tuple(xy)
        elif (k := _tensor_entry(mech, parts)) is not None:
            b = tables["bodies"][parts[1]]
            entries = list(b.inertia)
            entries[k] = value
            b = replace(b, inertia=tuple(entries))
            if not check:  # (the constructor makes the entries floats: a symbol NaN)
                object.__setattr__(b, "inertia", tuple(entries))
            tables["bodies"][parts[1]] = b
        elif parts[0] == "loads":
            ld = loads[parts[1]]
            loads[parts[1]] = replace(ld, law=replace(ld.law, **{parts[2]: value}))
        elif parts[0] in tables:
            table = tables[parts[0]]
            obj = table[parts[1]]
            if len(parts) == 3:
                table[parts[1]] = replace(obj, **{parts[2]: value})
            else:
                sub = getattr(obj, parts[2])
                if sub is None:
                    sub = _SUB[parts[2]](**({"stiffness": 0.0} if parts[2] == "spring"
                                            else {"damping": 0.0}
                                            if parts[2] == "damper" else {}))
                table[parts[1]] = replace(obj, **{parts[2]: replace(sub, **{parts[3]: value})})
        elif parts[0] == "initial":
            (ini_j if parts[1] == "joints" else ini_v)[parts[2]] = value
        else:
            gravity["xyz".index(parts[1])] = value
    for body, pts in points.items():
        b = replace(tables["bodies"][body], points=pts)
        if not check:  # the constructor makes the points floats
            object.__setattr__(b, "points", _frozen(pts))
        tables["bodies"][body] = b
    out = mech.replace(**tables, loads=loads,
                       initial=Initial(ini_j, ini_v, mech.initial.equilibrium),
                       gravity=tuple(gravity), ground=ground, check=check)
    if not check:  # the constructor makes the gravity and the ground points floats
        object.__setattr__(out, "gravity", tuple(gravity))
        object.__setattr__(out, "ground", _frozen(ground))
    return out
