"""The geometry and constraint rows of a spatial mechanism, in natural coordinates.

Each body is carried by 12 coordinates: its centroid ``r`` and its three principal axes
of inertia ``e1, e2, e3`` as vectors in global axes, tied by six rows of its own (unit
lengths, right angles). A point of the body is then ``r + E X`` (``E = [e1 e2 e3]``,
``X`` the point's principal coordinates): every position is *linear* in the coordinates,
no rotation is parametrised (so no pose is singular, as a gimbal lock is for angles and
the norm's sign for Euler parameters), and the kinetic energy is
``m |r'|^2 / 2 + sum_k J_k |e_k'|^2 / 2`` with ``J_k = (I1 + I2 + I3) / 2 - I_k``: the mass
matrix is constant and diagonal, as the planar model's is, so the equations, the KKT
solves, the impacts, the compiled segment and the fixed-step algorithm serve both spaces
unchanged. A planar body's ``(x, y, theta)`` is the same idea with one angle.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..description.mechanism import GROUND
from ..description.spatial import centre, principal, rotation

__all__ = ["NQ", "Geometry", "body_rows", "initial_guess", "joint_rows", "mass",
           "velocity_guess"]

#: coordinates of a spatial body: centroid (3) and three principal axes (3 x 3)
NQ = 12


def _perp(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors across the unit vector ``a``, and across each other."""
    t = np.eye(3)[int(np.argmin(np.abs(a)))]
    n1 = np.cross(a, t)
    n1 /= np.linalg.norm(n1)
    return n1, np.cross(a, n1)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def mass(smech) -> list:
    """The diagonal of the mass matrix, 12 entries a body (kg, kg m^2): the mass three
    times, then each principal axis's second moment ``J_k`` three times."""
    out: list = []
    for b in smech.bodies.values():
        _, w = principal(b.inertia)
        half = (w[0] + w[1] + w[2]) / 2
        out += [b.mass] * 3
        for k in range(3):
            out += [half - w[k]] * 3
    return out


class Geometry:
    """Points, directions and rotations of a spatial mechanism's bodies in its
    coordinates ``q`` (CasADi), read from ``smech`` (whose numbers may be symbols)."""

    def __init__(self, mdl, smech, q) -> None:
        self._mdl, self._smech, self.q = mdl, smech, q
        #: each body's principal axes in its frame (numbers: from the mechanism's values)
        self.R = {n: principal(b.inertia)[0] for n, b in mdl.mech.bodies.items()}

    def axes(self, body: str):
        """The body's principal axes in global axes, columns (3 x 3)."""
        o = NQ * self._mdl.bidx[body]
        q = self.q
        return ca.horzcat(q[o + 3:o + 6], q[o + 6:o + 9], q[o + 9:o + 12])

    def r(self, body: str):
        o = NQ * self._mdl.bidx[body]
        return self.q[o:o + 3]

    def _local(self, body: str, x):
        """Body-frame vector ``x`` in principal coordinates."""
        R = self.R[body]
        x = ca.vertcat(*x)
        return x if np.array_equal(R, np.eye(3)) else ca.DM(R.T) @ x

    def point(self, ref: str):
        """Global position of ``"body.point"`` (3,)."""
        body, _ = ref.split(".", 1)
        x = self._smech.point(ref)
        if body == GROUND:
            return ca.vertcat(*x)
        c = self._smech.bodies[body].centroid
        return self.r(body) + self.axes(body) @ self._local(body, [x[i] - c[i] for i in range(3)])

    def direction(self, body: str, d) -> ca.SX:
        """A body-frame direction ``d`` (numbers) in global axes."""
        if body == GROUND:
            return ca.DM(np.asarray(d, float))
        return self.axes(body) @ self._local(body, [float(x) for x in d])

    def axis(self, ref: str) -> np.ndarray:
        """``"body.axis"`` in its body frame, normalised (numbers)."""
        return _unit(self._mdl.mech.axis(ref))


def body_rows(geo: Geometry, body: str) -> list:
    """The six rows that keep a body's axes unit and at right angles."""
    E = geo.axes(body)
    e = [E[:, k] for k in range(3)]
    return [(ca.dot(e[0], e[0]) - 1) / 2, (ca.dot(e[1], e[1]) - 1) / 2,
            (ca.dot(e[2], e[2]) - 1) / 2, ca.dot(e[0], e[1]), ca.dot(e[1], e[2]),
            ca.dot(e[0], e[2])]


def _frame(geo: Geometry, j, mech):
    """(a1, n1, n2, r1, r2) in global axes: the first body's axis, two directions across
    it, and each body's reference projected across its own axis (normalised)."""
    b1, b2 = j.first_body, j.second_body
    a1, a2 = geo.axis(j.axes[0]), geo.axis(j.axes[1])
    refs = j.reference if j.reference is not None else (f"{b1}.x", f"{b2}.x")
    out = []
    for ref, a in zip(refs, (a1, a2), strict=True):
        r = np.asarray(mech.axis(ref), float)
        out.append(_unit(r - (r @ a) * a))
    n1, n2 = _perp(a1)
    return (geo.direction(b1, a1), geo.direction(b1, n1), geo.direction(b1, n2),
            geo.direction(b2, a2), geo.direction(b1, out[0]), geo.direction(b2, out[1]))


def joint_rows(geo: Geometry, j, mech) -> tuple[ca.SX, list, tuple | None]:
    """A spatial joint's coordinate (0 without one), its rows, and for a revolute or
    cylindrical joint ``(s, c)``: the sine and cosine of its angle (its driver's row is
    written in them, so a driven joint may turn any number of times)."""
    d = geo.point(j.second) - geo.point(j.first)
    if j.type == "spherical":
        return ca.SX(0), [d[0], d[1], d[2]], None
    if j.type == "universal":
        u1 = geo.direction(j.first_body, geo.axis(j.axes[0]))
        u2 = geo.direction(j.second_body, geo.axis(j.axes[1]))
        return ca.SX(0), [d[0], d[1], d[2], ca.dot(u1, u2)], None
    a1, n1, n2, a2, r1, r2 = _frame(geo, j, mech)
    if j.type == "slide":  # a cylindrical joint's second coordinate: no row of its own
        return ca.dot(a1, d), [], None
    align = [ca.dot(a2, n1), ca.dot(a2, n2)]
    s, c = ca.dot(a1, ca.cross(r1, r2)), ca.dot(r1, r2)
    # the angle within pi of the joint's centre (the middle of its range: its stops never
    # lie at the cut, where the angle jumps by 2 pi)
    mid = centre(mech.joints[j.name])
    cm, sm = np.cos(mid), np.sin(mid)
    angle = mid + ca.atan2(s * cm - c * sm, c * cm + s * sm)
    if j.type == "revolute":
        return angle, [d[0], d[1], d[2], *align], (s, c)
    if j.type == "cylindrical":  # the second point on the first's axis, the axes aligned
        return angle, [ca.dot(d, n1), ca.dot(d, n2), *align], (s, c)
    # prismatic: the second point on the first's axis, the axes aligned, no roll
    return ca.dot(a1, d), [ca.dot(d, n1), ca.dot(d, n2), *align, s], None


def initial_guess(model) -> np.ndarray:
    """Natural coordinates from the bodies' guessed poses (the frame's origin and rotation
    vector; the identity pose at the origin where none is given)."""
    q = np.zeros(model.nq)
    for i, b in enumerate(model.mech.bodies.values()):
        g = b.guess if b.guess is not None else (0.0,) * 6
        Rg = rotation(g[3:6])
        E = Rg @ principal(b.inertia)[0]
        q[NQ * i:NQ * i + 3] = np.asarray(g[:3], float) + Rg @ np.asarray(b.centroid, float)
        q[NQ * i + 3:NQ * i + NQ] = E.T.reshape(-1)  # e1, e2, e3 one after the other
    return q


def velocity_guess(model, q: np.ndarray) -> np.ndarray:
    """Coordinate rates from the bodies' guessed velocities (the frame origin's, m/s, and
    the angular velocity omega, rad/s, global axes; zero where none is given) at the
    coordinates ``q``: r' = v_o + omega x (r - o), e_k' = omega x e_k."""
    v = np.zeros(model.nq)
    for i, b in enumerate(model.mech.bodies.values()):
        g = b.guess if b.guess is not None and len(b.guess) == 12 else (0.0,) * 12
        vo, om = np.asarray(g[6:9], float), np.asarray(g[9:12], float)
        blk = q[NQ * i:NQ * i + NQ]
        E = blk[3:].reshape(3, 3)  # rows e1, e2, e3
        X = principal(b.inertia)[0].T @ np.asarray(b.centroid, float)
        v[NQ * i:NQ * i + 3] = vo + np.cross(om, E.T @ X)  # (E.T X: the centroid from o)
        v[NQ * i + 3:NQ * i + NQ] = np.cross(om, E).reshape(-1)
    return v
