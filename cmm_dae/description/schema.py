"""The model-file format, written once.

Every table and key of a mechanism TOML file is described here with its type, unit,
default and meaning. Three things are generated from it, so they cannot disagree:

* the loader's key checks (:mod:`cmm_dae.description.loader` takes its allowed keys
  and defaults from :data:`SPEC`),
* the JSON Schema shipped with the package (:func:`json_schema`, ``cmm-dae schema``), which
  editors and TOML language servers read,
* the model-file reference of the documentation (:func:`reference_markdown`).

The semantic checks a schema cannot say stay in :mod:`cmm_dae.description.checks`.
"""

from __future__ import annotations

import json
from typing import Any

from .checks import CURVES, FRAMES, JOINT_TYPES, LAWS, MOTIONS, SIDES
from .spatial import SPACES, SPATIAL_TYPES
from .spec import (  # noqa: F401 (schema.Key, Table, LAW_KEYS, ... as before)
    _COORD,
    _DRIVER_VALUES,
    _LAW_VALUES,
    _RATE,
    LAW_KEYS,
    MOTION_KEYS,
    REQUIRED,
    Key,
    Table,
    _json,
    _table_json,
)

#: The whole file, table by table (the order is the order of the reference).
SPEC: dict[str, Table] = {
    "mechanism": Table("Name, space and gravity.", {
        "name": Key("string", "name shown in reports", default="the file's stem"),
        "space": Key("choice", "planar (x, y; every body turns about z) or spatial (x, y, "
                     "z: points, centroids, gravity and directions get three coordinates, "
                     "bodies an inertia tensor and named axes)", choices=SPACES,
                     default="planar"),
        "gravity": Key("vector23", "gravitational acceleration, global frame ([0, 0, -9.81] "
                       "by default in space)", "m/s^2", default=[0.0, -9.81]),
    }, example='[mechanism]\nname = "offset slider-crank"\ngravity = [0.0, -9.81]'),
    "ground": Table("Fixed points, in global coordinates.", {
        "points": Key("map", "point name -> [x, y] ([x, y, z] in space)", "m",
                      of="vector23", default={}),
        "axes": Key("map", "spatial only: direction name -> [x, y, z] (normalised), named by "
                    "joints as `ground.NAME`", of="vector3", default={}),
    }, example='[ground.points]\nA = [0.0, 0.0]\nrail = [0.0, 0.01]'),
    "bodies": Table("One table per moving rigid body; `ground` is reserved.", {
        "mass": Key("number", "mass", "kg", minimum=0.0),
        "inertia": Key("inertia", "moment of inertia about the centroid (or about "
                       "`inertia_about`); 0 is a point mass, whose rotation its joints must "
                       "fix. In space the centroidal tensor in body axes: [Ixx, Iyy, Izz] "
                       "(principal) or [Ixx, Iyy, Izz, Ixy, Ixz, Iyz], positive definite",
                       "kg m^2", minimum=0.0),
        "inertia_about": Key("string", "name of one of the body's points about which "
                             "`inertia` is given (the parallel-axis theorem is applied)",
                             default=None),
        "centroid": Key("vector23", "centre of mass in the body frame", "m",
                        default=[0.0, 0.0]),
        "points": Key("map", "point name -> [x, y] ([x, y, z] in space) in the body frame "
                      "(the frame the body's pose is the position and angle of)", "m",
                      of="vector23", default={}),
        "axes": Key("map", "spatial only: direction name -> [x, y, z] in the body frame "
                    "(normalised), named by joints as `BODY.NAME`", of="vector3",
                    default={}),
        "guess": Key("guess", "pose guess [x, y, theta] (m, m, rad) for the assembly; in "
                     "space { position, rotation, velocity, angular_velocity }: the frame "
                     "origin's position (m) and velocity (m/s), its rotation vector (axis "
                     "times angle, rad) and angular velocity (rad/s, global axes), where the "
                     "motion no [initial] coordinate names starts (made consistent)",
                     default=None),
    }, named=True, example='[bodies.crank]\nmass = 0.1\ninertia = 2.0e-5\n'
       'centroid = [0.025, 0.0]\npoints = { A = [0.0, 0.0], B = [0.05, 0.0] }'),
    "joints": Table("One table per joint between two bodies (or a body and the ground).", {
        "type": Key("choice", "revolute: coordinate theta_second - theta_first; prismatic: "
                    "displacement of the second point from the first along `axis`; contact: "
                    "the second point on a `curve` of the first body (a higher pair), "
                    "coordinate its arc length (bilateral) or its gap (unilateral); gear: "
                    "two joints' coordinates in a fixed `ratio` (gears, rack and pinion). "
                    "In space: revolute (coordinate: the angle about `axis` from the first "
                    "`reference` to the second, within pi of its range's middle), prismatic "
                    "(displacement along the first body's `axis`), cylindrical (both: the "
                    "joint J:slide has the displacement), spherical, universal (none)",
                    choices=JOINT_TYPES + ("gear",) + SPATIAL_TYPES[2:]),
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
        "axis": Key("axis", "planar prismatic: sliding direction [x, y] in the first body's "
                    "frame; spatial revolute and prismatic: [\"BODY.AXIS\", \"BODY.AXIS\"], "
                    "one named axis of each body, held aligned", default=[1.0, 0.0]),
        "reference": Key("strings2", "spatial revolute and prismatic: one named direction "
                         "of each body across the axis; the coordinate's zero (default: the "
                         "bodies' axes `x`)", default=None),
        "axes": Key("strings2", "spatial universal joint: its two arms, one named axis of "
                    "each body, held perpendicular", default=None),
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
        "direction": Key("vector23", "force direction (normalised), in `frame`; in space "
                         "also a moment's axis", default=None),
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


_J = SPEC["joints"].keys  # a cylindrical joint's slide: the parts of a joint's coordinate
_J["slide"] = Key("table", "spatial cylindrical joint J: the parts on its displacement along "
                  "`axis`, the coordinate of the joint `J:slide`", default=None, keys={
                      k: _J[k] for k in ("limits", "restitution", "spring", "damper",
                                         "friction")})


def keys_of(table: str, sub: str | None = None) -> tuple[str, ...]:
    """Allowed keys of ``table`` (or of its inline sub-table ``sub``)."""
    keys = SPEC[table].keys
    return tuple(keys[sub].keys) if sub else tuple(keys)


def default(table: str, key: str, sub: str | None = None) -> Any:
    """Default of a key (lists as tuples, as the mechanism stores them)."""
    k = SPEC[table].keys[sub].keys[key] if sub else SPEC[table].keys[key]
    return tuple(k.default) if isinstance(k.default, list) else k.default


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
        "description": "A planar or spatial constrained metamorphic mechanism (SI units "
                       "throughout).",
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
            "vector3": "[x, y, z]", "boolean": "true \\| false",
            "vector23": "[x, y] or [x, y, z]", "inertia": "number, or 3 or 6 numbers",
            "axis": "[x, y] or two strings", "guess": "[x, y, theta] or inline table",
            "numbers": "list of numbers",
            "pair": "two strings", "strings2": "two strings", "points": "list of [x, y]",
            "paths": "\"position\" or list of strings",
            "table": "inline table",
            "map": "table of name = " + {"vector2": "[x, y]", "vector3": "[x, y, z]",
                                         "vector23": "[x, y] or [x, y, z]"}.get(k.of, k.of),
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
