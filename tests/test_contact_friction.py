"""Friction in unilateral contacts: a slider of a cross-slide (a carriage on a horizontal
guide, the slider on a vertical guide of the carriage; no body turns) that touches a ground
curve, with friction mu |N| along it (N the contact force) while it touches.

References, each independent of the code under test:

* dropped from h onto a floor with the carriage moving at u0: it lands at sqrt(2 h / g)
  keeping u0 (a frictionless, plastic impact), then slides to rest under the friction
  mu_k m_s g, decelerating the carriage and slider at a = mu_k m_s g / (m_c + m_s): it
  sticks at t1 + u0 / a, x(t) piecewise quadratic;
* resting on the floor and pushed along it by a force k t on the carriage: it sticks until
  k t = mu_s m_s g; lifted by a force k t on the slider, it lifts off at k t = m_s g (stuck
  or not);
* over a circular hump with friction: the carriage's and the slider's balances give the
  acceleration and N together at every state (linear for N > 0), DOP853 at rtol 1e-13,
  lift-off where N reaches zero.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import cmm_dae as cd

MC, MS, G = 0.5, 0.3, 9.81  # carriage and slider masses kg; gravity m/s^2
R = 0.2  # the hump's radius, m


def cross_slide(curve: cd.Curve, friction: cd.Friction, x0: float, gap: float, u0: float,
                loads=()) -> cd.Mechanism:
    """The cross-slide over ``curve`` (through ground point O), its slider ``gap`` off it,
    the carriage at ``x0`` moving at ``u0``."""
    y0 = gap + (R if curve.kind == "circle" else 0.0)
    return cd.Mechanism(
        "cross-slide", ground={"O": (0.0, 0.0)},
        bodies=[cd.Body("carriage", MC, 1e-3, points={"C": (0.0, 0.0)},
                        guess=(x0, 0.0, 0.0)),
                cd.Body("slider", MS, 1e-4, points={"P": (0.0, 0.0)}, guess=(x0, y0, 0.0))],
        joints=[cd.Joint("X", "prismatic", "ground.O", "carriage.C"),
                cd.Joint("Y", "prismatic", "carriage.C", "slider.P", axis=(0.0, 1.0)),
                cd.Joint("K", "contact", "ground.O", "slider.P", unilateral=True,
                         curve=curve, friction=friction)],
        loads=list(loads),
        initial=cd.Initial(joints={"X": x0, "K": gap}, velocities={"X": u0, "K": 0.0}))


FLOOR = cd.Curve("line", direction=(1.0, 0.0))
H, U0 = 0.05, 1.2


def dropped(mu_k: float = 0.3) -> cd.Mechanism:
    return cross_slide(FLOOR, cd.Friction(mu_static=0.4, mu_kinetic=mu_k), 0.0, H, U0)


@pytest.mark.timeout(120)
def test_dropped_slider_lands_slides_and_sticks():
    """Landing within 1e-9 s of sqrt(2h/g), sticking within 1e-9 s of t1 + u0 / a, the
    carriage's x within 1e-9 m of the piecewise quadratic, the friction -mu_k m_s g while
    it slides, the audit within 1e-8 J (the friction's loss is the kinetic energy u0
    carried into the floor's plane, within 1e-9 J); the fixed-step algorithm (dt 1e-4) the
    same events within 2e-3 s. Measured: 2.9e-15 s, 2.0e-14 s, 3.2e-15 m, 8.5e-15 J,
    2.2e-16 J; fixed-step 1.4e-4 and 2.1e-4 s."""
    mu_k = 0.3
    t1 = math.sqrt(2 * H / G)
    a = mu_k * MS * G / (MC + MS)
    t2 = t1 + U0 / a
    res = cd.run_dae(dropped(mu_k), 1.5, rtol=1e-10, output_dt=0.01)
    assert [(e.kind, e.joint) for e in res.events] == [("landing", "K"), ("stick", "K:slide")]
    assert abs(res.events[0].t - t1) <= 1e-9 and abs(res.events[1].t - t2) <= 1e-9
    t = res.t
    x = np.where(t < t1, U0 * t, np.where(t < t2, U0 * t - 0.5 * a * (t - t1) ** 2,
                                          U0 * t1 + 0.5 * U0**2 / a))
    assert np.max(np.abs(res.joint("X").position - x)) <= 1e-9
    sliding = (t > t1 + 1e-6) & (t < t2 - 1e-6)
    assert np.max(np.abs(res.joint("K").friction[sliding] + mu_k * MS * G)) <= 1e-9
    en = res.energy()
    assert np.max(np.abs(en.residual)) <= 1e-8
    assert abs(en.friction_loss[-1] - 0.5 * (MC + MS) * U0**2) <= 1e-9
    it = cd.run_iterative(dropped(mu_k), 1.5, dt=1e-4)
    assert [e.kind for e in it.events] == ["landing", "stick"]
    assert max(abs(a_.t - b.t) for a_, b in zip(it.events, res.events, strict=True)) <= 2e-3


@pytest.mark.timeout(180)
@pytest.mark.parametrize("path", ["joints.K.friction.mu_kinetic", "bodies.slider.mass"])
def test_sensitivities_through_landing_and_stick(path):
    """d t / d p of the landing (0) and the stick against the closed form's derivatives,
    d t2 / d mu_k = -u0 (m_c + m_s) / (mu_k^2 m_s g) and d t2 / d m_s = -u0 m_c /
    (mu_k m_s^2 g), within 1e-7 relative (measured 1.5e-14 and 1.5e-14)."""
    mu_k = 0.3
    s = cd.sensitivities(dropped(mu_k), [path], 1.5, rtol=1e-10)
    assert [e.kind for e in s.result.events] == ["landing", "stick"]
    exact = -U0 * (MC + MS) / (mu_k**2 * MS * G) if "mu" in path else \
        -U0 * MC / (mu_k * MS**2 * G)
    assert abs(s.event_times[0, 0]) <= 1e-9
    assert abs(s.event_times[1, 0] - exact) <= 1e-7 * abs(exact)


@pytest.mark.timeout(120)
def test_resting_slider_sticks_until_the_push_beats_static_friction():
    """At rest on the floor, pushed by 2 t N on the carriage: stuck from the start (a lock
    and a stick), slipping at mu_s m_s g / 2 within 1e-9 s; then lifted by 5 t N on the
    slider instead: lifting off (stuck) at m_s g / 5 within 1e-9 s (both measured 0 s)."""
    push = cd.Load("push", cd.Law("polynomial", coefficients=(0.0, 2.0)), joint="X")
    mech = cross_slide(FLOOR, cd.Friction(mu_static=0.4, mu_kinetic=0.3), 0.0, 0.0, 0.0,
                       [push])
    res = cd.run_dae(mech, 1.0, rtol=1e-10)
    assert [(e.kind, e.joint) for e in res.events][:3] == [
        ("lock", "K"), ("stick", "K:slide"), ("slip", "K:slide")]
    assert abs(res.events[2].t - 0.4 * MS * G / 2.0) <= 1e-9
    lift = cd.Load("lift", cd.Law("polynomial", coefficients=(0.0, 5.0)), joint="Y")
    res = cd.run_dae(mech.replace(loads={"lift": lift}), 1.0, rtol=1e-10)
    assert [(e.kind, e.joint) for e in res.events] == [
        ("lock", "K"), ("stick", "K:slide"), ("lift-off", "K")]
    assert abs(res.events[2].t - MS * G / 5.0) <= 1e-9
    assert res.configurations[res.events[2].after].locked == ()


def _hump_reference(x0: float, u0: float, mu_k: float):
    def solve(x, xd):
        f = math.sqrt(R * R - x * x)
        d1, d2 = -x / f, -R * R / f**3
        w, s = math.sqrt(1 + d1 * d1), math.copysign(1.0, xd)
        A = np.array([[MC + MS, (d1 + mu_k * s) / w], [MS * d1, -(1 - mu_k * s * d1) / w]])
        return np.linalg.solve(A, [0.0, -MS * (d2 * xd * xd + G)])

    def lift(_t, z):
        return solve(*z)[1]
    lift.terminal = True
    return solve_ivp(lambda _t, z: [z[1], solve(*z)[0]], (0.0, 3.0), [x0, u0],
                     method="DOP853", rtol=1e-13, atol=1e-15, dense_output=True,
                     events=lift)


@pytest.mark.timeout(120)
def test_slider_lifts_off_a_hump_with_friction():
    """Over a hump of radius 0.2 m with friction mu |N| (mu_k 0.2), started 0.02 m past its
    top at 0.5 m/s: the carriage's x within 1e-8 m of the reference until the lift-off, the
    lift-off within 1e-8 s of N's zero, the audit within 1e-8 J. Measured: 1.8e-10 m,
    2.9e-10 s, 5.2e-10 J."""
    ref = _hump_reference(0.02, 0.5, 0.2)
    t_lift = ref.t_events[0][0]
    mech = cross_slide(cd.Curve("circle", radius=R),
                       cd.Friction(mu_static=0.3, mu_kinetic=0.2), 0.02, 0.0, 0.5)
    res = cd.run_dae(mech, 0.6, rtol=1e-10, output_dt=0.005)
    assert [(e.kind, e.joint) for e in res.events] == [("lock", "K"), ("lift-off", "K")]
    assert abs(res.events[1].t - t_lift) <= 1e-8
    before = res.t < t_lift - 1e-6
    assert np.max(np.abs(res.joint("X").position[before] - ref.sol(res.t[before])[0])) \
        <= 1e-8
    assert np.max(np.abs(res.energy().residual)) <= 1e-8


@pytest.mark.timeout(120)
def test_slider_dropped_straight_down_lands_and_sticks_at_one_instant():
    """Dropped with no speed along the floor: the landing and the slide's stick at one
    instant, sqrt(2h/g) within 1e-9 s, on both integrators (fixed-step within 2e-3 s)."""
    mech = cross_slide(FLOOR, cd.Friction(mu_static=0.4, mu_kinetic=0.3), 0.0, H, 0.0)
    t1 = math.sqrt(2 * H / G)
    for res, tol in ((cd.run_dae(mech, 0.5, rtol=1e-10), 1e-9),
                     (cd.run_iterative(mech, 0.5, dt=1e-4), 2e-3)):
        assert [(e.kind, e.joint) for e in res.events] == [("landing", "K"),
                                                           ("stick", "K:slide")]
        assert res.events[0].t == res.events[1].t and abs(res.events[0].t - t1) <= tol
        assert res.configurations[res.events[1].after].locked == ("K", "K:slide")


@pytest.mark.timeout(180)
def test_sensitivities_through_slip_and_stuck_lift_off():
    """d t / d p of the slip of the pushed slider (t = mu_s m_s g / 2: d/d mu_s = m_s g / 2,
    d/d m_s = mu_s g / 2) and of the stuck slider's lift-off (t = m_s |g| / 5: d/d m_s =
    |g| / 5, d/d g_y = -m_s / 5) against those closed forms within 1e-9 relative; the
    lock and the stick at the start have none."""
    push = cd.Load("push", cd.Law("polynomial", coefficients=(0.0, 2.0)), joint="X")
    lift = cd.Load("lift", cd.Law("polynomial", coefficients=(0.0, 5.0)), joint="Y")
    friction = cd.Friction(mu_static=0.4, mu_kinetic=0.3)
    for load, params, t_end, exact in (
            (push, ["joints.K.friction.mu_static", "bodies.slider.mass"], 0.7,
             [MS * G / 2, 0.4 * G / 2]),
            (lift, ["bodies.slider.mass", "gravity.y"], 1.0, [G / 5, -MS / 5])):
        mech = cross_slide(FLOOR, friction, 0.0, 0.0, 0.0, [load])
        s = cd.sensitivities(mech, params, t_end, rtol=1e-10)
        assert [e.kind for e in s.result.events][:2] == ["lock", "stick"]
        assert np.all(s.event_times[:2] == 0.0)
        assert np.max(np.abs(s.event_times[2] - exact) / np.abs(exact)) <= 1e-9
