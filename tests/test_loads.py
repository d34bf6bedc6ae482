"""Applied loads and force elements against independent references: Andrews' squeezing
mechanism against the Test Set for IVP Solvers, and a pendulum carrying every kind of load
against a minimal-coordinate model integrated by DOP853."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import cmm_dae as cd

from refs import for_method

MODELS = Path(__file__).resolve().parent.parent / "models"

#: Test Set for IVP Solvers (CWI / Bari), problem "andrews": y(0.03), computed with PSIDE at
#: tolerance 1e-14; the order of the benchmark's coordinates.
ANDREWS_003 = {"beta": 0.1581077119629904e2, "Theta": -0.1575637105984298e2,
               "gamma": 0.4082224013073101e-1, "Phi": -0.5347301163226948,
               "delta": 0.5244099658805304, "Omega": 0.5347301163226948,
               "epsilon": 0.1048080741042263e1}


def test_andrews_squeezer_against_the_test_set():
    mech = cd.load(MODELS / "andrews_squeezer.toml")
    res = cd.run_dae(mech, 0.03, rtol=1e-10, atol=1e-12, output_dt=None)
    err = {k: res.joint(k).position[-1] - v for k, v in ANDREWS_003.items()}
    assert max(abs(e) for e in err.values()) <= 1e-7, err
    # the audit books the motor's work and the spring's energy: it closes (the work is a
    # Simpson quadrature over IDA's steps, the reference the exact product)
    e = res.energy()
    assert e.load_work[-1] == pytest.approx(0.033 * (res.joint("beta").position[-1]
                                                     - res.joint("beta").position[0]),
                                            rel=1e-9)
    assert np.max(np.abs(e.residual)) <= 1e-8
    s = res.element("spring")
    assert s.tension == pytest.approx(4530.0 * (s.length - 0.07785), rel=1e-12, abs=1e-9)


def test_andrews_squeezer_at_a_loose_tolerance_runs_through():
    """At rtol 1e-3 IDA gave up on the squeezer's stiff spring at 0.0237 s while the
    multipliers were in its error test; a mechanism without locks or friction leaves them
    out (index-2 variables), and the run goes through, 2.1e-2 rad off the Test Set's
    reference at 0.03 s (the error test is on the motion, whose tolerance is loose)."""
    mech = cd.load(MODELS / "andrews_squeezer.toml")
    res = cd.run_dae(mech, 0.03, rtol=1e-3, output_dt=None)
    assert res.success and res.t[-1] == 0.03 and not res.events
    err = max(abs(float(res.joint(k).position[-1]) - v) for k, v in ANDREWS_003.items())
    assert 1e-3 < err < 0.05


def test_a_stiff_failure_without_a_singular_position_is_no_dead_point(tmp_path):
    """The squeezer with its spring 1e4 times stiffer (4.53e7 N/m): at rtol 1e-2, 5e-3 and
    1e-3 IDA gives up before 0.001 s. The constraints' singular-value ratio is 3e-3
    throughout (no singular position anywhere); such a failure was once crossed as a
    singular position and reported as a "dead point". It is IDA's own failure, said so,
    with the run kept up to it."""
    text = (MODELS / "andrews_squeezer.toml").read_text()
    assert "stiffness = 4530.0 " in text
    stiff = tmp_path / "stiff_squeezer.toml"
    stiff.write_text(text.replace("stiffness = 4530.0 ", "stiffness = 4.53e7 "))
    for rtol in (1e-2, 5e-3, 1e-3):  # (at 1e-2 the ratio at the failure, 3.6e-3, fell
        # locally but was above the segment's start's, 2.8e-3: once read as a dead point)
        res = cd.run_dae(cd.load(stiff), 0.03, rtol=rtol, output_dt=None, throw=False)
        assert res.status is cd.Status.INTEGRATOR, rtol
        assert "no dead point found" in res.message
        assert 1e-4 < res.t[-1] < 0.03 and not res.events


# --------------------------------------------------------------- loaded pendulum
M, L, JC, RC = 0.5, 0.4, 0.5 * 0.4**2 / 12, 0.2   # rod mass, length, centroidal inertia
S = (0.25, 0.3)                                     # ground end of the spring element
K, REST, DAMP, PRE = 30.0, 0.15, 0.2, 1.5           # element
STALL, W0 = 0.8, 6.0                                # motor on the pivot
FB = 0.6                                            # body-frame tip force, N (frame y)
FG = (0.6, -1.0)                                    # global tip force direction (1 N)
MOM = (0.1, 0.05, 1.5, 0.3)                         # moment: mean, amplitude, Hz, phase
ZONE = (1.0, 1.33)                                   # the global force acts for th in it


def loaded_pendulum() -> cd.Mechanism:
    rod = cd.Body("rod", M, JC, (RC, 0.0), {"O": (0.0, 0.0), "T": (L, 0.0)},
                  guess=(0.0, 0.0, 0.3))
    joint = cd.Joint("O", "revolute", "ground.O", "rod.O")
    loads = [
        cd.Load("motor", cd.Law("motor", stall=STALL, no_load_speed=W0), joint="O"),
        cd.Load("tip_body", cd.Law("constant", value=FB), body="rod", point="T",
                direction=(0.0, 1.0), frame="body"),
        cd.Load("tip_global", cd.Law("constant", value=1.0), body="rod", point="T",
                direction=FG, frame="global", zone=cd.Zone("O", *ZONE)),
        cd.Load("moment", cd.Law("harmonic", mean=MOM[0], amplitude=MOM[1],
                                 frequency=MOM[2], phase=MOM[3]), body="rod"),
    ]
    el = cd.Element("spring", "ground.S", "rod.T", K, REST, DAMP, PRE)
    return cd.Mechanism("loaded pendulum", [rod], [joint], ground={"O": (0, 0), "S": S},
                        initial=cd.Initial({"O": 0.3}, {"O": 0.0}), loads=loads,
                        elements=[el])


def pendulum_rhs(t, y, acting):
    th, w = y
    tip = np.array([L * math.cos(th), L * math.sin(th)])
    dtip = np.array([-L * math.sin(th), L * math.cos(th)])
    d = tip - np.array(S)
    ln = math.hypot(*d)
    dl = d @ dtip / ln
    tension = PRE + K * (ln - REST) + DAMP * dl * w
    tau = STALL * (1 - w / W0)                                   # motor
    tau += L * FB                                                # body-frame force (y)
    if acting:
        g = np.array(FG) / math.hypot(*FG)
        tau += tip[0] * g[1] - tip[1] * g[0]
    tau += MOM[0] + MOM[1] * math.sin(2 * math.pi * MOM[2] * t + MOM[3])
    tau += -tension * dl                                         # element
    tau += -M * 9.81 * RC * math.cos(th)                         # gravity
    return [w, tau / (JC + M * RC**2)]


def minimal_solution(t_end: float, grid: np.ndarray):
    """DOP853 with the zone edges as events, restarted at each switch."""
    t0, y0 = 0.0, [0.3, 0.0]
    acting = ZONE[0] <= y0[0] <= ZONE[1]
    switches, ts, ys = [], [], []
    while t0 < t_end:
        edges = [lambda t, y, *_, e=e: y[0] - e for e in ZONE]  # solve_ivp passes args too
        for f, e in zip(edges, ZONE, strict=True):
            f.terminal = True
            # only a crossing back from the side the state is on (or moving to) counts:
            # a restart on an edge must not find that edge again at once
            gap = y0[0] - e
            f.direction = -1.0 if (gap > 1e-9 or (abs(gap) <= 1e-9 and y0[1] > 0)) else 1.0
        sol = solve_ivp(pendulum_rhs, (t0, t_end), y0, method="DOP853", rtol=1e-12,
                        atol=1e-14, args=(acting,), events=edges, dense_output=True)
        seg = grid[(grid >= t0) & (grid <= sol.t[-1])]
        if seg.size:
            ts.append(seg)
            ys.append(sol.sol(seg)[0])
        if sol.status == 1:
            t0, y0 = sol.t[-1], sol.y[:, -1]
            switches.append(t0)
            acting = not acting
            t0 = np.nextafter(t0, np.inf)
        else:
            break
    return np.concatenate(ts), np.concatenate(ys), switches


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_loaded_pendulum_against_minimal_coordinates(method):
    mech = loaded_pendulum()
    t_end = 3.0
    if method == "ida":
        res = cd.run_dae(mech, t_end, rtol=1e-11, atol=1e-13, output_dt=0.01)
    else:
        res = cd.run_iterative(mech, t_end, dt=1e-4, output_every=100)
    grid = np.round(np.arange(0, 301) * 0.01, 12)
    tm, thm, switches = minimal_solution(t_end, grid)
    assert len(switches) >= 2  # the zone is entered and left
    zone_events = [e for e in res.events if e.kind == "zone"]
    assert [e.load for e in zone_events] == ["tip_global"] * len(switches)
    th = res.resample(tm, res.joint("O").position)
    if method == "ida":
        assert np.max(np.abs(th - thm)) <= 1e-8
        assert np.max(np.abs(np.array([e.t for e in zone_events]) - switches)) <= 1e-9
        assert [e.side for e in zone_events][:2] == (
            ["leave", "enter"] if ZONE[0] <= 0.3 <= ZONE[1] else ["enter", "leave"])
        # the audit's integrals are Simpson sums over the samples: a 1 ms grid for it
        fine = cd.run_dae(mech, t_end, rtol=1e-11, atol=1e-13, output_dt=0.001)
        assert np.max(np.abs(fine.energy().residual)) <= 1e-8
    else:  # first order in dt: 1e-4 s steps, switches at the end of the crossing step
        assert np.max(np.abs(th - thm)) <= 5e-3
        assert np.max(np.abs(np.array([e.t for e in zone_events]) - switches)) <= 5e-4
    # load series: the motor line and the zone's on/off
    mot = res.load("motor")
    assert mot.value == pytest.approx(STALL * (1 - res.joint("O").velocity / W0), rel=1e-12)
    acting = np.array(["tip_global" in res.configurations[i].zones for i in res.configuration])
    assert acting.any() and not acting.all()
    assert np.all(res.load("tip_global").value[~acting] == 0.0)
    assert np.all(res.load("tip_global").value[acting] == 1.0)


def test_bad_loads_and_elements(tmp_path):
    text = (MODELS / "pendulum_stop.toml").read_text() + '''
[loads.a]
joint = "Q"
law = "constant"
value = 1.0

[loads.b]
body = "rod"
point = "nose"
direction = [1.0, 0.0]
law = "constant"
value = 1.0

[loads.c]
joint = "O"
law = "motor"
stall = 1.0
no_load_speed = 0.0

[loads.d]
body = "rod"
point = "tip"
direction = [0.0, 0.0]
law = "motor"
stall = 1.0
no_load_speed = 2.0

[loads.e]
joint = "O"
law = "constant"
value = 1.0
zone = { lower = -2.0, upper = -1.0 }

[loads.f]
body = "wheel"
law = "sinus"
value = 1.0

[elements.g]
connects = ["ground.O", "rod.nose"]
stiffness = -1.0
'''
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(cd.ModelError) as info:
        cd.load(path)
    got = {(p.table, p.key) for p in info.value.problems}
    assert {("loads.a", "joint"), ("loads.b", "point"), ("loads.c", "no_load_speed"),
            ("loads.d", "direction"), ("loads.d", "law"), ("loads.e", "zone"),
            ("loads.f", "law"), ("elements.g", "connects"), ("elements.g", "stiffness")} <= got
    msg = str(info.value)
    assert "[loads.e] zone: [-2.0, -1.0] lies outside the limits [-0.6, None]" in msg
    assert "unknown joint 'Q'" in msg and "has no point 'nose'" in msg
    assert "a motor law needs a joint rate" in msg


def test_nipper_cutting_load_by_virtual_work():
    """While the jaw cuts, G is held on its collar and the mechanism moves with its driver:
    by virtual work the cut's torque tau on joint C changes the driving torque by
    -tau C' / omega, and nothing else changes."""
    plain = cd.run_dae(cd.load(MODELS / "nipper_swing.toml"), 6.0, rtol=1e-10, atol=1e-12)
    mech = cd.load(MODELS / "nipper_cutting.toml")
    cut = cd.run_dae(mech, 6.0, rtol=1e-10, atol=1e-12)
    enter, leave = [e for e in cut.events if e.kind == "zone"][:2]
    assert (enter.side, leave.side) == ("enter", "leave")
    assert leave.t == [e.t for e in cut.events if e.kind == "limit"][0]  # cut till closed
    omega = mech.drivers["O"].speed
    tau = mech.loads["cut"].law.value
    t = np.linspace(enter.t + 1e-3, leave.t - 1e-3, 200)
    d_eff = cut.resample(t, cut.driver("O").effort) - plain.resample(t, plain.driver("O").effort)
    c_rate = plain.resample(t, plain.joint("C").velocity)
    assert np.max(np.abs(d_eff - (-tau * c_rate / omega))) <= 1e-8
    before = np.linspace(0.1, enter.t - 1e-3, 100)
    assert np.max(np.abs(cut.resample(before, cut.driver("O").effort)
                         - plain.resample(before, plain.driver("O").effort))) <= 1e-8
    assert np.max(np.abs(cut.energy().residual)) <= 1e-6


def test_motor_driven_crank_reaches_its_stop():
    """A motor's torque-speed line lifts a crank onto a stop: the impact time against a
    DOP853 minimal-coordinate model, then the stop holds the stalled motor against the
    weight."""
    mech = cd.load(MODELS / "motor_crank_stop.toml")
    res = cd.run_dae(mech, 1.5, rtol=1e-11, atol=1e-13)
    m, r, jc, stall, w0 = 0.3, 0.1, 1.0e-3, 0.6, 8.0

    def rhs(t, y):
        return [y[1], (stall * (1 - y[1] / w0) - m * 9.81 * r * math.cos(y[0]))
                / (jc + m * r**2)]

    hit = lambda t, y: y[0] - 1.2  # noqa: E731
    hit.terminal = True
    sol = solve_ivp(rhs, (0, 1.5), [-math.pi / 2, 0.0], method="DOP853", rtol=1e-12,
                    atol=1e-14, events=hit)
    assert [e.kind for e in res.events] == ["limit"]
    assert abs(res.events[0].t - sol.t_events[0][0]) <= 1e-9
    assert res.events[0].velocity_before == pytest.approx(sol.y_events[0][0][1], rel=1e-8)
    held = res.t > res.events[0].t
    # the ground pushes the crank back with the stalled motor's torque less the weight's
    expect = -(stall - m * 9.81 * r * math.cos(1.2))
    assert np.max(np.abs(res.joint("O").torque[held] - expect)) <= 1e-9


def callable_rod(func) -> cd.Mechanism:
    rod = cd.Body("rod", M, JC, (RC, 0.0), {"O": (0.0, 0.0)}, guess=(0.0, 0.0, 0.3))
    joint = cd.Joint("O", "revolute", "ground.O", "rod.O")
    load = cd.Load("hand", cd.Law(func=func), joint="O")
    return cd.Mechanism("rod pushed by a Python law", [rod], [joint], ground={"O": (0, 0)},
                        initial=cd.Initial({"O": 0.3}, {"O": 0.0}), loads=[load])


def hand(t: float, c: float, rate: float) -> float:
    """A nonlinear law of time, angle and rate, N m."""
    return 0.3 * math.sin(c) - 0.05 * rate + 0.1 * math.cos(3.0 * t)


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_callable_law_against_minimal_coordinates(method):
    res = cd.simulate(callable_rod(hand), 2.0, method=method,
                      **for_method(method, rtol=1e-11, atol=1e-13, dt=1e-4, output_every=100))
    jo = JC + M * RC**2

    def rhs(t, y):
        return [y[1], (hand(t, y[0], y[1]) - M * 9.81 * RC * math.cos(y[0])) / jo]

    sol = solve_ivp(rhs, (0, 2.0), [0.3, 0.0], method="DOP853", rtol=1e-12, atol=1e-14,
                    dense_output=True)
    err = np.max(np.abs(res.joint("O").position - sol.sol(res.t)[0]))
    assert err <= (1e-8 if method == "ida" else 5e-3)
    th, w = res.joint("O").position, res.joint("O").velocity
    assert res.load("hand").value == pytest.approx(
        [hand(t, a, b) for t, a, b in zip(res.t, th, w, strict=True)], rel=1e-12, abs=1e-15)


def test_callable_law_errors():
    rod = cd.Body("rod", M, JC, (RC, 0.0), {"O": (0.0, 0.0)})
    joint = cd.Joint("O", "revolute", "ground.O", "rod.O")
    with pytest.raises(cd.ModelError, match=r"\[loads\.push\] law: a callable law .* needs a "
                       r"joint"):
        cd.Mechanism("m", [rod], [joint], ground={"O": (0, 0)},
                     loads=[cd.Load("push", cd.Law(func=hand), body="rod")])
    with pytest.raises(cd.ModelError, match=r"expected a callable f\(t, coordinate, rate\), "
                       r"got str"):
        callable_rod("0.3 * sin(c)")  # never evaluated
    bad = callable_rod(lambda t, c, rate: math.nan if t > 0.5 else 0.0)
    with pytest.raises(cd.SolverError, match=r"\[loads\.hand\] law: the Python callable "
                       r"returned nan") as info:
        cd.run_dae(bad, 1.0)
    assert info.value.status is cd.Status.NUMERICAL and 0.4 < info.value.result.t[-1] <= 0.5


def test_load_switched_on_by_a_zone_releases_a_held_joint_at_once():
    """A slider-crank press whose tool is preloaded onto its stop by a spring (10 N) and
    whose cutting load (30 N) switches on in a zone of the carriage: the tool must leave
    its stop at the zone's edge (the lock force's event function jumps below zero there, it
    does not cross it). Reference: the tool's own equation of motion relative to the
    prescribed carriage (minimal coordinate, scipy at rtol 1e-12) until it hits the lower
    stop."""
    mech = cd.load(Path(__file__).parent / "models" / "overload_press.toml")
    res = cd.run_dae(mech, 0.45, rtol=1e-11, atol=1e-13)
    kinds = [(e.kind, e.joint, e.side) for e in res.events]
    assert kinds[1:4] == [("zone", "rail", "enter"), ("release", "T", "upper"),
                          ("limit", "T", "lower")]
    t0, t_hit, v_hit = res.events[1].t, res.events[3].t, res.events[3].velocity_before
    assert res.events[2].t == t0

    w, r, ell = 2 * np.pi, 0.05, 0.2

    def x_carriage_acc(t):
        th = np.pi + w * t
        s2 = (r * np.sin(th)) ** 2
        root = np.sqrt(ell**2 - s2)
        # d2/dt2 of r cos(th) + sqrt(l^2 - r^2 sin^2 th)
        d1 = -r**2 * np.sin(th) * np.cos(th) * w / root
        d2 = -r**2 * np.cos(2 * th) * w**2 / root - d1**2 / root
        return -r * np.cos(th) * w**2 + d2

    def rhs(t, y):
        s, sd = y
        force = -30.0 + 1000.0 * (0.01 - s) + 2.0  # load, spring, kinetic friction (s' < 0)
        return [sd, force / 0.3 - x_carriage_acc(t)]

    hit = lambda t, y: y[0] + 0.03  # noqa: E731
    hit.terminal, hit.direction = True, -1
    ref = solve_ivp(rhs, (t0, 1.0), [0.0, 0.0], events=hit, rtol=1e-12, atol=1e-14,
                    method="DOP853")
    assert abs(t_hit - ref.t_events[0][0]) < 1e-8
    assert abs(v_hit - ref.y_events[0][0][1]) < 1e-7 * abs(v_hit)
    # the iterative algorithm releases at the end of the step that enters the zone
    it = cd.run_iterative(mech, 0.45, dt=1e-3)
    zone = next(e for e in it.events if e.kind == "zone")
    assert next(e for e in it.events if e.kind == "release").t == zone.t


def test_andrews_squeezer_at_tight_tolerance_runs_through():
    """At rtol 1e-12 the run ended as a 'dead point' at 0.0112 s: the squeezer spins up
    from rest to about 1400 rad/s, and an absolute tolerance of 1e-14 on a velocity passing
    zero is below the round-off of such a state (3e-13), so Newton could not converge and
    IDA's step collapsed to 1e-22 s. The tolerances now keep above the state's round-off:
    it runs through, within 1e-8 rad of the test set (measured 1.5e-9)."""
    mech = cd.load(MODELS / "andrews_squeezer.toml")
    res = cd.run_dae(mech, 0.03, rtol=1e-12, output_dt=None)
    assert res.status == cd.Status.SUCCESS and not res.events
    err = {k: res.joint(k).position[-1] - v for k, v in ANDREWS_003.items()}
    assert max(abs(e) for e in err.values()) <= 1e-8, err
