"""The KKT system's Schur complement of a large mechanism as a band: for a chain of loops
``S = Phi_q M^-1 Phi_q^T - D`` is banded once its rows are reordered (reverse
Cuthill-McKee), and each sample costs one banded Cholesky (LAPACK ``dpbsv``; an LU,
``dgbsv``, where it is not positive definite), its values accumulated from Phi_q's
nonzeros through one sparse product (:func:`structure`, :func:`lower_blocks`,
:func:`banded_solve`); post-processing evaluates those nonzeros alone
(:func:`batch_from_nonzeros`)."""

from __future__ import annotations

import functools
import weakref
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.linalg.lapack import dgbsv, dpbsv, dpbtrf
from scipy.sparse.csgraph import reverse_cuthill_mckee

__all__ = ["BANDED_FROM", "BAND_SHARE", "BandedSchur", "IDA_BAND_SHARE", "banded_solve",
           "batch_from_nonzeros", "for_model", "full_band", "ida_order", "kkt_nz_function",
           "lower_blocks", "shifted_cholesky", "structure"]


#: The banded path is taken from this many constraint rows on, when the band is narrow
#: (at most BAND_SHARE of m after reordering); smaller systems are solved dense and batched.
#: A02 with 8 loops (50 rows, bandwidth 5), 200 samples: the multipliers in 7.1 ms banded
#: against 16.4 ms dense; log det(J J^T) for the stepped-over screen in 3.9 against 9.8 ms
#: (16 loops, 98 rows: 6.3 against 141 ms). Below 40 rows no band is narrow enough.
BANDED_FROM = 32
BAND_SHARE = 0.125


@dataclass(frozen=True)
class BandedSchur:
    """The fixed structure of ``S`` for one model (see :func:`structure`)."""

    rows: np.ndarray      # (nnz,) row of each structural nonzero of Phi_q
    cols: np.ndarray      # (nnz,) column of each
    la: np.ndarray        # (nlow,) the two nonzeros of each product on or below S's
    lb: np.ndarray        #   diagonal (each unordered pair of a column's nonzeros once)
    lk: np.ndarray        # (nlow,) their common column
    to_lower: sp.csr_matrix  # (m (bw + 1), nlow): products -> S's lower band storage
    perm: np.ndarray      # (m,) the reordering: new row i is old row perm[i]
    bw: int               # half bandwidth after reordering
    m: int
    dest: np.ndarray      # (nlow,) each product's row in to_lower (its entry's flat index)


def structure(rows: np.ndarray, cols: np.ndarray, m: int, limited: bool = True
              ) -> BandedSchur | None:
    """The banded structure of ``S`` for Phi_q's nonzeros at (rows, cols), or None when the
    system is small or its band is not narrow (then the dense batched solve is better);
    ``limited=False``: at any size and width (a small system's band is the whole matrix)."""
    if limited and m < BANDED_FROM:
        return None
    pa, pb = [], []
    by_col: dict[int, list[int]] = {}
    for e, k in enumerate(cols):
        by_col.setdefault(int(k), []).append(e)
    for ents in by_col.values():
        for a in ents:
            for b in ents:
                pa.append(a)
                pb.append(b)
    pa, pb = np.array(pa, int), np.array(pb, int)
    ra, rb = rows[pa], rows[pb]
    pattern = sp.csr_matrix((np.ones(pa.size), (ra, rb)), shape=(m, m)) + sp.identity(m)
    perm = np.asarray(reverse_cuthill_mckee(pattern.tocsr(), symmetric_mode=True), int)
    inv = np.empty(m, int)
    inv[perm] = np.arange(m)
    i, j = inv[ra], inv[rb]
    bw = int(np.max(np.abs(i - j), initial=0))
    if limited and bw > BAND_SHARE * m:
        return None
    # the products on or below the diagonal (S is symmetric: LAPACK's lower band storage
    # holds it), A[i, j] at row i - j of column j of a (bw + 1, m) Fortran array
    low = i >= j
    la, lb, i, j = pa[low], pb[low], i[low], j[low]
    dest = j * (bw + 1) + i - j
    to_lower = sp.csr_matrix((np.ones(la.size), (dest, np.arange(la.size))),
                             shape=((bw + 1) * m, la.size))
    return BandedSchur(rows, cols, la, lb, cols[la], to_lower, perm, bw, m, dest)


def lower_blocks(st: BandedSchur, vals: np.ndarray, scale: np.ndarray | None = None
                 ) -> np.ndarray:
    """Each state's ``S`` (``Phi_q diag(scale) Phi_q^T``; unit ``scale`` where None) from its
    Phi_q nonzeros ``vals`` (nonzeros at ``st.rows``, ``st.cols``, states) in LAPACK's
    lower band storage, as the blocks of one block-diagonal band matrix: (bw + 1, states
    m), Fortran-ordered, for one LAPACK call on all states: their coupling entries are
    zero (the storage holds zeros where a block's band runs past its last row), so the
    arithmetic is each block's own, bit for bit. The products are gathered row by row
    from the nonzeros-first layout mapped functions return (by columns of the states-first
    layout and on both halves of S, with a copy into the blocks, this took 6.1 ms for 201
    states of A02 with 32 loops)."""
    prod = vals[st.la] * vals[st.lb]
    if scale is not None:
        prod *= scale[st.lk][:, None]
    n = vals.shape[1]
    size = (st.bw + 1) * st.m
    if n == 1:  # one state (a singular instant, a bound): a sparse product's dispatch
        # cost more than the sum (in the same order: the same bits)
        return np.bincount(st.dest, weights=prod[:, 0], minlength=size).reshape(
            st.m, st.bw + 1).T
    if n <= 4:  # a few (a short run's samples): the same sums state by state (0.18 ->
        # 0.04 ms for two states with 32 loops)
        low = np.stack([np.bincount(st.dest, weights=prod[:, k], minlength=size)
                        for k in range(n)], axis=1)
    else:
        low = st.to_lower @ prod  # ((bw + 1) m, states): summed into S's entries
    return np.ascontiguousarray(low.T).reshape(n * st.m, st.bw + 1).T


def shifted_cholesky(low: np.ndarray, shift: float) -> np.ndarray | None:
    """The banded Cholesky factor (LAPACK ``dpbtrf``, lower band storage) of the symmetric
    band matrix whose lower band storage is ``low`` (kept) plus ``shift`` on its diagonal:
    for inverse iteration on a Gram matrix ``J J^T``, positive definite with a shift of
    round-off also where J is singular; None where it is not positive definite."""
    shifted = low.copy()
    shifted[0] += shift
    c, info = dpbtrf(shifted, lower=1)
    return c if info == 0 else None


def full_band(low: np.ndarray, bw: int) -> np.ndarray:
    """The general band storage dgbsv takes (3 bw + 1 rows, A[i, j] at row 2 bw + i - j)
    of the symmetric band matrix whose lower band storage is ``low`` (bw + 1 rows)."""
    ab = np.zeros((3 * bw + 1, low.shape[1]), order="F")
    ab[2 * bw:] = low
    for d in range(1, bw + 1):  # A[i, i + d] = A[i + d, i]
        ab[2 * bw - d, d:] = low[d, :low.shape[1] - d]
    return ab


def banded_solve(st: BandedSchur, vals: np.ndarray, mass: np.ndarray, Qf: np.ndarray,
          gamma: np.ndarray, free: np.ndarray, logdet: list | None = None) -> np.ndarray:
    """Multipliers (n, m) of every sample from Phi_q's nonzeros ``vals`` (nnz, n; at
    ``st.rows``, ``st.cols``), Q (nq, n), gamma (m, n) and the inactive-row flags ``free``
    (m, n): the layouts mapped functions return. Raises numpy.linalg.LinAlgError on a
    singular sample. ``logdet``: a list that gets log det(Phi_q M^-1 Phi_q^T) of every
    sample (n,) appended, from the Cholesky factor, where every row is active."""
    n, m = vals.shape[1], st.m
    big = lower_blocks(st, vals, 1.0 / mass)
    big[0] -= free[st.perm].T.reshape(-1)  # S = Phi_q M^-1 Phi_q^T - D
    # Phi_q M^-1 Q, nonzero by nonzero, summed into rows by a sparse product (np.add.at
    # took a sixth of the solve: 1.1 of 6 ms for 64 samples with 32 loops)
    rhs = _scatter(st.rows, m) @ (vals * (Qf[st.cols] / mass[st.cols][:, None]))
    rhs = np.ascontiguousarray((rhs - gamma)[st.perm].T).reshape(-1)
    # one banded factorization of all the samples' systems as the blocks of one
    # block-diagonal band matrix (their coupling entries are zero, so the arithmetic is
    # each block's own): one call per sample took 40 us each, most of it the call, with
    # 32 loops. With every row active S = Phi_q M^-1 Phi_q^T is symmetric positive
    # definite: a banded Cholesky (dpbsv), 3.6 -> 1.7 ms for 64 samples with 32 loops; an
    # LU with pivoting (dgbsv) where rows are free (S indefinite) or the Cholesky meets a
    # pivot that is not positive (a sample next to a singular position)
    info = 1
    if not free.any():
        c, x, info = dpbsv(big, rhs, lower=1)
        if info == 0 and logdet is not None:  # (the factor's diagonal, block by block)
            logdet.append(2.0 * np.log(c[0].reshape(n, m)).sum(axis=1))
    if info != 0:
        _, _, x, info = dgbsv(st.bw, st.bw, full_band(big, st.bw), rhs, overwrite_ab=True,
                              overwrite_b=True)
    if info != 0:
        raise np.linalg.LinAlgError(f"singular Schur complement at sample {(info - 1) // m}")
    lam = np.empty((n, m))
    lam[:, st.perm] = x.reshape(n, m)
    return lam


_cache: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def for_model(model) -> BandedSchur | None:
    """:func:`structure` of a model's Phi_q pattern (computed once per structure: a zero
    mass is part of it)."""
    key = model.shared
    if key not in _cache:
        rows, cols = model.phi_q_pattern.get_triplet()
        _cache[key] = (structure(np.asarray(rows, int), np.asarray(cols, int), model.m)
                       if np.all(model.mass > 0.0) else None)
    return _cache[key]


def batch_from_nonzeros(model: Any, t: np.ndarray, q: np.ndarray, v: np.ndarray, P: np.ndarray,
                        logdet: list | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """(a, lambda) of every sample of a banded mechanism (:func:`for_model`) from Phi_q's
    nonzeros alone; None if a sample's Schur complement is singular. ``logdet``: see
    :func:`banded_solve`."""
    n, st = t.size, for_model(model)
    kkt_nz_function(model)
    vals, Qf, gamma = (np.asarray(x).reshape(-1, n) for x in model.mapped(
        "kkt_nz_fn", n)(q.T, v.T, t, P.T))
    free = np.asarray(model.mapped("free_fn", n)(P.T)[0]).reshape(-1, n)
    try:
        lam = banded_solve(st, vals, model.mass, Qf, gamma, free, logdet)
    except np.linalg.LinAlgError:
        return None
    # Phi_q^T lambda, nonzero by nonzero
    force = _scatter(st.cols, model.nq) @ (vals * lam.T[st.rows])
    return (Qf - force).T / model.mass, lam


def kkt_nz_function(model: Any) -> ca.Function:
    """``kkt_nz(q, v, t, p)`` -> (Phi_q's nonzeros, Q, gamma): the parts of the KKT system
    a banded mechanism's post-processing evaluates (built once, as ``model.kkt_nz_fn``,
    for :meth:`~cmm_dae.equations.model.Model.mapped`)."""
    if getattr(model, "kkt_nz_fn", None) is None:
        args = model.kkt_fn.sx_in()
        _, Qf, gamma = model.kkt_fn(*args)
        nz = model.phi_q_nz_fn(args[0], args[2], args[3])
        model.kkt_nz_fn = ca.Function("kkt_nz", args, [nz, Qf, gamma])
    return model.kkt_nz_fn


def constraints_nz_function(model: Any) -> ca.Function:
    """``con_nz(q, t, p)`` -> (phi, Phi_q's nonzeros, Phi_t): the constraints of one state
    without the dense Phi_q (a long chain's projections; built once, as
    ``model.con_nz_fn``)."""
    if getattr(model, "con_nz_fn", None) is None:
        args = model.phi_fn.sx_in()
        phi, _, Phi_t = model.phi_fn(*args)
        model.con_nz_fn = ca.Function("con_nz", args, [phi, model.phi_q_nz_fn(*args), Phi_t])
    return model.con_nz_fn


@functools.lru_cache(maxsize=16)
def _scatter_cached(index: bytes, size: int) -> sp.csr_matrix:
    where = np.frombuffer(index, dtype=np.int64)
    return sp.csr_matrix((np.ones(where.size), (where, np.arange(where.size))),
                         shape=(size, where.size))


def _scatter(index: np.ndarray, size: int) -> sp.csr_matrix:
    """The (size, entries) matrix whose product sums entry e into row ``index[e]`` (built
    as such: transposing it at every use took 0.2 ms a run with 8 loops)."""
    return _scatter_cached(np.asarray(index, dtype=np.int64).tobytes(), size)


#: IDA's Jacobian is factored as a band (the compiled segment, ``linsolver="auto"``) where
#: its reordered half bandwidths add up to at most this share of the unknowns. A02's
#: reordered: 130 unknowns (8 loops) 9 + 8, 514 (32) 9 + 8, 2050 (128) 14 + 15; one LU
#: took 0.08, 0.13, 0.80 ms by band (LAPACK dgbtrf) against 0.60, 0.93, 2.9 by SuperLU.
IDA_BAND_SHARE = 0.25


def ida_order(colptr: np.ndarray, rowind: np.ndarray, n: int
              ) -> tuple[np.ndarray, int, int] | None:
    """An ordering of IDA's unknowns, the same for its residuals, that makes the n x n
    Jacobian with CSC pattern (``colptr``, ``rowind``) a band: reverse Cuthill-McKee on
    the pattern made symmetric. Returns (perm, ml, mu): the new i-th is the old
    ``perm[i]``, ml and mu the band's half widths below and above the diagonal; None
    where the band is wide (:data:`IDA_BAND_SHARE`)."""
    col = np.repeat(np.arange(n), np.diff(colptr))
    a = sp.csr_matrix((np.ones(rowind.size), (rowind, col)), shape=(n, n))
    # (contiguous: the compiled segment reads it through a pointer; RCM's is reversed)
    perm = np.ascontiguousarray(reverse_cuthill_mckee((a + a.T).tocsr(),
                                                      symmetric_mode=True), dtype=np.intc)
    inv = np.empty(n, dtype=int)
    inv[perm] = np.arange(n)
    d = inv[rowind] - inv[col]
    ml, mu = int(max(d.max(initial=0), 0)), int(max(-d.min(initial=0), 0))
    return (perm, ml, mu) if ml + mu <= IDA_BAND_SHARE * n else None
