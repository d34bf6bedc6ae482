"""Mechanism description: frozen dataclasses, buildable in Python or loaded from TOML.

SI units throughout: m, kg, s, rad, N, N m. A body's pose is the position and angle
of its own frame, the frame its ``points`` and ``centroid`` are written in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import InitVar, dataclass, field
from types import MappingProxyType
from typing import Literal

from .errors import ModelError, Problem

GROUND = "ground"
JOINT_TYPES = ("revolute", "prismatic")
MOTIONS = ("constant_speed", "polynomial", "harmonic", "table")
LAWS = ("constant", "polynomial", "harmonic", "table", "motor")
FRAMES = ("global", "body")

Vec2 = tuple[float, float]


def _frozen(d: dict | None) -> MappingProxyType:
    return MappingProxyType(dict(d or {}))


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
        Pose guess (x m, y m, theta rad) of the body frame for assembly.
    """

    name: str
    mass: float
    inertia: float
    centroid: Vec2 = (0.0, 0.0)
    points: MappingProxyType = field(default_factory=lambda: _frozen({}))
    guess: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", _frozen(
            {k: (float(v[0]), float(v[1])) for k, v in dict(self.points).items()}))
        object.__setattr__(self, "centroid", (float(self.centroid[0]), float(self.centroid[1])))

    def __reduce__(self):  # MappingProxyType does not pickle: rebuild from plain dicts
        return (Body, (self.name, self.mass, self.inertia, self.centroid, dict(self.points),
                       self.guess))

    @classmethod
    def with_inertia_about(cls, name: str, mass: float, inertia: float, about: Vec2,
                           centroid: Vec2, **kw) -> Body:
        """Build a body whose inertia is given about a point (parallel-axis theorem).

        ``inertia`` is about ``about`` (body frame, m); the stored value is centroidal.
        """
        d2 = (about[0] - centroid[0]) ** 2 + (about[1] - centroid[1]) ** 2
        return cls(name, mass, inertia - mass * d2, centroid, **kw)


@dataclass(frozen=True)
class Limits:
    """Extreme positions of a joint coordinate (rad or m); either side may be None."""

    lower: float | None = None
    upper: float | None = None


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
class Friction:
    """Dry friction in a joint: it sticks while the force it must carry stays within
    ``static`` and slides against ``kinetic`` (N for a prismatic joint, N m for a revolute
    one; static >= kinetic >= 0)."""

    static: float
    kinetic: float


@dataclass(frozen=True)
class Joint(_TwoPoints):
    """A lower pair between two bodies (either may be ``ground``).

    Parameters
    ----------
    name : str
        Joint name.
    type : {"revolute", "prismatic"}
        Pair type.
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
    """

    name: str
    type: Literal["revolute", "prismatic"]
    first: str
    second: str
    axis: Vec2 = (1.0, 0.0)
    angle: float = 0.0
    limits: Limits | None = None
    restitution: float = 0.0
    spring: Spring | None = None
    damper: Damper | None = None
    friction: Friction | None = None

    @property
    def unit(self) -> str:
        return "rad" if self.type == "revolute" else "m"


@dataclass(frozen=True)
class Driver:
    """Prescribed motion of a joint coordinate (one driver per driven joint).

    motion : {"constant_speed", "polynomial", "harmonic", "table"}
        ``constant_speed``: ``initial + speed t``; ``polynomial``: ``sum c_k t^k``;
        ``harmonic``: ``initial + amplitude sin(2 pi frequency t + phase)``;
        ``table``: C2 cubic spline through ``times``/``values`` with zero end slopes,
        held at the last value after the last time.
    Units: rad, rad/s, Hz, s (m, m/s for a prismatic joint).
    """

    joint: str
    motion: str = "constant_speed"
    initial: float = 0.0
    speed: float = 0.0
    coefficients: tuple[float, ...] = ()
    amplitude: float = 0.0
    frequency: float = 0.0
    phase: float = 0.0
    times: tuple[float, ...] = ()
    values: tuple[float, ...] = ()

    def value0(self) -> float:
        """Coordinate at t = 0."""
        if self.motion == "constant_speed":
            return self.initial
        if self.motion == "polynomial":
            return self.coefficients[0] if self.coefficients else 0.0
        if self.motion == "harmonic":
            return self.initial + self.amplitude * math.sin(self.phase)
        return self.values[0]


@dataclass(frozen=True)
class Law:
    """A scalar law of a load: of time, and for ``motor`` of the loaded joint's rate.

    kind : {"constant", "polynomial", "harmonic", "table", "motor"}
        ``constant``: ``value``; ``polynomial``: ``sum coefficients[k] t^k``;
        ``harmonic``: ``mean + amplitude sin(2 pi frequency t + phase)``;
        ``table``: C2 cubic spline through ``times``/``values`` (zero end slopes), held at
        the last value after the last time; ``motor``: ``stall (1 - rate / no_load_speed)``
        with the rate of the loaded joint (a motor's torque-speed line).
    func : callable or None
        From Python only: ``func(t, coordinate, rate) -> float`` replaces the law (its
        derivatives are taken by finite differences); never a string.
    Units: those of the load (N, N m), s, Hz, rad.
    """

    kind: str = "constant"
    value: float = 0.0
    coefficients: tuple[float, ...] = ()
    mean: float = 0.0
    amplitude: float = 0.0
    frequency: float = 0.0
    phase: float = 0.0
    times: tuple[float, ...] = ()
    values: tuple[float, ...] = ()
    stall: float = 0.0
    no_load_speed: float = 0.0
    func: Callable[[float, float, float], float] | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Zone:
    """Where a load acts: while joint ``joint`` (default: the loaded joint) lies in
    [``lower``, ``upper``] (rad or m; either may be None, open on that side)."""

    joint: str | None = None
    lower: float | None = None
    upper: float | None = None


@dataclass(frozen=True)
class Load:
    """An applied load: a scalar :class:`Law` times what it acts on.

    On a joint coordinate (``joint``): a torque (revolute, N m) or force (prismatic, N),
    positive along the coordinate on the second body, negative on the first. At a body
    point (``body`` and ``point``): a force ``law * direction`` (N; ``direction``
    normalised, in the ``"global"`` or the ``"body"`` frame). On a body without a point: a
    pure moment (N m, counter-clockwise positive). ``zone`` limits where it acts.
    """

    name: str
    law: Law
    joint: str | None = None
    body: str | None = None
    point: str | None = None
    direction: Vec2 | None = None
    frame: str = "global"
    zone: Zone | None = None

    @property
    def target(self) -> str:
        """``"joint"``, ``"point"`` or ``"moment"``."""
        if self.joint is not None:
            return "joint"
        return "point" if self.point is not None else "moment"


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


@dataclass(frozen=True)
class Mechanism:
    """A planar mechanism: ground points, bodies, joints, drivers, initial state.

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
        object.__setattr__(self, "joints", as_map(self.joints, "name", "joints"))
        object.__setattr__(self, "drivers", as_map(self.drivers, "joint", "drivers"))
        object.__setattr__(self, "loads", as_map(self.loads, "name", "loads"))
        object.__setattr__(self, "elements", as_map(self.elements, "name", "elements"))
        object.__setattr__(self, "ground", _frozen(
            {k: (float(v[0]), float(v[1])) for k, v in dict(self.ground).items()}))
        object.__setattr__(self, "gravity", (float(self.gravity[0]), float(self.gravity[1])))
        problems = dup + validate(self) if check else []
        if problems:
            raise ModelError(problems, self.source)

    def __reduce__(self):
        return (_rebuild, (self.name, dict(self.bodies), dict(self.joints), dict(self.ground),
                           dict(self.drivers), self.initial, self.gravity, self.source,
                           dict(self.loads), dict(self.elements)))

    def replace(self, **changes) -> Mechanism:
        """A copy with some fields replaced (``bodies=``, ``loads=``, ...), validated."""
        kw = dict(name=self.name, bodies=dict(self.bodies), joints=dict(self.joints),
                  ground=dict(self.ground), drivers=dict(self.drivers), initial=self.initial,
                  gravity=self.gravity, source=self.source, loads=dict(self.loads),
                  elements=dict(self.elements))
        kw.update(changes)
        return Mechanism(**kw)

    @property
    def limited_joints(self) -> list[str]:
        """Names of the joints with limits (the metamorphic joints), in file order."""
        return [n for n, j in self.joints.items() if j.limits is not None]

    @property
    def lockable_joints(self) -> list[str]:
        """Joints that can lock: on a stop (limits) or sticking (friction), in file order."""
        return [n for n, j in self.joints.items()
                if j.limits is not None or j.friction is not None]

    @property
    def frictional_joints(self) -> list[str]:
        """Joints with dry friction, in file order."""
        return [n for n, j in self.joints.items() if j.friction is not None]

    def point(self, ref: str) -> Vec2:
        """Local coordinates (m) of ``"body.point"`` in its body frame."""
        body, pt = ref.split(".", 1)
        if body == GROUND:
            return self.ground[pt]
        return self.bodies[body].points[pt]


def _rebuild(name, bodies, joints, ground, drivers, initial, gravity, source, loads=None,
             elements=None) -> Mechanism:
    """Unpickling: the description was validated when it was first built."""
    return Mechanism(name=name, bodies=bodies, joints=joints, ground=ground, drivers=drivers,
                     initial=initial, gravity=gravity, source=source, loads=loads or {},
                     elements=elements or {}, check=False)


def _finite(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def _check_ref(m: Mechanism, table: str, key: str, ref: str, out: list[Problem]) -> None:
    if not isinstance(ref, str) or "." not in ref:
        out.append(Problem(table, key, f"expected 'body.point', got {ref!r}"))
        return
    body, pt = ref.split(".", 1)
    if body == GROUND:
        if pt not in m.ground:
            out.append(Problem(table, key, f"unknown ground point '{pt}' in {ref!r} "
                               f"(ground points: {', '.join(m.ground) or 'none'})"))
    elif body not in m.bodies:
        out.append(Problem(table, key, f"unknown body '{body}' in {ref!r} "
                           f"(bodies: {', '.join(m.bodies) or 'none'})"))
    elif pt not in m.bodies[body].points:
        out.append(Problem(table, key, f"body '{body}' has no point '{pt}' "
                           f"(its points: {', '.join(m.bodies[body].points) or 'none'})"))


def validate(m: Mechanism) -> list[Problem]:
    """All semantic problems of a mechanism (empty list when it is sound)."""
    out: list[Problem] = []
    if not all(_finite(g) for g in m.gravity):
        out.append(Problem("mechanism", "gravity", f"expected two finite numbers, got {m.gravity}"))
    if not m.bodies:
        out.append(Problem("bodies", "", "a mechanism needs at least one body"))
    for name, b in m.bodies.items():
        t = f"bodies.{name}"
        if name == GROUND:
            out.append(Problem(t, "", "'ground' is reserved for the frame"))
        if not (_finite(b.mass) and b.mass > 0):
            out.append(Problem(t, "mass", f"expected a positive mass in kg, got {b.mass}"))
        if not (_finite(b.inertia) and b.inertia > 0):
            out.append(Problem(t, "inertia", "expected a positive centroidal inertia in kg m^2, "
                               f"got {b.inertia:.6g}" if _finite(b.inertia) else
                               f"expected a positive centroidal inertia, got {b.inertia}"))
    used_bodies: set[str] = set()
    for name, j in m.joints.items():
        t = f"joints.{name}"
        if j.type not in JOINT_TYPES:
            out.append(Problem(t, "type", f"expected one of {', '.join(JOINT_TYPES)}, "
                               f"got {j.type!r}"))
        _check_ref(m, t, "connects", j.first, out)
        _check_ref(m, t, "connects", j.second, out)
        if j.first_body == j.second_body:
            out.append(Problem(t, "connects", f"joins body '{j.first_body}' to itself"))
        used_bodies.update((j.first_body, j.second_body))
        if j.type == "prismatic" and not (all(_finite(a) for a in j.axis)
                                          and math.hypot(*j.axis) > 1e-12):
                out.append(Problem(t, "axis", f"expected a non-zero direction, got {j.axis}"))
        if j.limits is not None:
            lo, up = j.limits.lower, j.limits.upper
            if lo is None and up is None:
                out.append(Problem(t, "limits", "give 'lower', 'upper' or both"))
            if lo is not None and up is not None and not lo < up:
                out.append(Problem(t, "limits", f"lower ({lo}) must be below upper ({up})"))
        if not (_finite(j.restitution) and 0.0 <= j.restitution <= 1.0):
            out.append(Problem(t, "restitution", f"expected a number in [0, 1], "
                               f"got {j.restitution}"))
        if j.spring is not None and not (_finite(j.spring.stiffness) and j.spring.stiffness >= 0):
            out.append(Problem(t, "spring.stiffness", "expected a stiffness >= 0, "
                               f"got {j.spring.stiffness}"))
        if j.damper is not None and not (_finite(j.damper.damping) and j.damper.damping >= 0):
            out.append(Problem(t, "damper.damping", f"expected a damping >= 0, "
                               f"got {j.damper.damping}"))
        if j.friction is not None:
            fs, fk = j.friction.static, j.friction.kinetic
            if not (_finite(fs) and _finite(fk) and fs >= fk >= 0):
                out.append(Problem(t, "friction", f"expected static >= kinetic >= 0 "
                                   f"({'N' if j.type == 'prismatic' else 'N m'}), got "
                                   f"static = {fs}, kinetic = {fk}"))
    for name in m.bodies:
        if name not in used_bodies:
            out.append(Problem(f"bodies.{name}", "", "is connected by no joint"))
    for name, d in m.drivers.items():
        t = f"drivers.{name}"
        if name not in m.joints:
            out.append(Problem(t, "", f"drives unknown joint '{name}' "
                               f"(joints: {', '.join(m.joints) or 'none'})"))
        elif m.joints[name].limits is not None:
            out.append(Problem(t, "", f"joint '{name}' has limits: a driven joint cannot be "
                               "metamorphic"))
        elif m.joints[name].friction is not None:
            out.append(Problem(t, "", f"joint '{name}' has friction: the driver would carry "
                               "it (put the friction on an undriven joint)"))
        out.extend(_check_driver(t, d))
    for name, ld in m.loads.items():
        out.extend(_check_load(m, f"loads.{name}", ld))
    for name, el in m.elements.items():
        t = f"elements.{name}"
        _check_ref(m, t, "connects", el.first, out)
        _check_ref(m, t, "connects", el.second, out)
        if el.first_body == el.second_body:
            out.append(Problem(t, "connects", f"both points are on body '{el.first_body}': "
                               "the element would do nothing"))
        for key in ("stiffness", "rest", "damping"):
            val = getattr(el, key)
            if not (_finite(val) and val >= 0):
                out.append(Problem(t, key, f"expected a number >= 0, got {val}"))
        if not _finite(el.preload):
            out.append(Problem(t, "preload", f"expected a finite number, got {el.preload}"))
    _check_initial(m, out)
    return out


def _check_law(t: str, law: Law, target: str) -> list[Problem]:
    out: list[Problem] = []
    if law.func is not None:
        if not callable(law.func):
            out.append(Problem(t, "law", f"expected a callable f(t, coordinate, rate), got "
                               f"{type(law.func).__name__}"))
        if target != "joint":
            out.append(Problem(t, "law", "a callable law f(t, coordinate, rate) needs a "
                               "joint: only a load on a joint coordinate can use it"))
        return out
    if law.kind not in LAWS:
        out.append(Problem(t, "law", f"expected one of {', '.join(LAWS)}, got {law.kind!r}"))
        return out
    nums = {"constant": ("value",), "harmonic": ("mean", "amplitude", "frequency", "phase"),
            "motor": ("stall", "no_load_speed")}.get(law.kind, ())
    for key in nums:
        if not _finite(getattr(law, key)):
            out.append(Problem(t, key, f"expected a finite number, got {getattr(law, key)}"))
    if law.kind == "polynomial" and not law.coefficients:
        out.append(Problem(t, "coefficients", "expected at least one coefficient"))
    if law.kind == "harmonic" and _finite(law.frequency) and law.frequency < 0:
        out.append(Problem(t, "frequency", f"expected a frequency >= 0 Hz, got {law.frequency}"))
    if law.kind == "table":
        out.extend(_check_table(t, law.times, law.values))
    if law.kind == "motor":
        if target != "joint":
            out.append(Problem(t, "law", "a motor law needs a joint rate: only a load on a "
                               "joint coordinate can use it"))
        if _finite(law.no_load_speed) and not law.no_load_speed > 0:
            out.append(Problem(t, "no_load_speed", f"expected a positive speed (rad/s or "
                               f"m/s), got {law.no_load_speed}"))
    return out


def _check_load(m: Mechanism, t: str, ld: Load) -> list[Problem]:
    out: list[Problem] = []
    if ld.joint is not None:
        if ld.body is not None or ld.point is not None:
            out.append(Problem(t, "joint", "a load acts on a joint or on a body, not both"))
        if ld.joint not in m.joints:
            out.append(Problem(t, "joint", f"unknown joint '{ld.joint}' "
                               f"(joints: {', '.join(m.joints) or 'none'})"))
    elif ld.body is None:
        out.append(Problem(t, "", "give 'joint' (a load on a joint coordinate) or 'body' "
                           "(a force at a point, or a moment)"))
    elif ld.body not in m.bodies:
        out.append(Problem(t, "body", f"unknown body '{ld.body}' "
                           f"(bodies: {', '.join(m.bodies) or 'none'})"))
    elif ld.point is not None and ld.point not in m.bodies[ld.body].points:
        out.append(Problem(t, "point", f"body '{ld.body}' has no point '{ld.point}' "
                           f"(its points: {', '.join(m.bodies[ld.body].points) or 'none'})"))
    if ld.target == "point":
        d = ld.direction
        if d is None or not (all(_finite(x) for x in d) and math.hypot(*d) > 1e-12):
            out.append(Problem(t, "direction", f"expected a non-zero direction [x, y], got {d}"))
        if ld.frame not in FRAMES:
            out.append(Problem(t, "frame", f"expected one of {', '.join(FRAMES)}, "
                               f"got {ld.frame!r}"))
    elif ld.direction is not None:
        out.append(Problem(t, "direction", "only a force at a body point has a direction"))
    out.extend(_check_law(t, ld.law, ld.target))
    z = ld.zone
    if z is not None:
        zj = z.joint if z.joint is not None else ld.joint
        if zj is None:
            out.append(Problem(t, "zone.joint", "a load on a body needs the zone's joint"))
        elif zj not in m.joints:
            out.append(Problem(t, "zone.joint", f"unknown joint '{zj}'"))
        elif z.lower is None and z.upper is None:
            out.append(Problem(t, "zone", "give 'lower', 'upper' or both"))
        elif z.lower is not None and z.upper is not None and not z.lower < z.upper:
            out.append(Problem(t, "zone", f"lower ({z.lower}) must be below upper ({z.upper})"))
        else:
            lim = m.joints[zj].limits
            lo = -math.inf if lim is None or lim.lower is None else lim.lower
            up = math.inf if lim is None or lim.upper is None else lim.upper
            zlo = -math.inf if z.lower is None else z.lower
            zup = math.inf if z.upper is None else z.upper
            if zup <= lo or zlo >= up:
                out.append(Problem(t, "zone", f"[{z.lower}, {z.upper}] lies outside the "
                                   f"limits [{lim.lower}, {lim.upper}] of joint '{zj}': "
                                   "the load could never act"))
    return out


def _check_driver(t: str, d: Driver) -> list[Problem]:
    out: list[Problem] = []
    if d.motion not in MOTIONS:
        out.append(Problem(t, "motion", f"expected one of {', '.join(MOTIONS)}, got {d.motion!r}"))
    elif d.motion == "polynomial" and not d.coefficients:
        out.append(Problem(t, "coefficients", "expected at least one coefficient"))
    elif d.motion == "table":
        out.extend(_check_table(t, d.times, d.values))
    elif d.motion == "harmonic" and not d.frequency >= 0:
        out.append(Problem(t, "frequency", f"expected a frequency >= 0 Hz, got {d.frequency}"))
    return out


def _check_table(t: str, times: tuple, values: tuple) -> list[Problem]:
    if len(times) < 2 or len(times) != len(values):
        return [Problem(t, "times", "expected 'times' and 'values' of equal length >= 2, "
                        f"got {len(times)} and {len(values)}")]
    if any(b <= a for a, b in zip(times, times[1:], strict=False)):
        return [Problem(t, "times", "expected strictly increasing times")]
    if times[0] != 0.0:
        return [Problem(t, "times", f"the table must start at t = 0, starts at {times[0]}")]
    return []


def _check_equilibrium(m: Mechanism, out: list[Problem]) -> None:
    eq = m.initial.equilibrium
    if not eq:
        return
    known = [k for k in m.initial.joints if k not in m.drivers]
    if isinstance(eq, str):
        if eq != "position":
            out.append(Problem("initial", "equilibrium", f"expected \"position\" or a list "
                               f"of parameter paths, got {eq!r}"))
        elif not known:
            out.append(Problem("initial", "equilibrium", "\"position\" solves the "
                               "coordinates named in [initial] joints: it names none"))
        return
    if len(eq) != len(known):
        out.append(Problem("initial", "equilibrium", f"{len(eq)} parameter(s) for "
                           f"{len(known)} free coordinate(s) ({', '.join(known) or 'none'}): "
                           "give one parameter per coordinate named in [initial] joints"))
    if len(set(eq)) != len(eq):
        out.append(Problem("initial", "equilibrium", "a parameter is listed twice"))


def _check_initial(m: Mechanism, out: list[Problem]) -> None:
    _check_equilibrium(m, out)
    for key, table in (("joints", m.initial.joints), ("velocities", m.initial.velocities)):
        for jn, val in table.items():
            if jn not in m.joints:
                out.append(Problem("initial", f"{key}.{jn}", f"unknown joint '{jn}' "
                                   f"(joints: {', '.join(m.joints) or 'none'})"))
            elif not _finite(val):
                out.append(Problem("initial", f"{key}.{jn}",
                                   f"expected a finite number, got {val}"))
            elif key == "joints" and jn in m.drivers:
                v0 = m.drivers[jn].value0()
                if abs(val - v0) > 1e-12 * max(1.0, abs(v0)):
                    out.append(Problem("initial", f"joints.{jn}", f"joint '{jn}' is driven: its "
                                       f"driver gives {v0!r} at t = 0, the file says {val!r}"))
            elif key == "velocities" and jn in m.drivers:
                out.append(Problem("initial", f"velocities.{jn}", f"joint '{jn}' is driven: its "
                                   "velocity comes from its driver"))
            elif key == "joints" and m.joints[jn].limits is not None:
                lim = m.joints[jn].limits
                tol = 1e-12
                if (lim.lower is not None and val < lim.lower - tol) or (
                        lim.upper is not None and val > lim.upper + tol):
                    out.append(Problem("initial", f"joints.{jn}", f"{val} lies outside the "
                                       f"limits [{lim.lower}, {lim.upper}] of joint '{jn}'"))
