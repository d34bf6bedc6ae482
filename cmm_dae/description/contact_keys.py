"""Reading a contact joint's own keys from a model file (its curve, side and
``unilateral``), for :mod:`.loader`."""

from __future__ import annotations

from typing import Any

from .checks import CURVES, SIDES
from .mechanism import Curve
from .schema import default, keys_of


def contact_keys(r: Any, t: str, d: dict, jtype: str) -> tuple[Curve | None, str, bool]:
    """``(curve, side, unilateral)`` of joint table ``t`` (``d``) read with the loader's
    reader ``r``, each problem noted there; keys only a contact may have refused on the
    other joint types (and a prismatic joint's keys on the others)."""
    if jtype in ("revolute", "contact"):
        for k in ("axis", "angle"):
            if k in d:
                r.bad(t, k, "only a prismatic joint has this key")
    if jtype != "contact":
        for k in ("curve", "side", "unilateral"):
            if k in d:
                r.bad(t, k, "only a contact joint has this key")
    curve = None
    if "curve" in d:
        ct = r.keys(f"{t}.curve", r.sub(t, d, "curve"), keys_of("joints", "curve"))
        curve = Curve(r.choice(f"{t}.curve", ct, "kind", CURVES) or "circle",
                      r.num(f"{t}.curve", ct, "radius", default("joints", "radius", "curve")),
                      r.vec(f"{t}.curve", ct, "direction", 2,
                            default=default("joints", "direction", "curve")))
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
