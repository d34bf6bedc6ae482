"""Faults during a run: each raises SolverError (or returns a failed Result with
throw=False) carrying the partial Result up to the failure; and determinism."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cmm_dae as cd
import cmm_dae.integrators.ida as ida_mod

from refs import short_coupler_four_bar

MODELS = Path(__file__).resolve().parent.parent / "models"


def stopped_slider_crank(tmp_path: Path) -> cd.Mechanism:
    """A driven slider-crank whose slider meets a plastic stop: with the slider held, the
    driven crank cannot move on (no spring joint in the loop): a lock-up."""
    text = (MODELS / "slider_crank.toml").read_text().replace(
        'axis = [1.0, 0.0]', 'axis = [1.0, 0.0]\nlimits = { upper = 0.245 }')
    path = tmp_path / "lockup.toml"
    path.write_text(text)
    return cd.load(path)


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_lock_up(tmp_path, method):
    mech = stopped_slider_crank(tmp_path)
    run = (lambda **k: cd.run_dae(mech, 2.0, rtol=1e-10, atol=1e-12, **k)) if method == "ida" \
        else (lambda **k: cd.run_iterative(mech, 2.0, dt=0.001, **k))
    with pytest.raises(cd.SolverError, match=r"lock-up at t = [0-9.]+ s: with joint E locked "
                       r"on its upper stop .*\(driver A\)") as info:
        run()
    part = info.value.result
    # the slider (centred crank 0.05, rod 0.2, starting at 0.5 rad and 1 rev/s) reaches
    # 0.245 m at the first crank angle where 0.05 cos th + sqrt(0.2^2 - 0.05^2 sin^2 th) = 0.245
    th = np.linspace(0.5, 2 * np.pi, 200001)
    x = 0.05 * np.cos(th) + np.sqrt(0.04 - 0.0025 * np.sin(th) ** 2)
    t_hit = (th[np.flatnonzero((x[:-1] < 0.245) & (x[1:] >= 0.245))[0]] - 0.5) / (2 * np.pi)
    if method == "ida":
        assert abs(part.t[-1] - t_hit) < 1e-4
    else:  # the iterative algorithm switches at the end of the step that crossed
        assert 0.0 <= part.t[-1] - t_hit < 1e-3 + 1e-4
    assert part.status.startswith("lock-up") or "lock-up" in part.status
    assert info.value.configuration is not None
    res = run(throw=False)
    assert not res.success and res.t[-1] == part.t[-1]


def test_keyboard_interrupt_keeps_partial_result(monkeypatch):
    mech = cd.load(MODELS / "double_folded.toml")
    orig = ida_mod.IdaIntegrator._events

    def interrupted(self, t, y, yp, out):
        if t > 4.0:
            raise KeyboardInterrupt
        orig(self, t, y, yp, out)

    monkeypatch.setattr(ida_mod.IdaIntegrator, "_events", interrupted)
    with pytest.raises(cd.SolverError, match="interrupted") as info:
        cd.run_dae(mech, 10.0)
    part = info.value.result
    assert 3.9 <= part.t[-1] <= 4.0 + 1e-9
    assert [e.kind for e in part.events] == ["limit"]  # the switch at 2.63 s is kept
    assert np.all(np.isfinite(part.driver("A").effort))


def non_grashof(tmp_path: Path) -> cd.Mechanism:
    """Crank 0.04, coupler 0.09, rocker 0.1, ground 0.16: s + l > p + q, so the driven crank
    cannot turn fully; coupler and rocker reach a toggle (a dead point)."""
    return short_coupler_four_bar(tmp_path, 0.16)


def toggle_time() -> float:
    """First time the crank (1 + 2 pi t) puts B at 0.19 m from D: coupler and rocker
    collinear (0.09 + 0.1)."""
    t = np.linspace(0.0, 0.5, 500001)
    th = 1.0 + 2 * np.pi * t
    dist = np.hypot(0.16 - 0.04 * np.cos(th), 0.04 * np.sin(th))
    return float(t[np.flatnonzero(dist >= 0.19)[0]])


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_dead_point(tmp_path, method):
    mech = non_grashof(tmp_path)
    with pytest.raises(cd.SolverError, match=r"dead point (at|near) t = 0\.2[0-9]* s.*joint B, "
                       r"joint C, joint D") as info:
        if method == "ida":
            cd.run_dae(mech, 1.0)
        else:
            cd.run_iterative(mech, 1.0, dt=0.01)
    part = info.value.result
    t_dead = toggle_time()
    assert t_dead - 0.011 <= part.t[-1] <= t_dead  # the last state reached before the toggle
    assert np.all(np.isfinite(part.driver("A").effort))


def test_zeno_with_high_restitution_ends_in_a_lock(tmp_path):
    text = (MODELS / "pendulum_stop.toml").read_text().replace(
        "restitution = 0.0", "restitution = 0.8")
    path = tmp_path / "zeno.toml"
    path.write_text(text)
    res = cd.run_dae(cd.load(path), 5.0, rtol=1e-10, atol=1e-12)
    assert res.events[-1].kind in ("lock", "limit")
    assert 50 < len(res.events) < 200
    assert res.t[-1] == 5.0 and res.success


@pytest.mark.parametrize("name", ["double_folded", "nipper_swing"])
def test_determinism(name):
    mech = cd.load(MODELS / f"{name}.toml")
    a = cd.run_dae(mech, 10.0)
    b = cd.run_dae(mech, 10.0)
    assert a.data.keys() == b.data.keys()
    for k in a.data:
        assert np.array_equal(a.data[k], b.data[k], equal_nan=True), k  # NaN: not integrated
    assert a.events == b.events
    c = cd.run_iterative(mech, 10.0, dt=0.01)
    d = cd.run_iterative(mech, 10.0, dt=0.01)
    for k in c.data:
        assert np.array_equal(c.data[k], d.data[k], equal_nan=True), k
