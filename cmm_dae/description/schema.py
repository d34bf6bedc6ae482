"""The model-file format, written once.

Every table and key of a mechanism TOML file is described here with its type, unit,
default and meaning. Three things are generated from this one description, so they
cannot disagree:

* the loader's key checks (:mod:`cmm_dae.description.loader` takes its allowed keys
  and defaults from :data:`SPEC`),
* the JSON Schema shipped with the package (:func:`json_schema`, ``cmm-dae schema``), which
  editors and TOML language servers read,
* the model-file reference of the documentation (:func:`reference_markdown`).

The semantic checks that a schema cannot say (a body named by a joint exists, limits are
ordered, a driven joint has no limits, ...) stay in :mod:`cmm_dae.description.checks`.
"""

from __future__ import annotations

import json
from typing import Any

from .checks import CURVES, FRAMES, JOINT_TYPES, LAWS, MOTIONS, SIDES
from .spec import REQUIRED, Key, Table  # noqa: F401 (schema.Key and schema.Table, as before)

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

#: The whole file, table by table (the order is the order of the reference).
SPEC: dict[str, Table] = {
    "mechanism": Table("Name and gravity.", {
        "name": Key("string", "name shown in reports", default="the file's stem"),
        "gravity": Key("vector2", "gravitational acceleration, global frame", "m/s^2",
                       default=[0.0, -9.81]),
    }, example='[mechanism]\nname = "offset slider-crank"\ngravity = [0.0, -9.81]'),
    "ground": Table("Fixed points, in global coordinates.", {
        "points": Key("map", "point name -> [x, y]", "m", of="vector2", default={}),
    }, example='[ground.points]\nA = [0.0, 0.0]\nrail = [0.0, 0.01]'),
    "bodies": Table("One table per moving rigid body; `ground` is reserved.", {
        "mass": Key("number", "mass", "kg", minimum=0.0),
        "inertia": Key("number", "moment of inertia about the centroid (or about "
                       "`inertia_about`); 0 is a point mass, whose rotation its joints must "
                       "fix", "kg m^2", minimum=0.0),
        "inertia_about": Key("string", "name of one of the body's points about which "
                             "`inertia` is given (the parallel-axis theorem is applied)",
                             default=None),
        "centroid": Key("vector2", "centre of mass in the body frame", "m",
                        default=[0.0, 0.0]),
        "points": Key("map", "point name -> [x, y] in the body frame (the frame the "
                      "body's pose is the position and angle of)", "m", of="vector2",
                      default={}),
        "guess": Key("vector3", "pose guess [x, y, theta] for the assembly at t = 0",
                     "m, m, rad", default=None),
    }, named=True, example='[bodies.crank]\nmass = 0.1\ninertia = 2.0e-5\n'
       'centroid = [0.025, 0.0]\npoints = { A = [0.0, 0.0], B = [0.05, 0.0] }'),
    "joints": Table("One table per joint between two bodies (or a body and the ground).", {
        "type": Key("choice", "revolute: coordinate theta_second - theta_first; prismatic: "
                    "displacement of the second point from the first along `axis`; contact: "
                    "the second point on a `curve` of the first body (a higher pair), "
                    "coordinate its arc length (bilateral) or its gap (unilateral); gear: "
                    "two joints' coordinates in a fixed `ratio` (gears, rack and pinion)",
                    choices=JOINT_TYPES + ("gear",)),
        "connects": Key("strings2", "[\"body.point\", \"body.point\"]: the first and the "
                        "second body and their points (`ground.X` for a ground point; a "
                        "contact's curve passes through the first point); a gear pair: "
                        "[\"JOINT\", \"JOINT\"], its two joints"),
        "ratio": Key("number", "gear only: rate of the second joint / rate of the first "
                     "(< 0 for two gears in external mesh, > 0 and not 1 for a pinion inside a "
                     "ring gear; +- the pitch radius for a rack)",
                     "rad/rad, m/rad or rad/m", default=None),
        "pressure_angle": Key("number", "gear only: the line of action's angle from the "
                              "pitch circles' tangent (the tooth force is reported along it)",
                              "rad", minimum=0.0, default=0.3490658503988659),
        "offset": Key("number", "gear only: the second joint's coordinate where the first's "
                      "is 0", _COORD, default=0.0),
        "axis": Key("vector2", "prismatic only: sliding direction in the first body's frame",
                    default=[1.0, 0.0]),
        "angle": Key("number", "prismatic only: the relative angle theta_second - "
                     "theta_first the joint holds", "rad", default=0.0),
        "curve": Key("table", "contact only: the first body's curve, in its frame through the "
                     "first point", keys={
                         "kind": Key("choice", "circle (centred on the point; arc length "
                                     "radius atan2 from the body's x axis), line (through "
                                     "the point; arc length along `direction`) or spline "
                                     "(a smooth curve through `points`, closed or open; "
                                     "arc length from the first point)",
                                     choices=CURVES),
                         "radius": Key("number", "circle: radius", "m", minimum=0.0,
                                       default=0.0),
                         "direction": Key("vector2", "line: direction in the first body's "
                                          "frame", default=[1.0, 0.0]),
                         "points": Key("points", "spline: points [[x, y], ...] relative to "
                                       "the first point: closed, counter-clockwise once "
                                       "around it (a cam profile, a closed groove); open, "
                                       "in increasing x (a curved slot)", "m",
                                       default=[]),
                         "closed": Key("boolean", "spline: a closed curve around the first "
                                       "point (true) or an open one along x, whose ends "
                                       "are stops (false)", default=True)},
                     default=None),
        "side": Key("choice", "contact only: the side of the curve the point keeps to (a "
                    "circle's or spline's outside or inside; left or right of a line's "
                    "direction, where outside and inside read as left and right)",
                    choices=SIDES, default="outside"),
        "unilateral": Key("boolean", "contact only: the point may leave the curve (lift-off "
                          "when the contact would pull, landing with `restitution`); its "
                          "coordinate is then the gap (m)", default=False),
        "limits": Key("table", "extreme positions of the coordinate: a metamorphic joint "
                      "locks there (geometric constraint)", keys={
                          "lower": Key("number", "lower limit", _COORD, default=None),
                          "upper": Key("number", "upper limit", _COORD, default=None)},
                      default=None),
        "restitution": Key("number", "Newton coefficient at the limits or a unilateral "
                           "contact's landing (0 plastic: the joint locks; > 0: it bounces)",
                           minimum=0.0, default=0.0),
        "spring": Key("table", "linear spring on the coordinate; a `rest` beyond a limit "
                      "preloads the joint onto it (force constraint)", keys={
                          "stiffness": Key("number", "stiffness", "N m/rad or N/m",
                                           minimum=0.0),
                          "rest": Key("number", "rest coordinate", _COORD, default=0.0)},
                      default=None),
        "damper": Key("table", "linear damper on the coordinate", keys={
            "damping": Key("number", "damping", "N m s/rad or N s/m", minimum=0.0)},
            default=None),
        "friction": Key("table", "Coulomb friction: the joint sticks while the force it "
                        "carries stays within its static level, slips with its kinetic level "
                        "against its rate; each level is a constant plus `mu` times the "
                        "joint's reaction (revolute: `mu radius |F|`; prismatic: `mu |N|`, "
                        "N the guide's normal reaction), solved together with it",
                        keys={"static": Key("number", "constant static friction level",
                                            "N m or N", minimum=0.0, default=0.0),
                              "kinetic": Key("number", "constant kinetic friction level "
                                             "(<= static)", "N m or N", minimum=0.0,
                                             default=0.0),
                              "mu_static": Key("number", "static friction coefficient on "
                                               "the reaction", "-", minimum=0.0,
                                               default=0.0),
                              "mu_kinetic": Key("number", "kinetic friction coefficient on "
                                                "the reaction (<= mu_static)", "-",
                                                minimum=0.0, default=0.0),
                              "radius": Key("number", "pin radius of a revolute joint with "
                                            "mu_static or mu_kinetic", "m", minimum=0.0,
                                            default=0.0)},
                        default=None),
    }, named=True, example='[joints.E]\ntype = "prismatic"\nconnects = ["ground.rail", '
       '"slider.C"]\naxis = [1.0, 0.0]\nlimits = { lower = 0.15, upper = 0.30 }\n'
       'spring = { stiffness = 1.03, rest = 0.0 }'),
    "drivers": Table("One table per driven joint, named after the joint: a prescribed "
                     "coordinate (rheonomic constraint); its effort is the driving torque or "
                     "force.", {
        "motion": Key("choice", "the law of the coordinate", choices=MOTIONS),
        **_DRIVER_VALUES,
    }, named=True, variants=("motion", MOTION_KEYS),
        example='[drivers.A]\nmotion = "constant_speed"\ninitial = 3.141592653589793\n'
                'speed = 0.6283185307179586'),
    "loads": Table("One table per applied load: a scalar law times what it acts on (a joint "
                   "coordinate, a force at a body point, or a pure moment on a body).", {
        "joint": Key("string", "load on this joint's coordinate: + along it on the second "
                     "body, - on the first", default=None),
        "body": Key("string", "load on this body (at `point`, or a pure moment, CCW +, "
                    "without one)", default=None),
        "point": Key("string", "the body point the force acts at", default=None),
        "direction": Key("vector2", "force direction (normalised), in `frame`",
                         default=None),
        "frame": Key("choice", "frame of `direction`", choices=FRAMES, default="global"),
        "law": Key("choice", "the law of the value", choices=LAWS),
        **_LAW_VALUES,
        "zone": Key("table", "acts only while a joint coordinate lies inside [lower, "
                    "upper]; the edges are events", keys={
                        "joint": Key("string", "the joint (default: the loaded joint)",
                                     default=None),
                        "lower": Key("number", "lower edge", _COORD, default=None),
                        "upper": Key("number", "upper edge", _COORD, default=None)},
                    default=None),
    }, named=True, variants=("law", LAW_KEYS),
        example='[loads.cut]\nbody = "jaw"\npoint = "tip"\ndirection = [0.0, -1.0]\n'
                'law = "constant"\nvalue = 20.0\nzone = { joint = "C", lower = -0.05, '
                'upper = 0.0 }'),
    "elements": Table("One table per spring-damper-actuator between two points of any two "
                      "bodies; tension = preload + stiffness (L - rest) + damping L', "
                      "positive tension pulls the points together.", {
        "connects": Key("pair", "[\"body.point\", \"body.point\"]"),
        "stiffness": Key("number", "stiffness", "N/m", minimum=0.0, default=0.0),
        "rest": Key("number", "rest length", "m", minimum=0.0, default=0.0),
        "damping": Key("number", "damping", "N s/m", minimum=0.0, default=0.0),
        "preload": Key("number", "constant tension", "N", default=0.0),
    }, named=True, example='[elements.squeeze]\nconnects = ["ground.C", "link3.D"]\n'
       'stiffness = 4530.0\nrest = 0.07785'),
    "initial": Table("The state at t = 0.", {
        "joints": Key("map", "known coordinates, as many non-driven ones as the mechanism "
                      "has free DOF; the others are assembled", _COORD, default={}),
        "velocities": Key("map", "rates of the coordinates named in `joints` (default 0)",
                          _RATE, default={}),
        "equilibrium": Key("paths", "\"position\" (solve the coordinates in `joints`) or a "
                           "list of parameter paths (e.g. \"joints.D.spring.rest\"), as "
                           "many as the free motion's degrees of freedom, solved so that the "
                           "free motion does not accelerate at the start (at rest: no "
                           "generalized force on it, a static analysis)",
                           default=[]),
    }, example='[initial]\njoints = { A = 3.141592653589793, E = 0.22773 }\n'
       'velocities = { E = 0.0 }'),
}


def keys_of(table: str, sub: str | None = None) -> tuple[str, ...]:
    """Allowed keys of ``table`` (or of its inline sub-table ``sub``)."""
    keys = SPEC[table].keys
    return tuple(keys[sub].keys) if sub else tuple(keys)


def default(table: str, key: str, sub: str | None = None) -> Any:
    """Default of a key (lists as tuples, as the mechanism stores them)."""
    k = SPEC[table].keys[sub].keys[key] if sub else SPEC[table].keys[key]
    return tuple(k.default) if isinstance(k.default, list) else k.default


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


def json_schema() -> dict:
    """The JSON Schema (draft 2020-12) of a mechanism model file.

    Returns
    -------
    dict
        Serialisable with :func:`json.dumps`; TOML language servers (Taplo, Even Better
        TOML) read it to check and complete model files in an editor.
    """
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "https://cmm-dae.example/schema/model.json",
        "title": "cmm_dae mechanism model file",
        "description": "A planar constrained metamorphic mechanism (SI units throughout).",
        "type": "object",
        "properties": {name: _table_json(t) for name, t in SPEC.items()},
        "required": ["bodies", "joints"],
        "additionalProperties": False,
    }


def json_text() -> str:
    """:func:`json_schema` as indented JSON text."""
    return json.dumps(json_schema(), indent=2) + "\n"


def _type_text(k: Key) -> str:
    return {"number": "number", "string": "string", "vector2": "[x, y]",
            "vector3": "[x, y, theta]", "boolean": "true \\| false",
            "numbers": "list of numbers",
            "pair": "two strings", "strings2": "two strings", "points": "list of [x, y]",
            "paths": "\"position\" or list of strings",
            "table": "inline table", "map": f"table of name = {k.of.replace('vector2', '[x, y]')}",
            "choice": " \\| ".join(f"`{c}`" for c in k.choices)}[k.kind]


def _default_text(k: Key) -> str:
    if k.default is REQUIRED:
        return "required"
    if k.default is None:
        return "none"
    if isinstance(k.default, str) and k.kind == "string":
        return k.default
    return f"`{json.dumps(k.default)}`"


def reference_markdown() -> str:
    """The model-file reference (Markdown): every table and key with type, unit, default."""
    out: list[str] = []
    for name, t in SPEC.items():
        head = f"[{name}.NAME]" if t.named else f"[{name}]"
        out += [f"## `{head}`", "", t.doc, ""]
        if t.variants:
            disc, extra = t.variants
            out += [f"Keys admitted by each `{disc}`:", ""]
            out += [f"- `{v}`: " + ", ".join(f"`{k}`" for k in ks) for v, ks in extra.items()]
            out.append("")
        out += ["| key | type | unit | default | meaning |", "|---|---|---|---|---|"]
        for kn, k in t.keys.items():
            out.append(f"| `{kn}` | {_type_text(k)} | {k.unit} | {_default_text(k)} | "
                       f"{k.doc} |")
            for sn, sk in k.keys.items():
                out.append(f"| `{kn}.{sn}` | {_type_text(sk)} | {sk.unit} | "
                           f"{_default_text(sk)} | {sk.doc} |")
        if t.example:
            out += ["", "Example:", "", "```toml", t.example, "```"]
        out.append("")
    return "\n".join(out)
