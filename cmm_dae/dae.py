"""The index-reduced DAE on SUNDIALS IDA (scikit-sundae) and the hybrid loop around it.

Stabilized index-2 (Gear-Gupta-Leimkuhler) form, ``y = [q, v, lambda, mu]``::

    q' - v + Phi_q^T mu = 0,   M v' + Phi_q^T lambda - Q = 0,   Phi = 0,   Phi_q v + Phi_t = 0

with the residual and its exact Jacobian ``dF/dy + cj dF/dy'`` evaluated through
``casadi.Function.buffer()`` straight into scikit-sundae's arrays (:mod:`cmm_dae.ida`).
Each configuration is one IDA segment; every event stops the segment and the hybrid loop
here, with :mod:`cmm_dae.events`, decides the next configuration.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from . import events as ev
from .assembly import start_state
from .equations import Model
from .errors import ModelError, Problem, SolverError
from .ida import _Segment
from .mechanism import Mechanism
from .post import build_result
from .result import Event, Result, Stats


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
    if err is not None and throw:
        raise SolverError(status, result=res, configuration=hs.configurations[hs.current()],
                          last_event=events[-1] if events else None) from err
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
