"""Prescribed motions of drivers and laws of loads as CasADi expressions of time (and of a
joint's rate, for a motor)."""

from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.interpolate import CubicSpline

from ..description.mechanism import Driver, Law


def driver_expr(d: Driver, t: ca.SX) -> ca.SX:
    """The prescribed coordinate f(t) of a driver as a CasADi expression."""
    if d.motion == "constant_speed":
        return d.initial + d.speed * t
    if d.motion == "polynomial":
        return sum(c * t**k for k, c in enumerate(d.coefficients))
    if d.motion == "harmonic":
        return d.initial + d.amplitude * ca.sin(2 * np.pi * d.frequency * t + d.phase)
    return spline_expr(d.times, d.values, t)


def law_expr(law: Law, t: ca.SX, rate: ca.SX | None = None) -> ca.SX:
    """The value of a load law as a CasADi expression (``rate``: the loaded joint's rate,
    for a motor)."""
    if law.kind == "constant":
        return ca.SX(law.value)
    if law.kind == "polynomial":
        return sum(c * t**k for k, c in enumerate(law.coefficients))
    if law.kind == "harmonic":
        return law.mean + law.amplitude * ca.sin(2 * np.pi * law.frequency * t + law.phase)
    if law.kind == "table":
        return spline_expr(law.times, law.values, t)
    return law.stall * (1 - rate / law.no_load_speed)  # motor


def spline_expr(times, values, t: ca.SX) -> ca.SX:
    """Clamped cubic spline (zero end slopes) through a table as a CasADi expression: C2
    inside the table; held at the last value after it (C1 there, thanks to the zero end
    slope). Shared by driver and load tables."""
    sp = CubicSpline(np.array(times), np.array(values), bc_type="clamped")
    f = None
    for i, t0 in enumerate(sp.x[:-1]):
        c = sp.c[:, i]
        s = t - t0
        piece = ((c[0] * s + c[1]) * s + c[2]) * s + c[3]
        f = piece if f is None else ca.if_else(t >= t0, piece, f)
    return ca.if_else(t >= sp.x[-1], float(values[-1]), f)

