"""A contact joint's gap and arc length as CasADi expressions of the point's place relative
to its curve: circles and lines in closed form, splines piece by piece with the formulas of
:mod:`cmm_dae.description.curves` (the same ones the checks and drawings use)."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..description.curves import spline

__all__ = ["contact_gap_arc"]


def contact_gap_arc(j, d, theta1) -> tuple:
    """A contact joint's gap (distance of the point from the curve on its ``side``, m, to
    first order) and arc length (m) for ``d`` = point - curve origin (global, CasADi) and
    the first body's angle ``theta1``. On the curve the gap's gradient is the unit normal,
    so its multiplier is the contact force (N)."""
    c, s = ca.cos(theta1), ca.sin(theta1)
    dl = ca.vertcat(c * d[0] + s * d[1], -s * d[0] + c * d[1])  # in the first body's frame
    cv = j.curve
    if cv.kind == "circle":
        r = ca.sqrt(ca.dot(dl, dl))
        gap = r - cv.radius
        arc = cv.radius * ca.atan2(dl[1], dl[0])
    elif cv.kind == "spline":
        gap, arc = _spline_gap_arc(cv, dl)
    else:
        u = np.array(cv.direction, float) / math.hypot(*cv.direction)
        gap = -u[1] * dl[0] + u[0] * dl[1]  # left of the direction
        arc = u[0] * dl[0] + u[1] * dl[1]
    return (gap if j.side in ("outside", "left") else -gap), arc


def _spline_gap_arc(cv, dl) -> tuple:
    """Gap and arc length to a spline curve, piece by piece (nested from the last piece).

    Closed: the parameter is the polar angle of ``dl``, brought into the knots' turn (the
    periodic spline is C2 across its ends, so the angle's jump does not show in the gap;
    the arc length restarts at the first point), the gap ``(|dl| - r) r / sqrt(r^2 +
    r'^2)``. Open: the parameter is x (the first and last pieces extend past the ends,
    which are stops), the gap ``(y - f(x)) / sqrt(1 + f'^2)``. On the curve the gap's
    gradient is the unit normal and the arc length's the unit tangent."""
    sp = spline(cv)
    k = sp.knots
    if sp.closed:
        turn = 2 * math.pi
        u = k[0] + ca.fmod(ca.fmod(ca.atan2(dl[1], dl[0]) - k[0], turn) + turn, turn)
        rho = ca.sqrt(ca.dot(dl, dl))
    else:
        u = dl[0]
    gap = arc = None
    for i in reversed(range(k.size - 1)):
        s = u - k[i]
        val, slope = sp.piece(i, s)
        speed = sp.speed(val, slope)
        g = (rho - val) * val / speed if sp.closed else (dl[1] - val) / speed
        # the arc length plus a multiple of the gap (zero on the curve) that makes its
        # gradient there the unit tangent: s(u)'s own gradient has a normal part
        # (-r'/r or -f' of the unit normal), through which a force along the coordinate
        # (friction, a spring, a load) would change the contact force
        a = sp.arc[i] + sp.piece_arc(i, s) + (slope / val if sp.closed else slope) * g
        if gap is None:
            gap, arc = g, a
        else:
            gap, arc = ca.if_else(u < k[i + 1], g, gap), ca.if_else(u < k[i + 1], a, arc)
    return gap, arc
