"""Core checks of run_dae against independent references (issue: core).

Slider-crank and four-bar: driving torque against d(T+V)/dtheta along the closed-form
kinematic solution, and every joint reaction against a hand-written Newton-Euler free-body
solve. Crank + swinging link: against a minimal-coordinate model integrated by DOP853.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import simpson, solve_ivp

import cmm_dae as cd

from refs import Jet, body_kin, cos, newton_euler, sin, sqrt

MODELS = Path(__file__).resolve().parent.parent / "models"
G = 9.81
RTOL = 1e-10  # solver tolerance used in these checks (positions and velocities atol 1e-12)


@pytest.fixture(scope="module")
def slider_crank():
    mech = cd.load(MODELS / "slider_crank.toml")
    return mech, cd.run_dae(mech, 2.0, rtol=RTOL, atol=1e-12, output_dt=0.005)


@pytest.fixture(scope="module")
def four_bar():
    mech = cd.load(MODELS / "four_bar.toml")
    return mech, cd.run_dae(mech, 2.0, rtol=RTOL, atol=1e-12, output_dt=0.005)


@pytest.fixture(scope="module")
def crank_pendulum():
    mech = cd.load(MODELS / "crank_pendulum.toml")
    return mech, cd.run_dae(mech, 4.0, rtol=RTOL, atol=1e-12, output_dt=0.002)


# ----------------------------------------------------------------- slider-crank reference
def slider_crank_kin(mech, th: float, w: float):
    r, l = 0.05, 0.2
    x = Jet(th, 1.0)
    c1, s1 = cos(x), sin(x)
    sphi = -r * s1 / l
    cphi = sqrt(1 - sphi * sphi)
    crank = body_kin(0.5 * r * c1, 0.5 * r * s1, c1, s1, th, w, th_value=th)
    rod = body_kin(r * c1 + 0.5 * l * cphi, r * s1 + 0.5 * l * sphi, cphi, sphi, th, w)
    xs = r * c1 + l * cphi
    slider = body_kin(xs, Jet(0.0), Jet(1.0), Jet(0.0), th, w, th_value=0.0)
    B = np.array([(r * c1).f, (r * s1).f])
    return {"crank": crank, "rod": rod, "slider": slider}, B, xs.f


def energy_torque(mech, kin: dict, w: float) -> float:
    """tau = d(T + V)/dtheta for a crank at constant speed w (kin holds time derivatives)."""
    tau = 0.0
    for name, k in kin.items():
        b = mech.bodies[name]
        # dT/dtheta = (1/w) dT/dt = (1/w) (m v.a + J om al)
        tau += (b.mass * k.v @ k.a + b.inertia * k.om * k.al) / w
        tau += -b.mass * np.array(mech.gravity) @ k.v / w
    return tau


def test_slider_crank_torque_and_reactions(slider_crank):
    mech, res = slider_crank
    w = mech.drivers["A"].speed
    tau = res.driver("A").effort
    ref_tau = np.empty_like(tau)
    ne = {k: np.empty((res.t.size, 2)) for k in ("A", "B", "C", "E")}
    ne_tau = np.empty_like(tau)
    slider_x = np.empty_like(tau)
    for i, t in enumerate(res.t):
        th = 0.5 + w * t
        kin, B, slider_x[i] = slider_crank_kin(mech, th, w)
        ref_tau[i] = energy_torque(mech, kin, w)
        bodies = {n: {"m": mech.bodies[n].mass, "J": mech.bodies[n].inertia, "kin": k}
                  for n, k in kin.items()}
        C = np.array([slider_x[i], 0.0])
        sol = newton_euler(bodies, [
            {"name": "A", "type": "revolute", "first": "ground", "second": "crank",
             "point": np.zeros(2)},
            {"name": "B", "type": "revolute", "first": "crank", "second": "rod", "point": B},
            {"name": "C", "type": "revolute", "first": "rod", "second": "slider", "point": C},
            {"name": "E", "type": "prismatic", "first": "ground", "second": "slider",
             "point": C, "normal": np.array([0.0, 1.0])},
        ], [{"joint": "A", "first": "ground", "second": "crank"}], mech.gravity)
        for k in ("A", "B", "C"):
            ne[k][i] = sol[k]
        ne["E"][i] = sol["E"]
        ne_tau[i] = sol["driver A"][0]
    scale = np.max(np.abs(ref_tau))
    assert np.max(np.abs(tau - ref_tau)) / scale <= 1e-8
    assert np.max(np.abs(ne_tau - ref_tau)) / scale <= 1e-10  # the two references agree
    assert np.max(np.abs(res.joint("E").position - slider_x)) <= 1e-9
    for k in ("A", "B", "C"):
        assert np.max(np.abs(res.joint(k).force - ne[k])) <= 1e-8, k
        assert np.max(np.abs(res.joint(k).torque)) <= 1e-10, k  # revolute: no moment
    E = res.joint("E")
    assert np.max(np.abs(E.force[:, 0])) <= 1e-10
    assert np.max(np.abs(E.force[:, 1] - ne["E"][:, 0])) <= 1e-8
    assert np.max(np.abs(E.torque - ne["E"][:, 1])) <= 1e-8


# --------------------------------------------------------------------- four-bar reference
def four_bar_kin(mech, th: float, w: float):
    a, b, c, d = 0.04, 0.12, 0.10, 0.12
    x = Jet(th, 1.0)
    c1, s1 = cos(x), sin(x)
    Bx, By = a * c1, a * s1
    dx, dy = d - Bx, -By
    L = sqrt(dx * dx + dy * dy)
    p = (b * b - c * c + L * L) / (2 * L)
    h = sqrt(b * b - p * p)
    ex, ey = dx / L, dy / L
    Cx, Cy = Bx + p * ex - h * ey, By + p * ey + h * ex
    cphi, sphi = (Cx - Bx) / b, (Cy - By) / b
    cpsi, spsi = (Cx - d) / c, Cy / c
    gx, gy = 0.06, 0.01  # coupler centroid in its frame
    crank = body_kin(0.02 * c1, 0.02 * s1, c1, s1, th, w, th_value=th)
    coupler = body_kin(Bx + cphi * gx - sphi * gy, By + sphi * gx + cphi * gy, cphi, sphi, th, w)
    rocker = body_kin(d + 0.05 * cpsi, 0.05 * spsi, cpsi, spsi, th, w)
    return ({"crank": crank, "coupler": coupler, "rocker": rocker},
            np.array([Bx.f, By.f]), np.array([Cx.f, Cy.f]))


def test_four_bar_torque_and_reactions(four_bar):
    mech, res = four_bar
    w = mech.drivers["A"].speed
    tau = res.driver("A").effort
    errs = {k: 0.0 for k in "ABCD"}
    err_tau = 0.0
    scale = 0.0
    for i, t in enumerate(res.t):
        th = 1.0 + w * t
        kin, B, C = four_bar_kin(mech, th, w)
        ref = energy_torque(mech, kin, w)
        scale = max(scale, abs(ref))
        err_tau = max(err_tau, abs(tau[i] - ref))
        bodies = {n: {"m": mech.bodies[n].mass, "J": mech.bodies[n].inertia, "kin": k}
                  for n, k in kin.items()}
        sol = newton_euler(bodies, [
            {"name": "A", "type": "revolute", "first": "ground", "second": "crank",
             "point": np.zeros(2)},
            {"name": "B", "type": "revolute", "first": "crank", "second": "coupler", "point": B},
            {"name": "C", "type": "revolute", "first": "coupler", "second": "rocker", "point": C},
            {"name": "D", "type": "revolute", "first": "ground", "second": "rocker",
             "point": np.array([0.12, 0.0])},
        ], [{"joint": "A", "first": "ground", "second": "crank"}], mech.gravity)
        assert abs(sol["driver A"][0] - ref) <= 1e-10 * max(1.0, abs(ref))
        for k in "ABCD":
            errs[k] = max(errs[k], float(np.max(np.abs(res.joint(k).force[i] - sol[k]))))
        coupler_angle = res.body("coupler").pose[i, 2]
        assert abs(math.remainder(coupler_angle - kin["coupler"].th, 2 * math.pi)) <= 1e-9
    assert err_tau / scale <= 1e-8
    for k in "ABCD":
        assert errs[k] <= 1e-8, (k, errs[k])


# ------------------------------------------------------------- crank + swinging link
def crank_pendulum_reference(mech, t_eval):
    """Minimal-coordinate model: the link angle phi is the only unknown."""
    crank, link = mech.bodies["crank"], mech.bodies["link"]
    w = mech.drivers["O"].speed
    rOB, half = 0.08, 0.1
    m, JG = link.mass, link.inertia
    k, rest = mech.joints["B"].spring.stiffness, mech.joints["B"].spring.rest
    cdamp = mech.joints["B"].damper.damping
    g = np.array(mech.gravity)

    def parts(t, phi, dphi):
        th = w * t
        aB = -rOB * w**2 * np.array([math.cos(th), math.sin(th)])
        e = np.array([math.cos(phi), math.sin(phi)])
        tau_s = -k * (phi - th - rest) - cdamp * (dphi - w)
        return th, aB, e, tau_s

    def rhs(t, y):
        phi, dphi = y
        _, aB, e, tau_s = parts(t, phi, dphi)
        cr = lambda u, v: u[0] * v[1] - u[1] * v[0]  # noqa: E731
        ddphi = (-half * m * cr(e, aB) + half * m * cr(e, g) + tau_s) / (JG + m * half**2)
        return [dphi, ddphi]

    phi0 = mech.initial.joints["B"]  # crank starts at 0, so relative = absolute
    # [initial] velocities are relative rates: B' = 0 means the link turns with the crank
    sol = solve_ivp(rhs, (0, t_eval[-1]), [phi0, w], method="DOP853", rtol=1e-12,
                    atol=1e-12, t_eval=t_eval)
    phi, dphi = sol.y
    tau = np.empty_like(phi)
    for i, t in enumerate(t_eval):
        th, aB, e, tau_s = parts(t, phi[i], dphi[i])
        ddphi = rhs(t, [phi[i], dphi[i]])[1]
        eperp = np.array([-e[1], e[0]])
        aG = aB + half * (ddphi * eperp - dphi[i] ** 2 * e)
        FB = m * aG - m * g  # force of crank on link
        rB = rOB * np.array([math.cos(th), math.sin(th)])
        rc = 0.04 * np.array([math.cos(th), math.sin(th)])
        cr = lambda u, v: u[0] * v[1] - u[1] * v[0]  # noqa: E731
        # crank at constant speed: 0 = tau + rB x (-FB) + rc x m1 g - tau_s
        tau[i] = -(cr(rB, -FB) + cr(rc, crank.mass * g) - tau_s)
    return phi, tau


def test_crank_pendulum_against_minimal_coordinates(crank_pendulum):
    mech, res = crank_pendulum
    phi_ref, tau_ref = crank_pendulum_reference(mech, res.t)
    phi = res.body("link").pose[:, 2]
    assert np.max(np.abs(phi - phi_ref)) <= 1e-7
    assert np.max(np.abs(res.driver("O").effort - tau_ref)) <= 1e-6


# ------------------------------------------------------------------------ energy, drift
def energy_terms(mech, res):
    """Driver work, kinetic + potential energy, damper dissipation along a result."""
    T = np.zeros(res.t.size)
    V = np.zeros(res.t.size)
    for name, b in mech.bodies.items():
        i = list(mech.bodies).index(name)
        q, v = res.data["q"][:, 3 * i:3 * i + 3], res.data["v"][:, 3 * i:3 * i + 3]
        T += 0.5 * b.mass * (v[:, 0] ** 2 + v[:, 1] ** 2) + 0.5 * b.inertia * v[:, 2] ** 2
        V -= b.mass * (mech.gravity[0] * q[:, 0] + mech.gravity[1] * q[:, 1])
    P_diss = np.zeros(res.t.size)
    for name, j in mech.joints.items():
        js = res.joint(name)
        if j.spring is not None:
            V += 0.5 * j.spring.stiffness * (js.position - j.spring.rest) ** 2
        if j.damper is not None:
            P_diss += j.damper.damping * js.velocity**2
    P_drv = sum(res.driver(n).effort * res.joint(n).velocity for n in mech.drivers)
    return T + V, simpson(P_drv, x=res.t), simpson(P_diss, x=res.t)


@pytest.mark.parametrize("fixture", ["slider_crank", "four_bar", "crank_pendulum"])
def test_energy_balance_and_drift(fixture, request):
    mech, res = request.getfixturevalue(fixture)
    E, W, D = energy_terms(mech, res)
    assert abs(W - (E[-1] - E[0]) - D) <= 1e-7
    pos, vel = res.drift
    assert pos <= 1e-9 and vel <= 1e-7


@pytest.mark.parametrize("name", ["slider_crank", "four_bar", "crank_pendulum"])
def test_drift_at_default_tolerance(name):
    """At the documented default rtol 1e-8 the constraint drift stays within the local
    error's order: the samples are IDA's interpolants between its steps, whose positions
    are good to about rtol times the largest coordinate (0.12-0.25 m here; measured
    1.0e-9, 1.5e-10, 2.4e-10 m), and the velocity drift below 1e-7 m/s."""
    res = cd.run_dae(cd.load(MODELS / f"{name}.toml"), 3.0, rtol=1e-8)
    pos, vel = res.drift
    q = res.data["q"]
    xy = np.delete(q, np.s_[2::3], axis=1)  # the centroids' coordinates (m)
    assert pos <= 1e-8 * np.max(np.abs(xy)) and vel <= 1e-7


def test_result_layout_is_its_mechanism_typed(tmp_path):
    """``Result.layout``: the mechanism's names, types and geometry as typed fields (the
    stored ``meta`` read through it); a result file written before a key existed reads
    as that key's empty default, and the run's own entries stay in ``meta``."""
    from cmm_dae.results.layout import Layout

    mech = cd.load(Path(__file__).resolve().parent.parent / "models" / "slider_crank.toml")
    res = cd.run_dae(mech, 0.05, output_dt=0.01)
    lay = res.layout
    assert lay.mechanism == mech.name and lay.joints == tuple(mech.joints)
    assert lay.drivers == tuple(mech.drivers) and lay.bodies == tuple(mech.bodies)
    assert [lay.joint_type(j) for j in mech.joints] == [j.type for j in mech.joints.values()]
    assert [lay.coordinate_unit(j) for j in mech.joints] == [
        "rad" if j.type == "revolute" else "m" for j in mech.joints.values()]
    assert lay.connects == {n: (j.first, j.second) for n, j in mech.joints.items()}
    assert lay.axes == {n: tuple(j.axis) for n, j in mech.joints.items()
                        if j.type == "prismatic"}
    saved = cd.load_result(res.save(tmp_path / "r.npz"))
    assert saved.layout.body_points == lay.body_points and saved.layout.masses == lay.masses
    old = {k: v for k, v in res.meta.items() if k not in ("curves", "gears", "frictional")}
    assert Layout.of(old).curves == {} and Layout.of(old).gears == {}
    assert Layout.of(old).frictional == ()
    assert "tolerances" in res.meta and not hasattr(lay, "tolerances")
