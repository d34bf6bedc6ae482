"""The parts of a joint's description: its limits, spring, damper, friction and a contact's
curve, and the gear pair between two joints (frozen dataclasses, SI units)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from .curves import polar_knots

__all__ = ["Curve", "Damper", "Friction", "Gear", "Limits", "Spring"]

Vec2 = tuple[float, float]


@dataclass(frozen=True)
class Limits:
    """Extreme positions of a joint coordinate (rad or m); either side may be None."""

    lower: float | None = None
    upper: float | None = None

    def sides(self) -> list[tuple[str, float]]:
        """The stops that are given, as (side, position) pairs."""
        return [(s, L) for s, L in (("lower", self.lower), ("upper", self.upper))
                if L is not None]

    def beyond(self, c: float) -> float:
        """How far ``c`` lies beyond the nearer stop it passes (rad or m; 0 inside)."""
        out = 0.0
        if self.lower is not None:
            out = max(out, self.lower - c)
        if self.upper is not None:
            out = max(out, c - self.upper)
        return out

    def on(self, c: float) -> str | None:
        """The side whose stop ``c`` lies on, within :func:`stop_tolerance` (either way of
        it), else None."""
        return next((s for s, L in self.sides() if abs(c - L) <= stop_tolerance(L)), None)

    def outside(self, c: float) -> bool:
        """``c`` beyond a stop by more than :func:`stop_tolerance` (a start refused)."""
        return self.beyond(c) > 0.0 and self.on(c) is None

    def snap(self, c: float) -> float:
        """``c`` put exactly on a stop it lies on (:meth:`on`), else unchanged."""
        side = self.on(c)
        return c if side is None else (self.lower if side == "lower" else self.upper)


#: How near a joint coordinate must be to a stop to be on it: this times max(1, |stop|)
#: (rad or m). One tolerance everywhere: the file check refuses a start beyond a stop by
#: more, the start puts a joint within it exactly on the stop, the policy decides a start on
#: the stop with it. With three (1e-12 absolute in the file check, relative at the start),
#: a block 1e-12 m beyond its stop at 1 m passed the one and not the other, and fell 5 m
#: through the stop in 1 s with "success".
STOP_TOL = 1e-12


def stop_tolerance(L: float) -> float:
    """:data:`STOP_TOL` times max(1, |L|): the tolerance of "on the stop" at ``L``."""
    return STOP_TOL * max(1.0, abs(L))


@dataclass(frozen=True)
class Spring:
    """Linear spring on a joint coordinate: force -stiffness (c - rest).

    stiffness in N m/rad (revolute) or N/m (prismatic); rest in rad or m.
    """

    stiffness: float
    rest: float = 0.0


@dataclass(frozen=True)
class Damper:
    """Linear damper on a joint coordinate rate: N m s/rad or N s/m."""

    damping: float


@dataclass(frozen=True)
class Friction:
    """Dry friction in a joint: it sticks while the force it must carry stays within its
    static level and slides against its kinetic level.

    Each level is a constant (``static``, ``kinetic``: N for a prismatic or contact joint,
    N m for a revolute one) plus a part proportional to the joint's reaction
    (``mu_static``, ``mu_kinetic``, dimensionless): ``mu * radius * |F|`` on a revolute
    joint (F its reaction force, ``radius`` the pin's radius in m), ``mu * |N|`` on a
    prismatic joint (N the guide's normal reaction) or a bilateral contact (N the contact
    force). The reaction and the friction it causes are solved
    together. static >= kinetic >= 0, mu_static >= mu_kinetic >= 0."""

    static: float = 0.0
    kinetic: float = 0.0
    mu_static: float = 0.0
    mu_kinetic: float = 0.0
    radius: float = 0.0

    @property
    def from_reaction(self) -> bool:
        """Whether the levels grow with the joint's reaction."""
        return self.mu_static > 0.0 or self.mu_kinetic > 0.0


@dataclass(frozen=True)
class Curve:
    """The curve of a contact joint, in its first body's frame, through the first
    connect point (its origin).

    kind : {"circle", "line", "spline"}
        ``circle``: centred on the origin point, of ``radius`` (m); its arc length is
        measured counter-clockwise from the body's x axis, ``radius * atan2`` in
        (-pi radius, pi radius]. ``line``: through the origin point along ``direction``
        (normalised on use); its arc length is the distance along it from the origin.
        ``spline``: a smooth curve through ``points`` (m, relative to the origin point).
        Closed (``closed``, the default): counter-clockwise once around the origin, each
        ray from it meeting the curve once; its radius is the periodic cubic spline
        through the points' radii over their polar angles (a cam profile, a closed
        groove). Open: the points in increasing x, the curve the cubic spline y(x) through
        them (a curved slot or guide), its ends stops at arc lengths 0 and its length.
        A spline's arc length is measured from its first point.
    closed : bool
        ``spline`` only: a closed curve (True) or an open one (False).
    """

    kind: Literal["circle", "line", "spline"] = "circle"
    radius: float = 0.0
    direction: Vec2 = (1.0, 0.0)
    points: tuple[Vec2, ...] = ()
    closed: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", tuple(
            (float(x), float(y)) for x, y in self.points))

    def polar(self) -> tuple:
        """A closed spline's knots: polar angles and radii (m), :func:`.curves.polar_knots`."""
        return polar_knots(self.points)


@dataclass(frozen=True)
class Gear:
    """A gear pair or a rack and pinion: the coordinates of two joints in a fixed ratio,
    ``c_second = ratio * c_first + offset`` (a higher pair, one constraint row).

    Parameters
    ----------
    name : str
        Name of the pair (a joint name in the model file: ``[joints.NAME]``, type "gear").
    first, second : str
        The two joints: both revolute (two gears on axles held by one carrier body, or
        the ground: an external mesh, ``ratio`` < 0, or a pinion inside a ring gear, an
        internal mesh, ``ratio`` > 0), or one revolute and one prismatic (a pinion and
        its rack, on one carrier).
    ratio : float
        Rate of the second joint over the rate of the first: rad/rad for two gears
        (-z_first / z_second external, +z_first / z_second internal, not 1), m/rad for a
        rack driven by its pinion (+- the pitch radius), rad/m the other way round. The
        pitch radii follow from the axles' distance: r_first + r_second (external) or
        |r_second - r_first| (internal).
    pressure_angle : float
        Angle of the line of action from the pitch circles' common tangent, rad (default
        20 degrees); the tooth force is reported along it.
    offset : float
        ``c_second`` where ``c_first`` is 0, rad or m.
    """

    name: str
    first: str
    second: str
    ratio: float
    pressure_angle: float = math.radians(20.0)
    offset: float = 0.0
