"""Small things users met (issue: trust in long runs, item 11), each checked as they met it."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cmm_dae as cd

from refs import gear_pair

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("path", ["gears.Z.ratio", "joints.Z.ratio"])
def test_a_gear_ratio_is_a_parameter(path):
    """As the file writes it ([joints.Z]) or as the API keeps it: the pair's closed-form
    acceleration (2 - r) / (I_A + r^2 I_B) (the brake -1 N m on B) at r = -0.4, to 1e-9."""
    res = cd.run_dae(cd.with_params(gear_pair(), {path: -0.4}), 0.1, rtol=1e-10,
                     output_dt=0.05)
    r = -0.4
    assert np.allclose(res.joint("A").acceleration, (2.0 - r) / (1e-4 + r * r * 2e-3),
                       rtol=1e-9)
    with pytest.raises(cd.ModelError, match=r"\[parameters\] gears\.Y\.ratio: .*no gear 'Y'"):
        cd.with_params(gear_pair(), {"gears.Y.ratio": 1.0})


def test_a_one_argument_load_law_is_refused_up_front():
    m = gear_pair()
    with pytest.raises(cd.ModelError, match=r"\[loads\.motor\] law: expected a callable "
                       r"f\(t, coordinate, rate\) of three arguments"):
        cd.Mechanism("x", ground=m.ground, bodies=list(m.bodies.values()),
                     joints=list(m.joints.values()), gears=list(m.gears.values()),
                     loads=[cd.Load("motor", cd.Law(func=lambda t: 1.0), joint="A")])


def test_a_missing_body_is_named_as_a_body():
    res = cd.run_dae(gear_pair(), 0.01, output_dt=0.01)
    with pytest.raises(cd.CmmError, match="no body named 'gc'"):
        res.body("gc")


def slot_file(tmp_path, old: str, new: str) -> Path:
    text = (ROOT / "models" / "curved_slot.toml").read_text()
    assert old in text
    f = tmp_path / "slot.toml"
    f.write_text(text.replace(old, new))
    return f


def test_restitution_at_an_open_curves_ends(tmp_path):
    """An open spline's ends are stops: a restitution acts there (the pin bounces off the
    slot's end with -e times its speed)."""
    f = slot_file(tmp_path, 'curve = { kind = "spline"',
                  'restitution = 0.5\ncurve = { kind = "spline"')
    res = cd.run_dae(cd.load(f), 1.0)
    bounce = next(e for e in res.events if e.kind == "bounce")
    assert bounce.velocity_after == pytest.approx(-0.5 * bounce.velocity_before, rel=1e-12)


def test_a_non_finite_spline_point_is_named(tmp_path):
    f = slot_file(tmp_path, "[0.165, 0.011]", "[0.165, nan]")
    with pytest.raises(cd.ModelError, match=r"\[joints\.K\] curve\.points\[1\]: expected "
                       r"finite coordinates"):
        cd.load(f)


def test_a_lines_sides_are_left_and_right():
    """side = "left" is a line's outside (the block rests on the line from above), "right"
    the other side; "left" on a circle is refused."""
    def block(side: str, curve: dict) -> dict:
        return {"mechanism": {"name": "block", "gravity": [0.0, -9.81]},
                "ground": {"points": {"O": [0.0, 0.0]}},
                "bodies": {"b": {"mass": 1.0, "inertia": 1e-3, "points": {"P": [0.0, 0.0]},
                                 "guess": [0.0, 0.1, 0.0]}},
                "joints": {"X": {"type": "prismatic", "connects": ["ground.O", "b.P"],
                                 "axis": [0.0, 1.0]},
                           "K": {"type": "contact", "connects": ["ground.O", "b.P"],
                                 "curve": curve, "unilateral": True, "side": side}},
                "initial": {"joints": {"X": 0.1}, "velocities": {"X": 0.0}}}
    line = {"kind": "line", "direction": [1.0, 0.0]}
    res = cd.run_dae(cd.from_dict(block("left", line)), 0.5)
    landing = next(e for e in res.events if e.kind in ("landing", "bounce", "limit"))
    assert landing.t == pytest.approx(math.sqrt(2 * 0.1 / 9.81), abs=1e-8)
    with pytest.raises(cd.ModelError, match=r"joint 'K' assembles at -0\.1"):
        cd.run_dae(cd.from_dict(block("right", line)), 0.5)
    with pytest.raises(cd.ModelError, match=r"\[joints\.K\] side: 'left' is a side of a line"):
        cd.from_dict(block("left", {"kind": "circle", "radius": 0.05}))


def test_an_element_between_points_a_joint_holds_together():
    m = gear_pair()
    with pytest.raises(cd.ModelError, match=r"\[elements\.s\] connects: revolute joint 'A' "
                       r"holds these two points together"):
        cd.Mechanism("x", ground=m.ground, bodies=list(m.bodies.values()),
                     joints=list(m.joints.values()),
                     elements=[cd.Element("s", "ground.A", "ga.O", stiffness=10.0)])


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cmm_dae.cli", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=120)


def test_save_and_csv_to_one_file_are_refused_and_events_reads_any_saved_name(tmp_path):
    r = cli("run", str(ROOT / "models" / "slider_crank_stop.toml"), "--t-end", "3",
            "--save", "P", "--csv", "P", cwd=tmp_path)
    assert r.returncode != 0 and "both be written to" in r.stderr
    assert not (tmp_path / "P").exists()
    r = cli("run", str(ROOT / "models" / "slider_crank_stop.toml"), "--t-end", "3",
            "--save", "r.dat", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = cli("events", "r.dat", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "limit" in r.stdout and "E" in r.stdout


def test_the_iterative_methods_failures_name_it():
    """The singular-position crossing's messages name the integrator that stopped."""
    from cmm_dae.singular.approach import Start

    st = Start(None, None, 1.0, None, None, None, 0.5, None, 1.0, 0.0, "iterative")
    msg = str(st.not_singular("ahead"))
    assert "fixed-step algorithm could not continue" in msg and "smaller dt" in msg
    assert "IDA" not in msg and "rtol" not in msg
    st = Start(None, None, 1.0, None, None, None, 0.5, None, 1.0, 0.0)
    assert "IDA could not continue" in str(st.not_singular("ahead"))


def test_ctrl_c_on_the_python_path_keeps_the_run_so_far():
    """A Ctrl-C (here raised by a load law past 0.5 s) on the Python IDA path: the partial
    Result holds the samples up to the last step completed (it held the start alone: the
    grid's samples came back only when IDA's whole call returned)."""
    def law(t: float, c: float, rate: float) -> float:
        if t > 0.5:
            raise KeyboardInterrupt
        return 2.0 + math.sin(20 * t)

    m = gear_pair()
    mech = cd.Mechanism("x", ground=m.ground, bodies=list(m.bodies.values()),
                        joints=list(m.joints.values()), gears=list(m.gears.values()),
                        initial=m.initial, loads=[cd.Load("motor", cd.Law(func=law), joint="A")])
    with pytest.raises(cd.SolverError) as info:
        cd.simulate(mech, 2.0, compiled=False)
    res = info.value.result
    assert info.value.status is cd.Status.INTERRUPTED
    assert 0.4 < res.t[-1] <= 0.5 and res.t.size > 40
    assert np.all(np.diff(res.t) > 0)


def test_friction_from_the_reaction_settles_alike_on_both_integrators():
    """A free slider-crank with friction from the reaction on every joint, thrown at 20
    rad/s, settles on both integrators (it ended as a friction jam at 0.83 s on IDA and at
    0.096 s on the fixed-step algorithm, then in a storm of slip events at rates of
    1e-42). The rod pin C's rate passes zero while the crank passes upright, where C's lock
    would be redundant: IDA locates that instant and C slips on reversed; the fixed-step
    algorithm meets it a step late, where sticking has no consistent forces, and C slips on
    reversed there too. Once the slider sticks the mechanism cannot move: the pins are
    held at rest by its lock at that instant, with no friction of their own to reverse. The
    two agree on the sequence of slips and the stick (but for one direction at the last
    instant), and
    the fixed-step algorithm's rest state converges on IDA's (first order: dt 1e-3 -> 1e-4
    brings crank A from 3.1e-3 to 3.2e-4 rad of IDA's)."""
    mech = cd.load(ROOT / "tests" / "models" / "free_slider_crank_friction.toml")
    ida = cd.simulate(mech, 1.5)
    steps = [cd.simulate(mech, 1.5, method="iterative", dt=dt) for dt in (1e-3, 1e-4)]
    assert ida.success and all(r.success for r in steps)
    held = [e for e in ida.events if "held at rest" in e.note]
    assert sorted(e.joint for e in held) == ["A", "B", "C"] and \
        all(e.kind == "stick" for e in held)

    def groups(events) -> list[tuple[float, list]]:
        """The events by instant (an instant's order is the policy's, not the physics')."""
        out: list = []
        for e in events:
            if out and abs(e.t - out[-1][0]) < 1e-9:
                out[-1][1].append((e.kind, e.joint, e.side))
            else:
                out.append((e.t, [(e.kind, e.joint, e.side)]))
        return [(t, sorted(g)) for t, g in out]

    ref = groups(ida.events)
    assert ("stick", "E", "stick") in ref[-1][1]
    assert all(abs(e.t - ref[-1][0]) < 1e-9 for e in held)  # with the slider's stick
    for r in steps:
        got = groups(r.events)
        assert [g for _, g in got][:-1] == [g for _, g in ref][:-1]
        # the instant it comes to rest: the same joints change, the slider sticks and
        # holds the pins at rest with it; the pin C's last slip direction, decided before
        # or after A's and B's reversals of the same instant, differs (and is moot)
        assert sorted({x[:2] for x in got[-1][1]}) == sorted({x[:2] for x in ref[-1][1]})
    assert max(abs(a[0] - b[0]) for a, b in zip(ref, groups(steps[1].events), strict=True)) \
        < 1e-3
    fine = steps[1]
    errs = [abs(r.joint("A").position[-1] - ida.joint("A").position[-1]) for r in steps]
    assert errs[1] < 1e-3 and errs[0] / errs[1] > 5.0
    assert abs(fine.joint("E").position[-1] - ida.joint("E").position[-1]) < 1e-4
    assert np.max(np.abs(ida.joint("A").velocity[ida.t > 1.0])) < 1e-20  # at rest


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_a_contact_started_on_its_curve_that_leaves_at_once_says_so(method):
    """A block started on a line (K = 0) with side = "right" (below it) while gravity pulls
    it down falls away at once: a lift-off at t = 0 whose note asks about the side (it
    flew off with no event at all); with side = "left" it rests on the line (a lock)."""
    def block(side: str) -> cd.Mechanism:
        return cd.from_dict({
            "mechanism": {"name": "block", "gravity": [0.0, -9.81]},
            "ground": {"points": {"O": [0.0, 0.0]}},
            "bodies": {"b": {"mass": 1.0, "inertia": 1e-3, "points": {"P": [0.0, 0.0]}}},
            "joints": {"X": {"type": "prismatic", "connects": ["ground.O", "b.P"],
                             "axis": [0.0, 1.0]},
                       "K": {"type": "contact", "connects": ["ground.O", "b.P"],
                             "curve": {"kind": "line", "direction": [1.0, 0.0]},
                             "unilateral": True, "side": side}},
            "initial": {"joints": {"K": 0.0}, "velocities": {"K": 0.0}}})
    wrong = cd.simulate(block("right"), 0.2, method=method)
    assert [(e.kind, e.t) for e in wrong.events] == [("lift-off", 0.0)]
    assert "is `side` the side it keeps to?" in wrong.events[0].note
    right = cd.simulate(block("left"), 0.2, method=method)
    assert [(e.kind, e.t) for e in right.events] == [("lock", 0.0)]
    assert np.max(np.abs(right.joint("X").position)) == 0.0


def test_the_order_one_trap_loosens_the_velocities_at_most_1000x(monkeypatch):
    """Where IDA is stuck at order 1 (suppress.TrapCheck, here made to say so after five
    steps of every segment), the segment ends and goes on with the velocities' absolute
    tolerance 10x looser, three times at most; the fourth time the run fails and says why,
    the run so far kept."""
    from cmm_dae.integrators import suppress

    def stuck_after_five(self, nst: int, trapped=lambda: None) -> bool:
        if nst >= 5:
            trapped()
            return True
        return False

    monkeypatch.setattr(suppress.TrapCheck, "__call__", stuck_after_five)
    with pytest.raises(cd.SolverError, match=r"stuck at order 1 .* atol raised 1000x") as info:
        cd.simulate(cd.load(ROOT / "models" / "double_folded.toml"), 1.0, compiled=False)
    assert info.value.status is cd.Status.INTEGRATOR
    assert info.value.result.t[-1] > 0.0


@pytest.mark.parametrize("name, t_end, t_rest", [
    ("free_four_bar_pin_friction", 1.2, 0.9033),
    ("slider_crank_pushed_after_rest", 2.5, 2.0910)])
def test_joints_passing_rest_together_all_turn_back(name, t_end, t_rest):
    """The pins of a one-degree-of-freedom linkage pass rest together at its turning
    points; IDA locates the instant on one of them. The others' rates sat just past zero
    after the restart's projection, where no root finder saw them cross: their friction
    then pushed them along (positive power for 0.15 s on the four-bar at the default rtol,
    and on the slider-crank a missed stick let the guide's friction restart it). Now every
    joint turning back there is decided at that instant: friction never does positive
    work, the mechanism comes to rest at the same instant at every rtol 1e-6 .. 1e-10
    (1e-4 s), a release by the load decides the held joints again, and the fixed-step
    algorithm's rest state converges on IDA's (dt 1e-3 -> 5e-4: about half the error)."""
    mech = cd.load(ROOT / "tests" / "models" / f"{name}.toml")
    runs = [cd.simulate(mech, t_end, rtol=rtol, output_dt=None) for rtol in (1e-6, 1e-8, 1e-10)]
    for r in runs:
        assert r.success
        for j in mech.joints:  # friction opposes the motion (or the joint is at rest)
            assert np.max(r.joint(j).friction * r.joint(j).velocity) <= 1e-9, (j, r.meta)
        last = [e for e in r.events if e.kind == "stick" and "held" not in e.note][-1]
        assert abs(last.t - t_rest) < 1e-4
    ref = runs[-1].data["q"][-1]
    errs = [np.max(np.abs(cd.simulate(mech, t_end, method="iterative", dt=dt).data["q"][-1]
                          - ref)) for dt in (1e-3, 5e-4)]
    assert errs[1] < 0.7 * errs[0] and errs[1] < 0.05


def test_an_impact_that_reverses_a_slipping_pin_reverses_its_friction():
    """The shipped double-folded mechanism with pin friction: the slider's stop at 2.68 s
    sends pin D the other way, and its friction kept pushing it along until 4.88 s (up to
    2.9e-3 W over 2,200 samples); its slip now follows the impulse. At the start, D's
    slip was decided before the slider's stick and pushed it the first 2 ms; it is
    decided again once all joints at rest are. Friction does no positive work (1e-9 W),
    and the energy audit closes within 1e-7 J."""
    res = cd.simulate(cd.load(cd.example("double_folded_pin_friction")), 10.0, output_dt=1e-3)
    for j in ("C", "D", "E"):
        power = res.joint(j).friction * res.joint(j).velocity
        assert np.max(power) <= 1e-9, j
    assert np.max(np.abs(res.energy().residual)) < 1e-7


def test_a_sample_whose_reaction_friction_fails_keeps_the_run(monkeypatch):
    """Post-processing solves friction from the reaction sample by sample; one sample it
    cannot solve (here made to fail) no longer loses the run to a raw LinAlgError: the
    Result stands, that sample's accelerations and forces are NaN, and a warning names
    the first time."""
    from cmm_dae.equations import model as model_module

    mech = cd.load(cd.example("double_folded_pin_friction"))
    orig = model_module.Model.kkt
    calls: list = []

    def flaky(self, q, v, t, p):
        if t > 1.0 and not calls and self.reacting and np.any(p != 0.0):
            calls.append(t)
            raise np.linalg.LinAlgError("made to fail")
        return orig(self, q, v, t, p)

    res_ok = cd.simulate(mech, 2.0, compiled=False)
    monkeypatch.setattr(model_module.Model, "kkt", flaky)
    with pytest.warns(RuntimeWarning, match=r"could not be solved at 1 sample\(s\), the first "
                                             r"at t = 1\.\d+ s"):
        res = cd.simulate(mech, 2.0, compiled=False)
    bad = np.isnan(res.data["a"]).any(axis=1)
    assert res.success and bad.sum() == 1 and res.t[bad][0] > 1.0
    assert np.array_equal(res.data["q"], res_ok.data["q"])


@pytest.mark.timeout(120)
def test_events_of_a_model_take_the_runs_rtol(tmp_path):
    """``events MODEL --rtol`` lists the run at that tolerance (found by a new user: it
    always ran at the default, so its times differed from the ``run --rtol`` just made)."""
    model = str(ROOT / "models" / "pendulum_stop.toml")
    r = cli("events", model, "--t-end", "1", "--rtol", "1e-10", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    t = cd.run_dae(cd.load(model), 1.0, rtol=1e-10).events[0].t
    assert f"{t:.9f}" in r.stdout
    r = cli("events", model, "--rtol", "-1", cwd=tmp_path)
    assert r.returncode != 0 and "rtol" in r.stderr
