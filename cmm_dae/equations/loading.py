"""The applied loads of a model: a law times a joint direction, a point force or a body
moment, in the plane and in space (:func:`body_loads`, called by
:func:`~.build.applied_forces`)."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from . import spatial
from .laws import law_expr

__all__ = ["body_loads", "rot"]


def rot(th):
    """The planar rotation matrix of angle ``th`` (CasADi)."""
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))


def body_loads(mdl, fr, c_q, cdot, Qf) -> tuple[ca.SX, list, list]:
    """``Qf`` with the applied loads added (a law times a joint direction, a point force or
    a body moment), and their values and powers. Sets ``mdl.load_names`` and
    ``zone_info``."""
    mech, jidx, q, v, t, p = mdl.mech, mdl.jidx, fr.q, fr.v, fr.t, fr.p
    point = fr.point
    nl = len(mdl.locks)
    mdl.load_names = list(mech.loads)
    mdl.zone_info: dict[str, tuple[int, float, float]] = {}
    load_val, load_pow = [], []
    for name, ld in mech.loads.items():
        k = jidx[ld.joint] if ld.joint is not None else None
        if ld.law.func is not None:
            val = p[mdl._u0 + [n for n, _ in mdl.callables].index(name)]
        else:
            val = law_expr(ld.law, t, cdot[k] if k is not None else None)
        if ld.zone is not None:
            zj = jidx[ld.zone.joint if ld.zone.joint is not None else ld.joint]
            mdl.zone_info[name] = (zj, -math.inf if ld.zone.lower is None
                                    else ld.zone.lower,
                                    math.inf if ld.zone.upper is None else ld.zone.upper)
            val = val * p[2 * nl + mdl.zoned.index(name)]
        if k is not None:
            Qf += c_q[k, :].T * val
            power = val * cdot[k]
        elif fr.geo is not None:
            Qf, power = _spatial_load(fr, ld, val, Qf)
        else:
            i = mdl.bidx[ld.body]
            om = v[3 * i + 2]
            if ld.point is None:
                Qf[3 * i + 2] += val
                power = val * om
            else:
                dvec = np.array(ld.direction, float) / math.hypot(*ld.direction)
                dirn = ca.DM(dvec) if ld.frame == "global" else \
                    rot(q[3 * i + 2]) @ ca.DM(dvec)
                F = dirn * val
                r = point(f"{ld.body}.{ld.point}") - q[3 * i:3 * i + 2]
                Qf[3 * i] += F[0]
                Qf[3 * i + 1] += F[1]
                Qf[3 * i + 2] += r[0] * F[1] - r[1] * F[0]
                vP = v[3 * i:3 * i + 2] + om * ca.vertcat(-r[1], r[0])
                power = ca.dot(F, vP)
        load_val.append(val)
        load_pow.append(power)

    return Qf, load_val, load_pow


def _spatial_load(fr, ld, val, Qf) -> tuple[ca.SX, ca.SX]:
    """``Qf`` with a spatial body load added (a force ``val`` along ``direction`` at a
    point, or a moment ``val`` about it), and its power."""
    geo, q, v = fr.geo, fr.q, fr.v
    d = np.asarray(ld.direction, float) / np.linalg.norm(ld.direction)
    dirn = ca.DM(d) if ld.frame == "global" else geo.direction(ld.body, d)
    if ld.point is not None:  # a force: its point's Jacobian carries it to q
        P_q = ca.jacobian(fr.point(f"{ld.body}.{ld.point}"), q)
        F = dirn * val
        return Qf + P_q.T @ F, ca.dot(F, P_q @ v)
    # A moment M: on each axis e_k the generalized force (M x e_k) / 2 (its virtual work
    # over a rotation dtheta, dtheta x e_k, summed over k is M . dtheta); its power is
    # M . omega with omega = sum_k e_k x e_k' / 2.
    M = dirn * val
    o = spatial.NQ * fr._mdl.bidx[ld.body]
    Qf = ca.SX(Qf)
    omega = ca.SX.zeros(3)
    for k in range(3):
        e, ed = q[o + 3 + 3 * k:o + 6 + 3 * k], v[o + 3 + 3 * k:o + 6 + 3 * k]
        Qf[o + 3 + 3 * k:o + 6 + 3 * k] += ca.cross(M, e) / 2
        omega += ca.cross(e, ed) / 2
    return Qf, ca.dot(M, omega)
