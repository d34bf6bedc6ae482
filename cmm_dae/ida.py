"""One IDA integration in one configuration (scikit-sundae): the index-2 (GGL) residual
and its exact Jacobian through ``casadi.Function.buffer()``, event functions, outputs.

This is the only module that imports scikit-sundae; the hybrid loop around it is in
:mod:`cmm_dae.dae`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import sksundae as sun

from . import events as ev
from .equations import Model
from .errors import CmmError, SolverError
from .result import Stats

if TYPE_CHECKING:  # pragma: no cover
    from .dae import Options, _Recorder


#: Absolute tolerances on the multipliers. Both are index-2 variables of the GGL form and
#: scikit-sundae cannot suppress them from the error test. mu (zero on the exact solution)
#: gets a huge tolerance, which takes it out of the test (with 1e-8 IDA fails at t = 0).
#: lambda, the constraint forces in N or N m, must still converge in the Newton iteration,
#: since the accelerations depend on it: with 1e3 the slider-crank with a stop needed 2.8x
#: the steps and 6x the residual evaluations at rtol 1e-8 (convergence failures); 1e-2 N
#: was the most robust value over the shipped models and rtol 1e-6 .. 1e-12.
ATOL_LAMBDA = 1e-2
ATOL_MU = 1e3


class _Buffered:
    """A CasADi function evaluated through its buffer API into fixed numpy arrays."""

    def __init__(self, fn, inputs: list[np.ndarray], output: np.ndarray | None = None):
        self.buf, self.call = fn.buffer()
        self.inputs = inputs
        for i, arr in enumerate(inputs):
            self.buf.set_arg(i, memoryview(arr))
        self.out = output if output is not None else np.zeros(fn.nnz_out(0))
        self.buf.set_res(0, memoryview(self.out))

    def set(self, i: int, arr: np.ndarray) -> None:
        self.buf.set_arg(i, memoryview(arr))


def _output_times(opts: Options, t0: float) -> np.ndarray:
    if opts.output_dt is None:
        return np.array([opts.t_end])
    n = int(math.floor(opts.t_end / opts.output_dt + 1e-9))
    grid = opts.output_dt * np.arange(1, n + 1)
    grid = grid[grid > t0 + 1e-12 * max(1.0, opts.t_end)]
    if grid.size == 0 or grid[-1] < opts.t_end - 1e-12 * opts.t_end:
        grid = np.append(grid, opts.t_end)
    return grid


class _StalledError(Exception):
    """Raised inside the root function when the run's step budget is spent."""


class _Segment:
    """One IDA integration in one configuration, until t_end or the first event."""

    def __init__(self, model: Model, hs: ev.HybridState, opts: Options):
        self.model, self.hs, self.opts = model, hs, opts
        self.p = hs.p.copy()
        N, nq = model.N, model.nq
        self.events = ev.event_list(hs)
        self.has_push = any(kind == "push" for _, _, kind in self.events)
        self.t_arr = np.zeros(1)
        self.cj_arr = np.zeros(1)
        dummy = np.zeros(N)
        self.res = _Buffered(model.res_fn, [self.t_arr, dummy, dummy, self.p])
        self.jac_out = None
        self.atol = np.concatenate([np.full(2 * nq, opts.atol), np.full(model.m, ATOL_LAMBDA),
                                    np.full(model.m, ATOL_MU)])
        self.n_steps = 0
        self.t_last = -math.inf
        self.outputs: set[float] = set()
        self.interrupted = False
        self.stalled = False
        self.step_budget = opts.max_steps

    def resfn(self, t, y, yp, res):
        self.t_arr[0] = t
        self.res.set(1, y)
        self.res.set(2, yp)
        self.res.call()
        res[:] = self.res.out

    def jacfn(self, t, y, yp, res, cj, JJ):
        if self.jac_out is None or self.jac_out.out is not JJ:
            self.jac_out = _Buffered(self.model.jac_fn, [self.t_arr, y, yp, self.cj_arr, self.p],
                                     output=JJ)
        self.t_arr[0] = t
        self.cj_arr[0] = cj
        self.jac_out.set(1, y)
        self.jac_out.set(2, yp)
        self.jac_out.call()

    def eventsfn(self, t, y, yp, out):
        # IDA checks the roots after every successful step (at the step's end, or at the
        # output time when the step passed it): count steps here.
        if t > self.t_last and t not in self.outputs:
            self.t_last = t
            self.n_steps += 1
            if self.n_steps > self.step_budget:
                raise _StalledError
        out[0] = 1.0  # keeps the root function alive for counting; never crosses zero
        if not self.events:
            return
        model = self.model
        nq = model.nq
        q, v = y[:nq], y[nq:2 * nq]
        if self.has_push:  # lock forces by a KKT solve at (q, v, t), never IDA's lambda
            c, cd, Phi_q, Qf, gamma = model.evparts(q, v, t, self.p)
            _, lam, _ = model.kkt_from(Phi_q, Qf, gamma, self.p)
        else:
            (c, cd), lam = model.cvel(q, v), None
        out[1:] = ev.event_values(self.hs, c, lam, self.events, cd)

    def run(self, t0: float, q: np.ndarray, v: np.ndarray, rec: _Recorder, first_step: float,
            stats: Stats, t_stop: float | None = None):
        model, opts = self.model, self.opts
        nq = model.nq
        # A state taken from IDA's interpolant at a root satisfies the constraints only to
        # the solver tolerance; restarting from it makes mu ~ Phi / h blow up as h shrinks.
        q = ev.project_positions(model, q, t0, self.p)
        v = ev.project_velocities(model, q, v, t0, self.p)
        a, lam, _ = model.kkt(q, v, t0, self.p)
        self.ratio0 = ev.dependent_rows(model, q, t0, self.p, tol=1.0)[1]
        y0 = np.concatenate([q, v, lam, np.zeros(model.m)])
        yp0 = np.concatenate([v, a, np.zeros(2 * model.m)])
        ne = 1 + len(self.events)

        # scikit-sundae keeps its event history on the function object: a fresh one per
        # segment, so no event of an earlier segment is seen again. A Ctrl-C inside a
        # callback would abort IDA and lose the segment's outputs: it is caught here and
        # turned into a root of the always-positive first event function instead, so IDA
        # returns what it has and the run stops with everything computed so far.
        def eventsfn(t, y, yp, out):
            try:
                self.eventsfn(t, y, yp, out)
            except KeyboardInterrupt:
                self.interrupted = True
            except _StalledError:
                self.stalled = self.interrupted = True
            if self.interrupted:
                out[:] = 1.0
                out[0] = -1.0

        def resfn(t, y, yp, res):
            try:
                self.resfn(t, y, yp, res)
            except KeyboardInterrupt:
                self.interrupted = True
                self.resfn(t, y, yp, res)

        eventsfn.direction = [0] + [-1] * len(self.events)
        eventsfn.terminal = [True] * ne
        solver = sun.ida.IDA(
            resfn, jacfn=self.jacfn, eventsfn=eventsfn, num_events=ne,
            rtol=opts.rtol, atol=self.atol, max_num_steps=opts.max_steps,
            first_step=first_step, algebraic_idx=list(range(2 * nq, model.N)))
        t_stop = opts.t_end if t_stop is None else t_stop
        outs = _output_times(opts, t0)
        if t_stop < opts.t_end:
            outs = np.append(outs[outs < t_stop - 1e-12 * max(1.0, t_stop)], t_stop)
        tspan = np.concatenate([[t0], outs])
        extra = None
        if tspan.size == 2:  # scikit-sundae returns internal steps for a 2-point tspan
            extra = 0.5 * (tspan[0] + tspan[1])
            tspan = np.array([tspan[0], extra, tspan[1]])
        # IDA evaluates the root functions at output times too: not steps
        self.outputs = set(tspan.tolist())
        try:
            r = solver.solve(tspan, y0, yp0)
        except CmmError:
            raise
        except Exception as e:  # an exception in a callback aborts IDA: say so plainly
            raise SolverError(f"the integration failed at t = {self.t_last:.9g} s: {e}") from e
        self._stats(stats, r)
        T, Y = np.asarray(r.t), np.asarray(r.y)
        keep = np.arange(1, T.size)
        if extra is not None:
            keep = keep[(T[keep] != extra) | (keep == T.size - 1)]
        rec.add_block(T[keep], Y[keep, :nq], Y[keep, nq:2 * nq], self.hs.current())
        if r.status < 0:
            raise SolverError(self._failure_message(r, float(T[-1]), Y[-1, :nq]))
        if r.status == 2 and self.stalled:
            raise SolverError(
                f"stalled at t = {float(T[-1]):.9g} s: more than {opts.max_steps} IDA steps "
                "in this run (tiny steps: a grazing contact, a near-singular position or "
                "forces too stiff for the tolerances); raise max_steps to go on")
        if r.status == 2 and self.interrupted:
            raise KeyboardInterrupt
        if r.status == 2:  # IDA_ROOT_RETURN: a terminal event ended the segment
            info = np.asarray(r.i_events)[-1]
            hit = int(np.flatnonzero(info[1:] != 0)[0])
            return float(T[-1]), Y[-1, :nq].copy(), Y[-1, nq:2 * nq].copy(), self.events[hit]
        if t_stop < opts.t_end:
            return float(T[-1]), Y[-1, :nq].copy(), Y[-1, nq:2 * nq].copy(), None
        return None

    def _stats(self, stats: Stats, r) -> None:
        stats.steps += self.n_steps
        stats.nfev += int(r.nfev)
        stats.njev += int(r.njev)

    def _failure_message(self, r, tt: float, q: np.ndarray) -> str:
        cfg = self.hs.configurations[self.hs.current()].label
        # the constraint rows' conditioning at the failure against the segment's start: a
        # dead point shows as a collapse of the smallest singular value (units mix, so
        # only the ratio of the two says anything)
        labels, ratio = ev.dependent_rows(self.model, q, tt, self.p, tol=1.0)
        if ratio < 0.2 * self.ratio0:
            what = (f"dead point at t = {tt:.6g} s: the constraints of {', '.join(labels)} "
                    f"become dependent (singular-value ratio {ratio:.1e}), so the mechanism "
                    "cannot follow its drivers through this position")
        else:
            what = (f"IDA could not continue at t = {tt:.9g} s (no dead point found: the "
                    "tolerances may be too tight or the forces too stiff)")
        return f"{what}; configuration '{cfg}'; IDA: {r.message} (status {r.status})"
