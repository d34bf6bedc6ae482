"""Parameter sweeps: local pool, Dask LocalCluster, failures kept as rows, checkpoints."""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cmm_dae as cd

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
GRID = {"joints.D.spring.stiffness": [0.6, 1.0313240312354817, 2.0],
        "joints.E.limits.upper": [0.24, 0.25204]}


@pytest.fixture(scope="module")
def mech():
    return cd.load(MODELS / "double_folded.toml")


@pytest.fixture(scope="module")
def local_table(mech):
    return cd.sweep(mech, GRID, t_end=10.0, workers=2)


def numeric(table):
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in table.rows]


def test_grid_order_and_values(mech, local_table):
    assert len(local_table) == 6
    assert [r["case"] for r in local_table.rows] == list(range(6))
    # last key varies fastest
    assert [r["joints.E.limits.upper"] for r in local_table.rows[:2]] == [0.24, 0.25204]
    # the unchanged model is case 3: its switching times are the single run's
    ref = cd.run_dae(mech, 10.0)
    row = local_table.rows[3]
    assert row["t_limit_E_1"] == ref.events[0].t and row["t_release_E_1"] == ref.events[1].t
    d = ref.driver("A")  # over every IDA step, not the grid (above its samples' peak)
    assert row["peak_effort_A"] == pytest.approx(max(abs(d.low), abs(d.high)), rel=1e-12)
    assert row["peak_effort_A"] >= np.max(np.abs(d.effort))
    # a lower stop is reached earlier and left later
    assert local_table.rows[2]["t_limit_E_1"] < row["t_limit_E_1"]
    assert all(r["status"] == "success" for r in local_table.rows)


def test_dask_local_cluster_same_table(mech, local_table):
    import distributed  # a test dependency (the "test" extra): never skipped
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        table = cd.sweep(mech, GRID, t_end=10.0, client=client)
    assert numeric(table) == numeric(local_table)


def test_failures_are_rows(mech):
    cases = [{"joints.E.limits.upper": 0.25204},
             {"joints.E.limits.upper": 0.15},          # below the start: cannot assemble
             {"bodies.slider.mass": -1.0},             # invalid variant
             {"joints.E.limits.upper": 0.24}]
    table = cd.sweep(mech, cases, t_end=10.0, workers=2)
    st = [r["status"] for r in table.rows]
    assert st == ["success", "error", "error", "success"]
    assert "lies outside the limits [None, 0.15] of joint 'E'" in table.rows[1]["message"]
    assert "[bodies.slider] mass" in table.rows[2]["message"]
    assert math.isnan(table.rows[1]["t_reached"])
    assert table.rows[3]["t_limit_E_1"] > 0 and table.rows[0]["t_release_E_1"] > 0


def test_failure_mid_run_keeps_its_row(tmp_path):
    cases = [{"joints.E.limits.upper": 0.245}, {"drivers.A.speed": 3.0}]
    text = (MODELS / "slider_crank.toml").read_text().replace(
        'axis = [1.0, 0.0]', 'axis = [1.0, 0.0]\nlimits = { upper = 0.3 }')
    p = tmp_path / "sc.toml"
    p.write_text(text)
    table = cd.sweep(cd.load(p), cases, t_end=2.0, workers=1)
    assert table.rows[0]["status"] == "failed" and "lock-up" in table.rows[0]["message"]
    assert 0 < table.rows[0]["t_reached"] < 2.0
    assert table.rows[1]["status"] == "success" and table.rows[1]["t_reached"] == 2.0


def test_checkpoint_resume(mech, tmp_path):
    calls = []

    def metric(res):
        calls.append(1)
        return {"n_events": float(len(res.events))}

    ck = tmp_path / "ck.csv"
    part = {"joints.D.spring.stiffness": [0.6, 2.0]}
    cd.sweep(mech, part, t_end=10.0, metrics=metric, workers=1, checkpoint=ck)
    assert len(calls) == 2
    full = {"joints.D.spring.stiffness": [0.6, 1.0, 2.0]}
    table = cd.sweep(mech, full, t_end=10.0, metrics=metric, workers=1, checkpoint=ck)
    assert len(calls) == 3  # only the new case ran
    assert [r["joints.D.spring.stiffness"] for r in table.rows] == [0.6, 1.0, 2.0]
    assert all(r["n_events"] == 2.0 for r in table.rows)
    with ck.open() as f:
        assert len(list(csv.DictReader(f))) == 3


def test_bad_parameter_path(mech):
    with pytest.raises(cd.ModelError, match=r"\[parameters\] joints\.Q\.spring\.stiffness: not a "
                       r"parameter"):
        cd.sweep(mech, {"joints.Q.spring.stiffness": [1.0]}, t_end=1.0)


def test_cli_sweep(tmp_path):
    out = tmp_path / "s.csv"
    r = subprocess.run([sys.executable, "-m", "cmm_dae.cli", "sweep", "models/double_folded.toml",
                        "--param", "joints.D.spring.stiffness=0.5:2:3", "--out", str(out),
                        "--workers", "2"], capture_output=True, text=True, cwd=ROOT,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert "3 runs (3 successful)" in r.stdout
    rows = list(csv.DictReader(out.open()))
    assert [float(x["joints.D.spring.stiffness"]) for x in rows] == [0.5, 1.25, 2.0] or \
        sorted(float(x["joints.D.spring.stiffness"]) for x in rows) == [0.5, 1.25, 2.0]
    r = subprocess.run([sys.executable, "-m", "cmm_dae.cli", "sweep", "models/double_folded.toml",
                        "--param", "joints.D.spring.stiffness", "--out", str(out)],
                       capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 2 and "expected PATH=A:B:N" in r.stderr
