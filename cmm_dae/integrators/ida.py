"""IDA (SUNDIALS, through scikit-sundae) as an :class:`~cmm_dae.integrators.contract.Integrator`.

Stabilized index-2 (Gear-Gupta-Leimkuhler) form, ``y = [q, v, lambda, mu]``::

    q' - v + Phi_q^T mu = 0,   M v' + Phi_q^T lambda - Q = 0,   Phi = 0,   Phi_q v + Phi_t = 0

with the residual and its exact Jacobian (:mod:`.ida_callbacks`) written through CasADi's
buffers into scikit-sundae's arrays (the multipliers out of the error test: :mod:`.suppress`).
Each :meth:`~IdaIntegrator.advance` is one IDA segment in one configuration, ended by a root
of an event function of :mod:`cmm_dae.hybrid.policy` or the end (limits: :mod:`.ida_steps`)."""

from __future__ import annotations

import math
import warnings

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..core.errors import CmmError, SolverError, Status
from ..core.memo import once
from ..core.records import Stats
from ..equations.kinematics import singular_ratio
from ..equations.model import Buffered, Model
from ..hybrid import policy as ev
from ..singular.step import PAST_RATIO, leaves_singular
from . import cbuild, dips
from .contract import Integrator, Recorder, RunOptions, SegmentEnd
from .extremes import driver_watch, keep_extremes
from .ida_callbacks import IdaCallbacks
from .ida_steps import (
    CRAWL_STEP,
    _own_steps,
    failure,
    ida_class,
    quiet_sundials,
    segment_start,
    segment_times,
    sparse_solver,
    stall_message,
)
from .suppress import start_suppressed, suppressed
from .tolerances import ATOL_LAMBDA, lambda_atol, tolerances

#: A lock force's event function is taken from IDA's multipliers while it is farther from
#: zero than this share of the largest multiplier (plus 100 ATOL_LAMBDA); nearer, from a KKT
#: solve. IDA's interpolated multipliers were within 2e-4 relative of the KKT values on the
#: shipped models, so the margin leaves a factor of 500.
PUSH_MARGIN = 0.1


class IdaIntegrator(IdaCallbacks, Integrator):
    """IDA on the GGL index-2 residual, one solver per configuration segment."""

    method = "ida"

    @staticmethod
    def time_resolution(opts: RunOptions) -> float:
        return ev.ZENO_DT  # events are located to round-off

    def after_run(self, seconds: float) -> None:
        cbuild.build_later(self.model, self.sparse, self.opts.compiled, self.c, seconds)

    @staticmethod
    def gap_resolution(opts: RunOptions) -> tuple[float, float]:
        # IDA keeps positions to about its tolerances: a rebound rising less than that came
        # back as a root at its apex, its time's derivative wrong (2.08 against 0.166)
        return opts.rtol, opts.atol

    def __init__(self, model: Model, hs: ev.HybridState, opts: RunOptions, stats: Stats):
        super().__init__(model, hs, opts, stats)
        #: IDA's unknowns (bodies pinned to the ground by their angle alone)
        self.u = u = model.ida
        self.t_arr = np.zeros(1)
        self.cj_arr = np.zeros(1)
        self.p = np.zeros(model.n_params)
        # IDA's arrays are copied into these (bound once) rather than bound at every
        # callback: a copy costs a third of a bind
        self.y_in, self.yp_in, self.res_out = (np.zeros(u.N) for _ in range(3))
        self.res = Buffered(u.res_fn)
        for i, arr in enumerate((self.t_arr, self.y_in, self.yp_in, self.p)):
            self.res.bind(i, arr)
        self.res.bind_out(0, self.res_out)
        self.jac: Buffered | None = None
        self._jj: np.ndarray | None = None  # the Jacobian array the function writes into
        self.sparse = sparse_solver(model, opts.linsolver)
        #: the compiled segment, or None for the Python path (cbuild.choose)
        self.c = cbuild.choose(model, self.sparse, opts.compiled)
        self.ls_options: dict = {}
        if self.sparse:  # (the pattern as scipy's: once per model, 0.2 ms with 32 loops)
            self.ls_options = {"linsolver": "sparse", "sparsity": once(
                model, ("ida sparsity",), lambda: sp.csc_matrix(
                    (np.ones(u.jac_pattern.nnz()), *(np.asarray(x, np.int32) for x in
                                                     u.jac_pattern.get_ccs()[::-1])),
                    shape=(u.N, u.N)))}
        self.tol_scale, self.rtol, self.atol = tolerances(u, opts.rtol, opts.atol)
        #: factor on the multipliers' absolute tolerances, from the forces at the start
        #: (set by the first segment)
        self.lambda_scale = 1.0
        self._scaled = False
        self.ev_out = np.zeros(0)
        self.triggers: list[ev.Trigger] = []
        self.first_step = 0.0
        # multipliers: Newton's test loose unless an event reads them; error test: suppress.py
        self.relaxed, self.suppress = not (model.locks or model.frictional), suppressed(model)
        self.crossed_at = math.nan  # where the last singular-position crossing ended
        self._ev_cache: dict[tuple, Buffered] = {}
        # Times where a driver law is only C1 (the end of a table): IDA cannot step over a
        # jump in the prescribed acceleration, so the run restarts there.
        self.watch = driver_watch(model)  # the drivers' multipliers: their peaks are kept
        self.v_raise = 1.0  # the velocities' atol factor, raised where IDA was trapped
        self.breaks = sorted({d.times[-1] for d in model.mech.drivers.values()
                              if d.motion == "table" and 0.0 < d.times[-1] < opts.t_end})

    # ------------------------------------------------- the event functions (callbacks: mixin)
    def _event_function(self) -> Buffered:
        """The segment's event functions as one CasADi function of y: the policy's own
        :func:`~cmm_dae.hybrid.policy.event_values` applied to symbols (one evaluation of a few
        microseconds instead of a dozen Python calls), with a second output below zero when
        a lock force is within the margin of its threshold. Cached per configuration."""
        hs, model = self.hs, self.model
        k = self.lambda_scale
        key = self.ev_key = (tuple(self.triggers), hs.mode(), k, hs.gap_band)
        fn = self._ev_cache.get(key)
        if fn is None:
            def build() -> ca.Function:
                y, p = ca.SX.sym("y", self.u.N), ca.SX.sym("p", model.n_params)
                q, v, lam = self.u.symbolic(y)
                c, cd = model.cvel_fn(q, v, p)
                vals: list = [None] * len(self.triggers)
                ev.event_values(hs, c, cd, lam, self.triggers, vals, where=ca.if_else)
                near = ca.SX(1.0)
                if self.has_push:
                    push = ca.vertcat(*[vals[i] for i in self.push_idx])
                    near = ca.mmin(ca.fabs(push)) - (PUSH_MARGIN * ca.mmax(ca.fabs(lam))
                                                     + 100.0 * ATOL_LAMBDA * k)
                return ca.Function("events", [y, p], [ca.vertcat(1.0, *vals), near])

            # built once per model and configuration (the next run of the model meets the
            # same ones); wrapped per run, whose buffers it writes
            fn = self._ev_cache[key] = Buffered(once(
                model, ("events", key, self.u.N, PUSH_MARGIN), build))
        return fn

    def after_events(self, transitions: list[ev.Transition]) -> None:
        last = transitions[-1].event if transitions else None
        if last is not None and last.kind == "bounce":
            c = float(self.model.joint_rates(transitions[-1].q, transitions[-1].v)[0]
                      [self.model.jidx[last.joint]])
            # A first step long enough that round-off in the gap cannot read as a crossing.
            self.first_step = min(1e-6, 1e3 * np.finfo(float).eps * (1 + abs(c))
                                  / max(abs(last.velocity_after), 1e-300))

    def output_times(self, t0: float, t1: float) -> np.ndarray:
        if self.opts.output_dt is None:  # IDA's own steps: none inside a crossing
            return np.zeros(0)
        return self._grid_inside(self.opts.output_dt, t0, min(t1, self.opts.t_end))

    def after_singular(self, t: float) -> None:
        # Near a singular position the multipliers' sensitivity grows as 1 / sigma^2 and a
        # restart (order 1, small steps) fails on their error test alone.
        self.relax_multipliers()
        self.crossed_at = t

    def relax_multipliers(self) -> None:
        """Multipliers out of IDA's error test from now on by a huge tolerance (where a contact
        lands they are out already, :mod:`.suppress`: it loosens Newton's test), as where no
        event reads them (A02, 32 loops, rtol 1e-3: 145 steps, not 189)."""
        self.relaxed = True
        self._lambda_atol()

    def _lambda_atol(self) -> None:
        self.atol[self.u.lam] = lambda_atol(self.relaxed, self.lambda_scale) * self.tol_scale

    def advance(self, t0: float, q: np.ndarray, v: np.ndarray, rec: Recorder) -> SegmentEnd:
        opts, hs, u = self.opts, self.hs, self.u
        first_step, q, v, y0, yp0, t_stop = self._begin(t0, q, v)
        solver = self._solver(first_step)
        tspan = segment_times(self.opts, t0, t_stop)
        r = self._solve(solver, tspan, y0, yp0, first_step, t0)
        T, Y = np.asarray(r.t), np.asarray(r.y)
        failed = r.status < 0 or self.crawled  # steps in place are a failure there
        h1 = self._first_step(y0, yp0, t_stop - t0) \
            if failed and self.error is None and not first_step else 0.0
        if h1 > 0.0 and T[-1] - t0 < h1:
            # IDA's own first step comes from y' and the tolerances alone: on Andrews' squeezer
            # at rtol 1e-10 it was 2.4e-16 s, where the index-2 Newton matrix (mass / h^2 beside
            # the constraint rows) cannot be solved, each failure making it smaller; after A02's
            # third crossing (40 loops, rtol 1e-11) its steps grew to 4e-8 s and failed alike.
            # A failure before one step from the accelerations is tried again with that step.
            self.first_step = h1
            return self.advance(t0, q, v, rec)
        if failed and self.error is None and T[-1] <= t0 and self.crossed_at == t0:
            # IDA cannot restart where a singular-position crossing ended, even with a first
            # step from the accelerations: still too near it; the policy takes the
            # crossing further out
            return SegmentEnd(t0, q, v, (), "singular")
        if failed and self.error is None and not self.relaxed and (
                T[-1] <= t0 + ev.ZENO_DT * max(1.0, abs(t0))):
            # IDA could not take a first step (or gave up a hair after the start: 3e-14 s
            # on a non-parallelogram A02 at rtol 1e-12): large or near-singular constraint
            # sets (long chains, just past a singular position) fail on the multipliers'
            # error test alone. Leave them out of it from here on and start again.
            self.relax_multipliers()
            return self.advance(t0, q, v, rec)
        keep = np.arange(1, T.size)
        keep = keep[T[keep] > t0]  # (a failure without a step returns t0 once more)
        if self.error is not None:  # only what was computed before the failure
            keep = keep[T[keep] <= self.t_error]
        # IDA's own steps (no output grid) end, at a failure, with its last time repeated
        # (A02 at rtol 1e-10: three samples at one time before each crossing): the last
        if keep.size:  # (a failure at the very start keeps nothing)
            keep = keep[np.append(T[keep][1:] > T[keep][:-1], True)]
        Q, V = u.centroids(Y[np.append(keep, T.size - 1)])
        # each sample's works since the sample before it (zero at the segment's start)
        W = u.works(Y[keep])
        rec.add_block(T[keep], Q[:-1], V[:-1], hs.current(),
                      work=np.diff(W, axis=0, prepend=np.zeros((1, W.shape[1]))))
        keep_extremes(rec, self.model, r, float(T[keep][-1]) if keep.size else t0, hs.current())
        t1, q1, v1 = float(T[-1]), Q[-1], V[-1]
        if self.error is not None:
            e = self.error
            raise SolverError(f"the integration failed after t = "
                              f"{self.t_error:.9g} s: "
                              f"{type(e).__name__}: {e}", status=Status.NUMERICAL) from e
        if failed and self.error is None and T[-1] > t0 and \
                self._roundoff_atol(Y[-1], check=True):
            # the coordinates grew until their round-off passes the absolute tolerance (the
            # squeezer from rest to 1400 rad/s: at rtol 1e-12, atol 1e-14 on a velocity
            # through zero is below 3e-13 of round-off; Newton could not converge, the step
            # collapsed to 1e-22 s and it read as a dead point): on from here with it raised
            return SegmentEnd(t1, q1, v1, (), "restart")
        if failed:
            self.v_fail = v1
            ratio0 = singular_ratio(self.model, *self.start_state)  # (only a failure asks)
            message, status, ratio = failure(self.model, self.hs, self.p, ratio0,
                                             self.crawled, self.v_fail, r, t1, q1)
            if status is Status.DEAD_POINT or (
                    max(ratio, ratio0) < PAST_RATIO
                    and leaves_singular(self.model, self.p, t1, q1, v1)):
                # the constraints collapse ahead: let the policy try to cross (a singular
                # position on the motion's branch), which says "dead point" if it cannot;
                # or the segment started next to one and failed on its way out (A02 started
                # 0.05 rad past the horizontal at rtol 1e-11), which the crossing's way
                # out covers
                return SegmentEnd(t1, q1, v1, (), "singular")
            raise SolverError(message, status=status)
        if r.status == 2 and self.trapped:  # (suppress.TrapCheck) on, velocities looser
            self.v_raise *= 10.0
            if self.v_raise > 1e3:  # (at most 1000x looser: then said)
                raise SolverError(f"IDA is stuck at order 1 at t = {t1:.9g} s with the velocities' "
                                  "atol raised 1000x: try another rtol", status=Status.INTEGRATOR)
            return SegmentEnd(t1, q1, v1, (), "restart")
        if r.status == 2 and self.stalled:
            raise SolverError(stall_message(self.model, t1, q1, v1, opts.max_steps,
                                            self.stats.steps), status=Status.STALLED)
        if r.status == 2 and self.interrupted:
            raise KeyboardInterrupt
        if r.status == 2:  # IDA_ROOT_RETURN: a terminal event ended the segment
            info = np.asarray(r.i_events)[-1]
            hit = tuple(self.triggers[i] for i in np.flatnonzero(info[1:] != 0))
            return SegmentEnd(t1, q1, v1, hit, "event")
        if t_stop < opts.t_end:
            return SegmentEnd(t1, q1, v1, (), "restart")
        return SegmentEnd(t1, q1, v1, (), "end")

    def _begin(self, t0: float, q: np.ndarray, v: np.ndarray) -> tuple:
        """A segment's start at (t0, q, v): its event functions, budgets and step limits,
        the state projected onto the constraints and IDA's consistent ``y0, yp0`` from a
        KKT solve; (first step, q, v, y0, yp0, the segment's stop time)."""
        model, opts, hs, u = self.model, self.opts, self.hs, self.u
        self.p[:] = hs.p
        first_step, self.first_step = self.first_step, 0.0
        self.n_steps, self.in_place, self.t_last = 0, 0, t0
        self.interrupted = self.stalled = self.crawled = self.trapped = False
        self.step_budget = opts.max_steps - self.stats.steps
        # A state taken from IDA's interpolant at a root satisfies the constraints only to
        # the solver tolerance; restarting from it makes mu ~ Phi / h blow up as h shrinks.
        q, v, a, lam, scale = segment_start(model, q, v, t0, self.p, first=not self._scaled)
        if scale is not None:  # the run's first segment: its force scale (the event
            self.lambda_scale, self._scaled = scale, True  # functions' lock forces are
            self._lambda_atol()  # measured in it)
        trig = self.triggers = ev.event_list(model, hs.locked)
        self.dips = dips.depths(hs, trig)  # (gaps that dip inside a step: dips.py)
        self.push_idx = np.flatnonzero([tr.kind in ev.LOCK_FORCES for tr in trig])
        self.has_push = self.push_idx.size > 0
        self.ev_out = np.zeros(1 + len(self.triggers))  # [always positive, triggers]
        self.ev_near = np.zeros(1)
        self.ev_fn = self._event_function()
        self.ev_fn.bind(0, self.y_in)
        self.ev_fn.bind(1, self.p)
        self.ev_fn.bind_out(0, self.ev_out)
        self.ev_fn.bind_out(1, self.ev_near)
        self.start_state = (q, t0, self.p.copy())  # (its ratio: 1.4 ms with 32 loops)
        y0, yp0 = u.start(q, v, a, lam, t0, model.fill(self.p, t0, q, v))
        self._roundoff_atol(y0)
        t_stop = next((b for b in self.breaks if b > t0 + 1e-12 * max(1.0, b)), opts.t_end)
        self.t_start = t0
        # (a segment given its first step is not judged slow again: it fails otherwise)
        self.h_natural = 0.0 if first_step else self._first_step(y0, yp0, t_stop - t0)
        # A step shorter than a quarter of t0's spacing cannot move t: IDA at a Newton failure
        # next to a singular position halved its step down to 1e-17 s and then took a million
        # such steps in place (A02 at rtol 1e-10); with this floor it fails there, as any other.
        self.min_step = 0.25 * np.finfo(float).eps * abs(t0)
        self.crawl_step = CRAWL_STEP * np.finfo(float).eps * max(abs(t0), opts.t_end)
        if first_step:
            first_step = max(first_step, 2.0 * self.min_step)
        return first_step, q, v, y0, yp0, t_stop

    def _solver(self, first_step: float):
        """IDA for the segment (None on the compiled path), with callbacks that keep a
        Ctrl-C, a spent budget, a crawl or an exception as a clean end."""
        u = self.u
        ne = 1 + len(self.triggers)
        # scikit-sundae keeps its event history on the function object: a fresh one per segment,
        # so no event of an earlier segment is seen again. A Ctrl-C inside a callback would
        # abort IDA and lose the segment's outputs: it is caught here and turned into a root of
        # the always-positive first event function, so IDA returns what it has and the run
        # stops with everything so far. An exception in the residual (a user's load law
        # failing) ends the segment the same way; samples after the last step before it go.
        self.error, self.t_error = None, math.inf  # (t_error: the last step before it)

        def eventsfn(t, y, yp, out):
            try:
                if self.error is None:
                    self._events(t, y, yp, out)
            except KeyboardInterrupt:
                self.interrupted = True
            except Exception as e:  # noqa: BLE001 - kept, raised with the samples so far
                self.error, self.t_error = e, self.t_last
            if self.interrupted or self.error is not None:
                out[:] = 1.0
                out[0] = -1.0

        def resfn(t, y, yp, res):
            try:
                self._residual(t, y, yp, res)
            except KeyboardInterrupt:
                self.interrupted = True
                self._residual(t, y, yp, res)
            except Exception as e:  # noqa: BLE001 - kept, raised with the samples so far
                if self.error is None:
                    self.error, self.t_error = e, self.t_last
                res[:] = 0.0

        def jacfn(t, y, yp, res, cj, JJ):
            try:
                self._jacobian(t, y, yp, res, cj, JJ)
            except KeyboardInterrupt:  # as in the residual: IDA stops at the next root
                self.interrupted = True  # check, with the samples so far
                self._jacobian(t, y, yp, res, cj, JJ)

        eventsfn.direction = [0] + [-1] * len(self.triggers)
        eventsfn.terminal = [True] * ne
        with warnings.catch_warnings():  # "custom sparse Jacobian approximation will be
            # ignored in favor of the user-defined jacfn": as intended
            warnings.simplefilter("ignore", UserWarning)
            solver = None if self.c is not None else ida_class()(
                resfn, jacfn=jacfn, eventsfn=eventsfn, num_events=ne,
                # IDA's limit per call: what is left of the run's budget, which the root
                # function counts across calls and ends cleanly ("stalled")
                rtol=self.rtol, atol=self.atol, max_num_steps=max(1, self.step_budget + 1),
                first_step=first_step, min_step=self.min_step,
                max_step=math.inf if self.min_step else 0.0,  # (0: unbounded, below min)
                algebraic_idx=list(range(u.lam.start, u.N)),
                **self.ls_options)
        return solver

    def _solve(self, solver, tspan: np.ndarray, y0: np.ndarray, yp0: np.ndarray,
               first_step: float, t0: float):
        """IDA's run over ``tspan`` (Python or compiled), its counts added to the stats."""
        try:
            if self.c is not None:
                r = self._solve_compiled(tspan, y0, yp0, first_step)
            else:
                with quiet_sundials():
                    start_suppressed(solver, float(tspan[0]), y0, yp0, self.suppress)
                    search = self.dips is not None  # (a gap among the triggers)
                    r = _own_steps(solver, tspan, y0, yp0, self._interrupt,
                                   self.opts.output_dt is not None, self.watch,
                                   self.u.lam.start, self._trap, self._after_step,
                                   self._dip if search else None,
                                   self._lean(y0) if search else None)
                self.n_steps = r.steps  # (IDA's count with the last step, as in C)
        except CmmError:
            raise
        except Exception as e:  # an exception in a callback aborts IDA: say so plainly
            raise SolverError(f"the integration failed at t = {max(self.t_last, t0):.9g} s: "
                              f"{e}",
                              status=Status.NUMERICAL) from e
        self.stats.steps += self.n_steps
        self.stats.nfev += int(r.nfev)
        self.stats.njev += int(r.njev)
        return r
