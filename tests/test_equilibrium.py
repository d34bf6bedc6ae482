"""Static-equilibrium start against closed forms, and the paper's double-folded mechanism
with its start-up jump at D removed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

import cmm_dae as cd

MODELS = Path(__file__).resolve().parent.parent / "models"
M, RC, K, REST0, TH0 = 0.4, 0.15, 2.0, 0.0, 0.3


def sprung_rod(equilibrium) -> cd.Mechanism:
    rod = cd.Body("rod", M, 3e-3, (RC, 0.0), {"O": (0.0, 0.0)}, guess=(0, 0, TH0))
    joint = cd.Joint("O", "revolute", "ground.O", "rod.O", spring=cd.Spring(K, REST0))
    return cd.Mechanism("sprung rod", [rod], [joint], ground={"O": (0, 0)},
                        initial=cd.Initial({"O": TH0}, {"O": 0.0}, equilibrium))


def test_spring_rest_from_statics():
    """k (rest - th0) = m g r cos th0: the spring holds the rod's weight at th0."""
    res = cd.run_dae(sprung_rod(["joints.O.spring.rest"]), 1.0)
    rest = res.meta["equilibrium"]["joints.O.spring.rest"]
    assert rest == pytest.approx(TH0 + M * 9.81 * RC * math.cos(TH0) / K, rel=1e-12)
    assert np.max(np.abs(res.joint("O").position - TH0)) <= 1e-9  # it stays there


def test_equilibrium_position():
    """k (th - rest) + m g r cos th = 0 solved for the coordinate itself."""
    res = cd.run_dae(sprung_rod("position"), 1.0)
    th = brentq(lambda x: K * (x - REST0) + M * 9.81 * RC * math.cos(x), -2.0, 2.0,
                xtol=1e-15)
    assert res.meta["equilibrium"]["initial.joints.O"] == pytest.approx(th, abs=1e-12)
    assert res.joint("O").position[0] == pytest.approx(th, abs=1e-12)
    assert np.max(np.abs(res.joint("O").position - th)) <= 1e-9


def test_double_folded_start_up_jump_removed():
    plain = cd.run_dae(cd.load(MODELS / "double_folded.toml"), 3.0)
    pre = cd.run_dae(cd.load(MODELS / "double_folded_preloaded.toml"), 3.0)
    early = plain.t <= 0.3

    def jump(r):
        d = r.joint("D").position[early]
        return float(np.max(np.abs(d - d[0])))

    # the static analysis leaves a smooth drift (measured 3.7e-5 rad); zeroing the named
    # coordinate's acceleration instead left a 9.2e-4 rad swing
    assert jump(plain) > 0.05 and jump(pre) < 1e-4
    assert abs(plain.joint("E").acceleration[0]) > 1.0
    assert [e.kind for e in pre.events] == ["limit"]


def test_static_analysis_does_not_depend_on_the_named_coordinate():
    """The preloaded double-folded mechanism started from the same state, named by E (the
    file) or by D: the same spring rest, and no acceleration along the free motion."""
    from scipy.linalg import null_space

    from cmm_dae.hybrid.policy import HybridState
    from cmm_dae.hybrid.start import start_state

    by_e = cd.load(MODELS / "double_folded_preloaded.toml")
    first = cd.run_dae(by_e, 0.01)
    d0 = float(first.joint("D").position[0])
    by_d = by_e.replace(initial=cd.Initial({"D": d0}, {"D": 0.0},
                                           ["joints.D.spring.rest"]))
    second = cd.run_dae(by_d, 0.01)
    rest_e = first.meta["equilibrium"]["joints.D.spring.rest"]
    rest_d = second.meta["equilibrium"]["joints.D.spring.rest"]
    assert rest_d == pytest.approx(rest_e, abs=1e-10)
    solved = cd.with_params(by_e.replace(initial=cd.Initial({"E": 0.17763}, {"D": 0.0})),
                            {"joints.D.spring.rest": rest_e})
    model = cd.Model(solved)
    hs = HybridState(model)
    q, v, _ = start_state(model, hs)
    a, _, _ = model.kkt(q, v, 0.0, hs.p)
    N = null_space(model.constraints(q, 0.0, hs.p).Phi_q[model.active_rows(hs.p)])
    # the free motion does not accelerate at the start (at rest this is N^T Q = 0, the
    # static analysis: the sprung rod's closed form above)
    assert N.shape[1] == 1 and abs(float(N[:, 0] @ a)) <= 1e-10


def test_bad_equilibrium_requests():
    with pytest.raises(cd.ModelError, match=r"\[initial\] equilibrium: 2 parameter\(s\) for 1 "
                       r"free coordinate\(s\) \(O\)"):
        sprung_rod(["joints.O.spring.rest", "bodies.rod.mass"])
    with pytest.raises(cd.ModelError, match=r"\[initial\] equilibrium: .*joints\.Q\.spring\."
                       r"rest: not a parameter"):
        cd.run_dae(sprung_rod(["joints.Q.spring.rest"]), 0.1)
    with pytest.raises(cd.ModelError, match=r"expected \"position\" or a list"):
        sprung_rod("statics")
    # spring and weight both turn the rod down at th0: no positive mass balances them
    with pytest.raises(cd.ModelError, match=r"no static equilibrium found for bodies\.rod\."
                       r"mass \(acceleration residual [0-9.]+ after"):
        cd.run_dae(sprung_rod(["bodies.rod.mass"]), 0.1)
    # a huge inertia makes every acceleration small: a run-off, not an equilibrium
    with pytest.raises(cd.ModelError, match=r"bodies\.rod\.inertia: the search ran off"):
        cd.run_dae(sprung_rod(["bodies.rod.inertia"]), 0.1)
