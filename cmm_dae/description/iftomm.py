"""The IFToMM planar benchmark problems A01 and A02, with their independent references.

The IFToMM library of computational benchmark problems for multibody simulators states:

* **A01, simple pendulum**: a 1 kg point mass on a massless 1 m rod, released from the
  horizontal at rest, g = 9.81 m/s^2 along -y, 2000 s; the mass's position is asked within
  1e-3 m.
* **A02, N four-bar mechanism**: 2N + 1 uniform rods of 1 m and 1 kg, N + 1 cranks pinned to
  the ground at x = 0, 1, ..., N and N couplers joining their tips; at t = 0 the cranks
  are vertical and the couplers horizontal on top, the first crank's tip moving at +1 m/s
  along x; g = 9.81 along -y; 20 s. One degree of freedom; at every horizontal crank
  position all rods lie on one line and the mobility jumps from 1 to N + 1 (the
  parallelogram meets its anti-parallelogram branches).

The references are derived here independently of the simulator: A01's exact solution in
Jacobi elliptic functions, and A02's one-degree-of-freedom reduction on the parallelogram
branch (every crank turns by the same angle, the couplers translate), integrated by SciPy.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.scipy_late import ellipj, ellipk, solve_ivp
from .mechanism import Body, Initial, Joint, Mechanism

G = 9.81
#: Length (m), mass (kg) and centroidal inertia (kg m^2) of every A02 rod.
ROD_L, ROD_M = 1.0, 1.0
ROD_I = ROD_M * ROD_L**2 / 12.0


def a01_pendulum() -> Mechanism:
    """A01: the point mass (inertia 0) on a massless rod pinned at the origin; the body's
    frame sits at the pivot, its centroid (the mass) 1 m along its x axis."""
    bob = Body("bob", 1.0, 0.0, (1.0, 0.0), {"O": (0.0, 0.0), "mass": (1.0, 0.0)},
               guess=(0.0, 0.0, 0.0))
    pivot = Joint("O", "revolute", "ground.O", "bob.O")
    return Mechanism("IFToMM A01: simple pendulum", [bob], [pivot], ground={"O": (0.0, 0.0)},
                     gravity=(0.0, -G), initial=Initial({"O": 0.0}, {"O": 0.0}))


def a01_reference(t: np.ndarray) -> np.ndarray:
    """Exact A01 position of the mass, (n, 2) m: released at rest from the horizontal,
    amplitude pi/2 about the bottom, so sin(phi/2) = k sn(K - sqrt(g) t, k), k = sin(pi/4),
    with phi the angle from the bottom."""
    t = np.asarray(t, float)
    k = math.sin(math.pi / 4)
    sn = ellipj(ellipk(k**2) - math.sqrt(G / 1.0) * t, k**2)[0]
    ang = -math.pi / 2 + 2 * np.arcsin(k * sn)  # from the +x axis
    return np.column_stack([np.cos(ang), np.sin(ang)])


def a02_four_bar(n: int) -> Mechanism:
    """A02 with ``n`` four-bar loops: cranks ``crank0`` .. ``crank{n}`` on ground pivots
    ``O0`` .. ``O{n}`` (joints ``G0`` ..), couplers ``coupler1`` .. ``coupler{n}`` joined
    to the crank tips by joints ``L1`` .. and ``R1`` ..; each body's frame at its first
    point, along the rod."""
    if not (isinstance(n, int) and n >= 1):
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    half = math.pi / 2
    bodies, joints, ground = [], [], {}
    for i in range(n + 1):
        ground[f"O{i}"] = (float(i), 0.0)
        bodies.append(Body(f"crank{i}", ROD_M, ROD_I, (0.5, 0.0),
                           {"O": (0.0, 0.0), "P": (1.0, 0.0)}, guess=(float(i), 0.0, half)))
        joints.append(Joint(f"G{i}", "revolute", f"ground.O{i}", f"crank{i}.O"))
    for i in range(1, n + 1):
        bodies.append(Body(f"coupler{i}", ROD_M, ROD_I, (0.5, 0.0),
                           {"L": (0.0, 0.0), "R": (1.0, 0.0)}, guess=(i - 1.0, 1.0, 0.0)))
        joints.append(Joint(f"L{i}", "revolute", f"crank{i - 1}.P", f"coupler{i}.L"))
        joints.append(Joint(f"R{i}", "revolute", f"crank{i}.P", f"coupler{i}.R"))
    # the first crank's tip at +1 m/s along x: the crank turns clockwise at 1 rad/s
    return Mechanism(f"IFToMM A02: four-bar mechanism, N = {n}", bodies, joints,
                     ground=ground, gravity=(0.0, -G),
                     initial=Initial({"G0": half}, {"G0": -1.0}))


def a02_reference(n: int, t: np.ndarray, rtol: float = 1e-13) -> np.ndarray:
    """Position of the first crank's tip, (n_t, 2) m, on the parallelogram branch.

    Every crank turns by the same angle theta and the couplers translate, so with rods of
    length L and mass m the kinetic energy is ``(n + 1) m L^2 / 6 theta'^2 + n m L^2 / 2
    theta'^2`` and the potential ``((n + 1) / 2 + n) m g L sin(theta)``: Lagrange's equation
    of this one coordinate, integrated by DOP853."""
    t = np.asarray(t, float)
    inertia = (n + 1) * ROD_M * ROD_L**2 / 3.0 + n * ROD_M * ROD_L**2
    weight = ((n + 1) / 2.0 + n) * ROD_M * G * ROD_L

    def rhs(_, y):
        return [y[1], -weight * math.cos(y[0]) / inertia]

    grid, back = np.unique(t, return_inverse=True)  # a Result repeats event times
    sol = solve_ivp(rhs, (0.0, float(grid.max(initial=0.0))), [math.pi / 2, -1.0 / ROD_L],
                    t_eval=grid, rtol=rtol, atol=1e-14, method="DOP853")
    ang = sol.y[0][back]
    return ROD_L * np.column_stack([np.cos(ang), np.sin(ang)])


def a02_energy(n: int) -> float:
    """A02's constant total energy (kinetic + potential, zero at the ground line), J."""
    inertia = (n + 1) * ROD_M * ROD_L**2 / 3.0 + n * ROD_M * ROD_L**2
    weight = ((n + 1) / 2.0 + n) * ROD_M * G * ROD_L
    return 0.5 * inertia * 1.0**2 + weight


def crank_tip(res, crank: str = "crank0") -> np.ndarray:
    """The A02 reference point (tip of a crank) from a Result, (n, 2) m."""
    P = res.body(crank).pose
    return P[:, :2] + ROD_L * np.column_stack([np.cos(P[:, 2]), np.sin(P[:, 2])])
