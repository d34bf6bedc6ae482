"""``cmm-dae bench --peers``: cmm_dae against MuJoCo at equal accuracy on IFToMM A02, and
against MuJoCo and Exudyn on the (spatial) Bennett linkage."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae.cli import main
from cmm_dae.description import iftomm
from cmm_dae.studies import peers, peers_bennett, peers_exudyn


def test_mujoco_model_is_the_a02_mechanism():
    """The MuJoCo model starts assembled on A02's parallelogram (the tip at (0, 1) m moving
    at +1 m/s at t = 0) and, with a tiny step and its closures tuned, follows the reference
    closely (within 1e-10 m over 0.2 s at h 1e-4, measured 7.9e-13; with 8 loops over 2 s
    within 1e-6 m, measured 6.0e-7): it is the same mechanism, timed as tuned."""
    t, tip = peers.a02_mujoco(2, 0.2, h=1e-4)
    assert t[0] == 0.0 and np.allclose(tip[0], [0.0, 1.0], atol=1e-12)
    assert abs((tip[1, 0] - tip[0, 0]) / 1e-4 - 1.0) <= 1e-3
    assert peers.error_a02(t, tip, 2) <= 1e-10
    assert peers.error_a02(*peers.a02_mujoco(8, 2.0, h=1e-4), 8) <= 1e-6


def test_compare_picks_the_cheapest_tolerance_reaching_mujocos_error():
    """One row: MuJoCo's error at h 1e-2 sets the target; the chosen rtol is the loosest
    of the ladder whose error is no larger, and the tolerance before it (if any) was
    worse or failed; the ratio is cmm_dae's time over MuJoCo's."""
    row = peers.compare_a02(1, t_end=0.5, repeat=1)
    assert row["mujoco_error"] > 0 and row["rtol"] in peers.RTOLS
    assert row["cmm_dae_error"] <= row["mujoco_error"]
    k = peers.RTOLS.index(row["rtol"])
    if k:
        res = cd.run_dae(iftomm.a02_four_bar(1), 0.5, rtol=peers.RTOLS[k - 1], throw=False)
        assert not res.success or peers.error_a02(res.t, iftomm.crank_tip(res), 1) \
            > row["mujoco_error"]
    assert math.isclose(row["ratio"], row["cmm_dae_s"] / row["mujoco_s"])
    # both times are reported (compared only in the benchmark: a test never times)
    assert math.isfinite(row["cmm_dae_first_s"]) and row["cmm_dae_first_s"] > 0
    assert math.isclose(row["first_ratio"], row["cmm_dae_first_s"] / row["mujoco_s"])
    assert "time ratio" in peers.peers_table([row])
    # which path the timed runs took, as the run's own meta says
    res = cd.run_dae(iftomm.a02_four_bar(1), 0.5, rtol=row["rtol"])
    assert row["path"] == ("C" if res.meta["compiled"] else "Python")
    assert f"  {row['path']:>6}" in peers.peers_table([row])


def test_cli_peers(capsys):
    assert main(["bench", "--peers", "--loops", "1", "--repeat", "1", "--steps", "1e-5"]) == 0
    out = capsys.readouterr().out
    assert "A02 four-bar chain" in out and "MuJoCo" in out and "Andrews' squeezer" in out
    assert "against Exudyn" in out
    assert "Bennett linkage" in out and "Exudyn" in out.split("Bennett linkage")[1]
    assert main(["bench", "--peers", "--loops", "0"]) == 2
    assert "--loops must be integers >= 1" in capsys.readouterr().err
    assert main(["bench", "--peers", "--steps", "0.1"]) == 2
    assert "--steps must be MuJoCo steps" in capsys.readouterr().err


def test_without_mujoco_the_error_says_how_to_get_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import fails as if not installed
    assert not peers.mujoco_available()
    with pytest.raises(cd.CmmError, match=r"pip install 'cmm_dae\[peers\]'"):
        peers.a02_mujoco(1, 0.1)


def test_mujoco_model_is_andrews_squeezer():
    """The MuJoCo squeezer against the Test Set's y(0.03): within 1.5e-3 rad at h 1e-5 and
    5e-5 at h 2e-6 (measured 1.5e-6 and 8.2e-8 with the closures tuned, 8.7e-4 and 2.9e-5
    with MuJoCo's default impedance), the error falling about as h^2 (the closures' time
    constant is 2 h): the same mechanism, its error MuJoCo's own."""
    from cmm_dae.studies.peers_andrews import _error, andrews_mujoco

    coarse, fine = _error(andrews_mujoco(1e-5)), _error(andrews_mujoco(2e-6))
    assert coarse <= 1.5e-3 and fine <= 5e-5
    assert 15.0 <= coarse / fine <= 45.0  # 25 for h^2


def test_compare_andrews_picks_the_cheapest_tolerance_reaching_mujocos_error():
    from cmm_dae.studies.peers_andrews import (
        ANDREWS_003,
        _error,
        andrews_table,
        compare_andrews,
    )

    row = compare_andrews(1e-5, repeat=1)
    assert row["rtol"] in peers.RTOLS and row["cmm_dae_error"] <= row["mujoco_error"]
    k = peers.RTOLS.index(row["rtol"])
    if k:  # the tolerance before it failed (too loose for the spring) or was worse
        mech = cd.load(cd.example("andrews_squeezer"))
        res = cd.run_dae(mech, 0.03, rtol=peers.RTOLS[k - 1], output_dt=None, throw=False)
        assert not res.success or _error({j: res.joint(j).position[-1]
                                          for j in ANDREWS_003}) > row["mujoco_error"]
    assert math.isclose(row["ratio"], row["cmm_dae_s"] / row["mujoco_s"])
    assert "Andrews' squeezer" in andrews_table([row])


def test_exudyn_model_is_the_a02_mechanism():
    """Exudyn's model starts on A02's parallelogram (the tip at (0, 1) m) and its error
    against the reference falls as h^2 (generalized-alpha, second order): 2.9e-3 m at
    h 1e-2, 100 times less at 1e-3 (ratio within 90-110), over 2 s with 2 loops."""
    errs = []
    for h in (1e-2, 1e-3):
        t, tip = peers_exudyn.a02_exudyn(2, 2.0, h)
        assert np.allclose(tip[0], [0.0, 1.0], atol=1e-12)
        assert t[-1] == pytest.approx(2.0, abs=1e-12)
        errs.append(peers.error_a02(t, tip, 2))
    assert 2e-3 <= errs[0] <= 4e-3
    assert 90.0 <= errs[0] / errs[1] <= 110.0


def test_compare_with_exudyn_picks_the_cheapest_tolerance():
    """The Exudyn row: cmm_dae's chosen rtol reaches Exudyn's error at h 1e-2; the table
    names Exudyn; without Exudyn the error says how to get it."""
    row = peers_exudyn.compare_a02_exudyn(1, t_end=0.5, repeat=1)
    assert row["exudyn_error"] > 0 and row["rtol"] in peers.RTOLS
    assert row["cmm_dae_error"] <= row["exudyn_error"]
    assert math.isclose(row["ratio"], row["cmm_dae_s"] / row["exudyn_s"])
    assert "Exudyn err" in peers_exudyn.exudyn_table([row])


def test_without_exudyn_the_error_says_how_to_get_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "exudyn", None)
    assert not peers_exudyn.exudyn_available()
    with pytest.raises(cd.CmmError, match=r"pip install 'cmm_dae\[peers\]'"):
        peers_exudyn.a02_exudyn(1, 0.1)


def test_side_by_side_timings_alternate():
    """The codes compared run in turn (a slow spell of a shared machine falls on both),
    each warmed once first; each gets its best time and its last result; a None is
    left out."""
    from cmm_dae.studies.bench import best_times

    order: list[str] = []
    got = best_times([lambda: order.append("a") or len(order),
                      lambda: order.append("b") or -len(order)], 3)
    assert order == ["a", "b"] * 4
    assert [r for _, r in got] == [7, -8]
    assert all(0.0 <= t < 1.0 for t, _ in got)
    # nothing to time (no cmm_dae setting matches the peer): (nan, None), the rest timed
    order.clear()
    (t_a, r_a), (t_none, r_none) = best_times([lambda: order.append("a") or 1, None], 2)
    assert order == ["a"] * 3 and r_a == 1 and 0.0 <= t_a < 1.0
    assert math.isnan(t_none) and r_none is None


def _bennett_cmm_dae(t_end: float, rtol: float) -> tuple[np.ndarray, np.ndarray]:
    """cmm_dae's Bennett linkage as a reference for peers_bennett.error_j1: (t, J1..J3)."""
    res = cd.run_dae(cd.load(cd.example("bennett_linkage")), t_end, rtol=rtol)
    return res.t, np.column_stack([res.joint(j).position for j in ("J1", "J2", "J3")])


@pytest.mark.timeout(120)
def test_mujoco_bennett_is_the_linkage():
    """MuJoCo's Bennett linkage starts at rest on the closed form (J1 1 rad, J2 from
    tan(th1/2) tan(th2/2) = sin 45 deg / sin 15 deg, J3 = -J1) and at h 1e-3 over 2 s keeps
    the closed form within 1e-6 (measured 2.4e-7: its loop closure is soft), J3 = -J1
    within 2e-7 rad (4.6e-8), and its J1 angle within 1e-7 rad of cmm_dae's at rtol 1e-10
    (2.0e-8): the same mechanism, in an independent formulation (a tree of hinges)."""
    mech = cd.load(cd.example("bennett_linkage"))
    t, q = peers_bennett.bennett_mujoco(1e-3, 2.0)
    k = math.sin(math.radians(45)) / math.sin(math.radians(15))
    assert q[0] == pytest.approx([1.0, 2 * math.atan(k / math.tan(0.5)), -1.0], abs=1e-15)
    assert t[-1] == pytest.approx(2.0) and len(t) == 2001
    assert np.max(np.abs(peers_bennett.bennett_relation(mech, q[:, 0], q[:, 1]))) <= 1e-6
    assert np.max(np.abs(q[:, 2] + q[:, 0])) <= 2e-7
    assert peers_bennett.error_j1(t[::10], q[::10, 0], _bennett_cmm_dae(2.0, 1e-10)) <= 1e-7
    # the J1 angle swings as the model file says: between 1 and 0.29 rad
    assert 0.28 <= q[:, 0].min() <= 0.30 and q[:, 0].max() == pytest.approx(1.0, abs=1e-9)


@pytest.mark.timeout(120)
def test_exudyn_bennett_is_the_linkage():
    """Exudyn's Bennett linkage (kinematic tree, loop closed by two rows) keeps the closed
    form within 1e-9 (hard constraints; measured 1.3e-10 at h 1e-2), and its J1 error
    against cmm_dae at rtol 1e-10 falls as h^2 (generalized-alpha): 2.1e-3 rad at h 1e-2,
    100 times less at 1e-3 (ratio within 90-110), over 2 s."""
    mech = cd.load(cd.example("bennett_linkage"))
    reference = _bennett_cmm_dae(2.0, 1e-10)
    errs = []
    for h in (1e-2, 1e-3):
        t, q = peers_bennett.bennett_exudyn(h, 2.0)
        assert q[0] == pytest.approx(peers_bennett.start_angles(mech), abs=1e-15)
        assert np.max(np.abs(peers_bennett.bennett_relation(mech, q[:, 0], q[:, 1]))) <= 1e-9
        every = int(round(0.01 / h))
        errs.append(peers_bennett.error_j1(t[::every], q[::every, 0], reference))
    assert 1.5e-3 <= errs[0] <= 3e-3
    assert 90.0 <= errs[0] / errs[1] <= 110.0


@pytest.mark.timeout(180)
def test_compare_bennett_picks_the_cheapest_tolerance():
    """The Bennett rows over 0.5 s: the reference (MuJoCo at h 1e-4) is within 1e-8 rad of
    cmm_dae at rtol 1e-12; each row's rtol is the loosest of the ladder whose J1 error is
    no larger than the peer's (the one before it was worse or failed); each peer's error
    falls from its loose step to its tight one; the table prints every row."""
    out = peers_bennett.compare_bennett(t_end=0.5, repeat=1, reference_step=1e-4)
    assert out["reference_gap"] <= 1e-8 and out["reference_relation"] <= 1e-7
    rows = out["rows"]
    assert [r["code"] for r in rows] == ["mujoco"] * 2 + ["exudyn"] * 2
    mech = cd.load(cd.example("bennett_linkage"))
    reference = peers_bennett.bennett_reference(0.5, 1e-4)
    for r in rows:
        err = r[f"{r['code']}_error"]
        assert r["rtol"] in peers.RTOLS and r["cmm_dae_error"] <= err
        k = peers.RTOLS.index(r["rtol"])
        if k:
            res = cd.run_dae(mech, 0.5, rtol=peers.RTOLS[k - 1], throw=False,
                             output_dt=max(r["h"], 0.01))
            assert not res.success or peers_bennett.error_j1(
                res.t, res.joint("J1").position, reference) > err
        assert math.isclose(r["ratio"], r["cmm_dae_s"] / r[f"{r['code']}_s"])
    assert rows[0]["mujoco_error"] > 100 * rows[1]["mujoco_error"]
    assert rows[2]["exudyn_error"] > 100 * rows[3]["exudyn_error"]
    table = peers_bennett.bennett_table(out)
    assert "Bennett linkage" in table and table.count("MuJoCo  ") == 2
    assert "2.5e-03" in table and table.count("Exudyn  ") == 2
