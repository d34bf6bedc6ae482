"""Bad input: each problem is a ModelError/AssemblyError naming file, table and key."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import cmm_dae as cd

MODELS = Path(__file__).resolve().parent.parent / "models"
BASE = (MODELS / "slider_crank.toml").read_text()


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "m.toml"
    p.write_text(text)
    return p


def load_text(tmp_path: Path, text: str):
    return cd.load(write(tmp_path, text))


CASES = [
    # (replace old -> new in the slider-crank file, regex the message must match)
    ("mass = 0.1\n", "mass = -0.1\n", r"\[bodies\.crank\] mass: expected a positive mass"),
    ("mass = 0.1\n", "mass = \"heavy\"\n", r"\[bodies\.crank\] mass: expected a number, got str"),
    ("mass = 0.1\n", "mass = nan\n", r"\[bodies\.crank\] mass: expected a finite number, got nan"),
    ("mass = 0.1\n", "mass = inf\n", r"\[bodies\.crank\] mass: expected a finite number"),
    ("mass = 0.1\n", "mas = 0.1\n", r"\[bodies\.crank\] mas: unknown key; did you mean 'mass'"),
    ("mass = 0.1\n", "", r"\[bodies\.crank\] mass: missing"),
    ("inertia = 2.5e-5 ", "inertia = -2.5e-5 ",
     r"\[bodies\.crank\] inertia: expected a centroidal inertia >= 0"),
    ('connects = ["crank.B", "rod.B"]', 'connects = ["crank.B", "rdo.B"]',
     r"\[joints\.B\] connects: unknown body 'rdo'"),
    ('connects = ["crank.B", "rod.B"]', 'connects = ["crank.X", "rod.B"]',
     r"\[joints\.B\] connects: body 'crank' has no point 'X'"),
    ('connects = ["ground.A", "crank.A"]', 'connects = ["ground.Z", "crank.A"]',
     r"\[joints\.A\] connects: unknown ground point 'Z'"),
    ('connects = ["crank.B", "rod.B"]', 'connects = "crank.B"',
     r"\[joints\.B\] connects: expected two strings"),
    ('type = "revolute"\nconnects = ["crank.B"', 'type = "hinge"\nconnects = ["crank.B"',
     r"\[joints\.B\] type: expected one of 'revolute', 'prismatic', 'contact', 'gear', "
     r"got 'hinge'"),
    ("axis = [1.0, 0.0]", "axis = [0.0, 0.0]", r"\[joints\.E\] axis: expected a non-zero"),
    ("axis = [1.0, 0.0]", "axis = [1.0]", r"\[joints\.E\] axis: expected a list of 2 numbers"),
    ('motion = "constant_speed"', 'motion = "constant_sped"',
     r"\[drivers\.A\] motion: .*did you mean 'constant_speed'"),
    ("speed = 6.283185307179586", "", r"\[drivers\.A\] speed: missing"),
    ("[drivers.A]", "[drivers.Q]", r"\[drivers\.Q\]: drives unknown joint 'Q'"),
    ("[mechanism]", "[mechanisms]", r"\[top level\] mechanisms: unknown key; did you mean "
     "'mechanism'"),
    ("gravity = [0.0, -9.81]", "gravity = [0.0, -9.81, 0.0]",
     r"\[mechanism\] gravity: expected a list of 2 numbers"),
    ("[joints.A]", "[joints.A]\nlimits = { lower = 1.0, upper = 0.5 }",
     r"\[joints\.A\] limits: lower \(1\.0\) must be below upper \(0\.5\)"),
    ("[joints.A]", "[joints.A]\nrestitution = 0.5",
     r"\[joints\.A\] restitution: a restitution needs 'limits'"),
    ("[joints.B]", "[joints.B]\nspring = { stiffness = -1.0 }",
     r"\[joints\.B\] spring\.stiffness: expected a stiffness >= 0"),
    ("[joints.B]", "[joints.B]\ndamper = { damping = -1.0 }",
     r"\[joints\.B\] damper\.damping: expected a damping >= 0"),
    ("[drivers.A]", "[joints.E2]\ntype = \"revolute\"\nconnects = [\"rod.B\", \"rod.C\"]\n"
     "[drivers.A]", r"\[joints\.E2\] connects: joins body 'rod' to itself"),
    ("[drivers.A]", "[initial]\njoints = { A = 0.7 }\n[drivers.A]",
     r"\[initial\] joints\.A: joint 'A' is driven: its driver gives 0\.5"),
    ("[drivers.A]", "[initial]\njoints = { Q = 0.7 }\n[drivers.A]",
     r"\[initial\] joints\.Q: unknown joint 'Q'"),
    ("[drivers.A]", "[bodies.lost]\nmass = 1.0\ninertia = 1.0\n[drivers.A]",
     r"\[bodies\.lost\]: is connected by no joint"),
    ("inertia = 2.5e-5 ", "inertia = 2.5e-5\ninertia_about = \"B\" ",
     r"\[bodies\.crank\] inertia: 2\.5e-05 kg m\^2 about 'B' leaves a centroidal inertia"),
]


@pytest.mark.parametrize(("old", "new", "pattern"), CASES)
def test_bad_model_message(tmp_path, old, new, pattern):
    assert old in BASE, old
    with pytest.raises(cd.ModelError, match=pattern) as info:
        load_text(tmp_path, BASE.replace(old, new, 1))
    assert str(tmp_path / "m.toml") in str(info.value)


def test_toml_syntax_error_names_line(tmp_path):
    with pytest.raises(cd.ModelError, match=r"TOML syntax error: .*at line 9, column 15"):
        load_text(tmp_path, BASE.replace("[ground.points]", "[ground.points", 1))


def test_missing_file():
    with pytest.raises(cd.ModelError, match=r"(?s)nope\.toml.*cannot read the file"):
        cd.load("nope.toml")


def test_several_problems_in_one_message(tmp_path):
    text = BASE.replace("mass = 0.1\n", "mass = -0.1\n", 1).replace(
        '"rod.B"]', '"rdo.B"]', 1).replace("speed = 6.283185307179586", "speed = \"fast\"")
    with pytest.raises(cd.ModelError) as info:
        load_text(tmp_path, text)
    msg = str(info.value)
    assert "3 problems" in msg
    assert re.search(r"\[bodies\.crank\] mass", msg)
    assert re.search(r"\[joints\.B\] connects: unknown body 'rdo'", msg)
    assert re.search(r"\[drivers\.A\] speed: expected a number, got str", msg)


def test_inertia_about_point_parallel_axis(tmp_path):
    m = load_text(tmp_path, BASE.replace("inertia = 2.5e-5 ", "inertia = 1.0e-4\n"
                                         "inertia_about = \"A\" ", 1))
    assert m.bodies["crank"].inertia == pytest.approx(1.0e-4 - 0.1 * 0.025**2, rel=1e-14)


def test_under_specified_initial_state(tmp_path):
    mech = cd.load(MODELS / "crank_pendulum.toml")
    text = (MODELS / "crank_pendulum.toml").read_text().replace(
        "joints = { B = -1.2 }", "joints = {}").replace("velocities = { B = 0.0 }", "")
    with pytest.raises(cd.ModelError, match=r"\[initial\] joints: the mechanism has 1 free "
                       r"degree\(s\) of freedom .* it names 0"):
        cd.run_dae(load_text(tmp_path, text), 0.1)
    assert mech.initial.joints["B"] == -1.2


def test_loop_that_cannot_close(tmp_path):
    # A rod shorter than the crank offset needs: the slider cannot reach the guide.
    text = BASE.replace("C = [0.2, 0.0] }", "C = [0.03, 0.0] }").replace(
        "rail = [0.0, 0.0]", "rail = [0.0, 0.2]")
    with pytest.raises(cd.AssemblyError, match=r"cannot be assembled at t = 0 s: the loop "
                       r"through .*joint [BCE].* does not close \(largest residual"):
        cd.run_dae(load_text(tmp_path, text), 0.1)


def test_redundant_constraints(tmp_path):
    """A second prismatic guide on the slider duplicates joint E: its two rows are left
    out as redundant, the motion is that of the single guide, and the guide's reaction is
    shared equally between the two (the minimum-norm solution)."""
    text = BASE.replace("[drivers.A]", "[joints.E2]\ntype = \"prismatic\"\n"
                        "connects = [\"ground.rail\", \"slider.C\"]\n[drivers.A]")
    twin = cd.run_dae(load_text(tmp_path, text), 0.5, rtol=1e-10, atol=1e-12)
    one = cd.run_dae(load_text(tmp_path, BASE), 0.5, rtol=1e-10, atol=1e-12)
    assert len(twin.meta["redundant"]) == 2 and not one.meta["redundant"]
    assert np.max(np.abs(twin.body("slider").pose - one.body("slider").pose)) <= 1e-9
    fe, fe2 = twin.joint("E").force, twin.joint("E2").force
    assert np.max(np.abs(fe - fe2)) <= 1e-9 * np.max(np.abs(fe))
    assert np.max(np.abs(fe + fe2 - one.joint("E").force)) <= 1e-8 * np.max(np.abs(fe))


@pytest.mark.parametrize(("kw", "pattern"), [
    ({"t_end": -1.0}, r"\[run\] t_end: expected a positive, finite end time"),
    ({"t_end": math.inf}, r"\[run\] t_end: expected a positive, finite end time .*got inf"),
    ({"t_end": 1.0, "rtol": 0.5}, r"\[run\] rtol: expected 1e-15 <= rtol <= 1e-2"),
    ({"t_end": 1.0, "atol": 0.0}, r"\[run\] atol: expected 0 < atol"),
    ({"t_end": 1.0, "output_dt": -0.1}, r"\[run\] output_dt: expected a positive step"),
])
def test_bad_run_options(kw, pattern):
    mech = cd.load(MODELS / "slider_crank.toml")
    with pytest.raises(cd.ModelError, match=pattern):
        cd.run_dae(mech, **kw)


def test_python_built_mechanism_is_validated():
    with pytest.raises(cd.ModelError, match=r"\[bodies\.b\] mass: expected a positive mass"):
        cd.Mechanism("m", bodies=[cd.Body("b", 0.0, 1.0, points={"O": (0, 0)})],
                     joints=[cd.Joint("O", "revolute", "ground.O", "b.O")],
                     ground={"O": (0.0, 0.0)})


def test_python_built_mechanism_runs():
    """A pendulum built in Python: small-amplitude period against 2 pi sqrt(J_O / m g d)."""
    L, m = 0.3, 0.5
    J = m * L**2 / 12
    mech = cd.Mechanism(
        "pendulum", ground={"O": (0.0, 0.0)},
        bodies=[cd.Body("rod", m, J, centroid=(L / 2, 0.0), points={"O": (0.0, 0.0)},
                        guess=(0.0, 0.0, -np.pi / 2))],
        joints=[cd.Joint("O", "revolute", "ground.O", "rod.O")],
        initial=cd.Initial({"O": -np.pi / 2 + 1e-4}))
    res = cd.run_dae(mech, 3.0, rtol=1e-10, atol=1e-12, output_dt=1e-3)
    th = res.joint("O").position + np.pi / 2
    i = np.flatnonzero((th[:-1] > 0) & (th[1:] <= 0))
    # linear interpolation is exact to O(dt^3) at a crossing of a sine (zero curvature there)
    crossings = res.t[i] + th[i] / (th[i] - th[i + 1]) * (res.t[i + 1] - res.t[i])
    period = np.mean(np.diff(crossings))
    ref = 2 * np.pi * np.sqrt((J + m * (L / 2) ** 2) / (m * 9.81 * L / 2))
    assert period == pytest.approx(ref, rel=1e-8)  # amplitude 1e-4 rad: correction ~6e-10


MORE_CASES = [
    ("[joints.E]", "[joints.E]\nlimits = { upper = 0.3 }\nrestitution = 1.5",
     r"\[joints\.E\] restitution: expected a number in \[0, 1\], got 1\.5"),
    ("[joints.E]", "[joints.E]\nlimits = { lowr = 0.1 }",
     r"\[joints\.E\.limits\] lowr: unknown key; did you mean 'lower'"),
    ("[joints.B]", "[joints.B]\nspring = { rest = 0.1 }",
     r"\[joints\.B\.spring\] stiffness: missing"),
    ("[bodies.rod]", "[bodys.extra]\nmass = 1.0\n[bodies.rod]",
     r"\[top level\] bodys: unknown key; did you mean 'bodies'"),
    ("[joints.A]\ntype", "[joints.A]\nlimits = { lower = 0.0 }\ntype",
     r"\[drivers\.A\]: joint 'A' has limits: a driven joint cannot be metamorphic"),
    ("[drivers.A]", "[initial]\njoints = { E = \"far\" }\n[drivers.A]",
     r"\[initial\] joints\.E: expected a number, got str"),
    ("points = { C = [0.0, 0.0] }", "points = { C = [0.0, \"x\"] }",
     r"\[bodies\.slider\.points\] C\[1\]: expected a number, got str"),
    ("guess = [0.24, 0.0, 0.0]", "guess = [0.24, 0.0]",
     r"\[bodies\.slider\] guess: expected a list of 3 numbers"),
    ("inertia = 1.0e-4\n", "inertia = -1.0e-4\n",
     r"\[bodies\.slider\] inertia: expected a centroidal inertia >= 0"),
    ('motion = "constant_speed"\ninitial', 'motion = "table"\ntimes = [0.0, 1.0, 0.5]\n'
     'values = [0.5, 1.0, 2.0]\n#', r"\[drivers\.A\] times: expected strictly increasing"),
]


@pytest.mark.parametrize(("old", "new", "pattern"), MORE_CASES)
def test_more_bad_model_messages(tmp_path, old, new, pattern):
    assert old in BASE, old
    with pytest.raises(cd.ModelError, match=pattern):
        load_text(tmp_path, BASE.replace(old, new, 1))


def test_initial_coordinate_outside_limits(tmp_path):
    text = BASE.replace('axis = [1.0, 0.0]', 'axis = [1.0, 0.0]\nlimits = { upper = 0.2 }')
    text = text.replace("[drivers.A]", "[initial]\njoints = { E = 0.25 }\n[drivers.A]")
    with pytest.raises(cd.ModelError, match=r"\[initial\] joints\.E: 0\.25 lies outside the "
                       r"limits \[None, 0\.2\] of joint 'E'"):
        load_text(tmp_path, text)


def _pendulum_parts():
    body = cd.Body("rod", 1.0, 0.01, (0.1, 0.0), {"O": (0.0, 0.0)})
    joint = cd.Joint("O", "revolute", "ground.O", "rod.O")
    return body, joint


def test_duplicate_names_in_python():
    body, joint = _pendulum_parts()
    with pytest.raises(cd.ModelError, match=r"\[bodies\.rod\]: two entries named 'rod'"):
        cd.Mechanism("m", bodies=[body, body], joints=[joint], ground={"O": (0, 0)})
    with pytest.raises(cd.ModelError, match=r"\[drivers\.O\]: two entries named 'O' \(one "
                       r"driver per joint\)"):
        cd.Mechanism("m", bodies=[body], joints=[joint], ground={"O": (0, 0)},
                     drivers=[cd.Driver("O", speed=1.0), cd.Driver("O", speed=2.0)])


def test_two_drivers_one_joint_in_toml_is_a_syntax_error(tmp_path):
    text = BASE + '\n[drivers.A]\nmotion = "constant_speed"\ninitial = 0.5\nspeed = 1.0\n'
    with pytest.raises(cd.ModelError,
                       match=r"TOML syntax error: Cannot declare \('drivers', 'A'\) twice"):
        load_text(tmp_path, text)


def test_nothing_is_evaluated(tmp_path):
    """An expression where a number belongs is a type error, never Python code."""
    text = BASE.replace("speed = 6.283185307179586", 'speed = "__import__(\'os\').getcwd()"')
    with pytest.raises(cd.ModelError, match=r"\[drivers\.A\] speed: expected a number, got str"):
        load_text(tmp_path, text)


def test_assembled_start_beyond_a_limit(tmp_path):
    """A coordinate not named in [initial] but assembled beyond its stop is reported."""
    text = BASE.replace('axis = [1.0, 0.0]', 'axis = [1.0, 0.0]\nlimits = { upper = 0.2 }')
    with pytest.raises(cd.ModelError, match=r"\[initial\] joints: joint 'E' assembles at "
                       r"0\.24[0-9]*, outside its limits \[None, 0\.2\]"):
        cd.run_dae(load_text(tmp_path, text), 0.1)
