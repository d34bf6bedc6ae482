"""The geometry of a spline curve of a contact joint: its cubic pieces, its arc length and
its gap, written once for numbers and for CasADi expressions (the model's equations use
the same formulas as the checks and the drawings).

Two shapes, both in the first body's frame relative to the curve's origin point:

* closed: ``r(phi)``, the periodic cubic spline of the points' radii over their polar
  angles (a cam profile, a closed groove around its origin); the curve's parameter ``u``
  is the polar angle, its speed ``ds/du = sqrt(r^2 + r'^2)``;
* open: ``y(x)``, the cubic spline (not-a-knot) of the points' y over their x (a curved
  slot or guide along the body's x axis, x increasing from the first point to the last);
  ``u`` is x, its speed ``sqrt(1 + y'^2)``.

The arc length from the first point is a Gauss-Legendre quadrature of the speed over each
piece (:data:`GAUSS_NODES` nodes: the speed is smooth on a piece, so the rule is exact to
round-off there), the gap the point's offset from the curve divided by the norm of its
gradient on the curve (the radial or vertical offset over the speed): a distance to first
order, whose gradient on the curve is the unit normal, so that a gap row's multiplier is the
contact force (N).
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from ..core.scipy_late import cubic_spline

__all__ = ["GAUSS_NODES", "Spline", "polar_knots", "spline"]

#: Gauss-Legendre nodes per piece for the arc length.
GAUSS_NODES = 12
_X, _W = np.polynomial.legendre.leggauss(GAUSS_NODES)


def polar_knots(points) -> tuple[np.ndarray, np.ndarray]:
    """A closed curve's knots: the points' polar angles (increasing, from the first
    point's, spanning one turn; the first repeated a turn later) and radii (m)."""
    pts = np.asarray(points, float)
    ang = np.unwrap(np.arctan2(pts[:, 1], pts[:, 0]))
    rad = np.hypot(pts[:, 0], pts[:, 1])
    return np.append(ang, ang[0] + 2 * math.pi), np.append(rad, rad[0])


class Spline:
    """A spline curve's pieces (``knots`` in rad or m, cubic coefficients ``coef`` (4,
    pieces) as scipy's ``CubicSpline.c``) and the arc length at each knot from the first
    (``arc``, m).

    Parameters
    ----------
    points : sequence of (x, y)
        The points the curve passes through, m, relative to its origin.
    closed : bool
        A closed curve around the origin (polar) or an open one along x.
    """

    def __init__(self, points, closed: bool) -> None:
        pts = np.asarray(points, float)
        self.closed = closed
        if closed:
            self.knots, rad = polar_knots(pts)
            sp = cubic_spline(self.knots, rad, bc_type="periodic")
        else:
            self.knots = pts[:, 0].copy()
            sp = cubic_spline(self.knots, pts[:, 1])
        self.coef = sp.c
        widths = np.diff(self.knots)
        self.arc = np.concatenate([[0.0], np.cumsum(
            [self.piece_arc(i, h) for i, h in enumerate(widths)])])

    @property
    def length(self) -> float:
        """The curve's length (m): once around a closed one, end to end an open one."""
        return float(self.arc[-1])

    def piece(self, i: int, s: Any) -> tuple[Any, Any]:
        """The curve's value (r or y, m) and slope (dr/dphi m/rad, or dy/dx) at ``s``
        past knot ``i`` (numbers or CasADi)."""
        c = self.coef[:, i]
        val = ((c[0] * s + c[1]) * s + c[2]) * s + c[3]
        slope = (3 * c[0] * s + 2 * c[1]) * s + c[2]
        return val, slope

    def speed(self, val: Any, slope: Any) -> Any:
        """ds/du, the arc length per unit of the parameter (m/rad or m/m)."""
        return (val * val + slope * slope) ** 0.5 if self.closed else \
            (1 + slope * slope) ** 0.5

    def piece_arc(self, i: int, s: Any) -> Any:
        """Arc length (m) from knot ``i`` to ``s`` past it, by Gauss-Legendre quadrature."""
        total = 0
        for x, w in zip(_X, _W, strict=True):
            total = total + w * self.speed(*self.piece(i, 0.5 * s * (1 + x)))
        return 0.5 * s * total

    def locate(self, u: float) -> int:
        """The piece holding parameter ``u`` (a number), clamped to the first or last."""
        return int(np.clip(np.searchsorted(self.knots, u, side="right") - 1, 0,
                           self.knots.size - 2))

    def sample(self, n: int = 200) -> np.ndarray:
        """Points along the curve (n, 2), m, in its frame relative to its origin (a closed
        one closed again), for drawings."""
        u = np.linspace(self.knots[0], self.knots[-1], n)
        val = np.array([self.piece(self.locate(x), x - self.knots[self.locate(x)])[0]
                        for x in u])
        if self.closed:
            return np.column_stack([val * np.cos(u), val * np.sin(u)])
        return np.column_stack([u, val])


def spline(curve: Any) -> Spline:
    """The :class:`Spline` of a ``Curve`` of kind "spline" (built once per shape)."""
    return _spline(tuple(curve.points), bool(curve.closed))


@functools.lru_cache(maxsize=64)
def _spline(points: tuple, closed: bool) -> Spline:
    return Spline(points, closed)
