"""Friction from the reaction: a joint's friction levels grow with the load it carries.

On a revolute joint the level is ``mu * radius * |F|`` (F the pin's reaction force), on a
prismatic joint ``mu * |N|`` (N the guide's normal reaction), on a (bilateral) contact
joint ``mu * |N|`` (N the contact force), each added to the joint's constant level. The
reaction is a combination of the joint's multipliers: a revolute joint's two rows hold its
two points together in global x and y, so their multipliers are the force itself (a
spatial one's first three rows, in x, y and z); a prismatic joint's second row holds the
point on the guide's normal, so its multiplier is the normal force (a spatial one's first
two rows, along two normals); a contact's one row is the point's distance from its curve, so its
multiplier is the contact force. The friction a slipping joint feels
therefore depends on the multipliers it helps determine, and the KKT system becomes
nonlinear: :func:`solve` corrects a linear solve by Newton's method, so that the reaction
and the friction it causes are solved together, never with a lagged reaction.

Written once for numbers and CasADi expressions (:func:`magnitude`, :func:`level`), as the
event functions are.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..description.records import slide_base

__all__ = ["SMOOTH", "arm", "growth", "level", "magnitude", "reacting", "solve"]

#: A reaction's magnitude is sqrt(F . F + SMOOTH^2) (N): its derivative, which IDA's and
#: Newton's Jacobians need, stays defined where the reaction passes zero; the level it
#: adds there, mu r SMOOTH, is below any tolerance.
SMOOTH = 1e-10
_NEWTON_TOL = 1e-14
_NEWTON_MAX = 30


def reacting(mech: Any) -> list[str]:
    """Joints whose friction levels grow with their reaction, in file order."""
    return [n for n, j in mech.joints.items()
            if j.friction is not None and j.friction.from_reaction]


def _rows(model: Any, joint: str) -> list[int]:
    """The rows whose multipliers make the reaction friction grows with: a revolute
    joint's two, a prismatic joint's normal one, a contact's one (a unilateral contact's
    lock row, for its slide: zero while the contact is open)."""
    if joint in model.slides:  # a unilateral contact's slide: its contact's lock row
        return [model.n_fixed + model.locks.index(model.slides[joint])]
    j = model.joints[joint]
    rows = model.rows_of("joint", joint)
    if len(rows) != j.rows:  # (the model refuses this when it is built)
        raise ValueError(f"joint '{joint}' has {len(rows)} constraint rows, not {j.rows}")
    if j.type == "slide":  # a cylindrical joint's slide: its joint's normal rows
        return model.rows_of("joint", slide_base(joint))[:2]
    if j.spatial:  # the point rows: a hinge's three (its pin's whole force, global axes),
        return rows[:3] if j.type == "revolute" else rows[:2]  # a guide's two normal ones
    return rows[1:] if j.type == "prismatic" else rows


def magnitude(model: Any, joint: str, lam: Any) -> Any:
    """|F| (revolute) or |N| (prismatic, contact) of ``joint`` from the model's
    multipliers (N)."""
    total = SMOOTH**2
    for r in _rows(model, joint):
        total = total + lam[r] * lam[r]
    return total ** 0.5


def arm(model: Any, joint: str, friction: Any = None) -> Any:
    """What mu multiplies besides the reaction: the pin's radius on a revolute joint (m),
    1 on a prismatic or contact one. ``friction`` (default the joint's) may hold symbols."""
    f = model.joints[joint].friction if friction is None else friction
    return f.radius if model.joints[joint].type in ("revolute", "cylindrical") else 1.0


def growth(model: Any, joint: str, lam: Any, kind: str, friction: Any = None) -> Any:
    """The part of the ``kind`` ("static" or "kinetic") level of ``joint`` that grows with
    the reaction, mu times the reaction's magnitude times :func:`arm` (N or N m; 0 for
    constant friction). ``friction`` (default the joint's) may hold symbols."""
    if not model.joints[joint].friction.from_reaction:
        return 0.0
    f = model.joints[joint].friction if friction is None else friction
    mu = f.mu_static if kind == "static" else f.mu_kinetic
    return mu * arm(model, joint, f) * magnitude(model, joint, lam)


def level(model: Any, joint: str, lam: Any, kind: str, friction: Any = None) -> Any:
    """The ``kind`` ("static" or "kinetic") friction level of ``joint`` (N or N m) with the
    multipliers ``lam``: the constant level plus :func:`growth`. ``friction`` (default the
    joint's) may hold symbols."""
    f = model.joints[joint].friction if friction is None else friction
    const = f.static if kind == "static" else f.kinetic
    if not model.joints[joint].friction.from_reaction:
        return const
    return const + growth(model, joint, lam, kind, f)


def solve(model: Any, q: np.ndarray, v: np.ndarray, p: np.ndarray, Phi_q: np.ndarray,
          Qf: np.ndarray, gamma: np.ndarray, a: np.ndarray, lam: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """Accelerations and multipliers with the kinetic friction of the slipping reacting
    joints taken from the multipliers themselves.

    ``Qf`` holds every applied force but that friction; ``a``, ``lam`` the solution without
    it (the start of Newton's iteration). Each slipping joint adds
    ``-c_q^T s mu_k arm |F(lambda)|`` to the forces (s its slip direction in ``p``), which
    makes the system ``[[M, Phi_q^T], [Phi_q, D]] [a; lambda] = [Qf + Q_r(lambda); gamma]``
    nonlinear; Newton's method on it converges in a few iterations (quadratically).
    """
    slipping = []
    c_q = None
    for name in model.reacting:
        s = p[model.slip_slot(name)]
        f = model.joints[name].friction
        if s != 0.0 and f.mu_kinetic > 0.0:
            if c_q is None:
                c_q = model.joint_coords(q, v).c_q
            slipping.append((name, s * f.mu_kinetic * arm(model, name)
                             * c_q[model.jidx[name]]))
    if not slipping:
        return a, lam
    nq = model.nq
    A = model.kkt_matrix(Phi_q, p)
    x = np.concatenate([a, lam])
    # each joint's rows once (looked up per iteration they took a tenth of a fixed-step
    # run of a pin with reaction friction); the magnitude as magnitude() gives it, the
    # same operations in the same order, and its gradient lambda_r / |F| on those rows
    joints = [(g, _rows(model, name)) for name, g in slipping]
    rhs = np.empty(x.size)
    rhs[nq:] = gamma
    for _ in range(_NEWTON_MAX):
        lam = x[nq:]
        Qr = np.zeros(nq)
        J = A.copy()
        for g, rows in joints:
            total = SMOOTH**2
            for r in rows:
                total = total + lam[r] * lam[r]
            mag = total ** 0.5
            Qr -= g * mag
            for r in rows:  # d Q_r / d lambda_r = -g lambda_r / |F|
                J[:nq, nq + r] += g * (lam[r] / mag)
        rhs[:nq] = Qf + Qr
        dx = np.linalg.solve(J, A @ x - rhs)
        x = x - dx
        if np.max(np.abs(dx)) <= _NEWTON_TOL * (1.0 + np.max(np.abs(x))):
            break
    else:
        raise np.linalg.LinAlgError("the friction from the reaction could not be solved "
                                    "with the motion (Newton did not converge: the "
                                    "friction would lock the joint against its own load)")
    return x[:nq], x[nq:]
