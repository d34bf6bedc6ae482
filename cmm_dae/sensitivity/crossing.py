"""The sensitivity pass through singular positions (:mod:`cmm_dae.singular`): the
crossing's Gauss steps replayed with their derivative, and the singular instant's own
derivative. A part of :class:`~cmm_dae.sensitivity.replay.SensitivityPass`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..equations.kinematics import project_state, singular_ratio
from ..hybrid.state import SegmentTrace
from ..singular.gauss import GL_A, GL_B, dense, gl2_step
from ..singular.instant import hermite, null_vectors

__all__ = ["CrossingPass", "Replay", "TAU_RATIO"]

#: Singular-value ratio at which the singular instant's derivative is taken on either side
#: of it (round-off in the singular vectors about 1e-16 / TAU_RATIO, the two sides' mean
#: off by the square of their distance).
TAU_RATIO = 1e-6


@dataclass
class Replay:
    """A crossing's Gauss steps replayed with their tangents: the step ends [(t, q, v, s_q,
    s_v)], each step's stage tangents' difference (the derivative of ``Crossing.dk``) and
    the end accelerations' tangents computed so far, by end."""

    ends: list
    dl: list = field(default_factory=list)
    da: dict = field(default_factory=dict)


class CrossingPass:
    """The crossing part of the sensitivity pass (it uses the pass's ``model``, ``eq``,
    ``th``, ``P``, ``project``, ``kkt_d``, ``dp_of``, ``tau``, ``notes`` and sample
    arrays)."""

    def crossing(self, seg: SegmentTrace, sq: np.ndarray, sv: np.ndarray, n: int):
        """Carry the sensitivities through the singular-position crossing after ``seg``:
        the derivative of the run's own Gauss steps (replayed: the same steps from the
        same state, :meth:`_gauss_tangent`). The motion is smooth there, so nothing jumps; the
        singular instant's derivative comes from the signed collapsing singular value
        (:meth:`Equations.singular_function`). Returns (q, v, s_q, s_v) after it."""
        cr = seg.crossing  # never a branch switch: refused before the pass
        p = seg.p
        dP = self.dp_of(p)
        rp = self._replay(cr, sq, sv, p, dP)
        ends = rp.ends
        if seg.crossing_logged:
            self.tau.append(self._singular_tau(p, dP, ends, cr.t_singular))
        # the output grid inside the window (the run recorded it from the crossing's steps)
        t = self.res.t
        while n < t.size - 1 and t[n] < cr.t_after:
            self.sq[n], self.sv[n] = self.inside(cr, rp, float(t[n]), p, dP)
            self.dP[n], self.params[n] = dP, p
            n += 1
        q, v = cr.q, cr.v
        sq, sv = self.project(q, v, cr.t_after, p, dP, ends[-1][3], ends[-1][4])
        self.sq[n], self.sv[n], self.dP[n], self.params[n] = sq, sv, dP, p
        return q, v, sq, sv

    def passage_tau(self, p, t_s: float, k: int) -> np.ndarray:
        """d t_singular / d theta of a singular position IDA integrated through between
        samples ``k - 1`` and ``k`` (after the segment holding them has been integrated):
        as for a crossing, with the state and its sensitivities interpolated between
        those two samples."""
        d = self.res.data
        ends = [(float(self.res.t[i]), d["q"][i], d["v"][i], self.sq[i], self.sv[i])
                for i in (k - 1, k)]
        return self._singular_tau(p, self.dp_of(p), ends, t_s)

    def _singular_tau(self, p, dP, ends: list, t_s: float) -> np.ndarray:
        """d t_singular / d theta: the root of the signed smallest singular value
        ``w . (Phi_q n)`` with its singular vectors held fixed, the state and its
        sensitivities interpolated between the crossing's step ends (cubic Hermite:
        s_q' = s_v).

        At the singular instant itself the right null space is two-dimensional (the
        motion's direction and the new one) and the singular vectors are undetermined, so
        the derivative is the mean of the values a little before and after it, where the
        singular-value ratio is ``TAU_RATIO``: the mean is off by the square of that
        distance, the singular vectors by round-off over the ratio. Where the instant
        lay before the crossing's start (the integrator had stepped across it), one Gauss
        step back reaches it."""
        model = self.model

        def tau_at(t, q, v, sq, sv):
            w, n = null_vectors(model, p, q, t)
            g, g_q, g_t, g_p, g_th = self.eq.singular_function()(q, t, p, self.th, w, n)
            rate = float((g_q @ v).item() + g_t.item())
            return -np.ravel(g_q @ sq + g_p @ dP + g_th) / rate

        if t_s < ends[0][0]:
            # the integrator had stepped across the instant and failed just beyond it: one
            # Gauss step back to it (its nodes lie between, off the instant)
            t0, q0, v0, sq0, sv0 = ends[0]
            guess = model.kkt(q0, v0, t0, p)[0]
            back = self._gauss_tangent(t0, q0, v0, sq0, sv0, t_s - t0, guess, p, dP)
            ends = [(t_s, *back[:4])] + list(ends)
        k = next((k for k in range(len(ends) - 1) if ends[k][0] <= t_s <= ends[k + 1][0]),
                 None)
        if k is None:  # beyond the crossing's end (it ended at the run's end)
            self.notes.append(f"the singular instant at t = {t_s:.9g} s lies beyond the "
                              f"crossing's end: its derivative is taken there")
            return tau_at(*ends[-1])
        a, b = ends[k], ends[k + 1]
        far = a if t_s - a[0] > b[0] - t_s else b
        slope = singular_ratio(model, far[1], far[0], p) / abs(far[0] - t_s)
        d = TAU_RATIO / slope
        out = []
        for t in (t_s - d, t_s + d):
            q, v = hermite(a[0], a[1], a[2], b[0], b[1], b[2], t)
            sq, sv = hermite(a[0], a[3], a[4], b[0], b[3], b[4], t)
            out.append(tau_at(t, q, v, sq, sv))
        return 0.5 * (out[0] + out[1])

    def inside(self, cr, rp: Replay, t: float, p, dP) -> tuple[np.ndarray, np.ndarray]:
        """(s_q, s_v) at a time t inside the crossing ``cr`` (replayed as ``rp``): the
        derivative of how :meth:`~cmm_dae.singular.Crossing.state_at` reads the step there
        (the same quintic on the tangents, those of the end accelerations from the KKT
        system's derivative), projected as that state is."""
        k = cr.interval(t)
        accels = [cr.end_accel(self.model, p, i) for i in (k, k + 1)]
        tangents = [self._end_tangent(cr, rp, i, p, dP) for i in (k, k + 1)]
        (t0, q0, v0, sq0, sv0), (t1, q1, v1, sq1, sv1) = rp.ends[k], rp.ends[k + 1]
        q, v = dense(t0, q0, v0, accels[0], t1, q1, v1, accels[1], cr.dk[k], t)
        sq, sv = dense(t0, sq0, sv0, tangents[0], t1, sq1, sv1, tangents[1], rp.dl[k], t)
        q, v = project_state(self.model, q, v, t, p)
        return self.project(q, v, t, p, dP, sq, sv)

    def _end_tangent(self, cr, rp: Replay, i: int, p, dP) -> np.ndarray | None:
        """The derivative of the accelerations at the crossing's step end i (None at the
        singular instant, where the stage tangents' difference stands in), once per end."""
        if i not in rp.da:
            got = cr.end_state(self.model, p, i)
            if got is None:
                rp.da[i] = None
            else:
                qp, vp, _ = got
                te, _, _, sqe, sve = rp.ends[i]
                zq, zv = self.project(qp, vp, te, p, dP, sqe, sve)
                rp.da[i] = self.kkt_d(qp, vp, te, p, dP, zq, zv)[2][:self.model.nq]
        return rp.da[i]

    def _replay(self, cr, sq, sv, p, dP) -> Replay:
        """The crossing's Gauss steps again from its start, with their tangents."""
        tt, qq, vv = cr.ends[0]
        guess = self.model.kkt(qq, vv, tt, p)[0]
        rp = Replay([(tt, qq, vv, sq, sv)])
        for h in cr.steps:
            qq, vv, sq, sv, guess = self._gauss_tangent(tt, qq, vv, sq, sv, h, guess, p, dP,
                                                        rp.dl)
            tt += h
            rp.ends.append((tt, qq, vv, sq, sv))
        return rp

    def _gauss_tangent(self, t, q, v, sq, sv, h, guess, p, dP, dl: list | None = None):
        """One Gauss step of the crossing (:func:`cmm_dae.singular.gauss.gl2_step`) and its
        derivative: the Gauss method on the variational equations, the stage tangents made
        consistent with the constraints as the stage states are (the derivative of the
        projections); returns (q, v, s_q, s_v, next guess). ``dl``, when given, receives
        the stage tangents' difference (the derivative of :attr:`Crossing.dk`)."""
        nq = self.model.nq
        stages: list = []
        qn, vn, guess = gl2_step(self.model, p, t, q, v, h, guess, stages)
        L = np.zeros((2, nq, self.P))
        for _ in range(50):  # the stages' linear equations, by the state's iteration
            dV = sv[None] + h * np.einsum("ij,jkl->ikl", GL_A, L)
            dQ = sq[None] + h * np.einsum("ij,jkl->ikl", GL_A, dV)
            Ln = np.empty_like(L)
            for i, (ti, Qi, Vi) in enumerate(stages):
                zq, zv = self.project(Qi, Vi, ti, p, dP, dQ[i], dV[i])
                Ln[i] = self.kkt_d(Qi, Vi, ti, p, dP, zq, zv)[2][:nq]
            change = float(np.max(np.abs(Ln - L)))
            L = Ln
            if change <= 1e-13 * (1.0 + float(np.max(np.abs(L)))):
                break
        dV = sv[None] + h * np.einsum("ij,jkl->ikl", GL_A, L)
        if dl is not None:
            dl.append(L[1] - L[0])
        return (qn, vn, sq + h * np.einsum("i,ikl->kl", GL_B, dV),
                sv + h * np.einsum("i,ikl->kl", GL_B, L), guess)
