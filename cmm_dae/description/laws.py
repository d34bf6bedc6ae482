"""Laws in time of a mechanism's description: a driver's prescribed motion, a load's law
and the zone where a load acts (frozen dataclasses, SI units)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

__all__ = ["Driver", "Law", "Zone"]


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
