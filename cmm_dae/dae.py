"""The index-reduced DAE on SUNDIALS IDA (scikit-sundae) and the hybrid loop around it.

Stabilized index-2 (Gear-Gupta-Leimkuhler) form, ``y = [q, v, lambda, mu]``::

    q' - v + Phi_q^T mu = 0,   M v' + Phi_q^T lambda - Q = 0,   Phi = 0,   Phi_q v + Phi_t = 0

with the residual and its exact Jacobian ``dF/dy + cj dF/dy'`` evaluated through
``casadi.Function.buffer()`` straight into scikit-sundae's arrays. Each configuration is
one IDA segment; every event stops the segment and the hybrid loop (``events``) decides the
next configuration. This is the only module that imports scikit-sundae.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import sksundae as sun

from . import events as ev
from .assembly import assemble_positions, assemble_velocities, initial_guess
from .equations import Model
from .errors import CmmError, ModelError, Problem, SolverError
from .mechanism import Mechanism
from .post import build_result
from .result import Event, Result, Stats

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


@dataclass
class Options:
    t_end: float
    rtol: float
    atol: float
    output_dt: float | None
    max_events: int
    v_lock: float
    max_steps: int


def _check_options(t_end, rtol, atol, output_dt, max_events) -> None:
    problems = []
    if not (isinstance(t_end, int | float) and math.isfinite(t_end) and t_end > 0):
        problems.append(Problem("run", "t_end",
                                f"expected a positive end time in s, got {t_end!r}"))
    if not (isinstance(rtol, int | float) and 1e-15 <= rtol <= 1e-2):
        problems.append(Problem("run", "rtol", f"expected 1e-15 <= rtol <= 1e-2, got {rtol!r}"))
    if not (isinstance(atol, int | float) and 0 < atol <= 1e-2):
        problems.append(Problem("run", "atol", f"expected 0 < atol <= 1e-2, got {atol!r}"))
    if output_dt is not None and not (isinstance(output_dt, int | float) and output_dt > 0
                                      and math.isfinite(output_dt)):
        problems.append(Problem("run", "output_dt", f"expected a positive step in s or None, "
                                f"got {output_dt!r}"))
    if not (isinstance(max_events, int) and max_events >= 0):
        problems.append(Problem("run", "max_events", f"expected an integer >= 0, "
                                f"got {max_events!r}"))
    if problems:
        raise ModelError(problems)


def start_state(model: Model, hs: ev.HybridState, t0: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray, list[Event]]:
    """Consistent positions and velocities at t0, with joints that start pressed on a stop
    locked (a ``lock`` event each)."""
    mech = model.mech
    ini = mech.initial
    # A joint given exactly on one of its limits is a candidate for a start on the stop.
    on_stop = {}
    for name in model.locks:
        if name in ini.joints:
            lim = mech.joints[name].limits
            val = ini.joints[name]
            for side, L in (("lower", lim.lower), ("upper", lim.upper)):
                if L is not None and abs(val - L) <= 1e-12 * max(1.0, abs(L)):
                    on_stop[name] = side
    known = {k: v for k, v in ini.joints.items() if k not in mech.drivers}
    rates = {k: 0.0 for k in known}
    rates.update({k: v for k, v in ini.velocities.items() if k not in mech.drivers})
    if len(ini.velocities) and set(ini.velocities) != set(known) and \
            len(ini.velocities) == len(known):
        rates = dict(ini.velocities)
    q = assemble_positions(model, t0, hs.p, known, initial_guess(model))
    v = assemble_velocities(model, q, t0, hs.p, rates)
    c0 = model.cvel(q, v)[0]
    beyond = []
    for name in model.locks:
        lim = mech.joints[name].limits
        val = float(c0[model.jidx[name]])
        tol = 1e-12 * max(1.0, abs(val))
        if (lim.lower is not None and val < lim.lower - tol) or (
                lim.upper is not None and val > lim.upper + tol):
            beyond.append(Problem("initial", "joints", f"joint '{name}' assembles at {val:.9g}, "
                                  f"outside its limits [{lim.lower}, {lim.upper}]"))
    if beyond:
        raise ModelError(beyond, mech.source)
    events: list[Event] = []
    for name, side in on_stop.items():
        if rates.get(name, 0.0) != 0.0:
            continue
        before = hs.current()
        hs.locked[name] = side
        _, lam, _ = model.kkt(q, v, t0, hs.p)
        if hs.push(lam, name) > 0.0:
            events.append(Event(t0, "lock", name, side, before, hs.current(), 0.0, 0.0))
        else:
            del hs.locked[name]
    return q, v, events


def run_dae(mech: Mechanism, t_end: float = 10.0, *, rtol: float = 1e-8, atol: float = 1e-10,
            output_dt: float | None = 0.01, max_events: int = 1000, v_lock: float = 1e-6,
            max_steps: int = 500_000, throw: bool = True, model: Model | None = None) -> Result:
    """Simulate a mechanism with IDA from t = 0 to ``t_end``.

    Parameters
    ----------
    mech : Mechanism
        The mechanism (``cmm_dae.load`` reads one from TOML).
    t_end : float
        End time, s.
    rtol, atol : float
        IDA's relative tolerance and absolute tolerance on positions (m, rad) and
        velocities (m/s, rad/s).
    output_dt : float or None
        Output spacing, s; event times are always added. None: IDA's own steps.
    max_events : int
        Stop with :class:`SolverError` after this many events.
    v_lock : float
        A rebound slower than this (rad/s or m/s) locks the joint.
    max_steps : int
        Most IDA steps in the whole run: beyond it the run stops with a "stalled"
        :class:`SolverError` (and its partial Result) instead of crawling on.
    throw : bool
        Raise :class:`SolverError` on failure (True) or return the partial Result with
        ``status`` saying what happened (False).
    model : Model or None
        A prebuilt model of ``mech`` (saves the CasADi build).

    Returns
    -------
    Result
    """
    _check_options(t_end, rtol, atol, output_dt, max_events)
    wall0 = time.perf_counter()
    if model is None:
        model = Model(mech)
    from .structure import force_constraint_joints, labeller

    build = time.perf_counter() - wall0
    hs = ev.HybridState(model, labeller(mech), force_held=force_constraint_joints(mech))
    stats = Stats(build_time=build, method="ida")
    opts = Options(float(t_end), rtol, atol, output_dt, max_events, v_lock, max_steps)
    q, v, events = start_state(model, hs)
    rec = _Recorder()
    try:
        _hybrid_loop(model, hs, opts, q, v, events, rec, stats)
        status = "success"
        err = None
    except (SolverError, KeyboardInterrupt) as e:
        status = str(e) if isinstance(e, SolverError) else "interrupted (KeyboardInterrupt)"
        err = e
    res = build_result(model, *rec.arrays(model.nq), hs.configurations, hs.params, events,
                       stats, status)
    stats.wall_time = time.perf_counter() - wall0  # the whole run, post-processing included
    if err is not None:
        if isinstance(err, KeyboardInterrupt) and throw:
            raise SolverError(status, result=res, configuration=hs.current(),
                              last_event=events[-1] if events else None) from err
        if throw:
            raise SolverError(status, result=res, configuration=hs.configurations[hs.current()],
                              last_event=events[-1] if events else None) from None
    return res


class _Recorder:
    """Output samples, appended in time order."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.q: list[np.ndarray] = []
        self.v: list[np.ndarray] = []
        self.c: list[int] = []

    def add(self, t: float, q: np.ndarray, v: np.ndarray, c: int) -> None:
        self.t.append(t)
        self.q.append(np.array(q))
        self.v.append(np.array(v))
        self.c.append(c)

    def add_block(self, t: np.ndarray, q: np.ndarray, v: np.ndarray, c: int) -> None:
        self.t.extend(t.tolist())
        self.q.extend(q)
        self.v.extend(v)
        self.c.extend([c] * t.size)

    def arrays(self, nq: int):
        n = len(self.t)
        return (np.array(self.t), np.array(self.q).reshape(n, nq), np.array(self.v).reshape(n, nq),
                np.array(self.c, int))


def _output_times(opts: Options, t0: float) -> np.ndarray:
    if opts.output_dt is None:
        return np.array([opts.t_end])
    n = int(math.floor(opts.t_end / opts.output_dt + 1e-9))
    grid = opts.output_dt * np.arange(1, n + 1)
    grid = grid[grid > t0 + 1e-12 * max(1.0, opts.t_end)]
    if grid.size == 0 or grid[-1] < opts.t_end - 1e-12 * opts.t_end:
        grid = np.append(grid, opts.t_end)
    return grid


def _hybrid_loop(model: Model, hs: ev.HybridState, opts: Options, q: np.ndarray,
                 v: np.ndarray, events: list[Event], rec: _Recorder, stats: Stats) -> None:
    t = 0.0
    rec.add(t, q, v, hs.current())
    first_step = 0.0
    last_bounce: dict[str, float] = {}
    stayed: dict[str, float] = {}
    # Times where a driver law is only C1 (the end of a table): IDA cannot step over a
    # jump in the prescribed acceleration, so the run restarts there.
    breaks = sorted({d.times[-1] for d in model.mech.drivers.values()
                     if d.motion == "table" and 0.0 < d.times[-1] < opts.t_end})
    while t < opts.t_end:
        seg = _Segment(model, hs, opts)
        seg.step_budget = opts.max_steps - stats.steps
        t_stop = next((b for b in breaks if b > t), opts.t_end)
        outcome = seg.run(t, q, v, rec, first_step, stats, t_stop)
        stats.segments += 1
        if outcome is None:
            return
        if outcome[3] is None:  # reached a driver breakpoint: restart, nothing switches
            t, q, v = outcome[:3]
            continue
        t, q, v, which = outcome
        first_step = 0.0
        joint, side, kind = which
        if kind == "gap":
            k = model.jidx[joint]
            _, cd, _ = model.coord(q, v)
            cdv = float(np.asarray(cd).ravel()[k])
            if (cdv >= 0.0 and side == "lower") or (cdv <= 0.0 and side == "upper"):
                # Moving away from the stop: a round-off root, not an impact.
                continue
            hs.locked[joint] = side
            q_on = ev.project_positions(model, q, t, hs.p)
            if abs(cdv) <= opts.v_lock:
                # Arrival at (almost) zero speed, e.g. just after a release: lock only if
                # the stop would push; otherwise the joint is leaving and this is round-off.
                _, lam, _ = model.kkt(q_on, v, t, hs.p)
                if hs.push(lam, joint) <= 0.0:
                    del hs.locked[joint]
                    continue
            del hs.locked[joint]
            out = ev.at_limit(hs, q, v, t, joint, side, opts.v_lock, last_bounce.get(joint))
            q, v = out.q, out.v
            for e in out.jammed:
                _append_event(events, e, opts, None, t, q, v, hs)
            _append_event(events, out.event, opts, rec, t, q, v, hs)
            if not out.locked:
                last_bounce[joint] = t
                c, _, _ = model.coord(q, v)
                # A first step long enough that round-off in the gap cannot read as a crossing.
                first_step = 1e3 * np.finfo(float).eps * (1 + abs(float(np.asarray(c)
                                                                          .ravel()[k]))) \
                    / max(abs(out.event.velocity_after), 1e-300)
                first_step = min(first_step, 1e-6)
            elif out.released_at_once:
                _, lam, _ = model.kkt(q, v, t, hs.p)
                rel = ev.release(hs, q, v, t, joint, hs.push(lam, joint))
                _append_event(events, rel, opts, rec, t, q, v, hs)
            else:
                last_bounce.pop(joint, None)
        else:  # push of a locked joint crossed zero: release
            _, lam, _ = model.kkt(q, v, t, hs.p)
            force = hs.push(lam, joint)
            rel = ev.release(hs, q, v, t, joint, force)
            if ev.would_reenter(hs, q, v, t, joint, side) and \
                    t - stayed.get(joint, -math.inf) > ev.ZENO_DT:
                hs.locked[joint] = side  # stays locked: no chattering
                stayed[joint] = t
                continue
            _append_event(events, rel, opts, rec, t, q, v, hs)


def _append_event(events: list[Event], e: Event, opts: Options, rec: _Recorder, t: float,
                  q: np.ndarray, v: np.ndarray, hs: ev.HybridState) -> None:
    events.append(e)
    if rec is not None:
        rec.add(t, q, v, hs.current())
    if len(events) > opts.max_events:
        raise SolverError(f"max_events = {opts.max_events} reached at t = {t:.9g} s "
                          f"(last: {e.kind} of joint {e.joint})")


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
