"""The DAE formulation and the run machinery: Jacobian, consistent start, failures, export."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae.hybrid.start import assemble_positions, assemble_velocities, initial_guess

from refs import short_coupler_four_bar

MODELS = Path(__file__).resolve().parent.parent / "models"


@pytest.mark.parametrize("name", ["slider_crank", "four_bar", "crank_pendulum"])
def test_jacobian_against_finite_differences(name):
    model = cd.Model(cd.load(MODELS / f"{name}.toml"))
    rng = np.random.default_rng(1)
    N = model.N
    y, yp = rng.normal(size=N), rng.normal(size=N)
    t, cj = 0.37, 123.0
    p = model.params()
    J = model.jac_sparse_fn(t, y, yp, cj, p).full()
    h = 1e-6
    fd = np.zeros((N, N))
    for k in range(N):
        e = np.zeros(N)
        e[k] = h
        F = lambda y_, yp_: np.asarray(model.res_fn(t, y_, yp_, p))  # noqa: E731
        dy = F(y + e, yp) - F(y - e, yp)
        dyp = F(y, yp + e) - F(y, yp - e)
        fd[:, k] = ((dy + cj * dyp) / (2 * h)).ravel()
    assert np.max(np.abs(J - fd)) <= 1e-6 * max(1.0, np.max(np.abs(J)))
    assert not np.allclose(J, J.T)  # the check would miss a transposition otherwise


def test_consistent_start_satisfies_all_levels():
    """Positions, velocities and the GGL residual are consistent at t = 0."""
    mech = cd.load(MODELS / "four_bar.toml")
    model = cd.Model(mech)
    p = model.params()
    q = assemble_positions(model, 0.0, p, {}, initial_guess(model))
    v = assemble_velocities(model, q, 0.0, p, {})
    a, lam, _ = model.kkt(q, v, 0.0, p)
    y = np.concatenate([q, v, lam, np.zeros(model.m)])
    yp = np.concatenate([v, a, np.zeros(2 * model.m)])
    assert np.max(np.abs(np.asarray(model.res_fn(0.0, y, yp, p)))) <= 1e-12
    # the crank is at its driver's initial angle and turns at its speed
    c, cd_, _ = model.coord_fn(q, v, p)
    assert float(c[0]) == pytest.approx(1.0, abs=1e-14)
    assert float(cd_[0]) == pytest.approx(2 * math.pi, rel=1e-13)
    # the next run's start is the one kept, as a copy of its own: changing it changes
    # nothing kept
    again = assemble_velocities(model, q, 0.0, p, {})
    assert np.array_equal(again, v) and again is not v
    again[:] = 0.0
    assert np.array_equal(assemble_velocities(model, q, 0.0, p, {}), v)


def test_failure_keeps_partial_result(tmp_path):
    """A non-Grashof four-bar driven through its toggle: the loop opens; the partial
    result reaches the dead point and the error says what happened."""
    mech = short_coupler_four_bar(tmp_path, 0.16)
    with pytest.raises(cd.SolverError, match=r"dead point at t = 0\.21[0-9]* s: the constraints of "
                       r"joint A, joint B, joint C, joint D become dependent") as info:
        cd.run_dae(mech, 1.0, rtol=1e-8)
    part = info.value.result
    assert part is not None and 0.0 < part.t[-1] < 1.0
    assert part.status != "success"
    # the partial result is complete up to its last time: forces are finite there
    assert np.all(np.isfinite(part.driver("A").effort))
    res = cd.run_dae(mech, 1.0, rtol=1e-8, throw=False)
    assert res.t[-1] == pytest.approx(part.t[-1], abs=1e-12)


def test_result_save_load_csv(tmp_path):
    mech = cd.load(MODELS / "slider_crank.toml")
    res = cd.run_dae(mech, 0.5, output_dt=0.01)
    path = res.save(tmp_path / "r.npz")
    back = cd.load_result(path)
    assert np.array_equal(back.t, res.t)
    assert np.array_equal(back.driver("A").effort, res.driver("A").effort)
    assert np.array_equal(back.body("rod").pose, res.body("rod").pose)
    assert back.stats.steps == res.stats.steps > 0
    csv_path = res.to_csv(tmp_path / "r.csv")
    lines = csv_path.read_text().splitlines()
    assert len(lines) == res.t.size + 1
    head = lines[0].split(",")
    col = head.index("driver A effort [N m]")
    assert float(lines[10].split(",")[col]) == res.driver("A").effort[9]


def test_outputs_and_stats():
    mech = cd.load(MODELS / "slider_crank.toml")
    res = cd.run_dae(mech, 1.0, output_dt=0.01)
    assert res.t.size == 101
    assert np.allclose(np.diff(res.t), 0.01, atol=1e-12)
    assert res.stats.steps > 50 and res.stats.nfev >= res.stats.steps and res.stats.njev > 0
    # body frame pose: the crank frame sits on A; the slider's on the guide
    assert np.max(np.abs(res.body("crank").pose[:, :2])) <= 1e-9
    assert np.max(np.abs(res.body("slider").pose[:, 1])) <= 1e-9
    assert np.max(np.abs(res.body("crank").velocity[:, 2] - 2 * math.pi)) <= 1e-7
    with pytest.raises(cd.CmmError, match="no joint named 'Z'"):
        res.joint("Z")


def test_body_frame_velocity_is_derivative_of_pose():
    mech = cd.load(MODELS / "four_bar.toml")
    res = cd.run_dae(mech, 0.2, rtol=1e-10, atol=1e-12, output_dt=1e-4)
    b = res.body("coupler")
    dpose = np.gradient(b.pose, res.t, axis=0, edge_order=2)
    assert np.max(np.abs(dpose[5:-5] - b.velocity[5:-5])) <= 1e-5
    dvel = np.gradient(b.velocity, res.t, axis=0, edge_order=2)
    assert np.max(np.abs(dvel[5:-5] - b.acceleration[5:-5])) <= 1e-3 * np.max(np.abs(
        b.acceleration))


def test_compiled_model_same_numbers_and_clean_fallback(tmp_path, monkeypatch):
    """The optional compiled path (C code generation + the system compiler) gives the same
    numbers; without a working compiler it warns and keeps CasADi's virtual machine."""
    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path / "cache"))
    mech = cd.load(MODELS / "pendulum_stop.toml")
    plain = cd.run_dae(mech, 1.0, rtol=1e-10, atol=1e-12)
    model = cd.Model(mech, compiled=True)
    assert model.compiled
    assert len(list((tmp_path / "cache").glob("cmm_*.so"))) == 1
    comp = cd.run_dae(mech, 1.0, rtol=1e-10, atol=1e-12, model=model)
    assert comp.events[0].t == pytest.approx(plain.events[0].t, abs=1e-12)
    assert np.max(np.abs(comp.joint("O").torque - plain.joint("O").torque)) <= 1e-12
    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path / "other"))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    with pytest.warns(UserWarning, match="virtual machine"):
        fallback = cd.Model(mech, compiled=True)
    assert not fallback.compiled
    again = cd.run_dae(mech, 1.0, rtol=1e-10, atol=1e-12, model=fallback)
    assert again.events[0].t == plain.events[0].t


@pytest.mark.parametrize("motion", ["table", "harmonic", "polynomial"])
def test_driver_motions(motion):
    """Each driver law is followed exactly: the crank angle against scipy's clamped spline,
    the sine, the polynomial; the rate by the derivative."""
    from scipy.interpolate import CubicSpline

    times, values = [0.0, 0.3, 0.7, 1.0], [0.5, 1.0, 0.8, 2.0]
    kw = {"table": dict(motion="table", times=tuple(times), values=tuple(values)),
          "harmonic": dict(motion="harmonic", initial=0.5, amplitude=0.3, frequency=2.0,
                           phase=0.0),
          "polynomial": dict(motion="polynomial", coefficients=(0.5, 1.0, -2.0, 0.5))}[motion]
    base = cd.load(MODELS / "slider_crank.toml")
    mech = cd.Mechanism(base.name, bodies=dict(base.bodies), joints=dict(base.joints),
                        ground=dict(base.ground), drivers=[cd.Driver("A", **kw)],
                        gravity=base.gravity)
    res = cd.run_dae(mech, 1.2, rtol=1e-10, atol=1e-12, output_dt=0.01)
    t, th, w = res.t, res.joint("A").position, res.joint("A").velocity
    if motion == "table":
        sp = CubicSpline(times, values, bc_type="clamped")
        inside = t <= 1.0
        ref, dref = sp(t[inside]), sp(t[inside], 1)
        assert np.max(np.abs(th[~inside] - 2.0)) <= 1e-12  # held after the table
        th, w = th[inside], w[inside]
    elif motion == "harmonic":
        ref = 0.5 + 0.3 * np.sin(4 * np.pi * t)
        dref = 0.3 * 4 * np.pi * np.cos(4 * np.pi * t)
    else:
        ref = 0.5 + t - 2 * t**2 + 0.5 * t**3
        dref = 1 - 4 * t + 1.5 * t**2
    assert np.max(np.abs(th - ref)) <= 1e-10
    assert np.max(np.abs(w - dref)) <= 1e-8
