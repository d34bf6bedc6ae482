"""Dry friction in the event policy: a joint at rest sticks while the force it must carry
stays within static friction, else slips; a stuck joint whose force passes it slips; a
joint whose motion the drivers fix cannot stick and its friction reverses with its rate.
Called by :func:`cmm_dae.hybrid.policy.handle` and by the start."""

from __future__ import annotations

import numpy as np

from ..core.errors import SolverError, Status
from ..core.records import Event, EventKind, Side
from ..equations.kinematics import project_state
from ..equations.kkt import impact_map
from .state import (
    HybridState,
    Transition,
    Trigger,
    TriggerKind,
    idle_slide,
    impulses,
    joint_acceleration,
    over_constrained,
)

__all__ = ["follow_impulse", "held_joints", "resting_slips", "settle", "slip_free",
           "stick_or_slip"]


def _direction(force: float) -> int:
    """Slip direction of a joint freed from a lock that carried ``force`` (along +c):
    it moves the way the applied loads push it, against the lock."""
    return -1 if force > 0.0 else 1


def _begin_slip(hs: HybridState, t: float, joint: str, force: float, before: int,
                rate: float) -> Event:
    """The joint (no longer locked) slips the way the loads push it; the slip event."""
    s = _direction(force)
    hs.stick_at.pop(joint, None)
    hs.slip = {**hs.slip, joint: s}
    return Event(t=t, kind=EventKind.SLIP, joint=joint,
                 side=Side.POSITIVE if s > 0 else Side.NEGATIVE, before=before,
                 after=hs.current(), velocity_before=rate, velocity_after=rate,
                 release_force=float(force))


def _immobile(hs: HybridState, q: np.ndarray, t: float) -> bool:
    """Whether the configuration in force leaves the mechanism no motion at all: its
    active rows fix every coordinate (rank nq) and none depends on time (no driver moves
    it). A joint whose rate merely passes zero where its lock would be redundant for an
    instant (the rod pin of a slider-crank while the crank passes upright) is not so."""
    model = hs.model
    p = hs.params_of(hs.locked)
    con = model.constraints(q, t, p)
    act = model.active_rows(p)
    return not np.any(con.Phi_t[act] != 0.0) and \
        np.linalg.matrix_rank(con.Phi_q[act]) >= model.nq


def held_joints(hs: HybridState) -> list[str]:
    """Frictional joints neither locked nor slipping (nor the slide of a contact that
    does not touch): held at rest by the locks of others (:func:`stick_or_slip`); a
    release that lets the mechanism move decides them again."""
    return [j for j in hs.model.frictional if j not in hs.locked and j not in hs.slip
            and not idle_slide(hs.model, j, hs.locked)]


def settle(hs: HybridState, done: Transition, t: float) -> list[Transition]:
    """``done`` (a joint's stick or slip at rest) and, where it was a stick that leaves the
    mechanism no motion at all, the joints still slipping held at rest with it, at that
    instant: their rates are round-off from here on (IDA met them one by one microseconds
    later, at rates of 1e-40; the fixed-step algorithm never, so the two logs differed)."""
    out = [done]
    if done.event.kind != EventKind.STICK or not hs.slip or not _immobile(hs, done.q, t):
        return out
    _, cd = hs.model.joint_rates(done.q, done.v)
    for joint in sorted(hs.slip):
        out.append(_hold(hs, done.q, done.v, t, joint, float(cd[hs.model.jidx[joint]])))
    return out


def _hold(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
          rate: float) -> Transition:
    """``joint`` held at rest by the other joints' locks (:func:`_immobile`): no lock of
    its own, which would repeat theirs, no friction of its own to reverse at every
    round-off sign of its rate (a storm of slip events at rates of 1e-42), until a release
    lets it move (:func:`held_joints`)."""
    before = hs.current()
    hs.slip = {j: s for j, s in hs.slip.items() if j != joint}
    hs.stick_at.pop(joint, None)
    return Transition(Event(t=t, kind=EventKind.STICK, joint=joint, side=Side.STICK,
                            before=before, after=hs.current(), velocity_before=rate,
                            velocity_after=rate, note="held at rest by the other joints' locks"),
                      q, v)


def resting_slips(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float
                  ) -> list[Trigger]:
    """The rate triggers of slipping joints that move against their slip where the next
    segment starts, at (q, v) projected onto the constraints as that start projects them
    (:func:`~cmm_dae.equations.kinematics.project_state`): the joints of a one-degree-of-
    freedom linkage all pass rest together at its turning points, IDA locates the instant
    on one of them, and the projection of IDA's interpolated state left the others' rates
    just past zero, where no root finder sees them cross (a free four-bar's pins B, C, D
    kept their friction pushing them for 0.15 s), where they turn back; and at the start,
    a joint at rest whose slip was decided before the others' and now accelerates against
    it. Decided at that instant."""
    model = hs.model
    if not hs.slip:
        return []
    qp, vp = project_state(model, q, v, t, hs.p)
    _, cd = model.joint_rates(qp, vp)
    back = [j for j, s in hs.slip.items() if s * cd[model.jidx[j]] <= 0.0]
    if not back:
        return []
    # and are turning back (a joint that has just begun to slip from rest, its rate a
    # round-off zero of either sign, accelerates the way it slips)
    acc = model.joint_accelerations(qp, vp, model.kkt(qp, vp, t, hs.p)[0], t)
    return [Trigger(j, Side.NONE, TriggerKind.RATE) for j in back
            if hs.slip[j] * acc[model.jidx[j]] < 0.0]


def follow_impulse(hs: HybridState, q: np.ndarray, v: np.ndarray, v_lock: float) -> None:
    """After an impact's impulse: a slipping joint that it sent the other way (faster than
    ``v_lock``) slips that way (the double-folded mechanism's pin D, reversed by the
    slider's stop, had kept its friction pushing it along for 2 s)."""
    _, cd = hs.model.joint_rates(q, v)
    rate = {j: float(cd[hs.model.jidx[j]]) for j in hs.slip}
    hs.slip = {j: (1 if rate[j] > 0 else -1) if s * rate[j] < -v_lock else s
               for j, s in hs.slip.items()}


def slip_free(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
              force: float) -> Event:
    """A stuck joint whose force exceeds static friction starts to slip."""
    before = hs.current()
    hs.locked = {j: x for j, x in hs.locked.items() if j != joint}
    return _begin_slip(hs, t, joint, force, before, 0.0)


def stick_or_slip(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str
                  ) -> Transition:
    """A joint with friction at rest (a slipping joint whose rate reached zero, or one
    that starts at rest): it sticks if the force it must then carry is within static
    friction, else it slips (on the other way). The lock puts the rate exactly to zero (a
    vanishing impulse at a located root; the fixed-step algorithm's overshoot of one step
    otherwise; nothing at all for a rate already zero)."""
    model = hs.model
    k = model.jidx[joint]
    before = hs.current()
    c, cd = model.joint_rates(q, v)
    slip = {j: s for j, s in hs.slip.items() if j != joint}
    trial = {**hs.locked, joint: "stick"}
    hs.stick_at[joint] = float(c[k])
    if over_constrained(hs, trial, q, t):
        if _immobile(hs, q, t):  # (the others' locks hold the mechanism: its slider stuck)
            return _hold(hs, q, v, t, joint, float(cd[k]))
        # the drivers (and locks) fix this joint's motion: it cannot stick of its own (a
        # press's slide at its dead centre, whose rate only passes zero); it goes on
        # slipping the way the drivers move it, the friction reversed with its rate
        # the way it moves on: already reversed (the fixed-step algorithm meets the
        # reversal a step late), else the way it accelerates from rest
        old = hs.slip.get(joint, 1)
        if cd[k] * old < 0.0:
            s = -old
        else:
            acc, _ = joint_acceleration(hs, q, v, t, joint, hs.locked)
            s = 1 if acc > 0.0 else -1 if acc < 0.0 else -old
        hs.stick_at.pop(joint, None)
        hs.slip = {**slip, joint: s}
        return Transition(Event(t=t, kind=EventKind.SLIP, joint=joint,
                                side=Side.POSITIVE if s > 0 else Side.NEGATIVE, before=before,
                                after=hs.current(), velocity_before=float(cd[k]),
                                velocity_after=float(cd[k]),
                                note="its lock would repeat the other constraints here "
                                     "(the drivers or the linkage move it through rest): "
                                     "the friction reverses with its rate"), q, v)
    p = hs.params_of(trial, slip=slip)
    v0, imp = v, np.zeros(model.m)
    if cd[k] != 0.0:
        v0, imp = impact_map(model, q, v, t, p, model.n_fixed + model.locks.index(joint), 0.0)
    try:
        _, lam, _ = model.kkt(q, v0, t, p)
    except np.linalg.LinAlgError as e:  # no consistent forces with the joint at rest
        on = _slip_on(hs, q, v, t, joint, slip, before, float(cd[k]))
        if on is not None:
            return on
        raise SolverError(
            f"friction jam at t = {t:.9g} s: joint '{joint}' comes to rest and neither "
            "sticking nor slipping is consistent: the friction from the reactions would lock "
            f"the mechanism against its own loads ({e}); less friction or another load "
            "frees it", status=Status.JAM) from e
    force = hs.push(lam, joint, trial)
    hs.slip = slip
    if abs(force) <= hs.static(joint, lam):
        hs.locked = trial
        lost = float(0.5 * np.sum(model.mass * (v**2 - v0**2)))
        return Transition(Event(t=t, kind=EventKind.STICK, joint=joint, side=Side.STICK,
                                before=before, after=hs.current(),
                                velocity_before=float(cd[k]), velocity_after=0.0,
                                impulses=impulses(model, imp), energy_lost=lost,
                                release_force=float(force)), q, v0)
    return Transition(_begin_slip(hs, t, joint, force, before, float(cd[k])), q, v)


def _slip_on(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
             slip: dict, before: int, rate: float) -> Transition | None:
    """A joint at rest whose sticking has no consistent forces slips on the other way
    where that is consistent: forces that solve with its friction reversed and a motion
    that goes that way (already moving so, or accelerating so from rest); None where it
    is not (a jam). So passes a joint whose rate crosses zero next to a position where its
    lock would leave the mechanism no consistent motion (a slider-crank's rod pin while
    the crank passes upright): the fixed-step algorithm meets it a step late, where the
    stick trial's forces are near-singular and friction from the reaction makes them
    inconsistent; IDA, at the located instant, found the lock's rows dependent."""
    model = hs.model
    k = model.jidx[joint]
    s = (1 if rate > 0.0 else -1) if rate != 0.0 else -hs.slip.get(joint, 1)
    trial = {**slip, joint: s}
    try:
        a, _, _ = model.kkt(q, v, t, hs.params_of(hs.locked, slip=trial))
    except np.linalg.LinAlgError:
        return None
    acc = float(model.joint_accelerations(q, v, a, t)[k])
    if rate == 0.0 and acc * s < 0.0:
        return None
    hs.stick_at.pop(joint, None)
    hs.slip = trial
    return Transition(Event(t=t, kind=EventKind.SLIP, joint=joint,
                            side=Side.POSITIVE if s > 0 else Side.NEGATIVE, before=before,
                            after=hs.current(), velocity_before=rate, velocity_after=rate,
                            note="sticking has no consistent forces here: the joint "
                                 "slips on, its friction reversed"), q, v)
