"""Tooth forces of gear pairs, and the bearing loads they add (post-processing).

A gear pair's row holds two joint coordinates in a ratio, so its multiplier acts as a pair
of torques (or a torque and a rack force) along those coordinates. The teeth really push
along the line of action at the pitch point: that force gives the same motion (its moment
about each axle is the torque) but it also loads the axles' bearings. Here the tooth force
is rebuilt from the multiplier and the pair's geometry, and the two joints' reported
forces (and a rack guide's moment) are corrected by the difference.
"""

from __future__ import annotations

import math

import numpy as np

from ..description.mechanism import GROUND
from ..equations.model import Model

__all__ = ["tooth_forces"]


def _perp(u: np.ndarray) -> np.ndarray:
    return np.stack([-u[..., 1], u[..., 0]], axis=-1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def tooth_forces(model: Model, q: np.ndarray, pts: np.ndarray, lam: np.ndarray,
                 jforce: np.ndarray, jtorque: np.ndarray) -> np.ndarray:
    """Tooth force (n, n_gears, 2) of each gear pair on its second joint's gear (or rack),
    N, global axes; ``jforce`` and ``jtorque`` (the joints' reported forces, (n, nj, 2)
    and (n, nj)) are corrected in place for it.

    ``pts`` (n, nj, 2) are the joints' second points (an axle's centre), ``lam`` the
    multipliers of every row (model.all_rows)."""
    mech = model.mech
    n = q.shape[0]
    out = np.zeros((n, len(mech.gears), 2))
    for g, (name, gr) in enumerate(mech.gears.items()):
        lam_g = lam[:, model.all_rows_of("gear", name)[0]]
        # generalized forces along the two coordinates (Q = -Phi_q^T lambda)
        tau = {gr.second: -lam_g, gr.first: gr.ratio * lam_g}
        ka, kb = model.jidx[gr.first], model.jidx[gr.second]
        ja, jb = mech.joints[gr.first], mech.joints[gr.second]
        tan_a = math.tan(gr.pressure_angle)
        if ja.type == jb.type == "revolute":
            d = pts[:, kb] - pts[:, ka]
            dist = np.hypot(d[:, 0], d[:, 1])
            u = d / dist[:, None]  # from the first gear's axle to the second's
            r_b = dist / (1.0 + abs(gr.ratio))  # the second gear's pitch radius
            tb = tau[gr.second]
            # tangential part: tb / r_b with the moment tb about b's axle; radial part:
            # the teeth push the gears apart
            F = (tb / r_b)[:, None] * -_perp(u) + (np.abs(tb) / r_b * tan_a)[:, None] * u
            P = pts[:, kb] - r_b[:, None] * u
            out[:, g] = F
            forces = ((gr.second, F), (gr.first, -F))
        else:  # a pinion and its rack
            rack, pinion = (gr.second, gr.first) if jb.type == "prismatic" else (
                gr.first, gr.second)
            kr, kp = model.jidx[rack], model.jidx[pinion]
            jr = mech.joints[rack]
            ax = np.asarray(jr.axis, float) / math.hypot(*jr.axis)
            th = (q[:, 3 * model.bidx[jr.first_body] + 2] if jr.first_body != GROUND
                  else np.zeros(n))
            c, s = np.cos(th), np.sin(th)
            a = np.stack([c * ax[0] - s * ax[1], s * ax[0] + c * ax[1]], axis=-1)
            nrm = _perp(a)
            side = np.sign(np.einsum("ni,ni->n", nrm, pts[:, kr] - pts[:, kp]))
            nrm = nrm * np.where(side == 0, 1.0, side)[:, None]  # from the pinion to the rack
            tr = tau[rack]
            F_rack = tr[:, None] * a + (np.abs(tr) * tan_a)[:, None] * nrm
            P = pts[:, kp] + abs(gr.ratio if jb.type == "prismatic" else 1.0 / gr.ratio) \
                * nrm
            out[:, g] = F_rack if rack == gr.second else -F_rack
            # the model applied tr along the axis at the rack's point; the teeth apply
            # F_rack at the pitch point: the guide carries the difference and its moment
            jforce[:, kr] -= F_rack - tr[:, None] * a
            jtorque[:, kr] -= _cross(P - pts[:, kr], F_rack)
            forces = ((pinion, -F_rack),)
        for joint, F in forces:  # an axle's bearing carries the tooth force as well
            jforce[:, model.jidx[joint]] -= F
    return out
