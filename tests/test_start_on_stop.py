"""Runs that start on, next to or beyond a stop (issue: a joint starting exactly on its stop,
moving into it, was carried through the stop by IDA with status "success").

Reference: a pendulum whose pivot has a lower stop at L. Started on the stop moving into it,
the impact is at t = 0: a plastic stop holds it there (the load presses it on), an elastic
one (restitution e) sends it back at -e times its rate. Whatever the start, neither
integrator may ever show the joint beyond its stop (by more than round-off)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

import cmm_dae as cd

from refs import for_method


def pendulum(L: float, th0: float, w0: float, e: float = 0.0, torque: float = 0.0):
    with open(cd.example("pendulum_stop"), "rb") as f:
        d = tomllib.load(f)
    d["joints"]["O"]["limits"] = {"lower": L}
    d["joints"]["O"]["restitution"] = e
    d["initial"] = {"joints": {"O": th0}, "velocities": {"O": w0}}
    if torque:
        d["loads"] = {"preload": {"joint": "O", "law": "constant", "value": torque}}
    return cd.from_dict(d)


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_start_on_stop_moving_in_is_an_impact_at_t0(method):
    res = cd.simulate(pendulum(-0.6, -0.6, -1.0), 1.0, method=method)
    first = res.events[0]
    assert (first.kind, first.joint, first.side, first.t) == ("limit", "O", "lower", 0.0)
    assert first.velocity_before == pytest.approx(-1.0, rel=1e-12)
    assert first.velocity_after == 0.0
    # plastic, gravity presses it on: it rests on the stop for the whole run
    assert np.max(np.abs(res.joint("O").position + 0.6)) <= 1e-12
    assert res.status == cd.Status.SUCCESS


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_start_on_stop_moving_in_bounces_back(method):
    res = cd.simulate(pendulum(-0.6, -0.6, -2.0, e=0.5), 0.05, method=method,
                      **for_method(method, dt=1e-4))
    first = res.events[0]
    assert (first.kind, first.t) == ("bounce", 0.0)
    assert first.velocity_after == pytest.approx(1.0, rel=1e-12)  # -e times -2 rad/s
    assert np.min(off_events(res)) >= -0.6 - 1e-12


def off_events(res) -> np.ndarray:
    """The joint's samples, but for those at event times: the fixed-step algorithm
    detects a crossing at the end of the step that made it and records that state before
    the switch (the paper's first-order algorithm); the switch puts it back on the stop."""
    at_event = np.isin(res.t, [e.t for e in res.events])
    keep = ~at_event
    keep[-1] = True  # the run's last state always counts
    return res.joint("O").position[keep]


def test_start_on_stop_moving_in_has_no_sensitivities():
    with pytest.raises(cd.CmmError, match="starts with an impact"):
        cd.sensitivities(pendulum(-0.6, -0.6, -1.0), ["joints.O.limits.lower"], 0.1)


@given(L=st.floats(-1.2, 0.5), where=st.sampled_from(["on", "next", "beyond", "above"]),
       w0=st.sampled_from([-3.0, -0.5, -1e-7, 0.0, 1e-7, 0.5, 3.0]),
       e=st.sampled_from([0.0, 0.0, 0.4]), torque=st.floats(-1.5, 1.5),
       method=st.sampled_from(["ida", "iterative"]))
@example(L=-0.6, where="on", w0=-3.0, e=0.0, torque=0.0, method="ida")
@example(L=-0.6, where="on", w0=-0.5, e=0.4, torque=1.0, method="ida")
@example(L=-0.6, where="on", w0=-1e-7, e=0.0, torque=-1.0, method="ida")
def test_never_beyond_a_stop(L, where, w0, e, torque, method):
    """Random stops, preloads (a constant torque at the pivot, N m) and start states on,
    1e-9 rad next to, 1e-3 rad beyond, or 0.2 rad above the stop, moving in or out: the run
    either refuses a start beyond the stop (ModelError naming [initial]) or never shows
    the joint beyond it by more than 1e-9 rad (the fixed-step algorithm: but at the end of
    a step that crosses, before its switch)."""
    th0 = {"on": L, "next": L + 1e-9, "beyond": L - 1e-3, "above": L + 0.2}[where]
    if where == "beyond":
        with pytest.raises(cd.ModelError, match=r"\[initial\] joints.O: .* outside the limits"):
            pendulum(L, th0, w0, e, torque)
        return
    mech = pendulum(L, th0, w0, e, torque)
    res = cd.simulate(mech, 0.5, method=method, throw=False, **for_method(method, dt=1e-3))
    assert res.status in (cd.Status.SUCCESS, cd.Status.MAX_EVENTS), res.message
    assert np.min(off_events(res)) >= L - 1e-9 * max(1.0, abs(L))
