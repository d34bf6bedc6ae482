"""The fixed-step algorithm in C (integrators/cstep.py, fixedstep.c): the same run as the
step on CasADi's virtual machine to round-off (its Newton iteration unrolled, symbolic QR
instead of LU), the C loop the same as stepping one call at a time to the last bit, and
parameter variants on their structure's build."""

from __future__ import annotations

import os

import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae.integrators import cbuild, cstep

pytestmark = [pytest.mark.skipif(cbuild.c_compiler() is None, reason="needs a C compiler"),
              pytest.mark.timeout(240), pytest.mark.usefixtures("module_cache")]
#: the module shares one build cache (conftest's module_cache)
SHARED_CACHE = True


def _same_run(a: cd.Result, b: cd.Result, q_tol: float) -> None:
    assert [(e.kind, e.joint, e.side) for e in a.events] == [
        (e.kind, e.joint, e.side) for e in b.events]
    assert max((abs(x.t - y.t) for x, y in zip(a.events, b.events, strict=True)),
               default=0.0) <= 1e-12
    assert np.array_equal(a.t, b.t)
    assert np.max(np.abs(a.data["q"] - b.data["q"])) <= q_tol
    for d in a.meta["drivers"]:
        assert np.max(np.abs(a.driver(d).effort - b.driver(d).effort)) <= 1e-10


@pytest.mark.parametrize(("name", "t_end"), [("double_folded", 10.0), ("pendulum_stop", 3.0),
                                             ("slotted_link", 3.0),
                                             ("stick_slip_block", 4.0)])
def test_compiled_fixed_step_is_the_virtual_machines(name, t_end):
    mech = cd.load(cd.example(name))
    model = cd.Model(mech)
    c = cd.run_iterative(mech, t_end, dt=1e-3, model=model, compiled=True)
    vm = cd.run_iterative(mech, t_end, dt=1e-3, model=model, compiled=False)
    assert c.meta["compiled"] and not vm.meta["compiled"]
    # positions where the step converged: within 1e-12 of each other (LU and QR)
    _same_run(c, vm, 1e-12)


def test_the_c_loop_is_stepping_one_call_at_a_time(monkeypatch):
    mech = cd.load(cd.example("double_folded"))
    model = cd.Model(mech)
    loop = cd.run_iterative(mech, 10.0, dt=1e-3, model=model, compiled=True)
    calls = []

    def none_in_c(self, q, v, a, t, n, p, *args):  # every step through iterative.py
        calls.append(n)
        return 1, q, v, a, t, n, (np.zeros(0), np.zeros((0, q.size)), np.zeros((0, q.size)))

    monkeypatch.setattr(cstep.CStep, "run", none_in_c)
    one = cd.run_iterative(mech, 10.0, dt=1e-3, model=model, compiled=True)
    assert len(calls) >= 10_000  # it did step one call at a time
    _same_run(loop, one, 0.0)
    assert np.array_equal(loop.driver("A").effort, one.driver("A").effort)


def test_variants_run_on_the_structures_build(tmp_path, monkeypatch):
    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    mech = cd.load(cd.example("slider_crank_stop"))
    base = cd.run_iterative(mech, 2.0, dt=1e-3, compiled=True)
    built = sorted(os.listdir(tmp_path))
    var = cd.with_params(mech, {"bodies.slider.mass": 0.37})
    c = cd.run_iterative(var, 2.0, dt=1e-3, compiled=True)
    vm = cd.run_iterative(var, 2.0, dt=1e-3, compiled=False)
    assert sorted(os.listdir(tmp_path)) == built  # nothing built again
    _same_run(c, vm, 1e-12)
    assert not np.allclose(c.driver("A").effort, base.driver("A").effort)  # its own numbers


def test_python_load_laws_keep_the_python_step(monkeypatch):
    mech = cd.load(cd.example("pendulum_stop"))
    law = cd.Law(func=lambda t, c, r: -0.05 * r)  # a damper written in Python
    var = mech.replace(loads={"hand": cd.Load("hand", law, joint="O")})
    monkeypatch.setattr(cbuild, "_warned", False)
    with pytest.warns(UserWarning, match="compiled fixed step not used .*Python callables"):
        c = cd.run_iterative(var, 1.0, dt=1e-3, compiled=True)
    vm = cd.run_iterative(var, 1.0, dt=1e-3, compiled=False)
    assert not c.meta["compiled"] and np.array_equal(c.data["q"], vm.data["q"])  # Python
    plain = cd.run_iterative(mech, 1.0, dt=1e-3, compiled=False)
    assert not np.allclose(c.data["q"], plain.data["q"])  # and the law acts


def test_cli_iterate_says_which_step_ran(capsys):
    from cmm_dae.cli import main

    assert main(["iterate", "pendulum_stop", "--t-end", "0.2", "--dt", "0.001",
                 "--compiled"]) == 0
    assert "(iterative, in C)" in capsys.readouterr().out
    assert main(["iterate", "pendulum_stop", "--t-end", "0.2", "--no-compiled"]) == 0
    assert "(iterative)" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["iterate", "pendulum_stop", "--compiled", "--no-compiled"])


def test_a_jaw_locked_on_a_zone_edge_does_not_flicker():
    """nipper_cutting: joint C locks on its stop at the cut zone's upper edge; each fixed
    step's Newton left it +-2e-16 off the edge, which the zone read as entering and
    leaving (140 zone events in 5 s on the virtual machine, another 142 in C). It now logs
    IDA's sequence of events."""
    mech = cd.load(cd.example("nipper_cutting"))
    ida = cd.run_dae(mech, 6.0)
    it = cd.run_iterative(mech, 6.0, dt=1e-3, compiled=False)  # (C: the same, tests above)
    assert [(e.kind, e.joint) for e in it.events] == [(e.kind, e.joint) for e in ida.events]
    assert max(abs(a.t - b.t) for a, b in zip(it.events, ida.events, strict=True)) < 2e-3
