"""The unified Newton-Euler model in absolute coordinates, built once with CasADi.

Each body has ``q_i = (x, y, theta)`` of its centroid, so the mass matrix is constant and
diagonal. Constraint rows, in this order:

* every joint: revolute ``r_P2 - r_P1`` (2 rows); prismatic ``theta2 - theta1 - angle`` and
  ``n1 . (r_P2 - r_P1)`` (2 rows);
* every driver: ``c(q) - f(t)`` (1 row);
* every limited (metamorphic) joint: a lock row ``a_k (c(q) - L_k)`` switched by the
  parameter vector ``p = [a_1..a_K, L_1..L_K]`` (``a_k`` = 1 locked, 0 free).

The equations of motion are ``M q'' + Phi_q^T lambda = Q(q, q', t)``, the paper's Eq. (10) for
all bodies at once; the multipliers are the physical constraint forces (the generalized force
of a row on the bodies is ``-Phi_q^T lambda``). An inactive lock row gets the trivial
equation ``lambda_k = 0`` (``mu_k = 0``), so every configuration shares one residual and one
Jacobian.

This is the only module besides ``dae`` that imports CasADi.
"""

from __future__ import annotations

import math
import reprlib
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..core.errors import ModelError, Problem
from ..description.mechanism import GROUND, Mechanism
from ..description.params import param_value, symbolic
from . import kkt, reaction
from .codegen import Buffered, compile_functions
from .laws import driver_expr, law_expr
from .reaction import reacting
from .unknowns import Unknowns, ground_pins

__all__ = ["Buffered", "Constraints", "JointCoords", "Model", "Row", "compile_functions"]


def contact_gap_arc(j, d, theta1) -> tuple:
    """A contact joint's gap (distance of the point from the curve on its ``side``, m) and
    arc length (m) for ``d`` = point - curve origin (global, CasADi) and the first body's
    angle ``theta1``. The gap is a distance, so its multiplier is the contact force (N)."""
    dl = _rot(theta1).T @ d  # in the first body's frame, where the curve is given
    c = j.curve
    if c.kind == "circle":
        r = ca.sqrt(ca.dot(dl, dl))
        gap = r - c.radius
        arc = c.radius * ca.atan2(dl[1], dl[0])
    else:
        u = np.array(c.direction, float) / math.hypot(*c.direction)
        gap = -u[1] * dl[0] + u[0] * dl[1]  # left of the direction
        arc = u[0] * dl[0] + u[1] * dl[1]
    return (gap if j.side == "outside" else -gap), arc


def _rot(th):
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))


@dataclass(frozen=True)
class Constraints:
    """Constraint values at (q, t): ``phi`` (m,), ``Phi_q`` (m, nq), ``Phi_t`` (m,)."""

    phi: np.ndarray
    Phi_q: np.ndarray
    Phi_t: np.ndarray


@dataclass(frozen=True)
class JointCoords:
    """Joint coordinates ``c`` (nj,) in rad or m, their rates ``cdot`` (nj,) and the
    Jacobian ``c_q`` (nj, nq), in the order of ``Model.joint_names``."""

    c: np.ndarray
    cdot: np.ndarray
    c_q: np.ndarray


@dataclass(frozen=True)
class Row:
    """One constraint row: what it belongs to (``joint``, ``driver`` or ``lock``) and whose."""

    kind: str
    name: str


class Model:
    """Symbolic model of a mechanism and its compiled CasADi functions.

    Parameters
    ----------
    mech : Mechanism
    compiled : bool
        Compile the residual and its Jacobian to C (CasADi code generation).
    drop : tuple of int
        Redundant joint and driver rows to leave out (indices into ``all_rows``).
    theta : sequence of str
        Model parameters kept as symbols (sensitivities).
    pinned_angles : bool
        Let IDA carry a body pinned to the ground by an undriven revolute joint by its
        angle alone (:attr:`ida`); False keeps every body in centroid coordinates.

    Attributes
    ----------
    nq : int
        Number of absolute coordinates (3 per body).
    m : int
        Number of constraint rows (joint, driver and lock rows).
    rows : list[Row]
        What each row belongs to.
    locks : list[str]
        Limited joints, in the order of their lock rows and of ``p``.
    """

    def __init__(self, mech: Mechanism, *, compiled: bool = False, drop: tuple[int, ...] = (),
                 theta: Sequence[str] = (), pinned_angles: bool = True):
        self.mech = mech
        #: model parameters (dotted paths, checked by the caller) kept as the symbols
        #: ``theta`` in :attr:`sym` (the equations for sensitivities); the compiled
        #: functions hold their values ``theta0``
        self.theta_paths = tuple(theta)
        self.theta = ca.SX.sym("theta", len(self.theta_paths))
        self.theta0 = np.array([param_value(mech, x) for x in self.theta_paths])
        smech = symbolic(mech, {x: self.theta[i] for i, x in enumerate(self.theta_paths)}) \
            if self.theta_paths else mech
        #: the mechanism with the parameters theta as symbols
        self.smech = smech
        self.body_names = list(mech.bodies)
        self.joint_names = list(mech.joints)
        self.driver_names = list(mech.drivers)
        #: joints with a lock row: on a stop (limits) or sticking (friction)
        self.locks = mech.lockable_joints
        #: joints with dry friction, in the order of their slip directions in ``p``
        self.frictional = mech.frictional_joints
        #: frictional joints whose levels grow with their reaction (equations.reaction)
        self.reacting = reacting(mech)
        nb = len(self.body_names)
        self.nq = nq = 3 * nb
        self.mass = np.repeat([b.mass for b in mech.bodies.values()], 3)
        for i, b in enumerate(mech.bodies.values()):
            self.mass[3 * i + 2] = b.inertia
        self.bidx = {n: i for i, n in enumerate(self.body_names)}

        q = ca.SX.sym("q", nq)
        v = ca.SX.sym("v", nq)
        a = ca.SX.sym("a", nq)
        t = ca.SX.sym("t")
        nl = len(self.locks)
        #: loads that act in a zone only, in the order of their switches in ``p``
        self.zoned = [n for n, ld in mech.loads.items() if ld.zone is not None]
        nz = len(self.zoned)
        nf = len(self.frictional)
        #: loads whose law is a Python callable f(t, coordinate, rate): (load, joint index).
        #: Their values enter as the last parameters, refilled from the state before every
        #: evaluation (:meth:`fill`); the solver's Jacobian gets their chain-rule term from
        #: :meth:`input_jacobian`.
        self.callables = [(n, list(mech.joints).index(ld.joint))
                          for n, ld in mech.loads.items() if ld.law.func is not None]
        nu = len(self.callables)
        p = ca.SX.sym("p", 2 * nl + nz + nf + nu)
        self._u0 = 2 * nl + nz + nf
        #: entries of ``p`` that make the configuration (the callable loads' values follow)
        self.n_switches = self._u0
        #: length of a configuration's parameter vector (lock switches and values, zones,
        #: slip directions, callable load values)
        self.n_params = int(p.numel())
        self._sym = (q, v, t, p)

        def angle(body):
            return 0.0 if body == GROUND else q[3 * self.bidx[body] + 2]

        def point(ref):  # its coordinates may be parameters (symbols in smech)
            body, _ = ref.split(".", 1)
            lx, ly = smech.point(ref)
            if body == GROUND:
                return ca.vertcat(lx, ly)
            i = self.bidx[body]
            cx, cy = mech.bodies[body].centroid
            return q[3 * i:3 * i + 2] + _rot(q[3 * i + 2]) @ ca.vertcat(lx - cx, ly - cy)

        coords = []
        rows: list[ca.SX] = []
        self.rows: list[Row] = []
        for name, j in mech.joints.items():
            d = point(j.second) - point(j.first)
            dth = angle(j.second_body) - angle(j.first_body)
            if j.type == "revolute":
                coords.append(dth)
                jrows = [d[0], d[1]]
            elif j.type == "prismatic":
                u = np.array(j.axis, float) / np.hypot(*j.axis)
                ua = _rot(angle(j.first_body)) @ ca.DM(u)
                na = ca.vertcat(-ua[1], ua[0])
                coords.append(ca.dot(ua, d))
                jrows = [dth - smech.joints[name].angle, ca.dot(na, d)]
            else:  # a contact: the gap is its row (bilateral) or its coordinate's stop
                gap, arc = contact_gap_arc(smech.joints[name], d, angle(j.first_body))
                coords.append(gap if j.unilateral else arc)
                jrows = [] if j.unilateral else [gap]
            rows += jrows
            self.rows += [Row("joint", name)] * len(jrows)
        c = ca.vertcat(*coords)
        jidx = {n: i for i, n in enumerate(self.joint_names)}
        self.jidx = jidx
        # Gear pairs: two joints' coordinates in a fixed ratio (one row each, a joint row
        # in all but its label: it may be redundant, e.g. in a closed gear train)
        for name, gr in smech.gears.items():
            rows.append(c[jidx[gr.second]] - gr.ratio * c[jidx[gr.first]] - gr.offset)
            self.rows.append(Row("gear", name))
        for name, d in smech.drivers.items():
            rows.append(c[jidx[name]] - driver_expr(d, t))
            self.rows.append(Row("driver", name))
        n_base = len(rows)
        for k, name in enumerate(self.locks):
            rows.append(p[k] * (c[jidx[name]] - p[nl + k]))
            self.rows.append(Row("lock", name))
        # Redundant joint and driver rows (dependent on the others wherever the mechanism
        # can be) are left out of the equations; the reactions are then shared among all
        # rows as the minimum-norm solution (post-processing, with ``base_fn``).
        #: every row before any was dropped, and the dropped ones (indices into it)
        self.all_rows = list(self.rows)
        self.dropped = tuple(sorted(set(drop)))
        if any(not 0 <= i < n_base for i in self.dropped):
            raise ValueError(f"only joint and driver rows can be dropped, got {drop}")
        base = ca.jacobian(ca.vertcat(*rows[:n_base]) if n_base else ca.SX(0, 1), q)
        if self.theta_paths:
            base = ca.substitute(base, self.theta, ca.DM(self.theta0))
        self.base_fn = ca.Function("base", [q, t], [ca.densify(base)])
        self.n_base = n_base
        keep = [i for i in range(len(rows)) if i not in self.dropped]
        rows = [rows[i] for i in keep]
        self.rows = [self.rows[i] for i in keep]
        self.m = m = len(rows)
        self.n_fixed = m - nl
        phi = ca.vertcat(*rows) if rows else ca.SX(0, 1)
        free = ca.vertcat(ca.SX.zeros(m - nl), 1 - p[:nl]) if nl else ca.SX.zeros(m)

        Phi_q = ca.jacobian(phi, q)
        Phi_t = ca.jacobian(phi, t)
        h = Phi_q @ v + Phi_t
        gamma = -(ca.jacobian(h, q) @ v + ca.jacobian(h, t))

        # Generalized applied forces: gravity, then springs and dampers on joint coordinates.
        Qf = ca.SX.zeros(nq)
        g = smech.gravity
        for i, b in enumerate(smech.bodies.values()):
            Qf[3 * i] += b.mass * g[0]
            Qf[3 * i + 1] += b.mass * g[1]
        c_q = ca.jacobian(c, q)
        cdot = c_q @ v
        for name, j in smech.joints.items():
            k = jidx[name]
            gen = 0.0
            if j.spring is not None:
                gen -= j.spring.stiffness * (c[k] - j.spring.rest)
            if j.damper is not None:
                gen -= j.damper.damping * cdot[k]
            if not (isinstance(gen, float) and gen == 0.0):
                Qf += c_q[k, :].T * gen
        cddot = c_q @ a + ca.jacobian(cdot, q) @ v
        # Kinetic friction of a slipping joint: against its slip direction s = +-1 (0 while
        # it sticks or stands on a stop); s is a configuration parameter, so the force is
        # smooth within a configuration and its switches are events.
        for f, name in enumerate(self.frictional):
            k = jidx[name]
            Qf -= c_q[k, :].T * (smech.joints[name].friction.kinetic * p[2 * nl + nz + f])
        # Kinetic friction from the reaction (equations.reaction): a function of the
        # multipliers, so it is kept apart from Qf; IDA's residual has it with its own
        # multipliers, the KKT solves add it by Newton's method.
        lam = ca.SX.sym("lam", m)
        Qr = ca.SX.zeros(nq)
        for f, name in enumerate(self.frictional):
            if name not in self.reacting:
                continue
            if len(self.rows_of("joint", name)) != mech.joints[name].rows:
                raise ModelError(Problem(
                    f"joints.{name}", "friction", "grows with the joint's reaction, but "
                    "its constraint rows are redundant and leave the reaction undetermined; "
                    "use constant friction levels (static, kinetic) there"))
            grows = reaction.growth(self, name, lam, "kinetic", smech.joints[name].friction)
            Qr -= c_q[jidx[name], :].T * (grows * p[2 * nl + nz + f])

        # Applied loads: a law times a joint direction, a point force or a body moment.
        self.load_names = list(mech.loads)
        self.zone_info: dict[str, tuple[int, float, float]] = {}
        load_val, load_pow = [], []
        for name, ld in mech.loads.items():
            k = jidx[ld.joint] if ld.joint is not None else None
            if ld.law.func is not None:
                val = p[self._u0 + [n for n, _ in self.callables].index(name)]
            else:
                val = law_expr(ld.law, t, cdot[k] if k is not None else None)
            if ld.zone is not None:
                zj = jidx[ld.zone.joint if ld.zone.joint is not None else ld.joint]
                self.zone_info[name] = (zj, -math.inf if ld.zone.lower is None
                                        else ld.zone.lower,
                                        math.inf if ld.zone.upper is None else ld.zone.upper)
                val = val * p[2 * nl + self.zoned.index(name)]
            if k is not None:
                Qf += c_q[k, :].T * val
                power = val * cdot[k]
            else:
                i = self.bidx[ld.body]
                om = v[3 * i + 2]
                if ld.point is None:
                    Qf[3 * i + 2] += val
                    power = val * om
                else:
                    dvec = np.array(ld.direction, float) / math.hypot(*ld.direction)
                    dirn = ca.DM(dvec) if ld.frame == "global" else \
                        _rot(q[3 * i + 2]) @ ca.DM(dvec)
                    F = dirn * val
                    r = point(f"{ld.body}.{ld.point}") - q[3 * i:3 * i + 2]
                    Qf[3 * i] += F[0]
                    Qf[3 * i + 1] += F[1]
                    Qf[3 * i + 2] += r[0] * F[1] - r[1] * F[0]
                    vP = v[3 * i:3 * i + 2] + om * ca.vertcat(-r[1], r[0])
                    power = ca.dot(F, vP)
            load_val.append(val)
            load_pow.append(power)

        # Force elements between two points: tension pulls the points together.
        self.element_names = list(mech.elements)
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
        P = ca.horzcat(*ref_pts) if ref_pts else ca.SX(2, 0)

        mass_sx = []
        for b in smech.bodies.values():
            mass_sx += [b.mass, b.mass, b.inertia]
        Mdiag = ca.vertcat(*mass_sx)
        # Stabilized index-2 (GGL) residual with y = [q, v, lambda, mu].
        mu = ca.SX.sym("mu", m)
        y = ca.vertcat(q, v, lam, mu)
        yp = ca.SX.sym("yp", y.numel())

        def ggl(Phi_q, Qf, phi, h, Mdiag):
            qp, vp = yp[:nq], yp[nq:2 * nq]
            return ca.vertcat(qp - v + Phi_q.T @ mu, Mdiag * vp + Phi_q.T @ lam - Qf,
                              phi + free * mu, h + free * lam)

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
        fr = ca.SX(0)
        for f, name in enumerate(self.frictional):
            kin = reaction.level(self, name, lam, "kinetic", smech.joints[name].friction)
            fr += kin * p[2 * nl + nz + f] * cdot[jidx[name]]
        powers = ca.vertcat(ca.dot(lam, Phi_t) if m else ca.SX(0), sum(load_pow, ca.SX(0)),
                            diss, fr)
        #: the symbolic equations with the parameters theta free (sensitivities)
        self.sym = {"q": q, "v": v, "a": a, "t": t, "p": p, "theta": self.theta,
                    "phi": phi, "Phi_q": Phi_q, "Phi_t": Phi_t, "h": h, "gamma": gamma,
                    "Qf": Qf, "c": c, "cdot": cdot, "c_q": c_q, "cddot": cddot, "free": free,
                    "mass": Mdiag,
                    "P": P, "y": y, "yp": yp, "lam": lam,
                    "Qr": Qr, "F": ggl(Phi_q, Qf + Qr, phi, h, Mdiag)}
        if self.theta_paths:  # the numeric functions below hold the parameters' values
            (phi, Phi_q, Phi_t, h, gamma, Qf, Qr, c, cdot, c_q, cddot, P, Mdiag, powers,
             *ex) = ca.substitute(
                [phi, Phi_q, Phi_t, h, gamma, Qf, Qr, c, cdot, c_q, cddot, P, Mdiag, powers,
                 *el_len, *el_rate, *el_ten, *load_val, *load_pow], [self.theta],
                [ca.DM(self.theta0)])
            ne, nld = len(el_len), len(load_val)
            el_len, el_rate, el_ten = ex[:ne], ex[ne:2 * ne], ex[2 * ne:3 * ne]
            load_val, load_pow = ex[3 * ne:3 * ne + nld], ex[3 * ne + nld:]
        dn = ca.densify
        self.phi_fn = ca.Function("phi", [q, t, p], [dn(phi), dn(Phi_q), dn(Phi_t)])
        #: Phi_q's nonzeros only, in CSC order of :attr:`phi_q_pattern` (large mechanisms'
        #: screens: a chain of 32 loops has 2 % of its 194 x 291 entries nonzero)
        self.phi_q_nz_fn = ca.Function("phi_q_nz", [q, t, p],
                                       [ca.vertcat(*Phi_q.nonzeros())])
        self.coord_fn = ca.Function("coord", [q, v], [dn(c), dn(cdot), dn(c_q)])
        self._rates_jac = Buffered(ca.Function("rates_jac", [q, v], [dn(c), dn(cdot), dn(c_q),
                                                                     dn(ca.jacobian(cdot, q))]))
        self.kin_fn = ca.Function("kin", [q, t, p], [dn(phi), dn(Phi_q), dn(Phi_t), dn(c),
                                                     dn(c_q)])
        self.kkt_fn = ca.Function("kkt", [q, v, t, p], [dn(Phi_q), dn(Qf), dn(gamma)])
        self.post_fn = ca.Function("post", [q, v, a, t], [dn(c), dn(cdot), dn(cddot), dn(P)])

        def col(xs):
            return dn(ca.vertcat(*xs)) if xs else ca.SX(0, 1)

        #: element lengths, rates, tensions; load values and powers (Result series)
        self.extras_fn = ca.Function("extras", [q, v, t, p],
                                     [col(el_len), col(el_rate), col(el_ten), col(load_val),
                                      col(load_pow)])
        #: the powers (W) of the drivers, the loads, the dampers (dissipated) and kinetic
        #: friction (lost) at (q, v, lambda, t, p), which IDA integrates with the motion
        self.power_fn = ca.Function("powers", [q, v, lam, t, p], [dn(powers)])
        #: the kinetic friction from the reaction as generalized forces (nq,) at
        #: (q, v, lambda, t, p): what Qf leaves out
        self.qr_fn = ca.Function("qr", [q, v, lam, t, p], [dn(Qr)])
        #: which of those powers the mechanism has at all (not identically zero)
        self.powered = tuple(k for k in range(powers.numel()) if not powers[k].is_zero())
        self.free_fn = ca.Function("free", [p], [dn(free)])
        # single-point evaluations for the step-by-step paths (private: callers use the
        # named methods below)
        self._phi = Buffered(self.phi_fn)
        self._coord = Buffered(self.coord_fn)
        self._kin = Buffered(self.kin_fn)
        self._kkt_parts = Buffered(self.kkt_fn)
        self._post = Buffered(self.post_fn)
        self._free = Buffered(self.free_fn)
        #: joint coordinates and rates (q, v) -> (c, cdot); also the symbolic base of
        #: IDA's event functions
        self.cvel_fn = ca.Function("cvel", [q, v], [dn(c), dn(cdot)])
        self._cvel = Buffered(self.cvel_fn)
        #: one evaluation serving an event function: (c, cdot, Phi_q, Qf, gamma)
        self.event_parts = Buffered(ca.Function(
            "evparts", [q, v, t, p], [dn(c), dn(cdot), dn(Phi_q), dn(Qf), dn(gamma)]))
        #: the single-state KKT solves (equations.kkt)
        self._kkt = kkt.Solver(self, Phi_q.sparsity())
        #: whether :meth:`kkt` factors the KKT matrix as a sparse one
        self.kkt_sparse = self._kkt.sparse
        self._active: dict[bytes, np.ndarray] = {}
        self._maps: dict[tuple[str, int], Buffered] = {}
        self._all_rows_index: dict[tuple[str, str], list[int]] | None = None

        cj = ca.SX.sym("cj")
        F = ggl(Phi_q, Qf + Qr, phi, h, Mdiag)
        J = ca.jacobian(F, y) + cj * ca.jacobian(F, yp)
        self.N = int(y.numel())
        self.res_fn = ca.Function("res", [t, y, yp, p], [F])
        # Transposed: CasADi writes column-major, scikit-sundae's JJ is row-major.
        self.jac_fn = ca.Function("resjac", [t, y, yp, cj, p], [ca.densify(J.T)])
        #: the Jacobian's nonzeros in CSC order (scikit-sundae's sparse solver) and its
        #: structural pattern
        self.jac_sparse_fn = ca.Function("resjac_sp", [t, y, yp, cj, p], [J])
        self.jac_pattern = J.sparsity()
        #: the structural pattern of Phi_q (m, nq)
        self.phi_q_pattern = Phi_q.sparsity()
        #: the symbolic residual (``res_fn`` may be replaced by a compiled one below), which
        #: :mod:`cmm_dae.integrators.csegment` generates C from with ``jac_sparse_fn``
        self.res_sx = self.res_fn
        # IDA's unknowns: a body pinned to the ground by its angle alone (not with load laws
        # given as Python callables, whose solver Jacobian terms are in centroid
        # coordinates)
        pins = {b: j for b, j in ground_pins(mech).items()
                if pinned_angles and not self.callables and j not in self.reacting
                and sum(r == Row("joint", j) for r in self.rows) == 2}
        #: what IDA integrates (:class:`~cmm_dae.equations.unknowns.Unknowns`)
        self.ida = Unknowns(self, pins, q, v, t, p, phi, Qf, free, Mdiag)
        self.compiled = False
        if compiled:  # IDA's residual and Jacobian (the model's are its core) in C
            funcs = compile_functions([self.ida.res_fn, self.ida.jac_fn])
            if funcs is not None:
                self.ida.res_fn, self.ida.jac_fn = funcs
                self.compiled = True

    # ------------------------------------------------------------- named interface
    def free_rows(self, p: np.ndarray) -> np.ndarray:
        """(m,) 1.0 on the inactive (unlocked) lock rows of configuration ``p``, else 0."""
        return self._free(p)[0]

    def active_rows(self, p: np.ndarray) -> np.ndarray:
        """Indices of the constraint rows in force in configuration ``p`` (cached)."""
        key = p[:self._u0].tobytes()
        rows = self._active.get(key)
        if rows is None:
            rows = self._active[key] = np.flatnonzero(self.free_rows(p) == 0.0)
        return rows

    def constraints(self, q: np.ndarray, t: float, p: np.ndarray) -> Constraints:
        """Constraint values, Jacobian and explicit time derivative at (q, t)."""
        return Constraints(*self._phi(q, t, p))

    def joint_coords(self, q: np.ndarray, v: np.ndarray) -> JointCoords:
        """Joint coordinates, their rates and their Jacobian at (q, v)."""
        return JointCoords(*self._coord(q, v))

    def joint_rates(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint coordinates (nj,) and rates (nj,) only (cheaper than :meth:`joint_coords`)."""
        c, cd = self._cvel(q, v)
        return c, cd

    def joint_accelerations(self, q: np.ndarray, v: np.ndarray, a: np.ndarray, t: float
                            ) -> np.ndarray:
        """Joint coordinate accelerations (nj,) from body accelerations ``a``."""
        return self._post(q, v, a, t)[2]

    def kinematics(self, q: np.ndarray, t: float, p: np.ndarray
                   ) -> tuple[Constraints, np.ndarray, np.ndarray]:
        """Constraints with the joint coordinates and their Jacobian in one evaluation:
        (Constraints, c (nj,), c_q (nj, nq))."""
        phi, Phi_q, Phi_t, c, c_q = self._kin(q, t, p)
        return Constraints(phi, Phi_q, Phi_t), c, c_q

    # ------------------------------------------------------------------ helpers
    def params(self, locked: dict[str, float] | None = None, zones=(),
               slip: dict[str, int] | None = None) -> np.ndarray:
        """Parameter vector for a configuration: ``locked`` maps joint -> lock value;
        ``zones`` names the zoned loads acting; ``slip`` maps a slipping joint to its
        direction (+1 or -1)."""
        nl = len(self.locks)
        p = np.zeros(self.n_params)
        for name, val in (locked or {}).items():
            k = self.locks.index(name)
            p[k] = 1.0
            p[nl + k] = val
        for name in zones:
            p[2 * nl + self.zoned.index(name)] = 1.0
        for name, s in (slip or {}).items():
            p[self.slip_slot(name)] = float(s)
        return p

    def slip_slot(self, joint: str) -> int:
        """Index in ``p`` of a frictional joint's slip direction (+1, -1, 0)."""
        return 2 * len(self.locks) + len(self.zoned) + self.frictional.index(joint)

    def rows_of(self, kind: str, name: str) -> list[int]:
        """Indices of the rows of one joint, driver or lock."""
        return [i for i, r in enumerate(self.rows) if r.kind == kind and r.name == name]

    def all_rows_of(self, kind: str, name: str) -> list[int]:
        """Indices in :attr:`all_rows` (the dropped redundant rows included) of the rows of
        one joint, driver or lock (a table built once: post-processing asks for every
        joint of every chunk)."""
        if self._all_rows_index is None:
            index: dict[tuple[str, str], list[int]] = {}
            for i, r in enumerate(self.all_rows):
                index.setdefault((r.kind, r.name), []).append(i)
            self._all_rows_index = index
        return list(self._all_rows_index.get((kind, name), ()))

    def mapped(self, name: str, n: int) -> Buffered:
        """``getattr(self, name)`` mapped over n samples, evaluated through the buffer API
        (converting CasADi matrices to numpy element by element cost more than the
        evaluation); cached, since building a map costs too."""
        key = (name, n)
        if key not in self._maps:
            self._maps[key] = Buffered(getattr(self, name).map(n))
        return self._maps[key]

    def fill(self, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``p`` with the values of the callable load laws at (t, q, v) (``p`` itself when
        there are none)."""
        if not self.callables:
            return p
        p = p.copy()
        c, cd = self.joint_rates(q, v)
        for i, (name, k) in enumerate(self.callables):
            p[self._u0 + i] = self._call(name, t, c[k], cd[k])
        return p

    def _call(self, name: str, t: float, c: float, cd: float) -> float:
        val = self.mech.loads[name].law.func(float(t), float(c), float(cd))
        ok = isinstance(val, int | float | np.number) and not isinstance(val, bool | np.bool_) \
            or (isinstance(val, np.ndarray) and val.shape == ())
        if not ok or not math.isfinite(float(val)):
            shown = reprlib.repr(val)
            raise ModelError(Problem(f"loads.{name}", "law", f"the Python callable returned "
                                     f"{shown} at t = {t:.9g} s (coordinate {c:.9g}, rate "
                                     f"{cd:.9g}); expected one finite number, the load in N "
                                     "or N m"), self.mech.source)
        return float(val)

    def input_jacobian(self, t: float, q: np.ndarray, v: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """d(generalized load forces of the callable laws)/dq and /dv, (nq, nq) each: the
        term CasADi cannot see (the law's own derivatives, by central differences)."""
        nq = self.nq
        dq, dv = np.zeros((nq, nq)), np.zeros((nq, nq))
        c, cd, c_q, cd_q = self._rates_jac(q, v)
        for name, k in self.callables:
            hc, hd = 1e-6 * (1 + abs(c[k])), 1e-6 * (1 + abs(cd[k]))
            f_c = (self._call(name, t, c[k] + hc, cd[k])
                   - self._call(name, t, c[k] - hc, cd[k])) / (2 * hc)
            f_d = (self._call(name, t, c[k], cd[k] + hd)
                   - self._call(name, t, c[k], cd[k] - hd)) / (2 * hd)
            g = c_q[k]  # the load's direction in generalized coordinates
            dq += np.outer(g, f_c * c_q[k] + f_d * cd_q[k])
            dv += np.outer(g, f_d * c_q[k])
        return dq, dv

    def kkt(self, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Accelerations, multipliers and Phi_q from ``[[M, Phi_q^T], [Phi_q, D]]``.

        ``D`` is 1 on the diagonal of inactive lock rows (their multiplier is 0).
        """
        p = self.fill(p, t, q, v)
        Phi_q, Qf, gamma = self._kkt_parts(q, v, t, p)
        a, lam, Phi_q = self.kkt_from(Phi_q, Qf, gamma, p)
        if self.reacting:  # friction from the reaction: solved with it (Newton)
            a, lam = reaction.solve(self, q, v, p, Phi_q, Qf, gamma, a, lam)
        return a, lam, Phi_q

    def kkt_from(self, Phi_q: np.ndarray, Qf: np.ndarray, gamma: np.ndarray, p: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The linear KKT solve of :meth:`kkt` from its already evaluated parts
        (:class:`cmm_dae.equations.kkt.Solver`)."""
        a, lam = self._kkt.solve(Phi_q, Qf, gamma, p)
        return a, lam, Phi_q

    def kkt_system(self, q, v, t, p) -> tuple[ca.MX | ca.SX, ca.MX | ca.SX]:
        """The KKT matrix and right-hand side of :meth:`kkt` for CasADi symbols (for the
        compiled event functions and iterative step)."""
        Phi_q, Qf, gamma = self.kkt_fn(q, v, t, p)
        return kkt.blocks(ca.DM(self.mass), Phi_q, self.free_fn(p)), ca.vertcat(Qf, gamma)

    def kkt_matrix(self, Phi_q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The numeric KKT matrix at Phi_q in configuration ``p``."""
        return kkt.matrix(self.mass, Phi_q, self.free_rows(p))
