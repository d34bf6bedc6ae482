"""Property tests over random assemblable slider-cranks and four-bars (hypothesis):
the energy balance closes, constraint drift stays small, results do not depend on how the
whole mechanism is rotated in the plane (with gravity), and both integrators see the same
event sequence. Profile "ci" (default) runs 8 fixed examples per property;
HYPOTHESIS_PROFILE=dev explores 100."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import assume, given
from hypothesis import strategies as st

import cmm_dae as cd


def rot(v, phi):
    c, s = math.cos(phi), math.sin(phi)
    return (c * v[0] - s * v[1], s * v[0] + c * v[1])


def assert_balanced(res) -> None:
    """Energy balance within 1e-6 of the energy moved about; drift within DESIGN's bounds."""
    en = res.energy()
    scale = float(np.max(en.kinetic + np.abs(en.potential - en.potential[0]) + en.spring)
                  + en.damper_dissipation[-1] + en.impact_losses[-1])
    assert np.max(np.abs(en.residual)) <= 1e-6 * scale
    pos, vel = res.drift
    assert pos <= 1e-9 and vel <= 1e-7


def significant(events):
    """Events that are well-conditioned: the impacts faster than 0.01 (rad or m)/s, and
    releases. In the slow tail of a bounce sequence each impact time carries the
    amplified errors of all earlier ones (and whether the last one is a bounce or a lock is
    decided by the Zeno threshold), so a rotated copy may legitimately differ there."""
    return [e for e in events if abs(e.velocity_before) > 1e-2 or e.kind == "release"]


@st.composite
def slider_cranks(draw):
    """A free (undriven) slider-crank: torsional spring-damper at A, stop(s) on the slider."""
    r = draw(st.floats(0.02, 0.06))
    l_ = draw(st.floats(0.15, 0.3))
    e = draw(st.floats(-0.02, 0.02))
    assume(r + abs(e) < 0.8 * l_)  # the crank turns fully
    p = {
        "r": r, "l": l_, "e": e,
        "m": [draw(st.floats(0.05, 0.5)) for _ in range(3)],
        "k": draw(st.floats(0.0, 2.0)), "c": draw(st.floats(0.0, 0.02)),
        "th0": draw(st.floats(-math.pi, math.pi)), "w0": draw(st.floats(-8.0, 8.0)),
        "rest": draw(st.floats(-1.0, 1.0)),
        "restitution": draw(st.sampled_from([0.0, 0.0, 0.3])),
        "stop": draw(st.floats(0.2, 0.8)),  # fraction of the slider's stroke
    }
    th0 = p["th0"]
    Bx, By = r * math.cos(th0), r * math.sin(th0)
    xs = Bx + math.sqrt(l_**2 - (By - e) ** 2)
    lo = math.sqrt((l_ - r) ** 2 - e**2)
    hi = math.sqrt((l_ + r) ** 2 - e**2)
    # keep the stop clear of the slider's dead centre (a lock there is a lock-up)
    assume(hi - xs > 0.02 * r)
    upper = lo + p["stop"] * (hi - lo)
    if xs >= upper - 1e-3:  # start clearly below the stop
        upper = xs + 0.5 * (hi - xs)
    p["upper"], p["xs"] = upper, xs
    return p


def slider_crank(p: dict, phi: float = 0.0) -> cd.Mechanism:
    r, l_, e = p["r"], p["l"], p["e"]
    m1, m2, m3 = p["m"]
    th0, upper, xs = p["th0"], p["upper"], p["xs"]
    Bx, By = r * math.cos(th0), r * math.sin(th0)
    rod_th = math.atan2(e - By, xs - Bx)
    g = rot((0.0, -9.81), phi)
    return cd.Mechanism(
        "random slider-crank", gravity=g,
        ground={"A": (0.0, 0.0), "rail": rot((0.0, e), phi)},
        bodies=[
            cd.Body("crank", m1, m1 * r**2 / 12, (r / 2, 0.0), {"A": (0, 0), "B": (r, 0)},
                    guess=(0.0, 0.0, th0 + phi)),
            cd.Body("rod", m2, m2 * l_**2 / 12, (l_ / 2, 0.0), {"B": (0, 0), "C": (l_, 0)},
                    guess=(*rot((Bx, By), phi), rod_th + phi)),
            cd.Body("slider", m3, m3 * 1e-3, (0.0, 0.0), {"C": (0, 0)},
                    guess=(*rot((xs, e), phi), phi)),
        ],
        joints=[
            cd.Joint("A", "revolute", "ground.A", "crank.A",
                     spring=cd.Spring(p["k"], p["rest"] + phi), damper=cd.Damper(p["c"])),
            cd.Joint("B", "revolute", "crank.B", "rod.B"),
            cd.Joint("C", "revolute", "rod.C", "slider.C"),
            cd.Joint("E", "prismatic", "ground.rail", "slider.C", axis=rot((1.0, 0.0), phi),
                     angle=0.0, limits=cd.Limits(None, upper), restitution=p["restitution"]),
        ],
        initial=cd.Initial({"A": th0 + phi}, {"A": p["w0"]}))


@given(slider_cranks())
def test_energy_balance_and_drift(p):
    mech = slider_crank(p)
    # the audit integrates power over the output samples: IDA's own steps resolve the
    # fast transients (a stiff spring far from its rest on a light crank, a hard damper
    # right after the start), which a fixed 0.25 ms grid did not (1.7e-5 J against a
    # bound of 1.2e-5 J on one example; 9.8e-9 J on IDA's steps)
    res = cd.run_dae(mech, 1.0, rtol=1e-10, atol=1e-12, output_dt=None)
    assert_balanced(res)


@given(slider_cranks(), st.floats(0.1, 2 * math.pi - 0.1))
def test_rotation_invariance(p, phi):
    a = cd.run_dae(slider_crank(p), 1.0, rtol=1e-10, atol=1e-12, output_dt=0.01)
    b = cd.run_dae(slider_crank(p, phi), 1.0, rtol=1e-10, atol=1e-12, output_dt=0.01)
    ea_, eb_ = significant(a.events), significant(b.events)
    assert [(e.kind, e.joint) for e in ea_] == [(e.kind, e.joint) for e in eb_]
    for ea, eb in zip(ea_, eb_, strict=True):
        # a position error of the solver's tolerance moves an impact by ~ tol / speed
        assert abs(ea.t - eb.t) <= 1e-7 + 1e-10 / max(abs(ea.velocity_before), 1e-12)
    if a.t.size == b.t.size:
        assert np.max(np.abs(a.joint("E").position - b.joint("E").position)) <= 1e-8
        assert np.max(np.abs(a.joint("A").position + phi - b.joint("A").position)) <= 1e-7
        fa = np.hypot(*a.joint("B").force.T)
        fb = np.hypot(*b.joint("B").force.T)
        assert np.max(np.abs(fa - fb)) <= 1e-7 * (1.0 + np.max(fa))


@given(slider_cranks())
def test_both_integrators_same_event_sequence(p):
    p = dict(p, restitution=0.0)
    mech = slider_crank(p)
    a = cd.run_dae(mech, 0.5, rtol=1e-10, atol=1e-12)
    # grazing contacts (arrival within a few steps of a turning point) may legitimately
    # differ between a located event and a step-end check: skip those examples
    assume(all(abs(e.velocity_before) > 0.05 or e.kind == "release" for e in a.events))
    # near misses likewise: the explicit scheme gains a little energy and may touch a stop
    # that the exact motion turns back from just before (any approach that is not an
    # event: a turning point off the stop, within 2 mm of it)
    gap = p["upper"] - a.joint("E").position
    turn = np.flatnonzero((gap[1:-1] < gap[:-2]) & (gap[1:-1] < gap[2:])) + 1
    assume(not np.any((gap[turn] > 1e-9) & (gap[turn] < 2e-3)))
    b = cd.run_iterative(mech, 0.5, dt=5e-4, output_every=20)
    assert [(e.kind, e.joint) for e in a.events] == [(e.kind, e.joint) for e in b.events]
    for ea, eb in zip(a.events, b.events, strict=True):
        assert abs(eb.t - ea.t) <= 0.01  # O(dt) switching-time differences


@st.composite
def four_bars(draw):
    """A free (undriven) Grashof crank-rocker: spring-damper at the crank pivot A, stops on
    both sides of the rocker pivot D (geometric constraints) with a random restitution."""
    a = draw(st.floats(0.02, 0.04))
    b = draw(st.floats(0.10, 0.16))
    c = draw(st.floats(0.08, 0.14))
    d = draw(st.floats(0.10, 0.15))
    assume(a + max(b, c, d) < sum(sorted([b, c, d])[:2]) - 0.005)  # a turns fully
    th0 = draw(st.floats(-math.pi, math.pi))
    return {"a": a, "b": b, "c": c, "d": d, "th0": th0,
            "m": [draw(st.floats(0.05, 0.5)) for _ in range(3)],
            "k": draw(st.floats(0.0, 1.0)), "cd": draw(st.floats(0.0, 0.01)),
            "w0": draw(st.floats(-6.0, 6.0)), "e": draw(st.sampled_from([0.0, 0.5])),
            "margin": draw(st.floats(0.02, 0.15))}


def four_bar(p: dict, phi: float = 0.0) -> cd.Mechanism:
    a, b, c, d, th0 = p["a"], p["b"], p["c"], p["d"], p["th0"]
    B = np.array([a * math.cos(th0), a * math.sin(th0)])
    D = np.array([d, 0.0])
    dv = D - B
    L = float(np.hypot(*dv))
    x = (b * b - c * c + L * L) / (2 * L)
    h = math.sqrt(b * b - x * x)
    e = dv / L
    C = B + x * e + h * np.array([-e[1], e[0]])
    phi2 = math.atan2(*(C - B)[::-1])
    psi = math.atan2(*(C - D)[::-1])
    m1, m2, m3 = p["m"]
    # stops on both sides of the rocker's start angle: it meets one of them
    lower, upper = psi - p["margin"], psi + p["margin"]
    return cd.Mechanism(
        "random four-bar", gravity=rot((0.0, -9.81), phi),
        ground={"A": (0.0, 0.0), "D": rot((d, 0.0), phi)},
        bodies=[
            cd.Body("crank", m1, m1 * a**2 / 12, (a / 2, 0.0), {"A": (0, 0), "B": (a, 0)},
                    guess=(0.0, 0.0, th0 + phi)),
            cd.Body("coupler", m2, m2 * b**2 / 12, (b / 2, 0.01), {"B": (0, 0), "C": (b, 0)},
                    guess=(*rot(B, phi), phi2 + phi)),
            cd.Body("rocker", m3, m3 * c**2 / 12, (c / 2, 0.0), {"D": (0, 0), "C": (c, 0)},
                    guess=(*rot(D, phi), psi + phi)),
        ],
        joints=[
            cd.Joint("A", "revolute", "ground.A", "crank.A",
                     spring=cd.Spring(p["k"], th0 + phi), damper=cd.Damper(p["cd"])),
            cd.Joint("B", "revolute", "crank.B", "coupler.B"),
            cd.Joint("C", "revolute", "coupler.C", "rocker.C"),
            cd.Joint("D", "revolute", "ground.D", "rocker.D",
                     limits=cd.Limits(lower + phi, upper + phi), restitution=p["e"]),
        ],
        initial=cd.Initial({"A": th0 + phi}, {"A": p["w0"]}))


@given(four_bars(), st.floats(0.1, 2 * math.pi - 0.1))
def test_four_bar_energy_drift_rotation(p, phi):
    a = cd.run_dae(four_bar(p), 1.0, rtol=1e-10, atol=1e-12, output_dt=2.5e-4)
    assert_balanced(a)
    b = cd.run_dae(four_bar(p, phi), 1.0, rtol=1e-10, atol=1e-12, output_dt=2.5e-4)
    ea_, eb_ = significant(a.events), significant(b.events)
    assert [(e.kind, e.joint) for e in ea_] == [(e.kind, e.joint) for e in eb_]
    for ea, eb in zip(ea_, eb_, strict=True):
        # a position error of the solver's tolerance moves an impact by ~ tol / speed
        assert abs(ea.t - eb.t) <= 1e-7 + 1e-10 / max(abs(ea.velocity_before), 1e-12)
    assert a.configurations[a.configuration[-1]].locked == \
        b.configurations[b.configuration[-1]].locked
    if a.t.size == b.t.size and len(a.events) == len(b.events):
        assert np.max(np.abs(a.joint("C").position - b.joint("C").position)) <= 1e-7
