"""Dry friction in the event policy: a joint at rest sticks while the force it must carry
stays within static friction, else slips; a stuck joint whose force passes it slips; a
joint whose motion the drivers fix cannot stick and its friction reverses with its rate.
Called by :func:`cmm_dae.hybrid.policy.handle` and by the start."""

from __future__ import annotations

import numpy as np

from ..core.errors import SolverError, Status
from ..core.records import Event, EventKind, Side
from ..equations.kkt import impact_map
from .state import (
    HybridState,
    Transition,
    impulses,
    joint_acceleration,
    over_constrained,
)

__all__ = ["slip_free", "stick_or_slip"]


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
        # the drivers (and locks) fix this joint's motion: it cannot stick of its own (a
        # press's slide at its dead centre, whose rate only passes zero); it goes on
        # slipping the way the drivers move it, the friction reversed with its rate
        acc, _ = joint_acceleration(hs, q, v, t, joint, hs.locked)
        s = 1 if acc > 0.0 else -1 if acc < 0.0 else -hs.slip.get(joint, 1)
        hs.stick_at.pop(joint, None)
        hs.slip = {**slip, joint: s}
        return Transition(Event(t=t, kind=EventKind.SLIP, joint=joint,
                                side=Side.POSITIVE if s > 0 else Side.NEGATIVE, before=before,
                                after=hs.current(), velocity_before=float(cd[k]),
                                velocity_after=float(cd[k]),
                                note="the drivers move this joint through rest: the "
                                     "friction reverses with its rate"), q, v)
    p = hs.params_of(trial, slip=slip)
    v0, imp = v, np.zeros(model.m)
    if cd[k] != 0.0:
        v0, imp = impact_map(model, q, v, t, p, model.n_fixed + model.locks.index(joint), 0.0)
    try:
        _, lam, _ = model.kkt(q, v0, t, p)
    except np.linalg.LinAlgError as e:  # no consistent forces with the joint at rest
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
