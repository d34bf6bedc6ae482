"""Independent references for the spatial examples: the spherical pendulum's
minimal-coordinate equations, and the closed-form input-output relations of the Bennett
linkage, the RSUR four-bar and the spherical four-bar a carton fold becomes when its flap
locks. Nothing here uses the package's equations (numpy and scipy alone); the numbers are
the shipped files'."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

G = 9.81


def pendulum(mass: float, inertia: float, t: np.ndarray, length: float = 0.5
             ) -> tuple[np.ndarray, np.ndarray]:
    """The spherical pendulum of ``spherical_pendulum.toml``: its centroid (n, 3) and the
    centroid's acceleration (n, 3) at ``t``, from the equations in (theta from the downward
    vertical, phi) with the pivot inertia I0 + m L^2 (the bob's centroidal inertia I0 is
    isotropic and it does not spin about the rod, so the spin stays 0; DOP853 at rtol
    1e-13). Start: tilted by atan(3/4) about x, swinging at 3 rad/s across the rod."""
    k = mass * G * length / (inertia + mass * length**2)

    def rhs(_, y):
        th, ph, thd, phd = y
        return [thd, phd, np.sin(th) * np.cos(th) * phd**2 - k * np.sin(th),
                -2.0 * np.cos(th) / np.sin(th) * thd * phd]

    a = np.arctan2(0.6, 0.8)
    sol = solve_ivp(rhs, (0.0, t[-1]), [a, np.pi / 2, 0.0, 3.0 / np.sin(a)], t_eval=t,
                    rtol=1e-13, atol=1e-13, method="DOP853")
    th, ph, thd, phd = sol.y
    thdd, phdd = np.array([rhs(0.0, y)[2:] for y in sol.y.T]).T
    s, c, sp, cp = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    u = np.column_stack([s * cp, s * sp, -c])
    # u'' from (theta, phi), their rates and accelerations, by the chain rule
    udd = np.column_stack([
        -s * cp * (thd**2 + phd**2) + c * cp * thdd - s * sp * phdd - 2 * c * sp * thd * phd,
        -s * sp * (thd**2 + phd**2) + c * sp * thdd + s * cp * phdd + 2 * c * cp * thd * phd,
        c * thd**2 + s * thdd])
    return length * u, length * udd


def bennett(th1: np.ndarray, th2: np.ndarray, alpha: float = np.pi / 6,
            beta: float = np.pi / 3) -> np.ndarray:
    """The residual of tan(th1/2) tan(th2/2) = sin((beta+alpha)/2) / sin((beta-alpha)/2)
    (Bennett 1903), written without the tangents' poles."""
    K = np.sin((beta + alpha) / 2) / np.sin((beta - alpha) / 2)
    return np.sin(th1 / 2) * np.sin(th2 / 2) - K * np.cos(th1 / 2) * np.cos(th2 / 2)


def nearest_root(a: float, b: float, c: float, near: float) -> float:
    """The root of ``a cos x + b sin x = c`` nearest ``near`` (rad): the branch a run
    follows (the two are far apart away from the mechanism's singular positions)."""
    base, dl = np.arctan2(b, a), np.arccos(c / np.hypot(a, b))
    d = np.angle(np.exp(1j * (np.array([base + dl, base - dl]) - near)))
    return near + d[np.argmin(np.abs(d))]


def rsur(th: np.ndarray, near: np.ndarray) -> np.ndarray:
    """The rocker angle of ``rsur_four_bar.toml`` from the crank angle: |B(th) - C(ph)| =
    |BC| with B on the crank's circle (0.03 m about z) and C on the rocker's (0.08 m
    about x through D = (0.1, 0, 0.06), the angle from y)."""
    r1, r3, L, D = 0.03, 0.08, 0.14520499232974682, np.array([0.1, 0.0, 0.06])
    e = np.column_stack([r1 * np.cos(th), r1 * np.sin(th), 0 * th]) - D
    a, b = 2 * r3 * e[:, 1], 2 * r3 * e[:, 2]
    c = (e * e).sum(axis=1) + r3**2 - L**2
    return np.array([nearest_root(*x) for x in zip(a, b, c, near, strict=True)])


def rot_y(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def carton_locked(th: np.ndarray, near: np.ndarray, stop: float = 0.3) -> np.ndarray:
    """The output crease D of ``carton_fold.toml`` from the driven crease A while the flap
    crease E is locked at ``stop``: the spherical four-bar whose coupler arc is the flap's
    (35 deg) and the coupler panel's (45 deg) folded at the stop, between the input panel
    (40 deg), the output panel (60 deg) and the ground's creases 70 deg apart."""
    a1, b1, b2, a3, a4 = np.deg2rad([40, 35, 45, 60, 70])
    z = np.array([0.0, 0.0, 1.0])
    cos_arc = z @ rot_y(b1) @ rot_z(stop) @ rot_y(b2) @ z
    u4, w0 = rot_y(a4) @ z, rot_y(a4) @ rot_y(a3) @ z  # the output crease; its end at 0
    out = []
    for t, p in zip(th, near, strict=True):
        u2 = rot_z(t) @ rot_y(a1) @ z
        out.append(nearest_root(u2 @ (w0 - u4 * (u4 @ w0)), u2 @ np.cross(u4, w0),
                                cos_arc - (u2 @ u4) * (u4 @ w0), p))
    return np.array(out)


def collar_bounces(n: int, s0: float = 0.1, v0: float = -0.5, stop: float = 0.05,
                   e: float = 0.5, k: float = 200.0, m: float = 0.5, rest: float = 0.1
                   ) -> list[tuple[float, float]]:
    """The first ``n`` impacts (time s, speed before m/s) of ``collar_on_shaft.toml``'s
    slide: between impacts the harmonic oscillation about the spring's equilibrium under
    gravity, in closed form, its arrival at the stop found by brentq; each impact sends it
    back at e times its speed."""
    from scipy.optimize import brentq

    w, eq = (k / m) ** 0.5, rest - m * G / k
    out, t, s, v = [], 0.0, s0, v0
    for _ in range(n):
        def pos(tau, s=s, v=v):
            return eq + (s - eq) * np.cos(w * tau) + v / w * np.sin(w * tau) - stop
        taus = np.linspace(1e-9, 2 * np.pi / w, 2001)
        f = pos(taus)
        i = int(np.flatnonzero((f[:-1] > 0) & (f[1:] <= 0))[0])
        tau = brentq(pos, taus[i], taus[i + 1], xtol=1e-15, rtol=1e-15)
        vin = -(s - eq) * w * np.sin(w * tau) + v * np.cos(w * tau)
        t, s, v = t + tau, stop, -e * vin
        out.append((t, vin))
    return out
