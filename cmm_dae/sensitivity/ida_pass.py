"""IDA on a segment's state and its sensitivities together (the sensitivity replay's
integrator, for :class:`~.replay.SensitivityPass`)."""

from __future__ import annotations

import numpy as np

from ..equations.model import Buffered
from ..integrators.ida_steps import ida_class, quiet_sundials
from ..integrators.tolerances import ATOL_MU, lambda_atol, natural_step

__all__ = ["ATOL_OFF", "LOOSE", "ida_segment"]

#: Absolute tolerance on the multipliers' sensitivities: out of IDA's error test.
ATOL_OFF = 1e6
#: Without ``error_control`` the position and velocity sensitivities are held to this many
#: times the state's absolute tolerance (per unit of parameter): entirely out of the test,
#: IDA took 107,163 residual evaluations instead of 1,123 on the slider-crank with a stop;
#: entirely in it, 138,780 instead of 1,258 on a soft-spring double-folded design. 1e2 and
#: 1e3 kept both near the plain cost, 1e4 did not.
LOOSE = 1e3


def ida_segment(self, t0, q, v, sq, sv, p, dP, outs, relaxed, k=1.0):
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
        solver = ida_class()(resfn, jacfn=jacfn, rtol=self.rtol, atol=atol,
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
