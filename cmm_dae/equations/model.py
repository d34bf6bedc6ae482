"""The unified Newton-Euler model in absolute coordinates, built once with CasADi.

Each body has ``q_i = (x, y, theta)`` of its centroid, so the mass matrix is constant and
diagonal. The constraint rows (:func:`~.build.constraint_rows`): each joint's (2 for a
revolute or prismatic joint, 1 for a bilateral contact, none for a unilateral one), each
gear pair's, each driver's ``c(q) - f(t)``, and a lock row ``a_k (c(q) - L_k)`` for each
joint that can lock, switched by the parameters ``p`` (``a_k`` = 1 locked, 0 free).

The equations of motion are ``M q'' + Phi_q^T lambda = Q(q, q', t)``, the paper's Eq. (10)
for all bodies at once; the multipliers are the physical constraint forces (a row's
generalized force on the bodies is ``-Phi_q^T lambda``). An inactive lock row gets the
trivial equation ``lambda_k = 0`` (``mu_k = 0``), so every configuration shares one
residual and one Jacobian.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from types import SimpleNamespace

import casadi as ca
import numpy as np

from ..description.mechanism import Mechanism
from . import build, kkt, laws, reaction, values
from .build import Constraints, JointCoords, Row  # noqa: F401 (model.Row, as before)
from .codegen import Buffered, compile_functions
from .unknowns import Unknowns, ground_pins

__all__ = ["Buffered", "Constraints", "JointCoords", "Model", "Row", "compile_functions"]


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
        p = values.parameters(self, mech, theta)  # (sets theta, value_paths, smech, ...)
        smech = self.smech
        nq = self.nq
        fr = build.Frame(self, smech, p)
        q, v, a, t = fr.q, fr.v, fr.a, fr.t
        self._sym = (q, v, t, p)

        c, phi, free = build.constraint_rows(self, fr, drop)
        m = self.m

        Phi_q = ca.jacobian(phi, q)
        Phi_t = ca.jacobian(phi, t)
        h = Phi_q @ v + Phi_t
        gamma = -(ca.jacobian(h, q) @ v + ca.jacobian(h, t))

        c_q = ca.jacobian(c, q)
        cdot = c_q @ v
        cddot = c_q @ a + ca.jacobian(cdot, q) @ v
        lam = ca.SX.sym("lam", m)
        forces = build.applied_forces(self, fr, c, c_q, cdot, lam)
        Qf, Qr, P = forces.Qf, forces.Qr, forces.P
        load_val, load_pow = forces.load_val, forces.load_pow
        el_len, el_rate, el_ten = forces.el_len, forces.el_rate, forces.el_ten

        Mdiag = fr.mass()
        # Stabilized index-2 (GGL) residual with y = [q, v, lambda, mu].
        mu = ca.SX.sym("mu", m)
        y = ca.vertcat(q, v, lam, mu)
        yp = ca.SX.sym("yp", y.numel())

        def ggl(Phi_q, Qf, phi, h, Mdiag):
            qp, vp = yp[:nq], yp[nq:2 * nq]
            return ca.vertcat(qp - v + Phi_q.T @ mu, Mdiag * vp + Phi_q.T @ lam - Qf,
                              phi + free * mu, h + free * lam)

        powers = build.powers(self, fr, lam, Phi_t, cdot, forces)
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
        e = SimpleNamespace(q=q, v=v, a=a, t=t, p=p, lam=lam, y=y, yp=yp, phi=phi,
                            Phi_q=Phi_q, Phi_t=Phi_t, gamma=gamma, Qf=Qf, Qr=Qr, c=c,
                            cdot=cdot, c_q=c_q, cddot=cddot, P=P, powers=powers, free=free,
                            F=ggl(Phi_q, Qf + Qr, phi, h, Mdiag), mass=Mdiag, el_len=el_len,
                            el_rate=el_rate, el_ten=el_ten, load_val=load_val,
                            load_pow=load_pow)
        self._functions(e)
        # IDA's unknowns: a body pinned to the ground by its angle alone (not with load laws
        # given as Python callables, whose solver Jacobian terms are in centroid
        # coordinates)
        rows = Counter(r.name for r in self.rows if r.kind == "joint")
        pins = {b: j for b, j in ground_pins(mech).items()
                if pinned_angles and not self.callables and j not in self.reacting
                and rows[j] == 2}
        #: what IDA integrates (:class:`~cmm_dae.equations.unknowns.Unknowns`)
        self.ida = Unknowns(self, pins, q, v, t, p, phi, Qf, free, Mdiag)
        self.compiled = False
        if compiled:  # IDA's residual and Jacobian (the model's are its core) in C
            funcs = compile_functions([self.ida.res_fn, self.ida.jac_fn])
            if funcs is not None:
                self.ida.res_fn, self.ida.jac_fn = funcs
                self.compiled = True

    def _functions(self, e: SimpleNamespace) -> None:
        """The numeric CasADi functions of the model from its expressions ``e`` (with the
        parameters theta at their values): constraints, coordinates, KKT parts, outputs,
        powers, IDA's residual and Jacobian, and the single-point evaluators."""
        q, v, a, t, p, lam, y, yp = e.q, e.v, e.a, e.t, e.p, e.lam, e.y, e.yp
        phi, Phi_q, Phi_t, gamma, Qf, Qr = e.phi, e.Phi_q, e.Phi_t, e.gamma, e.Qf, e.Qr
        c, cdot, c_q, cddot, P, powers, free = (e.c, e.cdot, e.c_q, e.cddot, e.P, e.powers,
                                                e.free)
        el_len, el_rate, el_ten = e.el_len, e.el_rate, e.el_ten
        load_val, load_pow = e.load_val, e.load_pow
        dn = ca.densify
        mk = ca.Function  # (F is the residual below: not a name these lambdas may share)
        # The dense single-state evaluators are built on first use (:meth:`__getattr__`):
        # a long chain's runs work from Phi_q's nonzeros, and densifying its Phi_q for each
        # (770 x 771 with 128 loops) took 0.5 of the model's 0.75 s
        self._lazy = {
            "phi_fn": lambda: mk("phi", [q, t, p], [dn(phi), dn(Phi_q), dn(Phi_t)]),
            "coord_fn": lambda: mk("coord", [q, v, p], [dn(c), dn(cdot), dn(c_q)]),
            "_rates_jac": lambda: Buffered(mk("rates_jac", [q, v, p], [
                dn(c), dn(cdot), dn(c_q), dn(ca.jacobian(cdot, q))])),
            "kin_fn": lambda: mk("kin", [q, t, p], [dn(phi), dn(Phi_q), dn(Phi_t), dn(c),
                                                   dn(c_q)]),
            "kkt_fn": lambda: mk("kkt", [q, v, t, p], [dn(Phi_q), dn(Qf), dn(gamma)]),
            "post_fn": lambda: mk("post", [q, v, a, t, p], [dn(c), dn(cdot), dn(cddot),
                                                          dn(P)]),
            #: one evaluation serving an event function: (c, cdot, Phi_q, Qf, gamma)
            "event_parts": lambda: Buffered(mk("evparts", [q, v, t, p], [
                dn(c), dn(cdot), dn(Phi_q), dn(Qf), dn(gamma)])),
            "_phi": lambda: Buffered(self.phi_fn), "_coord": lambda: Buffered(self.coord_fn),
            "_kin": lambda: Buffered(self.kin_fn), "_post": lambda: Buffered(self.post_fn),
            "_kkt_parts": lambda: Buffered(self.kkt_fn)}
        #: Phi_q's nonzeros only, in CSC order of :attr:`phi_q_pattern` (large mechanisms'
        #: screens: a chain of 32 loops has 2 % of its 194 x 291 entries nonzero)
        self.phi_q_nz_fn = ca.Function("phi_q_nz", [q, t, p],
                                       [ca.vertcat(*Phi_q.nonzeros())])

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
        # (not "free": compiled, the name is a C symbol, which would shadow libc's)
        self.free_fn = ca.Function("free_rows", [p], [dn(free)])
        # single-point evaluations for the step-by-step paths (private: callers use the
        # named methods below)
        self._free = Buffered(self.free_fn)
        #: joint coordinates and rates (q, v) -> (c, cdot); also the symbolic base of
        #: IDA's event functions
        self.cvel_fn = ca.Function("cvel", [q, v, p], [dn(c), dn(cdot)])
        #: the mass matrix's diagonal (nq,) of p (its values at p's tail)
        self.mass_fn = ca.Function("mass", [p], [dn(e.mass)])
        self._cvel = Buffered(self.cvel_fn)
        #: the single-state KKT solves (equations.kkt)
        self._kkt = kkt.Solver(self, Phi_q.sparsity())
        #: whether :meth:`kkt` factors the KKT matrix as a sparse one
        self.kkt_sparse = self._kkt.sparse
        self._active: dict[bytes, np.ndarray] = {}
        self._maps: dict[tuple[str, int], Buffered] = {}
        self._all_rows_index: dict[tuple[str, str], list[int]] | None = None

        cj = ca.SX.sym("cj")
        F = e.F
        J = ca.jacobian(F, y) + cj * ca.jacobian(F, yp)
        self.N = int(y.numel())
        self.res_fn = ca.Function("res", [t, y, yp, p], [F])
        # (no dense Jacobian of the model's own: IDA's is :attr:`ida`'s, built where its
        # dense solver asks; densifying A02's with 32 loops, 778 x 778, took 74 of 210 ms)
        #: the Jacobian's nonzeros in CSC order (scikit-sundae's sparse solver) and its
        #: structural pattern
        self.jac_sparse_fn = ca.Function("resjac_sp", [t, y, yp, cj, p], [J])
        self.jac_pattern = J.sparsity()
        #: the structural pattern of Phi_q (m, nq)
        self.phi_q_pattern = Phi_q.sparsity()
        #: the symbolic residual (``res_fn`` may be replaced by a compiled one below), which
        #: :mod:`cmm_dae.integrators.csegment` generates C from with ``jac_sparse_fn``
        self.res_sx = self.res_fn

    def variant(self, mech: Mechanism) -> Model:
        """A model of ``mech``, a mechanism of this one's structure (the same
        :func:`~.values.structure_key`: it differs at most in the values of
        :attr:`value_paths` and its start), sharing this one's functions, their maps and
        compiled libraries (:func:`.values.variant`)."""
        return values.variant(self, mech)

    def __getattr__(self, name: str):
        # (only for attributes not set: the lazy single-state evaluators of _functions)
        lazy = self.__dict__.get("_lazy")
        if lazy is None or name not in lazy:
            raise AttributeError(f"'Model' object has no attribute '{name}'")
        value = lazy[name]()
        setattr(self, name, value)
        return value

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
        return JointCoords(*self._coord(q, v, self._pw))

    def joint_rates(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint coordinates (nj,) and rates (nj,) only (cheaper than :meth:`joint_coords`)."""
        c, cd = self._cvel(q, v, self._pw)
        return c, cd

    def joint_accelerations(self, q: np.ndarray, v: np.ndarray, a: np.ndarray, t: float
                            ) -> np.ndarray:
        """Joint coordinate accelerations (nj,) from body accelerations ``a``."""
        return self._post(q, v, a, t, self._pw)[2]

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
        p[self.w_at:] = self.w0
        return p

    def slip_slot(self, joint: str) -> int:
        """Index in ``p`` of a frictional joint's slip direction (+1, -1, 0)."""
        return 2 * len(self.locks) + len(self.zoned) + self.frictional.index(joint)

    @property
    def mobility(self) -> int:
        """Degrees of freedom with no stop locked: coordinates less the body, joint and gear
        rows in the equations (the redundant ones were left out)."""
        return self.nq - sum(r.kind in ("body", "joint", "gear") for r in self.rows)

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

    def forget_maps(self, names) -> None:
        """Drop the maps of the functions ``names`` (built anew on their next use)."""
        self._maps = {k: v for k, v in self._maps.items() if k[0] not in names}

    def fill(self, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``p`` with the values of the callable load laws at (t, q, v) (``p`` itself when
        there are none)."""
        if not self.callables:
            return p
        p = p.copy()
        c, cd = self.joint_rates(q, v)
        for i, (name, k) in enumerate(self.callables):
            p[self._u0 + i] = laws.callable_value(self.mech, name, t, c[k], cd[k])
        return p

    def input_jacobian(self, t: float, q: np.ndarray, v: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """d(generalized load forces of the callable laws)/dq and /dv, (nq, nq) each: the
        term CasADi cannot see (:func:`~.laws.callable_jacobian`)."""
        return laws.callable_jacobian(self, t, q, v)

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
        system = kkt.symbolic(self, q, v, t, p)
        return system.A, system.b

    def kkt_matrix(self, Phi_q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The numeric KKT matrix at Phi_q in configuration ``p``."""
        return kkt.matrix(self.mass, Phi_q, self.free_rows(p))
