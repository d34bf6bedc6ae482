"""The sensitivity pass over a traced run (:func:`cmm_dae.sensitivities`): the start from
the assembly equations, each configuration segment integrated by IDA with its sensitivity
equations, the jump at every event, the derivatives of the Result's series."""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import SolverError, Status
from ..equations.kinematics import project_state
from ..equations.model import Model
from ..hybrid import policy as ev
from ..hybrid.start import start_spec
from ..hybrid.state import SegmentTrace
from ..results.result import Result
from ..singular.step import step_over
from .crossing import CrossingPass
from .ida_pass import ATOL_OFF, LOOSE, ida_segment
from .model import Equations

__all__ = ["ATOL_OFF", "LOOSE", "SensitivityPass"]

class SensitivityPass(CrossingPass):
    """The sensitivity pass over a traced run."""

    def __init__(self, model: Model, eq: Equations, res: Result, opts: dict,
                 error_control: bool):
        self.model, self.eq, self.res = model, eq, res
        self.P = eq.P
        self.th = model.theta0
        self.rtol, self.atol = opts["rtol"], opts["atol"]
        self.error_control = error_control
        n = res.t.size
        nq = model.nq
        self.sq = np.full((n, nq, self.P), np.nan)
        self.sv = np.full((n, nq, self.P), np.nan)
        self.dP: list[np.ndarray | None] = [None] * n
        self.params: list[np.ndarray | None] = [None] * n
        #: d(lock value)/d theta of each locked joint
        self.dL: dict[str, np.ndarray] = {}
        self.tau: list[np.ndarray] = []
        self.nfev = 0
        self.notes: list[str] = []

    # ---- helpers
    def unit(self, path: str) -> np.ndarray:
        """d value / d theta of a model value that is itself a parameter or a constant:
        the unit vector of ``path`` among the parameters (zeros when it is not one)."""
        d = np.zeros(self.P)
        if path in self.model.theta_paths:
            d[self.model.theta_paths.index(path)] = 1.0
        return d

    def dp_of(self, p: np.ndarray) -> np.ndarray:
        """d p / d theta of a configuration's parameter vector: its lock values'."""
        model = self.model
        nl = len(model.locks)
        out = np.zeros((model.n_params, self.P))
        for k, j in enumerate(model.locks):
            if p[k] == 1.0:
                out[nl + k] = self.dL[j]
        return out

    def kkt_d(self, q, v, t, p, dP, sq, sv):
        """(a, lambda), their total derivatives (nq + m, P) from (s_q, s_v, dP), and
        their time derivatives along the flow (nq + m,)."""
        model = self.model
        a, lam, _ = model.kkt(q, v, t, p)
        z = np.concatenate([a, lam])
        K, Rq, Rv, Rt, Rp, Rth = self.eq.kkt(q, v, t, p, self.th, z)
        rhs = Rq @ sq + Rv @ sv + Rp @ dP + Rth
        dz = -np.linalg.solve(K, rhs)
        zdot = -np.linalg.solve(K, Rq @ v + Rv @ a + Rt.ravel())
        return a, lam, dz, zdot

    def project(self, q, v, t, p, dP, sq, sv):
        """Sensitivities made consistent with the active constraints at fixed time (the
        derivative of the run's own projections at a segment start)."""
        act = self.model.active_rows(p)
        if act.size == 0:
            return sq, sv
        _, Phi_q, _, Phi_p, Phi_th = self.eq.pos(q, t, p, self.th)
        A = Phi_q[act]
        r = A @ sq + (Phi_p @ dP + Phi_th)[act]
        sq = sq - np.linalg.lstsq(A, r, rcond=None)[0]
        _, h_q, _, h_p, h_th = self.eq.vel(q, v, t, p, self.th)
        r = h_q[act] @ sq + A @ sv + (h_p @ dP + h_th)[act]
        sv = sv - np.linalg.lstsq(A, r, rcond=None)[0]
        return sq, sv

    # ---- the start
    def start(self, q0: np.ndarray, v0: np.ndarray, start_events) -> tuple:
        model, mech = self.model, self.model.mech
        known, rates = start_spec(mech)
        p0 = model.params()
        act = model.active_rows(p0)

        def d_of(prefix: str, names) -> np.ndarray:
            return np.array([self.unit(f"{prefix}.{n}") for n in names]).reshape(-1, self.P)

        kidx = [model.jidx[n] for n in known]
        _, Phi_q, _, Phi_p, Phi_th = self.eq.pos(q0, 0.0, p0, self.th)
        _, cd, c_q, cd_q, c_th, cd_th = self.eq.coords(q0, v0, self.th)
        G_q = np.vstack([Phi_q[act], c_q[kidx]])
        # a joint coordinate depends on the parameters itself where they move its points
        G_th = np.vstack([Phi_th[act], c_th[kidx] - d_of("initial.joints", list(known))])
        sq = -np.linalg.lstsq(G_q, G_th, rcond=None)[0]
        ridx = [model.jidx[n] for n in rates]
        _, h_q, _, _, h_th = self.eq.vel(q0, v0, 0.0, p0, self.th)
        V_v = np.vstack([Phi_q[act], c_q[ridx]])
        V_q = np.vstack([h_q[act], cd_q[ridx]])
        V_th = np.vstack([h_th[act], cd_th[ridx] - d_of("initial.velocities", list(rates))])
        sv = -np.linalg.lstsq(V_v, V_q @ sq + V_th, rcond=None)[0]
        for e in start_events:  # locks on a stop or sticking at t = 0
            if e.kind == "lock":
                self.dL[e.joint] = self.unit(f"joints.{e.joint}.limits.{e.side}")
            elif e.kind == "stick":
                k = model.jidx[e.joint]
                self.dL[e.joint] = c_q[k] @ sq + c_th[k]
        return sq, sv

    # ---- a segment
    def segment(self, seg: SegmentTrace, sq: np.ndarray, sv: np.ndarray):
        """Integrate the state and its sensitivities through one traced segment; returns
        (q, v, s_q, s_v) at its end (before any event).

        Where IDA with the sensitivities gives up near a singular position (a little
        before the run's own IDA did, or at one the run's IDA stepped over), the way on is
        the crossing's (:func:`cmm_dae.singular.step_over` from IDA's last state, replayed
        with its tangents, the outputs inside it as a crossing records them), and IDA
        starts again after it for the rest of the segment."""
        model = self.model
        nq = model.nq
        p = seg.p
        dP = self.dp_of(p)
        t0 = seg.t0
        q, v = project_state(model, seg.q, seg.v, t0, p)
        sq, sv = self.project(q, v, t0, p, dP, sq, sv)
        times = self.res.t[seg.n0:seg.n1]
        for i in range(seg.n0, seg.n1):
            self.dP[i], self.params[i] = dP, p
        # the output times, each a clear step after the one before (a sample a hair after
        # another, next to an event, is read from its neighbour below)
        want: list[float] = []
        for x in times:
            near = ev.ZENO_DT * max(1.0, abs(x))
            if want and x - want[-1] <= near:
                want[-1] = x  # the later one: the segment's end stays an output
            elif want or x - t0 > near:
                want.append(x)
        if not want:  # a segment of no length: the state and sensitivities as they start
            self.sq[seg.n0:seg.n1], self.sv[seg.n0:seg.n1] = sq, sv
            return q, v, sq, sv
        T_all: list[float] = []
        Sq_all: list[np.ndarray] = []
        Sv_all: list[np.ndarray] = []
        relaxed = seg.relaxed
        t = t0
        while True:
            outs = [x for x in want if x > t + ev.ZENO_DT * max(1.0, abs(t))]
            r, T, Y, S = ida_segment(self, t, q, v, sq, sv, p, dP, outs, relaxed, seg.lambda_scale)
            # (after a failure the last row is the step IDA ended on, not an output time)
            rows = [k for k in range(T.size) if T[k] in outs]
            T_all += [float(T[k]) for k in rows]
            Sq_all += [S[k, :nq] for k in rows]
            Sv_all += [S[k, nq:2 * nq] for k in rows]
            if r.status >= 0:
                q, v, sq, sv = Y[-1, :nq], Y[-1, nq:2 * nq], S[-1, :nq], S[-1, nq:2 * nq]
                break
            t_f = float(np.asarray(r.t)[-1])
            if not T.size or t_f <= t:
                raise SolverError(f"the sensitivity integration failed at t = {t_f:.9g} s: "
                                  f"IDA: {r.message}", status=Status.INTEGRATOR)
            q, v, sq, sv = Y[-1, :nq], Y[-1, nq:2 * nq], S[-1, :nq], S[-1, nq:2 * nq]
            try:
                cr = step_over(model, p, t_f, q, v, outs[-1], rtol=self.rtol, atol=self.atol)
            except SolverError:
                raise SolverError(f"the sensitivity integration failed at t = {t_f:.9g} s: "
                                  f"IDA: {r.message}", status=Status.INTEGRATOR) from None
            rp = self._replay(cr, sq, sv, p, dP)
            for x in outs:
                if t_f < x <= cr.t_after:
                    zq, zv = self.inside(cr, rp, x, p, dP)
                    T_all.append(x)
                    Sq_all.append(zq)
                    Sv_all.append(zv)
            self.notes.append(f"segment from t = {t0:.9g} s: IDA with the sensitivities "
                              f"stopped at t = {t_f:.9g} s near a singular position; "
                              f"the crossing's Gauss steps took them on to "
                              f"{cr.t_after:.9g} s")
            t, q, v = cr.t_after, cr.q, cr.v
            sq, sv = self.project(q, v, t, p, dP, rp.ends[-1][3], rp.ends[-1][4])
            relaxed = True
            if t >= want[-1] * (1.0 - 1e-15) or not [x for x in want if x > t]:
                break
        T = np.array(T_all)
        if T.size != len(want):
            raise SolverError(f"the sensitivity integration returned {T.size} of "
                              f"{len(want)} output times in the segment from t = {t0:.9g} s",
                              status=Status.INTEGRATOR)
        Sq, Sv = np.array(Sq_all), np.array(Sv_all)
        # each sample from the nearest output (the same time but for merged neighbours)
        hi = np.clip(np.searchsorted(T, times), 0, T.size - 1)
        lo = np.clip(hi - 1, 0, T.size - 1)
        idx = np.where(np.abs(T[lo] - times) < np.abs(T[hi] - times), lo, hi)
        self.sq[seg.n0:seg.n1] = Sq[idx]
        self.sv[seg.n0:seg.n1] = Sv[idx]
        return q.copy(), v.copy(), Sq[-1].copy(), Sv[-1].copy()

    # ---- events
    def events(self, seg: SegmentTrace, q, v, sq, sv, n: int):
        """Apply the traced events at the segment's end; returns (s_q, s_v, next sample
        index)."""
        model, eq = self.model, self.eq
        t = seg.t1
        p = seg.p
        dP = self.dp_of(p)
        for trig, done, p_after in seg.groups:
            if not done:
                continue
            # the event time's derivative from the function that located it
            a, lam, dz, zdot = self.kkt_d(q, v, t, p, dP, sq, sv)
            g, g_q, g_v, g_th, g_l = (np.ravel(x) for x in
                                      eq.event_function(seg, trig)(q, v, self.th, lam))
            nq = model.nq
            num = g_q @ sq + g_v @ sv + g_th + g_l @ dz[nq:]
            rate = float(g_q @ v + g_v @ a + g_l @ zdot[nq:])
            if rate == 0.0 or not math.isfinite(rate):
                raise SolverError(f"the event at t = {t:.9g} s is grazing (its event "
                                  "function has zero rate): its time is not "
                                  "differentiable", status=Status.NUMERICAL)
            tau = -num.ravel() / rate
            zq, zv = sq + np.outer(v, tau), sv + np.outer(a, tau)
            for tr, pa in zip(done, p_after, strict=True):
                e = tr.event  # (a singular crossing is no trigger's transition)
                if e.kind in ("lock", "limit", "landing", "bounce", "stick"):
                    zq, zv = self._impact(e, tr, v, t, p, dP, pa, zq, zv, tau)
                p = pa
                dP = self.dp_of(p)
                a1, _, _, _ = self.kkt_d(tr.q, tr.v, t, p, dP, zq, zv)
                q, v = tr.q, tr.v
                sq, sv = zq - np.outer(v, tau), zv - np.outer(a1, tau)
                self.tau.append(tau)
                self.sq[n], self.sv[n], self.dP[n], self.params[n] = sq, sv, dP, p
                n += 1
        return q, v, sq, sv, n

    def _impact(self, e, tr, vm, t, p_before, dP_before, p_after, zq, zv, tau):
        """Derivative of the impact map (and of the projection onto the new lock)."""
        model, eq = self.model, self.eq
        j = e.joint
        k = model.locks.index(j)
        nl = len(model.locks)
        jk = model.jidx[j]
        if e.kind == "stick":
            p_lock = p_after
            co = eq.coords(tr.q, tr.v, self.th)
            self.dL[j] = co[2][jk] @ zq + co[4][jk]
        else:
            p_lock = p_before.copy()
            p_lock[k] = 1.0
            stops = model.joints[j].stops
            p_lock[nl + k] = stops.lower if e.side == "lower" else stops.upper
            self.dL[j] = self.unit(f"joints.{j}.limits.{e.side}")
        dPl = dP_before.copy()
        dPl[nl + k] = self.dL[j]
        q = tr.q
        # positions: onto the stop (first-order consistent already; this removes drift)
        act = model.active_rows(p_lock)
        _, Phi_q, Phi_t, Phi_p, Phi_th = eq.pos(q, t, p_lock, self.th)
        A = Phi_q[act]
        r = A @ zq + np.outer(Phi_t[act], tau) + (Phi_p @ dPl + Phi_th)[act]
        zq = zq - np.linalg.lstsq(A, r, rcond=None)[0]
        # velocities: the impact map's derivative
        row = model.n_fixed + k
        erow = np.zeros(model.m)
        erow[row] = 1.0
        oh = np.zeros(len(model.jidx))
        oh[jk] = 1.0
        if e.kind == "bounce":
            tgt, t_q, t_v, t_th = eq.tgt(q, vm, self.th, oh)
            tgt = tgt.item()
        else:
            tgt, t_q, t_v, t_th = 0.0, np.zeros((1, model.nq)), np.zeros((1, model.nq)), \
                np.zeros((1, self.P))
        z = np.concatenate(ev.impact_map(model, q, vm, t, p_lock, row, tgt))
        K, Rq, Rv, Rt, Rp, Rth, Rtg = eq.imp(q, vm, t, p_lock, self.th, erow, tgt, z)
        dtg = (np.reshape(t_q, (1, -1)) @ zq + np.reshape(t_v, (1, -1)) @ zv).ravel() \
            + np.ravel(t_th)
        rhs = Rq @ zq + Rv @ zv + np.outer(Rt, tau) + Rp @ dPl + Rth + np.outer(Rtg, dtg)
        dz = -np.linalg.solve(K, rhs)
        return zq, dz[:model.nq]

    # ---- outputs
    def outputs(self) -> dict[str, np.ndarray]:
        model, eq, res = self.model, self.eq, self.res
        n, nq, P = res.t.size, model.nq, self.P
        nj, nd = len(model.joint_names), len(model.driver_names)
        ng = len(model.mech.gears)
        out = np.zeros((n, eq.n_out, P))
        acc = np.zeros((n, nq, P))
        for i in range(n):
            p = self.params[i]
            if p is None:
                continue
            q, v, t = res.data["q"][i], res.data["v"][i], float(res.t[i])
            sq, sv, dP = self.sq[i], self.sv[i], self.dP[i]
            a, lam, dz, _ = self.kkt_d(q, v, t, p, dP, sq, sv)
            _, O_q, O_v, O_a, O_th, O_l = eq.out(q, v, a, p, self.th, lam)
            out[i] = O_q @ sq + O_v @ sv + O_a @ dz[:nq] + O_l @ dz[nq:] + O_th
            acc[i] = dz[:nq]
        o = 0
        d = {}
        dim = model.dim  # (a spatial joint's force and moment are 3-vectors)
        for key, w in (("c", nj), ("cd", nj), ("cdd", nj), ("jforce", dim * nj),
                       ("jtorque", nj * (3 if dim == 3 else 1)), ("effort", nd),
                       ("gforce", 2 * ng)):
            d[key] = out[:, o:o + w]
            o += w
        d["jforce"] = d["jforce"].reshape(n, nj, dim, P)
        if dim == 3:
            d["jtorque"] = d["jtorque"].reshape(n, nj, 3, P)
        d["gforce"] = d["gforce"].reshape(n, ng, 2, P)
        d["q"], d["v"], d["a"] = self.sq, self.sv, acc
        return d


