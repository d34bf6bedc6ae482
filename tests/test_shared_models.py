"""One model per mechanism structure: the mechanism's values are inputs of its functions
(``equations.values``), so a parameter variant runs on its structure's model, built once.

The reference is the variant built from scratch (every kept model forgotten): its own
functions, holding nothing of the base's. A value the builder folded into a function
instead of reading it from p would run the variant with the base's number and differ."""

from __future__ import annotations

import os

import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae.equations.values import structure_key, value_paths
from cmm_dae.simulation import cache

pytestmark = pytest.mark.timeout(240)


def _runs(base, variant, t_end, **kw):
    """The variant run on the base's model (the base run first), and built anew."""
    cache.clear()
    cd.run_dae(base, t_end, **kw)
    shared = cd.run_dae(variant, t_end, **kw)
    cache.clear()
    fresh = cd.run_dae(variant, t_end, **kw)
    cache.clear()
    return shared, fresh


def _same(a, b):
    assert [(e.kind, e.joint) for e in a.events] == [(e.kind, e.joint) for e in b.events]
    assert [e.t for e in a.events] == [e.t for e in b.events]
    for key in ("q", "v", "jforce", "effort"):
        assert np.array_equal(np.asarray(a.data[key]), np.asarray(b.data[key])), key


@pytest.mark.parametrize("model, values", [
    ("double_folded", {"joints.D.spring.stiffness": 0.0033, "bodies.crank.points.B.x": 0.083,
                       "bodies.slider.mass": 0.3, "gravity.y": -9.7, "drivers.A.speed": 1.3}),
    ("double_folded_pin_friction", {"joints.D.friction.mu_kinetic": 0.17,
                                    "bodies.link3.inertia": 2.2e-4}),
    ("nipper_cutting", {"joints.G.spring.stiffness": 2100.0, "bodies.upper4.points.F.y": -0.056}),
    ("carton_fold", {"bodies.L3.mass": 0.031, "drivers.A.speed": 0.9}),
])
def test_a_variant_runs_on_its_structures_model_as_if_built_anew(model, values):
    """Each value changed alone, then all at once: the variant's model shares the base's
    functions (``shared``), and its run equals the fresh build's to the last bit
    (events, positions, velocities, joint forces, driver efforts)."""
    base = cd.load(cd.example(model))
    for case in [*({k: v} for k, v in values.items()), values]:
        var = cd.with_params(base, case)
        assert structure_key(var, value_paths(var)) == structure_key(base, value_paths(base))
        shared, fresh = _runs(base, var, 1.5, compiled=False)
        assert shared.success
        _same(shared, fresh)
    # and the variant's numbers are its own: the change shows in the run
    plain = cd.run_dae(base, 1.5, compiled=False)
    assert not np.array_equal(plain.data["q"], shared.data["q"])


def test_variants_share_the_model_and_its_compiled_libraries(tmp_path, monkeypatch):
    """Eight stiffness values and round ones (0.5, 1, 2, 3 times, a driver speed of -1)
    run on the base's model object's functions, in C, adding no library to the cache;
    C and Python give the same events (1e-12 s) and positions (1e-12 m)."""
    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    cache.clear()
    base = cd.load(cd.example("double_folded"))
    first = cd.run_dae(base, 3.0, compiled=True)
    assert first.meta["compiled"]
    kept = cd.run_dae(base, 0.1)  # (the base's model, kept by the run)
    assert kept.success
    files = sorted(os.listdir(tmp_path))
    k = base.joints["D"].spring.stiffness
    cases = [{"joints.D.spring.stiffness": x} for x in
             [*(k * np.linspace(0.6, 1.4, 8)), 0.5 * k, 1.0, 2.0, 3.0]]
    cases.append({"drivers.A.speed": -1.0})
    shared = cache._structures[(cache.structure_of(base), ())]
    for case in cases:
        var = cd.with_params(base, case)
        model = cache.built(var)
        assert model.shared is shared and model.res_fn is shared.res_fn
        c = cd.run_dae(var, 3.0)
        assert c.meta["compiled"]
        py = cd.run_dae(var, 3.0, compiled=False)
        assert [e.kind for e in c.events] == [e.kind for e in py.events]
        assert max((abs(a.t - b.t) for a, b in zip(c.events, py.events, strict=True)),
                   default=0.0) <= 1e-12
        assert np.max(np.abs(c.data["q"] - py.data["q"])) <= 1e-12
    assert sorted(os.listdir(tmp_path)) == files


def test_a_change_of_structure_builds_its_own_model():
    """A stop's position (the event policy's number), a zero made nonzero (a term the
    equations did not have) and a spring where there was none are other structures:
    other keys, their own models, their own numbers."""
    base = cd.load(cd.example("double_folded"))
    key = structure_key(base, value_paths(base))
    for case in ({"joints.E.limits.upper": 0.25}, {"bodies.crank.points.B.y": 0.001},
                 {"joints.B.spring.stiffness": 2.0}):
        var = cd.with_params(base, case)
        assert structure_key(var, value_paths(var)) != key
        shared, fresh = _runs(base, var, 3.0, compiled=False)
        _same(shared, fresh)
    assert "joints.E.limits.upper" not in value_paths(base)
    assert "bodies.crank.points.B.y" not in value_paths(base)  # (zero at the base)


def test_a_variant_of_another_structure_is_refused():
    """``Model.variant`` of a mechanism whose structure differs (gravity along x where
    the model's has none, a stop moved) raises, naming the mechanism, instead of running
    it with the model's numbers; one that differs in values only runs as its own."""
    base = cd.load(cd.example("double_folded"))
    model = cd.Model(base)
    for case in ({"gravity.x": 1.0}, {"joints.E.limits.upper": 0.25}):
        with pytest.raises(cd.ModelError, match="has another structure than the model's"):
            model.variant(cd.with_params(base, case))
    var = cd.with_params(base, {"gravity.y": -9.0})
    cache.clear()
    _same(cd.run_dae(var, 3.0, model=model.variant(var), compiled=False),
          cd.run_dae(var, 3.0, compiled=False))
