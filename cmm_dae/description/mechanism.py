"""Mechanism description: frozen dataclasses, buildable in Python or loaded from TOML.

SI units throughout: m, kg, s, rad, N, N m. A body's pose is the position and angle
of its own frame, the frame its ``points`` and ``centroid`` are written in.
"""

from __future__ import annotations

import os
from dataclasses import InitVar, dataclass, field
from types import MappingProxyType
from typing import Literal

from ..core.errors import ModelError, Problem
from ..core.memo import once
from .checks import FRAMES, GROUND, JOINT_TYPES, LAWS, MOTIONS, validate
from .curves import spline
from .laws import Driver, Law, Zone
from .parts import Curve, Damper, Friction, Gear, Limits, Spring
from .records import SLIDE_OF, Initial, Load, Vec2, Vec3, _floats, _frozen

__all__ = [
    "FRAMES", "GROUND", "JOINT_TYPES", "LAWS", "MOTIONS", "Body", "Curve", "Damper",
    "Driver", "Element", "Friction", "Gear", "Initial", "Joint", "Law", "Limits", "Load",
    "Mechanism", "Spring", "Zone", "require_mechanism", "validate",
]


#: joint types of spatial mechanisms only, and each spatial type's constraint rows
SPATIAL_ONLY = ("spherical", "universal", "cylindrical", "slide")
SPATIAL_ROWS = {"revolute": 5, "prismatic": 5, "cylindrical": 4, "universal": 4, "slide": 0,
                "spherical": 3}

@dataclass(frozen=True)
class Body:
    """A rigid body.

    Parameters
    ----------
    name : str
        Body name (unique, not ``"ground"``).
    mass : float
        Mass, kg (> 0).
    inertia : float
        Moment of inertia about the centroid, kg m^2 (> 0).
    centroid : (float, float)
        Centroid in the body frame, m.
    points : dict[str, (float, float)]
        Named points in the body frame, m.
    guess : (float, float, float) or None
        Pose guess (x m, y m, theta rad) of the body frame for assembly; in a spatial
        mechanism six numbers, the frame's origin (m) and its rotation vector (axis times
        angle, rad), or twelve, then the origin's velocity (m/s) and the angular velocity
        (rad/s, global axes) too (where no [initial] rate names the motion).
    axes : dict[str, (float, float, float)]
        Spatial mechanisms: named directions in the body frame (normalised on use), which
        joints name as ``"body.axis"``.

    In a spatial mechanism (``Mechanism.space == "spatial"``) points and the centroid have
    three coordinates and ``inertia`` is the centroidal tensor in the body frame: three
    principal moments ``(Ixx, Iyy, Izz)`` or six numbers ``(Ixx, Iyy, Izz, Ixy, Ixz, Iyz)``
    (kg m^2, products of inertia as the tensor's off-diagonal entries).
    """

    name: str
    mass: float
    inertia: float | tuple[float, ...]
    centroid: Vec2 | Vec3 = (0.0, 0.0)
    points: MappingProxyType = field(default_factory=lambda: _frozen({}))
    guess: tuple[float, ...] | None = None
    axes: MappingProxyType = field(default_factory=lambda: _frozen({}))

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", _frozen(
            {k: _floats(v) for k, v in dict(self.points).items()}))
        object.__setattr__(self, "centroid", _floats(self.centroid))
        object.__setattr__(self, "axes", _frozen(
            {k: _floats(v) for k, v in dict(self.axes).items()}))
        if isinstance(self.inertia, list | tuple):
            object.__setattr__(self, "inertia", _floats(self.inertia))

    def __reduce__(self):  # MappingProxyType does not pickle: rebuild from plain dicts
        return (Body, (self.name, self.mass, self.inertia, self.centroid, dict(self.points),
                       self.guess, dict(self.axes)))

    @classmethod
    def with_inertia_about(cls, name: str, mass: float, inertia: float, about: Vec2,
                           centroid: Vec2, **kw) -> Body:
        """Build a body whose inertia is given about a point (parallel-axis theorem).

        ``inertia`` is about ``about`` (body frame, m); the stored value is centroidal.
        """
        d2 = (about[0] - centroid[0]) ** 2 + (about[1] - centroid[1]) ** 2
        return cls(name, mass, inertia - mass * d2, centroid, **kw)


class _TwoPoints:
    """Bodies of a ``first``/``second`` pair of "body.point" references."""

    first: str
    second: str

    @property
    def first_body(self) -> str:
        return self.first.split(".", 1)[0]

    @property
    def second_body(self) -> str:
        return self.second.split(".", 1)[0]


@dataclass(frozen=True)
class Joint(_TwoPoints):
    """A lower pair between two bodies (either may be ``ground``).

    Parameters
    ----------
    name : str
        Joint name.
    type : {"revolute", "prismatic", "contact"}; in space also "cylindrical", "spherical",
        "universal"
        Pair type. A spatial cylindrical joint J's displacement along its axis is the
        coordinate of a second joint, ``Joint("J:slide", "slide", first, second,
        axes=J.axes)``, added by the Mechanism where it is not given (give it to put limits,
        a spring, a damper or friction on the displacement).
    first, second : str
        ``"body.point"`` of the first and the second body.
    axis : (float, float)
        Prismatic sliding direction in the first body's frame (normalised on use).
    angle : float
        Prismatic: the held relative angle ``theta_second - theta_first``, rad.
    limits : Limits or None
        Extreme positions of the joint coordinate (geometric constraint).
    restitution : float
        Newton coefficient at the limits, 0 (plastic) to 1.
    spring : Spring or None
        Spring on the joint coordinate (a rest beyond a limit is a preload: force constraint).
    damper : Damper or None
        Damper on the joint coordinate rate.
    friction : Friction or None
        Dry friction (stick/slip, event-located; no regularisation).
    curve : Curve or None
        Contact: the curve of the first body the second point stays on.
    side : {"outside", "inside", "left", "right"}
        Contact: the side of the curve the point keeps to (a circle's or a spline's
        outside or inside; a line's left or right of its direction, where "outside" and
        "inside" read as left and right).
    unilateral : bool
        Contact: the point may leave the curve (it lifts off when the contact would have
        to pull, lands again with ``restitution``); its coordinate is then its distance
        from the curve on its side (the gap, m, >= 0). A bilateral contact (a pin in a
        slot) keeps to the curve; its coordinate is the arc length (m), ``limits`` its
        ends (an open spline's own ends by default).
    axes : (str, str) or None
        Spatial mechanisms: one named axis of each body, ``("body.axis", "body.axis")``:
        held aligned (revolute, prismatic, cylindrical) or, for a universal joint, the
        two arms held perpendicular.
    reference : (str, str) or None
        Spatial revolute, prismatic and cylindrical joints: one named direction of each
        body across the axis; the angle about the first axis from the first to the second
        is the joint's coordinate (rad, in (-pi, pi]; a prismatic joint holds it at 0).
        Default: the bodies' axes named ``x``.
    """

    name: str
    type: Literal["revolute", "prismatic", "contact", "cylindrical", "spherical",
                  "universal", "slide"]
    first: str
    second: str
    axis: Vec2 = (1.0, 0.0)
    angle: float = 0.0
    limits: Limits | None = None
    restitution: float = 0.0
    spring: Spring | None = None
    damper: Damper | None = None
    friction: Friction | None = None
    curve: Curve | None = None
    side: str = "outside"
    unilateral: bool = False
    axes: tuple[str, str] | None = None
    reference: tuple[str, str] | None = None

    @property
    def unit(self) -> str:
        return "rad" if self.type in ("revolute", "cylindrical") else "m"

    @property
    def spatial(self) -> bool:
        """A joint of a spatial mechanism (it names its bodies' axes)."""
        return self.axes is not None or self.type in SPATIAL_ONLY

    @property
    def rows(self) -> int:
        """Constraint rows the joint holds with no stop locked: 2 for a planar lower pair,
        1 for a bilateral contact, 0 for a unilateral one; in space 5 for a revolute or
        prismatic joint, 4 for a cylindrical or universal one, 3 for a spherical one."""
        if self.spatial:
            return SPATIAL_ROWS[self.type]
        if self.type != "contact":
            return 2
        return 0 if self.unilateral else 1

    @property
    def lands(self) -> bool:
        """A unilateral contact: its stop is its curve, its lock a landing, its release a
        lift-off."""
        return self.type == "contact" and self.unilateral

    @property
    def stops(self) -> Limits | None:
        """Where the joint's coordinate meets a stop: its ``limits``, or for a unilateral
        contact the curve itself (gap 0); a bilateral contact on an open spline stops at
        the curve's ends unless ``limits`` are given."""
        if self.lands:
            return Limits(lower=0.0)
        c = self.curve
        if self.limits is None and c is not None and c.kind == "spline" and not c.closed:
            try:
                return Limits(0.0, spline(c).length)
            except ValueError:  # points out of order: the checks report the curve
                return Limits(lower=0.0)
        return self.limits


@dataclass(frozen=True)
class Element(_TwoPoints):
    """Spring-damper-actuator between two points of any two bodies (ground included).

    Tension ``preload + stiffness (L - rest) + damping L'`` (N) with L the distance of the
    points (m); a positive tension pulls the points together. stiffness N/m, rest m,
    damping N s/m, preload N.
    """

    name: str
    first: str
    second: str
    stiffness: float = 0.0
    rest: float = 0.0
    damping: float = 0.0
    preload: float = 0.0


@dataclass(frozen=True)
class Mechanism:
    """A planar or spatial mechanism (``space``: ``"planar"`` or ``"spatial"``): ground
    points (and, in space, ground ``axes``), bodies, joints, drivers, initial state.

    Built from lists or dicts; validated on construction (every problem at once,
    one :class:`ModelError`) unless ``check=False``.
    """

    name: str
    bodies: MappingProxyType
    joints: MappingProxyType
    ground: MappingProxyType = field(default_factory=lambda: _frozen({}))
    drivers: MappingProxyType = field(default_factory=lambda: _frozen({}))
    initial: Initial = field(default_factory=Initial)
    gravity: Vec2 = (0.0, -9.81)
    source: str | None = None
    loads: MappingProxyType = field(default_factory=lambda: _frozen({}))
    elements: MappingProxyType = field(default_factory=lambda: _frozen({}))
    gears: MappingProxyType = field(default_factory=lambda: _frozen({}))
    space: str = "planar"
    axes: MappingProxyType = field(default_factory=lambda: _frozen({}))
    check: InitVar[bool] = True

    def __post_init__(self, check: bool) -> None:
        dup: list[Problem] = []

        def as_map(items, key, table):
            if isinstance(items, dict | MappingProxyType):
                for k, x in items.items():
                    if getattr(x, key) != k:
                        dup.append(Problem(f"{table}.{k}", key, f"the entry is keyed '{k}' "
                                           f"but its {key} is '{getattr(x, key)}'"))
                return _frozen(items)
            out: dict = {}
            for x in items:
                k = getattr(x, key)
                if k in out:
                    dup.append(Problem(f"{table}.{k}", "", f"two entries named '{k}'"
                                       + (" (one driver per joint)" if table == "drivers"
                                          else "")))
                out[k] = x
            return _frozen(out)

        object.__setattr__(self, "bodies", as_map(self.bodies, "name", "bodies"))
        object.__setattr__(self, "joints", _with_slides(as_map(self.joints, "name", "joints")))
        object.__setattr__(self, "drivers", as_map(self.drivers, "joint", "drivers"))
        object.__setattr__(self, "loads", as_map(self.loads, "name", "loads"))
        object.__setattr__(self, "elements", as_map(self.elements, "name", "elements"))
        object.__setattr__(self, "gears", as_map(self.gears, "name", "gears"))
        object.__setattr__(self, "ground", _frozen(
            {k: _floats(v) for k, v in dict(self.ground).items()}))
        object.__setattr__(self, "axes", _frozen(
            {k: _floats(v) for k, v in dict(self.axes).items()}))
        object.__setattr__(self, "gravity", _floats(self.gravity))
        problems = dup + validate(self) if check else []
        if problems:
            raise ModelError(problems, self.source)

    def __reduce__(self):
        return (_rebuild, (self.name, dict(self.bodies), dict(self.joints), dict(self.ground),
                           dict(self.drivers), self.initial, self.gravity, self.source,
                           dict(self.loads), dict(self.elements), dict(self.gears),
                           self.space, dict(self.axes)))

    def replace(self, **changes) -> Mechanism:
        """A copy with some fields replaced (``bodies=``, ``loads=``, ...), validated."""
        kw = dict(name=self.name, bodies=dict(self.bodies), joints=dict(self.joints),
                  ground=dict(self.ground), drivers=dict(self.drivers), initial=self.initial,
                  gravity=self.gravity, source=self.source, loads=dict(self.loads),
                  elements=dict(self.elements), gears=dict(self.gears), space=self.space,
                  axes=dict(self.axes))
        kw.update(changes)
        return Mechanism(**kw)

    @property
    def limited_joints(self) -> list[str]:
        """Names of the joints with stops (the metamorphic joints: limits, unilateral
        contacts), in file order."""
        # (a frozen mechanism's: found once, 0.17 ms with 145 joints, asked at every run)
        return list(once(self, ("limited joints",),
                         lambda: [n for n, j in self.joints.items() if j.stops is not None]))

    @property
    def lockable_joints(self) -> list[str]:
        """Joints that can lock: on a stop (limits, a unilateral contact's curve) or
        sticking (friction), in file order."""
        return [n for n, j in self.joints.items()
                if j.stops is not None or j.friction is not None]

    @property
    def frictional_joints(self) -> list[str]:
        """Joints with dry friction, in file order."""
        return [n for n, j in self.joints.items() if j.friction is not None]

    def point(self, ref: str) -> Vec2 | Vec3:
        """Local coordinates (m) of ``"body.point"`` in its body frame."""
        body, pt = ref.split(".", 1)
        if body == GROUND:
            return self.ground[pt]
        return self.bodies[body].points[pt]

    def axis(self, ref: str) -> Vec3:
        """The direction ``"body.axis"`` in its body frame, as given (spatial)."""
        body, ax = ref.split(".", 1)
        return self.axes[ax] if body == GROUND else self.bodies[body].axes[ax]

    @property
    def spatial(self) -> bool:
        """Whether the mechanism is spatial (``space == "spatial"``)."""
        return self.space == "spatial"


def _with_slides(joints: MappingProxyType) -> MappingProxyType:
    """The joints, with the slide of each cylindrical joint that has none (a cylindrical
    joint J has two coordinates: its angle, J's own, and its displacement along the axis,
    that of the joint ``J:slide`` of type "slide", which holds no row of its own and takes
    limits, a spring, a damper, friction, a driver and loads as any joint)."""
    missing = {SLIDE_OF.format(n): Joint(SLIDE_OF.format(n), "slide", j.first, j.second,
                                         axes=j.axes, reference=j.reference)
               for n, j in joints.items()
               if j.type == "cylindrical" and SLIDE_OF.format(n) not in joints}
    if not missing:
        return joints
    out: dict = {}
    for n, j in joints.items():  # each slide just after its joint
        out[n] = j
        if SLIDE_OF.format(n) in missing:
            out[SLIDE_OF.format(n)] = missing[SLIDE_OF.format(n)]
    return _frozen(out)


def require_mechanism(obj: object, caller: str) -> None:
    """Raise a plain TypeError when ``obj`` is not a :class:`Mechanism` (a model file's
    path is the usual slip: it said "'PosixPath' object has no attribute 'bodies'")."""
    if not isinstance(obj, Mechanism):
        hint = (" (a model file: cmm_dae.load(path) reads it into one)"
                if isinstance(obj, str | os.PathLike) else "")
        raise TypeError(f"{caller} expects a cmm_dae.Mechanism{hint}, got "
                        f"{type(obj).__name__} {obj!r:.80}")


def _rebuild(name, bodies, joints, ground, drivers, initial, gravity, source, loads=None,
             elements=None, gears=None, space="planar", axes=None) -> Mechanism:
    """Unpickling: the description was validated when it was first built."""
    return Mechanism(name=name, bodies=bodies, joints=joints, ground=ground, drivers=drivers,
                     initial=initial, gravity=gravity, source=source, loads=loads or {},
                     elements=elements or {}, gears=gears or {}, space=space,
                     axes=axes or {}, check=False)


