"""The Result's joint and driver series from the constraint multipliers, written once as
CasADi expressions: the force and moment each joint transmits, the tooth force of each gear
pair, each driver's effort.

Post-processing (:mod:`cmm_dae.results.post`) evaluates :func:`function` over all samples;
the sensitivity pass (:mod:`cmm_dae.sensitivity.model`) differentiates
:func:`expressions`, so the numbers a Result reports and the ones whose derivatives are
given are one definition.

A joint's force is the one its first body exerts on its second, at the second's connect
point, in global axes (N); its moment (N m) is the rest of the rows' generalized force
about that point (a prismatic guide's or a locked joint's). The rows' generalized force is
``-Phi_q^T lambda`` over every row of the joint (a lock row's too), with every row of the
mechanism (``model.all_rows``: redundant rows, left out of the equations, carry their
share of the reactions).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..description.mechanism import GROUND
from .gearing import tooth

__all__ = ["expressions", "function", "kept_to_all", "series_function"]


def _all_rows_jacobian(model):
    """The Jacobian of every row (``model.all_rows``: the joint, gear and driver rows, the
    dropped redundant ones included, then the lock rows), with theta symbolic."""
    locks = model.sym["Phi_q"][model.n_fixed:, :]
    return ca.vertcat(model.base_sym, locks)


def expressions(model, lam_all: ca.SX) -> list[ca.SX]:
    """(jforce (2 nj,), jtorque (nj,), gforce (2 ng,), effort (nd,)) as CasADi
    expressions of the model's symbols ``q``, ``p``, ``theta`` and the multipliers
    ``lam_all`` of every row (``len(model.all_rows)``); in space jforce and jtorque are
    (3 nj,) each."""
    sy = model.sym
    q, P = sy["q"], sy["P"]
    J = _all_rows_jacobian(model)
    if model.mech.spatial:
        return _spatial(model, q, P, J, lam_all)
    fx, fy, tq = [], [], []
    for k, (name, j) in enumerate(model.mech.joints.items()):
        rows = model.all_rows_of("joint", name) + model.all_rows_of("lock", name)
        G = -(J[rows, :].T @ lam_all[rows]) if rows else ca.SX.zeros(model.nq)
        second = j.second_body != GROUND
        b = model.bidx[j.second_body if second else j.first_body]
        F, Mc = G[3 * b:3 * b + 2], G[3 * b + 2]
        d = P[:, k] - q[3 * b:3 * b + 2]
        moment = d[0] * F[1] - d[1] * F[0]  # of F at the point about the centroid
        # on the second body: the force itself; on the ground: minus the first body's
        s = 1.0 if second else -1.0
        fx.append(s * F[0])
        fy.append(s * F[1])
        tq.append(s * (Mc - moment))

    def angle(body: str):
        return ca.SX(0) if body == GROUND else q[3 * model.bidx[body] + 2]

    gforce = []
    for name in model.mech.gears:  # the tooth force, and the bearings' share of it
        (gx, gy), fixes = tooth(model, name, lam_all[model.all_rows_of("gear", name)[0]],
                                lambda k: (P[0, k], P[1, k]), angle, ca.if_else, ca.sign)
        gforce += [gx, gy]
        for k, dfx, dfy, dm in fixes:
            fx[k], fy[k], tq[k] = fx[k] - dfx, fy[k] - dfy, tq[k] - dm
    effort = [-lam_all[model.all_rows_of("driver", n)[0]] for n in model.driver_names]
    force = [x for pair in zip(fx, fy, strict=True) for x in pair]
    return [ca.vertcat(*xs) if xs else ca.SX(0, 1) for xs in (force, tq, gforce, effort)]


def _spatial(model, q, P, J, lam_all) -> list[ca.SX]:
    """:func:`expressions` of a spatial mechanism: (jforce (3 nj,), jtorque (3 nj,),
    gforce (0,), effort (nd,)). A body's share of the rows' generalized force is its force
    on the centroid's three coordinates and, on the axes e_k, ``G_k`` whose moment about the
    centroid is ``sum_k e_k x G_k`` (a virtual rotation moves e_k by dtheta x e_k)."""
    force, torque = [], []
    for k, (name, j) in enumerate(model.mech.joints.items()):
        rows = model.all_rows_of("joint", name) + model.all_rows_of("lock", name)
        G = -(J[rows, :].T @ lam_all[rows]) if rows else ca.SX.zeros(model.nq)
        second = j.second_body != GROUND
        o = model.nqb * model.bidx[j.second_body if second else j.first_body]
        F = G[o:o + 3]
        Mc = sum((ca.cross(q[o + 3 + 3 * i:o + 6 + 3 * i], G[o + 3 + 3 * i:o + 6 + 3 * i])
                  for i in range(3)), ca.SX.zeros(3))
        s = 1.0 if second else -1.0  # on the ground: minus the first body's
        force.append(s * F)
        torque.append(s * (Mc - ca.cross(P[:, k] - q[o:o + 3], F)))
    effort = [-lam_all[model.all_rows_of("driver", n)[0]] for n in model.driver_names]
    return [ca.vertcat(*xs) if xs else ca.SX(0, 1) for xs in (force, torque, [], effort)]


def function(model) -> ca.Function:
    """``outputs(q, p, lam_all) -> (jforce, jtorque, gforce, effort)`` with theta at its
    values (see :func:`expressions`), built once per model."""
    fn = getattr(model, "outputs_fn", None)
    if fn is None:
        lam_all = ca.SX.sym("lam_all", len(model.all_rows))
        out = expressions(model, lam_all)
        if model.theta_paths:
            out = ca.substitute(out, [model.theta], [ca.DM(model.theta0)])
        sy = model.sym
        fn = model.outputs_fn = ca.Function("outputs", [sy["q"], sy["p"], lam_all],
                                            [ca.densify(x) for x in out])
    return fn


def kept_to_all(model) -> np.ndarray:
    """(len(all_rows), m) the matrix that puts the multipliers of the rows in the
    equations at their places among every row (zero on the dropped ones)."""
    keep = [i for i in range(len(model.all_rows)) if i not in model.dropped]
    E = np.zeros((len(model.all_rows), model.m))
    E[keep, np.arange(model.m)] = 1.0
    return E


def series_function(model) -> ca.Function:
    """``series(q, v, a, t, p)``: every per-sample series of a Result but the forces, in
    one function for post-processing to map: the joint coordinates, rates and
    accelerations, the elements' lengths, rates and tensions, the loads' values and powers
    (the model's ``post_fn`` and ``extras_fn``), the constraint values and their rates
    ``Phi_q v + Phi_t`` (the drift); built once per model (``model.series_fn``)."""
    fn = getattr(model, "series_fn", None)
    if fn is None:
        sy = model.sym
        q, v, a, t, p = sy["q"], sy["v"], sy["a"], sy["t"], sy["p"]
        drift = [sy["phi"], sy["h"]]
        if model.theta_paths:
            drift = ca.substitute(drift, [model.theta], [ca.DM(model.theta0)])
        out = [*model.post_fn(q, v, a, t, p)[:3], *model.extras_fn(q, v, t, p), *drift]
        fn = model.series_fn = ca.Function("series", [q, v, a, t, p],
                                           [ca.densify(x) for x in out])
    return fn
