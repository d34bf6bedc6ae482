"""Checks of one joint of a mechanism description: its type, points, axis, limits,
spring, damper, friction, and a contact's curve (called by :func:`checks.validate`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..core.errors import Problem
from .curves import spline

GROUND = "ground"


JOINT_TYPES = ("revolute", "prismatic", "contact")


CURVES = ("circle", "line", "spline")


#: a circle's or a spline's sides, then a line's (where outside, inside read as left, right)
SIDES = ("outside", "inside", "left", "right")


def _finite(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def _check_ref(m: Any, table: str, key: str, ref: str, out: list[Problem]) -> None:
    if not isinstance(ref, str) or "." not in ref:
        out.append(Problem(table, key, f"expected 'body.point', got {ref!r}"))
        return
    body, pt = ref.split(".", 1)
    if body == GROUND:
        if pt not in m.ground:
            out.append(Problem(table, key, f"unknown ground point '{pt}' in {ref!r} "
                               f"(ground points: {', '.join(m.ground) or 'none'})"))
    elif body not in m.bodies:
        out.append(Problem(table, key, f"unknown body '{body}' in {ref!r} "
                           f"(bodies: {', '.join(m.bodies) or 'none'})"))
    elif pt not in m.bodies[body].points:
        out.append(Problem(table, key, f"body '{body}' has no point '{pt}' "
                           f"(its points: {', '.join(m.bodies[body].points) or 'none'})"))


def joint_problems(m: Any, t: str, j: Any) -> list[Problem]:
    """Every problem of joint ``j`` (table ``t``) of mechanism ``m``."""
    out: list[Problem] = []
    if j.type not in JOINT_TYPES:
        out.append(Problem(t, "type", f"expected one of {', '.join(JOINT_TYPES)}, "
                           f"got {j.type!r}"))
    _check_ref(m, t, "connects", j.first, out)
    _check_ref(m, t, "connects", j.second, out)
    if j.first_body == j.second_body:
        out.append(Problem(t, "connects", f"joins body '{j.first_body}' to itself"))
    if j.type == "prismatic" and not (all(_finite(a) for a in j.axis)
                                      and math.hypot(*j.axis) > 1e-12):
            out.append(Problem(t, "axis", f"expected a non-zero direction, got {j.axis}"))
    out += coordinate_parts_problems(t, j)
    if j.type == "contact":
        out += _contact_problems(t, j)
    elif j.curve is not None or j.unilateral or j.side != "outside":
        out.append(Problem(t, "curve", "only a contact joint has a curve, a side or "
                           "'unilateral'"))
    if j.friction is not None:
        out += _friction_problems(t, j)
    return out


def coordinate_parts_problems(t: str, j: Any) -> list[Problem]:
    """The parts on a joint's coordinate (either space): ordered limits, a restitution in
    [0, 1], a spring's stiffness and a damping >= 0."""
    out: list[Problem] = []
    if j.limits is not None:
        lo, up = j.limits.lower, j.limits.upper
        if lo is None and up is None:
            out.append(Problem(t, "limits", "give 'lower', 'upper' or both"))
        if lo is not None and up is not None and not lo < up:
            out.append(Problem(t, "limits", f"lower ({lo}) must be below upper ({up})"))
    if not (_finite(j.restitution) and 0.0 <= j.restitution <= 1.0):
        out.append(Problem(t, "restitution", f"expected a number in [0, 1], "
                           f"got {j.restitution}"))
    if j.spring is not None and not (_finite(j.spring.stiffness) and j.spring.stiffness >= 0):
        out.append(Problem(t, "spring.stiffness", "expected a stiffness >= 0, "
                           f"got {j.spring.stiffness}"))
    if j.damper is not None and not (_finite(j.damper.damping) and j.damper.damping >= 0):
        out.append(Problem(t, "damper.damping", f"expected a damping >= 0, "
                           f"got {j.damper.damping}"))
    return out


def _friction_problems(t: str, j) -> list[Problem]:
    """A joint's friction table: static >= kinetic >= 0, mu_static >= mu_kinetic >= 0,
    and a pin radius exactly where a revolute joint's levels grow with its reaction."""
    f, out = j.friction, []
    fs, fk = f.static, f.kinetic
    if not (_finite(fs) and _finite(fk) and fs >= fk >= 0):
        out.append(Problem(t, "friction", f"expected static >= kinetic >= 0 "
                           f"({'N' if j.type == 'prismatic' else 'N m'}), got "
                           f"static = {fs}, kinetic = {fk}"))
    ms, mk = f.mu_static, f.mu_kinetic
    if not (_finite(ms) and _finite(mk) and ms >= mk >= 0):
        out.append(Problem(t, "friction", f"expected mu_static >= mu_kinetic >= 0, got "
                           f"mu_static = {ms}, mu_kinetic = {mk}"))
    elif j.type in ("revolute", "cylindrical") and f.from_reaction and not (
            _finite(f.radius) and f.radius > 0):
        out.append(Problem(t, "friction.radius", "expected the pin radius > 0 (m): a "
                           "revolute joint's friction from its reaction is mu radius |F|, "
                           f"got radius = {f.radius}"))
    if j.type not in ("revolute", "cylindrical") and f.radius != 0.0:
        out.append(Problem(t, "friction.radius", f"a {j.type} joint's friction from its "
                           "reaction is mu |N|: it has no radius"))
    return out

def _spline_problems(t: str, j) -> list[Problem]:
    """A spline curve: at least 4 finite points; closed, counter-clockwise once around its
    origin and none at it; open, in increasing x, on a bilateral contact whose limits lie
    within the curve's ends."""
    c = j.curve
    if len(c.points) < 4:
        return [Problem(t, "curve.points", f"expected at least 4 points [x, y] (m), got "
                        f"{len(c.points)}")]
    bad = next((i for i, p in enumerate(c.points) if not all(_finite(x) for x in p)), None)
    if bad is not None:
        return [Problem(t, f"curve.points[{bad}]", f"expected finite coordinates (m), got "
                        f"{list(c.points[bad])}")]
    if not isinstance(c.closed, bool):
        return [Problem(t, "curve.closed", f"expected true or false, got {c.closed!r}")]
    if not c.closed:
        return _open_spline_problems(t, j)
    ang, rad = c.polar()
    if np.min(rad) <= 0.0:
        return [Problem(t, "curve.points", "a point lies at the curve's origin (the first "
                        "connect point); the points go around it")]
    if not (np.all(np.diff(ang) > 0.0) and ang[-2] - ang[0] < 2 * math.pi):
        return [Problem(t, "curve.points", "expected the points counter-clockwise once "
                        "around the curve's origin, each at a larger polar angle than the "
                        "one before")]
    return []


def _open_spline_problems(t: str, j) -> list[Problem]:
    """An open spline: x increasing; a bilateral contact (its ends are stops); limits, if
    any, within them."""
    c = j.curve
    if j.unilateral:
        return [Problem(t, "curve.closed", "an open curve is for a bilateral contact (a pin "
                        "in a slot) in this version: a point lifted off it could land beyond "
                        "its ends; a unilateral contact needs a closed curve, a circle or a "
                        "line")]
    if not np.all(np.diff([x for x, _ in c.points]) > 0.0):
        return [Problem(t, "curve.points", "expected an open curve's points in increasing "
                        "x (the curve is y(x) in its first body's frame)")]
    length = spline(c).length
    lim = j.limits
    if lim is not None and any(x is not None and _finite(x) and not 0.0 <= x <= length
                               for x in (lim.lower, lim.upper)):
        return [Problem(t, "limits", f"expected limits within the open curve's ends, 0 to "
                        f"{length:.9g} m of arc length from its first point, got "
                        f"lower = {lim.lower}, upper = {lim.upper}")]
    return []


def _contact_problems(t: str, j) -> list[Problem]:
    """A contact joint's curve, side and stops."""
    out: list[Problem] = []
    c = j.curve
    if c is None:
        out.append(Problem(t, "curve", "a contact joint needs its curve: { kind = \"circle\", "
                           "radius = R } or { kind = \"line\", direction = [x, y] }"))
    elif c.kind not in CURVES:
        out.append(Problem(t, "curve.kind", f"expected one of {', '.join(CURVES)}, "
                           f"got {c.kind!r}"))
    elif c.kind == "circle" and not (_finite(c.radius) and c.radius > 0):
        out.append(Problem(t, "curve.radius", f"expected a radius > 0 (m), got {c.radius}"))
    elif c.kind == "line" and not (all(_finite(a) for a in c.direction)
                                   and math.hypot(*c.direction) > 1e-12):
        out.append(Problem(t, "curve.direction", "expected a non-zero direction, got "
                           f"{c.direction}"))
    elif c.kind == "spline":
        out += _spline_problems(t, j)
    if j.side not in SIDES:
        out.append(Problem(t, "side", f"expected one of {', '.join(SIDES)}, got {j.side!r}"))
    elif j.side in ("left", "right") and c is not None and c.kind != "line":
        out.append(Problem(t, "side", f"'{j.side}' is a side of a line (of its direction); "
                           f"a {c.kind}'s sides are 'outside' and 'inside'"))
    if not isinstance(j.unilateral, bool):
        out.append(Problem(t, "unilateral", f"expected true or false, got {j.unilateral!r}"))
    if j.unilateral and j.limits is not None:
        out.append(Problem(t, "limits", "a unilateral contact's stop is its curve (it lands "
                           "on it); limits on the arc length need a bilateral contact"))
    return out




def gear_problems(m: Any, t: str, g: Any) -> list[Problem]:
    """A gear pair (table ``t``): two existing joints, revolute-revolute (an external
    mesh, ratio < 0, or an internal one, ratio > 0 and not 1) or revolute-prismatic, on
    one carrier, in a finite non-zero ratio."""
    out: list[Problem] = []
    if g.name in m.joints:
        out.append(Problem(t, "", "a gear pair and a joint share this name"))
    types = []
    for ref in (g.first, g.second):
        j = m.joints.get(ref)
        if j is None:
            out.append(Problem(t, "connects", f"unknown joint '{ref}' (a gear pair connects "
                               f"two joints; joints: {', '.join(m.joints) or 'none'})"))
        elif j.type not in ("revolute", "prismatic"):
            out.append(Problem(t, "connects", f"joint '{ref}' is a {j.type} joint; a gear "
                               "pair connects revolute or prismatic joints"))
        else:
            types.append(j.type)
    if len(types) < 2:
        return out
    if g.first == g.second:
        out.append(Problem(t, "connects", "connects a joint to itself"))
    first, second = m.joints[g.first], m.joints[g.second]
    for j in (first, second):
        if j.second_body == GROUND:
            out.append(Problem(t, "connects", f"joint '{j.name}' has the ground as its second "
                               "body: a gear pair's joints carry their gears second"))
    if types == ["prismatic", "prismatic"]:
        out.append(Problem(t, "connects", "two prismatic joints: a gear pair needs a "
                           "revolute joint (a pinion) on at least one side"))
    if first.first_body != second.first_body:
        out.append(Problem(t, "connects", f"joints '{g.first}' and '{g.second}' hold their "
                           f"gears on different bodies ('{first.first_body}', "
                           f"'{second.first_body}'): both must be on one carrier (or the "
                           "ground), their first body"))
    if not (_finite(g.ratio) and g.ratio != 0.0):
        out.append(Problem(t, "ratio", f"expected a finite non-zero ratio, got {g.ratio}"))
    elif types == ["revolute", "revolute"] and g.ratio == 1.0:
        out.append(Problem(t, "ratio", "expected a ratio other than 1 (negative: an external "
                           "mesh; positive: an internal one, whose gears of pitch radii "
                           "r_a and r_b have ratio r_a / r_b; 1 would make them one size)"))
    if not (_finite(g.pressure_angle) and 0.0 <= g.pressure_angle < 1.2):
        out.append(Problem(t, "pressure_angle", "expected an angle in [0, 1.2) rad, got "
                           f"{g.pressure_angle}"))
    if not _finite(g.offset):
        out.append(Problem(t, "offset", f"expected a finite number, got {g.offset}"))
    return out
