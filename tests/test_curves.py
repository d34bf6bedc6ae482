"""Spline curves in slots (bilateral contacts): a bead in a curved slot, open and closed.

References, each independent of the code under test:

* the bead (a body whose centroid runs in the slot, its rotation free) in an open slot
  y = f(x), f scipy's not-a-knot cubic spline through the same points: Lagrange's equation
  in x, (1 + f'^2) x'' + f' f'' x'^2 + g f' = 0, by DOP853 at rtol 1e-13; the slot's force
  m (g + f'' x'^2) / sqrt(1 + f'^2) (the bead's equation along the normal); the arc length
  the integral of sqrt(1 + f'^2) by scipy's adaptive quadrature;
* the bead in a closed groove r(phi), r scipy's periodic spline through the points' radii:
  Lagrange's equation in phi, (r^2 + r'^2) phi'' + r'(r + r'') phi'^2 + g (r' sin(phi) +
  r cos(phi)) = 0;
* the slot's end: the time x(t) of the reference reaches the end point (its event).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.interpolate import CubicSpline

import cmm_dae as cd
from cmm_dae.description.curves import spline

MC, MS, G = 0.5, 0.3, 9.81  # carriage and slider masses kg; gravity m/s^2
XS = np.linspace(0.0, 0.6, 9)
YS = 0.08 * np.cos(2 * math.pi * XS / 0.6) - 0.03 * XS  # a valley, lower to the right


def cross_slide(points, closed: bool, start: float, limits=None, guess=(0.0, 0.0)
                ) -> cd.Mechanism:
    """A cross-slide whose pin follows a slot in the ground through ``points`` (relative
    to ground point O): a carriage on a horizontal guide, a slider on a vertical guide of
    the carriage, the slider's pin P in the slot; started at rest at arc length
    ``start``. No body turns, so the pin's place on the slot is the one coordinate."""
    return cd.Mechanism(
        "cross-slide", ground={"O": (0.0, 0.0)},
        bodies=[cd.Body("carriage", MC, 1e-3, points={"C": (0.0, 0.0)},
                        guess=(guess[0], 0.0, 0.0)),
                cd.Body("slider", MS, 1e-4, points={"P": (0.0, 0.0)},
                        guess=(*guess, 0.0))],
        joints=[cd.Joint("X", "prismatic", "ground.O", "carriage.C"),
                cd.Joint("Y", "prismatic", "carriage.C", "slider.P", axis=(0.0, 1.0)),
                cd.Joint("K", "contact", "ground.O", "slider.P", limits=limits,
                         curve=cd.Curve("spline", points=tuple(map(tuple, points)),
                                        closed=closed))],
        initial=cd.Initial(joints={"K": start}, velocities={"K": 0.0}))


def _open_reference(x0: float, t_end: float, events=None):
    """The cross-slide on y = f(x): T = (MC + MS (1 + f'^2)) x'^2 / 2, V = MS g f."""
    f = CubicSpline(XS, YS)

    def rhs(_t, z):
        x, xd = z
        d1, d2 = f(x, 1), f(x, 2)
        return [xd, -MS * (d1 * d2 * xd**2 + G * d1) / (MC + MS * (1 + d1**2))]

    return f, solve_ivp(rhs, (0.0, t_end), [x0, 0.0], method="DOP853", rtol=1e-13,
                        atol=1e-15, dense_output=True, events=events)


def _arc(f, x0: float, x: float) -> float:
    return quad(lambda u: math.sqrt(1 + f(u, 1) ** 2), x0, x, epsabs=1e-14,
                epsrel=1e-13, limit=200)[0]


@pytest.mark.timeout(120)
def test_spline_arc_length_against_quadrature():
    """The curves' lengths and arc lengths at their knots within 1e-13 m of scipy's adaptive
    quadrature of the same splines (Gauss-Legendre, 12 nodes per piece)."""
    sp = spline(cd.Curve("spline", points=tuple(zip(XS, YS, strict=True)), closed=False))
    f = CubicSpline(XS, YS)
    ref = [_arc(f, XS[0], x) for x in XS]
    assert np.max(np.abs(sp.arc - ref)) <= 1e-13
    phi = np.linspace(0.0, 2 * math.pi, 12, endpoint=False)
    r = 0.1 + 0.02 * np.cos(2 * phi)
    sc = spline(cd.Curve("spline", points=tuple(zip(r * np.cos(phi), r * np.sin(phi),
                                                     strict=True))))
    S = CubicSpline(np.append(phi, 2 * math.pi), np.append(r, r[0]), bc_type="periodic")
    length = quad(lambda u: math.hypot(S(u), S(u, 1)), 0.0, 2 * math.pi, epsabs=1e-14,
                  epsrel=1e-13, limit=200)[0]
    assert abs(sc.length - length) <= 1e-13


@pytest.mark.timeout(120)
def test_cross_slide_in_an_open_slot_against_lagrange():
    """Released at rest at x = 0.08 m: over 2 s the pin's x within 1e-8 m of the reference
    (it swings about the valley's bottom), its height on the spline, its arc coordinate
    within 1e-8 m of the quadrature of the reference's path, the slot's force within 1e-7 N
    of sqrt(1 + f'^2) MS (g + f' x'' + f'' x'^2) (the slider's vertical balance), the energy
    audit closed within 1e-8 J. Measured: 8.7e-10 m, 8.9e-10 m, 2.2e-8 N of 5.8 N,
    3.8e-10 J."""
    f, ref = _open_reference(0.08, 2.0)
    res = cd.run_dae(cross_slide(list(zip(XS, YS, strict=True)), False, _arc(f, 0.0, 0.08),
                                 guess=(0.08, 0.07)), 2.0, rtol=1e-11, output_dt=0.01)
    assert res.status == "success" and not res.events
    x = res.body("slider").pose[:, 0]
    xr, xdr = ref.sol(res.t)
    assert np.max(np.abs(x - xr)) <= 1e-8
    assert np.max(np.abs(res.body("slider").pose[:, 1] - f(xr))) <= 1e-8
    arc = np.array([_arc(f, 0.0, xx) for xx in xr[::10]])
    assert np.max(np.abs(res.joint("K").position[::10] - arc)) <= 1e-8
    d1, d2 = f(xr, 1), f(xr, 2)
    xdd = -MS * (d1 * d2 * xdr**2 + G * d1) / (MC + MS * (1 + d1**2))
    N = np.sqrt(1 + d1**2) * MS * (G + d1 * xdd + d2 * xdr**2)
    assert np.max(np.abs(np.linalg.norm(res.joint("K").force, axis=1) - N)) <= 1e-7
    assert np.max(np.abs(res.energy().residual)) <= 1e-8


@pytest.mark.timeout(120)
def test_cross_slide_stops_at_the_open_slots_end():
    """Released at x = 0.02 m, the pin runs down the valley and up its far side past
    0.45 m, where the slot ends (limits = { upper = arc length at 0.45 m }): the end's
    event within 1e-8 s of the time the reference reaches x = 0.45 m (measured 3.5e-11 s),
    a plastic stop (rate 0 after it) that lets go at once (the end would have to pull
    the pin back from the slope); the fixed-step algorithm (dt 1e-4) within 2e-3 s. Without
    limits the slot's own ends (0 and its length) are the stops."""
    f = CubicSpline(XS, YS)
    end = _arc(f, 0.0, 0.45)

    def hit(_t, z):
        return z[0] - 0.45
    hit.terminal = True
    hit.direction = 1
    _, ref = _open_reference(0.02, 2.0, events=hit)
    t_hit = ref.t_events[0][0]
    pts = list(zip(XS, YS, strict=True))
    mech = cross_slide(pts, False, _arc(f, 0.0, 0.02), cd.Limits(upper=end),
                       guess=(0.02, 0.08))
    res = cd.run_dae(mech, 1.0, rtol=1e-11)
    assert [(e.kind, e.side) for e in res.events] == [("limit", "upper"),
                                                      ("release", "upper")]
    assert abs(res.events[0].t - t_hit) <= 1e-8 and res.events[1].t == res.events[0].t
    assert res.events[0].velocity_after == 0.0 and res.events[1].release_force < 0.0
    assert np.max(res.joint("K").position) <= end + 1e-12
    it = cd.run_iterative(mech, 1.0, dt=1e-4)
    assert [e.kind for e in it.events] == ["limit", "release"]
    assert abs(it.events[0].t - t_hit) <= 2e-3
    lim = cross_slide(pts, False, 0.1).joints["K"].stops
    assert lim.lower == 0.0 and abs(lim.upper - _arc(f, 0.0, 0.6)) <= 1e-13


@pytest.mark.timeout(120)
def test_cross_slide_in_a_closed_groove_against_lagrange():
    """A closed groove r = 0.1 + 0.02 cos(2 phi) + 0.01 sin(phi) m (a spline through 16
    points) in a vertical plane, the pin released at rest at phi = 0.3 rad: its polar
    angle within 1e-8 rad of the reference over 1.5 s (T = (MC x_phi^2 + MS (r^2 +
    r'^2)) phi'^2 / 2, V = MS g r sin(phi); measured 2.5e-9 rad, swinging 3.7 rad through
    the first point, where the arc length restarts), its radius within 1e-9 m of the
    spline's (2.1e-13 m), the energy audit within 1e-8 J (4.8e-10 J)."""
    phi = np.linspace(0.0, 2 * math.pi, 16, endpoint=False)
    r = 0.1 + 0.02 * np.cos(2 * phi) + 0.01 * np.sin(phi)
    pts = list(zip(r * np.cos(phi), r * np.sin(phi), strict=True))
    S = CubicSpline(np.append(phi, 2 * math.pi), np.append(r, r[0]), bc_type="periodic")

    def rhs(_t, z):
        p, pd = z
        c, s = math.cos(p), math.sin(p)
        rr, r1, r2 = S(p), S(p, 1), S(p, 2)
        x1 = r1 * c - rr * s  # dx/dphi
        x2 = r2 * c - 2 * r1 * s - rr * c
        A = MC * x1**2 + MS * (rr**2 + r1**2)
        dA = 2 * MC * x1 * x2 + 2 * MS * r1 * (rr + r2)
        return [pd, -(0.5 * dA * pd**2 + MS * G * (r1 * s + rr * c)) / A]

    ref = solve_ivp(rhs, (0.0, 1.5), [0.3, 0.0], method="DOP853", rtol=1e-13, atol=1e-15,
                    dense_output=True)
    s0 = quad(lambda u: math.hypot(S(u), S(u, 1)), 0.0, 0.3, epsabs=1e-15, epsrel=1e-14)[0]
    r0 = float(S(0.3))
    res = cd.run_dae(cross_slide(pts, True, s0, guess=(r0 * math.cos(0.3),
                                                       r0 * math.sin(0.3))), 1.5,
                     rtol=1e-11, output_dt=0.01)
    xy = res.body("slider").pose[:, :2]
    ang = np.unwrap(np.arctan2(xy[:, 1], xy[:, 0]))
    assert res.status == "success"
    assert np.max(np.abs(ang - ref.sol(res.t)[0])) <= 1e-8
    assert np.max(np.abs(np.hypot(*xy.T) - S(np.mod(ang, 2 * math.pi)))) <= 1e-9
    assert np.max(np.abs(res.energy().residual)) <= 1e-8


def _friction_reference(x0: float, mu: float, t_end: float, ms: float = MS):
    """The cross-slide on y = f(x) with the slot's friction mu N against the pin's motion,
    N the contact force: per state the pin's acceleration and N from the carriage's and
    the slider's balances (linear once N > 0 is assumed; checked), to the first rest."""
    f = CubicSpline(XS, YS)

    def solve(x, xd):
        d1, d2 = f(x, 1), f(x, 2)
        w, s = math.sqrt(1 + d1 * d1), math.copysign(1.0, xd)
        # (MC + ms) x'' + N (f' + mu s) / w = 0;  ms (f' x'' + f'' x'^2 + g) = N (1 - mu s f') / w
        A = np.array([[MC + ms, (d1 + mu * s) / w], [ms * d1, -(1 - mu * s * d1) / w]])
        xdd, N = np.linalg.solve(A, [0.0, -ms * (d2 * xd * xd + G)])
        assert N > 0.0
        return xdd, N

    def rest(_t, z):
        return z[1]
    rest.terminal = True
    rest.direction = -1  # it starts to the right, down the slope
    return solve, solve_ivp(lambda _t, z: [z[1], solve(*z)[0]], (0.0, t_end),
                            [x0, 1e-300], method="DOP853", rtol=1e-13, atol=1e-15,
                            dense_output=True, events=rest, first_step=1e-6)


def _slot_with_friction(mu: float) -> cd.Mechanism:
    """The cross-slide in the open slot with friction mu |N|, released at x = 0.25 m."""
    mech = cross_slide(list(zip(XS, YS, strict=True)), False,
                       _arc(CubicSpline(XS, YS), 0.0, 0.25), guess=(0.25, -0.08))
    k = mech.joints["K"]
    return mech.replace(joints={**mech.joints, "K": cd.Joint(
        "K", "contact", k.first, k.second, curve=k.curve,
        friction=cd.Friction(mu_static=0.2, mu_kinetic=mu))})


@pytest.mark.timeout(120)
def test_friction_in_a_spline_slot_from_its_contact_force():
    """The cross-slide released at x = 0.25 m in the open slot with friction mu |N| (mu_k
    0.15, mu_s 0.2; N the contact force): the pin's x within 1e-8 m of the reference that
    solves the friction with the slot's force at every step, until it comes to rest, where
    it sticks within 1e-8 s of the reference's rest; the audit books the friction's loss
    within 1e-8 J. Measured: 7.8e-12 m, 8.4e-12 s, 7.4e-12 J."""
    mu = 0.15
    solve, ref = _friction_reference(0.25, mu, 3.0)
    t_rest = ref.t_events[0][0]
    res = cd.run_dae(_slot_with_friction(mu), 3.0, rtol=1e-11, output_dt=0.01)
    sticks = [e for e in res.events if e.kind == "stick"]
    assert sticks and abs(sticks[0].t - t_rest) <= 1e-8
    before = res.t < t_rest - 1e-6
    assert np.max(np.abs(res.body("slider").pose[before, 0] - ref.sol(res.t[before])[0])) \
        <= 1e-8
    assert np.max(np.abs(res.energy().residual)) <= 1e-8


@pytest.mark.timeout(120)
@pytest.mark.parametrize("closed", [False, True])
def test_spline_gap_and_arc_gradients_are_the_curves_normal_and_tangent(closed):
    """At points on the curve the contact row's gradient is the unit normal (outward on a
    closed curve, to the left of an open one) and the arc
    coordinate's the unit tangent (scipy's derivatives of the same spline), within 1e-12:
    so the row's multiplier is the contact force, and friction along the coordinate is
    tangential (it would otherwise change the contact force it grows with)."""
    if closed:
        phi = np.linspace(0.0, 2 * math.pi, 16, endpoint=False)
        r = 0.1 + 0.02 * np.cos(2 * phi) + 0.01 * np.sin(phi)
        pts = list(zip(r * np.cos(phi), r * np.sin(phi), strict=True))
        S = CubicSpline(np.append(phi, 2 * math.pi), np.append(r, r[0]), bc_type="periodic")
        us = [0.2, 1.9, 3.5, 5.9]
        place = [(S(u) * math.cos(u), S(u) * math.sin(u)) for u in us]
        tang = [(S(u, 1) * math.cos(u) - S(u) * math.sin(u),
                 S(u, 1) * math.sin(u) + S(u) * math.cos(u)) for u in us]
    else:
        pts = list(zip(XS, YS, strict=True))
        f = CubicSpline(XS, YS)
        us = [0.03, 0.2, 0.37, 0.58]
        place = [(u, f(u)) for u in us]
        tang = [(1.0, f(u, 1)) for u in us]
    model = cd.Model(cross_slide(pts, closed, 0.01, guess=place[0]))
    row = model.rows_of("joint", "K")[0]
    p = model.params()
    for (x, y), (tx, ty) in zip(place, tang, strict=True):
        t = np.array([tx, ty]) / math.hypot(tx, ty)
        q = np.array([x, 0.0, 0.0, x, y, 0.0])
        c_q = model.joint_coords(q, np.zeros(6)).c_q[model.jidx["K"], 3:5]
        n_q = model.constraints(q, 0.0, p).Phi_q[row, 3:5]
        assert np.max(np.abs(c_q - t)) <= 1e-12
        n = np.array([t[1], -t[0]]) if closed else np.array([-t[1], t[0]])  # out; left
        assert np.max(np.abs(n_q - n)) <= 1e-12


@pytest.mark.timeout(180)
@pytest.mark.parametrize("path", ["joints.K.friction.mu_kinetic", "bodies.slider.mass"])
def test_spline_slot_sensitivities_through_stick(path):
    """d t_stick / d p (the frictional spline slot) against central differences of the
    reference's rest time (h 1e-4 relative; DOP853 at rtol 1e-13): within 1e-6 of it
    (central differences of cmm_dae's own runs at rtol 1e-12 carry their event times'
    round-off, 1e-6 of the derivative at h 1e-4). Measured 4.6e-8 and 9.3e-9."""
    mech = _slot_with_friction(0.15)
    s = cd.sensitivities(mech, [path], 1.0, rtol=1e-11)
    assert [e.kind for e in s.result.events] == ["slip", "stick"]
    h = 1e-4
    if path.startswith("joints"):
        rest = [_friction_reference(0.25, 0.15 * (1 + x), 3.0)[1].t_events[0][0]
                for x in (h, -h)]
        fd = (rest[0] - rest[1]) / (2 * h * 0.15)
    else:
        rest = [_friction_reference(0.25, 0.15, 3.0, ms=MS * (1 + x))[1].t_events[0][0]
                for x in (h, -h)]
        fd = (rest[0] - rest[1]) / (2 * h * MS)
    assert s.event_times[0, 0] == 0.0 and abs(fd) > 1e-2
    assert abs(s.event_times[1, 0] - fd) <= 1e-6 * abs(fd)


@pytest.mark.timeout(120)
def test_shipped_curved_slot_locks_slips_and_releases():
    """The shipped curved slot over 4 s: slips, locks at both ends of the open spline
    and releases; the pin within the slot's ends throughout, on an end at each lock
    (within 1e-9 m); the energy audit (friction's loss included) within 2e-6 J (IDA's
    error at the default rtol: 9.3e-7 J with the mechanism's values as constants, 1.03e-6
    J with them read from p, the same equations rounded otherwise); the
    fixed-step algorithm the same events within 1e-3 s (measured 6.7e-4 s at dt 2e-4 in
    29 s, 3.7e-4 s at dt 1e-4 in 57 s, the slowest test of the suite)."""
    mech = cd.load(cd.example("curved_slot"))
    res = cd.run_dae(mech, 4.0)
    kinds = [e.kind for e in res.events]
    assert kinds.count("slip") >= 2 and kinds.count("limit") >= 4
    assert kinds.count("release") >= 3
    lo, up = mech.joints["K"].stops.lower, mech.joints["K"].stops.upper
    k = res.joint("K").position
    assert lo - 1e-9 <= np.min(k) and np.max(k) <= up + 1e-9
    for e in res.events:
        if e.kind == "limit":
            i = np.searchsorted(res.t, e.t)
            assert k[i] == pytest.approx(up if e.side == "upper" else lo, abs=1e-9)
    assert np.max(np.abs(res.energy().residual)) <= 2e-6
    it = cd.run_iterative(mech, 4.0, dt=2e-4)
    assert [e.kind for e in it.events] == kinds
    assert max(abs(a.t - b.t) for a, b in zip(it.events, res.events, strict=True)) <= 1e-3


@pytest.mark.timeout(120)
def test_a_stop_tried_at_rest_drops_the_slipping_joints_friction():
    """The curved slot from 0.10 to 0.32 m with the motor at 3 N m: at 0.688 s the
    slipping pin comes to rest on the slot's end. Whether the end holds it was decided by
    a trial lock that kept the pin's kinetic friction mu |N| on top of the lock, which
    Newton could not solve (the run stopped there with a LinAlgError); the trial drops it
    now, and the run goes on to the upper end (locked at 1.08 s)."""
    mech = cd.load(cd.example("curved_slot"))
    k = mech.joints["K"]
    pts = ((0.10, 0.0), (0.155, 0.011), (0.21, 0.015), (0.265, 0.011), (0.32, 0.0))
    mech = cd.with_params(mech.replace(joints={**mech.joints, "K": cd.Joint(
        "K", "contact", k.first, k.second, friction=k.friction,
        curve=cd.Curve("spline", points=pts, closed=False))}), {"loads.motor.amplitude": 3.0})
    res = cd.run_dae(mech, 1.5)
    assert res.status == "success"
    assert [(e.kind, e.side) for e in res.events if e.kind == "limit"] == [("limit", "upper")]
