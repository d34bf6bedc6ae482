"""The one event policy of both integrators: crossings, impacts, locks, releases, the Zeno rule.

A configuration is the set of locked metamorphic joints (joint -> side). An integrator only
*detects* a trigger — IDA by locating a root of :func:`event_values`, the fixed-step
algorithm by :func:`crossings` at the end of a step — and hands it to :func:`handle`, which
decides what happens and returns the transitions (event, state after it). Nothing here knows
which integrator asked, except through :class:`Policy.resolution`, the shortest time between
two events that the integrator can tell apart.

Lock sets are values: a trial set (is this new lock a jam?) is an argument of the function
that asks, never an edit of the shared state undone afterwards.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.records import Event, EventKind, Side
from ..description.parts import stop_tolerance
from ..equations.kinematics import (
    dependent_rows,
    project_positions,
    project_velocities,
    row_names,
)
from ..equations.kkt import impact_map
from ..equations.model import Model
from .friction import follow_impulse, held_joints, resting_slips, settle, slip_free, stick_or_slip
from .state import (
    ZENO_DT,
    HybridState,
    Locked,
    LockUpError,
    Policy,
    SegmentTrace,
    Transition,
    Trigger,
    TriggerKind,
    idle_slide,
    impulses,
    joint_acceleration,
    joint_rate,
    over_constrained,
    slide_of,
    without,
    zeno,
)
from .zones import _zone_margin, initial_zones, pick, zone_switch

TK = TriggerKind
#: the triggers that read a lock's force (a KKT solve's multipliers)
LOCK_FORCES = (TK.PUSH, TK.SLIP)

# The names callers reach as ``events.X`` (the policy's vocabulary), whichever module holds
# them.
__all__ = [
    "ZENO_DT", "HybridState", "LockUpError", "Policy", "SegmentTrace", "Transition",
    "LOCK_FORCES", "Trigger", "TriggerKind", "at_limit",
    "confirm", "crossings", "dependent_rows", "event_list", "event_values", "handle",
    "impact_map", "initial_zones", "over_constrained", "project_positions",
    "project_velocities", "release", "resting_rate", "start_triggers", "stick_or_slip",
    "zone_edges",
    "would_reenter", "zeno", "zone_switch",
]


# ------------------------------------------------------------------- detection
def event_list(model: Model, locked: Locked) -> list[Trigger]:
    """The triggers watched in configuration ``locked``: a ``gap`` for each open limit side
    of an unlocked joint, a ``push`` for each locked joint, a ``zone`` for each load that
    acts in a zone (``joint`` holds the load's name). All cross zero downwards."""
    out = [Trigger(name, Side.NONE, TK.ZONE) for name in model.zoned]
    for name in model.locks:
        if name in locked:
            kind = TK.SLIP if locked[name] == Side.STICK else TK.PUSH
            out.append(Trigger(name, Side(locked[name]), kind))
            continue
        if idle_slide(model, name, locked):
            continue
        lim = model.joints[name].stops
        if lim is not None and lim.lower is not None:
            out.append(Trigger(name, Side.LOWER, TK.GAP))
        if lim is not None and lim.upper is not None:
            out.append(Trigger(name, Side.UPPER, TK.GAP))
        if model.joints[name].friction is not None:
            out.append(Trigger(name, Side.NONE, TK.RATE))  # a slipping joint's rate
    return out


def event_values(hs: HybridState, c, cdot, lam, triggers: list[Trigger], out,
                 where=pick) -> None:
    """Values of the event functions of ``triggers`` (see :func:`event_list`) into ``out``.

    A gap is armed only while its joint approaches the stop (+1 while it moves away): just
    after a release or a rejected root the joint leaves at almost zero speed and round-off
    in the gap would otherwise read as arrivals, one restart after the other. The jump to
    +1 is never a downward crossing. But a joint beyond its stop by more than the
    integrator resolves (``hs.gap_band``) reads as beyond it whichever way it moves: a
    follower that fell through a cam within one long step of free flight (a parabola IDA
    integrates exactly) and was moving out again at the step's end read +1 at both ends,
    and the landing was lost. A push needs the multipliers ``lam`` of a KKT solve.

    Written once for numbers and for CasADi expressions: with ``where=casadi.if_else`` and
    symbolic ``c``, ``cdot``, ``lam`` (``out`` a list) it builds IDA's event function."""
    jidx = hs.model.jidx
    for i, tr in enumerate(triggers):
        if tr.kind == TK.ZONE:
            out[i] = _zone_margin(hs, tr.joint, c, cdot, where)
        elif tr.kind == TK.RATE:  # positive while it slips on in its direction
            out[i] = hs.slip.get(tr.joint, 0) * cdot[jidx[tr.joint]]
        elif tr.kind == TK.SLIP:  # positive while the stuck joint carries less than Fs
            out[i] = hs.static(tr.joint, lam) - abs(hs.push(lam, tr.joint))
        elif tr.kind == TK.GAP:
            k = jidx[tr.joint]
            L = hs.limit_value(tr.joint, tr.side)
            band = hs.stop_band(L, where)
            if tr.side == "lower":
                out[i] = where(cdot[k] > 0.0, where(c[k] - L > -band, 1.0, c[k] - L), c[k] - L)
            else:
                out[i] = where(cdot[k] < 0.0, where(L - c[k] > -band, 1.0, L - c[k]), L - c[k])
        else:  # friction holds a joint on its stop until the pull beats it
            out[i] = hs.push(lam, tr.joint) + hs.static(tr.joint, lam)


def crossings(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float,
              values: np.ndarray | None = None,
              triggers: list[Trigger] | None = None,
              lam: np.ndarray | None = None) -> list[Trigger]:
    """Triggers crossed at a state reached by a finite step (the fixed-step algorithm):
    those whose event function (:func:`event_values`, IDA's too) is negative there. A gap
    must be beyond its stop by more than round-off (a just-released joint sits a hair
    beyond it); a joint that stayed locked at this very instant is not reported again.
    ``values``: the event functions of ``triggers`` (default ``event_list(model,
    hs.locked)``) at (q, v, t), when the caller has them already; ``lam``: the multipliers
    there, when the caller solved them already."""
    model = hs.model
    if triggers is None:
        triggers = event_list(model, hs.locked)
    if not triggers or (values is not None and not np.min(values) < 0.0):
        return []  # (every trigger below needs a negative value)
    if values is None:
        c, cd = model.joint_rates(q, v)
        needs_lam = any(tr.kind in (TK.PUSH, TK.SLIP) for tr in triggers)
        if needs_lam and lam is None:
            lam = model.kkt(q, v, t, hs.p)[1]
        values = np.empty(len(triggers))
        event_values(hs, c, cd, lam, triggers, values)
    out = []
    for tr, val in zip(triggers, values, strict=True):
        if tr.kind == TK.GAP:
            crossed = val < -1e-12 * (1.0 + abs(hs.limit_value(tr.joint, tr.side)))
        elif tr.kind == TK.ZONE:  # beyond round-off too: a jaw locked on its stop at a
            # zone's edge read +-2e-16 off it step after step, 140 zone events in 5 s
            edge = max((abs(x) for x in model.zone_info[tr.joint][1:] if math.isfinite(x)),
                       default=0.0)  # (a zone may be open on one side)
            crossed = val < -1e-12 * (1.0 + edge)
        elif tr.kind in (TK.PUSH, TK.SLIP):
            crossed = val < 0.0 and hs.stayed.get(tr.joint) != t
        else:
            crossed = val < 0.0
        if crossed:
            out.append(tr)
    return out


def resting_rate(cd: np.ndarray) -> float:
    """Largest joint rate that counts as rest at an assembled start: round-off of the
    velocity solve (a joint named at rest comes out at 1e-18, not 0)."""
    return 1e-12 * max(1.0, float(np.max(np.abs(cd), initial=0.0)))


def start_triggers(hs: HybridState, q: np.ndarray, v: np.ndarray) -> list[Trigger]:
    """Gaps that are zero at the start of a run and close: a joint that starts exactly on
    its stop, moving into it.

    A root finder only sees sign changes; an event function that starts at zero is decided
    by its rate here, and the run applies these triggers (an impact or a lock) before it
    integrates. Without it IDA carried a pendulum started on its stop, moving into it,
    2 rad through the stop with status "success"."""
    model = hs.model
    c, cd = model.joint_rates(q, v)
    still = resting_rate(cd)
    out = []
    for tr in event_list(model, hs.locked):
        if tr.kind != "gap":
            continue
        k = model.jidx[tr.joint]
        L = hs.limit_value(tr.joint, tr.side)
        into = cd[k] < -still if tr.side == "lower" else cd[k] > still
        if into and abs(c[k] - L) <= stop_tolerance(L):
            out.append(tr)
    return out + zone_edges(hs, q, v) + resting_slips(hs, q, v, 0.0)


def zone_edges(hs: HybridState, q: np.ndarray, v: np.ndarray) -> list[Trigger]:
    """Zones whose event function is not positive where a segment starts: a coordinate on
    an edge and already moving in or out (a joint released from a stop at a zone's edge),
    where a root finder sees no sign change and the zone would be missed. Decided here,
    by the direction of motion (:func:`zone_switch`), before the segment is integrated."""
    model = hs.model
    if not model.zoned:
        return []
    c, cd = model.joint_rates(q, v)
    return [tr for tr in event_list(model, hs.locked)
            if tr.kind == TK.ZONE and _zone_margin(hs, tr.joint, c, cd) <= 0.0]


def confirm(hs: HybridState, tr: Trigger, q: np.ndarray, v: np.ndarray, t: float,
            policy: Policy) -> bool:
    """Is a detected trigger a real switch? Re-entry guards shared by both integrators.

    A gap is rejected when the joint already moves away from the stop (a round-off root),
    or when it arrives at (almost) zero speed and the stop would have to pull (the joint
    is leaving); a push is rejected when the joint is no longer locked, a gap when it is
    locked already (an earlier event of the same instant changed it)."""
    if tr.kind in (TK.PUSH, TK.SLIP):
        return hs.locked.get(tr.joint) == tr.side
    if tr.kind == TK.RATE:
        return tr.joint in hs.slip
    if tr.joint in hs.locked:
        return False
    cdv = joint_rate(hs.model, q, v, tr.joint)
    if (cdv >= 0.0 and tr.side == "lower") or (cdv <= 0.0 and tr.side == "upper"):
        return False
    if abs(cdv) <= policy.v_lock:  # leaving only where the stop would have to pull (a
        # joint drifting in with nothing along it, force 0, passed through its stop)
        trial = {**hs.locked, tr.joint: tr.side}
        q_on = project_positions(hs.model, q, t, hs.params_of(trial))
        return hs.lock_force(q_on, v, t, tr.joint, trial) >= 0.0
    return True


def handle(hs: HybridState, tr: Trigger, q: np.ndarray, v: np.ndarray, t: float,
           policy: Policy) -> list[Transition]:
    """Decide what a trigger does and apply it to ``hs``; returns the transitions in order
    (none when the trigger is rejected or the joint stays locked)."""
    if tr.kind == TK.ZONE:
        done = zone_switch(hs, tr.joint, q, v, t)
        if done is None:
            return []
        # The load switched on or off at once: a joint held on its stop (or stuck) may no
        # longer be held from this very instant. Its event function jumped below zero
        # rather than crossing it, so no root finder would report it: check here.
        out = [done]
        for nxt in crossings(hs, done.q, done.v, t):
            if nxt.kind in (TK.PUSH, TK.SLIP):
                out += handle(hs, nxt, done.q, done.v, t, policy)
        return out
    if not confirm(hs, tr, q, v, t, policy):
        return []
    if tr.kind == TK.GAP:
        return at_limit(hs, q, v, t, tr.joint, tr.side, policy)
    if tr.kind == TK.RATE:
        return settle(hs, stick_or_slip(hs, q, v, t, tr.joint), t)
    force = hs.lock_force(q, v, t, tr.joint)
    if tr.kind == TK.SLIP:
        return _decide_held(hs, [Transition(slip_free(hs, q, v, t, tr.joint, force), q, v)], t)
    if would_reenter(hs, q, v, t, tr.joint, tr.side) and \
            t - hs.stayed.get(tr.joint, -math.inf) > ZENO_DT:
        hs.stayed[tr.joint] = t  # stays locked: no chattering
        return []
    away = 1 if tr.side == "lower" else -1  # a frictional joint slides off its stop
    return _decide_held(hs, [Transition(release(hs, q, v, t, tr.joint, force, away), q, v)],
                        t)


def _decide_held(hs: HybridState, out: list[Transition], t: float) -> list[Transition]:
    """After a release: the joints the released lock held at rest stick or slip again."""
    for joint in held_joints(hs):  # (each from the state the one before left)
        out.append(stick_or_slip(hs, out[-1].q, out[-1].v, t, joint))
    return out


def _release_jammed(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                    side: str) -> tuple[list[Transition], bool]:
    """Before ``joint`` locks: if the lock would over-constrain (jam) the mechanism, the
    impact frees locks that it depends on: first joints held on their stops by a preloaded
    spring (force constraints: the impact beats the preload), then other locks (the impact
    pulls them off their stops). One release event each, with the lock force just before.
    Returns them and whether it still jams with nothing left to free (a lock-up)."""
    out: list[Transition] = []
    if not over_constrained(hs, {**hs.locked, joint: side}, q, t):
        return out, False
    order = sorted(hs.locked.items(), key=lambda kv: hs.force_held.get(kv[0]) != kv[1])
    for other, _ in order:
        force = hs.lock_force(q, v, t, other)
        out.append(Transition(release(hs, q, v, t, other, force), q, v))
        if not over_constrained(hs, {**hs.locked, joint: side}, q, t):
            return out, False
    return out, True


def at_limit(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str, side: str,
             policy: Policy) -> list[Transition]:
    """Apply the impact map when ``joint`` reaches its ``side`` limit at time t.

    ``q`` is put exactly on the stop here (after any jammed lock is freed, so that the
    constraint set is consistent). Plastic impact, a rebound slower than ``v_lock``, a
    bounce closer than ``resolution`` to the previous one, or a rebound whose flight back
    would be shorter than ``resolution`` locks the joint; a lock whose force is already of
    the wrong sign releases at once (two events).
    """
    model = hs.model
    out, jammed = _release_jammed(hs, q, v, t, joint, side)
    target = {**hs.locked, joint: side}
    if jammed:
        labels, _ = dependent_rows(model, q, t, hs.params_of(target), tol=1e-9)
        drivers = ", ".join(f"driver {d}" for d in model.driver_names) or "no driver"
        raise LockUpError(
            f"lock-up at t = {t:.9g} s: with joint {joint} locked on its {side} stop the "
            f"constraints of {row_names(labels)} cannot all hold; the mechanism has no freedom "
            f"left for its drivers ({drivers}): the stop would have to stop a driver")
    p_locked = hs.params_of(target)
    q = project_positions(model, q, t, p_locked)  # clamp onto the stop
    before = hs.current()
    cdm = joint_rate(model, q, v, joint)
    e = model.joints[joint].restitution
    T_minus = 0.5 * np.sum(model.mass * v**2)
    row = model.n_fixed + model.locks.index(joint)
    v_plus, imp = impact_map(model, q, v, t, p_locked, row, -e * cdm)
    cdp = -e * cdm
    gap = policy.gap[0] * abs(hs.limit_value(joint, side)) + policy.gap[1]
    bounce = e > 0 and abs(cdp) > policy.v_lock and \
        not zeno(hs.bounces.get(joint, []), t, e, policy.resolution) and \
        (gap == 0.0 or _rise(hs, q, v_plus, t, joint, side, cdp) > gap)
    slide = slide_of(model, joint)
    if not bounce:
        v_plus, imp = impact_map(model, q, v, t, p_locked, row, 0.0)
        cdp = 0.0
        hs.locked = target
        hs.slip = {j: s for j, s in hs.slip.items() if j != joint}  # on the stop: no slip
        hs.bounces.pop(joint, None)
        if slide is not None:  # landed: its slide slips the way it moves (a frictionless
            rate = joint_rate(model, q, v_plus, slide)  # impact), or is decided below
            if abs(rate) > policy.v_lock:
                hs.slip = {**hs.slip, slide: 1 if rate > 0 else -1}
    else:
        hs.bounces.setdefault(joint, []).append(t)
        if joint in hs.slip:  # it slides back the other way
            hs.slip = {**hs.slip, joint: 1 if cdp > 0 else -1}
    follow_impulse(hs, q, v_plus, policy.v_lock)
    lost = float(T_minus - 0.5 * np.sum(model.mass * v_plus**2))
    kind = EventKind.BOUNCE if bounce else EventKind.LANDING if model.joints[joint].lands \
        else EventKind.LOCK if abs(cdm) <= policy.v_lock else EventKind.LIMIT
    out.append(Transition(Event(t=t, kind=kind, joint=joint, side=side, before=before,
                                after=hs.current(), velocity_before=cdm, velocity_after=cdp,
                                impulses=impulses(model, imp), energy_lost=lost), q, v_plus))
    if not bounce:
        force = hs.lock_force(q, v_plus, t, joint)
        if force < 0.0:  # the stop would have to pull at once: no chattering
            out.append(Transition(release(hs, q, v_plus, t, joint, force), q, v_plus))
        elif slide is not None and slide not in hs.slip:  # landed at rest along the curve
            out.append(stick_or_slip(hs, q, v_plus, t, slide))
    return out


def _rise(hs: HybridState, q: np.ndarray, v_plus: np.ndarray, t: float, joint: str,
          side: str, rate: float) -> float:
    """How far a rebound at ``rate`` would rise off its stop, m or rad: rate^2 / 2|a| under
    the joint's free acceleration back into the stop (inf when it does not come back)."""
    acc, _ = joint_acceleration(hs, q, v_plus, t, joint, hs.locked)
    back = acc if side == "upper" else -acc
    return 0.5 * rate * rate / back if back > 0.0 else math.inf


def release(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
            force: float, away: int = 1) -> Event:
    """Unlock ``joint`` at time t; the event carries the lock force at release. A joint
    with friction leaves slipping in direction ``away``."""
    before = hs.current()
    side = hs.locked[joint]
    hs.locked = without(hs.model, hs.locked, joint)  # a contact's slide goes with it
    slide = slide_of(hs.model, joint)
    hs.stick_at.pop(joint, None)
    hs.stick_at.pop(slide, None)
    hs.slip = {j: s for j, s in hs.slip.items() if j != slide}
    if hs.model.joints[joint].friction is not None:
        hs.slip = {**hs.slip, joint: away}
    cdv = joint_rate(hs.model, q, v, joint)
    kind = EventKind.LIFT_OFF if hs.model.joints[joint].lands else EventKind.RELEASE
    return Event(t=t, kind=kind, joint=joint, side=side, before=before,
                 after=hs.current(), velocity_before=cdv, velocity_after=cdv,
                 release_force=float(force))


def would_reenter(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                  side: str) -> bool:
    """True when, unlocked, the joint would clearly accelerate into its stop at once.

    At a release root the lock force and the free acceleration both pass through zero, so
    only an acceleration into the stop above round-off level (relative to the bodies'
    accelerations) counts; a single lock can never re-enter (complementarity).
    """
    free = without(hs.model, hs.locked, joint)
    acc, amax = joint_acceleration(hs, q, v, t, joint, free)
    into = -acc if side == "lower" else acc
    return into > 1e-9 * (1.0 + amax)
