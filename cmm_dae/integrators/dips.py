"""A gap that dips beyond its stop and comes back within one of IDA's steps.

IDA looks for roots at the ends of its steps: an event function positive at both ends of
a step is taken to have no root inside it. A gap's event function is the distance to its
stop while the joint approaches and +1 once it moves away (:func:`~cmm_dae.hybrid.policy.
event_values`), so a joint that reached its stop, went beyond it and turned back inside
one step read positive at both ends and the impact was lost: a grazing bounce of the
collar on its shaft (0.0038 m/s) was found or missed by the last bits of the arithmetic.

After each step whose gap went from approaching (a distance) at its start to moving away
(+1) at its end, the step's interpolant is searched: the instant it turned (bisection on
where the function reads +1), the distance just before it, and, where that is beyond the
stop by more than the integrator resolves (:meth:`~cmm_dae.hybrid.state.HybridState.
stop_band`), the first crossing (bisection on its sign): the segment ends there as at a
root of IDA's. Both IDA paths do this after each step (``segment.c``'s ``dip_step`` in
C, :func:`locate` here), on the same event functions.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..hybrid import policy as ev

__all__ = ["ITERATIONS", "SAME", "depths", "locate"]

#: Bisection steps of each search (a step's length to below its round-off).
ITERATIONS = 60
#: Crossings this many round-offs of the step apart are one instant (IDA's own root
#: tolerance, 100 uround (|t| + |h|)).
SAME = 100.0


def depths(hs: ev.HybridState, triggers: list[ev.Trigger]) -> np.ndarray | None:
    """Per event function (the first, always positive, then ``triggers``): how far beyond
    its stop a gap must have dipped inside a step to count (a negative distance, minus
    :meth:`~cmm_dae.hybrid.state.HybridState.stop_band`); NaN for the others. None where
    no trigger is a gap (nothing to search)."""
    out = np.full(1 + len(triggers), np.nan)
    for i, tr in enumerate(triggers):
        if tr.kind == ev.TK.GAP:
            out[1 + i] = -float(hs.stop_band(hs.limit_value(tr.joint, tr.side)))
    return out if np.any(~np.isnan(out)) else None


def locate(t0: float, t1: float, g0: np.ndarray, g1: np.ndarray, depth: np.ndarray,
           g_at: Callable[[float], np.ndarray]) -> tuple[float, list[int]] | None:
    """The first gaps that dipped beyond their stops inside the step from ``t0`` to
    ``t1`` (event values ``g0``, ``g1`` at its ends, ``g_at(t)`` on its interpolant):
    (the instant the first crossed, s, the indices among the event functions of those
    that crossed then, within IDA's own root tolerance: two stops a symmetric mechanism
    reaches at one instant), or None."""
    found: list[tuple[float, int]] = []
    for i in np.flatnonzero(~np.isnan(depth)):
        if not (g0[i] > 0.0 and g0[i] != 1.0 and g1[i] == 1.0):
            continue
        a, b = t0, t1  # where it turned: the last instant it still approached
        for _ in range(ITERATIONS):
            m = 0.5 * (a + b)
            if not a < m < b:
                break
            if g_at(m)[i] == 1.0:
                b = m
            else:
                a = m
        if not g_at(a)[i] < depth[i]:
            continue
        lo, hi = t0, a  # it crossed between the step's start and there
        for _ in range(ITERATIONS):
            m = 0.5 * (lo + hi)
            if not lo < m < hi:
                break
            if g_at(m)[i] > 0.0:
                lo = m
            else:
                hi = m
        found.append((hi, int(i)))
    if not found:
        return None
    first = min(t for t, _ in found)
    tol = SAME * np.finfo(float).eps * (abs(t1) + (t1 - t0))
    return first, [i for t, i in found if t <= first + tol]
