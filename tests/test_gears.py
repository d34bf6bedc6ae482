"""Gear pairs and rack and pinion (``type = "gear"``): the motion against the torque
balance reduced to the first joint, the tooth force along the line of action against each
gear's own torque balance, and the bearings' loads against each body's force balance.

Two gears on fixed axles, ratio r = -z_A/z_B, a motor torque T_A and a brake T_B:
(I_A + r^2 I_B) alpha_A = T_A + r T_B (virtual work); the tooth torque on B is
tau_B = I_B r alpha_A - T_B, the tooth force |tau_B| / (R_B cos(pressure angle)) at the
pitch point (R_B = distance / (1 + |r|)), tangential tau_B / R_B, radial (apart) its
tan(pressure angle) times; each axle's bearing carries the gear's weight and the tooth
force. All closed forms, each to 1e-9 relative.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import cmm_dae as cd

from refs import gear_pair

PA = math.radians(20.0)


def test_gear_pair_motion_tooth_force_and_bearings():
    res = cd.run_dae(gear_pair(), 0.2, rtol=1e-10, output_dt=0.05)
    r, IA, IB = -0.5, 1e-4, 2e-3
    alpha = (2.0 + r * -1.0) / (IA + r * r * IB)
    assert np.allclose(res.joint("A").acceleration, alpha, rtol=1e-9)
    assert np.allclose(res.joint("B").position, r * res.joint("A").position, rtol=1e-9,
                       atol=1e-12)
    tau_b = IB * r * alpha + 1.0
    R_b = 0.09 / 1.5
    F = res.gear("Z").force
    # on B (axle at +x of A's): tangential -tau_B / R_B along +y, radial +x (apart)
    assert np.allclose(F, [abs(tau_b) * math.tan(PA) / R_b, -tau_b / R_b], rtol=1e-9)
    assert np.allclose(res.gear("Z").magnitude, abs(tau_b) / (R_b * math.cos(PA)), rtol=1e-9)
    g = 9.81
    assert np.allclose(res.joint("B").force, -F + [0.0, 0.8 * g], rtol=1e-9, atol=1e-9)
    assert np.allclose(res.joint("A").force, F + [0.0, 0.2 * g], rtol=1e-9, atol=1e-9)
    assert abs(res.energy().residual[-1]) <= 1e-9
    it = cd.run_iterative(gear_pair(), 0.2, dt=1e-3)
    assert np.allclose(it.joint("A").acceleration, alpha, rtol=1e-9)


def internal_pair(ring_first: bool) -> cd.Mechanism:
    """A pinion of pitch radius 3 cm inside a ring gear of 9 cm: axles 6 cm apart, the
    ring's at the origin; ``ring_first``: the ring is the first joint (ratio 3), else
    the pinion (ratio 1/3)."""
    pinion = ("P", cd.Body("pinion", 0.2, 1e-4, points={"O": (0, 0)}), "ground.P")
    ring = ("R", cd.Body("ring", 0.8, 2e-3, points={"O": (0, 0)}), "ground.R")
    a, b = (ring, pinion) if ring_first else (pinion, ring)
    return cd.Mechanism(
        "internal", ground={"R": (0.0, 0.0), "P": (0.06, 0.0)},
        bodies=[a[1], b[1]],
        joints=[cd.Joint(x[0], "revolute", x[2], f"{x[1].name}.O") for x in (a, b)],
        gears=[cd.Gear("Z", a[0], b[0], ratio=3.0 if ring_first else 1.0 / 3.0)],
        initial=cd.Initial(joints={a[0]: 0.0}),
        loads=[cd.Load("motor", cd.Law(value=2.0), joint=a[0]),
               cd.Load("brake", cd.Law(value=-1.0), joint=b[0])])


@pytest.mark.parametrize("ring_first", [False, True])
def test_internal_gear_pair(ring_first):
    """A pinion inside a ring gear (ratio +z_first / z_second: both turn the same way).
    The motion against the torque balance; the tooth force on the second gear: its moment
    about that gear's axle is the tooth torque from the gear's own balance, it acts at the
    pitch point (on the line of centres, 3 cm beyond the pinion's axle from the ring's),
    and its radial part, tan(20 deg) of the tangential, pushes the pinion towards its
    own axle (the ring away from its own); each bearing against its gear's balance;
    energy audit. All to 1e-9 relative."""
    r = 3.0 if ring_first else 1.0 / 3.0
    IA, IB = (2e-3, 1e-4) if ring_first else (1e-4, 2e-3)
    res = cd.run_dae(internal_pair(ring_first), 0.2, rtol=1e-10, output_dt=0.05)
    first, second = ("R", "P") if ring_first else ("P", "R")
    alpha = (2.0 + r * -1.0) / (IA + r * r * IB)
    assert np.allclose(res.joint(first).acceleration, alpha, rtol=1e-9)
    assert np.allclose(res.joint(second).position, r * res.joint(first).position,
                       rtol=1e-9, atol=1e-12)
    tau_b = IB * r * alpha + 1.0  # the teeth's torque on the second gear
    F = res.gear("Z").force
    pitch = np.array([0.09, 0.0])  # P: on the ring's pitch circle, beyond the pinion
    axle_b = np.array([0.06, 0.0]) if ring_first else np.array([0.0, 0.0])
    arm = pitch - axle_b
    assert np.allclose(arm[0] * F[:, 1] - arm[1] * F[:, 0], tau_b, rtol=1e-9)
    radial = F[:, 0]  # the line of centres is the x axis
    # on the pinion (the second gear, or the reaction -F on the first) towards its axle
    on_pinion = radial if ring_first else -radial
    assert np.allclose(on_pinion, -abs(F[:, 1]) * math.tan(PA), rtol=1e-9)
    assert np.allclose(res.gear("Z").magnitude, np.abs(F[:, 1]) / math.cos(PA), rtol=1e-9)
    g, m_b, m_a = 9.81, (0.2 if ring_first else 0.8), (0.8 if ring_first else 0.2)
    assert np.allclose(res.joint(second).force, -F + [0.0, m_b * g], rtol=1e-9, atol=1e-9)
    assert np.allclose(res.joint(first).force, F + [0.0, m_a * g], rtol=1e-9, atol=1e-9)
    assert abs(res.energy().residual[-1]) <= 1e-9


def rack_and_pinion() -> cd.Mechanism:
    rp = 0.05
    return cd.Mechanism(
        "rack", ground={"P": (0.0, 0.0), "G": (0.0, -rp)},
        bodies=[cd.Body("pinion", 0.3, 1e-3, points={"O": (0, 0)}),
                cd.Body("rack", 2.0, 0.05, points={"R": (0, 0)}, guess=(0.0, -rp, 0.0))],
        joints=[cd.Joint("P", "revolute", "ground.P", "pinion.O"),
                cd.Joint("X", "prismatic", "ground.G", "rack.R")],
        gears=[cd.Gear("Z", "P", "X", ratio=-rp)], initial=cd.Initial(joints={"P": 0.0}),
        loads=[cd.Load("motor", cd.Law(value=1.0), joint="P"),
               cd.Load("push", cd.Law(value=5.0), joint="X")])


def test_rack_and_pinion():
    """A pinion (radius 5 cm, motor 1 N m) driving a 2 kg rack against a 5 N push: the
    rack force m a - push along the guide, the teeth pushing the rack off the pinion by
    tan(pressure angle) of it, the guide's normal force and moment balancing them."""
    rp, mr, Ip = 0.05, 2.0, 1e-3
    res = cd.run_dae(rack_and_pinion(), 0.3, rtol=1e-10, output_dt=0.05)
    alpha = (1.0 - rp * 5.0) / (Ip + rp**2 * mr)
    assert np.allclose(res.joint("P").acceleration, alpha, rtol=1e-9)
    ft = mr * (-rp * alpha) - 5.0
    F = res.gear("Z").force
    assert np.allclose(F, [ft, -abs(ft) * math.tan(PA)], rtol=1e-9)
    assert np.allclose(res.joint("X").force, [0.0, mr * 9.81 + abs(ft) * math.tan(PA)],
                       rtol=1e-9, atol=1e-9)
    # the guide's moment about the rack's point balances the tooth force at (0, -rp)
    arm = np.column_stack([-res.joint("X").position, np.zeros(res.t.size)])
    moment = arm[:, 0] * F[:, 1] - arm[:, 1] * F[:, 0]
    assert np.allclose(res.joint("X").torque, -moment, rtol=1e-9, atol=1e-12)
    # the pinion's bearing: its weight and the teeth's reaction -F
    assert np.allclose(res.joint("P").force, F + [0.0, 0.3 * 9.81], rtol=1e-9, atol=1e-9)


GEAR_FILE = """
[mechanism]
name = "gears"
[ground.points]
A = [0.0, 0.0]
B = [0.09, 0.0]
[bodies.ga]
mass = 0.2
inertia = 1e-4
points = { O = [0.0, 0.0] }
[bodies.gb]
mass = 0.8
inertia = 2e-3
points = { O = [0.0, 0.0] }
[joints.A]
type = "revolute"
connects = ["ground.A", "ga.O"]
[joints.B]
type = "revolute"
connects = ["ground.B", "gb.O"]
[joints.Z]
type = "gear"
connects = ["A", "B"]
ratio = -0.5
[loads.motor]
joint = "A"
law = "constant"
value = 2.0
[loads.brake]
joint = "B"
law = "constant"
value = -1.0
[initial]
joints = { A = 0.0 }
"""


def test_gear_pair_from_a_file(tmp_path):
    f = tmp_path / "gears.toml"
    f.write_text(GEAR_FILE)
    mech = cd.load(f)
    assert mech.gears["Z"] == cd.Gear("Z", "A", "B", -0.5)
    assert "Z" not in mech.joints
    a = cd.run_dae(mech, 0.1, rtol=1e-10, output_dt=0.05)
    b = cd.run_dae(gear_pair(), 0.1, rtol=1e-10, output_dt=0.05)
    assert np.array_equal(a.gear("Z").force, b.gear("Z").force)
    assert cd.structure(mech).mobility == 1


@pytest.mark.parametrize("old, new, message", [
    ('connects = ["A", "B"]', 'connects = ["A", "C"]', r"\[joints\.Z\] connects: unknown "
     "joint 'C'"),
    ("ratio = -0.5", "ratio = 1.0", r"\[joints\.Z\] ratio: expected a ratio other than 1"),
    ("ratio = -0.5", "ratio = 0.0", r"\[joints\.Z\] ratio: expected a finite non-zero"),
    ("ratio = -0.5\n", "", r"\[joints\.Z\] ratio: missing"),
    ("ratio = -0.5", "ratio = -0.5\ncurve = { kind = \"circle\", radius = 1.0 }",
     r"\[joints\.Z\] curve: unknown key"),
    ('connects = ["ground.A", "ga.O"]', 'connects = ["ground.A", "ga.O"]\nratio = 2.0',
     r"\[joints\.A\] ratio: only a gear pair"),
    ("ratio = -0.5", "ratio = -0.5\npressure_angle = 1.5", r"\[joints\.Z\] pressure_angle"),
])
def test_gear_file_errors(tmp_path, old, new, message):
    assert old in GEAR_FILE
    f = tmp_path / "bad.toml"
    f.write_text(GEAR_FILE.replace(old, new))
    with pytest.raises(cd.ModelError, match=message):
        cd.load(f)


def test_gears_on_different_carriers_are_refused():
    mech = gear_pair()
    with pytest.raises(cd.ModelError, match="one carrier"):
        mech.replace(joints={**mech.joints,
                             "B": cd.Joint("B", "revolute", "ga.O", "gb.O")})


@pytest.mark.parametrize(("build", "path", "joints"), [
    (gear_pair, "bodies.gb.inertia", ("A", "B")), (gear_pair, "bodies.ga.inertia", ("A", "B")),
    (rack_and_pinion, "bodies.rack.mass", ("P", "X")),
    (lambda: internal_pair(ring_first=True), "bodies.pinion.inertia", ("R", "P"))])
def test_sensitivities_of_the_bearing_loads(build, path, joints):
    """d/dp of both joints' forces (the tooth force included: an axle's bearing, a rack's
    guide) and of the tooth force itself against central differences (h 1e-6 relative,
    rtol 1e-12): within 1e-6 of the largest derivative."""
    from cmm_dae.description.params import param_value

    mech = build()
    s = cd.sensitivities(mech, [path], 0.1, rtol=1e-11, output_dt=0.02)
    x0 = param_value(mech, path)
    h = 1e-6 * abs(x0)
    runs = [cd.run_dae(cd.with_params(mech, {path: x}), 0.1, rtol=1e-12, output_dt=0.02)
            for x in (x0 + h, x0 - h)]
    for joint in joints:
        fd = (runs[0].joint(joint).force - runs[1].joint(joint).force) / (2 * h)
        got = s.joint(joint).force[..., 0]
        assert np.max(np.abs(fd)) > 1.0
        assert np.max(np.abs(got - fd)) <= 1e-6 * np.max(np.abs(fd))
    name = next(iter(mech.gears))
    fd = (runs[0].gear(name).force - runs[1].gear(name).force) / (2 * h)
    got = s.gear(name).force[..., 0]
    assert np.max(np.abs(fd)) > 1.0
    assert np.max(np.abs(got - fd)) <= 1e-6 * np.max(np.abs(fd))


def test_animation_draws_the_pitch_circles():
    """The animation's scene holds each gear's pitch circle about its axle: radii 3 and
    6 cm for the 9-cm centre distance at ratio -0.5, 9 and 3 cm for a 6-cm one at ratio 3
    (an internal mesh) (to 1e-12 m)."""
    from cmm_dae.report.animation import _Scene

    res = cd.run_dae(gear_pair(), 0.05, output_dt=0.01)
    circles = _Scene(res, 4).curves
    assert len(circles) == 2
    for ring, centre, radius in zip(circles, ((0.0, 0.0), (0.09, 0.0)), (0.03, 0.06),
                                    strict=True):
        dist = np.hypot(ring[..., 0] - centre[0], ring[..., 1] - centre[1])
        assert np.allclose(dist, radius, rtol=0, atol=1e-12)
    # an internal mesh: the pinion's 3 cm about (0.06, 0), the ring's 9 cm about the origin
    res = cd.run_dae(internal_pair(ring_first=True), 0.05, output_dt=0.01)
    for ring, centre, radius in zip(_Scene(res, 4).curves, ((0.0, 0.0), (0.06, 0.0)),
                                    (0.09, 0.03), strict=True):
        dist = np.hypot(ring[..., 0] - centre[0], ring[..., 1] - centre[1])
        assert np.allclose(dist, radius, rtol=0, atol=1e-12)
