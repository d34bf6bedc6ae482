"""A mechanism's numbers as inputs of its compiled functions (equations/lifting.py): the
lifted functions compute the original's numbers to the last bit, the variants of a
mechanism share them (and so one compiled library), and a variant's compiled run is its
own (the Python path's, not the base's)."""

from __future__ import annotations

import os

import casadi as ca
import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae.equations import compiled
from cmm_dae.equations.codegen import Buffered
from cmm_dae.equations.lifting import lift, wrap
from cmm_dae.integrators import cbuild

pytestmark = pytest.mark.timeout(180)


def _functions(model: cd.Model) -> dict[str, ca.Function]:
    """Every function the compiled paths lift: IDA's residual and Jacobian and the
    post-processing library's."""
    return {"res": model.ida.res_sx, "jac": model.ida.jac_sparse_fn,
            **compiled._functions(model), **compiled._singles(model)}


def _args(f: ca.Function, rng: np.random.Generator) -> list[np.ndarray]:
    return [rng.uniform(-1.0, 1.0, f.nnz_in(i)) for i in range(f.n_in())]


def _values(out) -> list[np.ndarray]:
    outs = out if isinstance(out, list | tuple) else [out]
    return [np.asarray(o.full()) for o in outs]


@pytest.mark.parametrize("name", ["double_folded", "cam_valve_train", "slotted_link"])
def test_lifted_functions_give_the_same_numbers_to_the_last_bit(name):
    model = cd.Model(cd.load(cd.example(name)))
    rng = np.random.default_rng(7)
    for key, f in _functions(model).items():
        args = _args(f, rng)
        want = _values(f(*args))
        trailing = lift(f)  # a new input w
        got = _values(trailing.fn(*args, trailing.values))
        assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(want, got,
                                                                        strict=True)), key
        # into an input (IDA's p), the constants after a gap another function fills
        p = f.n_in() - 1
        if f.size2_in(p) == 1:
            inner = lift(f, p, f.nnz_in(p) + 3)
            pw = np.concatenate([args[p], [np.nan] * 3, inner.values])
            got = _values(inner.fn(*args[:p], pw))
            assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(want, got,
                                                                            strict=True)), key
        assert trailing.values.size == sum(f.instruction_id(k) == ca.OP_CONST
                                           for k in range(f.n_instructions()))


def test_variants_share_their_lifted_functions():
    mech = cd.load(cd.example("double_folded"))
    k = mech.joints["D"].spring.stiffness
    variants = [mech, cd.with_params(mech, {"joints.D.spring.stiffness": 0.7 * k}),
                cd.with_params(mech, {"bodies.crank.points.B.x": 0.083}),
                cd.with_params(mech, {"bodies.coupler.mass": 1.7, "gravity.y": -9.7})]
    models = [cd.Model(m) for m in variants]
    lifted = [{n: lift(f) for n, f in _functions(model).items()} for model in models]
    for model, other in zip(models[1:], lifted[1:], strict=True):
        assert all(other[n].fn.serialize() == lifted[0][n].fn.serialize() for n in other)
        # the mechanism's numbers are inputs at p's tail (equations.values), not constants:
        # the same constants, each model its own values
        assert all(np.array_equal(other[n].values, lifted[0][n].values) for n in other)
        assert model.value_paths == models[0].value_paths
        assert not np.array_equal(model.w0, models[0].w0)
    # a change of structure (a spring where there was none) is another function
    bare = cd.Model(cd.with_params(mech, {"joints.B.spring.stiffness": 2.0}))
    assert lift(bare.ida.res_sx).fn.serialize() != lifted[0]["res"].fn.serialize()


def test_lifting_refuses_what_it_cannot_lift():
    x = ca.MX.sym("x", 2)
    with pytest.raises(TypeError, match="only SX functions"):
        lift(ca.Function("f", [x], [2.0 * x]))
    y = ca.SX.sym("y", 3)
    f = ca.Function("g", [y], [3.0 * y])
    with pytest.raises(ValueError, match="overlaps"):
        lift(f, 0, 2)
    with pytest.raises(ValueError, match="not a column vector"):
        m = ca.SX.sym("m", 2, 2)
        lift(ca.Function("h", [m], [1.5 * m[0]]), 0)


def test_a_wrapped_function_and_a_bound_buffer_take_the_original_inputs():
    y = ca.SX.sym("y", 2)
    f = ca.Function("g", [y], [ca.vertcat(3.25 * y[0] + 1.5, y[1] ** 2 / 7.0)])
    x = lift(f)
    w = wrap(x.fn, x.values)
    arg = np.array([0.3, -1.1])
    want = np.asarray(f(arg).full()).ravel()
    assert np.array_equal(np.asarray(w(arg).full()).ravel(), want)
    assert np.array_equal(np.asarray(w.map(3)(np.tile(arg[:, None], 3)).full())[:, 2], want)
    assert np.array_equal(Buffered(x.fn, fixed=x.values)(arg)[0], want)


@pytest.mark.skipif(cbuild.c_compiler() is None, reason="needs a C compiler")
def test_variants_run_compiled_on_the_base_build_and_give_their_own_results(tmp_path,
                                                                              monkeypatch):
    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    mech = cd.load(cd.example("double_folded"))
    base = cd.run_dae(mech, 10.0, compiled=True)
    built = sorted(os.listdir(tmp_path))
    assert len(built) >= 6  # the driver, the segment, post-processing, event functions
    k = mech.joints["D"].spring.stiffness
    for values in ({"joints.D.spring.stiffness": 0.6 * k}, {"bodies.crank.points.B.x": 0.084},
                   {"joints.E.limits.upper": 0.245}):
        var = cd.with_params(mech, values)
        c = cd.run_dae(var, 10.0, compiled=True)
        py = cd.run_dae(var, 10.0, compiled=False)
        assert c.meta["compiled"] and not py.meta["compiled"]
        assert [(e.kind, e.joint) for e in c.events] == [(e.kind, e.joint) for e in py.events]
        assert max(abs(a.t - b.t) for a, b in zip(c.events, py.events, strict=True)) < 1e-9
        assert np.max(np.abs(c.data["q"] - py.data["q"])) < 1e-9
        # its own numbers, not the base's: the switching moves
        assert max(abs(a.t - b.t) for a, b in zip(c.events, base.events, strict=True)) > 1e-3
    assert sorted(os.listdir(tmp_path)) == built  # nothing built again
