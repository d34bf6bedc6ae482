"""Reading the tables of a spatial model file (``space = "spatial"``) that differ from a
planar one's: bodies (3D points, inertia tensor, named axes, pose guess), the ground's
axes and the joints' axes and references. The loader (:mod:`.loader`) calls these with its
reader, which records every problem with its table and key instead of raising."""

from __future__ import annotations

import math
from typing import Any

from .mechanism import SLIDE_OF, Body
from .schema import keys_of

__all__ = ["is_cylindrical", "read_axes", "read_body", "read_joint_axes", "slides"]

#: the default gravity of a spatial mechanism, m/s^2 (z up)
GRAVITY = (0.0, 0.0, -9.81)


def read_axes(r: Any, t: str, d: dict) -> dict[str, tuple[float, ...]]:
    """The named directions ``axes = { name = [x, y, z] }`` of table ``t``."""
    axes_t = r.sub(t, d, "axes")
    return {k: r.vec(f"{t}.axes", axes_t, k, 3) for k in axes_t}


def read_body(r: Any, name: str, d: Any) -> Body:
    """A spatial body: mass, inertia (3 principal moments or 6 tensor entries, kg m^2),
    centroid, points and axes in the body frame, and a pose guess."""
    t = f"bodies.{name}"
    d = r.keys(t, d, keys_of("bodies"))
    if "inertia_about" in d:
        r.bad(t, "inertia_about", "planar only: give a spatial body's centroidal tensor")
    mass = r.num(t, d, "mass")
    raw = d.get("inertia")
    if isinstance(raw, list) and len(raw) in (3, 6):
        inertia: tuple[float, ...] = r.vec(t, d, "inertia", len(raw))
    else:
        r.bad(t, "inertia", "expected 3 principal moments [Ixx, Iyy, Izz] or 6 entries "
              "[Ixx, Iyy, Izz, Ixy, Ixz, Iyz] of the centroidal tensor in body axes "
              f"(kg m^2), got {raw!r:.60}" if raw is not None else "missing (expected "
              "[Ixx, Iyy, Izz] or [Ixx, Iyy, Izz, Ixy, Ixz, Iyz], kg m^2)")
        inertia = (math.nan,) * 3
    centroid = r.vec(t, d, "centroid", 3, default=(0.0, 0.0, 0.0))
    pts_t = r.sub(t, d, "points")
    points = {k: r.vec(f"{t}.points", pts_t, k, 3) for k in pts_t}
    guess = None
    if "guess" in d:
        keys = ("position", "rotation", "velocity", "angular_velocity")
        g = r.keys(f"{t}.guess", r.sub(t, d, "guess"), keys)
        guess = sum((r.vec(f"{t}.guess", g, k, 3, default=(0.0, 0.0, 0.0)) for k in keys), ())
    return Body(name, mass, inertia, centroid, points, guess, read_axes(r, t, d))


def _names2(r: Any, t: str, d: dict, key: str, what: str) -> tuple[str, str] | None:
    v = d.get(key)
    if v is None:
        return None
    if isinstance(v, list) and len(v) == 2 and all(isinstance(x, str) for x in v):
        return v[0], v[1]
    r.bad(t, key, f"expected two strings [\"body.{what}\", \"body.{what}\"], got {v!r:.60}")
    return None


def read_joint_axes(r: Any, t: str, d: dict, jtype: str
                    ) -> tuple[tuple[str, str] | None, tuple[str, str] | None]:
    """A spatial joint's ``axis`` (``axes``: a universal joint's arms) and ``reference``,
    each two ``"body.axis"`` names."""
    for key in ("angle",):
        if key in d:
            r.bad(t, key, "planar only (a spatial prismatic joint holds the angle between "
                  "its references at 0)")
    if jtype == "universal":
        if "axis" in d:
            r.bad(t, "axis", "a universal joint names its two arms as 'axes'")
        return _names2(r, t, d, "axes", "axis"), None
    if "axes" in d:
        r.bad(t, "axes", "only a universal joint has 'axes' (its arms); this joint's is "
              "'axis'")
    return _names2(r, t, d, "axis", "axis"), _names2(r, t, d, "reference", "axis")


#: what a cylindrical joint's ``slide`` table may hold: its second coordinate's parts
SLIDE_KEYS = ("limits", "restitution", "spring", "damper", "friction")


def is_cylindrical(d: Any) -> bool:
    """Whether a joint table (of the file, as parsed) is a cylindrical joint's."""
    return isinstance(d, dict) and d.get("type") == "cylindrical"


def slides(r: Any, joints: dict, spatial: bool) -> list[tuple[str, dict]]:
    """(joint, table) for the slide of each cylindrical joint: its ``slide`` sub-table's
    parts, with the joint's own connects and axes (read as a joint of type "slide")."""
    out = []
    for name, d in joints.items() if spatial else ():
        if not is_cylindrical(d):
            continue
        if SLIDE_OF.format(name) in joints:  # (it would be replaced by the slide, silently)
            r.bad(f"joints.{name}:slide", "", f"the slide of cylindrical joint '{name}' is "
                  f"written in joints.{name}.slide (limits, spring, ...), not as a table")
            continue
        sub = r.keys(f"joints.{name}.slide", r.sub(f"joints.{name}", d, "slide"), SLIDE_KEYS)
        out.append((name, {"type": "slide", **{k: d[k] for k in ("connects", "axis",
                                                                   "reference") if k in d},
                           **sub}))
    return out
