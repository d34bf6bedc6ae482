"""The event policy (cmm_dae.hybrid.policy) on its own and through both integrators, against closed
forms: the impact map, the Zeno rule, crossing detection and confirmation, a jam release,
two events at one instant, and the fixed-step algorithm coming to rest like IDA."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

import cmm_dae as cd
import cmm_dae.hybrid.policy as ev
from cmm_dae.hybrid.start import assemble_positions, assemble_velocities, initial_guess

from refs import for_method

MODELS = Path(__file__).resolve().parent.parent / "models"


def rod_at_stop(omega: float, e: float):
    """The pendulum_stop rod on its stop (-0.6 rad) turning at ``omega`` rad/s."""
    text = (MODELS / "pendulum_stop.toml").read_text().replace(
        "restitution = 0.0", f"restitution = {e}")
    mech = cd.from_dict(__import__("tomllib").loads(text))
    model = cd.Model(mech)
    hs = ev.HybridState(model)
    q = assemble_positions(model, 0.0, hs.p, {"O": -0.6}, initial_guess(model))
    v = assemble_velocities(model, q, 0.0, hs.p, {"O": omega})
    return model, hs, q, v


@pytest.mark.parametrize("e", [0.0, 0.3, 1.0])
def test_impact_map_of_a_pivoted_rod(e):
    """J_O (w+ - w-) = angular impulse of the stop; w+ = -e w-; the pivot keeps holding;
    the kinetic energy lost is 1/2 J_O w-^2 (1 - e^2) (Carnot for e = 0)."""
    w = -2.0
    model, hs, q, v = rod_at_stop(w, e)
    J_O = 3.0e-3 + 0.4 * 0.15**2
    p = hs.params_of({"O": "lower"})
    row = model.n_fixed + model.locks.index("O")
    v_plus, imp = ev.impact_map(model, q, v, 0.0, p, row, -e * w)
    w_plus = model.joint_rates(q, v_plus)[1][0]
    assert w_plus == pytest.approx(-e * w, abs=1e-13)
    # the lock row's generalized force along the joint is -lambda: its impulse is -Lambda
    assert -imp[row] == pytest.approx(J_O * (w_plus - w), rel=1e-12)
    con = model.constraints(q, 0.0, p)
    assert np.max(np.abs(con.Phi_q[:2] @ v_plus)) < 1e-14  # the pivot holds
    lost = 0.5 * np.sum(model.mass * (v**2 - v_plus**2))
    assert lost == pytest.approx(0.5 * J_O * w**2 * (1 - e**2), rel=1e-12, abs=1e-15)


def test_at_limit_bounces_then_locks_below_v_lock():
    model, hs, q, v = rod_at_stop(-2.0, 0.5)
    out = ev.at_limit(hs, q, v, 0.1, "O", "lower", ev.Policy(v_lock=1e-6))
    assert [t.event.kind for t in out] == ["bounce"] and "O" not in hs.locked
    assert out[0].event.velocity_after == pytest.approx(1.0, rel=1e-12)
    model, hs, q, v = rod_at_stop(-1e-6, 0.5)  # rebound 5e-7 < v_lock
    out = ev.at_limit(hs, q, v, 0.1, "O", "lower", ev.Policy(v_lock=1e-6))
    assert [t.event.kind for t in out] == ["lock"] and hs.locked == {"O": "lower"}
    assert out[0].event.velocity_after == 0.0


def test_zeno_rule():
    e, res = 0.5, 1e-3
    exact = list(np.cumsum(0.1 * e ** np.arange(12)))  # intervals shrinking by e
    # an exact Zeno sequence never stalls: only the interval floor ends it
    assert not any(ev.zeno(exact[:k], exact[k], e, res) for k in range(1, 7))
    assert ev.zeno(exact[:7], exact[7], e, res)  # 0.1 / 2^7 s apart: below 1 ms
    assert ev.zeno([0.0], 0.5e-3, e, res)  # closer than the resolution
    # the explicit scheme's cycle (5 steps, not shrinking) within 2/(1-e)+4 = 8 steps
    cycle = [0.0, 5e-3, 10e-3]
    assert ev.zeno(cycle[:2], cycle[2], e, res)
    assert not ev.zeno(cycle[:2], cycle[2], e, 1e-9)  # IDA's resolution: not a stall
    assert not ev.zeno([0.0, 0.1], 0.2, e, res)  # a regular bounce every 0.1 s: no lock
    assert not ev.zeno([0.0, 5e-3], 10e-3, 1.0, res)  # elastic: never


def test_crossing_detection_and_confirmation():
    model, hs, q, v = rod_at_stop(-2.0, 0.0)
    q_beyond = q.copy()
    q_beyond[2] -= 1e-3  # 1 mrad past the stop (the rod's angle)
    # beyond and moving toward the stop: a crossing; moving away: none
    assert ev.crossings(hs, q_beyond, v, 0.0) == [ev.Trigger("O", "lower", "gap")]
    assert ev.crossings(hs, q_beyond, -v, 0.0) == []
    assert ev.crossings(hs, q, v, 0.0) == []  # on it, not beyond
    pol = ev.Policy()
    tr = ev.Trigger("O", "lower", "gap")
    assert ev.confirm(hs, tr, q, v, 0.0, pol)
    assert not ev.confirm(hs, tr, q, -v, 0.0, pol)  # a root while leaving: round-off
    # the event function is armed while approaching, +1 while leaving
    out = np.zeros(1)
    c, cd_ = model.joint_rates(q_beyond, v)
    ev.event_values(hs, c, cd_, None, [tr], out)
    assert out[0] == pytest.approx(-1e-3, abs=1e-12)
    ev.event_values(hs, c, -cd_, None, [tr], out)
    assert out[0] == 1.0


def telescopic_slider_crank() -> cd.Mechanism:
    """Driven slider-crank whose rod is two pieces on a prismatic joint D, pressed onto
    D's upper stop by a preloaded spring (the nipper's G in a slider-crank): with D held it
    is a rigid slider-crank of rod 0.2 m. The slider meets a plastic stop E at x = 0.245:
    locking E with D held would jam the crank, so D is freed at the same instant."""
    a, l1, l2 = 0.05, 0.1, 0.1
    th0 = 0.5
    B = (a * math.cos(th0), a * math.sin(th0))
    x0 = a * math.cos(th0) + math.sqrt((l1 + l2) ** 2 - (a * math.sin(th0)) ** 2)
    phi = math.atan2(-B[1], x0 - B[0])
    bodies = [
        cd.Body("crank", 0.1, 2.5e-5, (0.025, 0.0), {"A": (0, 0), "B": (a, 0)},
                guess=(0, 0, th0)),
        cd.Body("rod1", 0.1, 1e-4, (0.05, 0.0), {"B": (0, 0), "D": (l1, 0)},
                guess=(B[0], B[1], phi)),
        cd.Body("rod2", 0.1, 1e-4, (0.05, 0.0), {"D": (0, 0), "C": (l2, 0)},
                guess=(B[0] + l1 * math.cos(phi), B[1] + l1 * math.sin(phi), phi)),
        cd.Body("slider", 0.3, 1e-4, (0, 0), {"C": (0, 0)}, guess=(x0, 0, 0)),
    ]
    joints = [
        cd.Joint("A", "revolute", "ground.A", "crank.A"),
        cd.Joint("B", "revolute", "crank.B", "rod1.B"),
        cd.Joint("D", "prismatic", "rod1.D", "rod2.D", limits=cd.Limits(-0.05, 0.0),
                 spring=cd.Spring(100.0, 0.05)),  # preload 5 N onto the upper stop
        cd.Joint("C", "revolute", "rod2.C", "slider.C"),
        cd.Joint("E", "prismatic", "ground.A", "slider.C", limits=cd.Limits(upper=0.245)),
    ]
    return cd.Mechanism("telescopic slider-crank", bodies, joints, ground={"A": (0.0, 0.0)},
                        drivers=[cd.Driver("A", "constant_speed", initial=th0,
                                           speed=2 * math.pi)],
                        initial=cd.Initial({"D": 0.0}), gravity=(0.0, 0.0))


def slider_x(t: float) -> float:
    th = 0.5 + 2 * math.pi * t
    return 0.05 * math.cos(th) + math.sqrt(0.04 - (0.05 * math.sin(th)) ** 2)


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_jam_frees_the_preloaded_joint_at_the_same_instant(method):
    mech = telescopic_slider_crank()
    t_hit = brentq(lambda t: slider_x(t) - 0.245, 0.8, 0.92, xtol=1e-15)
    h = 1e-7
    v_hit = (slider_x(t_hit + h) - slider_x(t_hit - h)) / (2 * h)
    res = cd.simulate(mech, 1.0, method=method,
                      **for_method(method, rtol=1e-11, atol=1e-13, dt=1e-3))
    got = [(e.kind, e.joint, e.side) for e in res.events[:3]]
    assert got == [("lock", "D", "upper"), ("release", "D", "upper"), ("limit", "E", "upper")]
    rel, hit = res.events[1], res.events[2]
    assert rel.t == hit.t and rel.release_force > 0.0  # freed while still pressed on
    # on the way back D reaches its stop when the rigid slider-crank would put the slider
    # on the stop again; locking D then jams the stopped slider: E is freed first
    t_back = brentq(lambda t: slider_x(t) - 0.245, 0.93, 1.0, xtol=1e-15)
    assert [(e.kind, e.joint) for e in res.events[3:]] == [("release", "E"), ("limit", "D")]
    assert res.events[3].t == res.events[4].t
    if method == "ida":
        assert abs(hit.t - t_hit) <= 1e-9 and abs(res.events[3].t - t_back) <= 1e-9
        assert hit.velocity_before == pytest.approx(v_hit, rel=1e-6)
    else:  # at the end of the step that crossed
        assert 0.0 <= hit.t - t_hit <= 1e-3 + 1e-12
        assert 0.0 <= res.events[3].t - t_back <= 1e-3 + 1e-12
    # afterwards the slider stands on its stop and D carries the crank's motion
    on = (res.t > hit.t) & (res.configuration == hit.after)
    assert np.max(np.abs(res.joint("E").position[on] - 0.245)) <= 1e-12
    assert np.ptp(res.joint("D").position[on]) > 1e-3


def two_rods() -> cd.Mechanism:
    """Two identical rods on one pivot (they do not touch each other), released together:
    their equations are the same to the bit, so both reach their stops at one instant."""
    bodies = [cd.Body(f"rod{i}", 0.4, 3e-3, (0.15, 0), {"O": (0, 0)}, guess=(0, 0, 0.3))
              for i in (1, 2)]
    joints = [cd.Joint(f"O{i}", "revolute", f"ground.O{i}", f"rod{i}.O",
                       limits=cd.Limits(lower=-0.6)) for i in (1, 2)]
    return cd.Mechanism("two rods", bodies, joints, ground={"O1": (0.0, 0), "O2": (0.0, 0)},
                        initial=cd.Initial({"O1": 0.3, "O2": 0.3}))


def test_two_events_at_one_instant_are_both_handled_and_audited():
    res = cd.run_dae(two_rods(), 0.5, rtol=1e-10, atol=1e-12)
    assert [(e.kind, e.joint) for e in res.events] == [("limit", "O1"), ("limit", "O2")]
    assert res.events[0].t == res.events[1].t
    assert res.configurations[res.configuration[-1]].locked == ("O1", "O2")
    # each loss is booked at its own sample: the audit closes (it was off by one loss)
    lost = sum(e.energy_lost for e in res.events)
    assert lost > 0.1
    assert np.max(np.abs(res.energy().residual)) <= 1e-7
    assert res.data["event_sample"].tolist() == [
        int(np.flatnonzero(res.t == res.events[0].t)[k]) for k in (1, 2)]


def test_iterative_bouncing_rod_comes_to_rest_like_ida(tmp_path):
    text = (MODELS / "pendulum_stop.toml").read_text().replace(
        "restitution = 0.0", "restitution = 0.5")
    path = tmp_path / "bounce.toml"
    path.write_text(text)
    mech = cd.load(path)
    ref = cd.run_dae(mech, 1.5, rtol=1e-10, atol=1e-12)
    assert ref.events[-1].kind in ("lock", "limit")  # at rest on the stop: locked
    t_rest = ref.events[-1].t
    errors = []
    for dt in (1e-2, 1e-3):
        r = cd.run_iterative(mech, 1.5, dt=dt)
        assert r.success and r.events[-1].kind in ("lock", "limit")
        assert r.configurations[r.configuration[-1]].locked == ("O",)
        assert len(r.events) < 30  # it came to rest (it bounced every 5 ms forever)
        errors.append(r.events[-1].t - t_rest)
    assert 0.0 < errors[1] < 40 * 1e-3 and errors[0] > 3 * errors[1]  # converges with dt
