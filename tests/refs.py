"""Independent references for the tests: closed-form kinematics with second-order Taylor
arithmetic (exact derivatives, no finite differences) and a hand-written Newton-Euler
free-body solve. Nothing here uses CasADi or the package's equations."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import cmm_dae as cd
from cmm_dae.description.library import four_bar_chain  # noqa: F401 - the tests' chain


class Jet:
    """Truncated Taylor number f + f1 e + f2 e^2 / 2 (value, first and second derivative)."""

    __slots__ = ("f", "d1", "d2")

    def __init__(self, f: float, d1: float = 0.0, d2: float = 0.0):
        self.f, self.d1, self.d2 = float(f), float(d1), float(d2)

    @staticmethod
    def _c(x) -> Jet:
        return x if isinstance(x, Jet) else Jet(x)

    def __add__(self, o):
        o = Jet._c(o)
        return Jet(self.f + o.f, self.d1 + o.d1, self.d2 + o.d2)

    __radd__ = __add__

    def __neg__(self):
        return Jet(-self.f, -self.d1, -self.d2)

    def __sub__(self, o):
        return self + (-Jet._c(o))

    def __rsub__(self, o):
        return Jet._c(o) - self

    def __mul__(self, o):
        o = Jet._c(o)
        return Jet(self.f * o.f, self.d1 * o.f + self.f * o.d1,
                   self.d2 * o.f + 2 * self.d1 * o.d1 + self.f * o.d2)

    __rmul__ = __mul__

    def __truediv__(self, o):
        return self * Jet._c(o).inv()

    def __rtruediv__(self, o):
        return Jet._c(o) * self.inv()

    def inv(self):
        f = 1.0 / self.f
        return Jet(f, -self.d1 * f * f, (2 * self.d1**2 * f - self.d2) * f * f)

    def chain(self, g0, g1, g2):
        return Jet(g0, g1 * self.d1, g2 * self.d1**2 + g1 * self.d2)


def sin(x):
    return x.chain(math.sin(x.f), math.cos(x.f), -math.sin(x.f)) if isinstance(x, Jet) \
        else math.sin(x)


def cos(x):
    return x.chain(math.cos(x.f), -math.sin(x.f), -math.cos(x.f)) if isinstance(x, Jet) \
        else math.cos(x)


def sqrt(x):
    s = math.sqrt(x.f)
    return x.chain(s, 0.5 / s, -0.25 / s**3)


@dataclass
class BodyKin:
    """Centroid position/velocity/acceleration and angle/rate/acceleration at one instant."""

    r: np.ndarray
    v: np.ndarray
    a: np.ndarray
    th: float
    om: float
    al: float


def body_kin(x: Jet, y: Jet, c: Jet, s: Jet, theta: float, rate: float, *,
             th_value: float | None = None) -> BodyKin:
    """From jets in the crank angle (x, y of the centroid; cos, sin of the body angle) to
    time derivatives for a crank turning at constant ``rate`` (rad/s)."""
    om = c.f * s.d1 - s.f * c.d1
    al = c.f * s.d2 - s.f * c.d2
    th = th_value if th_value is not None else math.atan2(s.f, c.f)
    return BodyKin(np.array([x.f, y.f]), rate * np.array([x.d1, y.d1]),
                   rate**2 * np.array([x.d2, y.d2]), th, rate * om, rate**2 * al)


def cross(a, b) -> float:
    return a[0] * b[1] - a[1] * b[0]


def newton_euler(bodies: dict[str, dict], joints: list[dict], drivers: list[dict],
                 gravity=(0.0, -9.81)) -> dict[str, np.ndarray]:
    """Solve the free-body equations of all bodies for the joint forces and driver efforts.

    bodies: name -> {m, J, kin: BodyKin}; joints: {name, first, second, point (global,
    where the force of first on second acts), type} - each revolute joint has 2 unknowns
    (force of first on second), each prismatic 2 (normal force component along ``normal``
    and a moment); drivers: {joint, first, second} with one unknown (torque on second).
    Applied extra generalized forces: bodies[name]['extra'] = (Fx, Fy, Mz about centroid).
    Returns name -> unknowns.
    """
    names = list(bodies)
    idx = {n: i for i, n in enumerate(names)}
    cols: list[tuple[str, int]] = []
    for j in joints:
        cols += [(j["name"], 0), (j["name"], 1)]
    for d in drivers:
        cols.append(("driver " + d["joint"], 0))
    A = np.zeros((3 * len(names), len(cols)))
    b = np.zeros(3 * len(names))
    for n, bd in bodies.items():
        k = bd["kin"]
        i = 3 * idx[n]
        ext = bd.get("extra", (0.0, 0.0, 0.0))
        b[i:i + 2] = bd["m"] * k.a - bd["m"] * np.array(gravity) - np.array(ext[:2])
        b[i + 2] = bd["J"] * k.al - ext[2]
    for col, (jn, comp) in enumerate(cols):
        if jn.startswith("driver "):
            d = next(x for x in drivers if x["joint"] == jn[7:])
            for body, sign in ((d["second"], 1.0), (d["first"], -1.0)):
                if body in idx:
                    A[3 * idx[body] + 2, col] += sign
            continue
        j = next(x for x in joints if x["name"] == jn)
        if j["type"] == "revolute":
            F = np.eye(2)[comp]
            M = 0.0
        else:  # prismatic: comp 0 = force along the normal, comp 1 = moment
            F = np.asarray(j["normal"]) if comp == 0 else np.zeros(2)
            M = 0.0 if comp == 0 else 1.0
        for body, sign in ((j["second"], 1.0), (j["first"], -1.0)):
            if body not in idx:
                continue
            i = 3 * idx[body]
            A[i:i + 2, col] += sign * F
            A[i + 2, col] += sign * (cross(j["point"] - bodies[body]["kin"].r, F) + M)
    x = np.linalg.solve(A, b)
    out: dict[str, np.ndarray] = {}
    for (jn, _), val in zip(cols, x, strict=True):
        out.setdefault(jn, [])
        out[jn].append(val)
    return {k: np.array(v) for k, v in out.items()}


def short_coupler_four_bar(tmp_path, ground: float):
    """models/four_bar.toml with a 0.09 m coupler and the ground pivot D at ``ground`` m:
    0.15 is a change-point linkage (s + l = p + q), 0.16 cannot turn its crank fully."""
    from pathlib import Path

    import cmm_dae as cd

    models = Path(__file__).resolve().parent.parent / "models"
    text = (models / "four_bar.toml").read_text().replace("D = [0.12, 0.0]",
                                                          f"D = [{ground}, 0.0]")
    text = text.replace("C = [0.12, 0.0] }", "C = [0.09, 0.0] }").replace(
        "guess = [0.0216, 0.0337, 0.586]", "guess = [0.0216, 0.0337, 0.3]").replace(
        "guess = [0.12, 0.0, 1.555]", f"guess = [{ground}, 0.0, 1.9]")
    path = tmp_path / "toggle.toml"
    path.write_text(text)
    return cd.load(path)




def for_method(method: str, **options) -> dict:
    """The run options that apply to ``method``, from a set written for both (simulate
    refuses the other method's by name)."""
    from cmm_dae.simulation.options import IDA_DEFAULTS, ITERATIVE_DEFAULTS

    drop = ITERATIVE_DEFAULTS if method == "ida" else IDA_DEFAULTS
    return {k: v for k, v in options.items() if k not in drop}


def gear_pair(ratio: float = -0.5) -> cd.Mechanism:
    """Two gears on ground axles 0.09 m apart (an external mesh at -0.5), a motor of 2 N m
    on A and a brake of -1 N m on B."""
    return cd.Mechanism(
        "gears", ground={"A": (0.0, 0.0), "B": (0.09, 0.0)},
        bodies=[cd.Body("ga", 0.2, 1e-4, points={"O": (0, 0)}),
                cd.Body("gb", 0.8, 2e-3, points={"O": (0, 0)})],
        joints=[cd.Joint("A", "revolute", "ground.A", "ga.O"),
                cd.Joint("B", "revolute", "ground.B", "gb.O")],
        gears=[cd.Gear("Z", "A", "B", ratio=ratio)],
        initial=cd.Initial(joints={"A": 0.0}),
        loads=[cd.Load("motor", cd.Law(value=2.0), joint="A"),
               cd.Load("brake", cd.Law(value=-1.0), joint="B")])


def spline_cam(w: float = 30.0, follower_mass: float = 0.2) -> cd.Mechanism:
    """A cam whose profile is a closed spline through 48 points of r = 30 + 6 cos(phi) +
    2 sin(3 phi) mm about its pivot, turning at ``w`` rad/s under a knife-edge follower on
    the vertical through the pivot (no spring: it flies between landings)."""
    phi = np.linspace(0.0, 2 * math.pi, 48, endpoint=False)
    r = 0.030 + 0.006 * np.cos(phi) + 0.002 * np.sin(3 * phi)
    pts = tuple(zip(r * np.cos(phi), r * np.sin(phi), strict=True))
    return cd.Mechanism(
        "spline cam", ground={"O": (0.0, 0.0)},
        bodies=[cd.Body("cam", 1.0, 1e-3, points={"O": (0, 0)}),
                cd.Body("follower", follower_mass, 1e-4, points={"tip": (0.0, 0.0)},
                        guess=(0.0, 0.04, 0.0))],
        joints=[cd.Joint("A", "revolute", "ground.O", "cam.O"),
                cd.Joint("F", "prismatic", "ground.O", "follower.tip", axis=(0.0, 1.0)),
                cd.Joint("K", "contact", "cam.O", "follower.tip", unilateral=True,
                         curve=cd.Curve("spline", points=pts))],
        drivers=[cd.Driver("A", speed=w)],
        initial=cd.Initial(joints={"K": 0.0}, velocities={"K": 0.0}))
