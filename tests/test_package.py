"""The package standing on its own: the model-file schema (one description for the loader,
the JSON Schema and the docs), the shipped examples, exports and friendlier output."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import tomllib
from pathlib import Path

import jsonschema
import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae.cli import main
from cmm_dae.description import loader, schema

ROOT = Path(__file__).resolve().parent.parent
MODELS = sorted((ROOT / "models").glob("*.toml")) + sorted((ROOT / "tests/models").glob("*.toml"))
VALIDATOR = jsonschema.Draft202012Validator(schema.json_schema())


def test_json_schema_is_valid_and_accepts_every_model():
    jsonschema.Draft202012Validator.check_schema(schema.json_schema())
    assert len(MODELS) >= 15
    for path in MODELS:
        errors = list(VALIDATOR.iter_errors(tomllib.loads(path.read_text())))
        assert errors == [], f"{path.name}: {[e.message for e in errors]}"


def test_shipped_schema_file_is_the_generated_one():
    shipped = Path(cd.__file__).with_name("model.schema.json").read_text()
    assert shipped == schema.json_text()


def test_loader_keys_come_from_the_schema():
    props = schema.json_schema()["properties"]
    assert set(loader.TOP_KEYS) == set(props)
    assert set(loader.BODY_KEYS) == set(props["bodies"]["additionalProperties"]["properties"])
    assert set(loader.JOINT_KEYS) == set(props["joints"]["additionalProperties"]["properties"])
    drivers = props["drivers"]["additionalProperties"]["oneOf"]
    assert {d["properties"]["motion"]["const"]: set(d["properties"]) for d in drivers} == \
        {m: set(ks) for m, ks in loader.DRIVER_KEYS.items()}


BAD = [
    ("[bodies.a]\nmass = 1.0\ninertia = 1.0\nmas = 2.0\n", "bodies.a", "mas"),
    ("[bodies.a]\nmass = \"heavy\"\ninertia = 1.0\n", "bodies.a", "mass"),
    ("[joints.J]\ntype = \"hinge\"\nconnects = [\"ground.O\", \"a.O\"]\n", "joints.J", "type"),
    ("[joints.J]\ntype = \"revolute\"\nconnects = [\"ground.O\", \"a.O\"]\n"
     "limits = { lower = 0.0, uper = 1.0 }\n", "joints.J.limits", "uper"),
    ("[drivers.J]\nmotion = \"constant_speed\"\ninitial = 0.0\nspeed = 1.0\namplitude = 2.0\n",
     "drivers.J", "amplitude"),
    ("[initial]\nvelocity = { J = 1.0 }\n", "initial", "velocity"),
]
BASE = ("[ground.points]\nO = [0.0, 0.0]\n[bodies.a]\nmass = 1.0\ninertia = 1.0\n"
        "points = { O = [0.0, 0.0] }\n[joints.J]\ntype = \"revolute\"\n"
        "connects = [\"ground.O\", \"a.O\"]\n")


@pytest.mark.parametrize("snippet,table,key", BAD)
def test_bad_keys_are_refused_by_loader_and_schema_alike(tmp_path, snippet, table, key):
    data = tomllib.loads(BASE)
    patch = tomllib.loads(snippet)
    for top, val in patch.items():
        for name, sub in (val.items() if top in ("bodies", "joints", "drivers") else [(None, val)]):
            if name is None:
                data[top] = sub
            else:
                data.setdefault(top, {}).setdefault(name, {}).update(sub)
    assert list(VALIDATOR.iter_errors(data)), "the schema accepted a bad file"
    with pytest.raises(cd.ModelError) as err:
        cd.from_dict(data, source="bad.toml")
    assert any(p.table == table and p.key.startswith(key) for p in err.value.problems), \
        err.value


def test_reference_names_every_table_and_key():
    md = schema.reference_markdown()
    for name, table in schema.SPEC.items():
        assert f"[{name}" in md
        for key, k in table.keys.items():
            assert f"| `{key}` |" in md
            for sub in k.keys:
                assert f"| `{key}.{sub}` |" in md


def test_examples_by_name(capsys):
    names = cd.examples()
    assert {"double_folded", "nipper_swing", "stick_slip_block"} <= set(names)
    assert cd.example("double_folded").read_bytes() == \
        (ROOT / "models/double_folded.toml").read_bytes()
    assert cd.load(cd.example("pendulum_stop.toml")).name
    with pytest.raises(cd.CmmError, match="did you mean 'double_folded'"):
        cd.example("double_foldd")
    with pytest.raises(cd.CmmError, match="no example model named"):
        cd.example("../models/double_folded")
    assert main(["run", "double_foldd", "--t-end", "0.1"]) == 2
    assert "did you mean 'double_folded'" in capsys.readouterr().err


def test_cli_schema_and_examples(capsys):
    assert main(["schema"]) == 0
    assert json.loads(capsys.readouterr().out) == schema.json_schema()
    assert main(["schema", "--markdown"]) == 0
    assert "| `restitution` |" in capsys.readouterr().out
    assert main(["examples"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == len(cd.examples()) and "double_folded" in out


@pytest.fixture(scope="module")
def folded():
    return cd.run_dae(cd.load(cd.example("double_folded")), 10.0)


def test_dataframe_and_csv_name_their_columns(folded, tmp_path):
    df = folded.to_dataframe()
    assert df.shape == (folded.t.size, len(folded.columns()))
    assert np.array_equal(df["driver A effort [N m]"].to_numpy(), folded.driver("A").effort)
    labels = set(df["configuration"].astype(str))
    assert labels == {"all free", "E locked (upper)"} or len(labels) == 2
    path = folded.to_csv(tmp_path / "run.csv")
    with path.open() as f:
        rows = list(csv.reader(f))
    head = rows[0]
    assert head[:3] == ["t [s]", "configuration", "configuration index"]
    k = head.index("joint E position [m]")
    # numbers read back to the bit; the configuration column is its description
    assert [float(r[k]) for r in rows[1:]] == folded.joint("E").position.tolist()
    assert {r[1] for r in rows[1:]} == labels
    locked = [r for r in rows[1:] if r[2] != rows[1][2]]
    assert locked and all("E" in r[1] for r in locked)


def test_report_leaves_out_relative_errors_of_round_off(folded):
    ref = cd.run_iterative(cd.load(cd.example("double_folded")), 10.0)
    cmp = cd.compare(folded, ref)
    torque_d = next(s for s in cmp.series if s.name == "joint D torque")
    assert torque_d.scale < 1e-20 and not torque_d.meaningful
    assert np.isnan(torque_d.max_rel)
    effort = next(s for s in cmp.series if s.name == "driver A effort")
    assert effort.meaningful and 1e-4 < effort.max_rel < 1e-2
    text = cmp.table()
    assert "nan" not in text and "round-off" in text

def test_report_moments_at_round_off_when_no_moment_is_real():
    """IFToMM A02 has no driver: every pin's torque is round-off (about 1e-15 N m against
    forces of 18 N), and the report gave them relative errors of 150 %. Moments are now
    measured against the largest force times the mechanism's size as well."""
    from cmm_dae.description import iftomm

    mech = iftomm.a02_four_bar(1)
    cmp = cd.compare(cd.run_dae(mech, 0.5), cd.run_iterative(mech, 0.5, dt=1e-3))
    torques = [s for s in cmp.series if s.name.endswith("torque")]
    assert torques and all(s.scale < 1e-12 and not s.meaningful for s in torques)
    forces = [s for s in cmp.series if s.unit == "N"]
    assert max(s.scale for s in forces) > 1.0 and all(s.meaningful for s in forces
                                                      if s.scale > 1e-6)



def test_report_html_has_an_animation(folded, tmp_path):
    ref = cd.run_iterative(cd.load(cd.example("double_folded")), 10.0)
    cmp = cd.compare(folded, ref)
    cmp.write_report(tmp_path, frames=12)
    page = (tmp_path / "report.html").read_text()
    assert page.count("data:image/png;base64,") == 12
    assert "Animation" in page and "E lost" in (tmp_path / "report.md").read_text()


def test_gif_has_the_frames_asked_for(folded, tmp_path):
    from PIL import Image

    from cmm_dae.report.animation import animate

    path = animate(folded, tmp_path / "a.gif", max_frames=15, fps=10)
    im = Image.open(path)
    assert im.n_frames == 15
    assert im.info["duration"] == 100
    im.seek(7)
    # the slider's stop bar (dark) and a red (locked) or green (free) joint square are drawn
    rgb = np.asarray(im.convert("RGB")).reshape(-1, 3).astype(int)
    red = np.sum((rgb[:, 0] > 200) & (rgb[:, 1] < 80) & (rgb[:, 2] < 80))
    green = np.sum((rgb[:, 1] > 100) & (rgb[:, 0] < 80) & (rgb[:, 2] < 80))
    assert red + green > 20


def test_progress_bar_reaches_the_end(capsys):
    res = cd.run_dae(cd.load(cd.example("pendulum_stop")), 1.0, progress=True)
    err = capsys.readouterr().err
    assert res.success and err.rstrip().endswith("s/s wall)") and "1/1 s" in err
    cd.run_iterative(cd.load(cd.example("pendulum_stop")), 0.5)
    assert capsys.readouterr().err == ""  # no bar unless asked


def test_cli_refuses_bad_animation_settings(capsys, tmp_path):
    for flag in (["--frames", "0"], ["--fps", "0"]):
        assert main(["animate", "pendulum_stop", "--t-end", "0.2", "--out",
                     str(tmp_path / "a.gif"), *flag]) == 2
        assert "expected a whole number >= 1" in capsys.readouterr().err


def test_importing_the_package_draws_in_no_plotting_library(tmp_path):
    """``import cmm_dae`` (every command-line call) leaves matplotlib unimported: it
    comes with the first figure (it took 0.7 of 1.7 s to import); a figure drawn after
    still works, on the Agg backend."""
    code = ("import sys, cmm_dae\n"
            "print('matplotlib' in sys.modules)\n"
            "from cmm_dae.core.figures import pyplot\n"
            "plt = pyplot()\n"
            "print(plt.get_backend().lower())\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=tmp_path, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "agg"]
