"""Small records of a mechanism's description: an applied load and the initial state
(frozen dataclasses, SI units), and the helpers that freeze a description's maps and
points."""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from types import MappingProxyType

from .laws import Law, Zone

__all__ = ["SLIDE", "SLIDE_OF", "Initial", "Load", "Vec2", "Vec3", "slide_base"]

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]


#: the suffix of a slide's name: a cylindrical joint J's second coordinate is the joint
#: "J:slide" (and a frictional unilateral contact K's arc length the model's "K:slide")
SLIDE = ":slide"
#: the name of a cylindrical joint's slide, the joint of its second coordinate
SLIDE_OF = "{}" + SLIDE


def slide_base(name: str) -> str | None:
    """The joint whose slide ``name`` is ("J" of "J:slide"), else None."""
    return name[:-len(SLIDE)] if name.endswith(SLIDE) else None


def _floats(v) -> tuple:
    """A point, direction or tensor as a tuple of floats (any length: 2 in a planar
    mechanism, 3 in a spatial one; the checks say when it is the wrong one). Entries that
    are not real numbers (a sensitivity's symbols, a bad value for the checks) are kept."""
    try:
        return tuple(float(x) if isinstance(x, numbers.Real) else x for x in v)
    except TypeError:  # not a sequence: the checks report it
        return (v,)


def _frozen(d: dict | None) -> MappingProxyType:
    return MappingProxyType(dict(d or {}))


@dataclass(frozen=True)
class Load:
    """An applied load: a scalar :class:`Law` times what it acts on.

    On a joint coordinate (``joint``): a torque (revolute, N m) or force (prismatic, N),
    positive along the coordinate on the second body, negative on the first. At a body
    point (``body`` and ``point``): a force ``law * direction`` (N; ``direction``
    normalised, in the ``"global"`` or the ``"body"`` frame). On a body without a point: a
    pure moment (N m; in the plane counter-clockwise positive, in space about
    ``direction``). ``zone`` limits where it acts.
    """

    name: str
    law: Law
    joint: str | None = None
    body: str | None = None
    point: str | None = None
    direction: Vec2 | Vec3 | None = None
    frame: str = "global"
    zone: Zone | None = None

    @property
    def target(self) -> str:
        """``"joint"``, ``"point"`` or ``"moment"``."""
        if self.joint is not None:
            return "joint"
        return "point" if self.point is not None else "moment"


@dataclass(frozen=True)
class Initial:
    """Known joint coordinates and joint-coordinate rates at t = 0 (rad, m, rad/s, m/s).

    ``equilibrium``: dotted model paths (``"joints.D.spring.rest"``) solved so that the
    coordinates named in ``joints`` start with zero acceleration (as many paths as those
    coordinates), or ``"position"`` to solve those coordinates themselves; () for none.
    """

    joints: MappingProxyType = field(default_factory=lambda: _frozen({}))
    velocities: MappingProxyType = field(default_factory=lambda: _frozen({}))
    equilibrium: tuple[str, ...] | str = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "joints", _frozen(self.joints))
        object.__setattr__(self, "velocities", _frozen(self.velocities))
        if not isinstance(self.equilibrium, str):
            object.__setattr__(self, "equilibrium", tuple(self.equilibrium))

    def __reduce__(self):
        return (Initial, (dict(self.joints), dict(self.velocities), self.equilibrium))
