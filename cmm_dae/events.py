"""The one event policy of both integrators: configurations, crossings, impact map, lock,
release, jams and the Zeno rule.

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
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from .equations import Model
from .errors import SolverError, Status
from .result import Configuration, Event

#: Consecutive bounces of one joint closer than this in time end in a lock (Zeno guard), s;
#: also the shortest time between a "stay locked" decision and a release of the same joint.
ZENO_DT = 1e-9

Locked = Mapping[str, str]


class LockUpError(SolverError):
    """A new lock leaves the drivers no freedom: the mechanism locks up."""

    def __init__(self, message: str):
        super().__init__(message, status=Status.LOCK_UP)


@dataclass(frozen=True)
class Trigger:
    """What an integrator detected: ``kind`` ``"gap"`` (an unlocked joint reached its
    ``side`` limit) or ``"push"`` (the stop of a locked joint would have to pull)."""

    joint: str
    side: str
    kind: str


@dataclass(frozen=True)
class Policy:
    """Options of the event policy.

    v_lock : float
        A rebound slower than this (rad/s or m/s) locks the joint.
    resolution : float
        Shortest time between two events the integrator resolves, s: :data:`ZENO_DT` for
        IDA, the step for the fixed-step algorithm. Bounces that accumulate (Zeno) come to
        rest when they reach it (see :func:`zeno`).
    """

    v_lock: float = 1e-6
    resolution: float = ZENO_DT


@dataclass(frozen=True)
class Transition:
    """One event and the state (positions m/rad, velocities) right after it."""

    event: Event
    q: np.ndarray
    v: np.ndarray


def _key(locked: Locked) -> tuple:
    return tuple(sorted(locked.items()))


@dataclass
class HybridState:
    """The locked joints now, the registry of configurations met so far and the memory the
    policy needs across events (last bounce of each joint, "stayed locked" decisions)."""

    model: Model
    labeller: Callable[[dict[str, str]], tuple[str, int]] | None = None
    locked: dict[str, str] = field(default_factory=dict)
    zones: frozenset[str] = frozenset()  # zoned loads acting now
    slip: dict[str, int] = field(default_factory=dict)  # slipping joint -> direction
    stick_at: dict[str, float] = field(default_factory=dict)  # stuck joint -> coordinate
    force_held: dict[str, str] = field(default_factory=dict)  # preloaded joint -> side
    configurations: list[Configuration] = field(default_factory=list)
    params: list[np.ndarray] = field(default_factory=list)
    bounces: dict[str, list[float]] = field(default_factory=dict)  # joint -> bounce times
    stayed: dict[str, float] = field(default_factory=dict)
    _index: dict[tuple, int] = field(default_factory=dict)
    _trial: dict[tuple, np.ndarray] = field(default_factory=dict)

    def limit_value(self, joint: str, side: str) -> float:
        if side == "stick":
            return self.stick_at[joint]
        lim = self.model.mech.joints[joint].limits
        return lim.lower if side == "lower" else lim.upper

    def _mode(self, locked: Locked, zones, slip) -> tuple:
        zones = self.zones if zones is None else zones
        slip = self.slip if slip is None else slip
        return (tuple((j, s, self.limit_value(j, s)) for j, s in sorted(locked.items())),
                tuple(sorted(zones)), tuple(sorted(slip.items())))

    def params_of(self, locked: Locked, zones: frozenset[str] | None = None,
                  slip: Mapping[str, int] | None = None) -> np.ndarray:
        """Parameter vector of any lock set (cached; a trial set is not registered), with
        the zoned loads ``zones`` acting and the joints ``slip`` slipping (default: as
        now)."""
        key = self._mode(locked, zones, slip)
        p = self._trial.get(key)
        if p is None:
            p = self._trial[key] = self.model.params(
                {j: val for j, _, val in key[0]}, key[1], dict(key[2]))
        return p

    def index_of(self, locked: Locked, zones: frozenset[str] | None = None,
                 slip: Mapping[str, int] | None = None) -> int:
        """Index of the configuration (registered, labelled, on first use)."""
        key = self._mode(locked, zones, slip)
        if key not in self._index:
            lk = {j: s for j, s, _ in key[0]}
            label, dof = self.labeller(lk) if self.labeller else ("", 0)
            self._index[key] = len(self.configurations)
            self.configurations.append(Configuration(
                tuple(lk), tuple(lk.values()), dof, label, key[1], key[2]))
            self.params.append(self.params_of(lk, key[1], dict(key[2])))
        return self._index[key]

    def current(self) -> int:
        """Index of the configuration in force."""
        return self.index_of(self.locked)

    @property
    def p(self) -> np.ndarray:
        return self.params_of(self.locked)

    def push(self, lam: np.ndarray, joint: str, locked: Locked | None = None) -> float:
        """Force/torque with which the stop of a locked joint pushes it (>= 0 while held).

        The lock row is ``c - L``; the generalized force on the second body along the joint
        is ``-lambda``, which the lower stop must give positive and the upper stop negative.
        """
        side = (self.locked if locked is None else locked)[joint]
        k = self.model.n_fixed + self.model.locks.index(joint)
        return lam[k] if side == "upper" else -lam[k]  # "stick": the lock's force along +c

    def static(self, joint: str) -> float:
        """Static friction limit of a joint (0 without friction), N or N m."""
        f = self.model.mech.joints[joint].friction
        return f.static if f is not None else 0.0

    def lock_force(self, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                   locked: Locked | None = None) -> float:
        """:meth:`push` from a KKT solve at (q, v, t) in configuration ``locked``."""
        locked = self.locked if locked is None else locked
        _, lam, _ = self.model.kkt(q, v, t, self.params_of(locked))
        return self.push(lam, joint, locked)


# ------------------------------------------------------------------- detection
def event_list(model: Model, locked: Locked) -> list[Trigger]:
    """The triggers watched in configuration ``locked``: a ``gap`` for each open limit side
    of an unlocked joint, a ``push`` for each locked joint, a ``zone`` for each load that
    acts in a zone (``joint`` holds the load's name). All cross zero downwards."""
    out = [Trigger(name, "", "zone") for name in model.zoned]
    for name in model.locks:
        if name in locked:
            kind = "slip" if locked[name] == "stick" else "push"
            out.append(Trigger(name, locked[name], kind))
            continue
        lim = model.mech.joints[name].limits
        if lim is not None and lim.lower is not None:
            out.append(Trigger(name, "lower", "gap"))
        if lim is not None and lim.upper is not None:
            out.append(Trigger(name, "upper", "gap"))
        if model.mech.joints[name].friction is not None:
            out.append(Trigger(name, "", "rate"))  # a slipping joint's rate
    return out


def event_values(hs: HybridState, c: np.ndarray, cdot: np.ndarray, lam: np.ndarray | None,
                 triggers: list[Trigger], out: np.ndarray) -> None:
    """Values of the event functions of ``triggers`` (see :func:`event_list`) into ``out``.

    A gap is armed only while its joint approaches the stop (+1 while it moves away): just
    after a release or a rejected root the joint leaves at almost zero speed and round-off
    in the gap would otherwise read as arrivals, one restart after the other. The jump to
    +1 is never a downward crossing. A push needs the multipliers ``lam`` of a KKT solve."""
    jidx = hs.model.jidx
    for i, tr in enumerate(triggers):
        if tr.kind == "zone":
            out[i] = _zone_margin(hs, tr.joint, c, cdot)
        elif tr.kind == "rate":  # positive while it slips on in its direction
            out[i] = hs.slip.get(tr.joint, 0) * cdot[jidx[tr.joint]]
        elif tr.kind == "slip":  # positive while the stuck joint carries less than Fs
            out[i] = hs.static(tr.joint) - abs(hs.push(lam, tr.joint))
        elif tr.kind == "gap":
            k = jidx[tr.joint]
            L = hs.limit_value(tr.joint, tr.side)
            if tr.side == "lower":
                out[i] = 1.0 if cdot[k] > 0.0 else c[k] - L
            else:
                out[i] = 1.0 if cdot[k] < 0.0 else L - c[k]
        else:  # friction holds a joint on its stop until the pull beats it
            out[i] = hs.push(lam, tr.joint) + hs.static(tr.joint)


def crossings(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float) -> list[Trigger]:
    """Triggers crossed at a state reached by a finite step (the fixed-step algorithm):
    a joint beyond its stop while moving toward it, a locked joint whose stop would pull.
    A joint that stayed locked at this very instant is not reported again."""
    model = hs.model
    triggers = event_list(model, hs.locked)
    if not triggers:
        return []
    c, cd = model.joint_rates(q, v)
    lam = None
    out = []
    for tr in triggers:
        if tr.kind == "zone":
            if _zone_margin(hs, tr.joint, c, cd) < 0.0:
                out.append(tr)
            continue
        k = model.jidx[tr.joint]
        if tr.kind == "rate":
            if hs.slip.get(tr.joint, 0) * cd[k] < 0.0:
                out.append(tr)
            continue
        if tr.kind == "gap":
            L = hs.limit_value(tr.joint, tr.side)
            beyond = (L - c[k]) if tr.side == "lower" else (c[k] - L)
            toward = (cd[k] <= 0.0) if tr.side == "lower" else (cd[k] >= 0.0)
            # round-off leaves a just-released joint a hair beyond its stop: not a crossing
            if beyond > 1e-12 * (1.0 + abs(L)) and toward:
                out.append(tr)
        elif hs.stayed.get(tr.joint) != t:
            if lam is None:
                lam = model.kkt(q, v, t, hs.p)[1]
            f = hs.push(lam, tr.joint)
            if (tr.kind == "slip" and abs(f) > hs.static(tr.joint)) or \
                    (tr.kind == "push" and f + hs.static(tr.joint) < 0.0):
                out.append(tr)
    return out


def _zone_margin(hs: HybridState, load: str, c: np.ndarray, cdot: np.ndarray) -> float:
    """Distance of a zone's joint coordinate to the edge it moves toward, positive while
    the load's acting state matches where the coordinate is (acting inside, idle
    outside). As with the stops, an edge is armed only while the coordinate approaches
    it (+1 otherwise): a coordinate at rest on an edge (a jaw closed on its stop at the
    end of a cut) must not read as a root at every restart."""
    k, lo, up = hs.model.zone_info[load]
    x, xd = c[k], cdot[k]
    tol = _edge_tol(x)  # on an edge to round-off counts as on it (see zone_switch)
    if load in hs.zones:  # acting: it leaves through the edge ahead
        return (x - lo) if xd < 0.0 else (up - x) if xd > 0.0 else 1.0
    if x <= lo + tol:  # idle below the zone: it enters moving up
        return (lo - x) if xd > 0.0 else 1.0
    if x >= up - tol:
        return (x - up) if xd < 0.0 else 1.0
    return -min(x - lo, up - x)  # idle inside: a mismatch (after a finite step)


def _edge_tol(x: float) -> float:
    """How close to a zone edge (rad or m) a coordinate counts as on it."""
    return 1e-9 * (1.0 + abs(x))


def zone_switch(hs: HybridState, load: str, q: np.ndarray, v: np.ndarray, t: float
                ) -> Transition | None:
    """A load's zone edge reached: it starts or stops acting. At a located root (the
    coordinate on the edge) the direction of motion decides; after a finite step, where
    the coordinate is. None when nothing changes (a round-off root)."""
    model = hs.model
    k, lo, up = model.zone_info[load]
    c, cd = model.joint_rates(q, v)
    tol = _edge_tol(c[k])
    if abs(c[k] - lo) <= tol:
        inside = cd[k] > 0.0
    elif abs(c[k] - up) <= tol:
        inside = cd[k] < 0.0
    else:
        inside = lo <= c[k] <= up
    if inside == (load in hs.zones):
        return None
    before = hs.current()
    hs.zones = hs.zones | {load} if inside else hs.zones - {load}
    name = model.joint_names[k]
    return Transition(Event(t, "zone", name, "enter" if inside else "leave", before,
                            hs.current(), float(cd[k]), float(cd[k]), load=load), q, v)


def initial_zones(model: Model, q: np.ndarray) -> frozenset[str]:
    """The zoned loads whose zone holds the joint coordinate at q (edges included)."""
    c = model.joint_rates(q, np.zeros_like(q))[0]
    return frozenset(n for n, (k, lo, up) in model.zone_info.items() if lo <= c[k] <= up)


# ------------------------------------------------------------------- geometry
def project_positions(model: Model, q: np.ndarray, t: float, p: np.ndarray) -> np.ndarray:
    """Minimal-norm Newton projection of q onto the active position constraints."""
    act = model.active_rows(p)
    for _ in range(10):
        con = model.constraints(q, t, p)
        r = con.phi[act]
        if np.max(np.abs(r), initial=0.0) < 1e-15:
            break
        # least squares: a new lock may make the rows dependent until a jam is resolved
        q = q - np.linalg.lstsq(con.Phi_q[act], r, rcond=None)[0]
    return q


def project_velocities(model: Model, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray
                       ) -> np.ndarray:
    """Minimal-norm correction of v onto ``Phi_q v + Phi_t = 0`` (active rows)."""
    act = model.active_rows(p)
    con = model.constraints(q, t, p)
    J = con.Phi_q[act]
    r = J @ v + con.Phi_t[act]
    return v - np.linalg.lstsq(J, r, rcond=None)[0]


def impact_map(model: Model, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray,
               lock_row: int | None, target: float) -> tuple[np.ndarray, np.ndarray]:
    """Post-impact velocities and impulses.

    Solves ``[[M, Phi_q^T], [Phi_q, D]] [v+; Lambda] = [M v-; b]`` where drivers keep their
    prescribed velocity, locked joints keep 0 and the new lock row asks ``c'+ = target``.
    Returns (v+, Lambda) with Lambda the impulse of each row (N s or N m s).
    """
    con = model.constraints(q, t, p)
    b = -con.Phi_t  # drivers keep their velocity, locks keep 0
    b[model.free_rows(p) != 0.0] = 0.0
    if lock_row is not None:
        b[lock_row] = target
    A = model.kkt_matrix(con.Phi_q, p)
    sol = np.linalg.solve(A, np.concatenate([model.mass * v, b]))
    return sol[:model.nq], sol[model.nq:]


def over_constrained(hs: HybridState, locked: Locked, q: np.ndarray, t: float) -> bool:
    """True when the active constraint rows of lock set ``locked`` are dependent at q."""
    p = hs.params_of(locked)
    J = hs.model.constraints(q, t, p).Phi_q[hs.model.active_rows(p)]
    s = np.linalg.svd(J, compute_uv=False)
    rank = int(np.sum(s > 1e-9 * s[0])) if s.size else 0
    return rank < J.shape[0]


def dependent_rows(model: Model, q: np.ndarray, t: float, p: np.ndarray,
                   tol: float = 1e-6) -> tuple[list[str], float]:
    """Constraint rows that (nearly) depend on each other at q: the joints, drivers and
    locks of a dead point or a lock-up. Returns (labels, smallest/largest singular value);
    no labels when the rows are independent."""
    act = model.active_rows(p)
    J = model.constraints(q, t, p).Phi_q[act]
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


def joint_acceleration(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                       locked: Locked) -> float:
    """Acceleration of a joint coordinate from a KKT solve in configuration ``locked``."""
    model = hs.model
    a, _, _ = model.kkt(q, v, t, hs.params_of(locked))
    return float(model.joint_accelerations(q, v, a, t)[model.jidx[joint]]), \
        float(np.max(np.abs(a), initial=0.0))


# ------------------------------------------------------------------- decisions
def _joint_rate(model: Model, q: np.ndarray, v: np.ndarray, joint: str) -> float:
    return float(model.joint_rates(q, v)[1][model.jidx[joint]])


def confirm(hs: HybridState, tr: Trigger, q: np.ndarray, v: np.ndarray, t: float,
            policy: Policy) -> bool:
    """Is a detected trigger a real switch? Re-entry guards shared by both integrators.

    A gap is rejected when the joint already moves away from the stop (a round-off root),
    or when it arrives at (almost) zero speed and the stop would not push (the joint is
    leaving); a push is rejected when the joint is no longer locked, a gap when it is
    locked already (an earlier event of the same instant changed it)."""
    if tr.kind in ("push", "slip"):
        return hs.locked.get(tr.joint) == tr.side
    if tr.kind == "rate":
        return tr.joint in hs.slip
    if tr.joint in hs.locked:
        return False
    cdv = _joint_rate(hs.model, q, v, tr.joint)
    if (cdv >= 0.0 and tr.side == "lower") or (cdv <= 0.0 and tr.side == "upper"):
        return False
    if abs(cdv) <= policy.v_lock:
        trial = {**hs.locked, tr.joint: tr.side}
        q_on = project_positions(hs.model, q, t, hs.params_of(trial))
        return hs.lock_force(q_on, v, t, tr.joint, trial) > 0.0
    return True


def handle(hs: HybridState, tr: Trigger, q: np.ndarray, v: np.ndarray, t: float,
           policy: Policy) -> list[Transition]:
    """Decide what a trigger does and apply it to ``hs``; returns the transitions in order
    (none when the trigger is rejected or the joint stays locked)."""
    if tr.kind == "zone":
        done = zone_switch(hs, tr.joint, q, v, t)
        return [done] if done is not None else []
    if not confirm(hs, tr, q, v, t, policy):
        return []
    if tr.kind == "gap":
        return at_limit(hs, q, v, t, tr.joint, tr.side, policy)
    if tr.kind == "rate":
        return [rate_zero(hs, q, v, t, tr.joint)]
    force = hs.lock_force(q, v, t, tr.joint)
    if tr.kind == "slip":
        return [Transition(slip_free(hs, q, v, t, tr.joint, force), q, v)]
    if would_reenter(hs, q, v, t, tr.joint, tr.side) and \
            t - hs.stayed.get(tr.joint, -math.inf) > ZENO_DT:
        hs.stayed[tr.joint] = t  # stays locked: no chattering
        return []
    away = 1 if tr.side == "lower" else -1  # a frictional joint slides off its stop
    return [Transition(release(hs, q, v, t, tr.joint, force, away), q, v)]


def _direction(force: float) -> int:
    """Slip direction of a joint freed from a lock that carried ``force`` (along +c):
    it moves the way the applied loads push it, against the lock."""
    return -1 if force > 0.0 else 1


def slip_free(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
              force: float) -> Event:
    """A stuck joint whose force exceeds static friction starts to slip."""
    before = hs.current()
    s = _direction(force)
    hs.locked = {j: x for j, x in hs.locked.items() if j != joint}
    hs.stick_at.pop(joint, None)
    hs.slip = {**hs.slip, joint: s}
    return Event(t, "slip", joint, "positive" if s > 0 else "negative", before, hs.current(),
                 0.0, 0.0, {}, 0.0, float(force))


def rate_zero(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str
              ) -> Transition:
    """A slipping joint's rate reached zero: it sticks if the force it must then carry is
    within static friction, else it slips on the other way. The lock puts the rate
    exactly to zero (a vanishing impulse at a located root; the fixed-step algorithm's
    overshoot of one step otherwise)."""
    model = hs.model
    k = model.jidx[joint]
    before = hs.current()
    c, cd = model.joint_rates(q, v)
    slip = {j: s for j, s in hs.slip.items() if j != joint}
    hs.stick_at[joint] = float(c[k])
    trial = {**hs.locked, joint: "stick"}
    p = hs.params_of(trial, slip=slip)
    row = model.n_fixed + model.locks.index(joint)
    T_minus = 0.5 * np.sum(model.mass * v**2)
    v0, imp = impact_map(model, q, v, t, p, row, 0.0)
    _, lam, _ = model.kkt(q, v0, t, p)
    force = hs.push(lam, joint, trial)
    if abs(force) <= hs.static(joint):
        hs.locked, hs.slip = trial, slip
        impulses = {f"{r.kind} {r.name}": float(x) for r, x in
                    zip(model.rows, imp, strict=True) if x != 0.0}
        lost = float(T_minus - 0.5 * np.sum(model.mass * v0**2))
        return Transition(Event(t, "stick", joint, "stick", before, hs.current(),
                                float(cd[k]), 0.0, impulses, lost, float(force)), q, v0)
    hs.stick_at.pop(joint, None)
    s = _direction(force)
    hs.slip = {**slip, joint: s}
    return Transition(Event(t, "slip", joint, "positive" if s > 0 else "negative", before,
                            hs.current(), float(cd[k]), float(cd[k]), {}, 0.0, float(force)),
                      q, v)


def _release_jammed(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                    side: str) -> list[Transition]:
    """Before ``joint`` locks: if the lock would over-constrain (jam) the mechanism, the
    impact frees locks that it depends on: first joints held on their stops by a preloaded
    spring (force constraints: the impact beats the preload), then other locks (the impact
    pulls them off their stops). One release event each, with the lock force just before."""
    out: list[Transition] = []
    if not over_constrained(hs, {**hs.locked, joint: side}, q, t):
        return out
    order = sorted(hs.locked.items(), key=lambda kv: hs.force_held.get(kv[0]) != kv[1])
    for other, _ in order:
        force = hs.lock_force(q, v, t, other)
        out.append(Transition(release(hs, q, v, t, other, force), q, v))
        if not over_constrained(hs, {**hs.locked, joint: side}, q, t):
            break
    return out


def zeno(times: list[float], t: float, e: float, resolution: float) -> bool:
    """Have the bounces of a joint (at ``times``, now ``t``) reached the integrator's time
    resolution? Then the joint locks instead of bouncing on.

    Under a steady load the intervals between bounces shrink by the restitution ``e`` each
    time and sum to a finite rest time (Zeno). Two rules end them:

    * a bounce closer than ``resolution`` to the previous one;
    * an interval that no longer shrinks (above ``(1 + e) / 2`` of the previous one) while
      within ``2 / (1 - e) + 4`` resolutions: a fixed-step explicit scheme catches each
      crossing up to a step late, gains about ``a dt`` of speed per bounce and settles into
      a cycle of about ``2 e / (1 - e) + 2`` steps instead of coming to rest. Locking there
      leaves O(resolution) of the exact accumulation time, so the rest time converges as
      the step shrinks.
    """
    if not times:
        return False
    gap = t - times[-1]
    if gap < resolution:
        return True
    if len(times) < 2 or e >= 1.0:
        return False
    prev = times[-1] - times[-2]
    return gap <= (2.0 / (1.0 - e) + 4.0) * resolution and gap > 0.5 * (1.0 + e) * prev


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
    out = _release_jammed(hs, q, v, t, joint, side)
    target = {**hs.locked, joint: side}
    if over_constrained(hs, target, q, t):
        labels, _ = dependent_rows(model, q, t, hs.params_of(target), tol=1e-9)
        drivers = ", ".join(f"driver {d}" for d in model.driver_names) or "no driver"
        raise LockUpError(
            f"lock-up at t = {t:.9g} s: with joint {joint} locked on its {side} stop the "
            f"constraints of {', '.join(labels)} cannot all hold; the mechanism has no freedom "
            f"left for its drivers ({drivers}): the stop would have to stop a driver")
    p_locked = hs.params_of(target)
    q = project_positions(model, q, t, p_locked)  # clamp onto the stop
    before = hs.current()
    cdm = _joint_rate(model, q, v, joint)
    e = model.mech.joints[joint].restitution
    T_minus = 0.5 * np.sum(model.mass * v**2)
    row = model.n_fixed + model.locks.index(joint)
    v_plus, imp = impact_map(model, q, v, t, p_locked, row, -e * cdm)
    cdp = -e * cdm
    bounce = e > 0 and abs(cdp) > policy.v_lock and \
        not zeno(hs.bounces.get(joint, []), t, e, policy.resolution)
    if not bounce:
        v_plus, imp = impact_map(model, q, v, t, p_locked, row, 0.0)
        cdp = 0.0
        hs.locked = target
        hs.slip = {j: s for j, s in hs.slip.items() if j != joint}  # on the stop: no slip
        hs.bounces.pop(joint, None)
    else:
        hs.bounces.setdefault(joint, []).append(t)
        if joint in hs.slip:  # it slides back the other way
            hs.slip = {**hs.slip, joint: 1 if cdp > 0 else -1}
    impulses = {f"{r.kind} {r.name}": float(x) for r, x in zip(model.rows, imp, strict=True)
                if x != 0.0}
    lost = float(T_minus - 0.5 * np.sum(model.mass * v_plus**2))
    kind = "bounce" if bounce else ("lock" if abs(cdm) <= policy.v_lock else "limit")
    out.append(Transition(Event(t, kind, joint, side, before, hs.current(), cdm, cdp,
                                impulses, lost), q, v_plus))
    if not bounce:
        force = hs.lock_force(q, v_plus, t, joint)
        if force < 0.0:  # the stop would have to pull at once: no chattering
            out.append(Transition(release(hs, q, v_plus, t, joint, force), q, v_plus))
    return out


def release(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
            force: float, away: int = 1) -> Event:
    """Unlock ``joint`` at time t; the event carries the lock force at release. A joint
    with friction leaves slipping in direction ``away``."""
    before = hs.current()
    locked = dict(hs.locked)
    side = locked.pop(joint)
    hs.locked = locked
    hs.stick_at.pop(joint, None)
    if hs.model.mech.joints[joint].friction is not None:
        hs.slip = {**hs.slip, joint: away}
    cdv = _joint_rate(hs.model, q, v, joint)
    return Event(t, "release", joint, side, before, hs.current(), cdv, cdv, {}, 0.0,
                 float(force))


def would_reenter(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                  side: str) -> bool:
    """True when, unlocked, the joint would clearly accelerate into its stop at once.

    At a release root the lock force and the free acceleration both pass through zero, so
    only an acceleration into the stop above round-off level (relative to the bodies'
    accelerations) counts; a single lock can never re-enter (complementarity).
    """
    free = {j: s for j, s in hs.locked.items() if j != joint}
    acc, amax = joint_acceleration(hs, q, v, t, joint, free)
    into = -acc if side == "lower" else acc
    return into > 1e-9 * (1.0 + amax)
