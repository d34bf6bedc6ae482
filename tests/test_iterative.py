"""The paper's iterative algorithm, comparison reports and the command line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cmm_dae as cd

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"


def test_zero_dof_mechanism_matches_ida():
    """No free DOF: only kinematics and the KKT solve are involved."""
    mech = cd.load(MODELS / "four_bar.toml")
    model = cd.Model(mech)
    a = cd.run_dae(mech, 2.0, rtol=1e-10, atol=1e-12, output_dt=0.01, model=model)
    b = cd.run_iterative(mech, 2.0, dt=0.01, model=model)
    assert np.allclose(a.t, b.t, atol=1e-12)
    ta, tb = a.driver("A").effort, b.driver("A").effort
    assert np.max(np.abs(ta - tb)) <= 1e-8 * np.max(np.abs(ta))
    assert np.max(np.abs(a.joint("C").force - b.joint("C").force)) <= 1e-8
    assert b.stats.steps == 200 and b.stats.method == "iterative"


def test_observed_order_is_one():
    """One free DOF (crank + swinging link): explicit Euler steps, order 1."""
    mech = cd.load(MODELS / "crank_pendulum.toml")
    conv = cd.convergence(mech, [0.002, 0.001, 0.0005, 0.00025], t_end=1.0, ref_rtol=1e-11)
    for name, orders in conv.orders.items():
        assert len(orders) == 3
        assert all(0.8 <= p <= 1.2 for p in orders), (name, orders)
    assert conv.errors["joint B"][-1] < conv.errors["joint B"][0] / 6


def test_stop_case_same_sequence_and_switch_times_within_dt():
    mech = cd.load(MODELS / "slider_crank_stop.toml")
    model = cd.Model(mech)
    a = cd.run_dae(mech, 10.0, rtol=1e-9, atol=1e-11, model=model)
    for dt in (0.01, 0.005):
        b = cd.run_iterative(mech, 10.0, dt=dt, model=model)
        cmp = cd.compare(a, b)
        assert cmp.same_event_sequence
        assert [e.kind for e in a.events] == [e.kind for e in b.events]
        assert all(0.0 <= m.dt < dt + 1e-12 for m in cmp.events)  # at the step's end


def test_plastic_stop_iterative_clamps_and_locks():
    mech = cd.load(MODELS / "pendulum_stop.toml")
    b = cd.run_iterative(mech, 1.0, dt=0.001)
    assert [(e.kind, e.joint) for e in b.events] == [("limit", "O")]
    after = b.t > b.events[0].t
    assert np.max(np.abs(b.joint("O").position[after] + 0.6)) <= 1e-12
    a = cd.run_dae(mech, 1.0, rtol=1e-10, atol=1e-12)
    assert 0.0 <= b.events[0].t - a.events[0].t < 0.001 + 1e-12


def test_energy_audit_both_integrators():
    mech = cd.load(MODELS / "slider_crank_stop.toml")
    a = cd.run_dae(mech, 10.0, rtol=1e-10, atol=1e-12, output_dt=0.001)
    ea = a.energy()
    assert np.max(np.abs(ea.residual)) <= 1e-7
    assert ea.impact_losses[-1] == pytest.approx(sum(e.energy_lost for e in a.events))
    b = cd.run_iterative(mech, 10.0, dt=0.001)
    eb = b.energy()
    # the explicit scheme does not conserve energy: its residual is O(dt) and is shown
    assert 1e-7 < np.max(np.abs(eb.residual)) < 1e-3
    assert eb.driver_work[-1] == pytest.approx(ea.driver_work[-1], rel=1e-2)


def test_report_files(tmp_path):
    mech = cd.load(MODELS / "slider_crank_stop.toml")
    model = cd.Model(mech)
    a = cd.run_dae(mech, 10.0, model=model)
    b = cd.run_iterative(mech, 10.0, dt=0.01, model=model)
    cmp = cd.compare(a, b)
    md = cmp.write_report(tmp_path).read_text()
    for name in ("driving.png", "joints.png", "forces_E.png", "differences.png",
                 "timeline.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name
        assert f"]({name})" in md
    html = (tmp_path / "report.html").read_text()
    assert "<table>" in html and "driving.png" in html
    assert "limit E (upper)" in md and "release E (upper)" in md
    s = {x.name: x for x in cmp.series}
    assert s["driver A effort"].max_rel < 1e-2  # dt = 0.01 away from the switches


def cli(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "cmm_dae.cli", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


def test_cli_commands(tmp_path):
    r = cli("run", "models/pendulum_stop.toml", "--t-end", "1", "--save",
            str(tmp_path / "r.npz"))
    assert r.returncode == 0, r.stderr
    assert "limit" in r.stdout and "external collision (joint O)" in r.stdout
    r = cli("events", str(tmp_path / "r.npz"))
    assert r.returncode == 0 and "limit" in r.stdout
    # a saved run is over: an end time or rtol for it is refused, not ignored
    r = cli("events", str(tmp_path / "r.npz"), "--t-end", "5")
    assert r.returncode == 2 and "is a saved result (its run ended at t = 1 s)" in r.stderr
    assert "Traceback" not in r.stderr
    r = cli("iterate", "models/slider_crank.toml", "--t-end", "0.5", "--dt", "0.01")
    assert r.returncode == 0 and "(iterative)" in r.stdout
    r = cli("structure", "models/slider_crank_stop.toml")
    assert r.returncode == 0 and "augmented Assur group RRRP" in r.stdout
    r = cli("compare", "models/slider_crank_stop.toml", "--out", str(tmp_path / "rep"),
            "--no-work-precision")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "rep" / "report.html").is_file()
    r = cli("animate", "models/pendulum_stop.toml", "--t-end", "0.5", "--frames", "5",
            "--out", str(tmp_path / "a.gif"))
    assert r.returncode == 0 and (tmp_path / "a.gif").stat().st_size > 1000
    r = cli("plot", str(tmp_path / "r.npz"), "--out", str(tmp_path / "pl"))
    assert r.returncode == 0 and (tmp_path / "pl" / "forces_O.png").is_file()


def test_cli_errors(tmp_path):
    r = cli("run", "missing.toml")
    assert r.returncode == 2 and "cannot read the file" in r.stderr and "Traceback" not in r.stderr
    bad = tmp_path / "bad.toml"
    bad.write_text((MODELS / "slider_crank.toml").read_text().replace("mass = 0.1", "mass = -1"))
    r = cli("run", str(bad))
    assert r.returncode == 2 and "[bodies.crank] mass" in r.stderr
    r = cli("events", str(tmp_path / "nothing.npz"))
    assert r.returncode == 2 and "no such result file" in r.stderr
    r = cli("run", "models/slider_crank.toml", "--t-end", "-1")
    assert r.returncode == 2 and "t_end" in r.stderr
    r = cli("frobnicate")
    assert r.returncode == 2 and "invalid choice" in r.stderr
    r = cli("compare", "--help")
    assert r.returncode == 0 and "--no-work-precision" in r.stdout
