"""The faster paths give the numbers of the plain ones.

- IDA's event function built symbolically from the policy's ``event_values``, with lock
  forces read from IDA's multipliers away from their threshold, against the KKT value at
  every evaluation (the version before the change);
- the sparse linear solver against the dense one on a chain of four-bar loops;
- the banded Schur complement of large mechanisms against the dense KKT solve;
- the sparse LU of single KKT solves against the dense one and the one-DOF reduction;
- the iterative algorithm's compiled step against its Python stepper.
Tolerances are stated at each assertion.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import cmm_dae as cd
from cmm_dae.core.errors import ModelError
from cmm_dae.description.library import four_bar_chain
from cmm_dae.equations import banded
from cmm_dae.integrators import csegment, ida, iterative
from cmm_dae.results import post


def test_lean_lock_force_events_locate_the_same_roots(monkeypatch):
    """Lock and release of the double-folded mechanism: with the KKT solve at every event
    evaluation (PUSH_MARGIN huge) the same event times to 1e-12 s."""
    mech = cd.load(cd.example("double_folded"))
    model = cd.Model(mech)
    lean = cd.run_dae(mech, 10.0, model=model)
    calls = []
    exact = ida.IdaIntegrator._exact_events

    def counting(self, *a):
        calls.append(1)
        return exact(self, *a)

    monkeypatch.setattr(ida.IdaIntegrator, "_exact_events", counting)
    monkeypatch.setattr(ida, "PUSH_MARGIN", 1e300)
    full = cd.run_dae(mech, 10.0, model=model)
    assert [(e.kind, e.joint) for e in lean.events] == [(e.kind, e.joint) for e in full.events]
    assert max(abs(a.t - b.t) for a, b in zip(lean.events, full.events, strict=True)) <= 1e-12
    assert np.max(np.abs(lean.driver("A").effort - full.driver("A").effort)) <= 1e-9
    # while locked, every evaluation solved the KKT system in the reference run
    assert len(calls) > 500


def test_sparse_linear_solver_matches_dense():
    """Chain of 6 loops (74 unknowns): sparse LU (SuperLU_MT) vs dense LU, rtol 1e-10:
    positions agree to 1e-8 m (the two take slightly different steps)."""
    mech = four_bar_chain(6)
    model = cd.Model(mech)
    dense = cd.run_dae(mech, 0.5, model=model, rtol=1e-10, atol=1e-12, linsolver="dense")
    sparse = cd.run_dae(mech, 0.5, model=model, rtol=1e-10, atol=1e-12, linsolver="sparse")
    assert sparse.success and dense.success
    assert np.max(np.abs(sparse.data["q"] - dense.data["q"])) <= 1e-8
    assert np.max(np.abs(sparse.data["lam"] - dense.data["lam"])) <= 1e-6 * np.max(
        np.abs(dense.data["lam"]))


def test_bad_linsolver_is_a_model_error():
    with pytest.raises(ModelError, match=r"\[run\] linsolver: expected 'auto', 'dense' or "
                       r"'sparse', got 'superlu'"):
        cd.run_dae(cd.load(cd.example("pendulum_stop")), 0.1, linsolver="superlu")


def test_banded_schur_complement_solves_the_kkt_system():
    """Chain of 24 loops (146 rows): the banded path is taken (from Phi_q's nonzeros) and
    its accelerations and multipliers satisfy the whole KKT system to round-off (relative
    residual 1e-12); they equal the dense Schur complement's to 1e-10 relative."""
    mech = four_bar_chain(24)
    model = cd.Model(mech)
    st = banded.for_model(model)
    assert st is not None and st.bw <= 0.125 * model.m
    res = cd.run_dae(mech, 0.05, model=model)
    t, q, v = res.t, res.data["q"], res.data["v"]
    P = np.tile(model.params(), (t.size, 1))
    a, lam = post.batch_kkt(model, t, q, v, P)
    for i in (0, t.size // 2, t.size - 1):
        Pq, Qf, gamma = (np.asarray(x) for x in model.kkt_fn(q[i], v[i], t[i], P[i]))
        Qf, gamma = Qf.ravel(), gamma.ravel()
        r1 = model.mass * a[i] + Pq.T @ lam[i] - Qf
        r2 = Pq @ a[i] - gamma
        assert np.max(np.abs(r1)) <= 1e-12 * np.max(np.abs(Qf))
        assert np.max(np.abs(r2)) <= 1e-12 * max(np.max(np.abs(gamma)), 1.0)
    saved = banded._cache[model]
    banded._cache[model] = None  # force the dense Schur complement
    try:
        _, lam_d = post.batch_kkt(model, t, q, v, P)
    finally:
        banded._cache[model] = saved
    assert np.max(np.abs(lam - lam_d)) <= 1e-10 * np.max(np.abs(lam_d))


def test_sparse_kkt_solve_matches_dense_and_the_one_dof_reduction():
    """A02 with 20 loops (KKT size 245, sparse from 160; 4 loops stay dense): the
    accelerations and multipliers of the sparse LU equal the dense LU's to 1e-13
    relative (measured 1.4e-15, 4.1e-15), the cranks' angular acceleration equals the
    parallelogram's one-DOF value -c cos(theta) / I to 1e-12 relative, and at the
    singular position itself both say the KKT matrix is singular."""
    from cmm_dae.description import iftomm

    assert not cd.Model(iftomm.a02_four_bar(4)).kkt_sparse
    n, theta = 20, -2.0
    model = cd.Model(iftomm.a02_four_bar(n))
    p = model.params()
    assert model.kkt_sparse and model.nq + model.m == 245

    def state(th):  # every crank at th, couplers level, at rest
        q = [[i + 0.5 * np.cos(th), 0.5 * np.sin(th), th] for i in range(n + 1)]
        q += [[i - 0.5 + np.cos(th), np.sin(th), 0.0] for i in range(1, n + 1)]
        return np.ravel(q), np.zeros(3 * (2 * n + 1))

    q, v = state(theta)
    a_s, lam_s, _ = model.kkt(q, v, 0.0, p)
    model.kkt_sparse = False
    a_d, lam_d, _ = model.kkt(q, v, 0.0, p)
    assert np.max(np.abs(a_s - a_d)) <= 1e-13 * np.max(np.abs(a_d))
    assert np.max(np.abs(lam_s - lam_d)) <= 1e-13 * np.max(np.abs(lam_d))
    inertia, c = (n + 1) / 3 + n, 9.81 * ((n + 1) / 2 + n)
    assert a_s[2:3 * (n + 1):3] == pytest.approx(-c * np.cos(theta) / inertia, rel=1e-12)
    q0, v0 = state(0.0)
    for sparse in (True, False):
        model.kkt_sparse = sparse
        with pytest.raises(np.linalg.LinAlgError, match="singular KKT matrix"):
            model.kkt(q0, v0, 0.0, p)


@pytest.mark.parametrize("name,t_end", [("double_folded", 10.0), ("stick_slip_block", 3.0),
                                        ("pendulum_stop", 2.0), ("nipper_cutting", 2.0)])
def test_iterative_compiled_step_matches_python_stepper(name, t_end, monkeypatch):
    """Same events at the same grid times, states to 1e-12, forces to 1e-9 relative."""
    mech = cd.load(cd.example(name))
    model = cd.Model(mech)
    fast = cd.run_iterative(mech, t_end, dt=1e-3, model=model)
    monkeypatch.setattr(iterative.IterativeIntegrator, "_compiled_step", lambda self: None)
    slow = cd.run_iterative(mech, t_end, dt=1e-3, model=model)
    assert [(e.kind, e.joint, e.t) for e in fast.events] == [
        (e.kind, e.joint, e.t) for e in slow.events]
    assert np.max(np.abs(fast.data["q"] - slow.data["q"])) <= 1e-12
    assert np.max(np.abs(fast.data["lam"] - slow.data["lam"])) <= 1e-9 * max(
        np.max(np.abs(slow.data["lam"])), 1.0)


def test_bench_cli_reports_ratios(capsys):
    from cmm_dae.cli import main

    assert main(["bench", "pendulum_stop", "--t-end", "0.2", "--repeat", "1"]) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.startswith("pendulum_stop")]
    methods = [" ".join(r[1:3]) if r[2] == "compiled" else r[1] for r in rows]
    assert methods[0] == "IDA" and methods[-1] == "iterative"
    assert float(rows[0][6]) == 1.0  # IDA against itself
    assert main(["bench", "pendulum_stop", "--repeat", "0"]) == 2


def test_run_cli_compiled_and_linsolver(capsys, tmp_path, monkeypatch):
    """`cmm-dae run --compiled --linsolver sparse` runs (the saved Result says how), and a
    linear solver that does not exist is refused by the parser."""
    from cmm_dae.cli import main

    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "r.npz"
    assert main(["run", "pendulum_stop", "--t-end", "0.3", "--compiled", "--linsolver",
                 "sparse", "--save", str(out)]) == 0
    res = cd.load_result(out)
    assert res.meta["linsolver"] == "sparse"
    assert res.meta["compiled"] == (csegment.available() is None)  # C where it can be built
    assert len(res.events) == 1
    with pytest.raises(SystemExit) as exc:
        main(["run", "pendulum_stop", "--linsolver", "klu"])
    assert exc.value.code == 2
    assert "invalid choice: 'klu'" in capsys.readouterr().err


def test_clean_fallback_without_compiler(tmp_path):
    """compiled=True without a working compiler (here or on any machine): one warning,
    then the Python path with the same numbers."""
    code = textwrap.dedent("""
        import warnings
        import cmm_dae as cd
        mech = cd.load(cd.example("pendulum_stop"))
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            a = cd.run_dae(mech, 1.0, compiled=True)
            b = cd.run_dae(mech, 1.0, compiled=True)
        print(len(w), str(w[0].message))
        print(a.meta["compiled"], b.meta["compiled"])
        print(a.events[0].t == cd.run_dae(mech, 1.0).events[0].t, b.events[0].t == a.events[0].t)
    """)
    env = dict(os.environ, CC=str(tmp_path / "no-such-compiler"),
               CMM_DAE_CACHE=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=300, check=True).stdout.splitlines()
    out = [line for line in out if line and not line.startswith("[IDA")]
    assert out[0].startswith("1 compiled segment not used")
    assert "no-such-compiler" in out[0] or "compiler" in out[0]
    assert out[1] == "False False"  # the Python path ran
    assert out[2] == "True True"


def test_sparse_screen_matches_the_dense_one(monkeypatch):
    """The stepped-over screen of a large mechanism takes its measure from Phi_q's
    nonzeros (banded Cholesky of all samples' Gram matrices in one block-diagonal band):
    log det(J J^T) the same as the dense path (measured 7e-14 on a chain of 32 loops);
    on this chain, whose rows are all active, log det(J M^-1 J^T) (the Schur complement
    post-processing factors), the same as numpy's slogdet of that matrix formed densely
    from the model's Phi_q (to 1e-10 of a log determinant near 171; measured 2.3e-13).
    The start's
    assembly is computed once per model."""
    from cmm_dae.simulation import measure

    mech = four_bar_chain(32)
    model = cd.Model(mech)
    res = cd.run_dae(mech, 0.5, model=model)
    assert model.kkt_sparse
    p = model.params()
    act = model.active_rows(p)
    keep = np.r_[True, np.diff(res.t) > 0]
    t, q = res.t[keep], res.data["q"][keep]
    assert measure.weighted(model, act)
    weighted = measure.log_gram(model, p, t, q, act)
    dense_w = np.array([np.linalg.slogdet((J / model.mass) @ J.T)[1] for J in (
        model.constraints(qi, float(ti), p).Phi_q[act] for ti, qi in zip(t, q, strict=True))])
    assert np.max(np.abs(weighted - dense_w)) <= 1e-10
    with monkeypatch.context() as m:
        m.setattr(measure, "weighted", lambda *a: False)
        sparse = measure.log_gram(model, p, t, q, act)
        # the dense path: no band, not sparse
        m.setattr(model, "kkt_sparse", False)
        m.setattr(measure, "gram_band", lambda *a: None)
        dense = measure.log_gram(model, p, t, q, act)
    assert np.max(np.abs(sparse - dense)) <= 1e-10

    def starts() -> int:  # the start's values the model keeps (core.memo.once)
        return sum(1 for key in model._once if key[0] == "start")

    cached = starts()
    again = cd.run_dae(mech, 0.5, model=model)
    assert cached and starts() == cached  # nothing assembled anew
    assert np.array_equal(again.data["q"], res.data["q"])


def test_a_mechanism_run_again_reuses_its_model():
    """run_dae(mech) without model= keeps the model of the mechanisms it ran last: the same
    object run again reuses it (and gives the same numbers); another object, of the same
    content or with a parameter changed, gets its own."""
    from cmm_dae.simulation import cache

    cache.clear()
    mech = four_bar_chain(2)
    built = []
    build = cd.Model
    a = cd.run_dae(mech, 0.05)
    first = cache.model_of(mech, lambda m: built.append(m) or build(m))
    assert built == []  # kept from the run
    b = cd.run_dae(mech, 0.05)
    assert cache.model_of(mech, lambda m: built.append(m) or build(m)) is first
    assert built == [] and np.array_equal(a.data["q"], b.data["q"])
    other = four_bar_chain(2)  # equal content, another object
    assert cache.model_of(other, lambda m: built.append(m) or build(m)) is not first
    heavier = cd.with_params(mech, {"bodies.r0.mass": 2.0})
    assert cache.model_of(heavier, lambda m: built.append(m) or build(m)) is not first
    assert len(built) == 2
    for _ in range(cache.MODELS_KEPT + 1):  # the least recently run goes first
        cd.run_dae(four_bar_chain(1), 0.01)
    assert len(cache._models) == cache.MODELS_KEPT


def test_a_mechanism_changed_in_place_gets_a_new_model():
    """What a user can still change in place in a frozen Mechanism, the mutable values
    handed to it (a load's table given as lists, an array), is checked at every run: the
    same content reuses the model, a changed value builds a new one; a mechanism of
    immutable values alone has nothing to check."""
    from cmm_dae.simulation import cache

    times, values = [0.0, 0.5, 1.0], np.array([0.0, 1.0, 0.0])
    base = four_bar_chain(1)
    assert cache._mutable(base, []) == []
    load = cd.Load("push", cd.Law("table", times=times, values=values),
                   joint=next(iter(base.joints)))
    mech = cd.Mechanism(base.name, base.bodies, base.joints, base.ground, base.drivers,
                        base.initial, base.gravity, loads=[load])
    built = []

    def build(m):
        built.append(m)
        return cd.Model(m)

    cache.clear()
    first = cache.model_of(mech, build)
    assert cache.model_of(mech, build) is first and len(built) == 1
    values[1] = 2.0  # in place, in the middle of the array
    assert cache.model_of(mech, build) is not first and len(built) == 2
    second = cache.model_of(mech, build)
    times[2] = 1.2  # the list
    assert len(cache._mutable(mech, [])) == 2
    assert cache.model_of(mech, build) is not second and len(built) == 3


def test_block_diagonal_band_factors_are_each_states_own():
    """log det(J J^T) of many states from one banded Cholesky of their block-diagonal
    matrix: bit for bit what one LAPACK call per state on its block gives, also where
    states in the middle are singular (-inf there, the states after them factored on),
    and a dense log det of J J^T to 1e-12; the multipliers of many
    samples from one banded Cholesky, and from the LU that takes over where rows are free
    (one to four states' blocks, summed one by one, bit for bit those of many):
    those of a dense solve of each sample's Schur complement to 1e-12 of their largest.
    A02 with 8 loops, its run's samples."""
    from scipy.linalg.lapack import dpbtrf

    from cmm_dae.description import iftomm
    from cmm_dae.equations import kinematics

    mech = iftomm.a02_four_bar(8)
    model = cd.Model(mech)
    res = cd.run_dae(mech, 2.0, rtol=1e-3, model=model)
    p, n = model.params(), res.t.size
    act = model.active_rows(p)
    fz = model.mapped("phi_q_nz_fn", n)
    nz = fz(res.data["q"].T, res.t, np.tile(p[:, None], (1, n)))[0].reshape(-1, n)
    nz[:, [7, 20, n - 1]] = 0.0  # three singular states, the last one among them
    band = kinematics.gram_band(model, act)
    rows, cols = (np.asarray(x, int) for x in model.phi_q_pattern.get_triplet())
    blocks = banded.lower_blocks(band, nz[kinematics._csc_index(model, act)])
    one_by_one, dense, conds = [], [], []
    for i in range(n):
        c, info = dpbtrf(blocks[:, i * band.m:(i + 1) * band.m], lower=1)
        one_by_one.append(2.0 * float(np.sum(np.log(c[0]))) if info == 0 else -np.inf)
        J = np.zeros((model.m, model.nq))
        J[rows, cols] = nz[:, i]  # (the nonzeros in CSC order, as get_triplet's)
        sign, logdet = np.linalg.slogdet(J[act] @ J[act].T)
        dense.append(logdet if sign > 0 else -np.inf)
        conds.append(np.linalg.cond(J[act] @ J[act].T) if sign > 0 else np.inf)
    got = kinematics.log_gram(model, act, nz)
    assert np.array_equal(got, np.array(one_by_one))
    for k in (1, 2, 4):  # a few states summed one by one: the same bits
        assert np.array_equal(banded.lower_blocks(band, nz[kinematics._csc_index(
            model, act)][:, 30:30 + k]), blocks[:, 30 * band.m:(30 + k) * band.m])
    assert np.isneginf(got[[7, 20, n - 1]]).all() and np.isfinite(got[8])
    ok, dense = np.isfinite(got), np.array(dense)
    assert np.array_equal(ok, np.isfinite(dense))
    # to round-off where the Gram matrix is well conditioned (log det above 0); next to
    # the two singular positions (log det down to -93) round-off grows as its condition
    # number: within 1e-14 of it (measured 1.6e-9 and 6.6e-7 at two runs' samples, whose
    # nearest to the singular positions differ; at most 1.2e-16 and 1.4e-16 of the condition)
    far = ok & (got > 0.0)
    assert far.sum() > n // 2
    assert np.max(np.abs(got[far] - dense[far])) <= 1e-12 * np.max(np.abs(got[far]))
    assert np.all(np.abs(got[ok] - dense[ok]) <= 1e-14 * np.array(conds)[ok])

    st = banded.for_model(model)
    assert st is not None  # 50 rows: banded from 32 on
    t, q, v = res.t, res.data["q"], res.data["v"]
    P = np.tile(p, (n, 1))
    vals, Qf, gamma = (np.asarray(x).reshape(-1, n) for x in model.mapped(
        "kkt_nz_fn", n)(q.T, v.T, t, P.T))
    for free_row in (None, 3):  # every row active (Cholesky); one row free (LU)
        free = np.zeros((model.m, n))
        if free_row is not None:
            free[free_row] = 1.0
        lam = banded.banded_solve(st, vals, model.mass, Qf, gamma, free)
        for i in (0, n // 2, n - 1):
            J = np.zeros((model.m, model.nq))
            J[rows, cols] = vals[:, i]
            S = J @ (J / model.mass).T - np.diag(free[:, i])
            x = np.linalg.solve(S, J @ (Qf[:, i] / model.mass) - gamma[:, i])
            assert np.max(np.abs(lam[i] - x)) <= 1e-12 * np.max(np.abs(x))


def test_collapsed_rows_from_the_gram_eigenpairs_are_the_svds():
    """At the singular instants of A02 with 8 loops (50 rows, banded) the rank drop and
    the dependent rows come from the Gram matrix's eigenpairs below the threshold: the
    same count (8) and labels as the SVD gives, and their eigenvectors span the SVD's
    last 8 left singular vectors to 1e-8."""
    from cmm_dae.description import iftomm
    from cmm_dae.equations import kinematics, rank
    from cmm_dae.singular.instant import hermite

    mech = iftomm.a02_four_bar(8)
    model = cd.Model(mech)
    res = cd.run_dae(mech, 2.0, rtol=1e-3, model=model)
    p = model.params()
    act = model.active_rows(p)
    assert kinematics.gram_band(model, act) is not None
    assert len(res.events) == 2
    t, q, v = res.t, res.data["q"], res.data["v"]
    for e in res.events:
        a = int(np.searchsorted(t, e.t)) - 1
        qs = hermite(t[a], q[a], v[a], t[a + 1], q[a + 1], v[a + 1], e.t)[0]
        r0 = 0.05
        drop, labels = kinematics.collapsed_rows(model, qs, e.t, p, r0)
        J = model.constraints(qs, e.t, p).Phi_q[act]
        U, s, _ = np.linalg.svd(J, full_matrices=False)
        assert drop == rank.count_collapsed(s, r0) == 8
        assert labels == kinematics._row_labels(model, act, U, drop)
        got = rank.collapsed_gram(J, r0, float(s[0] ** 2))
        assert got is not None and got[0] == 8
        Uk = U[:, -8:]
        assert np.max(np.abs(Uk @ Uk.T - got[1] @ got[1].T)) <= 1e-8
    # a threshold below GRAM_FROM: the SVD decides
    assert rank.collapsed_gram(J, 0.1 * rank.GRAM_FROM, float(s[0] ** 2)) is None


@pytest.mark.parametrize("loops", [8, 32])
def test_collapsed_rows_of_a_long_chain_by_block_inverse_iteration(monkeypatch, loops):
    """A02 with 8 and 32 loops (50 and 194 rows, from BLOCK_FROM on): at both singular
    instants the rank drop (the loops) and the rows come from the Gram band's eigenvalues
    and a block inverse iteration, without the dense eigensolver (made to fail here); the
    basis spans the SVD's last left singular vectors to 1e-8 and the labels are the
    SVD's."""
    from cmm_dae.description import iftomm
    from cmm_dae.equations import kinematics, rank
    from cmm_dae.singular.instant import hermite

    mech = iftomm.a02_four_bar(loops)
    model = cd.Model(mech)
    res = cd.run_dae(mech, 2.0, rtol=1e-3, model=model)
    p = model.params()
    act = model.active_rows(p)
    band = kinematics.gram_band(model, act)
    assert band is not None and act.size >= rank.BLOCK_FROM and len(res.events) == 2

    def no_dense(*args):
        raise AssertionError("the dense eigensolver was called")

    t, q, v = res.t, res.data["q"], res.data["v"]
    for e in res.events:
        a = int(np.searchsorted(t, e.t)) - 1
        qs = hermite(t[a], q[a], v[a], t[a + 1], q[a + 1], v[a + 1], e.t)[0]
        J = model.constraints(qs, e.t, p).Phi_q[act]
        U, s, _ = np.linalg.svd(J, full_matrices=False)
        low = kinematics.banded.lower_blocks(
            band, kinematics.active_values_at(model, act, qs, e.t, p)[:, None])
        with monkeypatch.context() as mp:
            mp.setattr(rank, "collapsed_gram", no_dense)
            drop, basis = rank.collapsed_band(low, band.perm, lambda J=J: J, 0.01)
            assert kinematics.collapsed_rows(model, qs, e.t, p, 0.01) == (
                drop, kinematics._row_labels(model, act, U, drop))
        assert drop == rank.count_collapsed(s, 0.01) == loops
        Uk = U[:, -loops:]
        assert np.max(np.abs(Uk @ Uk.T - basis @ basis.T)) <= 1e-8


def test_collapsed_band_without_a_gap_is_the_dense_eigensolvers():
    """Eigenvalues just under and just over the threshold (no clear gap): the block
    iteration would converge slowly, so the dense eigensolver decides; with a gap of
    1e-6 the block's basis is the eigenvectors' (here the unit vectors)."""
    from cmm_dae.equations import rank

    m, r0 = 120, 0.01
    tau = (rank.COLLAPSE * r0) ** 2  # the largest eigenvalue is 1
    for lam_k, gapped in ((1e-12 * tau, True), (0.9 * tau, False)):
        lam = np.concatenate([[lam_k] * 5, [1.1 * tau], np.linspace(0.5, 1.0, m - 6)])
        J = np.hstack([np.diag(np.sqrt(lam)), np.zeros((m, 1))])
        low = lam[None, :].copy()  # a diagonal band: J J^T = diag(lam)
        got = rank.collapsed_band(low, np.arange(m), lambda J=J: J, r0)
        dense = rank.collapsed_gram(J, r0, 1.0)
        assert got[0] == dense[0] == 5
        if gapped:
            assert np.max(np.abs(got[1] @ got[1].T - np.diag([1.0] * 5 + [0.0] * (m - 5)))) \
                <= 1e-12
        else:
            assert np.array_equal(got[1], dense[1])


def test_post_processing_reuses_the_screens_solves(monkeypatch):
    """The stepped-over screen solves every sample's accelerations and multipliers with
    its measure (the Schur complement's Cholesky) and the run keeps them: post-processing
    solves none again, and every series is bit for bit what its own solve gives (A02 with
    8 loops, two passages, the run's start sample included)."""
    from cmm_dae.description import iftomm
    from cmm_dae.integrators import contract
    from cmm_dae.results import post

    mech = iftomm.a02_four_bar(8)
    model = cd.Model(mech)
    solved = []
    batch = post.batch_kkt
    monkeypatch.setattr(post, "batch_kkt", lambda *a: solved.append(a[1].size) or batch(*a))
    kept = cd.run_dae(mech, 2.0, rtol=1e-3, model=model)
    assert solved == [] and len(kept.events) == 2
    monkeypatch.setattr(contract.Recorder, "kkt", lambda self, *a: None)
    own = cd.run_dae(mech, 2.0, rtol=1e-3, model=model)
    assert solved  # (its own solve this time)
    for key in ("a", "lam", "jforce", "jtorque", "drift_pos", "drift_vel"):
        assert np.array_equal(kept.data[key], own.data[key]), key


def test_recorder_keeps_solves_of_the_samples_it_holds():
    """Solved samples kept with the recorder: NaN rows where none were kept, dropped
    with the samples a cut-back truncates."""
    from cmm_dae.integrators.contract import Recorder

    rec = Recorder()
    assert rec.kkt(2, 1) is None
    rec.add_block(np.arange(5.0), np.zeros((5, 2)), np.zeros((5, 2)), 0)
    rec.keep_kkt(1, np.ones((3, 2)), 2.0 * np.ones((3, 1)))
    a, lam = rec.kkt(2, 1)
    assert np.isnan(a[[0, 4]]).all() and (a[1:4] == 1.0).all() and (lam[1:4] == 2.0).all()
    assert rec.at(3)[0] == 3.0 and rec.at(3)[3] == 0
    rec.truncate(2)
    a, lam = rec.kkt(2, 1)
    assert a.shape == (2, 2) and np.isnan(a[0]).all() and (a[1] == 1.0).all()
    rec.truncate(1)
    assert rec.kkt(2, 1) is None


def test_post_processing_chunks_pad_at_most_a_quarter():
    """Chunk widths (the sizes mapped functions are built for): every sample once, in
    order, the last one repeated as padding; at most a quarter of the width padding from
    8 samples on (powers of two padded 201 samples to 256); four widths an octave."""
    from cmm_dae.results.post import chunk_indices

    widths = set()
    for n in range(1, 3000):
        k, idx = chunk_indices(0, n, 4096)
        assert k == n and np.array_equal(idx[:n], np.arange(n)) and np.all(idx[n:] == n - 1)
        assert idx.size == 8 if n <= 8 else 4 * (idx.size - n) < idx.size
        widths.add(idx.size)
    assert len([w for w in widths if 1024 < w <= 2048]) == 4
    k, idx = chunk_indices(128, 201, 64)  # a full chunk keeps the chunk size
    assert k == 64 and np.array_equal(idx, np.arange(128, 192))


def test_recent_keeps_the_last_keys_of_a_kind():
    """core.memo.recent: a key asked again is not computed again, a kind keeps its last
    ``keep`` keys (the least recently asked goes first), kinds are apart."""
    from types import SimpleNamespace

    from cmm_dae.core.memo import recent

    owner, calls = SimpleNamespace(), []

    def get(kind, key):
        return recent(owner, kind, key, lambda: calls.append(key) or [key], keep=2)
    first = get("a", 1)
    assert get("a", 1) is first and calls == [1]
    get("a", 2)
    get("a", 1)  # 1 asked last: 2 goes when 3 comes
    get("a", 3)
    assert get("a", 1) is first and calls == [1, 2, 3]
    get("a", 2)
    assert calls == [1, 2, 3, 2] and get("b", 1) == [1] and calls[-1] == 1


def test_a_run_from_a_kept_start_is_the_same(monkeypatch):
    """The first segment's projection and KKT solve are kept per model and start: the
    model run again from the same start projects nothing anew and gives the same numbers
    bit for bit (the returned arrays are copies: the run changing them leaves the kept
    ones), a start changed in the mechanism is projected anew (A02 with 8 loops)."""
    from cmm_dae.description import iftomm
    from cmm_dae.integrators import ida_steps

    projected = []
    project = ida_steps.project_state
    monkeypatch.setattr(ida_steps, "project_state",
                        lambda *a, **k: projected.append(a[3]) or project(*a, **k))
    mech = iftomm.a02_four_bar(8)
    model = cd.Model(mech)
    first = cd.run_dae(mech, 0.5, rtol=1e-6, model=model)
    n = len(projected)
    assert n >= 1 and projected[0] == 0.0
    again = cd.run_dae(mech, 0.5, rtol=1e-6, model=model)
    assert len(projected) == 2 * n - 1  # all but the first segment's start
    for key in ("q", "v", "a", "lam", "jforce", "effort"):
        assert np.array_equal(first.data[key], again.data[key]), key
    moved = mech.replace(initial=dataclasses.replace(
        mech.initial, velocities={**mech.initial.velocities, "G0": 0.5}))
    other = cd.run_dae(moved, 0.5, rtol=1e-6)
    assert projected[2 * n - 1] == 0.0 and not np.array_equal(other.data["v"][0],
                                                              first.data["v"][0])


def test_iterative_python_step_hands_its_solves_to_post_processing(monkeypatch):
    """The fixed-step algorithm's Python step (friction from the reaction) solves the KKT
    system once a step and the run keeps it at the samples: post-processing solves only
    the samples without one (the start's and those just before a switch), and every
    series is bit for bit what its own solve gives (a pin with reaction friction, 0.8 s
    at dt 1e-3: slips and sticks)."""
    from test_reaction_friction import _pin_pendulum

    from cmm_dae.integrators import contract

    solved = []
    batch = post.batch_kkt
    monkeypatch.setattr(post, "batch_kkt", lambda *a: solved.append(a[1].size) or batch(*a))
    mech = _pin_pendulum()
    kept = cd.run_iterative(mech, 0.8, dt=1e-3)
    # the start's sample and the one before each switch, in one evaluation of the
    # narrowest width the maps are built for
    assert kept.events and kept.t.size > 700 and len(solved) == 1 and solved[0] <= 8
    solved.clear()
    monkeypatch.setattr(contract.Recorder, "kkt", lambda self, *a: None)
    own = cd.run_iterative(mech, 0.8, dt=1e-3)
    assert sum(solved) >= own.t.size  # (its own solve of every sample, padded)
    for key in ("a", "lam", "jforce", "jtorque", "friction"):
        assert np.array_equal(kept.data[key], own.data[key]), key
