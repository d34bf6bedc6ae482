"""The coordinates the paper's fixed-step algorithm advances (its step's independent
variables): the joint coordinates that span a configuration's free motion best, or where
joint coordinates do not span it (a spatial ball joint's rotation has none) natural
coordinates of the bodies (``"body#k"``, the k-th of its 12) for the rest. They are the
entries of the extended vector ``[c; q]``: joint coordinates, then the bodies'."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..equations import rank
from ..equations.model import Model
from ..hybrid import policy as ev

__all__ = ["extend", "free", "index", "kinematics", "natural", "residual", "turning"]


def index(model: Model, name: str) -> int:
    """The index in ``[c; q]`` of a joint coordinate (its name) or of a natural coordinate
    (``"body#k"``)."""
    if name in model.jidx:
        return model.jidx[name]
    body, k = name.rsplit("#", 1)
    return len(model.jidx) + model.nqb * model.bidx[body] + int(k)


def turning(model: Model, kidx: list[int]) -> list[bool]:
    """Which of the coordinates ``kidx`` are a spatial hinge's angle, measured within pi of
    its range's middle: past its cut the angle jumps by 2 pi, so a step's target beyond it
    is the same position as one 2 pi back (:func:`residual`)."""
    if not model.mech.spatial:
        return [False] * len(kidx)
    names = model.joint_names
    return [k < len(names) and model.mech.joints[names[k]].type in ("revolute", "cylindrical")
            for k in kidx]


def residual(c, targets, wrap: list[bool]):
    """``c - targets``, the hinges' angles' differences wrapped into (-pi, pi] (numbers or
    CasADi): a free hinge turning through its cut is stepped as any other."""
    d = c - targets
    if not any(wrap):
        return d
    if isinstance(d, np.ndarray):
        d = d.copy()
        d[wrap] = np.arctan2(np.sin(d[wrap]), np.cos(d[wrap]))
        return d
    return ca.vertcat(*[ca.atan2(ca.sin(d[i]), ca.cos(d[i])) if w else d[i]
                        for i, w in enumerate(wrap)])


def natural(coords: list[str]) -> bool:
    """Whether any of ``coords`` is a natural coordinate."""
    return any("#" in c for c in coords)


def extend(joint: tuple, bodies: tuple, natural: bool) -> tuple:
    """Each joint-coordinate quantity (values, rates, accelerations: numbers) with the
    bodies' matching one appended, where natural coordinates are stepped (else as is)."""
    if not natural:
        return joint
    return tuple(np.concatenate([x, y]) for x, y in zip(joint, bodies, strict=True))


def kinematics(model: Model, q: np.ndarray, t: float, p: np.ndarray, natural: bool
               ) -> tuple:
    """:meth:`Model.kinematics`, with the natural coordinates appended to the joint
    coordinates where they are stepped: (Constraints, [c; q], [c_q; I])."""
    con, c, c_q = model.kinematics(q, t, p)
    if not natural:  # (a long chain's identity, nq x nq, each Newton iteration: not built)
        return con, c, c_q
    return con, np.concatenate([c, q]), np.vstack([c_q, np.eye(model.nq)])


def free(model: Model, hs: ev.HybridState, q: np.ndarray, t: float,
         prefer: list[str]) -> list[str]:
    """Choose the differential variables: non-driven, unlocked joint coordinates that span
    the free motion best (greedy pivoting on their rates over the null space of the
    active constraints), the user's [initial] choice first when it is well conditioned;
    where they span only part of it, the natural coordinates that span the rest best."""
    J = model.constraints(q, t, hs.p).Phi_q[model.active_rows(hs.p)]
    N = rank.null_space(J, model.nq)  # the free motions
    dof = N.shape[1]
    if dof == 0:
        return []
    C = model.joint_coords(q, np.zeros(model.nq)).c_q @ N
    cand = [n for n in model.joint_names if n not in model.mech.drivers and n not in hs.locked]
    pref = [n for n in prefer if n in cand]
    if len(pref) == dof:
        sub = C[[model.jidx[n] for n in pref]]
        sv = np.linalg.svd(sub, compute_uv=False)
        if sv[-1] > 1e-6 * max(1.0, sv[0]):
            return pref
    rows = C[[model.jidx[n] for n in cand]].reshape(len(cand), dof)
    chosen, _ = _pivot(rows, dof, [])
    if len(chosen) == dof:
        return [cand[k] for k in chosen]
    # the joint coordinates leave free motions (a ball joint's rotation): natural
    # coordinates for the rest, those the remaining motions move most
    names = [f"{b}#{k}" for b in model.body_names for k in range(model.nqb)]
    P = _span(rows[chosen], dof)
    more, _ = _pivot(N - N @ P, dof - len(chosen), [])
    return [cand[k] for k in chosen] + [names[k] for k in more]


def _pivot(rows: np.ndarray, most: int, chosen: list[int]) -> tuple[list[int], np.ndarray]:
    """Greedy pivoting: up to ``most`` rows, each the one with the largest component left
    once the chosen ones' directions are taken out (those below round-off not taken);
    the chosen rows and what is left of every row."""
    R = rows.copy()
    scale = float(np.max(np.linalg.norm(R, axis=1), initial=0.0))
    for _ in range(most):
        norms = np.linalg.norm(R, axis=1)
        k = int(np.argmax(norms)) if norms.size else 0
        if not norms.size or norms[k] <= 1e-9 * max(scale, 1e-300):
            break
        chosen.append(k)
        u = R[k] / norms[k]
        R = R - np.outer(R @ u, u)
    return chosen, R


def _span(rows: np.ndarray, dof: int) -> np.ndarray:
    """The projector (dof x dof) onto the free motions that ``rows`` (the chosen joint
    coordinates' rates over them) move."""
    if not rows.size:
        return np.zeros((dof, dof))
    Q, _ = np.linalg.qr(rows.T)
    return Q @ Q.T
