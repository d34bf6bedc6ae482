"""The records the layers pass each other: a configuration met in a run, an event of the
hybrid policy, a run's solver statistics. Built by the event policy and the integrators,
read by the Result and the reports; they depend on nothing else in the package."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

__all__ = ["Configuration", "Event", "EventKind", "Side", "Stats"]


class EventKind(StrEnum):
    """What an :class:`Event` is (its ``kind``; equal to the plain string, so results and
    files written before keep comparing equal)."""

    LIMIT = "limit"  #: reached a limit and locked (an impact)
    BOUNCE = "bounce"  #: reached a limit and rebounded
    LOCK = "lock"  #: locked without an impact
    RELEASE = "release"  #: a lock let go
    STICK = "stick"  #: a joint with friction came to rest and holds
    SLIP = "slip"  #: a joint with friction slips (or its friction reverses)
    ZONE = "zone"  #: a load's zone entered or left
    SINGULAR = "singular"  #: a singular position passed
    LANDING = "landing"  #: a unilateral contact met its curve and holds (an impact)
    LIFT_OFF = "lift-off"  #: a unilateral contact let go (its force would pull)


class Side(StrEnum):
    """An :class:`Event`'s (and a trigger's) ``side``; equal to the plain string."""

    LOWER = "lower"  #: a joint's lower limit (a unilateral contact's curve)
    UPPER = "upper"  #: its upper limit
    STICK = "stick"  #: held by static friction
    POSITIVE = "positive"  #: slipping towards +c
    NEGATIVE = "negative"  #: slipping towards -c
    ENTER = "enter"  #: a load's zone entered
    LEAVE = "leave"  #: a load's zone left
    CONTINUE = "continue"  #: a singular position passed on the branch of the motion
    NONE = ""  #: a trigger without a side (a zone, a slipping joint's rate)


@dataclass(frozen=True)
class Configuration:
    """A configuration: the set of locked metamorphic joints.

    Attributes
    ----------
    locked : tuple[str, ...]
        Locked joints (sorted).
    sides : tuple[str, ...]
        ``"lower"``/``"upper"`` for each locked joint.
    dof : int
        Degrees of freedom of the mechanism with its drivers removed (mobility).
    label : str
        The paper's name: non-collision, internal/external collision (joint ...).
    zones : tuple[str, ...]
        The loads with a zone that act in this configuration.
    slip : tuple[tuple[str, int], ...]
        Joints slipping against kinetic friction, with their direction (+1 or -1).
    """

    locked: tuple[str, ...]
    sides: tuple[str, ...]
    dof: int
    label: str
    zones: tuple[str, ...] = ()
    slip: tuple[tuple[str, int], ...] = ()

    def describe(self) -> str:
        """The label with the locked joints, the slipping joints (+/- direction) and the
        zoned loads acting, e.g. ``non-collision [E] slip X+ load cut``."""
        txt = self.label + (f" [{','.join(self.locked)}]" if self.locked else "")
        if self.slip:
            txt += " slip " + ",".join(f"{j}{'+' if s > 0 else '-'}" for j, s in self.slip)
        if self.zones:
            txt += " load " + ",".join(self.zones)
        return txt


@dataclass(frozen=True, kw_only=True)
class Event:
    """One configuration change (or bounce), in time order.

    Attributes
    ----------
    t : float
        Time, s.
    kind : str
        ``"limit"`` (reached a limit and locked), ``"bounce"`` (reached it and rebounded),
        ``"lock"`` (locked without impact), ``"release"``, ``"zone"`` (a load's zone
        entered or left), ``"stick"`` and ``"slip"`` (dry friction; ``side`` "stick",
        "positive" or "negative", the force at the switch in ``release_force``),
        ``"singular"`` (a singular position passed: crossed on the branch of the motion or
        onto the branch a rule asks for, or integrated through by IDA, as its note says),
        ``"landing"`` and ``"lift-off"`` (a unilateral contact joint meets its curve and
        holds, with the impact's impulses and energy lost, or lets go; a landing that
        rebounds is a ``"bounce"``).
    joint : str
        The metamorphic joint (for a zone: the joint whose coordinate defines it).
    side : str
        ``"lower"`` or ``"upper"``; for a zone ``"enter"`` or ``"leave"``.
    before, after : int
        Configuration indices (into ``Result.configurations``).
    velocity_before, velocity_after : float
        Joint coordinate rate just before and after, rad/s or m/s.
    impulses : dict[str, float]
        Impulse carried by each constraint row label, N s (or N m s): the row's multiplier
        impulse Lambda in the impact map (``M v+ + Phi_q^T Lambda = M v-``), so a stop
        gives its joint ``-Lambda`` along the joint's coordinate (a lower stop's is
        negative, an upper stop's positive).
    energy_lost : float
        Kinetic energy lost in the impact, J.
    release_force : float
        Lock force/torque at a release (the value whose sign change released it), N or N m.
    load : str
        For a zone event, the load whose zone it is.
    note : str
        For a ``"singular"`` event (a singular position crossed: the constraints dependent
        for an instant, ``side`` the branch rule, ``"continue"``): the dependent
        constraints, the rank drop and the continuity of the velocities. Its
        ``velocity_before``/``after`` are the norms of the body velocities where the
        crossing began and ended, ``joint`` the first joint among the dependent ones and
        ``energy_lost`` 0 (the motion is continuous through it).
    """

    t: float
    kind: str
    joint: str
    side: str
    before: int
    after: int
    velocity_before: float = 0.0
    velocity_after: float = 0.0
    impulses: dict[str, float] = field(default_factory=dict)
    energy_lost: float = 0.0
    release_force: float = 0.0
    load: str = ""
    note: str = ""


@dataclass
class Stats:
    """Solver statistics of a run.

    steps: successful integration steps; nfev/njev: residual and Jacobian evaluations;
    segments: integrator (re)starts; wall_time and build_time in s.
    """

    steps: int = 0
    nfev: int = 0
    njev: int = 0
    segments: int = 0
    wall_time: float = 0.0
    build_time: float = 0.0
    method: str = ""
