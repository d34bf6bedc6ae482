"""Design studies on exact gradients: targets reached, the optimised model file, bad
input named, the command line."""

from pathlib import Path

import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae.cli import main
from cmm_dae.core.errors import CmmError, ModelError
from cmm_dae.description.params import param_value
from cmm_dae.description.writer import write_model

ROOT = Path(__file__).resolve().parents[1]
PARAMS = ["joints.D.spring.stiffness", "joints.D.spring.rest", "joints.E.limits.upper"]
TARGETS = [{"event": "limit E", "value": 2.5}, {"event": "release E", "value": 7.5}]


@pytest.fixture(scope="module")
def mech():
    return cd.load(ROOT / "models" / "double_folded.toml")


def _bounds(mech):
    k, r = mech.joints["D"].spring.stiffness, mech.joints["D"].spring.rest
    return [(0.5 * k, 2.0 * k), (r - 0.1, r + 0.1), (0.245, 0.255)]


def test_double_folded_reaches_its_targets(mech, tmp_path):
    """E locks at 2.5 s and releases at 7.5 s (to 1e-6 s, checked by a fresh run of the
    written model file) with a lower peak driving torque than the paper's design."""
    # samples every 50 ms (the peak torque on that grid) keep the study's 30-odd runs short
    d = cd.design(mech, PARAMS, _bounds(mech), "peak_effort", TARGETS, 10.0,
                  rtol=1e-10, atol=1e-12, output_dt=0.05)
    assert abs(d.targets_end[0] - 2.5) < 1e-6 and abs(d.targets_end[1] - 7.5) < 1e-6
    assert d.objective_end < 0.7 * d.objective_start
    path = d.report(tmp_path / "rep")
    assert (tmp_path / "rep" / "effort.png").stat().st_size > 1000
    assert "Optimiser" in path.read_text()
    again = cd.run_dae(cd.load(tmp_path / "rep" / "optimised.toml"), 10.0, rtol=1e-10,
                       atol=1e-12, output_dt=0.05)
    t = [e.t for e in again.events]
    assert abs(t[0] - 2.5) < 1e-6 and abs(t[1] - 7.5) < 1e-6
    peak = float(np.max(np.abs(again.driver("A").effort)))
    assert peak == pytest.approx(d.objective_end, rel=1e-6)
    with pytest.raises(CmmError, match="would overwrite"):
        d.report(tmp_path / "rep")


def test_bad_design_input_is_named(mech):
    b = _bounds(mech)
    with pytest.raises(ModelError, match="excludes the start value"):
        cd.design(mech, PARAMS, [b[0], b[1], (0.26, 0.27)], constraints=TARGETS)
    with pytest.raises(ModelError, match="method"):
        cd.design(mech, PARAMS, b, constraints=TARGETS, method="nelder")
    with pytest.raises(ModelError, match="constraints\\[0\\].*unknown key"):
        cd.design(mech, PARAMS, b, constraints=[{"event": "limit E", "time": 2.5}])
    with pytest.raises(ModelError, match="KIND JOINT"):
        cd.design(mech, PARAMS, b, constraints=[{"event": "limit Z", "value": 2.5}])
    with pytest.raises(ModelError, match="KIND JOINT.*'jam E'"):
        cd.design(mech, PARAMS, b, constraints=[{"event": "jam E", "value": 2.5}])
    with pytest.raises(ModelError, match="3 \\(lower, upper\\) pairs"):
        cd.design(mech, PARAMS, b[:2], constraints=TARGETS)
    with pytest.raises(ModelError, match="lower < upper"):
        cd.design(mech, PARAMS, [b[0], (1.0, 0.5), b[2]], constraints=TARGETS)


def test_model_file_round_trip(mech, tmp_path):
    vals = {"joints.D.spring.stiffness": 0.75, "joints.E.limits.upper": 0.2501,
            "bodies.coupler.mass": 0.2, "drivers.A.speed": -0.7, "gravity.y": -9.8,
            "bodies.crank.points.B.x": 0.085, "ground.points.rail.y": -0.14}
    out = write_model(cd.with_params(mech, vals), tmp_path / "m.toml", vals)
    back = cd.load(out)
    for p, v in vals.items():
        assert param_value(back, p) == v
    assert back.bodies["crank"].points["B"] == (0.085, 0.0)  # the other component kept
    # the coupler's inertia was given about C: written back as the same centroidal value
    assert back.bodies["coupler"].inertia == pytest.approx(mech.bodies["coupler"].inertia,
                                                           rel=1e-15)
    with pytest.raises(CmmError, match="exists"):
        write_model(back, out, vals)


def test_cli_sensitivities_and_design_errors(tmp_path, capsys):
    assert main(["sensitivities", "pendulum_stop", "--t-end", "1",
                 "--param", "joints.O.limits.lower"]) == 0
    out = capsys.readouterr().out
    assert "joints.O.limits.lower" in out and "limit O" in out
    assert main(["sensitivities", "pendulum_stop", "--t-end", "1"]) == 2
    assert "--param" in capsys.readouterr().err
    assert main(["sensitivities", "pendulum_stop", "--param", "joints.X.limits.lower"]) == 2
    assert "joints.X.limits.lower" in capsys.readouterr().err
    spec = tmp_path / "s.toml"
    spec.write_text('model = "double_folded"\n[[params]]\npath = "drivers.A.speed"\n')
    assert main(["design", str(spec)]) == 2
    assert "params[0]" in capsys.readouterr().err and True
    spec.write_text("model = 3\n[[params\n")
    assert main(["design", str(spec)]) == 2
    assert "not a TOML file" in capsys.readouterr().err


def test_event_a_hair_before_an_output_time(mech):
    """The design the optimiser met on its way: E locks 5.7e-11 s before the output time
    2.5 s. The run used to restart IDA toward that output and end as a 'dead point'."""
    m = cd.with_params(mech, dict(zip(PARAMS, [0.5199318543243575, 0.8256207276895722,
                                               0.2496119951144816], strict=True)))
    r = cd.run_dae(m, 10.0, rtol=1e-10, atol=1e-12)
    assert [e.kind for e in r.events] == ["limit", "release"]
    assert 2.5 - 1e-10 < r.events[0].t < 2.5
