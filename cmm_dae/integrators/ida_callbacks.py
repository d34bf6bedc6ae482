"""IDA's callbacks for :class:`~.ida.IdaIntegrator`: the residual and its Jacobian
through CasADi's buffers, the root function (which also counts IDA's steps and tells a
crawl or a stall), the lock forces from a KKT solve near their thresholds, and the
tolerances that follow the state's round-off."""

from __future__ import annotations

import numpy as np

from ..core.memo import once
from ..equations.model import Buffered
from ..hybrid import policy as ev
from . import csegment, dips
from .exact_events import exact_parts
from .ida_steps import (
    IN_PLACE_STEPS,
    OUTGROWN,
    ROUNDOFF_ATOL,
    SLOW_STEPS,
    first_tout,
)
from .tolerances import natural_step

__all__ = ["IdaCallbacks"]


class IdaCallbacks:
    """The callbacks' half of :class:`~.ida.IdaIntegrator` (a mixin: the state they read,
    ``model``, ``u``, ``p``, the bound arrays and the segment's counters, is the
    integrator's)."""

    def _residual(self, t, y, yp, res):
        if self.model.callables:  # the callable loads' values at this state
            nq = self.model.nq
            self.p[:] = self.model.fill(self.p, t, y[:nq], y[nq:2 * nq])
        self.t_arr[0] = t
        self.y_in[:] = y
        self.yp_in[:] = yp
        self.res.run()
        res[:] = self.res_out

    def _jacobian(self, t, y, yp, res, cj, JJ):
        if self.jac is None:  # sparse: the nonzeros in CSC order, as JJ holds them
            self.jac = (Buffered(self.u.jac_sparse_fn, sparse=True) if self.sparse
                        else Buffered(self.u.jac_fn))
            for i, arr in enumerate((self.t_arr, self.y_in, self.yp_in, self.cj_arr, self.p)):
                self.jac.bind(i, arr)
        self.t_arr[0] = t
        self.cj_arr[0] = cj
        self.y_in[:] = y
        self.yp_in[:] = yp
        model = self.model
        if model.callables:
            nq = model.nq
            self.p[:] = model.fill(self.p, t, y[:nq], y[nq:2 * nq])
        if JJ is not self._jj:  # one array per solver: bound once per segment
            self.jac.bind_out(0, JJ)  # transposed in the model: JJ is row-major
            self._jj = JJ
        self.jac.run()
        if model.callables:  # M v' - Q = ...: the laws' own derivatives, which CasADi
            dq, dv = model.input_jacobian(t, y[:nq], y[nq:2 * nq])  # cannot see
            JJ[nq:2 * nq, :nq] -= dq
            JJ[nq:2 * nq, nq:2 * nq] -= dv

    def _after_step(self, t: float, nst: int) -> bool:
        """After each of IDA's steps on the Python path (step ``nst`` of the segment by
        IDA's count, ending at ``t``), the checks the compiled segment makes after each of
        its steps, in its order: more than IN_PLACE_STEPS steps in a row that do not move
        t (IDA halving next to a singular position), or SLOW_STEPS steps short of the
        segment's natural first step, are a crawl; more steps than the run's budget a
        stall. True ends the segment there."""
        if t - self.t_last > self.crawl_step:
            self.in_place = 0
        else:
            self.in_place += 1
            self.crawled = self.in_place > IN_PLACE_STEPS
        if nst == SLOW_STEPS and t - self.t_start < self.h_natural:
            self.crawled = True
        self.t_last = t
        self.stalled = not self.crawled and nst > self.step_budget
        if self.opts.progress is not None:
            self.opts.progress.update(t)
        return self.crawled or self.stalled

    def _dip(self, t0: float, t1: float, g0: np.ndarray, y1: np.ndarray, dky
             ) -> tuple[tuple[float, list[int]] | None, np.ndarray]:
        """After a step of the Python path from t0 to t1 (event values ``g0`` at t0, y1 at
        t1, ``dky`` its interpolant): the first gap that dipped beyond its stop inside it
        (:func:`.dips.locate`, as ``segment.c`` after each step), and the values at t1."""
        def g_at(t: float) -> np.ndarray:
            return self._lean(dky(t))

        g1 = self._lean(y1)
        return dips.locate(t0, t1, g0, g1, self.dips, g_at), g1

    def _lean(self, y: np.ndarray) -> np.ndarray:
        """The configuration's lean event functions at y (a gap's value is the same in the
        exact ones: the dip search reads them alone, as ``segment.c`` does)."""
        self.y_in[:] = y
        self.ev_fn.run()
        return self.ev_out.copy()

    def _events(self, t, y, yp, out):
        out[0] = 1.0  # (below zero only to end the segment: a Ctrl-C, an exception)
        if not self.triggers:
            return
        self.y_in[:] = y
        self.ev_fn.run()
        if self.has_push and (self.relaxed or self.ev_near[0] < 0.0):
            # Lock forces: the event function reads IDA's own multipliers, which are in the
            # error test and tell a force's sign while it is far from its threshold; near
            # it (or with the multipliers out of the test) the values come from a KKT solve,
            # so a root is located on the same function as always. The two agree to well
            # under the margin, so switching between them makes no sign change of its own.
            q, v = self.u.centroids(y[None, :])
            self._exact_events(t, q[0], v[0])
        out[:] = self.ev_out

    def _exact_events(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """Event values with the lock forces of a KKT solve at (q, v, t): the compiled
        segment's own graph (:mod:`.exact_events`), or with friction from the reaction
        (a nonlinear system) the model's solve."""
        model = self.model
        p = model.fill(self.p, t, q, v)
        if model.reacting:
            c, cd, _, _, _ = model.event_parts(q, v, t, p)
            _, lam, _ = model.kkt(q, v, t, p)
            ev.event_values(self.hs, c, cd, lam, self.triggers, self.ev_out[1:])
            return
        key = ("exact events", self.ev_key)
        fn = self._ev_cache.get(key)
        if fn is None:
            hs, triggers = self.hs, list(self.triggers)
            fn = self._ev_cache[key] = Buffered(once(
                model, key, lambda: exact_parts(model, hs, triggers).compose()))
        self.ev_out[:] = fn(t, self.y_in, p)[0]

    def _roundoff_atol(self, y: np.ndarray, check: bool = False) -> bool:
        """Raise the absolute tolerances of positions and of velocities to the round-off
        of their largest entry in ``y`` (:data:`ROUNDOFF_ATOL` of it) where the run's
        atol is below it; True when that raises them by more than :data:`OUTGROWN` (with
        ``check``: only tell, change nothing). A state that has grown so much since the
        segment's start (the squeezer's spin-up, 1e-14 to 3e-10) is what IDA failed on;
        a smaller rise (A02's speeds change by a few times near a singular position)
        leaves the failure to the singular-position logic."""
        nz = self.u.nz
        cur = self.atol[:2 * nz]
        new = np.empty_like(cur)
        for blk, raise_ in ((slice(0, nz), 1.0), (slice(nz, 2 * nz), self.v_raise)):
            floor = ROUNDOFF_ATOL * float(np.max(np.abs(y[blk]), initial=0.0))
            new[blk] = np.maximum(self.opts.atol, floor) * self.tol_scale * raise_
        raised = bool(np.any(new > OUTGROWN * cur))
        if not check:
            self.atol[:2 * nz] = new
        return raised

    def _interrupt(self) -> None:
        """Ctrl-C arrived outside IDA's callbacks: the segment ends with what it has."""
        self.interrupted = True

    def _trap(self) -> None:
        """IDA stuck at order 1 (:class:`~.suppress.TrapCheck`): the segment ends there."""
        self.trapped = True

    def _first_step(self, y0: np.ndarray, yp0: np.ndarray, span: float) -> float:
        """:func:`~.tolerances.natural_step` of the coordinates at a consistent start."""
        nz = self.u.nz
        return natural_step(y0[:nz], yp0[nz:2 * nz], self.rtol / self.tol_scale,
                            self.atol[:nz] / self.tol_scale, span)

    @property
    def linear_solver(self) -> str:
        """The linear solver IDA's segments use: "dense", "sparse" (SuperLU_MT) or "band"
        (the compiled segment's band LU, under ``linsolver="auto"`` where the Jacobian
        reorders into a narrow band: :attr:`~.csegment.CompiledModel.band`)."""
        if not self.sparse:
            return "dense"
        band = self.c is not None and self.c.band is not None
        return "band" if band and self.opts.linsolver == "auto" else "sparse"

    def _solve_compiled(self, tspan: np.ndarray, y0: np.ndarray, yp0: np.ndarray,
                        first_step: float) -> csegment.SegmentRun:
        """The segment in C: the same IDA options, residual, Jacobian and event functions
        (compiled) as the Python path; the step budget and Ctrl-C act between chunks."""
        fns = self.c.event_functions(self.ev_key, self.ev_fn.fn, self.hs, self.triggers,
                                     self.has_push)
        r = self.c.run(self.p, tspan, y0, yp0, self.atol, self.rtol, first_step,
                       self.min_step, self.opts.max_steps, self.step_budget, self.relaxed,
                       fns, len(self.triggers), self.opts.progress,
                       band=self.linear_solver == "band", suppress=self.suppress,
                       onestep=self.opts.output_dt is None,
                       watch=self.watch, crawl=(self.crawl_step, IN_PLACE_STEPS, SLOW_STEPS,
                                                self.h_natural),
                       first_tout=first_tout(float(tspan[0]), float(tspan[-1])),
                       dips=self.dips)
        self.n_steps = r.steps
        self.stalled, self.interrupted, self.trapped = r.stalled, r.interrupted, r.trapped
        self.crawled = r.crawled
        return r
