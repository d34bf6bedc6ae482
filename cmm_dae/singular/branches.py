"""Which branch at a singular position: the tangents of the other branches through it
(where one loop is singular) and the one a branch rule asks for. A part of
:func:`cmm_dae.singular.step_over`, which calls these at the singular instant itself."""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import SolverError, Status
from ..equations.model import Model

__all__ = ["choose_branch", "other_branches"]


def other_branches(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray
              ) -> list[np.ndarray] | None:
    """Velocities of the other branches through the singular position q (rank drop 1).

    A branch's tangent v keeps the velocity constraints and the acceleration-level one
    projected on the left null vector w of the constraint Jacobian, where the accelerations
    drop out: ``w . gamma(q, v, t) = 0`` (quadratic in v). With a driver the velocities
    are ``v + c n`` (n the new null direction; c = 0 is the branch of the motion); without
    one, the kinetic energy is kept and the tangents are the roots of a quadratic form on
    the two-dimensional null space. None where several singular values collapse at once
    (several loops singular): those branches are not enumerated."""
    act = model.active_rows(p)
    J = model.constraints(q, t, p).Phi_q[act]
    U, sv, Vt = np.linalg.svd(J)
    rank = int(np.sum(sv > 1e-8 * sv[0]))
    if min(J.shape) - rank > 1:
        return None  # several loops singular at once: not enumerated
    w = U[:, rank] if rank < U.shape[1] else None
    null = Vt[rank:].T
    if w is None or null.shape[1] == 0:
        return []

    def f(vel: np.ndarray) -> float:
        return float(w @ model._kkt_parts(q, vel, t, p)[2][act])

    out = []
    if null.shape[1] == 1:  # driven: f(v + c n) = a c^2 + b c, f(v) = 0
        n = null[:, 0]
        f1, fm = f(v + n), f(v - n)
        a_, b_ = 0.5 * (f1 + fm) - f(v), 0.5 * (f1 - fm)
        if abs(a_) > 1e-300:
            out.append(v - (b_ / a_) * n)
    elif null.shape[1] == 2:  # undriven: unit directions, energy kept
        Mh = np.sqrt(np.maximum(model.mass, 1e-300))
        B = null * Mh[:, None]  # M-orthonormal basis of the null space
        Qb, _ = np.linalg.qr(B)
        u1, u2 = Qb[:, 0] / Mh, Qb[:, 1] / Mh
        scale = math.sqrt(float(v @ (model.mass * v)))
        A_, C_ = f(u1), f(u2)
        B_ = 0.5 * (f(u1 + u2) - A_ - C_)
        roots = np.roots([C_, 2 * B_, A_]) if abs(C_) > 1e-300 else np.array([-A_ / (2 * B_)])
        for r in roots[np.isreal(roots)].real:
            d = (u1 + r * u2) / math.hypot(1.0, r)
            for sgn in (1.0, -1.0):
                cand = sgn * scale * d
                if np.linalg.norm((cand - v) * Mh) > 1e-3 * scale:  # not the motion's own
                    out.append(cand)
    return out


def choose_branch(model: Model, v: np.ndarray, others: list[np.ndarray] | None, q: np.ndarray,
            rule: tuple[str, int], t: float) -> tuple[np.ndarray, bool]:
    """The velocity whose joint ``rule[0]`` moves with the sign ``rule[1]``, the branch
    of the motion first; (velocity, switched). ``others`` None: the other branches are
    not known (several loops singular at once)."""
    joint, sign = rule
    k = model.jidx[joint]

    def rate(vel):
        return float(model.joint_rates(q, vel)[1][k])

    scale = max(float(np.max(np.abs(v))), 1e-300)
    if rate(v) * sign > 1e-9 * scale:
        return v, False
    if others is None:
        raise SolverError(f"joint '{joint}' would need another branch through the "
                          f"singular position at t = {t:.9g} s, but several loops are "
                          "singular at once here (rank drop above 1) and cmm_dae enumerates "
                          "branches only where one is: run with branch='continue' or a rule "
                          "the motion keeps",
                          status=Status.DEAD_POINT)
    for cand in others:
        # another branch, moving on (not back along the way it came)
        if rate(cand) * sign > 1e-9 * scale and float(cand @ (model.mass * v)) > -0.999 * \
                float(v @ (model.mass * v)):
            return cand, True
    raise SolverError(f"no branch through the singular position at t = {t:.9g} s moves "
                      f"joint '{joint}' "
                      f"{'forwards' if sign > 0 else 'backwards'}", status=Status.DEAD_POINT)
