"""Spatial mechanisms (``space = "spatial"``): the geometry of a body's frame and
inertia, and the checks a spatial description needs beyond the planar ones.

A spatial body is carried by *natural coordinates*: its centroid and its three principal
axes of inertia as unit vectors in global axes (:mod:`cmm_dae.equations.spatial`). This
module gives what that needs from the description: the principal axes and moments of an
inertia tensor (:func:`principal`), rotation vectors and quaternions
(:func:`rotation`, :func:`quaternion`), and every problem of a spatial file
(:func:`problems`), each naming its table and key.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..core.errors import Problem
from .joint_checks import (
    GROUND,
    _check_ref,
    _finite,
    _friction_problems,
    coordinate_parts_problems,
)
from .records import slide_base

__all__ = ["SPACES", "SPATIAL_TYPES", "centre", "principal", "problems", "quaternion",
           "rotation"]

#: the values of ``[mechanism] space``
SPACES = ("planar", "spatial")
#: joint types of a spatial mechanism
SPATIAL_TYPES = ("revolute", "prismatic", "cylindrical", "spherical", "universal")
#: joint types with a coordinate (limits, springs, dampers, friction, drivers, loads): a
#: cylindrical joint's angle, its slide's displacement (the joint "J:slide")
WITH_COORDINATE = ("revolute", "prismatic", "cylindrical", "slide")
#: the smallest principal moment's share of the largest a body may have, and the smallest
#: share of the tensor's trace each pseudo-inertia (I2 + I3 - I1) / 2 may have: below, the
#: rotation about that axis has no inertia to speak of (a thin rod about its own axis) and
#: the accelerations are undetermined to round-off
MIN_SHARE = 1e-9


def centre(j: Any) -> float:
    """The middle of a spatial revolute (or cylindrical) joint's coordinate range, rad: its
    coordinate is the angle within pi of it, so it jumps by 2 pi only half a turn away
    (no function of the bodies' coordinates alone can count turns). The middle of its two
    limits; else a quarter turn past its one limit (it may swing 1.5 pi away from the
    stop, and nothing can sink half a turn into it); else its spring's rest; else 0."""
    lim = j.limits
    if lim is not None and lim.lower is not None and lim.upper is not None:
        return (lim.lower + lim.upper) / 2
    if lim is not None and lim.lower is not None:
        return lim.lower + math.pi / 2
    if lim is not None and lim.upper is not None:
        return lim.upper - math.pi / 2
    if j.spring is not None and isinstance(j.spring.rest, float):
        return j.spring.rest
    return 0.0


def tensor(inertia: tuple[float, ...]) -> np.ndarray:
    """The 3 x 3 centroidal inertia tensor (kg m^2) of three principal moments or six
    entries ``(Ixx, Iyy, Izz, Ixy, Ixz, Iyz)``."""
    v = [float(x) for x in inertia]
    if len(v) == 3:
        return np.diag(v)
    xx, yy, zz, xy, xz, yz = v
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def principal(inertia: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The principal axes ``R`` (3 x 3, columns in the body frame, a right-handed frame)
    and moments (3,) of a body's inertia. Three principal moments keep the body's own
    axes (``R`` the identity), so they may be symbols (sensitivities)."""
    if len(inertia) == 3:
        return np.eye(3), np.asarray(inertia, dtype=object)
    w, R = np.linalg.eigh(tensor(inertia))
    if np.linalg.det(R) < 0.0:
        R[:, 2] = -R[:, 2]
    return R, w


def rotation(rv) -> np.ndarray:
    """The rotation matrix of a rotation vector ``rv`` (axis times angle, rad)."""
    rv = np.asarray(rv, float)
    th = float(np.linalg.norm(rv))
    if th < 1e-300:
        return np.eye(3)
    k = rv / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * (K @ K)


def quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(w, x, y, z)`` (..., 4) of rotation matrices ``R`` (..., 3, 3),
    with ``w >= 0`` (Shepperd's method: the largest of the four squares first, so no
    division by a small number)."""
    R = np.asarray(R, float)
    tr = np.trace(R, axis1=-2, axis2=-1)
    d = np.stack([tr, R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]], axis=-1)
    k = np.argmax(d, axis=-1)
    q = np.empty(R.shape[:-2] + (4,))
    m = lambda i, j: R[..., i, j]  # noqa: E731 - a short alias for the formulas below
    four = [np.stack([1 + tr, m(2, 1) - m(1, 2), m(0, 2) - m(2, 0), m(1, 0) - m(0, 1)], -1),
            np.stack([m(2, 1) - m(1, 2), 1 + 2 * m(0, 0) - tr, m(0, 1) + m(1, 0),
                      m(0, 2) + m(2, 0)], -1),
            np.stack([m(0, 2) - m(2, 0), m(0, 1) + m(1, 0), 1 + 2 * m(1, 1) - tr,
                      m(1, 2) + m(2, 1)], -1),
            np.stack([m(1, 0) - m(0, 1), m(0, 2) + m(2, 0), m(1, 2) + m(2, 1),
                      1 + 2 * m(2, 2) - tr], -1)]
    for i in range(4):
        sel = k == i
        q[sel] = four[i][sel]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def _vec3(x: Any) -> bool:
    return isinstance(x, tuple | list) and len(x) == 3 and all(_finite(v) for v in x)


def _body_problems(name: str, b: Any) -> list[Problem]:
    t, out = f"bodies.{name}", []
    if name == GROUND:
        out.append(Problem(t, "", "'ground' is reserved for the frame"))
    if not (_finite(b.mass) and b.mass > 0):
        out.append(Problem(t, "mass", f"expected a positive mass in kg, got {b.mass}"))
    inertia = b.inertia if isinstance(b.inertia, tuple) else (b.inertia,)
    if len(inertia) not in (3, 6) or not all(_finite(x) for x in inertia):
        out.append(Problem(t, "inertia", "expected 3 principal moments [Ixx, Iyy, Izz] or 6 "
                           "entries [Ixx, Iyy, Izz, Ixy, Ixz, Iyz] of the centroidal tensor "
                           f"in body axes (kg m^2), got {b.inertia}"))
    else:
        w = np.linalg.eigvalsh(tensor(inertia))
        pseudo = w.sum() / 2.0 - w  # (I2 + I3 - I1) / 2: the axes' second moments
        if not w[0] > MIN_SHARE * abs(w[-1]) or w[0] <= 0.0:
            out.append(Problem(t, "inertia", "the tensor is not positive definite "
                               f"(principal moments {', '.join(f'{x:.6g}' for x in w)} "
                               "kg m^2): every rigid body has three positive moments"))
        elif not pseudo.min() > MIN_SHARE * w.sum():
            out.append(Problem(t, "inertia", "a principal moment is not below the sum of "
                               f"the other two (moments {', '.join(f'{x:.6g}' for x in w)} "
                               "kg m^2): only a body of no thickness has it (a flat plate, "
                               "a thin rod), which leaves a rotation without inertia; give "
                               "it its thickness"))
    if not _vec3(b.centroid):
        out.append(Problem(t, "centroid", f"expected [x, y, z] (m), got {list(b.centroid)}"))
    for k, p in b.points.items():
        if not _vec3(p):
            out.append(Problem(t, f"points.{k}", f"expected [x, y, z] (m), got {list(p)}"))
    out += _axes_problems(t, b.axes)
    if b.guess is not None and not (len(b.guess) in (6, 12)
                                    and all(_finite(x) for x in b.guess)):
        out.append(Problem(t, "guess", "expected { position = [x, y, z], rotation = "
                           "[rx, ry, rz], velocity = [vx, vy, vz], angular_velocity = "
                           f"[wx, wy, wz] }} (m, rad, m/s, rad/s), got {b.guess}"))
    return out


def _axes_problems(t: str, axes: Any) -> list[Problem]:
    out = []
    for k, a in axes.items():
        if not _vec3(a) or not math.hypot(*a) > 1e-12:
            out.append(Problem(t, f"axes.{k}", f"expected a non-zero direction [x, y, z], "
                               f"got {list(a)}"))
    return out


def _axis_ref(m: Any, t: str, key: str, ref: Any, out: list[Problem]) -> np.ndarray | None:
    """The direction ``"body.axis"`` (body frame, normalised), or None with the problem."""
    if not isinstance(ref, str) or "." not in ref:
        out.append(Problem(t, key, f"expected 'body.axis', got {ref!r}"))
        return None
    body, ax = ref.split(".", 1)
    axes = m.axes if body == GROUND else m.bodies[body].axes if body in m.bodies else None
    if axes is None:
        out.append(Problem(t, key, f"unknown body '{body}' in {ref!r}"))
        return None
    if ax not in axes:
        out.append(Problem(t, key, f"{'the ground' if body == GROUND else f'body {body!r}'}"
                           f" has no axis '{ax}' (its axes: {', '.join(axes) or 'none'})"))
        return None
    a = np.asarray(axes[ax], float)
    n = float(np.linalg.norm(a)) if _vec3(axes[ax]) else 0.0
    return a / n if n > 1e-12 else None


def _joint_problems(m: Any, name: str, j: Any) -> list[Problem]:
    t, out = f"joints.{name}", []
    if j.type == "slide":
        base = m.joints.get(slide_base(name))
        if base is None or base.type != "cylindrical" or (base.first, base.second) != \
                (j.first, j.second):
            return [Problem(t, "type", "a slide is the second coordinate of a cylindrical "
                            "joint J, the joint 'J:slide' with J's connects")]
        return _coordinate_problems(t, j)
    if j.type not in SPATIAL_TYPES:
        why = " (a planar higher pair: not yet in space)" if j.type in ("contact", "gear") \
            else ""
        out.append(Problem(t, "type", f"expected one of {', '.join(SPATIAL_TYPES)} in a "
                           f"spatial mechanism, got {j.type!r}{why}"))
        return out
    _check_ref(m, t, "connects", j.first, out)
    _check_ref(m, t, "connects", j.second, out)
    if j.first_body == j.second_body:
        out.append(Problem(t, "connects", f"joins body '{j.first_body}' to itself"))
    bodies = (j.first_body, j.second_body)
    known = all(b == GROUND or b in m.bodies for b in bodies)
    if j.type == "spherical":
        if j.axes is not None or j.reference is not None:
            out.append(Problem(t, "axis", "a spherical joint has no axis or reference"))
    elif j.axes is None:
        key = "axes" if j.type == "universal" else "axis"
        out.append(Problem(t, key, "missing: one named axis of each body, [\"body.axis\", "
                           "\"body.axis\"]" + (" (the two arms)" if key == "axes" else "")))
    elif known:
        key = "axes" if j.type == "universal" else "axis"
        dirs = [_axis_ref(m, t, key, a, out) for a in j.axes]
        for a, b in zip(j.axes, bodies, strict=True):
            if isinstance(a, str) and a.split(".", 1)[0] != b:
                out.append(Problem(t, key, f"{a!r} is not an axis of body '{b}' (one axis of "
                                   "each body the joint connects, in the order of connects)"))
        if j.type == "universal":
            out += _arms_problems(m, t, bodies, dirs)
        else:
            out += _reference_problems(m, t, j, bodies, dirs)
    return out + _coordinate_problems(t, j)


def _coordinate_problems(t: str, j: Any) -> list[Problem]:
    """The parts on a joint's coordinate: none without one; ordered limits."""
    out: list[Problem] = []
    if j.type not in WITH_COORDINATE:
        for key in ("limits", "spring", "damper", "friction"):
            if getattr(j, key) is not None:
                out.append(Problem(t, key, f"a {j.type} joint has no coordinate for "
                                   f"{key} to act on (revolute, prismatic and cylindrical "
                                   "joints have)"))
        if j.restitution != 0.0:
            out.append(Problem(t, "restitution", f"a {j.type} joint has no stops"))
        return out
    out += coordinate_parts_problems(t, j)
    if j.type in ("revolute", "cylindrical") and j.limits is not None:
        mid = centre(j)
        if any(x is not None and _finite(x) and not mid - math.pi < x < mid + math.pi
               for x in (j.limits.lower, j.limits.upper)):
            out.append(Problem(t, "limits", "a spatial revolute joint's angle is measured "
                               f"within pi of the middle of its stops, {mid:.6g} rad: "
                               "they must lie less than a turn apart"))
    if j.type in ("revolute", "cylindrical") and j.spring is not None and _finite(
            j.spring.rest) and not centre(j) - math.pi < j.spring.rest < centre(j) + math.pi:
        out.append(Problem(t, "spring.rest", "a spatial revolute joint's angle is measured "
                           f"within pi of {centre(j):.6g} rad (the middle of its range): "
                           f"a rest there, got {j.spring.rest}"))
    if j.friction is not None:
        out += _friction_problems(t, j)
    if j.curve is not None or j.unilateral:
        out.append(Problem(t, "curve", "contacts are planar only so far"))
    return out


def _reference_problems(m, t, j, bodies, dirs) -> list[Problem]:
    """A revolute or prismatic joint's references: named, one of each body, across the
    axis (default: each body's axis ``x``)."""
    out: list[Problem] = []
    refs = j.reference if j.reference is not None else \
        tuple(f"{b}.x" for b in bodies)
    for r, b, a in zip(refs, bodies, dirs, strict=True):
        d = _axis_ref(m, t, "reference", r, out)
        if isinstance(r, str) and r.split(".", 1)[0] != b:
            out.append(Problem(t, "reference", f"{r!r} is not a direction of body '{b}'"))
        elif d is not None and a is not None and abs(float(d @ a)) > 1.0 - 1e-6:
            out.append(Problem(t, "reference", f"{r!r} is parallel to the joint's axis: the "
                               "reference must lie across it (its angle about the axis is "
                               "the coordinate)"))
    return out


def _arms_problems(m, t, bodies, dirs) -> list[Problem]:
    """A universal joint's arms: not parallel where both bodies' guessed poses say."""
    if any(d is None for d in dirs):
        return []
    glob = []
    for b, d in zip(bodies, dirs, strict=True):
        if b == GROUND:
            glob.append(d)
            continue
        g = m.bodies[b].guess
        if g is None or len(g) not in (6, 12):
            return []
        glob.append(rotation(g[3:6]) @ d)
    if abs(float(glob[0] @ glob[1])) > 1.0 - 1e-6:
        return [Problem(t, "axes", "the two arms are parallel at the bodies' guessed poses: "
                        "a universal joint holds them perpendicular (name arms across "
                        "each other, or correct the guesses)")]
    return []


def problems(m: Any) -> list[Problem]:
    """Every problem of a spatial mechanism's gravity, ground, bodies and joints (the
    tables whose form differs from the plane's; the rest is checked as in the plane)."""
    out: list[Problem] = []
    if not _vec3(m.gravity):
        out.append(Problem("mechanism", "gravity", "expected [gx, gy, gz] (m/s^2), got "
                           f"{list(m.gravity)}"))
    for k, p in m.ground.items():
        if not _vec3(p):
            out.append(Problem("ground", f"points.{k}", f"expected [x, y, z] (m), got "
                               f"{list(p)}"))
    out += _axes_problems("ground", m.axes)
    for name, b in m.bodies.items():
        out += _body_problems(name, b)
    for name, j in m.joints.items():
        out += _joint_problems(m, name, j)
    if m.gears:
        out.append(Problem(f"joints.{next(iter(m.gears))}", "type", "gear pairs are planar "
                           "only so far"))
    for name, ld in m.loads.items():
        d = ld.direction
        if d is not None and not (_vec3(d) and math.hypot(*d) > 1e-12):
            out.append(Problem(f"loads.{name}", "direction", "expected a non-zero direction "
                               f"[x, y, z], got {d}"))
        elif ld.joint is None and d is None and ld.body is not None:
            out.append(Problem(f"loads.{name}", "direction", "a force or moment on a body "
                               "of a spatial mechanism needs its direction [x, y, z]"))
        if ld.joint is not None and ld.joint in m.joints \
                and m.joints[ld.joint].type not in WITH_COORDINATE:
            out.append(Problem(f"loads.{name}", "joint", f"joint '{ld.joint}' is "
                               f"{m.joints[ld.joint].type}: it has no coordinate to load"))
    for name, val in m.initial.joints.items():  # within pi of the angle's middle
        j = m.joints.get(name)
        if j is not None and j.type in ("revolute", "cylindrical") and _finite(val) and \
                not centre(j) - math.pi < val <= centre(j) + math.pi:
            out.append(Problem("initial", f"joints.{name}", f"{val} rad lies more than pi "
                               f"from {centre(j):.6g} rad, the middle of the joint's range, "
                               "where its angle is measured: give the same position within "
                               "it (2 pi less or more)"))
    for name in m.drivers:
        if name in m.joints and m.joints[name].type not in WITH_COORDINATE:
            out.append(Problem(f"drivers.{name}", "", f"joint '{name}' is "
                               f"{m.joints[name].type}: it has no coordinate to drive"))
    return out
