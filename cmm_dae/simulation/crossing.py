"""One singular position crossed inside a run: the crossing (tried again from an earlier
sample where the first try fails or its velocities jump), the samples inside its window
and its ``"singular"`` event in the log."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable

import numpy as np

from ..core.errors import SolverError, Status
from ..core.records import Event, EventKind
from ..equations.kinematics import collapsed_rows, row_names
from ..hybrid import policy as ev
from ..integrators.contract import Integrator, Recorder, RunOptions, SegmentEnd
from ..singular.step import FINE_NODE_RATIO, NODE_RATIO, Crossing, step_over
from .passage import stepped_over

#: A crossing whose velocities jump by more than this times rtol (relative) is tried again
#: from an earlier start: on A02 with 40 loops at rtol 1e-8, a crossing from where IDA gave
#: up jumped 9.3e-6 and lost 0.024 J (tip 1.5e-4 m off after 2 s), from the earlier
#: sample 6.5e-8 (3.6e-7 m); with one or ten loops no crossing at rtol 1e-8 or 1e-10
#: jumped more than 1.3e-8.
RETRY_JUMP = 100.0


def cross_singular(hs: ev.HybridState, integ: Integrator, t: float, q: np.ndarray,
                   v: np.ndarray, opts: RunOptions, rec: Recorder, events: list[Event],
                   after: list[int],
                   retry: Callable[[], tuple[int, SegmentEnd] | None] | None = None,
                   stalled: bool = False, t_min: float = -math.inf
                   ) -> tuple[Crossing, int | None]:
    """Cross the singular position ahead of (t, q, v): the crossing (with the state after
    it), one sample there and a "singular" event at the singular instant. ``retry`` gives
    (the samples to keep, an earlier state) to start again from if the crossing from
    (t, q, v) finds a dead point or a velocity jump above :data:`RETRY_JUMP` times rtol.
    ``stalled``: the segment that ended here recorded no sample (IDA could not restart).
    ``t_min``: that segment's start (s); an instant IDA stepped across lies after it.
    Returns the crossing and, where it started from that earlier state, the number of
    samples kept before it (the segment now ends there), else None."""
    def cross(t: float, q: np.ndarray, v: np.ndarray, node_ratio: float = NODE_RATIO
              ) -> Crossing:
        return step_over(hs.model, hs.p, t, q, v, opts.t_end, opts.branch, rtol=opts.rtol,
                         atol=opts.atol, t_min=t_min, node_ratio=node_ratio,
                         method=integ.method)

    first: Crossing | None = None
    try:
        first = cross(t, q, v)
    except SolverError as e:
        # a dead point, or no singular position where IDA gave up: an earlier start may
        # still find one (the second-order path from IDA's state can miss it)
        if e.status not in (Status.DEAD_POINT, Status.INTEGRATOR) or retry is None:
            raise
        error = e
    cr, kept = first, None
    if retry is not None and (first is None or first.velocity_jump > RETRY_JUMP * opts.rtol):
        # from where IDA gave up the crossing saw the velocities jump (round-off rules
        # the accelerations that close to the instant): again from well before, and the
        # one that jumped less is kept
        cut = retry()
        second = None
        if cut is not None and cut[1].t < t:
            with contextlib.suppress(SolverError):  # the first stands, or its error
                second = cross(cut[1].t, cut[1].q, cut[1].v)
            if second is not None and second.instant and \
                    second.t_singular > t + (t - cut[1].t):
                # not the instant IDA gave up next to but one beyond it: from far back (a
                # long chain's ratio is low everywhere: A02 with 48 loops restarted 0.22 s
                # back) the Gauss steps went through that instant unseen, and the run
                # went on with one event fewer
                second = None
        if second is not None and (first is None or second.velocity_jump < first.velocity_jump):
            cr, kept = second, cut[0]
            rec.truncate(kept)  # the samples IDA took beyond the new start
        elif first is None:  # the last resort: from where IDA gave up, nodes nearer
            with contextlib.suppress(SolverError):
                cr = cross(t, q, v, FINE_NODE_RATIO)
    if cr is None:
        raise error
    cfg = hs.current()
    # the output grid inside the crossing's window, from its own steps (a window can be
    # 0.3 s long where the integrator gave up early, at tight tolerances)
    inside = [(x, *cr.state_at(hs.model, hs.p, x))
              for x in integ.output_times(cr.t0, cr.t_after)]
    if stalled and events and events[-1].kind == "singular" and after[-1] == len(rec) - 1:
        # the integrator could not restart where the last crossing ended: the same
        # crossing, taken further out (one event, its sample moved)
        _add_window(rec, inside, cr, cfg, integ)
        after[-1] = len(rec) - 1
        return cr, kept
    if not cr.instant:
        # only the way out of a near-singular position the run started at (or left
        # already, its instant logged): samples, no event
        _add_window(rec, inside, cr, cfg, integ)
        return cr, kept
    how = ("crossed on the branch of the motion, velocities continuous to "
           f"{cr.velocity_jump:.1e}")
    side = "continue" if opts.branch is None else (
        f"{'switch' if cr.switched else 'continue'} ({opts.branch[0]} "
        f"{'+' if opts.branch[1] > 0 else '-'})")
    if cr.switched:
        how = (f"crossed onto the branch on which joint {opts.branch[0]} moves "
               f"{'forwards' if opts.branch[1] > 0 else 'backwards'}, velocities continuous "
               f"to {cr.velocity_jump:.1e}")
    events.append(_event(cr.t_singular, cr.labels, cr.rank_drop, cr.ratio_min, how, side,
                         cfg, float(np.linalg.norm(v)), float(np.linalg.norm(cr.v))))
    _add_window(rec, inside, cr, cfg, integ)
    after.append(len(rec) - 1)
    if len(events) > opts.max_events:
        raise SolverError(f"max_events = {opts.max_events} reached at t = {t:.9g} s (last: "
                          "a singular position)", status=Status.MAX_EVENTS)
    return cr, kept


def _add_window(rec: Recorder, inside: list, cr: Crossing, cfg: int,
                integ: Integrator) -> None:
    """The crossing's samples on the output grid, the state after it, and the integrator
    told where to go on from."""
    for x, qx, vx in inside:
        rec.add(x, qx, vx, cfg)
    rec.add(cr.t_after, cr.q, cr.v, cfg)
    integ.after_singular(cr.t_after)


def _event(t: float, labels: list[str], drop: int, ratio: float, how: str, side: str,
           cfg: int, speed_before: float, speed_after: float) -> Event:
    """The "singular" event of a singular position passed at t (s)."""
    joint = next((lab.split(" ", 1)[1] for lab in labels if lab.startswith("joint ")), "")
    note = (f"constraints of {row_names(labels)} dependent for an instant (rank drop {drop}, "
            f"singular-value ratio down to {ratio:.1e}); {how}")
    # nothing is lost at a singular position (the velocities are continuous); the kinetic
    # energy changes across a crossing's window by the work of the forces, which the
    # energy audit books from the samples
    return Event(t=t, kind=EventKind.SINGULAR, joint=joint, side=side, before=cfg,
                 after=cfg, velocity_before=speed_before, velocity_after=speed_after,
                 note=note)


def log_stepped_over(hs: ev.HybridState, t: float, q: np.ndarray, v: np.ndarray,
                     opts: RunOptions, rec: Recorder, n0: int, end: SegmentEnd,
                     events: list[Event], after: list[int]) -> list[tuple[float, int]]:
    """Under ``branch = "continue"``: a "singular" event for every singular position IDA
    integrated through inside the segment from (t, q, v) (:func:`passage.stepped_over`),
    at the instant where the samples' interpolant has the smallest singular-value ratio,
    its state after it being the first sample after that instant. Returns (instant, index
    of that sample) for each."""
    model, p, cfg = hs.model, hs.p, hs.current()
    logged = []
    for ps, k, q_s, v_s, r0 in stepped_over(model, p, t, q, v, rec, n0, end):
        # against r0, the ratio a crossing of it would start from
        drop, labels = collapsed_rows(model, q_s, ps.t, p, r0)
        speed = float(np.linalg.norm(v_s))
        events.append(_event(ps.t, labels, drop, ps.ratio, "IDA integrated through it "
                             "within its error test (found afterwards in its samples, the "
                             "instant on their cubic interpolant)", "continue", cfg, speed,
                             speed))
        after.append(k)
        logged.append((ps.t, k))
        if len(events) > opts.max_events:
            raise SolverError(f"max_events = {opts.max_events} reached at t = {ps.t:.9g} s "
                              "(last: a singular position)", status=Status.MAX_EVENTS)
    return logged


#: Two records of a singular instant closer than this (relative to the time, s) are one.
TWIN_INSTANT = 1e-6


def drop_twin_passage(events: list, after: list[int], passed: list[tuple[float, int]],
                       cr) -> None:
    """A singular position IDA integrated through (found in its samples) and then, IDA
    failing right after it, crossed from its last state: one instant, logged once, by the
    crossing (A02 at rtol 1e-8 with IDA's own steps logged 1.2152617825 s twice, 2e-11 s
    apart). The passage's event, its sample index and its entry in ``passed`` go."""
    # the same instant to well within what either finds it to (the passage on the
    # samples' interpolant, the crossing along its Gauss steps); two singular positions a
    # microsecond apart are one event to any integrator
    if not passed or abs(passed[-1][0] - cr.t_singular) > TWIN_INSTANT * max(1.0, cr.t_after):
        return
    t_p = passed.pop()[0]
    i = next(i for i in range(len(events) - 2, -1, -1)
             if events[i].kind == "singular" and events[i].t == t_p)
    del events[i], after[i]
