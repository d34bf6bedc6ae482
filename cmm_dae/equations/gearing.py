"""The tooth force of a gear pair from its row's multiplier, written once for numbers
(post-processing, over all samples) and CasADi expressions (the sensitivity pass).

A gear pair's row holds two joint coordinates in a ratio, so its multiplier acts as a pair
of torques (or a torque and a rack force) along those coordinates. The teeth really push
along the line of action at the pitch point: the same motion (the force's moment about
each axle is the torque), but the axles' bearings carry the force too. :func:`tooth` gives
the force and the corrections of the two joints' reported forces (and a rack guide's
moment) that make them the bearings' real loads.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np

from ..description.mechanism import GROUND

__all__ = ["pinion_radius", "pitch_radius", "tooth"]


def pitch_radius(dist: Any, ratio: float) -> Any:
    """The second gear's pitch radius of two gears on axles ``dist`` apart (m; the first
    gear's is ``|ratio|`` times it): the axles are r_a + r_b apart in an external mesh
    (ratio -r_a / r_b), |r_b - r_a| in an internal one (ratio r_a / r_b > 0)."""
    return dist / abs(1.0 - ratio)


def pinion_radius(ratio: float, rack_second: bool) -> float:
    """The pinion's pitch radius beside its rack, m: ``|ratio|`` where the rack is the
    pair's second joint (m/rad), ``1 / |ratio|`` where it is the first (rad/m)."""
    return abs(ratio) if rack_second else 1.0 / abs(ratio)


def tooth(model: Any, name: str, lam_g: Any, point: Callable[[int], tuple],
          angle: Callable[[str], Any], where: Callable = np.where,
          sign: Callable = np.sign) -> tuple[tuple, list[tuple]]:
    """Tooth force of gear pair ``name`` on its second joint's gear (or rack), N, global
    axes, as (Fx, Fy); and the corrections ``(joint index, dFx, dFy, dM)`` to subtract from
    the reported forces (first body on second) and moments of the joints.

    ``lam_g`` is the pair's multiplier; ``point(k)`` the (x, y) of joint k's second point
    (an axle's centre, a rack's point), ``angle(body)`` a body's angle (0 for the ground);
    ``where`` and ``sign`` numpy's or CasADi's (``casadi.if_else``, ``casadi.sign``)."""
    mech = model.mech
    gr = mech.gears[name]
    ja, jb = mech.joints[gr.first], mech.joints[gr.second]
    ka, kb = model.jidx[gr.first], model.jidx[gr.second]
    tan_a = math.tan(gr.pressure_angle)
    # generalized forces along the two coordinates (Q = -Phi_q^T lambda)
    tau = {gr.second: -lam_g, gr.first: gr.ratio * lam_g}
    if ja.type == jb.type == "revolute":
        (ax, ay), (bx, by) = point(ka), point(kb)
        dx, dy = bx - ax, by - ay
        dist = (dx * dx + dy * dy) ** 0.5
        ux, uy = dx / dist, dy / dist  # from the first gear's axle to the second's
        rb = pitch_radius(dist, gr.ratio)
        tb = tau[gr.second]
        # the pitch point P: P - b = -rb u (between the axles; beyond the pinion where b
        # is the ring), +rb u where a is the ring and b the pinion inside it
        d = -1.0 if gr.ratio > 1.0 else 1.0
        # the radial part pushes the gears apart in an external mesh; in an internal one
        # it pushes the pinion towards its axle and the ring away from its own
        e = 1.0 if gr.ratio < 0.0 else -1.0
        # tangential: moment tb about b's axle; radial: tan(pressure angle) of it
        fx = d * tb / rb * uy + e * abs(tb) / rb * tan_a * ux
        fy = -d * tb / rb * ux + e * abs(tb) / rb * tan_a * uy
        return (fx, fy), [(kb, fx, fy, 0.0), (ka, -fx, -fy, 0.0)]
    rack, pinion = (gr.second, gr.first) if jb.type == "prismatic" else (gr.first, gr.second)
    kr, kp = model.jidx[rack], model.jidx[pinion]
    jr = mech.joints[rack]
    u = np.asarray(jr.axis, float) / math.hypot(*jr.axis)
    th = angle(jr.first_body) if jr.first_body != GROUND else 0.0
    c, s = _cos_sin(th)
    axx, axy = c * u[0] - s * u[1], s * u[0] + c * u[1]
    (rx, ry), (px, py) = point(kr), point(kp)
    side = sign(-axy * (rx - px) + axx * (ry - py))
    side = where(side == 0, 1.0, side)
    nx, ny = -axy * side, axx * side  # the guide's normal, from the pinion to the rack
    tr = tau[rack]
    fx = tr * axx + abs(tr) * tan_a * nx
    fy = tr * axy + abs(tr) * tan_a * ny
    rp = pinion_radius(gr.ratio, jb.type == "prismatic")
    qx, qy = px + rp * nx, py + rp * ny  # the pitch point
    # the model applied tr along the axis at the rack's point; the teeth apply the force
    # at the pitch point: the guide carries the difference and its moment
    fixes = [(kr, fx - tr * axx, fy - tr * axy, (qx - rx) * fy - (qy - ry) * fx),
             (kp, -fx, -fy, 0.0)]
    return ((fx, fy) if rack == gr.second else (-fx, -fy)), fixes


def _cos_sin(th: Any) -> tuple:
    """cos and sin of a number, a numpy array or a CasADi expression."""
    if isinstance(th, float | int | np.ndarray):
        return np.cos(th), np.sin(th)
    return ca.cos(th), ca.sin(th)
