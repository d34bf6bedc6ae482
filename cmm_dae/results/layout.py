"""What a Result keeps of its mechanism, typed: names, masses and geometry for the report,
the drawings, the exports and the energy audit (:class:`Layout`, ``Result.layout``).

A Result stores this as the plain dictionary ``Result.meta`` (it goes into a result file
as JSON, with what the run itself adds: tolerances, linear solver, the solved
equilibrium); every reader goes through :class:`Layout`, which fills what an older file
lacks with its empty default."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

__all__ = ["Layout"]


@dataclass(frozen=True, eq=False)
class Layout:
    """The mechanism a Result belongs to (lengths m, angles rad, masses kg).

    Attributes
    ----------
    mechanism : str
        Its name.
    source : str or None
        The model file it was read from.
    bodies, joints, joint_types, drivers, loads : tuple of str
        Names in the model's order (``joint_types``: each joint's type).
    centroids : tuple of (float, float)
        Each body's centroid in its own frame, m.
    masses : tuple of float
        The mass matrix's diagonal, three entries per body (kg, kg, kg m^2).
    rows, redundant : tuple of str
        The constraint rows ("joint A", "driver A", ...) and those left out as redundant.
    gravity : (float, float)
        m/s^2.
    springs : dict
        Joint -> (stiffness, rest) of its spring.
    dampers : dict
        Joint -> damping of its damper.
    metamorphic, frictional : tuple of str
        Joints with limits; joints with friction.
    elements : dict
        Element -> (stiffness, rest, damping, preload).
    gears : dict
        Gear pair -> (first joint, second joint, ratio).
    body_points, ground : dict
        Each body's points in its frame and the ground's points, m.
    connects : dict
        Joint -> its two points ("body.point").
    axes, limits, curves : dict
        Prismatic joints' guides, joints' (lower, upper) limits, contact joints' curves.
    slides : dict
        Unilateral contact with friction -> the column of its slide (its arc length) in
        the coordinate series; its friction is the slide's.
    space : str
        "planar" or "spatial" (then points and centroids have three coordinates, the
        masses are twelve entries per body and the coordinates are natural ones).
    principal : tuple of 9 floats
        Spatial: each body's principal axes of inertia in its frame (the 3 x 3 matrix by
        columns).
    """

    mechanism: str = ""
    source: str | None = None
    bodies: tuple[str, ...] = ()
    centroids: tuple[tuple[float, float], ...] = ()
    masses: tuple[float, ...] = ()
    joints: tuple[str, ...] = ()
    joint_types: tuple[str, ...] = ()
    drivers: tuple[str, ...] = ()
    loads: tuple[str, ...] = ()
    rows: tuple[str, ...] = ()
    redundant: tuple[str, ...] = ()
    gravity: tuple[float, float] = (0.0, -9.81)
    springs: dict[str, tuple[float, float]] = field(default_factory=dict)
    dampers: dict[str, float] = field(default_factory=dict)
    metamorphic: tuple[str, ...] = ()
    frictional: tuple[str, ...] = ()
    elements: dict[str, tuple[float, ...]] = field(default_factory=dict)
    gears: dict[str, tuple[str, str, float]] = field(default_factory=dict)
    body_points: dict[str, dict[str, tuple[float, float]]] = field(default_factory=dict)
    ground: dict[str, tuple[float, float]] = field(default_factory=dict)
    connects: dict[str, tuple[str, str]] = field(default_factory=dict)
    axes: dict[str, tuple[float, float]] = field(default_factory=dict)
    limits: dict[str, tuple[float | None, float | None]] = field(default_factory=dict)
    curves: dict[str, dict[str, Any]] = field(default_factory=dict)
    slides: dict[str, int] = field(default_factory=dict)
    space: str = "planar"
    principal: tuple[tuple[float, ...], ...] = ()

    @classmethod
    def of(cls, meta: dict[str, Any]) -> Layout:
        """The layout stored in a Result's ``meta`` (lists become tuples; keys an older
        file lacks take their defaults; keys the run added are left to ``meta``)."""
        def typed(v: Any) -> Any:
            if isinstance(v, list):
                return tuple(typed(x) for x in v)
            if isinstance(v, dict):
                return {k: typed(x) for k, x in v.items()}
            return v

        return cls(**{f.name: typed(meta[f.name]) for f in fields(cls) if f.name in meta})

    def joint_type(self, joint: str) -> str:
        """The type of a joint ("revolute", "prismatic", "contact")."""
        return self.joint_types[self.joints.index(joint)]

    def coordinate_unit(self, joint: str) -> str:
        """The unit of a joint's coordinate: "rad" (revolute, a cylindrical joint's angle),
        else "m"."""
        return "rad" if self.joint_type(joint) in ("revolute", "cylindrical") else "m"

    def joint_components(self) -> list[tuple[str, str, Callable[[Any], np.ndarray]]]:
        """A joint's reaction as series (reports, figures, columns): (name, unit, getter of
        a ``JointSeries``) for the force's x and y and the torque, or in space the force's
        and the torque's x, y and z (global axes)."""
        if self.space != "spatial":
            return [("force x", "N", lambda j: j.force[:, 0]),
                    ("force y", "N", lambda j: j.force[:, 1]),
                    ("torque", "N m", lambda j: j.torque)]
        return [(f"{what} {x}", unit, lambda j, w=what, k=k: getattr(j, w)[:, k])
                for what, unit in (("force", "N"), ("torque", "N m"))
                for k, x in enumerate("xyz")]
