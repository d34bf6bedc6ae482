"""Loads that act only while a joint coordinate lies in a zone: the zone's event function
(armed only toward the edge approached), the switch at an edge, the zones acting at t = 0."""

from __future__ import annotations

import numpy as np

from ..core.records import Event, EventKind, Side
from ..equations.model import Model
from .state import HybridState, Transition


def pick(cond, a, b):
    """``a if cond else b`` for numbers: the numeric ``where`` of the event functions
    (:func:`cmm_dae.hybrid.policy.event_values`; ``casadi.if_else`` builds them symbolically)."""
    return a if cond else b


def _zone_margin(hs: HybridState, load: str, c, cdot, where=pick):
    """Distance of a zone's joint coordinate to the edge it moves toward, positive while
    the load's acting state matches where the coordinate is (acting inside, idle
    outside). As with the stops, an edge is armed only while the coordinate approaches
    it (+1 otherwise): a coordinate at rest on an edge (a jaw closed on its stop at the
    end of a cut) must not read as a root at every restart. ``where`` as in
    :func:`cmm_dae.hybrid.policy.event_values`."""
    k, lo, up = hs.model.zone_info[load]
    x, xd = c[k], cdot[k]
    tol = _edge_tol(x)  # on an edge to round-off counts as on it (see zone_switch)
    if load in hs.zones:  # acting: it leaves through the edge ahead
        return where(xd < 0.0, x - lo, where(xd > 0.0, up - x, 1.0))
    # idle below the zone: it enters moving up; above it, moving down; idle inside is a
    # mismatch (after a finite step)
    return where(x <= lo + tol, where(xd > 0.0, lo - x, 1.0),
                 where(x >= up - tol, where(xd < 0.0, x - up, 1.0),
                       -where(x - lo < up - x, x - lo, up - x)))


def _edge_tol(x: float) -> float:
    """How close to a zone edge (rad or m) a coordinate counts as on it."""
    return 1e-9 * (1.0 + abs(x))


def zone_switch(hs: HybridState, load: str, q: np.ndarray, v: np.ndarray, t: float
                ) -> Transition | None:
    """A load's zone edge reached: it starts or stops acting. At a located root (the
    coordinate on the edge) the direction of motion decides; after a finite step, where
    the coordinate is. None when nothing changes (a round-off root)."""
    model = hs.model
    k, lo, up = model.zone_info[load]
    c, cd = model.joint_rates(q, v)
    tol = _edge_tol(c[k])
    if abs(c[k] - lo) <= tol:
        inside = cd[k] > 0.0
    elif abs(c[k] - up) <= tol:
        inside = cd[k] < 0.0
    else:
        inside = lo <= c[k] <= up
    if inside == (load in hs.zones):
        return None
    before = hs.current()
    hs.zones = hs.zones | {load} if inside else hs.zones - {load}
    name = model.joint_names[k]
    return Transition(Event(t=t, kind=EventKind.ZONE, joint=name,
                            side=Side.ENTER if inside else Side.LEAVE, before=before,
                            after=hs.current(), velocity_before=float(cd[k]),
                            velocity_after=float(cd[k]), load=load), q, v)


def initial_zones(model: Model, q: np.ndarray) -> frozenset[str]:
    """The zoned loads whose zone holds the joint coordinate at q (edges included)."""
    c = model.joint_rates(q, np.zeros_like(q))[0]
    return frozenset(n for n, (k, lo, up) in model.zone_info.items() if lo <= c[k] <= up)

