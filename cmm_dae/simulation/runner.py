"""The one run driver: ``simulate(mech, method="ida" | "iterative", ...)``.

It owns, once for every method, what a run is: checking the options, building the model,
the consistent initial state, the hybrid loop's bookkeeping (the event policy of
:mod:`cmm_dae.hybrid.policy` applied to what the integrator detected, a sample after each
event), failure wrapping (every exception inside a run becomes a
:class:`~cmm_dae.core.errors.SolverError` carrying the partial Result) and the Result itself.
An integrator (:mod:`cmm_dae.integrators.ida`, ``.iterative``) only advances the state to
the end time or to the next trigger.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time

import numpy as np
from threadpoolctl import ThreadpoolController

from ..core.errors import AssemblyError, CmmError, SolverError, Status
from ..core.memo import once
from ..core.progress import Bar
from ..core.records import Stats
from ..description.mechanism import Mechanism, require_mechanism
from ..description.structure import force_constraint_joints, labeller
from ..equations.model import Model
from ..hybrid import policy as ev
from ..hybrid.equilibrium import solve_equilibrium
from ..hybrid.start import start_state
from ..integrators.contract import Integrator, Recorder, RunOptions
from ..integrators.csegment import load_sundials
from ..integrators.ida import IdaIntegrator
from ..integrators.iterative import IterativeIntegrator
from ..results.post import build_result
from ..results.result import Result
from .cache import built, model_of, without_redundant
from .crossing import cross_singular, drop_twin_passage, log_stepped_over
from .options import IDA_DEFAULTS, ITERATIVE_DEFAULTS, branch_rule, check_options
from .passage import passage_cut, watch_segment

#: The integration methods, by name.
METHODS: dict[str, type[Integrator]] = {"ida": IdaIntegrator, "iterative": IterativeIntegrator}

_BLAS = None


def _one_blas_thread():
    """A context with one BLAS and one OpenMP thread: the package's systems are small, and
    on a busy 2-core machine OpenBLAS's default threads turned a 0.47 s run into 5.3 s.
    SuperLU_MT (IDA's sparse solver) is asked for one thread, yet its OpenMP runtime
    started the default team, whose idle threads spin: IDA's segments of A02 with 8 loops
    took 71 ms on average against 10 ms with one thread (best of 20: 8.1 against 9.0)."""
    global _BLAS
    if _BLAS is None:  # finding the loaded BLAS libraries costs ~0.4 ms: once, after
        load_sundials()  # SUNDIALS' (its OpenMP and OpenBLAS) are loaded
        _BLAS = ThreadpoolController()
    return _BLAS.limit(limits=1)


def simulate(mech: Mechanism, t_end: float = 10.0, *, method: str = "ida",
             rtol: float = IDA_DEFAULTS["rtol"], atol: float | None = IDA_DEFAULTS["atol"],
             output_dt: float | None = IDA_DEFAULTS["output_dt"],
             dt: float = ITERATIVE_DEFAULTS["dt"],
             output_every: int = ITERATIVE_DEFAULTS["output_every"],
             max_events: int | None = None, v_lock: float = 1e-6,
             max_steps: int | None = None, throw: bool = True,
             model: Model | None = None, progress: bool = False,
             branch: str | tuple[str, int] = "continue",
             compiled: bool | str = IDA_DEFAULTS["compiled"],
             linsolver: str = IDA_DEFAULTS["linsolver"], _trace: list | None = None) -> Result:
    """Simulate a mechanism from t = 0 to ``t_end`` with IDA or the paper's algorithm.

    Parameters
    ----------
    mech : Mechanism
        The mechanism (:func:`cmm_dae.load` reads one from TOML).
    t_end : float
        End time, s (with IDA at least 1e-9 s, the run's time resolution).
    method : {"ida", "iterative"}
        SUNDIALS IDA on the index-2 DAE, or the paper's fixed-step iterative algorithm.
    rtol : float
        IDA: relative tolerance.
    atol : float or None
        IDA: absolute tolerance on positions (m, rad) and velocities (m/s, rad/s); None:
        1e-2 of ``rtol``, so that a tighter rtol is not capped by a fixed atol where a
        coordinate passes zero (IFToMM A01, 50 s, rtol 1e-11: 1.5e-6 m at atol 1e-10).
    output_dt : float or None
        IDA: output spacing, s (None: IDA's own steps). Event times are always added.
    dt : float
        Iterative: the fixed step, s (the paper uses 0.01 s).
    output_every : int
        Iterative: keep every k-th step (events are always kept).
    max_events : int or None
        Stop with :class:`SolverError` after this many events (default: 1000 per
        simulated second, at least 1000).
    v_lock : float
        A rebound slower than this (rad/s or m/s) locks the joint.
    max_steps : int or None
        Most steps in the run (default 50,000 per simulated second, at least 500,000, both
        times (1e-8 / rtol) ** 0.25 below rtol 1e-8): beyond it a "stalled"
        :class:`SolverError` with the partial Result; a fixed step needing more is refused.
    throw : bool
        Raise :class:`SolverError` on failure (True) or return the partial Result with
        ``status`` and ``message`` saying what happened (False).
    model, progress : Model or None, bool
        A prebuilt model of ``mech`` (saves the CasADi build); a progress bar on stderr.
    branch : "continue" or (joint, sign)
        Which branch to take at a singular position: the branch of the motion (continuity
        of velocity), or the one on which ``joint``'s coordinate moves with ``sign`` (+1
        or -1). Other branches are found where one loop is singular at a time; where
        several are, a rule that needs a switch ends the run as a dead point. With a
        rule, IDA's samples are searched for singular positions it integrated through
        without stopping (the rule is applied at each one's instant).
    compiled : bool or "auto"
        IDA: each configuration segment in C (built with the C compiler, cached), the
        same numbers bit for bit. "auto": where the build is cached or short (built now),
        else Python, and once the model's runs took 2 s (and twice the build's estimate)
        together it is built in the background (said once); True: build now (without a
        compiler or for Python load laws, a warning and Python); False: Python.
        Iterative: each configuration's whole step in C (cached); "auto": where built,
        or built now where builds are allowed; else on CasADi's virtual machine.
    linsolver : {"auto", "dense", "sparse"}
        IDA's linear solver: dense LU, or sparse LU (SuperLU_MT) on the Jacobian's
        structural pattern; "auto": sparse from 120 IDA unknowns where at most 5 % of the
        Jacobian is nonzero, in C by band LU where reordering makes it a band ("band").

    Returns
    -------
    Result

    Raises
    ------
    TypeError
        ``mech`` is not a Mechanism (a model file's path: :func:`cmm_dae.load` reads it).
    ModelError
        A bad option (all of them named at once, under ``[run]``): a bad value, an option
        of the other method given a value other than its default (it would be ignored),
        a ``model`` built from another mechanism; or a bad initial state.
    AssemblyError
        The mechanism cannot be assembled at t = 0.
    SolverError
        The run failed part-way; ``.result`` holds everything computed up to then.
    """
    require_mechanism(mech, "simulate")
    opts = check_options(mech, method, t_end, rtol=rtol, atol=atol, output_dt=output_dt, dt=dt,
                         output_every=output_every, max_events=max_events, v_lock=v_lock,
                         max_steps=max_steps, linsolver=linsolver, compiled=compiled,
                         model=model)
    rule = branch_rule(mech, branch)
    bar = Bar(opts.t_end, f"{mech.name} ({method})", "s", enabled=progress)
    opts = dataclasses.replace(opts, progress=bar, branch=rule, compiled=compiled,
                               linsolver=linsolver)
    try:
        with _one_blas_thread():
            res = _run(mech, opts, METHODS[method], throw, model, _trace)
        bar.update(float(res.t[-1]))
        return res
    finally:
        bar.close()


def _run(mech: Mechanism, opts: RunOptions, cls: type[Integrator], throw: bool,
         model: Model | None, trace: list | None = None) -> Result:
    """The run; ``trace`` (a list) receives the start state and one
    :class:`~cmm_dae.hybrid.SegmentTrace` per segment (for :mod:`cmm_dae.sensitivity`)."""
    wall0 = time.perf_counter()
    mech, eq_values, model, hs, q, v, events = _start(mech, model)
    build = time.perf_counter() - wall0
    stats = Stats(build_time=build, method=cls.method)
    rec = Recorder()
    rec.add(0.0, q, v, hs.current())
    after = [0] * len(events)  # the sample right after each event
    integ = cls(model, hs, opts, stats)
    status, message, err = Status.SUCCESS, "success", None
    t = 0.0
    try:
        # joints that start on a stop, moving into it: the impact comes before any step
        seen: set = set()
        while starting := [x for x in ev.start_triggers(hs, q, v) if x not in seen]:
            seen.add(starting[0])  # a rejected trigger (a joint leaving) is not asked again
            q, v = _apply(ev.handle(hs, starting[0], q, v, 0.0, integ.policy), 0.0, q, v,
                          events, rec, after, integ, opts)
        if trace is not None:
            trace.append((q.copy(), v.copy(), list(events)))
        while True:
            seg = None if trace is None else ev.SegmentTrace(
                t, q.copy(), v.copy(), hs.p.copy(), dict(hs.locked), hs.zones, dict(hs.slip),
                dict(hs.stick_at), len(rec))
            n0, t_seg = len(rec), t
            passed: list[tuple[float, int]] = []
            end = integ.advance(t, q, v, rec)
            stats.segments += 1
            retry = None
            stalled = len(rec) == n0
            if opts.branch is not None and cls.method == "ida":
                end = watch_segment(hs.model, hs.p, t, q, v, rec, n0, end)
            elif cls.method == "ida":
                passed = log_stepped_over(hs, t, q, v, opts, rec, n0, end, events, after)
                if seg is not None:
                    seg.passages = passed
                if end.reason == "singular" and not end.triggers:
                    # where IDA gave up close to the instant, a crossing from its last
                    # state can start too near (the accelerations there are ruled by
                    # round-off): if it fails or jumps, it is tried again from the last
                    # sample well before
                    retry = functools.partial(passage_cut, hs.model, hs.p, t, q, v, rec, n0,
                                              end, last=True)
            t, q, v = end.t, end.q, end.v
            if seg is not None:
                seg.n1, seg.t1, seg.reason = len(rec), t, end.reason
                seg.relaxed = bool(getattr(integ, "relaxed", False))
                seg.lambda_scale = float(getattr(integ, "lambda_scale", 1.0))
                trace.append(seg)
            edges: set = set()
            for trig in end.triggers:
                done = ev.handle(hs, trig, q, v, t, integ.policy)
                if seg is not None:
                    seg.groups.append((trig, done, [hs.params[x.event.after] for x in done]))
                q, v = _apply(done, t, q, v, events, rec, after, integ, opts)
            # the events may leave a coordinate on a zone's edge, already moving across it
            # (released from a stop there), or joints past rest with the one: decided now
            while end.triggers and (edge := [x for x in ev.zone_edges(hs, q, v)
                                             + ev.resting_slips(hs, q, v, t) if x not in edges]):
                edges.add(edge[0])
                done = ev.handle(hs, edge[0], q, v, t, integ.policy)
                if seg is not None:
                    seg.groups.append((edge[0], done, [hs.params[x.event.after] for x in done]))
                q, v = _apply(done, t, q, v, events, rec, after, integ, opts)
            if end.reason == "singular":
                n_events = len(events)
                # a segment that recorded nothing restarts the last crossing (its instant before)
                cr, kept = cross_singular(hs, integ, t, q, v, opts, rec, events, after, retry,
                                          stalled, -math.inf if stalled else t_seg)
                if len(events) > n_events:
                    drop_twin_passage(events, after, passed, cr)
                t, q, v = cr.t_after, cr.q, cr.v
                if seg is not None:
                    seg.crossing, seg.crossing_logged = cr, len(events) > n_events
                    if kept is not None:  # crossed from an earlier sample: the segment,
                        seg.n1, seg.t1 = kept, cr.t0  # as the sensitivities replay it, ends there
                if t >= opts.t_end * (1.0 - 1e-12):
                    break
                continue
            if end.reason == "end":
                break
    except KeyboardInterrupt as e:
        status, message, err = Status.INTERRUPTED, "interrupted (KeyboardInterrupt)", e
    except SolverError as e:
        status, message, err = e.status, str(e), e
    except Exception as e:  # noqa: BLE001 - every failure inside a run keeps its partial Result
        status, err = Status.NUMERICAL, e
        more = "; out of memory: a coarser output_dt needs less" * isinstance(e, MemoryError)
        message = (f"numerical failure after t = {rec.last_t:.9g} s (the last state kept): "
                   f"{type(e).__name__}: {e}{more}")
    return _finish(model, hs, rec, events, after, stats, integ, opts, wall0, eq_values,
                   status, message, err, throw)


def _start(mech: Mechanism, model: Model | None) -> tuple:
    """The run's start: an ``[initial] equilibrium`` solved, the model (built, reused or the
    caller's without its redundant rows), the hybrid state and the consistent initial
    state with the locks it starts in; (mech, solved values, model, hs, q, v, events).
    Failures are :class:`AssemblyError`s that say why."""
    mech, eq_values = solve_equilibrium(mech)
    if any(not p.startswith("initial.") for p in eq_values):
        model = None  # the solved parameters are compiled into the model: build it anew
    try:
        if model is None:  # built (or kept) without its redundant rows
            model = model_of(mech, built)
        elif not model.dropped and model.m > 0:  # the caller's: as a run builds it
            model = without_redundant(model)
        # (the labels' structure analysis once per model; in space, its rank's mobility)
        hs = ev.HybridState(model, once(model, ("labeller",), lambda: labeller(
            mech, mobility=model.mobility if mech.spatial else None)),
            force_held=force_constraint_joints(mech))
        q, v, events = start_state(model, hs)
        # the accelerations must be determined at the start (once: 1 ms a run, 32 loops)
        once(model, ("start kkt", q.tobytes(), v.tobytes(), hs.p.tobytes()),
             lambda: model.kkt(q, v, 0.0, hs.p) and True)
    except CmmError:
        raise
    except np.linalg.LinAlgError as e:
        point = [n for n, b in mech.bodies.items() if b.inertia == 0.0]
        if point:
            raise AssemblyError(
                f"the accelerations at t = 0 are undetermined: the rotation of point mass "
                f"{', '.join(repr(n) for n in point)} (inertia 0) is not fixed by its joints; "
                "give it an inertia or a second joint that fixes its angle",
                joints=[]) from e
        raise AssemblyError(f"the initial state cannot be computed: {e}") from e
    except MemoryError as e:
        raise _out_of_memory(mech, e) from e
    except (ArithmeticError, ValueError, RuntimeError) as e:
        if "bad_alloc" in str(e) or "out of memory" in str(e).lower():
            raise _out_of_memory(mech, e) from e  # CasADi's allocation failures
        raise AssemblyError(f"the initial state cannot be computed: {e}") from e
    return mech, eq_values, model, hs, q, v, events


def _finish(model: Model, hs, rec: Recorder, events: list, after: list[int], stats: Stats,
            integ: Integrator, opts: RunOptions, wall0: float, eq_values: dict,
            status: Status, message: str, err: BaseException | None, throw: bool) -> Result:
    """The Result of the run so far (post-processed), with how IDA ran in its meta; raised
    inside a :class:`SolverError` where the run failed and ``throw`` asks for it."""
    integ.after_run(time.perf_counter() - wall0)
    res = build_result(model, *rec.arrays(model.nq), hs.configurations, hs.params, events, stats,
                       status, message, after, rec.works(), rec.kkt(model.nq, model.m),
                       rec.peaks())
    res.meta["equilibrium"] = eq_values  # the solved [initial] equilibrium, if any
    res.meta["tolerances"] = ({"rtol": opts.rtol, "atol": opts.atol} if integ.method == "ida"
                              else None)  # (atol defaults to 1e-2 of rtol)
    # IDA's linear solver; whether its segments ran in C (else the Python path's fallback)
    res.meta["linsolver"] = getattr(integ, "linear_solver", None)
    res.meta["compiled"] = getattr(integ, "c", None) is not None
    stats.wall_time = time.perf_counter() - wall0  # the whole run, post-processing included
    if "lam" not in res.data and res.t.size:  # post-processing ran out of memory: the
        # states are kept (build_result), the run fails with them
        status, message = res.status, res.message
        err = err if err is not None else MemoryError(message)
    if err is not None and throw:
        raise SolverError(message, status=status, result=res,
                          configuration=hs.configurations[hs.current()],
                          last_event=events[-1] if events else None) from err
    return res




def _apply(done: list, t: float, q: np.ndarray, v: np.ndarray, events: list, rec: Recorder,
           after: list[int], integ: Integrator, opts: RunOptions
           ) -> tuple[np.ndarray, np.ndarray]:
    """Book the transitions the policy decided at time t (an event and a sample after each,
    the event budget checked), tell the integrator, and return the state after them."""
    for tr in done:
        events.append(tr.event)
        q, v = tr.q, tr.v
        rec.add(t, q, v, tr.event.after)
        after.append(len(rec) - 1)
        if len(events) > opts.max_events:
            e = tr.event
            raise SolverError(f"max_events = {opts.max_events} reached at t = {t:.9g} s "
                              f"(last: {e.kind} of joint {e.joint})", status=Status.MAX_EVENTS)
    integ.after_events(done)
    return q, v


def _out_of_memory(mech: Mechanism, e: BaseException) -> CmmError:
    """Running out of memory while the model or the start is built: said as such, not as
    a mechanism that cannot be assembled."""
    return CmmError(f"out of memory while building the equations of {mech.name!r} "
                    f"({len(mech.bodies)} bodies, {len(mech.joints)} joints): "
                    f"{type(e).__name__}: {e}. Free memory or simulate a smaller mechanism")


def run_dae(mech: Mechanism, t_end: float = 10.0, *, rtol: float = IDA_DEFAULTS["rtol"],
            atol: float | None = IDA_DEFAULTS["atol"],
            output_dt: float | None = IDA_DEFAULTS["output_dt"], max_events: int | None = None,
            v_lock: float = 1e-6, max_steps: int | None = None, throw: bool = True,
            model: Model | None = None, progress: bool = False,
            branch: str | tuple[str, int] = "continue",
            compiled: bool | str = IDA_DEFAULTS["compiled"],
            linsolver: str = IDA_DEFAULTS["linsolver"]) -> Result:
    """:func:`simulate` with IDA (``method="ida"``); see there for the parameters."""
    require_mechanism(mech, "run_dae")
    return simulate(mech, t_end, method="ida", rtol=rtol, atol=atol, output_dt=output_dt,
                    max_events=max_events, v_lock=v_lock, max_steps=max_steps, throw=throw,
                    model=model, progress=progress, branch=branch, compiled=compiled,
                    linsolver=linsolver)


def run_iterative(mech: Mechanism, t_end: float = 10.0, *,
                  dt: float = ITERATIVE_DEFAULTS["dt"],
                  output_every: int = ITERATIVE_DEFAULTS["output_every"],
                  v_lock: float = 1e-6, max_events: int | None = None,
                  max_steps: int | None = None, throw: bool = True,
                  model: Model | None = None, progress: bool = False,
                  branch: str | tuple[str, int] = "continue",
                  compiled: bool | str = "auto") -> Result:
    """:func:`simulate` with the paper's fixed-step algorithm (``method="iterative"``);
    ``stats.steps`` counts the fixed steps. See :func:`simulate` for the parameters."""
    require_mechanism(mech, "run_iterative")
    return simulate(mech, t_end, method="iterative", dt=dt, output_every=output_every,
                    v_lock=v_lock, max_events=max_events, max_steps=max_steps, throw=throw,
                    model=model, progress=progress, branch=branch, compiled=compiled)


__all__ = ["METHODS", "check_options", "run_dae", "run_iterative", "simulate"]
