"""Prescribed motions of drivers and laws of loads as CasADi expressions of time (and of a
joint's rate, for a motor)."""

from __future__ import annotations

import math
import reprlib
from typing import Any

import casadi as ca
import numpy as np

from ..core.errors import ModelError, Problem
from ..core.scipy_late import cubic_spline
from ..description.mechanism import Driver, Law, Mechanism


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
    sp = cubic_spline(np.array(times), np.array(values), bc_type="clamped")
    f = None
    for i, t0 in enumerate(sp.x[:-1]):
        c = sp.c[:, i]
        s = t - t0
        piece = ((c[0] * s + c[1]) * s + c[2]) * s + c[3]
        f = piece if f is None else ca.if_else(t >= t0, piece, f)
    return ca.if_else(t >= sp.x[-1], float(values[-1]), f)


def callable_value(mech: Mechanism, name: str, t: float, c: float, cd: float) -> float:
    """The load ``name``'s Python law at time t (s), its joint's coordinate c and rate cd:
    one finite number (N or N m), else a ModelError naming the load."""
    val = mech.loads[name].law.func(float(t), float(c), float(cd))
    ok = isinstance(val, int | float | np.number) and not isinstance(val, bool | np.bool_) \
        or (isinstance(val, np.ndarray) and val.shape == ())
    if not ok or not math.isfinite(float(val)):
        shown = reprlib.repr(val)
        raise ModelError(Problem(f"loads.{name}", "law", f"the Python callable returned "
                                 f"{shown} at t = {t:.9g} s (coordinate {c:.9g}, rate "
                                 f"{cd:.9g}); expected one finite number, the load in N "
                                 "or N m"), mech.source)
    return float(val)


def callable_jacobian(model: Any, t: float, q: np.ndarray, v: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """d(generalized load forces of ``model``'s callable laws)/dq and /dv, (nq, nq) each:
    the laws' own derivatives (central differences), which CasADi cannot see."""
    nq = model.nq
    dq, dv = np.zeros((nq, nq)), np.zeros((nq, nq))
    c, cd, c_q, cd_q = model._rates_jac(q, v, model._pw)
    for name, k in model.callables:
        hc, hd = 1e-6 * (1 + abs(c[k])), 1e-6 * (1 + abs(cd[k]))
        f_c = (callable_value(model.mech, name, t, c[k] + hc, cd[k])
               - callable_value(model.mech, name, t, c[k] - hc, cd[k])) / (2 * hc)
        f_d = (callable_value(model.mech, name, t, c[k], cd[k] + hd)
               - callable_value(model.mech, name, t, c[k], cd[k] - hd)) / (2 * hd)
        g = c_q[k]  # the load's direction in generalized coordinates
        dq += np.outer(g, f_c * c_q[k] + f_d * cd_q[k])
        dv += np.outer(g, f_d * c_q[k])
    return dq, dv
