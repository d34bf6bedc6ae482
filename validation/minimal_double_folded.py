"""A hand-written minimal-coordinate model of the double-folded mechanism, integrated with
scipy's solve_ivp (DOP853) with events: the alternative a user would pick.

Its own derivation, sharing nothing with cmm_dae but the parameters of
models/double_folded.toml (read through cd.load). Coordinates: the crank angle theta1(t) is
prescribed; the slider position x is the one free coordinate while E is open. The loop
B + L2 e(theta2) + L3 e(theta3) = D = (x, y_d) gives theta2, theta3 by a circle intersection,
their rates and accelerations by 2x2 linear solves. Kane's equation in x gives x''; Kane's
equation in theta1 gives the driving torque; with E on its stop (x fixed, 0 DOF) the
x-equation gives the stop force, whose sign change (found by brentq) releases it.

Run: python validation/minimal_double_folded.py   (self-check against run_dae)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import cmm_dae as cd

ROOT = Path(__file__).resolve().parent.parent


@dataclass
class Params:
    L1: float
    L2: float
    L3: float
    y_d: float
    m: tuple  # crank, coupler, link3, slider
    J: tuple  # centroidal
    g: float
    c1: float  # crank centroid distance from A
    c2: float  # coupler centroid distance from B
    c3: tuple  # link3 centroid in its frame (from C, x along C->D)
    k: float
    rest: float
    damp: float
    th0: float
    w: float
    upper: float
    x0: float


def params_from(mech: cd.Mechanism) -> Params:
    b, j = mech.bodies, mech.joints
    d = mech.drivers["A"]
    return Params(
        L1=b["crank"].points["B"][0], L2=b["coupler"].points["C"][0],
        L3=b["link3"].points["D"][0],
        y_d=mech.ground["rail"][1] + b["slider"].points["D"][1],
        m=tuple(b[n].mass for n in ("crank", "coupler", "link3", "slider")),
        J=tuple(b[n].inertia for n in ("crank", "coupler", "link3", "slider")),
        g=-mech.gravity[1], c1=b["crank"].centroid[0], c2=b["coupler"].centroid[0],
        c3=b["link3"].centroid, k=j["D"].spring.stiffness, rest=j["D"].spring.rest,
        damp=j["D"].damper.damping, th0=d.initial, w=d.speed, upper=j["E"].limits.upper,
        x0=mech.initial.joints["E"])


class Minimal:
    """Kinematics and dynamics in the minimal coordinate x."""

    def __init__(self, p: Params):
        self.p = p

    def angles(self, th1: float, x: float) -> tuple[float, float]:
        """theta2, theta3 of the branch the mechanism starts in (C above the line B-D)."""
        p = self.p
        Bx, By = p.L1 * math.cos(th1), p.L1 * math.sin(th1)
        dx, dy = x - Bx, p.y_d - By
        L = math.hypot(dx, dy)
        a = (p.L2**2 - p.L3**2 + L * L) / (2 * L)
        h = math.sqrt(max(p.L2**2 - a * a, 0.0))
        ex, ey = dx / L, dy / L
        Cx, Cy = Bx + a * ex - h * ey, By + a * ey + h * ex
        return math.atan2(Cy - By, Cx - Bx), math.atan2(p.y_d - Cy, x - Cx)

    def kin(self, t: float, x: float, xd: float):
        """Positions, and accelerations as (constant part, coefficient of x'') of the
        centroids; angular rates and accelerations likewise; partial velocities."""
        p = self.p
        th1 = p.th0 + p.w * t
        w1 = p.w
        th2, th3 = self.angles(th1, x)
        e = lambda a: np.array([math.cos(a), math.sin(a)])  # noqa: E731
        n = lambda a: np.array([-math.sin(a), math.cos(a)])  # noqa: E731
        # velocity closure: L2 n2 w2 + L3 n3 w3 = (xd, 0) - L1 n1 w1
        Amat = np.column_stack([p.L2 * n(th2), p.L3 * n(th3)])
        Ainv = np.linalg.inv(Amat)
        # partial rates: d(w2, w3)/d(xd) and d(w2, w3)/d(w1)
        Wx = Ainv @ np.array([1.0, 0.0])
        W1 = Ainv @ (-p.L1 * n(th1))
        w2, w3 = Wx * xd + W1 * w1
        # accelerations: L2 n2 al2 + L3 n3 al3 = (xdd, 0) - B'' + L2 e2 w2^2 + L3 e3 w3^2
        Bdd = -p.L1 * e(th1) * w1**2
        rhs0 = -Bdd + p.L2 * e(th2) * w2**2 + p.L3 * e(th3) * w3**2
        Al0 = Ainv @ rhs0  # constant part of (al2, al3); the x'' part is Wx
        # centroids
        rc3 = np.array(p.c3)
        R3 = np.array([[math.cos(th3), -math.sin(th3)], [math.sin(th3), math.cos(th3)]])
        B = p.L1 * e(th1)
        C = B + p.L2 * e(th2)
        G1, G2, G3 = p.c1 * e(th1), B + p.c2 * e(th2), C + R3 @ rc3
        # velocities of the centroids: linear in (xd, w1)
        d3 = R3 @ rc3
        perp = lambda r: np.array([-r[1], r[0]])  # noqa: E731
        # partial velocities wrt xd (Vx) and wrt w1 (V1), for crank, coupler, link3, slider
        Vx = [np.zeros(2), p.c2 * n(th2) * Wx[0],
              p.L2 * n(th2) * Wx[0] + perp(d3) * Wx[1], np.array([1.0, 0.0])]
        V1 = [p.c1 * n(th1), p.L1 * n(th1) + p.c2 * n(th2) * W1[0],
              p.L1 * n(th1) + p.L2 * n(th2) * W1[0] + perp(d3) * W1[1], np.zeros(2)]
        Ox = [0.0, Wx[0], Wx[1], 0.0]
        O1 = [1.0, W1[0], W1[1], 0.0]
        # accelerations (constant part a0, al0; the x'' part is Vx, Ox)
        a0 = [-p.c1 * e(th1) * w1**2,
              Bdd + p.c2 * (n(th2) * Al0[0] - e(th2) * w2**2),
              Bdd + p.L2 * (n(th2) * Al0[0] - e(th2) * w2**2)
              + perp(d3) * Al0[1] - d3 * w3**2,
              np.zeros(2)]
        al0 = [0.0, Al0[0], Al0[1], 0.0]
        return dict(th=(th1, th2, th3), w=(w1, w2, w3), G=(G1, G2, G3), Vx=Vx, V1=V1, Ox=Ox,
                    O1=O1, a0=a0, al0=al0)

    def forces(self, k: dict) -> tuple[list[np.ndarray], list[float]]:
        """Applied forces (gravity) and torques (spring-damper at D) on each body."""
        p = self.p
        F = [np.array([0.0, -m * p.g]) for m in p.m]
        _, _, th3 = k["th"]
        _, _, w3 = k["w"]
        cD, cDd = -th3, -w3  # joint D coordinate theta_slider - theta3, slider angle 0
        tau = p.k * (cD - p.rest) + p.damp * cDd  # on link 3 (the first body)
        return F, [0.0, 0.0, tau, -tau]

    def generalized(self, k: dict, V: list, O: list, xdd: float) -> float:
        """Kane: sum of inertia minus applied generalized forces for partial velocities
        (V, O), with the accelerations at x'' = xdd."""
        p = self.p
        F, M = self.forces(k)
        s = 0.0
        for i in range(4):
            a = k["a0"][i] + k["Vx"][i] * xdd
            al = k["al0"][i] + k["Ox"][i] * xdd
            s += p.m[i] * V[i] @ a + p.J[i] * O[i] * al - F[i] @ V[i] - M[i] * O[i]
        return s

    def xdd(self, t: float, x: float, xd: float) -> float:
        k = self.kin(t, x, xd)
        r0 = self.generalized(k, k["Vx"], k["Ox"], 0.0)
        r1 = self.generalized(k, k["Vx"], k["Ox"], 1.0) - r0
        return -r0 / r1

    def torque(self, t: float, x: float, xd: float, xdd: float) -> float:
        k = self.kin(t, x, xd)
        return self.generalized(k, k["V1"], k["O1"], xdd)

    def stop_force(self, t: float) -> float:
        """Generalized force the stop applies in +x to hold the slider at x = upper."""
        k = self.kin(t, self.p.upper, 0.0)
        return self.generalized(k, k["Vx"], k["Ox"], 0.0)


def simulate(mech: cd.Mechanism, t_end: float = 10.0, rtol: float = 1e-8,
             t_eval: np.ndarray | None = None) -> dict:
    """Run the minimal model; returns t, x, driving torque and the switching times."""
    p = params_from(mech)
    mm = Minimal(p)
    t_eval = np.arange(0.0, t_end + 1e-9, 0.01) if t_eval is None else t_eval

    def rhs(t, y):
        return [y[1], mm.xdd(t, y[0], y[1])]

    T, X, XD, switches = [], [], [], []
    # [initial] velocities: the rate at D is zero, theta3' = 0 (links 3 and 4 move together)
    k0 = mm.kin(0.0, p.x0, 0.0)
    w3_x = mm.kin(0.0, p.x0, 1.0)["w"][2] - k0["w"][2]
    t0, y0 = 0.0, [p.x0, -k0["w"][2] / w3_x]
    while t0 < t_end:

        def hit(t, y):
            # only an approach counts: just after a release x'' = 0 and round-off in
            # upper - x would read as a new arrival while the slider leaves
            return p.upper - y[0] if y[1] >= 0.0 else 1.0

        hit.terminal, hit.direction = True, -1
        te = t_eval[(t_eval > t0) & (t_eval <= t_end)]
        # after a release x'' = 0 at t0, which fools the automatic first step: give one
        sol = solve_ivp(rhs, (t0, t_end), y0, method="DOP853", rtol=rtol, atol=rtol * 1e-2,
                        events=hit, t_eval=te, first_step=1e-6 if t0 > 0 else None)
        T += list(sol.t)
        X += list(sol.y[0])
        XD += list(sol.y[1])
        if sol.status != 1:
            break
        t_hit = float(sol.t_events[0][0])
        switches.append(("limit", t_hit))
        # held on the stop (0 DOF): the stop force pushes in -x while it is negative
        f = mm.stop_force
        grid = np.linspace(t_hit, t_end, 2001)
        t_rel, prev = None, f(grid[0])
        for a, b in zip(grid[:-1], grid[1:], strict=True):  # scan to the first sign change
            cur = f(b)
            if prev < 0 <= cur:
                t_rel = brentq(f, a, b, xtol=1e-13)
                break
            prev = cur
        pos = np.array([0]) if t_rel is not None else np.array([], int)
        t_rel = t_end if t_rel is None else t_rel
        held = te[(te > t_hit) & (te <= t_rel)]
        T += list(held)
        X += [p.upper] * held.size
        XD += [0.0] * held.size
        if not pos.size:
            break
        switches.append(("release", t_rel))
        t0, y0 = t_rel, [p.upper, 0.0]
    T, X, XD = np.array(T), np.array(X), np.array(XD)
    held = np.isclose(X, p.upper, atol=0.0, rtol=0.0) & (XD == 0.0)
    tau = np.array([mm.torque(t, x, xd, 0.0 if h else mm.xdd(t, x, xd))
                    for t, x, xd, h in zip(T, X, XD, held, strict=True)])
    return {"t": T, "x": X, "torque": tau, "switches": switches}


def main() -> None:
    import time

    mech = cd.load(ROOT / "models" / "double_folded.toml")
    ref = cd.run_dae(mech, 10.0, rtol=1e-12, atol=1e-14, output_dt=0.01)
    w0 = time.perf_counter()
    out = simulate(mech, 10.0, rtol=1e-10)
    wall = time.perf_counter() - w0
    tau_ref = ref.resample(out["t"], ref.driver("A").effort)
    far = np.ones(out["t"].size, bool)
    for e in ref.events:
        far &= np.abs(out["t"] - e.t) > 0.02
    print(f"minimal model (DOP853 rtol 1e-10): {wall * 1e3:.1f} ms")
    print("switches:", [(k, round(t, 9)) for k, t in out["switches"]])
    print("run_dae (rtol 1e-12):", [(e.kind, round(e.t, 9)) for e in ref.events])
    print(f"max |torque - run_dae| away from switches: "
          f"{np.max(np.abs(out['torque'] - tau_ref)[far]):.3e} N m")


if __name__ == "__main__":
    main()
