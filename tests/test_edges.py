"""Edges: every bad file, option, saved result and CLI argument ends in a cmm_dae error that
names what is wrong; every failure inside a run keeps the partial Result; reports work for
every valid mechanism; sweeps never damage a user's file."""

from __future__ import annotations

import csv
import io
import json
import math
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import cmm_dae as cd

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"


def cli(*args, cwd=ROOT, **kw):
    return subprocess.run([sys.executable, "-m", "cmm_dae.cli", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=300, **kw)


def one_line_error(r) -> str:
    """The CLI said one thing on stderr, no traceback."""
    assert "Traceback" not in r.stderr, r.stderr
    return r.stderr


# ------------------------------------------------------------------ model files
def test_binary_file(tmp_path):
    p = tmp_path / "m.toml"
    p.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(cd.ModelError, match=r"(?s)m\.toml.*binary file") as info:
        cd.load(p)
    assert info.value.source == str(p)


def test_file_not_utf8(tmp_path):
    p = tmp_path / "m.toml"
    p.write_bytes('[mechanism]\nname = "K\xf6ln"\n'.encode("latin-1"))
    with pytest.raises(cd.ModelError, match=r"not UTF-8 text \(byte 21"):
        cd.load(p)


def test_absurd_nesting_in_a_file_and_from_python(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text("a = " + "[" * 20000 + "]" * 20000 + "\n")
    with pytest.raises(cd.ModelError, match="nested too deeply"):
        cd.load(p)
    deep: list = []
    for _ in range(100000):
        deep = [deep]
    with pytest.raises(cd.ModelError, match=r"\[mechanism\] gravity: expected a list of 2 "
                       r"numbers, got \[+\.\.\.\]+\n"):
        cd.from_dict({"mechanism": {"gravity": deep}})


def test_directory_and_huge_file(tmp_path, monkeypatch):
    with pytest.raises(cd.ModelError, match="cannot read the file"):
        cd.load(tmp_path)
    import cmm_dae.description.loader as loader

    monkeypatch.setattr(loader, "MAX_FILE_BYTES", 100)
    p = tmp_path / "big.toml"
    p.write_text("# " + "x" * 200 + "\n")
    with pytest.raises(cd.ModelError, match=r"the file has 203 bytes; a model file is text of "
                       r"at most 100 bytes"):
        cd.load(p)


# ------------------------------------------------------------------ run options
@pytest.fixture(scope="module")
def four_bar():
    return cd.load(MODELS / "four_bar.toml")


def test_output_grid_that_would_not_fit_in_memory(four_bar):
    with pytest.raises(cd.ModelError, match=r"run options: 1 problem:\n  - \[run\] output_dt: "
                       r"1e\+13 output samples would take [0-9.e+]+ GiB, more than the 4 GiB"):
        cd.run_dae(four_bar, 10.0, output_dt=1e-12)


def test_step_count_that_would_not_end(four_bar):
    with pytest.raises(cd.ModelError, match=r"\[run\] dt: 1e-09 s would take 1e\+10 fixed "
                       r"steps to t_end = 10\.0 s, more than max_steps = 500000"):
        cd.run_iterative(four_bar, 10.0, dt=1e-9)



def test_a_model_path_instead_of_a_mechanism_is_named():
    """A path handed to a run used to end in "'PosixPath' object has no attribute
    'bodies'"; now a TypeError says what to do."""
    path = cd.example("four_bar")
    for call, name in ((lambda: cd.run_dae(path, 1.0), "run_dae"),
                       (lambda: cd.run_iterative(str(path), 1.0), "run_iterative"),
                       (lambda: cd.simulate(path, 1.0), "simulate"),
                       (lambda: cd.sensitivities(path, ["gravity.y"], 1.0), "sensitivities"),
                       (lambda: cd.with_params(path, {"gravity.y": -9.0}), "with_params")):
        with pytest.raises(TypeError, match=rf"^{name} expects a cmm_dae\.Mechanism \(a model "
                           r"file: cmm_dae\.load\(path\) reads it into one\), got "):
            call()
    with pytest.raises(TypeError, match=r"^run_dae expects a cmm_dae\.Mechanism, got int 3$"):
        cd.run_dae(3)
    with pytest.raises(TypeError, match=r"^compare expects two cmm_dae\.Result objects .*got "
                       r"Mechanism for b$"):
        cd.compare(cd.run_dae(cd.load(path), 0.1), cd.load(path))

def test_all_bad_options_at_once(four_bar):
    with pytest.raises(cd.ModelError) as info:
        cd.simulate(four_bar, 1.0, method="rk4", v_lock=-1.0, max_steps=2.5, output_every=0)
    assert {p.key for p in info.value.problems} == {"method", "v_lock", "max_steps",
                                                    "output_every"}


def test_tiny_end_times_and_a_bad_rtol(four_bar):
    """IDA failed at t = 0 ("corrector convergence failed", h = 1.9e-24 s) for t_end below
    about 1e-13 s; such an end time is now refused by name, while the fixed-step
    algorithm, which takes any step, still runs it. A bad rtol no longer drags in an
    atol the user never gave."""
    ok = cd.run_dae(four_bar, 1e-9)
    assert ok.status == "success" and ok.t[-1] == 1e-9
    for t_end in (1e-15, 1e-200):
        with pytest.raises(cd.ModelError, match=r"\[run\] t_end: expected at least 1e-09 s "
                           r"with IDA .*got 1e-"):
            cd.run_dae(four_bar, t_end)
    assert cd.run_iterative(four_bar, 1e-15, dt=1e-15).t[-1] == 1e-15
    with pytest.raises(cd.ModelError) as info:
        cd.run_dae(four_bar, 1.0, rtol=float("nan"))
    assert [p.key for p in info.value.problems] == ["rtol"]

@pytest.mark.parametrize("mass_scale, g", [(1e9, 9.81), (1e-9, 9.81), (1.0, 9.81e6),
                                           (1.0, 9.81e-6), (1e9, 9.81e6)])
def test_huge_and_tiny_masses_and_gravity(mass_scale, g):
    """The pendulum on a stop with its mass and inertia scaled by 1e9 stalled (steps of
    4e-8 s) and under 1e6 m/s^2 IDA gave up at 5.2e-4 s: the multipliers' absolute
    tolerance (1e-2 N) was fixed while the forces grew, so their relative tolerance became
    the run's rtol, too tight for index-2 variables. Against closed forms: the fall time
    by quadrature of the energy equation, and the statics at rest on the stop, rtol 1e-8
    (the weight's moment) and 1e-12 of the weight (the pin force); the fall time's
    derivative in the stop's angle, rtol 1e-8."""
    from scipy.integrate import quad

    m0, j0, d, th0, stop = 0.4, 3e-3, 0.15, 0.3, -0.6  # the file's rod, start and stop
    mech = cd.with_params(cd.load(MODELS / "pendulum_stop.toml"), {
        "bodies.rod.mass": m0 * mass_scale, "bodies.rod.inertia": j0 * mass_scale,
        "gravity.y": -g})
    io = j0 + m0 * d * d  # about the pivot (per unit mass scale)

    def dt_du(u):  # theta = th0 - u^2 takes the square root out of the endpoint
        return 2.0 * u / math.sqrt(2.0 * m0 * g * d * (math.sin(th0) - math.sin(th0 - u * u))
                                   / io)

    t_fall = quad(dt_du, 0.0, math.sqrt(th0 - stop), epsabs=0.0, epsrel=1e-13, limit=200)[0]
    res = cd.run_dae(mech, 1.5 * t_fall, rtol=1e-10, output_dt=t_fall / 100)
    assert [e.kind for e in res.events] == ["limit"]
    assert res.events[0].t == pytest.approx(t_fall, rel=1e-8)
    weight = m0 * mass_scale * g
    pin = res.joint("O")
    assert pin.torque[-1] == pytest.approx(weight * d * math.cos(stop), rel=1e-8)
    assert np.allclose(pin.force[-1], [0.0, weight], rtol=0.0, atol=1e-12 * weight)
    # the sensitivity pass replays the run with the same tolerances: d t_fall / d stop is
    # minus one over the rate at the stop
    sens = cd.sensitivities(mech, ["joints.O.limits.lower"], 1.5 * t_fall, rtol=1e-11,
                            output_dt=t_fall / 100)
    rate = math.sqrt(2.0 * m0 * g * d * (math.sin(th0) - math.sin(stop)) / io)
    assert sens.event_times[0][0] == pytest.approx(-1.0 / rate, rel=1e-8)


# ------------------------------------------------------------------ saved results
@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    path = tmp_path_factory.mktemp("res") / "r.npz"
    cd.run_dae(cd.load(MODELS / "pendulum_stop.toml"), 1.0).save(path)
    return path


def test_truncated_result(saved, tmp_path):
    p = tmp_path / "t.npz"
    p.write_bytes(saved.read_bytes()[:3000])
    with pytest.raises(cd.CmmError, match=r"t\.npz' is truncated or not a result file"):
        cd.load_result(p)


def test_not_a_result_file(tmp_path):
    p = tmp_path / "x.npz"
    p.write_text("hello")
    with pytest.raises(cd.CmmError, match=r"x\.npz' is not a result file"):
        cd.load_result(p)
    q = tmp_path / "plain.npz"
    np.savez(q, a=np.zeros(3))
    with pytest.raises(cd.CmmError, match=r"plain\.npz' is not a cmm_dae result file"):
        cd.load_result(q)


def _rewrite(saved: Path, out: Path, meta_edit=None, drop=None) -> Path:
    with np.load(saved) as z:
        arrays = {k: z[k] for k in z.files if k != drop}
    meta = json.loads(str(arrays["__meta__"]))
    if meta_edit:
        meta_edit(meta)
    arrays["__meta__"] = np.array(json.dumps(meta))
    np.savez(out, **arrays)
    return out


def test_corrupted_results(saved, tmp_path):
    bad_json = tmp_path / "j.npz"
    with zipfile.ZipFile(bad_json, "w") as zf:
        buf = io.BytesIO()
        np.save(buf, np.array("{not json"))
        zf.writestr("__meta__.npy", buf.getvalue())
    with pytest.raises(cd.CmmError, match=r"j\.npz' is a corrupted result file \(JSONDecode"):
        cd.load_result(bad_json)
    p = _rewrite(saved, tmp_path / "k.npz", meta_edit=lambda m: m.pop("stats"))
    with pytest.raises(cd.CmmError, match=r"k\.npz' is a corrupted result file \(KeyError"):
        cd.load_result(p)
    p = _rewrite(saved, tmp_path / "q.npz", drop="q")
    with pytest.raises(cd.CmmError, match=r"q\.npz' is a corrupted result file \(KeyError"):
        cd.load_result(p)
    with np.load(saved) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["t"] = arrays["t"][:-5]
    np.savez(tmp_path / "n.npz", **arrays)
    with pytest.raises(cd.CmmError, match=r"array 'q' has \d+ rows for \d+ times"):
        cd.load_result(tmp_path / "n.npz")


def test_status_and_message_survive_save_and_load(tmp_path):
    mech = cd.load(MODELS / "slider_crank.toml")
    text = (MODELS / "slider_crank.toml").read_text().replace(
        'axis = [1.0, 0.0]', 'axis = [1.0, 0.0]\nlimits = { upper = 0.245 }')
    (tmp_path / "l.toml").write_text(text)
    res = cd.run_dae(cd.load(tmp_path / "l.toml"), 2.0, throw=False)
    assert res.status == cd.Status.LOCK_UP and res.status == "lock-up" and not res.success
    assert res.message.startswith("lock-up at t = 0.856")
    assert "stop a driver" in res.explanation
    back = cd.load_result(res.save(tmp_path / "l.npz"))
    assert back.status is cd.Status.LOCK_UP and back.message == res.message
    assert cd.run_dae(mech, 0.1).status is cd.Status.SUCCESS


# ------------------------------------------------------------------ CLI
def test_cli_edges(tmp_path, saved):
    (tmp_path / "x.csv").write_text("a,b\n")
    r = cli("events", str(tmp_path / "x.csv"))
    assert r.returncode == 2
    assert "expected a model file (.toml) or a saved result (.npz), not a '.csv' file" in \
        one_line_error(r)
    r = cli("iterate", "models/four_bar.toml", "--dt", "1e-9")
    assert r.returncode == 2 and "[run] dt: 1e-09 s would take" in one_line_error(r)
    (tmp_path / "t.npz").write_bytes(saved.read_bytes()[:2000])
    r = cli("animate", str(tmp_path / "t.npz"), "--out", str(tmp_path / "a.gif"))
    assert r.returncode == 2 and "truncated" in one_line_error(r)
    r = cli("run", str(tmp_path))
    assert r.returncode == 2 and "cannot read the file" in one_line_error(r)
    r = cli("sweep", "models/double_folded.toml", "--param",
            "joints.D.spring.stiffness=1:2:100000000", "--out", str(tmp_path / "s.csv"))
    assert r.returncode == 2 and "expected 1 to 1000000 values" in one_line_error(r)


def test_cli_branch_option():
    """``cmm-dae run --branch JOINT:SIGN``: a rule the motion keeps is logged with the
    crossing; a malformed rule or an unknown joint is refused by name."""
    r = cli("run", "iftomm_a02_four_bar_N1", "--t-end", "1.0", "--branch", "G1:-1")
    assert r.returncode == 0 and "continue (G1 -)" in r.stdout
    for bad, said in (("G1:2", "expected 'continue' or JOINT:SIGN"),
                      ("G1", "expected 'continue' or JOINT:SIGN"),
                      ("X:+1", "[run] branch: expected")):
        r = cli("run", "iftomm_a02_four_bar_N1", "--t-end", "1.0", "--branch", bad)
        assert r.returncode == 2 and said in one_line_error(r), (bad, r.stderr)


def test_cli_quiet_on_a_closed_pipe():
    r = subprocess.run(f"{sys.executable} -m cmm_dae.cli structure models/nipper_swing.toml "
                       "| head -n 1", shell=True, capture_output=True, text=True, cwd=ROOT,
                       timeout=120)
    assert r.stdout.startswith("Structure of") and r.stderr == ""


def test_compare_names_the_failed_run_and_keeps_the_report(tmp_path):
    text = (MODELS / "slider_crank.toml").read_text().replace(
        'axis = [1.0, 0.0]', 'axis = [1.0, 0.0]\nlimits = { upper = 0.245 }')
    (tmp_path / "l.toml").write_text(text)
    r = cli("compare", str(tmp_path / "l.toml"), "--out", str(tmp_path / "rep"), "--t-end",
            "2")
    assert r.returncode == 3
    err = one_line_error(r)
    assert "note: the IDA run failed at t = 0.856" in err
    assert "note: the iterative run failed at t = 0.86" in err
    assert "work-precision study left out: the work-precision reference run (IDA at rtol " \
           "1e-12) failed: lock-up" in err
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "## Notes" in md and "the IDA run failed" in md
    assert (tmp_path / "rep" / "driving.png").stat().st_size > 1000


@pytest.mark.parametrize("name, figures", [
    ("pendulum_stop", {"joints.png", "forces_O.png", "timeline.png", "differences.png"}),
    ("four_bar", {"driving.png", "forces_A.png", "forces_D.png", "timeline.png"}),
    ("crank_pendulum", {"driving.png", "forces_B.png", "joints.png"}),
])
def test_reports_for_every_kind_of_mechanism(tmp_path, name, figures):
    """No driver; no metamorphic joint; only a sprung joint."""
    mech = cd.load(MODELS / f"{name}.toml")
    cmp = cd.compare(cd.run_dae(mech, 0.5), cd.run_iterative(mech, 0.5, dt=0.005))
    md = cmp.write_report(tmp_path).read_text()
    assert figures <= {p.name for p in tmp_path.glob("*.png")}
    assert ("driving.png" in md) == bool(mech.drivers)


# ------------------------------------------------------------------ sweeps
def test_sweep_refuses_a_foreign_file_and_leaves_it_untouched(tmp_path):
    mech = cd.load(MODELS / "double_folded.toml")
    for content in (b"name,value\nmine,1\n", b"\x89PNG\r\n\x1a\n\x00\x00",
                    b"case,other.param,status\n0,1,success\n"):
        p = tmp_path / "mine.csv"
        p.write_bytes(content)
        with pytest.raises(cd.CmmError, match=r"mine\.csv' is not a .*untouched"):
            cd.sweep(mech, {"joints.D.spring.stiffness": [1.0]}, t_end=0.1, checkpoint=p,
                     workers=1)
        assert p.read_bytes() == content


def test_torn_checkpoint_is_repaired_not_glued(tmp_path):
    mech = cd.load(MODELS / "double_folded.toml")
    grid = {"joints.D.spring.stiffness": [0.6, 1.0, 2.0]}
    ck = tmp_path / "ck.csv"
    full = cd.sweep(mech, grid, t_end=3.0, checkpoint=ck, workers=1)
    text = ck.read_text()
    lines = text.splitlines(keepends=True)
    ck.write_text("".join(lines[:-1]) + lines[-1][: len(lines[-1]) // 2])  # torn mid-line
    again = cd.sweep(mech, grid, t_end=3.0, checkpoint=ck, workers=1)
    rows = list(csv.DictReader(ck.open()))
    assert len(rows) == 3 and all(r["status"] == "success" for r in rows)
    assert sorted(float(r["joints.D.spring.stiffness"]) for r in rows) == [0.6, 1.0, 2.0]
    t_full = [r["t_limit_E_1"] for r in full.rows]
    assert [r["t_limit_E_1"] for r in again.rows] == pytest.approx(t_full, rel=1e-12)


@pytest.mark.parametrize("path, why", [
    ("drivers.A.amplitude", "driver 'A' moves by 'constant_speed', which reads initial, speed"),
    ("joints.A.restitution", "joint 'A' has no limits"),
    ("joints.A.angle", "joint 'A' is revolute"),
    ("joints.A.spring.rest", "joint 'A' has no spring"),
])
def test_with_params_refuses_paths_without_effect(path, why):
    mech = cd.load(MODELS / "double_folded.toml")
    with pytest.raises(cd.ModelError, match=rf"\[parameters\] {path}: has no effect: {why}"):
        cd.with_params(mech, {path: 0.5})


def test_with_params_refuses_names_and_non_numbers():
    mech = cd.load(MODELS / "double_folded.toml")
    with pytest.raises(cd.ModelError) as info:
        cd.with_params(mech, {"bodies.crank.name": 1.0, "bodies.crank.mass": "heavy",
                              "bodies.crank.centroid": 0.1, "initial.joints.Q": 0.0})
    keys = {p.key: p.message for p in info.value.problems}
    assert set(keys) == {"bodies.crank.name", "bodies.crank.mass", "bodies.crank.centroid",
                         "initial.joints.Q"}
    assert keys["bodies.crank.mass"] == "expected a number, got 'heavy'"


# ------------------------------------------------------------------ failures inside runs
@pytest.mark.parametrize("method", ["ida", "iterative"])
@pytest.mark.parametrize("exc", [np.linalg.LinAlgError("singular KKT matrix"),
                                 ZeroDivisionError("float division by zero"),
                                 MemoryError()])
def test_any_exception_in_a_run_keeps_the_partial_result(monkeypatch, method, exc):
    mech = cd.load(MODELS / "slider_crank_stop.toml")
    orig = cd.Model.kkt_from

    def failing(self, Phi_q, Qf, gamma, p):
        if failing.armed:
            raise exc
        return orig(self, Phi_q, Qf, gamma, p)

    failing.armed = False
    monkeypatch.setattr(cd.Model, "kkt_from", failing)
    import cmm_dae.simulation.runner as sim

    orig_advance = sim.METHODS[method].advance

    def advance(self, t0, q, v, rec):  # fails from the first restart on (after the lock)
        failing.armed = t0 > 0.0 or failing.armed
        return orig_advance(self, t0, q, v, rec)

    monkeypatch.setattr(sim.METHODS[method], "advance", advance)
    with pytest.raises(cd.SolverError, match=type(exc).__name__) as info:
        cd.simulate(mech, 10.0, method=method)
    err = info.value
    assert err.status is cd.Status.NUMERICAL and err.result.status is cd.Status.NUMERICAL
    part = err.result
    assert [e.kind for e in part.events] == ["limit"] and 2.7 < part.events[0].t < 2.9
    # the failure came in the first step after the lock: everything up to it is kept
    assert 0.0 <= part.t[-1] - part.events[0].t <= 0.0101
    assert np.all(np.isfinite(part.driver("A").effort))


def test_iterative_ctrl_c_keeps_the_partial_result(monkeypatch):
    import cmm_dae.integrators.iterative as it

    mech = cd.load(MODELS / "double_folded.toml")
    orig = it._CompiledStep.__call__

    def step(self, q, v, a, t, tn, p):  # Ctrl-C in the middle of the step to t = 4.01 s
        if tn > 4.0:
            raise KeyboardInterrupt
        return orig(self, q, v, a, t, tn, p)

    monkeypatch.setattr(it._CompiledStep, "__call__", step)
    with pytest.raises(cd.SolverError, match="interrupted") as info:
        cd.run_iterative(mech, 10.0)
    part = info.value.result
    assert info.value.status is cd.Status.INTERRUPTED
    assert 3.99 <= part.t[-1] <= 4.0 + 1e-9 and [e.kind for e in part.events] == ["limit"]


def test_runs_use_one_blas_thread(monkeypatch):
    from threadpoolctl import threadpool_info

    seen = []
    orig = cd.Model.kkt

    def kkt(self, *a):
        if not seen:
            seen.append([i["num_threads"] for i in threadpool_info()
                         if i["user_api"] == "blas"])
        return orig(self, *a)

    monkeypatch.setattr(cd.Model, "kkt", kkt)
    from cmm_dae.simulation import cache
    cache.clear()  # (built anew: a kept model of the same file has its start solved)
    cd.run_dae(cd.load(MODELS / "four_bar.toml"), 0.1)
    assert seen and seen[0] and set(seen[0]) == {1}


def test_an_examples_file_name_where_no_such_file_is_names_the_example(tmp_path):
    """The README lists the examples as files: `run double_folded.toml` outside the
    repository says to give the name alone (it had read "cannot read the file")."""
    r = cli("run", "double_folded.toml", "--t-end", "0.1", cwd=tmp_path)
    assert r.returncode == 2
    assert "the shipped example is run by its name alone: 'double_folded'" in \
        one_line_error(r)
    r = cli("run", "double_foldd.toml", cwd=tmp_path)  # no example: the loader's message
    assert r.returncode == 2 and "cannot read the file" in one_line_error(r)


def test_a_run_summary_lists_at_most_forty_events():
    """A run of the valve train logs hundreds of events a second: the summary lists the
    first 20 and the last 20 and says how many more there are; `events` and
    Result.event_table() list them all."""
    res = cd.run_dae(cd.load(cd.example("cam_valve_train")), 0.3, compiled=False)
    n = len(res.events)
    assert n > 40
    full, short = res.event_table(), res.event_table(limit=40)
    rows = [ln for ln in full.splitlines() if ln[:12].strip().replace(".", "").isdigit()]
    kept = [ln for ln in short.splitlines() if ln[:12].strip().replace(".", "").isdigit()]
    assert len(rows) == n and kept == rows[:20] + rows[-20:]
    assert f"... {n - 40} events more" in short
    assert res.event_table(limit=n) == full
    for limit in (0, 1):  # (no last half: the count still said)
        assert f"... {n - limit} events more" in res.event_table(limit=limit)
