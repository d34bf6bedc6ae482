"""Edges a tester found (non-finite input that bypassed the loader, SUNDIALS' messages on
stdout, IDA steps that no longer move t): each asserts the error with its table and key,
or the quiet output, or the number."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae import iftomm


@pytest.mark.parametrize("path,value,key", [
    ("joints.O.limits.lower", math.nan, "limits.lower"),   # was silently dropped
    ("joints.O.limits.lower", -math.inf, "limits.lower"),
    ("bodies.rod.points.O.x", math.nan, "points.O[0]"),
    ("ground.points.O.y", math.inf, "O[1]"),
])
def test_with_params_refuses_non_finite_values(path, value, key):
    mech = cd.load(cd.example("pendulum_stop"))
    table = "ground" if path.startswith("ground") else ".".join(path.split(".")[:2])
    with pytest.raises(cd.ModelError) as info:
        cd.with_params(mech, {path: value})
    probs = info.value.problems
    assert [(p.table, p.key) for p in probs] == [(table, key)]
    assert f"expected a finite number, got {value}" in probs[0].message


def test_python_builder_refuses_a_nan_stop_and_speed():
    mech = cd.load(cd.example("double_folded"))
    joints = dict(mech.joints)
    joints["E"] = joints["E"].__class__(**{**joints["E"].__dict__,
                                          "limits": cd.Limits(None, math.nan)})
    drivers = {k: d.__class__(**{**d.__dict__, "speed": math.inf})
               for k, d in mech.drivers.items()}
    with pytest.raises(cd.ModelError) as info:
        mech.replace(joints=joints, drivers=drivers)
    got = {(p.table, p.key) for p in info.value.problems}
    assert got == {("joints.E", "limits.upper"), ("drivers.A", "speed")}


def test_sweep_cli_refuses_nan_parameter(tmp_path, capsys):
    from cmm_dae.cli import main

    rc = main(["sweep", "pendulum_stop", "--param", "joints.O.limits.lower=nan:nan:1",
               "--out", str(tmp_path / "sw")])
    err = capsys.readouterr().err
    assert rc == 2
    assert "[joints.O] limits.lower: expected a finite number, got nan" in err
    assert not (tmp_path / "sw").exists()


def test_a02_steps_in_place_hand_over_to_the_crossing(caplog):
    """A02 (one loop) at rtol 1e-10 with IDA's own steps: IDA halved its step next to the
    first singular position until it no longer moved t and took about a million steps in
    place (over an hour on one machine; the step floor relative to t0 was zero in the
    first segment). Now 50 steps in place end the segment and the crossing carries the
    motion through: both singular positions of 1.3 s, the reference instants within 1e-6 s,
    every step counted, SUNDIALS' failure messages in the log, not on stdout."""
    import contextlib
    import io

    out = io.StringIO()
    with caplog.at_level(logging.DEBUG, logger="cmm_dae.ida"), contextlib.redirect_stdout(out):
        res = cd.run_dae(iftomm.a02_four_bar(1), 1.3, rtol=1e-10, atol=1e-12,
                         output_dt=None)
    assert out.getvalue() == ""
    sing = [e.t for e in res.events if e.kind == "singular"]
    assert len(sing) == 2
    # the singular positions are where the cranks are horizontal: the reference's tip
    # (one-coordinate Lagrange equation, DOP853 at rtol 1e-13) is on the ground line there
    assert np.max(np.abs(iftomm.a02_reference(1, np.array(sing))[:, 1])) <= 1e-8
    err = np.max(np.abs(iftomm.crank_tip(res) - iftomm.a02_reference(1, res.t)))
    assert err <= 1e-7  # m
    assert res.stats.steps < 20_000 and res.stats.nfev < 100_000
    assert np.all(np.diff(res.t) > 0.0)
    assert any("Error: -" in r.getMessage() for r in caplog.records)
