"""The sensitivity pass over a traced run (:func:`cmm_dae.sensitivities`): the start from
the assembly equations, each configuration segment integrated by IDA with its sensitivity
equations, the jump at every event, the derivatives of the Result's series."""

from __future__ import annotations

import math

import numpy as np
import sksundae as sun

from ..core.errors import SolverError, Status
from ..equations.kinematics import project_state
from ..equations.model import Buffered, Model
from ..hybrid import policy as ev
from ..hybrid.start import start_spec
from ..hybrid.state import SegmentTrace
from ..integrators.ida_steps import quiet_sundials
from ..integrators.tolerances import ATOL_MU, lambda_atol, natural_step
from ..results.result import Result
from ..singular.step import step_over
from .crossing import CrossingPass
from .model import Equations

__all__ = ["ATOL_OFF", "LOOSE", "SensitivityPass"]

#: Absolute tolerance on the multipliers' sensitivities: out of IDA's error test.
ATOL_OFF = 1e6
#: Without ``error_control`` the position and velocity sensitivities are held to this many
#: times the state's absolute tolerance (per unit of parameter): entirely out of the test,
#: IDA took 107,163 residual evaluations instead of 1,123 on the slider-crank with a stop;
#: entirely in it, 138,780 instead of 1,258 on a soft-spring double-folded design. 1e2 and
#: 1e3 kept both near the plain cost, 1e4 did not.
LOOSE = 1e3


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
            r, T, Y, S = self._ida(t, q, v, sq, sv, p, dP, outs, relaxed, seg.lambda_scale)
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
            ends = self._replay(cr, sq, sv, p, dP)
            for x in outs:
                if t_f < x <= cr.t_after:
                    zq, zv = self.inside(cr, ends, x, p, dP)
                    T_all.append(x)
                    Sq_all.append(zq)
                    Sv_all.append(zv)
            self.notes.append(f"segment from t = {t0:.9g} s: IDA with the sensitivities "
                              f"stopped at t = {t_f:.9g} s near a singular position; "
                              f"the crossing's Gauss steps took them on to "
                              f"{cr.t_after:.9g} s")
            t, q, v = cr.t_after, cr.q, cr.v
            sq, sv = self.project(q, v, t, p, dP, ends[-1][3], ends[-1][4])
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

    def _ida(self, t0, q, v, sq, sv, p, dP, outs, relaxed, k=1.0):
        """IDA on the state and its sensitivities from t0 to the output times ``outs``;
        (IDA's result, the times, states and sensitivities (n, N, P) after t0). ``k``: the
        run's factor on the multipliers' absolute tolerances (its force scale)."""
        model, eq = self.model, self.eq
        nq, m, N, P = model.nq, model.m, model.N, self.P
        a, lam, dz, _ = self.kkt_d(q, v, t0, p, dP, sq, sv)
        S0 = np.zeros((N, P))
        S0[:nq], S0[nq:2 * nq], S0[2 * nq:2 * nq + m] = sq, sv, dz[nq:]
        Sp0 = np.zeros((N, P))
        Sp0[:nq], Sp0[nq:2 * nq] = sv, dz[:nq]
        y0 = np.concatenate([q, v, lam, np.zeros(m)])
        yp0 = np.concatenate([v, a, np.zeros(2 * m)])
        Y0 = np.concatenate([y0, S0.ravel(order="F")])
        Yp0 = np.concatenate([yp0, Sp0.ravel(order="F")])
        dPv = dP.ravel(order="F")
        th = self.th
        t_arr, cj_arr = np.zeros(1), np.zeros(1)
        n_all = Y0.size
        y_in, yp_in, r_out = np.zeros(n_all), np.zeros(n_all), np.zeros(n_all)
        res = Buffered(eq.res)
        for i, arr in enumerate((t_arr, y_in, yp_in, p, dPv, th)):
            res.bind(i, arr)
        res.bind_out(0, r_out)
        jac = Buffered(eq.jac)
        for i, arr in enumerate((t_arr, y_in, yp_in, cj_arr, p, dPv, th)):
            jac.bind(i, arr)
        bound = [None]

        def resfn(t, y, yp, out):
            t_arr[0] = t
            y_in[:] = y
            yp_in[:] = yp
            res.run()
            out[:] = r_out

        def jacfn(t, y, yp, rr, cj, JJ):
            t_arr[0], cj_arr[0] = t, cj
            y_in[:] = y
            yp_in[:] = yp
            if JJ is not bound[0]:
                jac.bind_out(0, JJ)
                bound[0] = JJ
            jac.run()

        scale = np.maximum(np.abs(th), 1e-300)
        scale[th == 0.0] = 1.0
        # the multipliers as the run had them (out of the test after a singular position)
        base = np.concatenate([np.full(2 * nq, self.atol), np.full(m, lambda_atol(relaxed, k)),
                               np.full(m, ATOL_MU)])
        # the multipliers' sensitivities stay out of the error test (index-2 variables:
        # in it, IDA failed to converge at rtol 1e-12 on the double-folded mechanism)
        off = np.concatenate([np.zeros(2 * nq), np.full(2 * m, ATOL_OFF)])
        alg = [k for i in range(P + 1) for k in range(i * N + 2 * nq, (i + 1) * N)]
        tspan = np.concatenate([[t0], outs])
        extra = None
        if tspan.size == 2:  # scikit-sundae returns its own steps for two points
            extra = 0.5 * (tspan[0] + tspan[1])
            tspan = np.array([tspan[0], extra, tspan[1]])
        # the first step from the accelerations, not IDA's from y' alone (tiny at tight
        # tolerances, where the Newton matrix's noise kept the steps tiny: natural_step)
        h0 = natural_step(q, a, self.rtol, self.atol, float(tspan[-1]) - t0)
        for control in ((True, False) if self.error_control else (False,)):
            atol = np.concatenate([base] + [np.maximum(base / scale[i] * (1.0 if control
                                                                          else LOOSE), off)
                                            for i in range(P)])
            solver = sun.ida.IDA(resfn, jacfn=jacfn, rtol=self.rtol, atol=atol,
                                 algebraic_idx=alg, max_num_steps=10**7, first_step=h0)
            with quiet_sundials():
                r = solver.solve(tspan, Y0, Yp0)
            self.nfev += int(r.nfev)
            if r.status >= 0 or not control:
                break
            # a restart just after an impact can fail the error test on the jumped
            # sensitivities alone: the segment again with them following the state's steps
            self.notes.append(f"segment from t = {t0:.9g} s: the sensitivities were left "
                              "out of the error test (IDA failed with them in it)")
        Y = np.asarray(r.y)
        T = np.asarray(r.t)
        if extra is not None:
            keep = (extra != T) | (np.arange(T.size) == T.size - 1)
            Y, T = Y[keep], T[keep]
        Y, T = Y[1:], T[1:]
        S = Y[:, N:].reshape(-1, P, N).transpose(0, 2, 1)  # (n, N, P)
        return r, T, Y, S

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
            stops = model.mech.joints[j].stops
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
        oh = np.zeros(len(model.joint_names))
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
        for key, w in (("c", nj), ("cd", nj), ("cdd", nj), ("jforce", 2 * nj),
                       ("jtorque", nj), ("effort", nd)):
            d[key] = out[:, o:o + w]
            o += w
        d["jforce"] = d["jforce"].reshape(n, nj, 2, P)
        d["q"], d["v"], d["a"] = self.sq, self.sv, acc
        return d


