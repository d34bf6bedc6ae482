"""The state of a hybrid run: which joints are locked (and how), which loads act in their
zones, which joints slip; the registry of configurations met; the records the event policy
passes around (:class:`Trigger`, :class:`Transition`, :class:`Policy`); the queries the
policy asks of a lock set (a contact's slide, the Zeno rule, lock forces).

Lock sets are values: a trial set is an argument of the function that asks, never an edit
of the shared state undone afterwards.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np

from ..core.errors import SolverError, Status
from ..core.records import Configuration, Event, Side
from ..description.parts import STOP_TOL
from ..equations import rank, reaction
from ..equations.build import SLIDE
from ..equations.model import Model

#: Consecutive bounces of one joint closer than this in time end in a lock (Zeno guard), s;
#: also the shortest time between a "stay locked" decision and a release of the same joint.
ZENO_DT = 1e-9


Locked = Mapping[str, str]


class LockUpError(SolverError):
    """A new lock leaves the drivers no freedom: the mechanism locks up."""

    def __init__(self, message: str):
        super().__init__(message, status=Status.LOCK_UP)


class TriggerKind(StrEnum):
    """What a :class:`Trigger` watches (equal to the plain string)."""

    GAP = "gap"  #: an unlocked joint's distance to its ``side`` stop
    PUSH = "push"  #: a locked joint's stop force (it would have to pull)
    SLIP = "slip"  #: a stuck joint's margin to static friction
    RATE = "rate"  #: a slipping joint's rate (it comes to rest)
    ZONE = "zone"  #: a zoned load's margin to its zone's edge (``joint``: the load)


@dataclass(frozen=True)
class Trigger:
    """What an integrator watches and detects: an event function of the policy
    (:func:`~cmm_dae.hybrid.policy.event_values`), of ``kind`` at ``joint`` (a zoned
    load's name for a zone) on ``side``."""

    joint: str
    side: Side
    kind: TriggerKind


@dataclass(frozen=True)
class Policy:
    """Options of the event policy.

    v_lock : float
        A rebound slower than this (rad/s or m/s) locks the joint.
    resolution : float
        Shortest time between two events the integrator resolves, s: :data:`ZENO_DT` for
        IDA, the step for the fixed-step algorithm. Bounces that accumulate (Zeno) come to
        rest when they reach it (see :func:`zeno`).
    gap : (float, float)
        Smallest gap to a stop at L the integrator resolves is ``gap[0] |L| + gap[1]``, m
        or rad (IDA: its tolerances on positions): a rebound whose flight would
        rise less off the stop locks.
    """

    v_lock: float = 1e-6
    resolution: float = ZENO_DT
    #: Smallest gap the integrator tells from its own error, (relative to the stop's
    #: position, absolute m or rad): a rebound that would rise less off its stop locks.
    gap: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class Transition:
    """One event and the state (positions m/rad, velocities) right after it."""

    event: Event
    q: np.ndarray
    v: np.ndarray


@dataclass
class SegmentTrace:
    """What a run did in one configuration segment, for a second pass over the same
    sequence (the sensitivities): the state handed to the integrator at ``t0``, the
    configuration (``p``, and the policy's state ``locked``, ``zones``, ``slip``,
    ``stick_at``), the samples it recorded (indices ``n0`` to ``n1``), how it ended and,
    per trigger handled there, the transitions it caused."""

    t0: float
    q: np.ndarray
    v: np.ndarray
    p: np.ndarray
    locked: dict[str, str]
    zones: frozenset[str]
    slip: dict[str, int]
    stick_at: dict[str, float]
    n0: int
    n1: int = 0
    t1: float = math.nan
    reason: str = ""
    #: per trigger: the trigger, its transitions, the parameter vector after each
    groups: list[tuple[Trigger, list[Transition], list[np.ndarray]]] = field(
        default_factory=list)
    #: the singular-position crossing that followed the segment (a
    #: :class:`~cmm_dae.singular.Crossing`), if it ended at one
    crossing: Any = None
    #: whether that crossing logged a "singular" event (not when it only took an earlier
    #: crossing further out)
    crossing_logged: bool = False
    #: whether IDA ran the segment with the multipliers out of its error test
    relaxed: bool = False
    #: the factor on the multipliers' absolute tolerances (the run's force scale)
    lambda_scale: float = 1.0
    #: the singular positions IDA integrated through inside the segment, logged as
    #: events: (instant in s, index of the first sample after it)
    passages: list[tuple[float, int]] = field(default_factory=list)


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
    #: (relative to |L|, absolute) m or rad: a joint beyond its stop by more than this
    #: (and the stop tolerance) reads as beyond it even while it moves away (IDA's gap
    #: resolution; by default never, as the fixed-step algorithm reads it)
    gap_band: tuple[float, float] = (0.0, math.inf)
    _index: dict[tuple, int] = field(default_factory=dict)
    _trial: dict[tuple, np.ndarray] = field(default_factory=dict)

    def stop_band(self, L, where: Callable = np.where):
        """How far beyond its stop at ``L`` a joint must be to read as beyond it (m or rad):
        what the integrator resolves there (``gap_band[0] |L| + gap_band[1]``), at least
        the stop tolerance. ``where``: numpy's or CasADi's (a stop is a symbol in
        sensitivities: ``where``, not ``max``)."""
        x = self.gap_band[0] * abs(L) + self.gap_band[1]
        y = STOP_TOL * where(abs(L) > 1.0, abs(L), 1.0)
        return where(x > y, x, y)

    def limit_value(self, joint: str, side: str) -> float:
        if side == "stick":
            return self.stick_at[joint]
        lim = self.model.joints[joint].stops
        return lim.lower if side == "lower" else lim.upper

    def _mode(self, locked: Locked, zones, slip) -> tuple:
        zones = self.zones if zones is None else zones
        slip = self.slip if slip is None else slip
        # a locked joint does not slip: a trial lock of a slipping joint (is the stop it
        # reaches at rest going to hold it?) must not keep its kinetic friction
        slip = {j: s for j, s in slip.items() if j not in locked}
        return (tuple((j, s, self.limit_value(j, s)) for j, s in sorted(locked.items())),
                tuple(sorted(zones)), tuple(sorted(slip.items())))

    def mode(self) -> tuple:
        """The configuration in force as a hashable key: locked joints with their sides and
        lock values, acting zoned loads, slip directions (what the event functions and a
        configuration's equations depend on)."""
        return self._mode(self.locked, None, None)

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

    def static(self, joint: str, lam: Any = None) -> Any:
        """Static friction limit of a joint (0 without friction), N or N m; with friction
        from the reaction, at the multipliers ``lam`` (numbers or CasADi symbols)."""
        f = self.model.joints[joint].friction
        if f is None:
            return 0.0
        if f.from_reaction and lam is not None:
            return reaction.level(self.model, joint, lam, "static")
        return f.static

    def lock_force(self, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                   locked: Locked | None = None) -> float:
        """:meth:`push` from a KKT solve at (q, v, t) in configuration ``locked``."""
        locked = self.locked if locked is None else locked
        _, lam, _ = self.model.kkt(q, v, t, self.params_of(locked))
        return self.push(lam, joint, locked)


# ------------------------------------------------------------------- queries
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


def slide_of(model: Model, joint: str) -> str | None:
    """The slide of a unilateral contact with friction (``"K:slide"``), or None."""
    name = joint + SLIDE
    return name if name in model.slides else None


def idle_slide(model: Model, name: str, locked: Locked) -> bool:
    """Whether ``name`` is the slide of a contact that does not touch under ``locked`` (a
    slide slips or sticks only while its contact touches)."""
    return name in model.slides and model.slides[name] not in locked


def without(model: Model, locked: Locked, joint: str) -> dict[str, str]:
    """Lock set ``locked`` without ``joint`` and, for a contact, its slide (a slide holds
    only while its contact touches)."""
    slide = slide_of(model, joint)
    return {j: s for j, s in locked.items() if j not in (joint, slide)}


def over_constrained(hs: HybridState, locked: Locked, q: np.ndarray, t: float) -> bool:
    """True when the active constraint rows of lock set ``locked`` are dependent at q."""
    p = hs.params_of(locked)
    return rank.dependent(hs.model.constraints(q, t, p).Phi_q[hs.model.active_rows(p)])


def joint_acceleration(hs: HybridState, q: np.ndarray, v: np.ndarray, t: float, joint: str,
                       locked: Locked) -> tuple[float, float]:
    """Acceleration of a joint coordinate from a KKT solve in configuration ``locked``,
    and the largest body acceleration (its scale)."""
    model = hs.model
    a, _, _ = model.kkt(q, v, t, hs.params_of(locked))
    return float(model.joint_accelerations(q, v, a, t)[model.jidx[joint]]), \
        float(np.max(np.abs(a), initial=0.0))


def joint_rate(model: Model, q: np.ndarray, v: np.ndarray, joint: str) -> float:
    return float(model.joint_rates(q, v)[1][model.jidx[joint]])


def impulses(model: Model, imp: np.ndarray) -> dict[str, float]:
    """The nonzero impulse of each constraint row, by row label (N s or N m s)."""
    return {f"{r.kind} {r.name}": float(x) for r, x in zip(model.rows, imp, strict=True)
            if x != 0.0}
