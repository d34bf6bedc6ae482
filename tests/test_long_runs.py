"""Long runs of fast contact mechanisms, and starts on a stop (issue: trust in long runs).

References, independent of the code under test:

* a knife-edge (or roller: its centre on the pitch circle) follower on an eccentric
  circular cam at constant speed, pressed on by a spring and gravity, in closed form: in
  contact its height is y(t) = e sin(th) + sqrt(R^2 - e^2 cos^2(th)), th = -pi/2 + w t;
  the cam's vertical force on it is m y'' + m g - F_spring(y), and it lifts off where that
  reaches zero. In contact the follower's state is the cam's, so every turn's lift-off
  is the first one's shifted by whole turns (brentq to 1e-15 s), however many bounces and
  landings lie between.
* a block on a guide with a stop: a start within the stop tolerance is on the stop (it
  never moves beyond it); a start beyond it by more is refused, naming the key.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

import cmm_dae as cd

MODELS = Path(__file__).parent / "models"
G = 9.81


def lift_off(e: float, R: float, w: float, m: float, k: float, y0: float, pre: float) -> float:
    """The first lift-off time (s) of a follower on the cam above (radius R of the curve
    its point follows, eccentricity e, speed w), mass m, spring k (N/m) whose force on the
    follower is -(pre + k (y - y0)) (y0 its height on the base circle, pre the preload)."""
    def force(t: float) -> float:
        th = -math.pi / 2 + w * t
        c, s = math.cos(th), math.sin(th)
        r = math.sqrt(R * R - e * e * c * c)
        ydd = w * w * (-e * s + e * e * math.cos(2 * th) / r - (e * e * c * s) ** 2 / r**3)
        y = e * s + r
        return m * ydd + m * G + pre + k * (y - y0)
    ts = np.linspace(0.0, 2 * math.pi / w, 4001)
    f = np.array([force(t) for t in ts])
    i = int(np.flatnonzero((f[:-1] > 0) & (f[1:] <= 0))[0])
    return brentq(force, ts[i], ts[i + 1], xtol=1e-15)


def lift_off_errors(res, t_lift: float, w: float) -> np.ndarray:
    lifts = np.array([e.t for e in res.events if e.kind == "lift-off"])
    period = 2 * math.pi / w
    return np.abs(lifts - t_lift - np.round((lifts - t_lift) / period) * period)


@pytest.mark.timeout(200)
def test_shipped_cam_runs_ten_seconds_at_the_default_settings():
    """The shipped valve train over 10 s on the default path (it stopped at 0.83 s of a
    2-s run, its steps at 2e-12 s after a bounce, and at 2.6 s on max_events = 1000):
    to the end, one lift-off a turn (637), each within 1e-10 s of the closed form
    (measured 3.9e-12 s), 3818 events in all. In C, as a user's default run is once its
    library is built (the Python path gives the same events: the test below; it took 45
    of this test's 50 s)."""
    res = cd.simulate(cd.load(cd.example("cam_valve_train")), 10.0, compiled=True)
    assert res.status is cd.Status.SUCCESS and res.t[-1] == 10.0
    err = lift_off_errors(res, lift_off(0.004, 0.02, 400.0, 0.08, 2000.0, 0.016, 30.0), 400.0)
    assert err.size == 637 and np.max(err) <= 1e-10
    assert len(res.events) > 1000


@pytest.mark.timeout(200)
@pytest.mark.parametrize("rtol, t_end", [(1e-8, 1.0), (1e-12, 0.3)])
def test_shipped_cam_the_same_on_both_paths(rtol, t_end):
    """C and Python: the same events (kinds and joints; times within the position
    tolerance over the approach speed: the slowest landings, at 1.9 mm/s, differ by 2.8e-8
    s at rtol 1e-8, 5.3e-11 m of approach, measured) and lift-offs within 1e-9 s of the
    closed form, at the default rtol and at 1e-12 (where the C path was stuck at an
    output time)."""
    mech = cd.load(cd.example("cam_valve_train"))
    runs = [cd.simulate(mech, t_end, rtol=rtol, compiled=c) for c in (False, True)]
    t_lift = lift_off(0.004, 0.02, 400.0, 0.08, 2000.0, 0.016, 30.0)
    for r in runs:
        assert r.status is cd.Status.SUCCESS and r.t[-1] == t_end
        assert np.max(lift_off_errors(r, t_lift, 400.0)) <= 1e-9
    a, b = ([(e.kind, e.joint) for e in r.events] for r in runs)
    assert a == b
    tol = rtol * 0.02 + 1e-2 * rtol  # m: the tolerance on the tappet's 20-mm lift
    for x, y in zip(*(r.events for r in runs), strict=True):
        assert abs(x.t - y.t) * max(abs(x.velocity_before), 1e-3) <= 10 * tol, (x, y)


@pytest.mark.timeout(200)
def test_roller_cam_from_the_docs_runs_to_the_end():
    """A roller cam written from the docs (eccentric disc 25 mm, e 5 mm, roller 8 mm,
    0.1 kg, 1000 N/m with 20 N preload, 300 rad/s), which failed at 4.57 s of 10: 6 s
    on the default path (in C, its library built), its lift-offs within 1e-10 s of the
    closed form."""
    res = cd.simulate(cd.load(MODELS / "roller_cam.toml"), 6.0, compiled=True)
    assert res.status is cd.Status.SUCCESS and res.t[-1] == 6.0
    err = lift_off_errors(res, lift_off(0.005, 0.033, 300.0, 0.1, 1000.0, 0.028, 20.0), 300.0)
    assert err.size == 287 and np.max(err) <= 1e-10


@pytest.mark.timeout(200)
def test_tighter_tolerances_never_much_cheaper_on_the_cam():
    """Steps of 0.5 s of the shipped cam at rtol 1e-4 .. 1e-12: tightening rtol 100x never
    halves the cost (it was 5,845 / 14,049 / 4,022 / 866 steps at 1e-4 .. 1e-10)."""
    mech = cd.load(cd.example("cam_valve_train"))
    steps = [cd.simulate(mech, 0.5, rtol=r).stats.steps for r in (1e-4, 1e-6, 1e-8, 1e-10)]
    assert all(b >= a / 2 for a, b in zip(steps, steps[1:], strict=False)), steps


def block(x0: float, L: float, upper: bool) -> cd.Mechanism:
    """A 1-kg block on a vertical guide, its stop at L, gravity pressing it on the stop."""
    return cd.from_dict({
        "mechanism": {"name": "block", "gravity": [0.0, 9.81 if upper else -9.81]},
        "ground": {"points": {"O": [0.0, 0.0]}},
        "bodies": {"b": {"mass": 1.0, "inertia": 1e-3, "points": {"P": [0.0, 0.0]}}},
        "joints": {"X": {"type": "prismatic", "connects": ["ground.O", "b.P"],
                         "axis": [0.0, 1.0], "limits": {"upper" if upper else "lower": L}}},
        "initial": {"joints": {"X": x0}, "velocities": {"X": 0.0}}})


@pytest.mark.parametrize("method", ["ida", "iterative"])
@pytest.mark.parametrize("L, upper", [(1.0, True), (1.0, False), (0.0, True), (-3.0, False),
                                      (100.0, True)])
def test_a_start_within_the_stop_tolerance_is_on_the_stop(method, L, upper):
    """A block resting 0.9e-12 max(1, |L|) beyond its stop is put on it: locked at t = 0,
    never beyond it (it fell 5 m through the stop at L = 1 m, 1e-12 m beyond, with
    "success"); 1.1e-12 max(1, |L|) beyond is refused, naming [initial] joints.X."""
    tol = 1e-12 * max(1.0, abs(L))
    sign = 1.0 if upper else -1.0
    res = cd.simulate(block(L + sign * 0.9 * tol, L, upper), 1.0, method=method)
    assert [(e.kind, e.t) for e in res.events] == [("lock", 0.0)]
    assert np.all(res.joint("X").position == L)
    with pytest.raises(cd.ModelError, match=r"\[initial\] joints\.X: .* outside the limits"):
        block(L + sign * 1.1 * tol, L, upper)


@pytest.mark.timeout(200)
def test_work_precision_takes_the_comparisons_grid():
    """``compare``'s work-precision study ran on a fixed 0.01-s grid with dt 0.01, 0.005,
    0.0025 whatever --dt said: on the cam (events every few ms) no sample was away from an
    event and every row read 0.0. On the run's grid now, and a row with nothing to measure
    is NaN, not 0."""
    from cmm_dae.studies.precision import work_precision

    mech = cd.load(cd.example("cam_valve_train"))
    wp = work_precision(mech, t_end=0.02, grid=1e-4, rtols=(1e-4, 1e-6, 1e-8))
    assert [r.setting for r in wp.rows] == ["rtol 0.0001", "rtol 1e-06", "rtol 1e-08",
                                           "dt 0.0001", "dt 5e-05", "dt 2.5e-05"]
    ida = [r.error for r in wp.rows if r.method == "IDA"]
    assert all(0.0 < e < 1e-3 for e in ida) and ida[0] > ida[1] > ida[2]
    coarse = work_precision(mech, t_end=0.02, grid=0.01, rtols=(1e-6,), dts=(1e-3,))
    assert all(math.isnan(r.error) for r in coarse.rows)


@pytest.mark.timeout(200)
@pytest.mark.parametrize("rtol", [1e-8, 1e-12])
def test_multipliers_stay_in_the_error_test_without_a_landing_contact(rtol):
    """With the multipliers out of IDA's error test on every model, the slider-crank with
    a stop fell to order 1 at 1.92 s and failed the error test at every step (11,120 steps
    over 10 s at rtol 1e-8 against 1,080), and stalled at rtol 1e-12; they leave it only
    where a unilateral contact lands. Both paths to the end, the same events within 1e-9
    s, at most 2,000 steps at rtol 1e-8 and 10,000 at 1e-12."""
    mech = cd.load(cd.example("slider_crank_stop"))
    runs = [cd.simulate(mech, 10.0, rtol=rtol, compiled=c) for c in (False, True)]
    for r in runs:
        assert r.status is cd.Status.SUCCESS and r.t[-1] == 10.0
        assert r.stats.steps <= (2000 if rtol == 1e-8 else 10_000), r.stats.steps
    assert [e.kind for e in runs[0].events] == [e.kind for e in runs[1].events] \
        == ["limit", "release"]
    assert max(abs(a.t - b.t) for a, b in zip(*(r.events for r in runs), strict=True)) <= 1e-9


@pytest.mark.timeout(200)
@pytest.mark.parametrize("atol", [1e-14, 1.0000001e-14])
def test_a02_tight_tolerance_does_not_hang_on_atols_last_bit(atol):
    """A02 (one loop) over 2 s at rtol 1e-12: with atol 1.0000001e-14 the compiled path
    took 500,000 steps in place next to the first singular position (it had no crawl
    test; the Python path failed there and crossed). Both atols and both paths now reach
    2 s through the same two crossings, the crank tip within 1e-9 m of the reference
    (Lagrange's one-coordinate equation by DOP853; measured 3.6e-10 and 4.1e-10 m)."""
    from cmm_dae.description import iftomm

    mech = iftomm.a02_four_bar(1)
    for compiled in (True, False):
        res = cd.simulate(mech, 2.0, rtol=1e-12, atol=atol, compiled=compiled)
        assert res.status is cd.Status.SUCCESS and res.t[-1] == 2.0
        assert [e.kind for e in res.events] == ["singular", "singular"]
        err = np.hypot(*(iftomm.crank_tip(res) - iftomm.a02_reference(1, res.t)).T)
        assert np.max(err) <= 1e-9, np.max(err)


@pytest.mark.timeout(200)
def test_a02_ten_loops_crosses_where_the_instant_was_predicted_early():
    """A02 with 10 loops over 2 s at rtol 1e-12, atol 1.0000001e-14 (compiled): IDA gave up
    at a ratio of 0.047, 0.146 s before the second singular position, the crossing's
    second-order path put the instant early, and the Gauss steps stopped there while the
    ratio was still falling: a "dead point" at 1.09 s. They go on until the ratio has risen
    past the instant; through both crossings, the tip within 1e-8 m of the reference
    (measured 2.2e-9 m; 4.2e-9 with atol 1e-14)."""
    from cmm_dae.description import iftomm

    res = cd.simulate(iftomm.a02_four_bar(10), 2.0, rtol=1e-12, atol=1.0000001e-14,
                      compiled=True)
    assert res.status is cd.Status.SUCCESS and res.t[-1] == 2.0
    assert [e.kind for e in res.events] == ["singular", "singular"]
    err = np.hypot(*(iftomm.crank_tip(res) - iftomm.a02_reference(10, res.t)).T)
    assert np.max(err) <= 1e-8, np.max(err)
