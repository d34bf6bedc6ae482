"""Structure analysis: active parts, Assur groups, augmented groups, configuration labels,
and the cost of finding them (polynomial, bounded, never paid by a run that needs no label)."""

from __future__ import annotations

from pathlib import Path

import pytest

import cmm_dae as cd
from cmm_dae.description.structure import configuration_label, labeller

from refs import four_bar_chain

MODELS = Path(__file__).resolve().parent.parent / "models"


def test_structure_classic_mechanisms():
    sc = cd.structure(cd.load(MODELS / "slider_crank.toml"))
    assert sc.mobility == 1 and sc.active == ("crank",)
    assert [(g.name, g.cls, g.augmented) for g in sc.groups] == [("RRP", 2, False)]
    assert sc.groups[0].internal == ("C",) and set(sc.groups[0].external) == {"B", "E"}
    fb = cd.structure(cd.load(MODELS / "four_bar.toml"))
    assert [(g.name, g.cls) for g in fb.groups] == [("RRR", 2)]
    text = str(cd.structure(cd.load(MODELS / "slider_crank_stop.toml")))
    assert "augmented Assur group RRRP (class II)" in text
    assert "E (external, geometric constraint)" in text


def test_paper_mechanisms_groups():
    df = cd.structure(cd.load(MODELS / "double_folded.toml"))
    assert [(g.name, g.cls, len(g.bodies), g.augmented) for g in df.groups] == [
        ("RRRP", 2, 3, True)]
    ni = cd.structure(cd.load(MODELS / "nipper_swing.toml"))
    assert [(g.name, g.cls, len(g.bodies), g.augmented) for g in ni.groups] == [
        ("RPR", 2, 2, False), ("RR-RR-RPR", 3, 5, True)]
    assert ni.active == ("crank9",) and not ni.unresolved


def test_internal_and_external_collision_labels():
    st = cd.structure(cd.load(MODELS / "slider_crank_stop.toml"))
    assert configuration_label(st, {}, {}) == "non-collision"
    assert configuration_label(st, {"D": "lower"}, {}) == "internal collision (joint D)"
    assert configuration_label(st, {"E": "upper"}, {}) == "external collision (joint E)"
    assert configuration_label(st, {"E": "upper"}, {"E": "upper"}) == "non-collision"
    # without a structure (groups not found): a plain label, never a stall
    assert configuration_label(None, {"E": "upper"}, {}) == "collision (joint E)"


@pytest.mark.parametrize("n", [4, 10])
def test_driven_chain_is_a_string_of_rrr_groups(n):
    st = cd.structure(four_bar_chain(n, driven=True))
    assert st.active == ("r0",) and st.mobility == 1 and not st.unresolved
    assert [g.name for g in st.groups] == ["RRR"] * n
    assert [set(g.bodies) for g in st.groups] == [{f"r{i + 1}", f"c{i}"} for i in range(n)]


def test_group_search_grows_polynomially_and_is_bounded():
    """An undriven chain has no Assur group at all, so the search examines every candidate
    it allows: that number must grow about linearly with the chain (it grew as 2^n)."""
    seen = {n: cd.structure(four_bar_chain(n)).examined for n in (8, 16, 32)}
    assert seen[8] > 0
    assert seen[16] / seen[8] < 2.5 and seen[32] / seen[16] < 2.5
    small = cd.structure(four_bar_chain(32), budget=50)
    assert small.examined <= 50 and len(small.unresolved) == 65


def test_labels_cost_nothing_without_a_geometric_lock(monkeypatch):
    """The labeller runs the structure analysis only for a label that needs it."""
    import sys

    # the package exports a function of that name too
    structure_mod = sys.modules["cmm_dae.description.structure"]
    calls = []
    orig = structure_mod.structure
    monkeypatch.setattr(structure_mod, "structure",
                        lambda m, **k: calls.append(1) or orig(m, **k))
    mech = cd.load(MODELS / "slider_crank_stop.toml")
    label = labeller(mech)
    assert label({}) == ("non-collision", 2) and calls == []
    assert label({"E": "upper"}) == ("external collision (joint E)", 1) and calls == [1]
    assert label({"D": "lower"})[0] == "internal collision (joint D)" and calls == [1]


def test_undriven_chain_of_32_loops_runs_with_plain_labels():
    """The run that took time exponential in the chain's size: here its first 0.05 s."""
    res = cd.run_dae(four_bar_chain(32), 0.05)
    assert res.success and res.t[-1] == 0.05 and res.configurations[0].label == "non-collision"
    assert res.drift[0] < 1e-9
