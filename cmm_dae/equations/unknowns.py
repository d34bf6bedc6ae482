"""IDA's unknowns: the centroid coordinates, with a body pinned to the ground by its angle.

The model's equations are written in every body's centroid coordinates (x, y, theta): a
constant diagonal mass matrix, and one formulation for sensitivities, post-processing,
crossings and the fixed-step algorithm. IDA integrates a smaller set. A body joined to
the ground by a revolute joint has one coordinate of its own, its angle: its centroid is
``x_c = G - R(theta) (l - c)`` (G the ground point, l the joint's point in the body
frame, c the centroid there), the joint's two rows hold identically and leave the DAE,
and so do its reaction unknowns. The rest stays as it was. With z IDA's coordinates
(``q = Q(z)``, ``v = T(z) w``, ``T = dQ/dz``) the stabilised index-2 residual is

    z' - w + G^T mu = 0
    T^T (M (T w' + (dT/dz w) w) - Q_f) + G^T lambda = 0
    phi_r(Q(z), t) + free mu = 0
    G w + d phi_r / dt + free lambda = 0,       G = d phi_r(Q(z), t) / dz

over the remaining rows ``phi_r`` (T^T Phi_q^T of an eliminated row is zero, so its reaction
drops out). The equations are the same; only the coordinates IDA's error test and Newton
iteration see change. Why: on a pendulum the centroid's coordinates made IDA take four times
the steps the angle alone needs (a reference point at the pivot, with linear constraints,
took 0.9x; see ``validation/a01_steps.py``). Everything IDA returns is mapped back to
centroid coordinates at once, so nothing downstream sees the difference; the reactions of
the eliminated joints come, like all reactions, from the KKT solve of post-processing.

Besides the motion IDA integrates the works of the drivers, the loads, the dampers and
kinetic friction (:data:`WORKS`, J) as quadratures ``W' = P(q, v, lambda, t, p)``, the
powers of :attr:`~cmm_dae.equations.model.Model.power_fn`: the energy audit then holds to
the solver's tolerance on any output grid. They sit between the rates and the multipliers,
``y = [z, w, W, lambda, mu]``, and start at zero in every segment.
"""
from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from ..description.mechanism import GROUND, Mechanism
from .codegen import Buffered, map_width


def ground_pins(mech: Mechanism) -> dict[str, str]:
    """The bodies a revolute joint without a driver pins to the ground: {body: joint}, the
    first such joint of each body (model order). A driven pin is left out: its angle is
    prescribed, so carrying its body by it gains nothing, and the double-folded cycle's
    driven crank by its angle took 9% more steps at rtol 1e-8 and stalled (1e-6 s steps)
    at 1e-12."""
    pins: dict[str, str] = {}
    for name, j in mech.joints.items() if not mech.spatial else ():
        if j.type != "revolute" or (j.first_body == GROUND) == (j.second_body == GROUND) \
                or name in mech.drivers:
            continue
        body = j.second_body if j.first_body == GROUND else j.first_body
        pins.setdefault(body, name)
    return pins


#: The works IDA integrates with the motion (J), in the order of ``Model.power_fn``: the
#: drivers' and the loads' work done on the mechanism, the dampers' dissipation and the
#: loss to kinetic friction.
WORKS = ("driver", "load", "damper", "friction")
NW = len(WORKS)


class Unknowns:
    """IDA's unknowns ``y = [z, w, W, lambda_r, mu_r]`` and its residual for a model.

    Attributes
    ----------
    pinned : dict[str, str]
        Bodies integrated by their angle alone, and the ground joint that pins each.
    sel : ndarray of int
        Indices into q of IDA's coordinates z (``z = q[sel]``, ``w = v[sel]``).
    nz : int
        Number of IDA's coordinates.
    powered : tuple of int
        The works the mechanism has (indices into :data:`WORKS`; one that is identically
        zero, as the drivers' on a mechanism without drivers, is not integrated).
    nw : int
        Number of them, at ``y[2 nz:2 nz + nw]``.
    rows : ndarray of int
        The model's constraint rows that stay in the DAE (indices into ``model.rows``).
    m : int
        Number of them.
    N : int
        IDA's number of unknowns, ``2 nz + nw + 2 m``.
    """

    def __init__(self, model: Any, pinned: dict[str, str], q, v, t, p, phi, Qf, free,
                 Mdiag):
        # model: the :class:`~cmm_dae.equations.model.Model` being built (not imported here:
        # this module sits below it)
        self.model = model
        self.pinned = dict(pinned)
        #: (a work identically zero is left out: every unknown IDA carries counts in the
        #: norm of its error test, and four that are always zero loosened A02's steps)
        self.powered = model.powered
        self.nw = nw = len(self.powered)
        nq = model.nq
        self._full = None
        self._power: Buffered | None = None  # (power_fn through the buffer API)
        if not pinned:  # the model's own residual, in centroid coordinates
            self.sel = np.arange(nq)
            self.rows = np.arange(model.m)
            self.nz, self.m = nq, model.m
            core_res, core_jac = model.res_fn, model.jac_sparse_fn
        else:
            core_res, core_jac = self._reduced(pinned, q, v, t, p, phi, Qf, free, Mdiag)
        nz, m = self.nz, self.m
        self.N = N = 2 * nz + nw + 2 * m
        # the core's unknowns within IDA's: the works sit between the rates and lambda
        idx = list(range(2 * nz)) + list(range(2 * nz + nw, N))
        S = ca.DM(ca.Sparsity.triplet(len(idx), N, list(range(len(idx))), idx), 1.0)
        ta, cj = ca.SX.sym("t"), ca.SX.sym("cj")
        pa = ca.SX.sym("p", model.n_params)
        y, yp = ca.SX.sym("y", N), ca.SX.sym("yp", N)
        yc, ypc = ca.mtimes(S, y), ca.mtimes(S, yp)
        qs, vs, lams = self.symbolic(y)
        Fw = yp[2 * nz:2 * nz + nw] - model.power_fn(qs, vs, lams, ta, pa)[list(
            self.powered)]
        F = ca.vertcat(core_res(ta, yc, ypc, pa), Fw)
        J = ca.vertcat(ca.mtimes(core_jac(ta, yc, ypc, cj, pa), S),
                       ca.jacobian(Fw, y) + cj * ca.jacobian(Fw, yp))
        self.res_fn = self.res_sx = ca.Function("ida_res", [ta, y, yp, pa], [F])
        self._jac: ca.Function | tuple = (J, [ta, y, yp, cj, pa])  # (built where asked)
        self.jac_sparse_fn = ca.Function("ida_resjac_sp", [ta, y, yp, cj, pa], [J])
        self.jac_pattern = J.sparsity()

    def _reduced(self, pinned, q, v, t, p, phi, Qf, free, Mdiag
                 ) -> tuple[ca.Function, ca.Function]:
        """The residual and its sparse Jacobian on ``[z, w, lambda_r, mu_r]`` (bodies
        pinned by their angles), and the maps back to centroid coordinates."""
        model = self.model
        mech = model.mech
        joints = set(pinned.values())
        self.rows = np.array([k for k, r in enumerate(model.rows)
                              if not (r.kind == "joint" and r.name in joints)], dtype=int)
        sel = []
        for i, b in enumerate(model.body_names):
            sel += [3 * i + 2] if b in pinned else [3 * i, 3 * i + 1, 3 * i + 2]
        self.sel = np.array(sel, dtype=int)
        self.nz = nz = len(sel)
        self.m = m = len(self.rows)
        z = ca.SX.sym("z", nz)
        w = ca.SX.sym("w", nz)
        parts, k = [], 0
        for b in model.body_names:
            if b in pinned:
                j = mech.joints[pinned[b]]
                ground, own = (j.first, j.second) if j.first_body == GROUND \
                    else (j.second, j.first)
                G = ca.DM(mech.point(ground))
                lx, ly = mech.point(own)
                cx, cy = mech.bodies[b].centroid
                th = z[k]
                c, s = ca.cos(th), ca.sin(th)
                d = ca.vertcat(c * (lx - cx) - s * (ly - cy), s * (lx - cx) + c * (ly - cy))
                parts += [G - d, th]
                k += 1
            else:
                parts.append(z[k:k + 3])
                k += 3
        qz = ca.vertcat(*parts)
        T = ca.jacobian(qz, z)
        vz = T @ w
        fn = ca.Function("centroid_parts", [q, v, t, p], [phi, Qf, free])
        phi_f, Q_f, free_f = fn(qz, vz, t, p)
        lam = ca.SX.sym("lam", m)
        mu = ca.SX.sym("mu", m)
        # every model row's multiplier from IDA's: a constant selection matrix (zero rows
        # for the eliminated joints), built once for every symbolic() call
        self._select = ca.DM(model.m, m)
        for k, i in enumerate(self.rows.tolist()):
            self._select[i, k] = 1.0
        if model.reacting:  # friction from the reaction: with IDA's own multipliers
            Q_f = Q_f + model.qr_fn(qz, vz, ca.mtimes(self._select, lam), t, p)
        idx = self.rows.tolist()
        phi_r = phi_f[idx] if m else ca.SX(0, 1)
        free_r = free_f[idx] if m else ca.SX(0, 1)
        Gz = ca.jacobian(phi_r, z)
        h_r = Gz @ w + ca.jacobian(phi_r, t)
        y = ca.vertcat(z, w, lam, mu)
        yp = ca.SX.sym("yp", 2 * nz + 2 * m)
        zp, wp = yp[:nz], yp[nz:2 * nz]
        acc = T @ wp + ca.jacobian(vz, z) @ w
        F = ca.vertcat(zp - w + Gz.T @ mu, T.T @ (Mdiag * acc - Q_f) + Gz.T @ lam,
                       phi_r + free_r * mu, h_r + free_r * lam)
        cj = ca.SX.sym("cj")
        J = ca.jacobian(F, y) + cj * ca.jacobian(F, yp)
        yz = ca.SX.sym("yz", 2 * nz)
        self._full = ca.Function("centroids", [yz], [ca.densify(ca.vertcat(
            ca.substitute(qz, z, yz[:nz]),
            ca.substitute(vz, ca.vertcat(z, w), yz)))])
        self._maps: dict[int, Buffered] = {}
        return (ca.Function("core_res", [t, y, yp, p], [F]),
                ca.Function("core_jac", [t, y, yp, cj, p], [J]))

    @property
    def jac_fn(self) -> ca.Function:
        """IDA's Jacobian as a dense matrix, transposed as the model's (CasADi writes
        column-major, scikit-sundae row-major); built on first use: the dense solver's
        (a sparse or compiled segment takes :attr:`jac_sparse_fn`)."""
        if not isinstance(self._jac, ca.Function):
            J, args = self._jac
            self._jac = ca.Function("ida_resjac", args, [ca.densify(J.T)])
        return self._jac

    @jac_fn.setter
    def jac_fn(self, fn: ca.Function) -> None:
        self._jac = fn

    @property
    def reduced(self) -> bool:
        """Whether any body is integrated by its angle alone."""
        return bool(self.pinned)

    @property
    def lam(self) -> slice:
        """Where IDA's multipliers lambda sit in y."""
        start = 2 * self.nz + self.nw
        return slice(start, start + self.m)

    def start(self, q: np.ndarray, v: np.ndarray, a: np.ndarray, lam: np.ndarray,
              t: float, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """IDA's (y, y') from a consistent state: centroid coordinates, rates and
        accelerations and the multipliers of every model row (mu = 0) at t (s) with the
        configuration's parameters p; the works start at zero at their powers' rate."""
        s, r = self.sel, self.rows
        fn = self.model.power_fn
        if self._power is None or self._power.fn is not fn:  # (through the buffer API:
            self._power = Buffered(fn)  # a CasADi call took 0.27 ms, a segment's start)
        P = self._power(q, v, lam, t, p)[0][list(self.powered)]
        y = np.concatenate([q[s], v[s], np.zeros(self.nw), lam[r], np.zeros(self.m)])
        yp = np.concatenate([v[s], a[s], P, np.zeros(2 * self.m)])
        return y, yp

    def works(self, Y: np.ndarray) -> np.ndarray:
        """The works (n, :data:`NW`) in J since the segment's start, of IDA's states Y
        (zero for those the mechanism does not have)."""
        out = np.zeros((Y.shape[0], NW))
        out[:, list(self.powered)] = Y[:, 2 * self.nz:2 * self.nz + self.nw]
        return out

    def centroids(self, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centroid coordinates and rates (n, nq) of IDA's states Y (n, >= 2 nz)."""
        nz, nq = self.nz, self.model.nq
        if self._full is None:
            return Y[:, :nq].copy(), Y[:, nq:2 * nq].copy()
        n = Y.shape[0]
        out = np.empty((n, 2 * nq))
        if n == 0:
            return out[:, :nq], out[:, nq:]
        # chunks of at most 256 (codegen.map_width) through the buffer API: a map per
        # segment length, its result converted from a CasADi matrix, took 6 % of a run of
        # A02 with 32 loops
        size = map_width(n, 256)
        fn = self._maps.get(size)
        if fn is None:
            fn = self._maps[size] = Buffered(self._full.map(size))
        X = np.empty((2 * nz, size))
        for k in range(0, n, size):
            m = min(size, n - k)
            X[:, :m] = Y[k:k + m, :2 * nz].T
            X[:, m:] = X[:, m - 1:m]
            out[k:k + m] = fn(X)[0][:, :m].T
        return out[:, :nq].copy(), out[:, nq:].copy()

    def symbolic(self, y) -> tuple:
        """Centroid coordinates, rates and every model row's multiplier (zero for an
        eliminated row) as expressions of IDA's y (CasADi SX or MX)."""
        nz, lam = self.nz, y[self.lam]
        if self._full is None:
            nq = self.model.nq
            return y[:nq], y[nq:2 * nq], lam
        qv = self._full(y[:2 * nz])
        nq = self.model.nq
        lam = ca.mtimes(self._select, lam)
        return qv[:nq], qv[nq:], lam
