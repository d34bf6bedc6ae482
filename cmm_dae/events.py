"""Hybrid logic shared by both integrators: configurations, impact map, lock and release.

A configuration is the set of locked metamorphic joints. This module decides what happens
at a limit (impact map, bounce or lock, Zeno guard, immediate release when the stop would
have to pull) and at a release, and keeps the registry of configurations with the paper's
labels. It knows the equations (:class:`Model`) but not the integrator.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .equations import Model
from .errors import SolverError
from .result import Configuration, Event


class LockUpError(SolverError):
    """A new lock leaves the drivers no freedom: the mechanism locks up."""

#: Consecutive bounces of one joint closer than this in time end in a lock (Zeno guard), s.
ZENO_DT = 1e-9


@dataclass
class HybridState:
    """The locked joints (joint -> side) and the registry of configurations met so far."""

    model: Model
    labeller: object = None  # callable(locked: dict[str, str]) -> (label, dof)
    locked: dict[str, str] = field(default_factory=dict)
    force_held: dict[str, str] = field(default_factory=dict)  # preloaded joint -> side
    configurations: list[Configuration] = field(default_factory=list)
    params: list[np.ndarray] = field(default_factory=list)
    _index: dict[tuple, int] = field(default_factory=dict)

    def limit_value(self, joint: str, side: str) -> float:
        lim = self.model.mech.joints[joint].limits
        return lim.lower if side == "lower" else lim.upper

    def current(self) -> int:
        """Index of the configuration of the current locked set (registered on first use)."""
        key = tuple(sorted(self.locked.items()))
        if key not in self._index:
            locked = dict(key)
            label, dof = self.labeller(locked) if self.labeller else ("", 0)
            self._index[key] = len(self.configurations)
            self.configurations.append(Configuration(
                tuple(locked), tuple(locked.values()), dof, label))
            self.params.append(self.model.params(
                {j: self.limit_value(j, s) for j, s in locked.items()}))
        return self._index[key]

    @property
    def p(self) -> np.ndarray:
        return self.params[self.current()]

    def push(self, lam: np.ndarray, joint: str) -> float:
        """Force/torque with which the stop of a locked joint pushes it (>= 0 while held).

        The lock row is ``c - L``; the generalized force on the second body along the joint
        is ``-lambda``, which the lower stop must give positive and the upper stop negative.
        """
        k = self.model.n_fixed + self.model.locks.index(joint)
        return -lam[k] if self.locked[joint] == "lower" else lam[k]


def event_values(hs: HybridState, c: np.ndarray, lam: np.ndarray | None,
                 events: list[tuple[str, str, str]] | None = None,
                 cdot: np.ndarray | None = None) -> np.ndarray:
    """Values of the event functions of the current configuration (see :func:`event_list`;
    pass that list as ``events`` to save building it at every call).

    With the coordinate rates ``cdot`` a gap is armed only while its joint approaches the
    stop (+1 while it moves away): just after a release or a rejected root the joint leaves
    at almost zero speed and round-off in the gap would otherwise read as arrivals, one
    restart after the other. The jump to +1 is never a downward crossing."""
    out = []
    for joint, side, kind in events if events is not None else event_list(hs):
        if kind == "gap":
            L = hs.limit_value(joint, side)
            k = hs.model.jidx[joint]
            away = cdot is not None and (cdot[k] > 0.0 if side == "lower" else cdot[k] < 0.0)
            out.append(1.0 if away else (c[k] - L if side == "lower" else L - c[k]))
        else:
            out.append(hs.push(lam, joint))
    return np.array(out)


def event_list(hs: HybridState) -> list[tuple[str, str, str]]:
    """(joint, side, kind) of each event function: ``gap`` for each open limit side of an
    unlocked joint, ``push`` for each locked joint. All cross zero downwards."""
    out = []
    for name in hs.model.locks:
        if name in hs.locked:
            out.append((name, hs.locked[name], "push"))
            continue
        lim = hs.model.mech.joints[name].limits
        if lim.lower is not None:
            out.append((name, "lower", "gap"))
        if lim.upper is not None:
            out.append((name, "upper", "gap"))
    return out


def project_positions(model: Model, q: np.ndarray, t: float, p: np.ndarray) -> np.ndarray:
    """Minimal-norm Newton projection of q onto the active position constraints."""
    free = model.free(p)[0]
    act = np.flatnonzero(free == 0.0)
    for _ in range(10):
        phi, Phi_q, _ = model.phi(q, t, p)
        r = np.asarray(phi).ravel()[act]
        if np.max(np.abs(r), initial=0.0) < 1e-15:
            break
        J = np.asarray(Phi_q)[act]
        # least squares: a new lock may make the rows dependent until a jam is resolved
        q = q - np.linalg.lstsq(J, r, rcond=None)[0]
    return q


def project_velocities(model: Model, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray
                       ) -> np.ndarray:
    """Minimal-norm correction of v onto ``Phi_q v + Phi_t = 0`` (active rows)."""
    free = model.free(p)[0]
    act = np.flatnonzero(free == 0.0)
    _, Phi_q, Phi_t = model.phi(q, t, p)
    J = np.asarray(Phi_q)[act]
    r = J @ v + np.asarray(Phi_t).ravel()[act]
    return v - np.linalg.lstsq(J, r, rcond=None)[0]


def impact_map(model: Model, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray,
               lock_row: int | None, target: float) -> tuple[np.ndarray, np.ndarray]:
    """Post-impact velocities and impulses.

    Solves ``[[M, Phi_q^T], [Phi_q, D]] [v+; Lambda] = [M v-; b]`` where drivers keep their
    prescribed velocity, locked joints keep 0 and the new lock row asks ``c'+ = target``.
    Returns (v+, Lambda) with Lambda the impulse of each row (N s or N m s).
    """
    _, Phi_q, h0 = model.phi(q, t, p)
    Phi_q = np.asarray(Phi_q)
    b = -np.asarray(h0).ravel()  # -Phi_t: drivers keep their velocity, locks keep 0
    free = model.free(p)[0]
    b[free != 0.0] = 0.0
    if lock_row is not None:
        b[lock_row] = target
    A = model.kkt_matrix(Phi_q, p)
    rhs = np.concatenate([model.mass * v, b])
    sol = np.linalg.solve(A, rhs)
    return sol[:model.nq], sol[model.nq:]


@dataclass
class LimitOutcome:
    """What a limit event does: the clamped positions, the new velocities, the event record,
    whether it locked,
    and the preloaded locks it released first (``jammed``: their release events)."""

    q: np.ndarray
    v: np.ndarray
    event: Event
    locked: bool
    released_at_once: bool = False
    jammed: list[Event] = field(default_factory=list)


def _over_constrained(hs: HybridState, q: np.ndarray, t: float) -> bool:
    """True when the active constraint rows of the current locked set are dependent."""
    model = hs.model
    free = model.free(hs.p)[0]
    act = np.flatnonzero(free == 0.0)
    J = model.phi(q, t, hs.p)[1][act]
    s = np.linalg.svd(J, compute_uv=False)
    rank = int(np.sum(s > 1e-9 * s[0])) if s.size else 0
    return rank < J.shape[0]


def dependent_rows(model: Model, q: np.ndarray, t: float, p: np.ndarray,
                   tol: float = 1e-6) -> tuple[list[str], float]:
    """Constraint rows that (nearly) depend on each other at q: the joints, drivers and
    locks of a dead point or a lock-up. Returns (labels, smallest/largest singular value);
    no labels when the rows are independent."""
    free = model.free(p)[0]
    act = np.flatnonzero(free == 0.0)
    J = model.phi(q, t, p)[1][act]
    U, s, _ = np.linalg.svd(J)
    if J.shape[0] > J.shape[1]:
        s = np.concatenate([s, np.zeros(J.shape[0] - J.shape[1])])
    ratio = float(s[-1] / s[0]) if s.size and s[0] > 0 else 0.0
    if ratio > tol:
        return [], ratio
    w = np.abs(U[:, -1])
    labels = []
    for i in np.flatnonzero(w > 0.05 * w.max()):
        r = model.rows[act[i]]
        lab = f"{r.kind} {r.name}" if r.kind != "joint" else f"joint {r.name}"
        if lab not in labels:
            labels.append(lab)
    return labels, ratio


def release_jammed(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                   side: str, force_held: dict[str, str]) -> list[Event]:
    """Before ``joint`` locks: if the lock would over-constrain (jam) the mechanism, the
    impact frees locks that it depends on: first joints held on their stops by a preloaded
    spring (force constraints: the impact beats the preload), then other locks (the impact
    pulls them off their stops). One release event each, with the lock force just before."""
    out: list[Event] = []
    trial = dict(hs.locked)
    saved = hs.locked
    hs.locked = dict(trial, **{joint: side})
    jam = _over_constrained(hs, q, t)
    hs.locked = saved
    if not jam:
        return out
    order = sorted(saved.items(), key=lambda kv: force_held.get(kv[0]) != kv[1])
    for other, _ in order:
        _, lam, _ = hs.model.kkt(q, v, t, hs.p)
        force = hs.push(lam, other)
        out.append(release(hs, q, v, t, other, force))
        hs.locked = dict(hs.locked, **{joint: side})
        still = _over_constrained(hs, q, t)
        del hs.locked[joint]
        if not still:
            break
    return out


def at_limit(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str, side: str,
             v_lock: float, last_bounce: float | None) -> LimitOutcome:
    """Apply the impact map when ``joint`` reaches its ``side`` limit at time t.

    ``q`` is put exactly on the stop here (after any jammed lock is freed, so that the
    constraint set is consistent). Plastic impact, a rebound slower than ``v_lock`` or a
    bounce closer than :data:`ZENO_DT` to the previous one locks the joint; a lock whose
    force is already of the wrong sign releases at once (two events).
    """
    model = hs.model
    k = model.jidx[joint]
    jammed = release_jammed(hs, q, v, t, joint, side, hs.force_held)
    hs.locked[joint] = side
    if _over_constrained(hs, q, t):
        labels, _ = dependent_rows(model, q, t, hs.p, tol=1e-9)
        del hs.locked[joint]
        drivers = ", ".join(f"driver {d}" for d in model.driver_names) or "no driver"
        raise LockUpError(
            f"lock-up at t = {t:.9g} s: with joint {joint} locked on its {side} stop the "
            f"constraints of {', '.join(labels)} cannot all hold; the mechanism has no freedom "
            f"left for its drivers ({drivers}): the stop would have to stop a driver")
    q = project_positions(model, q, t, hs.p)  # clamp onto the stop
    del hs.locked[joint]
    before = hs.current()
    _, cd_minus, _ = model.coord(q, v)
    cdm = float(np.asarray(cd_minus).ravel()[k])
    e = model.mech.joints[joint].restitution
    T_minus = 0.5 * np.sum(model.mass * v**2)

    hs.locked[joint] = side
    p_locked = hs.p
    row = model.n_fixed + model.locks.index(joint)
    zeno = last_bounce is not None and t - last_bounce < ZENO_DT
    v_plus, imp = impact_map(model, q, v, t, p_locked, row, -e * cdm)
    cdp = -e * cdm
    bounce = e > 0 and abs(cdp) > v_lock and not zeno
    if not bounce:
        v_plus, imp = impact_map(model, q, v, t, p_locked, row, 0.0)
        cdp = 0.0
    impulses = {f"{r.kind} {r.name}": float(x) for r, x in zip(model.rows, imp, strict=True)
                if x != 0.0}
    lost = float(T_minus - 0.5 * np.sum(model.mass * v_plus**2))
    kind = "bounce" if bounce else ("lock" if abs(cdm) <= v_lock else "limit")
    if bounce:
        del hs.locked[joint]
    after = hs.current()
    ev = Event(t, kind, joint, side, before, after, cdm, cdp, impulses, lost)
    out = LimitOutcome(q, v_plus, ev, not bounce, jammed=jammed)
    if not bounce:
        _, lam, _ = model.kkt(q, v_plus, t, hs.p)
        if hs.push(lam, joint) < 0.0:
            out.released_at_once = True
    return out


def release(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
            force: float) -> Event:
    """Unlock ``joint`` at time t; the event carries the lock force at release."""
    before = hs.current()
    side = hs.locked.pop(joint)
    after = hs.current()
    k = hs.model.jidx[joint]
    _, cd, _ = hs.model.coord(q, v)
    cdv = float(np.asarray(cd).ravel()[k])
    return Event(t, "release", joint, side, before, after, cdv, cdv, {}, 0.0, float(force))


def would_reenter(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                  side: str) -> bool:
    """True when, unlocked, the joint would clearly accelerate into its stop at once.

    At a release root the lock force and the free acceleration both pass through zero, so
    only an acceleration into the stop above round-off level (relative to the bodies'
    accelerations) counts; a single lock can never re-enter (complementarity).
    """
    model = hs.model
    a, _, _ = model.kkt(q, v, t, hs.p)
    _, _, cdd, _ = model.post1(q, v, a, t)
    acc = float(np.asarray(cdd).ravel()[model.jidx[joint]])
    into = -acc if side == "lower" else acc
    return into > 1e-9 * (1.0 + float(np.max(np.abs(a))))
