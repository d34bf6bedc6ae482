"""Reading the higher pairs of a model file for :mod:`.loader`: a contact joint's own keys
(its curve, side and ``unilateral``) and a gear pair (``type = "gear"``)."""

from __future__ import annotations

from typing import Any

from .checks import CURVES, SIDES
from .mechanism import Curve, Gear
from .schema import default, keys_of


def contact_keys(r: Any, t: str, d: dict, jtype: str, spatial: bool = False
                 ) -> tuple[Curve | None, str, bool]:
    """``(curve, side, unilateral)`` of joint table ``t`` (``d``) read with the loader's
    reader ``r``, each problem noted there; keys only a contact may have refused on the
    other joint types (and a planar prismatic joint's keys on the others)."""
    if jtype in ("revolute", "contact") and not spatial:
        for k in ("axis", "angle"):
            if k in d:
                r.bad(t, k, "only a prismatic joint has this key")
    if jtype != "contact":
        for k in ("curve", "side", "unilateral"):
            if k in d:
                r.bad(t, k, "only a contact joint has this key")
    for k in ("ratio", "pressure_angle", "offset"):
        if k in d:
            r.bad(t, k, "only a gear pair (type = \"gear\") has this key")
    curve = None
    if "curve" in d:
        ct = r.keys(f"{t}.curve", r.sub(t, d, "curve"), keys_of("joints", "curve"))
        pts = ct.get("points", [])
        if not (isinstance(pts, list) and all(
                isinstance(x, list) and len(x) == 2 and all(
                    isinstance(c, int | float) and not isinstance(c, bool) for c in x)
                for x in pts)):
            r.bad(f"{t}.curve", "points", f"expected a list of [x, y] numbers, got {pts!r:.60}")
            pts = []
        curve = Curve(r.choice(f"{t}.curve", ct, "kind", CURVES) or "circle",
                      r.num(f"{t}.curve", ct, "radius", default("joints", "radius", "curve")),
                      r.vec(f"{t}.curve", ct, "direction", 2,
                            default=default("joints", "direction", "curve")),
                      tuple(tuple(x) for x in pts), _closed(r, f"{t}.curve", ct))
    elif jtype == "contact":
        r.bad(t, "curve", "missing (expected { kind = \"circle\", radius = R } or "
              "{ kind = \"line\", direction = [x, y] })")
    side = (r.choice(t, d, "side", SIDES) or "outside") if "side" in d else "outside"
    unilateral = False
    if "unilateral" in d:
        unilateral = d["unilateral"]
        if not isinstance(unilateral, bool):
            r.bad(t, "unilateral", f"expected true or false, got {unilateral!r:.40}")
            unilateral = False
    return curve, side, unilateral


def _closed(r: Any, t: str, ct: dict) -> bool:
    """A spline's ``closed`` key (true unless given false)."""
    closed = ct.get("closed", True)
    if not isinstance(closed, bool):
        r.bad(t, "closed", f"expected true or false, got {closed!r:.40}")
        return True
    return closed


def is_gear(d: Any) -> bool:
    """Whether a ``[joints.NAME]`` table describes a gear pair."""
    return isinstance(d, dict) and d.get("type") == "gear"


def read_gear(r: Any, name: str, d: dict) -> Gear:
    """The gear pair of table ``joints.NAME`` (keys checked, each problem noted in ``r``)."""
    t = f"joints.{name}"
    d = r.keys(t, d, ("type", "connects", "ratio", "pressure_angle", "offset"))
    conn = d.get("connects")
    if not (isinstance(conn, list) and len(conn) == 2 and all(isinstance(c, str)
                                                              for c in conn)):
        r.bad(t, "connects", f"expected two joint names [\"A\", \"B\"], got {conn!r:.60}")
        conn = ["", ""]
    return Gear(name, conn[0], conn[1], r.num(t, d, "ratio"),
                r.num(t, d, "pressure_angle", default("joints", "pressure_angle")),
                r.num(t, d, "offset", default("joints", "offset")))
