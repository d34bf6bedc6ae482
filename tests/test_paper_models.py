"""The paper's two mechanisms (section 4): configuration sequences as golden lists, both
integrators, the structure the paper describes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cmm_dae as cd

MODELS = Path(__file__).resolve().parent.parent / "models"

# (kind, joint, label before, label after); the times are checked separately
GOLDEN_DOUBLE_FOLDED = [
    ("limit", "E", "non-collision", "external collision (joint E)"),
    ("release", "E", "external collision (joint E)", "non-collision"),
]
GOLDEN_NIPPER = [
    ("lock", "G", "non-collision", "non-collision"),
    ("release", "G", "non-collision", "non-collision"),
    ("limit", "C", "non-collision", "internal collision (joint C)"),
    ("release", "C", "internal collision (joint C)", "non-collision"),
    ("limit", "G", "non-collision", "non-collision"),
]


def sequence(res):
    return [(e.kind, e.joint, res.configurations[e.before].label,
             res.configurations[e.after].label) for e in res.events]


def both_methods(name: str):
    """One cycle of a model with IDA (rtol 1e-9) and the iterative algorithm (dt 0.01)."""
    mech = cd.load(MODELS / f"{name}.toml")
    model = cd.Model(mech)
    return (mech, cd.run_dae(mech, 10.0, rtol=1e-9, atol=1e-11, model=model),
            cd.run_iterative(mech, 10.0, dt=0.01, model=model))


@pytest.fixture(scope="module")
def double_folded():
    return both_methods("double_folded")


@pytest.fixture(scope="module")
def nipper():
    return both_methods("nipper_swing")


def test_double_folded_sequence(double_folded):
    mech, a, b = double_folded
    assert sequence(a) == GOLDEN_DOUBLE_FOLDED
    assert sequence(b) == GOLDEN_DOUBLE_FOLDED
    lock, rel = a.events
    # the paper's switching times: 2.63 s and 7.3 s
    assert abs(lock.t - 2.63) < 0.01 and abs(rel.t - 7.3) < 0.02
    assert 0.0 <= b.events[0].t - lock.t < 0.01 + 1e-12
    assert 0.0 <= b.events[1].t - rel.t < 0.01 + 1e-12
    # D turns while E holds the slider; D is nearly static otherwise
    D = a.joint("D").position
    held = a.configuration == lock.after
    free = (a.t > 0.5) & (a.t < lock.t)
    assert np.ptp(D[held]) > 0.3 and np.ptp(D[free]) < 0.05


def test_double_folded_start_up_jump(double_folded):
    """The spring at D is unloaded at t = 0, so D deflects within the first instants under
    the loads (the jump the paper remarks on): fast at first, then nearly static."""
    mech, a, _ = double_folded
    D = a.joint("D").position
    rest = mech.joints["D"].spring.rest
    assert D[0] == pytest.approx(rest, abs=1e-9)  # rest written to 10 decimals
    i02 = int(np.searchsorted(a.t, 0.2))
    jump = D[i02] - D[0]
    assert abs(jump) > 5e-3  # rad, within 0.2 s
    assert abs(D[2 * i02] - D[i02]) < 0.2 * abs(jump)  # then it settles


def test_double_folded_structure():
    st = cd.structure(cd.load(MODELS / "double_folded.toml"))
    assert st.active == ("crank",)
    (g,) = st.groups
    assert g.augmented and g.name == "RRRP" and g.cls == 2
    assert set(g.internal) == {"C", "D"} and set(g.external) == {"B", "E"}


def test_nipper_sequence(nipper):
    mech, a, b = nipper
    assert sequence(a) == GOLDEN_NIPPER
    assert sequence(b) == GOLDEN_NIPPER
    t_close = a.events[2].t
    t_open = a.events[3].t
    assert 5.0 < t_close < 5.6 and 9.0 < t_open < 9.6  # docs/paper_models.md: 5.3 s and 9.3 s
    for ea, eb in zip(a.events[1:], b.events[1:], strict=True):
        assert 0.0 <= eb.t - ea.t < 0.01 + 1e-12
    # G on its collar while open, sliding against the spring while closed
    G = a.joint("G").position
    closed = (a.t > t_close) & (a.t < t_open)
    open_ = (a.t < t_close) | (a.t > t_open + 1e-9)
    assert np.max(np.abs(G[open_] - 0.17237)) <= 1e-9
    assert np.max(G[closed]) - 0.17237 > 2e-3
    # the jaw angle stays on its stop while closed
    C = a.joint("C").position
    assert np.max(np.abs(C[closed] + 1.4671237692264283)) <= 1e-9


def test_nipper_structure():
    st = cd.structure(cd.load(MODELS / "nipper_swing.toml"))
    assert st.active == ("crank9",)
    rpr, aug = st.groups
    assert rpr.name == "RPR" and not rpr.augmented and set(rpr.bodies) == {"slider8", "link1"}
    assert aug.augmented and aug.cls == 3
    assert set(aug.bodies) == {"lower2", "upper4", "link3", "slider5", "rod6"}
    assert set(aug.metamorphic) == {"C", "G"} and "C" in aug.internal
    assert sorted(aug.name.replace("-", "")) == sorted("RPRRRRR")
    text = str(st)
    assert "class III" in text and "G (internal, force constraint)" in text


def test_double_folded_against_minimal_coordinate_model():
    """An independent minimal-coordinate derivation (validation/minimal_double_folded.py,
    Kane's equations in the slider position, DOP853 at rtol 1e-11, stop release by brentq):
    switching times within 1e-9 s and driving torque within 1e-8 N m of IDA at rtol 1e-10."""
    import importlib.util

    path = MODELS.parent / "validation" / "minimal_double_folded.py"
    spec = importlib.util.spec_from_file_location("minimal_double_folded", path)
    mdf = importlib.util.module_from_spec(spec)
    import sys

    sys.modules[spec.name] = mdf  # dataclasses look their module up there
    spec.loader.exec_module(mdf)
    mech = cd.load(MODELS / "double_folded.toml")
    res = cd.run_dae(mech, 10.0, rtol=1e-10, atol=1e-12, output_dt=0.05)
    grid = np.round(np.arange(0, 201) * 0.05, 10)
    out = mdf.simulate(mech, 10.0, rtol=1e-11, t_eval=grid)
    assert [k for k, _ in out["switches"]] == [e.kind for e in res.events]
    for (_, t_min), e in zip(out["switches"], res.events, strict=True):
        assert abs(t_min - e.t) <= 1e-9
    tau = res.resample(out["t"], res.driver("A").effort)
    far = np.ones(out["t"].size, bool)
    for e in res.events:
        far &= np.abs(out["t"] - e.t) > 0.02
    assert np.max(np.abs(out["torque"] - tau)[far]) <= 1e-8
