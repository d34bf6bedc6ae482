"""Reading mechanism TOML files into :class:`~cmm_dae.description.mechanism.Mechanism`.

Every problem in a file is collected (wrong type, unknown key with a "did you mean",
missing key, NaN, bad reference, ...) and raised once as a :class:`ModelError` that names
the file, the table and the key. Nothing in a file is evaluated as Python.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..core.errors import ModelError, Problem
from . import schema
from .checks import JOINT_TYPES
from .higher_pairs import contact_keys, is_gear, read_gear
from .mechanism import (
    LAWS,
    MOTIONS,
    Body,
    Damper,
    Driver,
    Element,
    Friction,
    Initial,
    Joint,
    Law,
    Limits,
    Load,
    Mechanism,
    Spring,
    Zone,
    validate,
)
from .reader import Reader as _Reader
from .reader import short as _short
from .records import SLIDE_OF, slide_base
from .schema import SPEC, default, keys_of
from .spatial import SPACES, SPATIAL_TYPES
from .spatial_reader import (
    GRAVITY,
    is_cylindrical,
    read_axes,
    read_body,
    read_joint_axes,
    slides,
)

#: Largest model file read, bytes (a mechanism description is a few kB of text).
MAX_FILE_BYTES = 16 * 2**20

# Allowed keys and defaults come from the one description of the format (schema.SPEC).
TOP_KEYS = tuple(SPEC)
MECH_KEYS = keys_of("mechanism")
BODY_KEYS = keys_of("bodies")
JOINT_KEYS = keys_of("joints")
LAW_KEYS = schema.LAW_KEYS
LOAD_KEYS = tuple(k for k in keys_of("loads") if k not in
                  {x for ks in LAW_KEYS.values() for x in ks})
ELEMENT_KEYS = keys_of("elements")
DRIVER_KEYS = {m: ("motion",) + ks for m, ks in schema.MOTION_KEYS.items()}


def load(path: str | Path) -> Mechanism:
    """Load a mechanism from a TOML file.

    Parameters
    ----------
    path : str or Path
        The model file.

    Returns
    -------
    Mechanism

    Raises
    ------
    ModelError
        Listing every problem of the file, each with its table and key.
    """
    path = Path(path)
    src = str(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ModelError(Problem("", "", f"the file has {size} bytes; a model file is "
                                     f"text of at most {MAX_FILE_BYTES} bytes"), src)
        raw = path.read_bytes()
    except OSError as e:
        raise ModelError(Problem("", "", f"cannot read the file: {e.strerror or e}"),
                         src) from None
    if b"\x00" in raw:
        raise ModelError(Problem("", "", "this is a binary file, not a TOML model file"),
                         src)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ModelError(Problem("", "", f"not UTF-8 text (byte {e.start}: "
                                 f"{raw[e.start:e.start + 1]!r}); save the model file as "
                                 "UTF-8"), src) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ModelError(Problem("", "", f"TOML syntax error: {e}"), src) from None
    except RecursionError:
        raise ModelError(Problem("", "", "arrays or tables nested too deeply to read"),
                         src) from None
    return from_dict(data, source=src)


def from_dict(data: dict, *, source: str | None = None) -> Mechanism:
    """Build a mechanism from the parsed TOML structure (see :func:`load`)."""
    if not isinstance(data, Mapping):
        raise ModelError(Problem("", "", f"expected a table of tables (a parsed model file), "
                                 f"got {type(data).__name__}"), source)
    try:
        return _from_dict(data, source)
    except RecursionError:
        raise ModelError(Problem("", "", "values nested too deeply (a model file holds "
                                 "numbers, short lists and tables)"), source) from None


def _from_dict(data: dict, source: str | None) -> Mechanism:
    r = _Reader()
    r.keys("", data, TOP_KEYS)
    mech = r.keys("mechanism", r.sub("", data, "mechanism"), MECH_KEYS)
    name = r.string("mechanism", mech, "name", default=Path(source).stem if source else "mechanism")
    space = r.choice("mechanism", mech, "space", SPACES) if "space" in mech else "planar"
    if space is None:  # every point would be read with the wrong number of coordinates
        raise ModelError(r.problems, source)
    spatial, dim = space == "spatial", 3 if space == "spatial" else 2
    gravity = r.vec("mechanism", mech, "gravity", dim, default=GRAVITY if spatial
                    else default("mechanism", "gravity"))

    ground_t = r.keys("ground", r.sub("", data, "ground"), keys_of("ground"))
    ground = {}
    for k, v in r.sub("ground", ground_t, "points").items():
        ground[k] = r.vec("ground.points", {k: v}, k, dim)
    gaxes = read_axes(r, "ground", ground_t) if spatial else _planar(r, "ground", ground_t)

    bodies = [read_body(r, k, v) if spatial else _body(r, k, v)
              for k, v in r.sub("", data, "bodies").items()]
    jt = r.sub("", data, "joints")
    added = slides(r, jt, spatial)  # (a table of one of their names: refused there)
    joints = [_joint(r, k, v, spatial) for k, v in jt.items() if not is_gear(v)
              and not (spatial and is_cylindrical(jt.get(slide_base(k))))]
    joints += [_joint(r, SLIDE_OF.format(k), s, spatial) for k, s in added]
    gears = [read_gear(r, k, v) for k, v in jt.items() if is_gear(v)]
    drivers = [_driver(r, k, v) for k, v in r.sub("", data, "drivers").items()]
    loads = [_load(r, k, v, dim) for k, v in r.sub("", data, "loads").items()]
    elements = [_element(r, k, v) for k, v in r.sub("", data, "elements").items()]

    ini = r.keys("initial", r.sub("", data, "initial"), keys_of("initial"))
    eq: tuple[str, ...] | str = ()
    if "equilibrium" in ini:
        raw = ini["equilibrium"]
        if isinstance(raw, str):
            eq = raw
        elif isinstance(raw, list) and all(isinstance(x, str) for x in raw):
            eq = tuple(raw)
        else:
            r.bad("initial", "equilibrium", f"expected \"position\" or a list of parameter "
                  f"paths, got {_short(raw)}")
    ij = {k: r._num("initial", f"joints.{k}", v)
          for k, v in r.sub("initial", ini, "joints").items()}
    iv = {k: r._num("initial", f"velocities.{k}", v)
          for k, v in r.sub("initial", ini, "velocities").items()}

    problems = list(r.problems)
    try:
        # Bad values were replaced by NaN above, so validation would repeat them: build
        # without validating, then report only what the reader did not already say.
        m = Mechanism(name=name, bodies=bodies, joints=joints, ground=ground, drivers=drivers,
                      initial=Initial(ij, iv, eq), gravity=gravity, source=source, loads=loads,
                      elements=elements, gears=gears, space=space, axes=gaxes, check=False)
        seen = {(p.table, p.key.split("[")[0]) for p in problems}
        problems += [p for p in validate(m) if (p.table, p.key) not in seen
                     and (p.table, p.key.split(".")[0]) not in seen
                     and not (problems and "nan" in p.message)]  # (a NaN put in above)
    except Exception as e:  # pragma: no cover - defensive: never a deep traceback on bad input
        problems.append(Problem("", "", f"could not build the mechanism: {e}"))
    if problems:
        raise ModelError(problems, source)
    return m


def _planar(r: _Reader, t: str, d: dict, keys: tuple[str, ...] = ("axes",)) -> dict:
    """Keys of the spatial format in a planar table: each is a problem."""
    for k in keys:
        if k in d:
            r.bad(t, k, "spatial mechanisms only (set [mechanism] space = \"spatial\")")
    return {}


def _body(r: _Reader, name: str, d: Any) -> Body:
    t = f"bodies.{name}"
    d = r.keys(t, d, BODY_KEYS)
    _planar(r, t, d)
    mass = r.num(t, d, "mass")
    inertia = r.num(t, d, "inertia")
    centroid = r.vec(t, d, "centroid", 2, default=default("bodies", "centroid"))
    pts_t = r.sub(t, d, "points")
    points = {k: r.vec(f"{t}.points", pts_t, k, 2) for k in pts_t}
    guess = r.vec(t, d, "guess", 3, default=None)
    about = r.string(t, d, "inertia_about", default=None)
    if about is not None:
        if about not in points:
            r.bad(t, "inertia_about", f"unknown point '{about}' (points: "
                  f"{', '.join(points) or 'none'})")
        else:
            p = points[about]
            inertia_c = inertia - mass * ((p[0] - centroid[0]) ** 2 + (p[1] - centroid[1]) ** 2)
            if math.isfinite(inertia_c) and inertia_c < 0:
                r.bad(t, "inertia", f"{inertia} kg m^2 about '{about}' leaves a centroidal "
                      f"inertia of {inertia_c:.6g} < 0 (parallel-axis theorem)")
                inertia_c = math.nan
            inertia = inertia_c
    return Body(name, mass, inertia, centroid, points, guess)


def _joint(r: _Reader, name: str, d: Any, spatial: bool = False) -> Joint:
    t = f"joints.{name}"
    d = r.keys(t, d, JOINT_KEYS)
    jtype = r.string(t, d, "type")
    types = SPATIAL_TYPES if spatial else JOINT_TYPES
    if jtype and jtype not in types and not (spatial and slide_base(name)):
        named = types if spatial else (*types, "gear")  # (a gear pair: a planar joint table)
        r.bad(t, "type", f"expected one of {', '.join(map(repr, named))}, got {jtype!r}")
    first, second = _connects(r, t, d)
    curve, side, unilateral = contact_keys(r, t, d, jtype, spatial)
    axes = reference = None
    if "slide" in d and jtype != "cylindrical":
        r.bad(t, "slide", "only a spatial cylindrical joint has a slide")
    if spatial:
        axes, reference = read_joint_axes(r, t, d, jtype)
        axis, angle = default("joints", "axis"), 0.0
    else:
        _planar(r, t, d, ("axes", "reference"))
        axis = r.vec(t, d, "axis", 2, default=default("joints", "axis"))
        angle = r.num(t, d, "angle", default=default("joints", "angle"))
    limits = None
    if "limits" in d:
        lt = r.keys(f"{t}.limits", r.sub(t, d, "limits"), keys_of("joints", "limits"))
        limits = Limits(r.num(f"{t}.limits", lt, "lower", None),
                        r.num(f"{t}.limits", lt, "upper", None))
    restitution = r.num(t, d, "restitution", default=default("joints", "restitution"))
    ends = curve is not None and curve.kind == "spline" and curve.closed is False  # stops
    if "restitution" in d and limits is None and not unilateral and not ends:
        r.bad(t, "restitution", "a restitution needs 'limits' (or a unilateral contact, or "
              "an open curve's ends) to act on")
    spring = damper = None
    if "spring" in d:
        st = r.keys(f"{t}.spring", r.sub(t, d, "spring"),
                    keys_of("joints", "spring"))
        spring = Spring(r.num(f"{t}.spring", st, "stiffness"),
                        r.num(f"{t}.spring", st, "rest",
                             default("joints", "rest", "spring")))
    if "damper" in d:
        dt = r.keys(f"{t}.damper", r.sub(t, d, "damper"), keys_of("joints", "damper"))
        damper = Damper(r.num(f"{t}.damper", dt, "damping"))
    friction = None
    if "friction" in d:
        ft = r.keys(f"{t}.friction", r.sub(t, d, "friction"),
                    keys_of("joints", "friction"))
        friction = Friction(*(r.num(f"{t}.friction", ft, k,
                                    default("joints", k, "friction"))
                              for k in ("static", "kinetic", "mu_static", "mu_kinetic",
                                        "radius")))
    return Joint(name, jtype, first, second, axis, angle, limits, restitution, spring, damper,
                 friction, curve, side, unilateral, axes, reference)


def _connects(r: _Reader, t: str, d: dict) -> tuple[str, str]:
    conn = d.get("connects")
    if conn is None:
        r.bad(t, "connects", "missing (expected [\"body.point\", \"body.point\"])")
    elif not (isinstance(conn, list) and len(conn) == 2 and all(isinstance(c, str)
                                                                for c in conn)):
        r.bad(t, "connects", f"expected two strings \"body.point\", got {_short(conn)}")
    else:
        return conn[0], conn[1]
    return "?.?", "?.?"


def _law(r: _Reader, t: str, d: dict) -> Law:
    kind = r.choice(t, d, "law", LAWS)
    if kind is None:
        return Law("constant")
    r.keys(t, d, LOAD_KEYS + LAW_KEYS[kind])
    if kind == "constant":
        return Law(kind, value=r.num(t, d, "value"))
    if kind == "polynomial":
        return Law(kind, coefficients=r.vec(t, d, "coefficients", None))
    if kind == "harmonic":
        return Law(kind, mean=r.num(t, d, "mean", 0.0), amplitude=r.num(t, d, "amplitude"),
                   frequency=r.num(t, d, "frequency"), phase=r.num(t, d, "phase", 0.0))
    if kind == "table":
        return Law(kind, times=r.vec(t, d, "times", None), values=r.vec(t, d, "values", None))
    return Law(kind, stall=r.num(t, d, "stall"), no_load_speed=r.num(t, d, "no_load_speed"))


def _load(r: _Reader, name: str, d: Any, dim: int = 2) -> Load:
    t = f"loads.{name}"
    if not isinstance(d, dict):
        r.bad(t, "", f"expected a table, got {_short(d)}")
        return Load(name, Law())
    law = _law(r, t, d)
    zone = None
    if "zone" in d:
        zt = r.keys(f"{t}.zone", r.sub(t, d, "zone"), keys_of("loads", "zone"))
        zone = Zone(r.string(f"{t}.zone", zt, "joint", None),
                    r.num(f"{t}.zone", zt, "lower", None), r.num(f"{t}.zone", zt, "upper", None))
    return Load(name, law, joint=r.string(t, d, "joint", None), body=r.string(t, d, "body", None),
                point=r.string(t, d, "point", None),
                direction=r.vec(t, d, "direction", dim, default=None),
                frame=r.string(t, d, "frame", default("loads", "frame")), zone=zone)


def _element(r: _Reader, name: str, d: Any) -> Element:
    t = f"elements.{name}"
    d = r.keys(t, d, ELEMENT_KEYS)
    first, second = _connects(r, t, d)
    vals = [r.num(t, d, k, default("elements", k))
            for k in ("stiffness", "rest", "damping", "preload")]
    return Element(name, first, second, *vals)


def _driver(r: _Reader, name: str, d: Any) -> Driver:
    t = f"drivers.{name}"
    if not isinstance(d, dict):
        r.bad(t, "", f"expected a table, got {_short(d)}")
        return Driver(name)
    motion = r.choice(t, d, "motion", MOTIONS)
    if motion is None:
        return Driver(name, "constant_speed")
    r.keys(t, d, DRIVER_KEYS[motion])
    if motion == "constant_speed":
        return Driver(name, motion, initial=r.num(t, d, "initial"), speed=r.num(t, d, "speed"))
    if motion == "polynomial":
        return Driver(name, motion, coefficients=r.vec(t, d, "coefficients", None))
    if motion == "harmonic":
        return Driver(name, motion, initial=r.num(t, d, "initial"),
                      amplitude=r.num(t, d, "amplitude"), frequency=r.num(t, d, "frequency"),
                      phase=r.num(t, d, "phase", 0.0))
    return Driver(name, motion, times=r.vec(t, d, "times", None),
                  values=r.vec(t, d, "values", None))
