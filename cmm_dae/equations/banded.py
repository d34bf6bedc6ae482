"""The KKT system's Schur complement of a large mechanism as a band: for a chain of loops
``S = Phi_q M^-1 Phi_q^T - D`` is banded once its rows are reordered (reverse
Cuthill-McKee), and each sample costs one banded LU (LAPACK ``dgbsv``), its values
accumulated from Phi_q's nonzeros through one sparse product (:func:`structure`,
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
from scipy.linalg.lapack import dgbsv
from scipy.sparse.csgraph import reverse_cuthill_mckee

__all__ = ["BANDED_FROM", "BAND_SHARE", "BandedSchur", "banded_solve", "batch_from_nonzeros",
           "for_model", "structure"]


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
    to_band: sp.csr_matrix  # (ntrip, band entries): products -> banded storage of S
    pa: np.ndarray        # (ntrip,) the two nonzeros of each product
    pb: np.ndarray
    pk: np.ndarray        # (ntrip,) their common column
    diag: np.ndarray      # (m,) flat banded index of S's diagonal, in the new order
    perm: np.ndarray      # (m,) the reordering: new row i is old row perm[i]
    bw: int               # half bandwidth after reordering
    m: int


def structure(rows: np.ndarray, cols: np.ndarray, m: int) -> BandedSchur | None:
    """The banded structure of ``S`` for Phi_q's nonzeros at (rows, cols), or None when the
    system is small or its band is not narrow (then the dense batched solve is better)."""
    if m < BANDED_FROM:
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
    if bw > BAND_SHARE * m:
        return None
    # dgbsv's storage: (2 bw + bw + 1, m), A[i, j] at row 2 bw + i - j, column j
    ldab = 3 * bw + 1
    flat = (2 * bw + i - j) * m + j
    to_band = sp.csr_matrix((np.ones(pa.size), (np.arange(pa.size), flat)),
                            shape=(pa.size, ldab * m))
    d = np.arange(m)
    return BandedSchur(rows, cols, to_band, pa, pb, cols[pa], 2 * bw * m + d, perm, bw, m)


def banded_solve(st: BandedSchur, vals: np.ndarray, mass: np.ndarray, Qf: np.ndarray,
          gamma: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Multipliers (n, m) of every sample from Phi_q's nonzeros ``vals`` (n, nnz; at
    ``st.rows``, ``st.cols``), Q (n, nq), gamma (n, m) and the inactive-row flags ``free``
    (n, m). Raises numpy.linalg.LinAlgError on a singular sample."""
    n, m = vals.shape[0], st.m
    prod = vals[:, st.pa] * vals[:, st.pb] / mass[st.pk]    # (n, ntrip)
    ab = np.asarray((st.to_band.T @ prod.T).T).reshape(n, 3 * st.bw + 1, m)
    ab = ab.reshape(n, -1)
    ab[:, st.diag] -= free[:, st.perm]
    ab = ab.reshape(n, 3 * st.bw + 1, m)
    # Phi_q M^-1 Q, nonzero by nonzero, summed into rows by a sparse product (np.add.at
    # took a sixth of the solve: 1.1 of 6 ms for 64 samples with 32 loops)
    rhs = np.asarray((_scatter(st.rows, m).T @ (vals * (Qf[:, st.cols] / mass[st.cols])).T).T)
    rhs = (rhs - gamma)[:, st.perm]
    # one banded LU of all the samples' systems as the blocks of one block-diagonal band
    # matrix (their coupling entries are zero, so pivoting stays inside each block and
    # the arithmetic is each block's own): one call per sample took 40 us each, most of
    # it the call, with 32 loops
    _, _, x, info = dgbsv(st.bw, st.bw, stacked(ab), rhs.reshape(-1), overwrite_ab=True,
                          overwrite_b=True)
    if info != 0:
        raise np.linalg.LinAlgError(f"singular Schur complement at sample {(info - 1) // m}")
    lam = np.empty((n, m))
    lam[:, st.perm] = x.reshape(n, m)
    return lam


def stacked(ab: np.ndarray) -> np.ndarray:
    """Band matrices in LAPACK's band storage, one per state (states, rows, m), as the
    blocks of one block-diagonal band matrix (rows, states m), Fortran-ordered. Each
    block's storage must hold zeros where its band runs past its last row or column
    (as :func:`structure`'s products leave it): those entries couple neighbouring
    blocks."""
    n, k, m = ab.shape
    return np.asfortranarray(ab.transpose(1, 0, 2).reshape(k, n * m))


_cache: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def for_model(model) -> BandedSchur | None:
    """:func:`structure` of a model's Phi_q pattern (computed once per model)."""
    if model not in _cache:
        rows, cols = model.phi_q_pattern.get_triplet()
        _cache[model] = (structure(np.asarray(rows, int), np.asarray(cols, int), model.m)
                         if np.all(model.mass > 0.0) else None)
    return _cache[model]


def batch_from_nonzeros(model: Any, t: np.ndarray, q: np.ndarray, v: np.ndarray, P: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray] | None:
    """(a, lambda) of every sample of a banded mechanism (:func:`for_model`) from Phi_q's
    nonzeros alone; None if a sample's Schur complement is singular."""
    n, st = t.size, for_model(model)
    if getattr(model, "kkt_nz_fn", None) is None:
        args = model.kkt_fn.sx_in()
        _, Qf, gamma = model.kkt_fn(*args)
        nz = model.phi_q_nz_fn(args[0], args[2], args[3])
        model.kkt_nz_fn = ca.Function("kkt_nz", args, [nz, Qf, gamma])
    vals, Qf, gamma = (np.asarray(x).reshape(-1, n).T for x in model.mapped(
        "kkt_nz_fn", n)(q.T, v.T, t, P.T))
    free = np.asarray(model.mapped("free_fn", n)(P.T)[0]).reshape(-1, n).T
    try:
        lam = banded_solve(st, vals, model.mass, Qf, gamma, free)
    except np.linalg.LinAlgError:
        return None
    # Phi_q^T lambda, nonzero by nonzero
    force = np.asarray((_scatter(st.cols, model.nq).T @ (vals * lam[:, st.rows]).T).T)
    return (Qf - force) / model.mass, lam


@functools.lru_cache(maxsize=16)
def _scatter_cached(index: bytes, size: int) -> sp.csr_matrix:
    where = np.frombuffer(index, dtype=np.int64)
    return sp.csr_matrix((np.ones(where.size), (np.arange(where.size), where)),
                         shape=(where.size, size))


def _scatter(index: np.ndarray, size: int) -> sp.csr_matrix:
    """The (entries, size) matrix that sums entry e into position ``index[e]``."""
    return _scatter_cached(np.asarray(index, dtype=np.int64).tobytes(), size)
