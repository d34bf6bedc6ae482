"""The model's equations, built by small functions from a mechanism: the symbols and the
geometry (:class:`Frame`), the constraint rows (:func:`constraint_rows`), the applied forces
(:func:`applied_forces`) and the powers IDA integrates (:func:`powers`). :class:`~.model.Model`
calls them in this order and keeps what they build; each sets the model attributes it owns
(rows and their labels, joint and load indices, names)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from ..core.errors import ModelError, Problem
from ..description.mechanism import GROUND
from ..description.records import SLIDE
from . import reaction, spatial
from .contact import contact_gap_arc
from .laws import driver_expr
from .loading import body_loads, rot
from .reaction import reacting

__all__ = ["SLIDE", "Constraints", "Forces", "Frame", "JointCoords", "Row", "applied_forces",
           "constraint_rows", "names", "powers"]



@dataclass(frozen=True)
class Row:
    """One constraint row: what it belongs to (``joint``, ``gear``, ``driver`` or
    ``lock``) and whose."""

    kind: str
    name: str



@dataclass(frozen=True)
class Constraints:
    """Constraint values at (q, t): ``phi`` (m,), ``Phi_q`` (m, nq), ``Phi_t`` (m,)
    (:func:`~.kinematics.active_constraints`: the rows in force, Phi_q's of a long chain
    as :class:`~.minnorm.SparseRows`)."""

    phi: np.ndarray
    Phi_q: np.ndarray
    Phi_t: np.ndarray


@dataclass(frozen=True)
class JointCoords:
    """Joint coordinates ``c`` (nj,) in rad or m, their rates ``cdot`` (nj,) and the
    Jacobian ``c_q`` (nj, nq), in the order of ``Model.joint_names`` and then of the
    slides (``Model.slides``: arc lengths of unilateral contacts with friction)."""

    c: np.ndarray
    cdot: np.ndarray
    c_q: np.ndarray


def names(mdl, mech) -> None:
    """The model's bookkeeping of ``mech``: names and indices of bodies, joints, drivers,
    the joints that lock (``locks``), slip (``frictional``), or whose friction grows with
    their reaction (``reacting``), zoned loads and callable laws, masses (``mass``, nq)."""
    mdl.body_names = list(mech.bodies)
    mdl.joint_names = list(mech.joints)
    mdl.driver_names = list(mech.drivers)
    #: the slides of unilateral contacts with friction: "K:slide" -> "K". A slide is a
    #: coordinate of its own (the arc length, after the joints' in ``c``) that slips or
    #: sticks while its contact touches; the contact's own coordinate is its gap.
    mdl.slides = {f"{n}{SLIDE}": n for n, j in mech.joints.items()
                  if j.lands and j.friction is not None}
    of = {k: s for s, k in mdl.slides.items()}
    #: the records the event policy and the equations read by lock name: the joints (a
    #: contact with a slide without its friction) and the slides (bilateral, the friction)
    mdl.joints, mdl.sjoints = ({**{n: replace(j, friction=None) if n in of else j
                                   for n, j in m.joints.items()},
                                **{s: replace(m.joints[k], name=s, unilateral=False,
                                              restitution=0.0)  # (it has no stop)
                                   for s, k in mdl.slides.items()}}
                               for m in (mech, mdl.smech))
    #: joints with a lock row: on a stop (limits) or sticking (friction), then the slides
    mdl.locks = mech.lockable_joints + list(mdl.slides)
    #: joints with dry friction, in the order of their slip directions in ``p``
    mdl.frictional = [of.get(n, n) for n in mech.frictional_joints]
    #: frictional joints whose levels grow with their reaction (equations.reaction)
    mdl.reacting = [of.get(n, n) for n in reacting(mech)]
    nb = len(mdl.body_names)
    #: 2 or 3: the coordinates of a point (planar or spatial)
    mdl.dim = 3 if mech.spatial else 2
    #: coordinates of a body: (x, y, theta) in the plane, natural coordinates in space
    mdl.nqb = spatial.NQ if mech.spatial else 3
    mdl.nq = mdl.nqb * nb
    if mech.spatial:
        mdl.mass = np.array(spatial.mass(mech), float)
    else:
        mdl.mass = np.repeat([b.mass for b in mech.bodies.values()], 3)
        for i, b in enumerate(mech.bodies.values()):
            mdl.mass[3 * i + 2] = b.inertia
    mdl.bidx = {n: i for i, n in enumerate(mdl.body_names)}
    #: loads that act in a zone only, in the order of their switches in ``p``
    mdl.zoned = [n for n, ld in mech.loads.items() if ld.zone is not None]
    #: loads whose law is a Python callable f(t, coordinate, rate): (load, joint index).
    #: Their values enter as the last parameters, refilled from the state before every
    #: evaluation (:meth:`fill`); the solver's Jacobian gets their chain-rule term from
    #: :meth:`input_jacobian`.
    mdl.callables = [(n, list(mech.joints).index(ld.joint))
                     for n, ld in mech.loads.items() if ld.law.func is not None]


class Frame:
    """The symbols of a model under construction, ``q, v, a`` (nq,), ``t`` and ``p``
    (n_params,: the mechanism's values at its tail), and its geometry: a body's angle
    and a body point's position in them. Points and masses are read from the mechanism
    ``smech``, whose values are those symbols (and the parameters theta)."""

    def __init__(self, mdl, smech, p: ca.SX) -> None:
        nq = mdl.nq
        self.q, self.v, self.a = (ca.SX.sym(x, nq) for x in ("q", "v", "a"))
        self.t = ca.SX.sym("t")
        self.p = p
        self._mdl, self._smech = mdl, smech
        #: a spatial mechanism's geometry (equations.spatial), else None
        self.geo = spatial.Geometry(mdl, smech, self.q) if mdl.mech.spatial else None

    def mass(self) -> ca.SX:
        """The mass matrix's diagonal (nq,), from the (possibly symbolic) mechanism."""
        if self.geo is not None:
            return ca.vertcat(*spatial.mass(self._smech))
        return ca.vertcat(*[x for b in self._smech.bodies.values()
                            for x in (b.mass, b.mass, b.inertia)])

    def angle(self, body: str):
        return 0.0 if body == GROUND else self.q[3 * self._mdl.bidx[body] + 2]

    def point(self, ref: str):
        """Global position of ``"body.point"`` (CasADi)."""
        if self.geo is not None:
            return self.geo.point(ref)
        body, _ = ref.split(".", 1)
        lx, ly = self._smech.point(ref)
        if body == GROUND:
            return ca.vertcat(lx, ly)
        q, i = self.q, self._mdl.bidx[body]
        cx, cy = self._mdl.mech.bodies[body].centroid
        return q[3 * i:3 * i + 2] + rot(q[3 * i + 2]) @ ca.vertcat(lx - cx, ly - cy)


def constraint_rows(mdl, fr: Frame, drop: tuple[int, ...]):
    """The joint, gear, driver and lock rows, with the redundant ones ``drop`` left out:
    returns the joint coordinates ``c``, the rows ``phi`` and ``free`` (1 on an
    inactive lock row). Sets ``mdl.rows``, ``all_rows``, ``jidx``, ``dropped``,
    ``base_fn``, ``base_sym``, ``n_base``, ``m`` and ``n_fixed``."""
    mech, smech = mdl.mech, mdl.smech
    q, t, p = fr.q, fr.t, fr.p
    angle, point = fr.angle, fr.point
    nl = len(mdl.locks)
    coords = []
    arcs = {}  # the unilateral contacts' arc lengths (their slides' coordinates)
    rows: list[ca.SX] = []
    mdl.rows: list[Row] = []
    geo, turns = fr.geo, {}  # (turns: a spatial revolute joint's sine and cosine)
    for b in mech.bodies if geo is not None else ():
        rows += spatial.body_rows(geo, b)
        mdl.rows += [Row("body", b)] * 6
    for name, j in mech.joints.items():
        if geo is not None:
            cj, jrows, turns[name] = spatial.joint_rows(geo, smech.joints[name], mech)
            coords.append(cj)
            rows += jrows
            mdl.rows += [Row("joint", name)] * len(jrows)
            continue
        d = point(j.second) - point(j.first)
        dth = angle(j.second_body) - angle(j.first_body)
        if j.type == "revolute":
            coords.append(dth)
            jrows = [d[0], d[1]]
        elif j.type == "prismatic":
            u = np.array(j.axis, float) / np.hypot(*j.axis)
            ua = rot(angle(j.first_body)) @ ca.DM(u)
            na = ca.vertcat(-ua[1], ua[0])
            coords.append(ca.dot(ua, d))
            jrows = [dth - smech.joints[name].angle, ca.dot(na, d)]
        else:  # a contact: the gap is its row (bilateral) or its coordinate's stop
            gap, arc = contact_gap_arc(smech.joints[name], d, angle(j.first_body))
            coords.append(gap if j.unilateral else arc)
            arcs[name] = arc
            jrows = [] if j.unilateral else [gap]
        rows += jrows
        mdl.rows += [Row("joint", name)] * len(jrows)
    c = ca.vertcat(*coords, *[arcs[k] for k in mdl.slides.values()])
    jidx = {n: i for i, n in enumerate(mdl.joint_names + list(mdl.slides))}
    mdl.jidx = jidx
    # Gear pairs: two joints' coordinates in a fixed ratio (one row each, a joint row
    # in all but its label: it may be redundant, e.g. in a closed gear train)
    for name, gr in smech.gears.items():
        rows.append(c[jidx[gr.second]] - gr.ratio * c[jidx[gr.first]] - gr.offset)
        mdl.rows.append(Row("gear", name))
    for name, d in smech.drivers.items():
        if turns.get(name) is not None:  # at the angle f: sin(theta - f) = 0
            f = driver_expr(d, t)
            rows.append(turns[name][0] * ca.cos(f) - turns[name][1] * ca.sin(f))
        else:
            rows.append(c[jidx[name]] - driver_expr(d, t))
        mdl.rows.append(Row("driver", name))
    n_base = len(rows)
    for k, name in enumerate(mdl.locks):
        rows.append(p[k] * (c[jidx[name]] - p[nl + k]))
        mdl.rows.append(Row("lock", name))
    # Redundant joint and driver rows (dependent on the others wherever the mechanism
    # can be) are left out of the equations; the reactions are then shared among all
    # rows as the minimum-norm solution (post-processing, with ``base_fn``).
    #: every row before any was dropped, and the dropped ones (indices into it)
    mdl.all_rows = list(mdl.rows)
    mdl.dropped = tuple(sorted(set(drop)))
    if any(not 0 <= i < n_base for i in mdl.dropped):
        raise ValueError(f"only joint and driver rows can be dropped, got {drop}")
    base = ca.jacobian(ca.vertcat(*rows[:n_base]) if n_base else ca.SX(0, 1), q)
    #: the Jacobian of every joint, gear and driver row, theta symbolic (equations.outputs)
    mdl.base_sym = base
    if mdl.theta_paths:
        base = ca.substitute(base, mdl.theta, ca.DM(mdl.theta0))
    mdl.base_fn = ca.Function("base", [q, t, p], [ca.densify(base)])
    mdl.n_base = n_base
    keep = [i for i in range(len(rows)) if i not in mdl.dropped]
    rows = [rows[i] for i in keep]
    mdl.rows = [mdl.rows[i] for i in keep]
    mdl.m = m = len(rows)
    mdl.n_fixed = m - nl
    phi = ca.vertcat(*rows) if rows else ca.SX(0, 1)
    free = ca.vertcat(ca.SX.zeros(m - nl), 1 - p[:nl]) if nl else ca.SX.zeros(m)
    return c, phi, free


@dataclass(frozen=True)
class Forces:
    """The generalized applied forces ``Qf`` (nq,), the kinetic friction from the reaction
    ``Qr`` (nq,, a function of the multipliers), the loads' values and powers, the
    elements' lengths, rates and tensions, and the points ``P`` (2, nj) where joint
    forces are reported."""

    Qf: ca.SX
    Qr: ca.SX
    load_val: list
    load_pow: list
    el_len: list
    el_rate: list
    el_ten: list
    P: ca.SX


def applied_forces(mdl, fr: Frame, c, c_q, cdot, lam) -> Forces:
    """Gravity, the joints' springs and dampers, kinetic friction (constant, and from the
    reaction ``lam``), the loads and the force elements, with the joint coordinates ``c``,
    their Jacobian ``c_q`` and rates ``cdot``. Sets ``mdl.load_names``,
    ``zone_info`` and ``element_names``."""
    mech, smech = mdl.mech, mdl.smech
    q, v, p = fr.q, fr.v, fr.p
    point = fr.point
    nq, jidx = mdl.nq, mdl.jidx
    nl, nz = len(mdl.locks), len(mdl.zoned)
    # Generalized applied forces: gravity, then springs and dampers on joint coordinates.
    Qf = ca.SX.zeros(nq)
    g = smech.gravity
    for i, b in enumerate(smech.bodies.values()):
        for k in range(mdl.dim):
            Qf[mdl.nqb * i + k] += b.mass * g[k]
    for name, j in smech.joints.items():
        k = jidx[name]
        gen = 0.0
        if j.spring is not None:
            gen -= j.spring.stiffness * (c[k] - j.spring.rest)
        if j.damper is not None:
            gen -= j.damper.damping * cdot[k]
        if not (isinstance(gen, float) and gen == 0.0):
            Qf += c_q[k, :].T * gen
    # Kinetic friction of a slipping joint: against its slip direction s = +-1 (0 while
    # it sticks or stands on a stop); s is a configuration parameter, so the force is
    # smooth within a configuration and its switches are events.
    for f, name in enumerate(mdl.frictional):
        k = jidx[name]
        Qf -= c_q[k, :].T * (mdl.sjoints[name].friction.kinetic * p[2 * nl + nz + f])
    # Kinetic friction from the reaction (equations.reaction): a function of the
    # multipliers, so it is kept apart from Qf; IDA's residual has it with its own
    # multipliers, the KKT solves add it by Newton's method.
    Qr = ca.SX.zeros(nq)
    for f, name in enumerate(mdl.frictional):
        if name not in mdl.reacting:
            continue
        if name not in mdl.slides and len(mdl.rows_of("joint", name)) != \
                mech.joints[name].rows:
            raise ModelError(Problem(
                f"joints.{name}", "friction", "grows with the joint's reaction, but "
                "its constraint rows are redundant and leave the reaction undetermined; "
                "use constant friction levels (static, kinetic) there"))
        grows = reaction.growth(mdl, name, lam, "kinetic", mdl.sjoints[name].friction)
        Qr -= c_q[jidx[name], :].T * (grows * p[2 * nl + nz + f])

    Qf, load_val, load_pow = body_loads(mdl, fr, c_q, cdot, Qf)
    # Force elements between two points: tension pulls the points together.
    mdl.element_names = list(mech.elements)
    el_len, el_rate, el_ten = [], [], []
    for el in smech.elements.values():
        dvec = point(el.second) - point(el.first)
        L = ca.sqrt(ca.dot(dvec, dvec))
        L_q = ca.jacobian(L, q)
        Ld = L_q @ v
        T = el.preload + el.stiffness * (L - el.rest) + el.damping * Ld
        Qf -= L_q.T * T
        el_len.append(L)
        el_rate.append(Ld)
        el_ten.append(T)

    # Points where joint forces are reported: each joint's second (or first) connect point.
    ref_pts = []
    for j in mech.joints.values():
        ref_pts.append(point(j.second))
    P = ca.horzcat(*ref_pts) if ref_pts else ca.SX(mdl.dim, 0)

    return Forces(Qf, Qr, load_val, load_pow, el_len, el_rate, el_ten, P)


def powers(mdl, fr: Frame, lam, Phi_t, cdot, f: Forces):
    """The powers (W) IDA integrates: the drivers', the loads', the dampers' and the
    kinetic friction's, a (4,) expression."""
    smech, jidx, p = mdl.smech, mdl.jidx, fr.p
    nl, nz, m = len(mdl.locks), len(mdl.zoned), mdl.m
    el_rate, load_pow = f.el_rate, f.load_pow
    # The powers IDA integrates with the motion (its quadratures, the energy audit's
    # works and losses): the drivers', the loads', the dampers' (joints and elements)
    # and the kinetic friction's. The drivers' is the constraint forces' power
    # lambda . Phi_t (only driver rows depend on t; dropped rows do not change it).
    # Written v . (M a - Q) with IDA's accelerations instead, a driven rod's work was
    # 15x less accurate (1e-6 J against 7.7e-8 at rtol 1e-8): y' is one order less
    # accurate than y. The multipliers, held to ATOL_LAMBDA, stall it at about 1e-9
    # of the work from rtol 1e-10 on.
    diss = ca.SX(0)
    for name, j in smech.joints.items():
        if j.damper is not None:
            diss += j.damper.damping * cdot[jidx[name]] ** 2
    for el, rate in zip(smech.elements.values(), el_rate, strict=True):
        diss += el.damping * rate**2
    fric = ca.SX(0)
    for f, name in enumerate(mdl.frictional):
        kin = reaction.level(mdl, name, lam, "kinetic", mdl.sjoints[name].friction)
        fric += kin * p[2 * nl + nz + f] * cdot[jidx[name]]
    powers = ca.vertcat(ca.dot(lam, Phi_t) if m else ca.SX(0), sum(load_pow, ca.SX(0)),
                        diss, fric)
    return powers
