"""Contact joints (higher pairs): a point of one body on a circle or a line of another.

References, each independent of the code under test:

* a knife-edge follower on an eccentric circular cam turning at constant speed, in closed
  form: in contact its height is y(t) = e sin(wt) + sqrt(R^2 - e^2 cos^2(wt)); it lifts
  off where y'' = -g (the contact force m (y'' + g) / n_y reaches zero), flies freely
  (a parabola) and lands where the parabola meets y(t) again (plastic: it takes the cam's
  speed). The times are roots of these explicit functions (brentq to 1e-15 s).
* a rod pivoted at O whose slider runs in a circular slot about O (bilateral contact): a
  pendulum of inertia I_O, against DOP853 at rtol 1e-13; the slot's force on the slider
  is m (g cos(phi) + R phi'^2) (its radial equation).
* a crank driving a slotted lever (bilateral line contact): the lever's angle and the
  pin's place along the slot in closed form.
* a ball on a vertical guide dropped onto a ground line with restitution e: bounce times
  sqrt(2h/g) (1 + 2e + ... + 2e^k), ending on the Zeno rule at sqrt(2h/g) (1+e)/(1-e).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import cmm_dae as cd

from refs import spline_cam

E, R, W, G = 0.01, 0.04, 40.0, 9.81  # cam eccentricity m, radius m, speed rad/s; gravity
M_F = 0.2  # follower mass, kg


def cam_mechanism(**kw) -> cd.Mechanism:
    return cd.Mechanism(
        "cam", ground={"O": (0.0, 0.0)},
        bodies=[cd.Body("cam", 1.0, 1e-3, centroid=(E, 0.0), points={"O": (0, 0), "C": (E, 0)}),
                cd.Body("follower", M_F, 1e-4, points={"tip": (0.0, 0.0)},
                        guess=(0.0, 0.05, 0.0))],
        joints=[cd.Joint("A", "revolute", "ground.O", "cam.O"),
                cd.Joint("F", "prismatic", "ground.O", "follower.tip", axis=(0.0, 1.0)),
                cd.Joint("K", "contact", "cam.C", "follower.tip",
                         curve=cd.Curve("circle", radius=R), unilateral=True, **kw)],
        drivers=[cd.Driver("A", speed=W)],
        initial=cd.Initial(joints={"K": 0.0}, velocities={"K": 0.0}))


def _y(t):
    s, c = np.sin(W * t), np.cos(W * t)
    return E * s + np.sqrt(R**2 - E**2 * c**2)


def _yd(t):
    s, c = np.sin(W * t), np.cos(W * t)
    return W * (E * c + E**2 * c * s / np.sqrt(R**2 - E**2 * c**2))


def _ydd(t):
    s, c = np.sin(W * t), np.cos(W * t)
    D = R**2 - E**2 * c**2
    return W**2 * (-E * s + E**2 * (c * c - s * s) / np.sqrt(D) - (E**2 * c * s) ** 2 / D**1.5)


def _root(f, a: float, b: float, step: float = 1e-4) -> float:
    """First downward zero of f after a (to 1e-15 s)."""
    x = np.arange(a, b, step)
    i = int(np.nonzero(f(x) < 0)[0][0])
    return brentq(f, x[i - 1], x[i], xtol=1e-15, rtol=1e-15)


def _circle_normal_y(t: float) -> float:
    """The eccentric circle's normal's vertical part where the follower touches it."""
    return (float(_y(t)) - E * math.sin(W * t)) / R


def cam_reference(t_end: float, y=_y, yd=_yd, ydd=_ydd, normal_y=_circle_normal_y):
    """[(t, kind, approach speed)] of the lift-offs and landings, and the height y(t), of
    a follower whose height in contact is ``y(t)`` (rate ``yd``, acceleration ``ydd``),
    its gap's rate ``normal_y(t)`` times the relative vertical speed."""
    _y, _yd, _ydd = y, yd, ydd
    events, flights = [], []
    t = 0.0
    while True:
        t_off = _root(lambda s: _ydd(s) + G, t + 1e-9, t + 0.3)
        if t_off > t_end:
            break
        events.append((t_off, "lift-off", 0.0))
        y0, v0 = float(_y(t_off)), float(_yd(t_off))

        def gap(s, y0=y0, v0=v0, t0=t_off):
            return y0 + v0 * (s - t0) - 0.5 * G * (s - t0) ** 2 - _y(s)

        t = _root(gap, t_off + 1e-6, t_off + 0.3)
        flights.append((t_off, t, y0, v0))
        if t > t_end:
            break
        # the gap's rate at the landing: n_y (v_follower - y'), n the cam's normal there
        events.append((t, "landing", normal_y(t) * (v0 - G * (t - t_off) - float(_yd(t)))))
        assert _ydd(t) + G > 0  # it stays on the cam after the landing

    def height(s):
        out = _y(s)
        for a, b, y0, v0 in flights:
            m = (s > a) & (s < b)
            out[m] = y0 + v0 * (s[m] - a) - 0.5 * G * (s[m] - a) ** 2
        return out

    return events, height


@pytest.fixture(scope="module")
def cam_run():
    return cd.run_dae(cam_mechanism(), 2.0, rtol=1e-10, output_dt=1e-3)


def test_cam_follower_lift_off_and_landing_times_and_height(cam_run):
    """Over 12.7 cam turns (25 events): every lift-off and landing within 1e-8 s of the
    closed form, the follower's height within 1e-8 m away from them (measured 6e-12 s
    and 4e-12 m at rtol 1e-10), each landing's approach speed and energy lost (the
    follower's 1/2 m (v-^2 - v+^2): the cam is driven) within 1e-7."""
    ref, height = cam_reference(2.0)
    got = [e for e in cam_run.events if e.kind in ("lift-off", "landing")]
    assert [e.kind for e in got] == [k for _, k, _ in ref]
    assert len(got) == 25
    assert cam_run.events[0].kind == "lock" and cam_run.events[0].t == 0.0  # starts touching
    for e, (t, kind, v) in zip(got, ref, strict=True):
        assert abs(e.t - t) <= 1e-8
        if kind == "landing":
            assert e.velocity_before == pytest.approx(v, abs=1e-7)  # the gap's rate
            assert e.velocity_after == 0.0
            v_cam = float(_yd(t))
            v_f = v_cam + v * R / (float(_y(t)) - E * math.sin(W * t))
            lost = 0.5 * M_F * (v_f**2 - v_cam**2)
            assert e.energy_lost == pytest.approx(lost, abs=1e-8)
    t = cam_run.t
    far = np.min(np.abs(t[:, None] - np.array([x for x, _, _ in ref])[None, :]), axis=1) > 1e-6
    y = cam_run.joint("F").position
    assert np.max(np.abs(y - height(t))[far]) <= 1e-8


def test_cam_follower_contact_force(cam_run):
    """In contact the force on the follower is along the cam's normal n with
    N n_y = m (y'' + g); in flight it is zero. Within 1e-6 N of the closed form."""
    ref, _ = cam_reference(2.0)
    t = cam_run.t
    F = cam_run.joint("K").force
    y = cam_run.joint("F").position
    times = [x for x, _, _ in ref]
    k = np.searchsorted(times, t)  # events before each sample: even = in contact
    far = np.min(np.abs(t[:, None] - np.array(times)[None, :]), axis=1) > 1e-6
    touching = far & (k % 2 == 0)
    flying = far & (k % 2 == 1)
    assert touching.sum() > 500 and flying.sum() > 500
    ny = (y - E * np.sin(W * t)) / R
    assert np.max(np.abs(F[touching, 1] - M_F * (_ydd(t) + G)[touching])) <= 1e-6
    nx = -E * np.cos(W * t) / R
    assert np.max(np.abs(F[touching, 0] * ny[touching] - F[touching, 1] * nx[touching])) <= 1e-6
    assert np.max(np.abs(F[flying])) == 0.0


def test_cam_follower_iterative_algorithm():
    """The fixed-step algorithm at dt 1e-4 s: the same 25 events, each within 2e-3 s
    (measured 2e-4 s)."""
    ref, _ = cam_reference(2.0)
    res = cd.run_iterative(cam_mechanism(), 2.0, dt=1e-4)
    got = [e for e in res.events if e.kind in ("lift-off", "landing")]
    assert [e.kind for e in got] == [k for _, k, _ in ref]
    assert max(abs(e.t - t) for e, (t, _, _) in zip(got, ref, strict=True)) <= 2e-3


@pytest.mark.parametrize("path", ["bodies.cam.points.C.x", "joints.K.curve.radius",
                                  "drivers.A.speed"])
def test_cam_follower_sensitivities_through_lift_off_and_landing(path):
    """d t_event / d p through three lift-offs and landings against central differences
    (h 1e-5 relative, runs at rtol 1e-12): within 2e-6 of the largest derivative
    (measured 5e-8, 4e-7, 2e-8)."""
    mech = cam_mechanism()
    s = cd.sensitivities(mech, [path], 0.5, rtol=1e-11)
    kinds = [e.kind for e in s.result.events]
    assert kinds.count("landing") == 3 and kinds.count("lift-off") == 4
    fd = _fd_event_times(mech, path, 0.5)
    assert np.max(np.abs(s.event_times[:, 0] - fd)) <= 2e-6 * np.max(np.abs(fd))


def _fd_event_times(mech: cd.Mechanism, path: str, t_end: float) -> np.ndarray:
    """d t_event / d p by central differences (h 1e-5 relative, runs at rtol 1e-12)."""
    from cmm_dae.description.params import param_value

    x0 = param_value(mech, path)
    h = 1e-5 * abs(x0)
    ts = [np.array([e.t for e in cd.run_dae(cd.with_params(mech, {path: x}), t_end,
                                           rtol=1e-12).events]) for x in (x0 + h, x0 - h)]
    return (ts[0] - ts[1]) / (2 * h)


def test_spline_cam_against_its_profile(capfd):
    """A cam whose profile is a closed spline through 48 points of r = 30 + 6 cos(phi) +
    2 sin(3 phi) mm about its pivot, turning at 30 rad/s under a knife-edge follower on
    the vertical through the pivot: in contact the follower's height is the profile's
    radius at the polar angle pi/2 - w t, y = S(pi/2 - w t) with S the same periodic
    cubic spline built by scipy (independently of the CasADi pieces the model evaluates).
    Lift-offs and landings over 2 s within 1e-8 s of that reference (measured 4.2e-10 s
    over 57), the height within 1e-8 m between them (2.7e-11 m). The run prints nothing
    (SUNDIALS warned on standard output that a root function stayed 0 after a lift-off)."""
    from scipy.interpolate import CubicSpline

    w = 30.0
    mech = spline_cam(w, M_F)
    S = CubicSpline(*mech.joints["K"].curve.polar(), bc_type="periodic")
    turn = 2 * math.pi

    def y(t):
        return S(np.mod(math.pi / 2 - w * np.asarray(t, float), turn))

    def yd(t):
        return -w * S(np.mod(math.pi / 2 - w * np.asarray(t, float), turn), 1)

    def ydd(t):
        return w * w * S(np.mod(math.pi / 2 - w * np.asarray(t, float), turn), 2)

    ref, height = cam_reference(2.0, y, yd, ydd, lambda t: 1.0)
    res = cd.run_dae(mech, 2.0, rtol=1e-10, output_dt=1e-3)
    got = [e for e in res.events if e.kind in ("lift-off", "landing")]
    assert [e.kind for e in got] == [k for _, k, _ in ref] and len(got) >= 10
    assert max(abs(e.t - t) for e, (t, _, _) in zip(got, ref, strict=True)) <= 1e-8
    far = np.min(np.abs(res.t[:, None] - np.array([x for x, _, _ in ref])[None, :]),
                 axis=1) > 1e-6
    assert np.max(np.abs(res.joint("F").position - height(res.t))[far]) <= 1e-8
    assert capfd.readouterr() == ("", "")


# ------------------------------------------------------------------ bilateral contacts
RS, MS, MR = 0.6, 0.3, 1.0  # slot radius m, slider and rod masses kg


def slot_pendulum(limits=None) -> cd.Mechanism:
    return cd.Mechanism(
        "slot", ground={"O": (0.0, 0.0)},
        bodies=[cd.Body("rod", MR, 1 / 12, centroid=(0.5, 0.0), points={"O": (0, 0)}),
                cd.Body("slider", MS, 1e-4, points={"P": (0, 0)}, guess=(0.0, -RS, 0.0))],
        joints=[cd.Joint("A", "revolute", "ground.O", "rod.O"),
                cd.Joint("S", "prismatic", "rod.O", "slider.P"),
                cd.Joint("K", "contact", "ground.O", "slider.P", side="inside",
                         curve=cd.Curve("circle", radius=RS), limits=limits)],
        initial=cd.Initial(joints={"A": -math.pi / 2 + 1.0}))


def slot_with_friction() -> cd.Mechanism:
    """The slot pendulum with friction mu |N| in the slot (mu_s 0.25, mu_k 0.2)."""
    mech = slot_pendulum()
    slot = mech.joints["K"]
    return mech.replace(joints={**mech.joints, "K": cd.Joint(
        "K", "contact", slot.first, slot.second, side="inside", curve=slot.curve,
        friction=cd.Friction(mu_static=0.25, mu_kinetic=0.2))})


def _pendulum(t_end: float, **kw):
    k = (MR * G * 0.5 + MS * G * RS) / (MR / 3 + MS * RS**2 + 1e-4)
    return solve_ivp(lambda t, y: [y[1], -k * math.sin(y[0])], (0.0, t_end), [1.0, 0.0],
                     method="DOP853", rtol=1e-13, atol=1e-14, dense_output=True, **kw)


def test_slider_in_a_circular_slot_against_the_pendulum():
    """The slot's arc length R (phi - pi/2) within 1e-8 m of R times the pendulum's angle
    (measured 8e-10), the slot's force m (g cos(phi) + R phi'^2) within 1e-7 N (9e-9),
    the energy audit within 1e-7 J over 3 s."""
    res = cd.run_dae(slot_pendulum(), 3.0, rtol=1e-10, output_dt=0.01)
    assert res.events == []
    ref = _pendulum(3.0)
    phi, om = ref.sol(res.t)
    assert np.max(np.abs(res.joint("K").position - RS * (phi - math.pi / 2))) <= 1e-8
    N = np.hypot(*res.joint("K").force.T)
    assert np.max(np.abs(N - MS * (G * np.cos(phi) + RS * om**2))) <= 1e-7
    assert abs(res.energy().residual[-1]) <= 1e-7


def _slot_reference(mu_s: float, mu_k: float, t_end: float):
    """The pendulum with the slot's friction mu_k N R against its rate (N the slot's normal
    force, explicit in phi and phi'), segment by segment between reversals (DOP853, rtol
    1e-13); a reversal where static friction mu_s N R holds the gravity torque sticks."""
    I = MR / 3 + MS * RS**2 + 1e-4
    k = MR * G * 0.5 + MS * G * RS

    def rhs(t, y, s):
        N = MS * (G * math.cos(y[0]) + RS * y[1] ** 2)
        return [y[1], (-k * math.sin(y[0]) - s * mu_k * RS * abs(N)) / I]

    t, y, s, segs, turns = 0.0, np.array([1.0, 0.0]), -1.0, [], []
    while True:
        def rest(tt, yy, s):
            return yy[1]

        rest.terminal, rest.direction = True, (1.0 if s < 0 else -1.0)
        sol = solve_ivp(rhs, (t, t_end), y, args=(s,), method="DOP853", rtol=1e-13,
                        atol=1e-14, dense_output=True, events=rest)
        segs.append(sol)
        if not sol.t_events[0].size:
            break
        t, y = float(sol.t_events[0][0]), np.array([sol.y_events[0][0][0], 0.0])
        turns.append(t)
        assert abs(k * math.sin(y[0])) > mu_s * RS * MS * G * math.cos(y[0])  # slips on
        s = -s

    def angle(tt):
        out = np.full(tt.shape, np.nan)
        for sol in segs:
            m = (tt >= sol.t[0]) & (tt <= sol.t[-1])
            out[m] = sol.sol(tt[m])[0]
        return out

    return turns, angle


def test_friction_in_a_slot_from_its_contact_force():
    """The slot's friction mu |N| (mu_k 0.2, mu_s 0.25), N the contact force, which grows
    with phi'^2: the seven reversals within 1e-8 s of the reference (measured 8e-12 s), the
    angle within 1e-8 rad (1e-10), the energy audit within 1e-8 J (4.6e-10) of 3 J lost
    to friction."""
    res = cd.run_dae(slot_with_friction(), 6.0, rtol=1e-11, output_dt=0.01)
    turns, angle = _slot_reference(0.25, 0.2, 6.0)
    slips = [e for e in res.events if e.kind == "slip" and e.t > 0]
    assert len(slips) == len(turns) == 7
    assert max(abs(e.t - t) for e, t in zip(slips, turns, strict=True)) <= 1e-8
    phi = res.joint("K").position / RS + math.pi / 2
    assert np.max(np.abs(phi - angle(res.t))) <= 1e-8
    e = res.energy()
    assert np.max(np.abs(e.residual)) <= 1e-8 and e.friction_loss[-1] > 2.5


def test_slot_end_is_a_stop():
    """A slot ending 0.7 rad past the bottom: the slider reaches it when the pendulum
    does (within 1e-8 s), locks plastically and is released at once (gravity pulls it
    back), as a prismatic joint's limit."""
    end = -math.pi / 2 - 0.7
    res = cd.run_dae(slot_pendulum(cd.Limits(lower=RS * end)), 1.0, rtol=1e-10)

    def at_end(t, y):
        return y[0] + 0.7

    at_end.terminal = True
    t_ref = float(_pendulum(3.0, events=at_end).t_events[0][0])
    assert [e.kind for e in res.events[:2]] == ["limit", "release"]
    assert abs(res.events[0].t - t_ref) <= 1e-8
    assert res.events[0].side == "lower"


def test_crank_and_slotted_lever_kinematics():
    """A crank (0.1 m, driven at 2 rad/s) whose pin runs in a slot along a lever pivoted
    0.3 m below the crank's pivot: the lever's angle atan2(d + r sin, r cos) and the pin's
    place along the slot |P - O2| within 1e-9 of the closed form."""
    r, d = 0.1, 0.3
    mech = cd.Mechanism(
        "slotted_lever", ground={"O1": (0.0, 0.0), "O2": (0.0, -d)},
        bodies=[cd.Body("crank", 0.5, 1e-3, points={"O": (0, 0), "P": (r, 0)}),
                cd.Body("lever", 1.0, 0.03, centroid=(0.2, 0.0), points={"O": (0, 0)},
                        guess=(0.0, -d, math.pi / 2))],
        joints=[cd.Joint("A", "revolute", "ground.O1", "crank.O"),
                cd.Joint("B", "revolute", "ground.O2", "lever.O"),
                cd.Joint("K", "contact", "lever.O", "crank.P",
                         curve=cd.Curve("line", direction=(1.0, 0.0)))],
        drivers=[cd.Driver("A", speed=2.0)])
    res = cd.run_dae(mech, 3.0, rtol=1e-10, output_dt=0.05)
    th = 2.0 * res.t
    px, py = r * np.cos(th), r * np.sin(th) + d
    psi = np.unwrap(np.arctan2(py, px))
    assert np.max(np.abs(res.joint("B").position - psi)) <= 1e-9
    assert np.max(np.abs(res.joint("K").position - np.hypot(px, py))) <= 1e-9


def test_ball_bounces_on_a_line_then_lands():
    """Restitution 0.5 from 0.2 m: the bounces at sqrt(2h/g)(1 + 2e + ... + 2e^k) within
    1e-8 s (measured 8e-9 after 18 bounces), each leaving at e times its arrival speed;
    the Zeno rule ends them with a landing before their limit sqrt(2h/g)(1 + e)/(1 - e)
    (within 1e-5 s of it: measured 1.5e-6 s), where the ball rests."""
    h0, e = 0.2, 0.5
    mech = cd.Mechanism(
        "ball", ground={"O": (0.0, 0.0)},
        bodies=[cd.Body("ball", 0.1, 1e-5, points={"B": (0, 0)}, guess=(0.0, h0, 0.0))],
        joints=[cd.Joint("G", "prismatic", "ground.O", "ball.B", axis=(0.0, 1.0)),
                cd.Joint("K", "contact", "ground.O", "ball.B", unilateral=True,
                         restitution=e, curve=cd.Curve("line", direction=(1.0, 0.0)))],
        initial=cd.Initial(joints={"G": h0}))
    res = cd.run_dae(mech, 1.0, rtol=1e-10)
    t1 = math.sqrt(2 * h0 / G)
    bounces = [x for x in res.events if x.kind == "bounce"]
    assert len(bounces) >= 10 and res.events[-1].kind == "landing"
    ref = t1 * np.r_[1.0, 1.0 + 2 * np.cumsum(e ** np.arange(1, len(bounces)))]
    assert np.max(np.abs(np.array([x.t for x in bounces]) - ref)) <= 1e-8
    for x in bounces:
        assert x.velocity_after == pytest.approx(-e * x.velocity_before, rel=1e-9)
    t_lim = t1 * (1 + e) / (1 - e)
    assert bounces[-1].t < res.events[-1].t < t_lim
    assert t_lim - res.events[-1].t <= 1e-5
    assert res.joint("G").position[-1] == pytest.approx(0.0, abs=1e-12)


# ------------------------------------------------------------------ the file format
CAM_FILE = """
[mechanism]
name = "cam"
[ground.points]
O = [0.0, 0.0]
[bodies.cam]
mass = 1.0
inertia = 1e-3
centroid = [0.01, 0.0]
points = { O = [0.0, 0.0], C = [0.01, 0.0] }
[bodies.follower]
mass = 0.2
inertia = 1e-4
points = { tip = [0.0, 0.0] }
guess = [0.0, 0.05, 0.0]
[joints.A]
type = "revolute"
connects = ["ground.O", "cam.O"]
[joints.F]
type = "prismatic"
connects = ["ground.O", "follower.tip"]
axis = [0.0, 1.0]
[joints.K]
type = "contact"
connects = ["cam.C", "follower.tip"]
curve = { kind = "circle", radius = 0.04 }
unilateral = true
[drivers.A]
motion = "constant_speed"
initial = 0.0
speed = 40.0
[initial]
joints = { K = 0.0 }
velocities = { K = 0.0 }
"""


def test_contact_from_a_file_runs_as_built_in_python(tmp_path):
    f = tmp_path / "cam.toml"
    f.write_text(CAM_FILE)
    mech = cd.load(f)
    j = mech.joints["K"]
    assert (j.type, j.curve, j.side, j.unilateral) == ("contact", cd.Curve("circle", 0.04),
                                                       "outside", True)
    assert mech.limited_joints == ["K"] and j.stops == cd.Limits(lower=0.0)
    a = cd.run_dae(mech, 0.3, rtol=1e-10)
    b = cd.run_dae(cam_mechanism(), 0.3, rtol=1e-10)
    assert [e.kind for e in a.events] == [e.kind for e in b.events]
    assert max(abs(x.t - y.t) for x, y in zip(a.events, b.events, strict=True)) <= 1e-12


@pytest.mark.parametrize("old, new, message", [
    ('curve = { kind = "circle", radius = 0.04 }\n', "",
     r"\[joints\.K\] curve: missing"),
    ('kind = "circle"', 'kind = "circel"', r"\[joints\.K\.curve\] kind: expected one of "
     r"circle, line, spline, got 'circel'; did you mean 'circle'\?"),
    ("radius = 0.04", "radius = -0.04", r"\[joints\.K\] curve\.radius: expected a radius > 0"),
    ("unilateral = true", 'unilateral = "yes"', r"\[joints\.K\] unilateral: expected true "
     "or false"),
    ("unilateral = true", "unilateral = true\nlimits = { lower = 0.0 }",
     r"\[joints\.K\] limits: a unilateral contact's stop is its curve"),
    ('connects = ["ground.O", "cam.O"]', 'connects = ["ground.O", "cam.O"]\nside = "inside"',
     r"\[joints\.A\] side: only a contact joint has this key"),
    ("unilateral = true", 'unilateral = true\nside = "above"',
     r"\[joints\.K\] side: expected one of outside, inside, left, right, got 'above'"),
    ('kind = "circle", radius = 0.04 }',
     'kind = "spline", points = [[0.04, 0.0], [0.0, 0.04], [-0.04, 0.0]] }',
     r"\[joints\.K\] curve\.points: expected at least 4 points"),
    ('kind = "circle", radius = 0.04 }',
     'kind = "spline", points = [[0.04, 0.0], [0.0, -0.04], [-0.04, 0.0], [0.0, 0.04]] }',
     r"\[joints\.K\] curve\.points: expected the points counter-clockwise"),
    ('kind = "circle", radius = 0.04 }',
     'kind = "spline", closed = false, points = [[0.0, 0.04], [0.01, 0.05], [0.02, 0.04], '
     '[0.03, 0.05]] }',
     r"\[joints\.K\] curve\.closed: an open curve is for a bilateral contact"),
    ('kind = "circle", radius = 0.04 }\nunilateral = true',
     'kind = "spline", closed = false, points = [[0.0, 0.04], [0.02, 0.05], [0.01, 0.04], '
     '[0.03, 0.05]] }',
     r"\[joints\.K\] curve\.points: expected an open curve's points in increasing x"),
    ('kind = "circle", radius = 0.04 }\nunilateral = true',
     'kind = "spline", closed = false, points = [[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], '
     '[0.3, 0.0]] }\nlimits = { upper = 0.31 }',
     r"\[joints\.K\] limits: expected limits within the open curve's ends, 0 to 0\.3 m"),
    ('kind = "circle", radius = 0.04 }',
     'kind = "spline", closed = "no", points = [[0.04, 0.0], [0.0, 0.04], [-0.04, 0.0], '
     '[0.0, -0.04]] }',
     r"\[joints\.K\.curve\] closed: expected true or false, got 'no'"),
    ("unilateral = true", "unilateral = true\naxis = [1.0, 0.0]",
     r"\[joints\.K\] axis: only a prismatic joint has this key"),
])
def test_contact_file_errors(tmp_path, old, new, message):
    assert old in CAM_FILE
    f = tmp_path / "bad.toml"
    f.write_text(CAM_FILE.replace(old, new))
    with pytest.raises(cd.ModelError, match=message) as err:
        cd.load(f)
    assert "bad.toml" in str(err.value)


def test_a_unilateral_contact_cannot_be_driven():
    mech = cam_mechanism()
    with pytest.raises(cd.ModelError, match=r"\[drivers\.K\].*unilateral contact"):
        mech.replace(drivers={**mech.drivers, "K": cd.Driver("K")})


def test_shipped_valve_train_floats_and_lands():
    """The shipped valve train at 400 rad/s: each turn a lift-off, bounces whose
    rebound is 0.2 of the arrival, and a landing (Zeno rule); the energy audit closes
    within 1e-6 J of the 0.7 J lost in the impacts (measured 3.4e-7 J)."""
    res = cd.run_dae(cd.load(cd.example("cam_valve_train")), 0.05)
    kinds = [e.kind for e in res.events]
    assert kinds.count("lift-off") == 3 and kinds.count("landing") == 3
    assert kinds.count("bounce") >= 6
    for e in res.events:
        if e.kind == "bounce":
            assert e.velocity_after == pytest.approx(-0.2 * e.velocity_before, rel=1e-9)
    en = res.energy()
    assert en.impact_losses[-1] > 0.5
    assert np.max(np.abs(en.residual)) <= 1e-6


def test_shipped_slotted_link_locks_at_the_slot_ends():
    """The shipped slotted link: the pin locks at alternate ends of its slot (mobility 1
    -> 0) and leaves each when the motor's torque turns; the fixed-step algorithm at dt
    1e-4 s has the same events within 1e-3 s (measured 4.2e-4 s)."""
    mech = cd.load(cd.example("slotted_link"))
    res = cd.run_dae(mech, 4.0)
    assert [e.kind for e in res.events] == ["limit", "release"] * 4 + ["limit"]
    assert [e.side for e in res.events[::2]] == ["lower", "upper", "lower", "upper", "lower"]
    assert {res.configurations[e.after].dof for e in res.events if e.kind == "limit"} == {0}
    assert {res.configurations[e.after].dof for e in res.events if e.kind == "release"} == {1}
    ends = {"lower": 0.12, "upper": 0.30}
    k = res.joint("K").position
    for e in res.events:
        if e.kind == "limit":
            i = np.searchsorted(res.t, e.t)
            assert k[i] == pytest.approx(ends[e.side], abs=1e-9)
    it = cd.run_iterative(mech, 4.0, dt=1e-4)
    assert [e.kind for e in it.events] == [e.kind for e in res.events]
    assert max(abs(a.t - b.t) for a, b in zip(it.events, res.events, strict=True)) <= 1e-3


@pytest.mark.parametrize("path", ["joints.K.friction.mu_kinetic", "joints.K.curve.radius"])
def test_slot_friction_sensitivities_through_reversals(path):
    """d t_reversal / d p through the slot friction's slips (mu |N|, N the contact force)
    against central differences (h 1e-5 relative, rtol 1e-12): within 1e-5 of the largest
    derivative (measured 1.4e-6 and 1.6e-6)."""
    mech = slot_with_friction()
    s = cd.sensitivities(mech, [path], 3.0, rtol=1e-11)
    assert [e.kind for e in s.result.events].count("slip") == 4
    fd = _fd_event_times(mech, path, 3.0)
    assert np.max(np.abs(s.event_times[:, 0] - fd)) <= 1e-5 * np.max(np.abs(fd))
