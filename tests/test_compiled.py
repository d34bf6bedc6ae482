"""The compiled IDA segment (``compiled=True``): the same Result as the Python path.

Both paths give IDA the same residual, Jacobian, event functions (the exact lock forces
from one QR graph, :mod:`cmm_dae.integrators.exact_events`), options, output times and
checks after each step, so they take the same steps: every shipped example gives the same
events, series and step counts bit for bit (the C functions are compiled without fused
multiply-adds, which round otherwise).
"""

from __future__ import annotations

import os
import re

import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae.core.errors import SolverError, Status
from cmm_dae.description import iftomm
from cmm_dae.equations import banded
from cmm_dae.integrators import cbuild, csegment

pytestmark = [pytest.mark.skipif(cbuild.c_compiler() is None, reason="needs a C compiler"),
              pytest.mark.usefixtures("module_cache")]
#: the module shares one build cache (conftest's module_cache), not one per test
SHARED_CACHE = True


def _same(a: cd.Result, b: cd.Result) -> None:
    """The two runs agree bit for bit: status, events, every series, IDA's step count."""
    assert a.status is b.status
    assert [(e.kind, e.joint, e.side, e.t) for e in a.events] == [
        (e.kind, e.joint, e.side, e.t) for e in b.events]
    assert a.t.shape == b.t.shape and np.array_equal(a.t, b.t)
    for name in ("q", "v", "a", "lam", "effort", "jforce", "jtorque"):
        if name in a.data:
            assert np.array_equal(a.data[name], b.data[name], equal_nan=True), name
    assert a.stats.steps == b.stats.steps > 0


#: every shipped example whose segments can run in C (friction from the reaction is solved
#: in Python), over a span that holds its events: (name, t_end s)
EXAMPLES = [("andrews_squeezer", 0.03), ("cam_valve_train", 0.3), ("crank_pendulum", 2.0),
            ("double_folded", 10.0), ("double_folded_preloaded", 4.0), ("four_bar", 2.0),
            ("iftomm_a01_pendulum", 2.0), ("iftomm_a02_four_bar_N1", 2.0),
            ("motor_crank_stop", 4.0), ("nipper_cutting", 1.0), ("nipper_swing", 1.0),
            ("pendulum_stop", 2.0), ("slider_crank", 2.0), ("slider_crank_stop", 4.0),
            ("slotted_link", 2.0), ("stick_slip_block", 3.0),
            # spatial: a lock in a spherical five-bar, ball and universal joints, a ball joint
            ("carton_fold", 1.0), ("rsur_four_bar", 1.0), ("spherical_pendulum", 2.0)]


@pytest.mark.parametrize("name,t_end", EXAMPLES)
def test_same_result_as_python_path(name, t_end):
    mech = cd.load(cd.example(name))
    model = cd.Model(mech)
    py = cd.run_dae(mech, t_end, model=model, compiled=False)
    c = cd.run_dae(mech, t_end, model=model, compiled=True)
    assert c.status is Status.SUCCESS
    assert c.meta["compiled"] and not py.meta["compiled"]  # it ran in C, not a fallback
    _same(py, c)


def test_same_stall_as_python_path():
    """A spent step budget ends both paths after the same step (the squeezer spinning
    up), the run so far kept alike."""
    mech = cd.load(cd.example("andrews_squeezer"))
    model = cd.Model(mech)
    got = []
    for compiled in (False, True):
        with pytest.raises(SolverError, match="stalled") as info:
            cd.run_dae(mech, 1.0, model=model, compiled=compiled, max_steps=3000)
        got.append(info.value.result)
    _same(*got)
    assert got[0].status is Status.STALLED
    # the squeezer is not stuck: it spins (about 736 rad/s, 0.0085 rad a step, at 0.0345 s)
    assert re.search(r"joint 'beta' moves at \d+(\.\d+)? rad/s \(0\.00\d+ rad a step\): "
                     r"a fast motion", str(info.value))


def test_internal_steps_and_table_driver():
    """output_dt=None (IDA's own steps) and a table driver's restart at the table's end."""
    base = cd.load(cd.example("slider_crank"))
    mech = cd.Mechanism(base.name, bodies=dict(base.bodies), joints=dict(base.joints),
                        ground=dict(base.ground), gravity=base.gravity,
                        drivers=[cd.Driver("A", motion="table", times=(0.0, 0.3, 0.7, 1.0),
                                           values=(0.5, 1.0, 0.8, 2.0))])
    model = cd.Model(mech)
    py = cd.run_dae(mech, 1.5, model=model, output_dt=None)
    c = cd.run_dae(mech, 1.5, model=model, output_dt=None, compiled=True)
    assert np.any(np.isclose(py.t, 1.0, rtol=0, atol=1e-12))  # the restart is a sample
    assert c.meta["compiled"]
    _same(py, c)


def test_step_budget_keeps_partial_result():
    mech = cd.load(cd.example("double_folded"))
    with pytest.raises(SolverError) as err:
        cd.run_dae(mech, 10.0, compiled=True, max_steps=300)
    assert err.value.status is Status.STALLED
    part = err.value.result
    # the budget counts every step; the compiled segment checks it after each output
    # interval (a few steps of 0.01 s here), and keeps the samples so far
    assert part is not None and 0.0 < part.t[-1] < 10.0 and 300 < part.stats.steps < 400
    assert part.status == "stalled" and np.all(np.diff(part.t) >= 0.0)
    # the slow cycle is not called a fast motion: its steps' average and the other causes
    h = part.t[-1] / part.stats.steps
    assert f"({h:.2g} s each on average: a run this long needs more" in str(err.value)
    assert "a fast motion" not in str(err.value)


_RUN = ("import cmm_dae as cd; r = cd.run_dae(cd.load(cd.example('pendulum_stop')), 0.5, "
        "compiled=True); print(repr(float(r.joint('O').position[-1])), r.meta['compiled'])")


def test_cut_or_foreign_cached_library_is_rebuilt(tmp_path):
    """A library cut to half its size in the cache (SIGBUS before: Python died, rc 135) or
    another library copied under its name is rebuilt with one warning line each, and the
    run gives the same numbers; $CC with arguments is a command, not a file name."""
    import os
    import shutil
    import subprocess
    import sys

    env = {**os.environ, "CMM_DAE_CACHE": str(tmp_path), "CC": f"{shutil.which('cc') or 'gcc'} -g0"}

    def run():
        return subprocess.run([sys.executable, "-W", "always", "-c", _RUN], env=env,
                              capture_output=True, text=True, timeout=500)

    first = run()
    assert first.returncode == 0, first.stderr
    assert first.stdout.split()[1] == "True" and "rebuilding" not in first.stderr
    libs = sorted(tmp_path.glob("cmm_*.so"))
    # the driver, the model's functions and its configurations' event functions
    driver, model = sorted(libs, key=lambda p: not p.name.startswith("cmm_seg_"))[:2]
    size = driver.stat().st_size
    with open(driver, "r+b") as f:
        f.truncate(size // 2)
    model.write_bytes(driver.read_bytes())  # another library under the model's name
    second = run()
    assert second.returncode == 0, second.stderr
    assert second.stdout == first.stdout
    assert second.stderr.count("incomplete, changed or not this model's") == 2
    assert driver.stat().st_size == size
    third = run()  # rebuilt and stamped: trusted now, quietly
    assert third.returncode == 0 and third.stdout == first.stdout
    assert "rebuilding" not in third.stderr


def test_cache_and_compiler_settings(monkeypatch, tmp_path):
    """An empty CMM_DAE_CACHE means the default folder, not the working directory."""
    from pathlib import Path

    from cmm_dae.equations import codegen as buffers

    monkeypatch.setenv("CMM_DAE_CACHE", "")
    assert buffers.cache_dir() == Path.home() / ".cache" / "cmm_dae"
    monkeypatch.setenv("CC", "  gcc -m64 -O1 ")
    assert buffers.c_compiler() == ["gcc", "-m64", "-O1"]
    lib = tmp_path / "cmm_x.so"
    lib.write_bytes(b"\x7fELF" + bytes(100))
    assert not buffers.verified(lib, "x")  # no stamp: never trusted


def test_another_scikit_sundae_falls_back_with_one_warning(monkeypatch):
    """The driver declares SUNDIALS' prototypes by hand: with another scikit-sundae than
    the one it was written for it is never built or loaded; compiled=True warns once and
    runs the Python path (the same numbers)."""
    import warnings

    monkeypatch.setattr(csegment, "_driver", None)
    monkeypatch.setattr(csegment, "_driver_error", None)
    monkeypatch.setattr(csegment, "sksundae_version", lambda: "9.0.0")
    with pytest.raises(OSError, match="scikit-sundae 9.0.0: the compiled segment was "
                       "written for 1.2.x"):
        csegment.check_version()
    mech = cd.load(cd.example("pendulum_stop"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = cd.run_dae(mech, 0.5, compiled=True)
    assert not res.meta["compiled"]
    assert sum("scikit-sundae 9.0.0" in str(w.message) for w in caught) == 1
    ref = cd.run_dae(mech, 0.5)
    assert np.array_equal(res.joint("O").position, ref.joint("O").position)
    # the default ("auto") in a new process: the same single warning, the Python path
    monkeypatch.setattr(csegment, "_driver_error", None)
    monkeypatch.setattr(cbuild, "_warned", False)
    cbuild.clear()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert not cd.run_dae(mech, 0.5).meta["compiled"]
        assert not cd.run_dae(mech, 0.5).meta["compiled"]
    assert sum("scikit-sundae 9.0.0" in str(w.message) for w in caught) == 1


def test_auto_runs_compiled_where_the_build_is_cached(monkeypatch, tmp_path):
    """compiled="auto" (the default): the Python path while the mechanism's build is not
    in the cache (no library written by that run), the compiled segment once it is; the
    same events, samples and crank torque bit for bit either way."""
    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    cbuild.clear()
    mech = cd.load(cd.example("double_folded"))
    first = cd.run_dae(mech, 10.0)
    assert first.meta["compiled"] is False
    assert not list(tmp_path.glob("cmm_[!s]*.so"))  # only the driver, if any
    assert cd.run_dae(mech, 10.0, compiled=True).meta["compiled"] is True
    cbuild.clear()  # a new process: found in the cache
    again = cd.run_dae(cd.load(cd.example("double_folded")), 10.0)
    assert again.meta["compiled"] is True
    _same(first, again)
    assert cd.run_dae(mech, 1.0, compiled=False).meta["compiled"] is False


def test_auto_builds_after_a_long_run_and_says_so_once(monkeypatch, tmp_path):
    """A run under "auto" that took longer than the threshold (here 0 s) builds the
    segment in the background and says so once per process (CompileNotice); the next
    run of the mechanism is compiled. A run shorter than the threshold builds nothing."""
    import warnings

    from cmm_dae.core.errors import CompileNotice

    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    cbuild.clear()
    mech = cd.load(cd.example("pendulum_stop"))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        cd.run_dae(mech, 0.5)  # 2 s and twice the estimate: far above this run
    assert not seen
    monkeypatch.setenv("CMM_DAE_AUTO_BUILD", "1")
    monkeypatch.setattr(cbuild, "AUTO_BUILD_NOW", -1.0)  # (the build-later rule alone)
    monkeypatch.setattr(cbuild, "AUTO_BUILD_AFTER", 0.0)
    monkeypatch.setattr(cbuild, "build_estimate", lambda model: 0.0)
    monkeypatch.setattr(cbuild, "_noticed", False)
    with pytest.warns(CompileNotice, match="in the background"):
        assert cd.run_dae(mech, 0.5).meta["compiled"] is False
    cbuild.clear()  # waits for the build
    assert cd.run_dae(mech, 0.5).meta["compiled"] is True
    other = cd.load(cd.example("slider_crank"))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        cd.run_dae(other, 0.2)
    assert not [w for w in seen if issubclass(w.category, CompileNotice)]
    cbuild.clear()
    assert cd.run_dae(other, 0.2).meta["compiled"] is True


def test_auto_builds_after_short_runs_that_add_up(monkeypatch, tmp_path):
    """A sweep of short runs of one model under "auto": their Python time adds up, and the
    build starts once the sum reaches the threshold (here 1 s: 0.6 s, then 1.2 s), not
    with the first run; later runs of the model are compiled."""
    import warnings

    from cmm_dae.core.errors import CompileNotice

    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    cbuild.clear()
    monkeypatch.setenv("CMM_DAE_AUTO_BUILD", "1")
    monkeypatch.setattr(cbuild, "AUTO_BUILD_NOW", -1.0)
    monkeypatch.setattr(cbuild, "AUTO_BUILD_AFTER", 1.0)
    monkeypatch.setattr(cbuild, "build_estimate", lambda model: 0.1)
    monkeypatch.setattr(cbuild, "_noticed", True)  # (said already: quiet here)
    mech = cd.load(cd.example("pendulum_stop"))
    model = cd.Model(mech)
    assert not cd.run_dae(mech, 0.2, model=model).meta["compiled"]
    monkeypatch.setitem(cbuild._spent, model, 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CompileNotice)
        cbuild.build_later(model, False, "auto", None, 0.6)
        assert cbuild._models[model].get(False, cbuild._MISSING) is cbuild._MISSING
        cbuild.build_later(model, False, "auto", None, 0.6)
        assert cbuild._models[model][False] is not cbuild._MISSING  # building or built
    cbuild.clear()  # waits for the build
    assert cd.run_dae(mech, 0.2, model=model).meta["compiled"] is True


def test_auto_builds_a_short_build_before_the_first_run(monkeypatch, tmp_path):
    """"auto" on a machine with a C compiler: a mechanism whose build is estimated short
    (the pendulum with a stop, 0.56 s against AUTO_BUILD_NOW) is built before its first
    run, which runs in C, quietly; one estimated longer runs in Python and builds
    nothing; CMM_DAE_AUTO_BUILD=0 uses only what is cached."""
    import warnings

    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    monkeypatch.setenv("CMM_DAE_AUTO_BUILD", "1")
    cbuild.clear()
    mech = cd.load(cd.example("pendulum_stop"))
    assert cbuild.build_estimate(cd.Model(mech)) < cbuild.AUTO_BUILD_NOW
    with monkeypatch.context() as mp:
        mp.setattr(cbuild, "AUTO_BUILD_NOW", 0.1)
        assert cd.run_dae(mech, 0.5).meta["compiled"] is False
    assert not list(tmp_path.glob("cmm_[!s]*.so"))
    monkeypatch.setenv("CMM_DAE_AUTO_BUILD", "0")
    cbuild.clear()
    assert cd.run_dae(mech, 0.5).meta["compiled"] is False
    monkeypatch.setenv("CMM_DAE_AUTO_BUILD", "1")
    cbuild.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # quiet
        first = cd.run_dae(mech, 0.5)
    assert first.meta["compiled"] is True and list(tmp_path.glob("cmm_[!s]*.so"))
    py = cd.run_dae(mech, 0.5, compiled=False)
    assert np.max(np.abs(first.joint("O").position - py.joint("O").position)) <= 1e-9


def test_auto_without_a_compiler_is_quiet(monkeypatch, tmp_path):
    """No compiler: "auto" runs the Python path with no warning and builds nothing;
    an unknown value of compiled is refused by name."""
    import warnings

    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    monkeypatch.setenv("CMM_DAE_AUTO_BUILD", "1")
    monkeypatch.setattr(cbuild, "c_compiler", lambda: None)
    monkeypatch.setattr(cbuild, "AUTO_BUILD_AFTER", 0.0)
    monkeypatch.setattr(cbuild, "build_estimate", lambda model: 0.0)
    cbuild.clear()
    mech = cd.load(cd.example("pendulum_stop"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cd.run_dae(mech, 0.5).meta["compiled"] is False
    assert not list(tmp_path.glob("cmm_[!s]*.so"))
    with pytest.raises(cd.ModelError, match="compiled: expected True, False or 'auto'"):
        cd.run_dae(mech, 0.5, compiled="yes")


def test_post_processing_in_c_gives_the_same_series():
    """With the compiled segment, post-processing's and the screen's mapped functions run
    in C too (equations.compiled): on the same (Python-path) run, every force, torque,
    effort, multiplier, acceleration and drift series of the double-folded cycle bit for
    bit CasADi's own evaluation of the same functions (the Schur complements solved by
    one LDL^T graph on both), and the same events."""
    from cmm_dae.equations import compiled

    mech = cd.load(cd.example("double_folded"))
    model = cd.Model(mech)
    a = cd.run_dae(mech, 10.0, model=model, compiled=False)
    assert not getattr(model, "outputs_compiled", False)
    assert compiled.use_compiled(model)
    assert all(any(f.is_a("External") for f in getattr(model, attr).find_functions())
               for attr in compiled.DENSE)
    b = cd.run_dae(mech, 10.0, model=model, compiled=False)
    _same(a, b)
    for key in ("drift_pos", "drift_vel"):
        assert np.array_equal(a.data[key], b.data[key]), key
    fast = cd.Model(mech)
    assert cd.run_dae(mech, 1.0, model=fast, compiled=True).meta["compiled"]
    assert fast.outputs_compiled


def test_a_large_model_compiles_its_segment_alone():
    """Post-processing's dense library is compiled only up to 40 constraint rows and
    OUTPUTS_BUDGET instructions (gcc took 13.5 s for A02 with 8 loops' 28,600 and 359 s
    with 32 loops); a banded mechanism compiles the functions of Phi_q's nonzeros alone:
    A02 with 8 loops (50 rows) runs its segment, post-processing and screen in C, the
    same series within 1e-12 as on CasADi's virtual machine, and the build estimate
    counts both libraries; the double-folded mechanism (12 rows) compiles the dense
    set, within budget."""
    from cmm_dae.description.iftomm import a02_four_bar
    from cmm_dae.equations import compiled

    model = cd.Model(a02_four_bar(8))
    a = cd.run_dae(model.mech, 1.0, rtol=1e-3, compiled=False, model=model)
    outs = compiled.instructions(model)
    assert 0 < outs <= compiled.OUTPUTS_BUDGET
    u = model.ida
    seg = 0.1 + 2.5e-4 * (u.res_sx.n_instructions() + u.jac_sparse_fn.n_instructions())
    post = 0.2 + 3e-4 * outs
    assert post > 0.3 and seg > 0.3
    assert cbuild.build_estimate(model) == pytest.approx(max(seg, post) if (
        os.cpu_count() or 1) > 1 else seg + post)
    assert compiled.use_compiled(model) and model.outputs_compiled
    assert all(any(f.is_a("External") for f in getattr(model, attr).find_functions())
               for attr in compiled.BANDED)
    b = cd.run_dae(model.mech, 1.0, rtol=1e-3, compiled=False, model=model)
    for key in ("jforce", "lam", "a", "drift_pos"):  # (no driver: no effort)
        x, y = a.data[key], b.data[key]
        assert x.size and np.max(np.abs(x - y)) <= 1e-12 * max(np.max(np.abs(x)), 1e-300), key
    assert len(a.events) == 1  # the first singular position, stepped over
    assert [(e.t, e.note) for e in a.events] == [(e.t, e.note) for e in b.events]
    small = cd.Model(cd.load(cd.example("double_folded")))
    assert 0 < compiled.instructions(small) <= compiled.OUTPUTS_BUDGET
    assert compiled.use_compiled(small) and small.outputs_compiled


def test_cli_says_which_path_ran(capsys, monkeypatch, tmp_path):
    """`cmm-dae run`: --compiled runs in C and says so, the default then finds the build,
    --no-compiled runs in Python; both flags at once are refused (exit 2)."""
    from cmm_dae.cli import main

    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    cbuild.clear()
    assert main(["run", "pendulum_stop", "--t-end", "0.2", "--compiled"]) == 0
    assert "(ida, in C)" in capsys.readouterr().out
    cbuild.clear()
    assert main(["run", "pendulum_stop", "--t-end", "0.2"]) == 0
    assert "(ida, in C)" in capsys.readouterr().out
    assert main(["run", "pendulum_stop", "--t-end", "0.2", "--no-compiled"]) == 0
    assert "(ida):" in capsys.readouterr().out
    with pytest.raises(SystemExit) as stop:
        main(["run", "pendulum_stop", "--compiled", "--no-compiled"])
    assert stop.value.code == 2


def test_ida_order_makes_a02s_jacobian_a_band():
    """IDA's unknowns reordered (reverse Cuthill-McKee): a permutation under which every
    structural nonzero of A02's Jacobian (8 loops, 130 unknowns) lies within the band's
    half widths, themselves narrow (measured 9 below, 8 above)."""
    model = cd.Model(iftomm.a02_four_bar(8))
    colind, row = model.ida.jac_pattern.get_ccs()
    colptr, rowind = np.asarray(colind), np.asarray(row)
    n = model.ida.N
    perm, ml, mu = banded.ida_order(colptr, rowind, n)
    assert perm.flags.c_contiguous and np.array_equal(np.sort(perm), np.arange(n))
    inv = np.empty(n, dtype=int)
    inv[perm] = np.arange(n)
    d = inv[rowind] - inv[np.repeat(np.arange(n), np.diff(colptr))]
    assert d.max() == ml and -d.min() == mu and ml + mu <= 20


def test_band_lu_segment_against_the_closed_form():
    """A02 with 8 loops in C: linsolver "auto" factors the reordered Jacobian by band LU,
    "sparse" by SuperLU_MT. Before the first singular position (0.6 s, rtol 1e-10) both
    follow the closed-form crank (measured 1.2e-9 and 1.0e-9 m) and each other (3.2e-10 m,
    multipliers 1.7e-9 of the largest)."""
    mech = iftomm.a02_four_bar(8)
    model = cd.Model(mech)
    runs = {ls: cd.run_dae(mech, 0.6, rtol=1e-10, model=model, linsolver=ls, compiled=True)
            for ls in ("auto", "sparse")}
    for ls, solver in (("auto", "band"), ("sparse", "sparse")):
        res = runs[ls]
        assert res.success and res.meta["compiled"] and res.meta["linsolver"] == solver
        err = np.hypot(*(iftomm.crank_tip(res) - iftomm.a02_reference(8, res.t)).T)
        assert np.max(err) <= 5e-9
    band, sparse = runs["auto"], runs["sparse"]
    assert np.array_equal(band.t, sparse.t)
    assert np.max(np.abs(band.data["q"] - sparse.data["q"])) <= 3e-9
    lam = np.max(np.abs(sparse.data["lam"]))
    assert np.max(np.abs(band.data["lam"] - sparse.data["lam"])) <= 2e-8 * lam
