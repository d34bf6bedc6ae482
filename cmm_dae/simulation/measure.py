"""The stepped-over screen's measure of the constraints' singular-value ratio at many
states at once: log det(J J^T) of the active rows' Jacobian J, which dips where the ratio
dips (:mod:`.passage`), evaluated in chunks of one mapped CasADi function."""

from __future__ import annotations

import numpy as np
from scipy.sparse import csc_matrix
from scipy.sparse.linalg import splu

from ..equations.kinematics import gram_band, gram_function
from ..equations.kinematics import log_gram as banded_log_gram
from ..equations.model import Model

__all__ = ["CHUNK", "log_gram", "mapped_chunks"]

#: Samples whose constraint Jacobians are screened in one mapped evaluation.
CHUNK = 256


def mapped_chunks(model: Model, name: str, p: np.ndarray, t: np.ndarray, q: np.ndarray):
    """``model.<name>`` (of q, t, p) over the samples in chunks of :data:`CHUNK`, one mapped
    evaluation each (the last chunk padded with its last sample, the padding dropped; fewer
    samples than a chunk make a chunk of the next power of two, so that the maps built
    stay few and the padding is less than the samples): yields (first sample, samples in
    the chunk, the function's outputs)."""
    size = min(CHUNK, 1 << max(t.size - 1, 1).bit_length())
    fn = model.mapped(name, size)
    P = np.repeat(p[:, None], size, axis=1)
    for k in range(0, t.size, size):
        m = min(size, t.size - k)
        qk = np.empty((model.nq, size))
        tk = np.empty(size)
        qk[:, :m], tk[:m] = q[k:k + m].T, t[k:k + m]
        qk[:, m:], tk[m:] = qk[:, m - 1:m], tk[m - 1]
        yield k, m, fn(qk, tk, P)


def log_gram(model: Model, p: np.ndarray, t: np.ndarray, q: np.ndarray,
              act: np.ndarray) -> np.ndarray:
    """log det(J J^T) of the active rows' Jacobian J at every sample (-inf where it is
    singular): a measure that dips where the ratio dips, at a fraction of the SVDs' cost
    (1.4 against 11.6 ms on the double-folded cycle's 1005 samples, 96 against 487 ms on
    102 samples of A02 with 40 loops), evaluated in chunks of one mapped function; from
    Phi_q's nonzeros alone where the Jacobian is banded or large."""
    if model.kkt_sparse or gram_band(model, act) is not None:
        return _log_gram_sparse(model, p, t, q, act)
    out = np.empty(t.size)
    gram_function(model)  # (model.gram_fn, built on first use)
    for k, m, outs in mapped_chunks(model, "gram_fn", p, t, q):
        G = np.asarray(outs[0]).reshape(model.m, -1, model.m).transpose(1, 0, 2)[:m]
        try:  # Cholesky: a third of an LU's time on these small symmetric matrices
            L = np.linalg.cholesky(G)
            out[k:k + m] = 2.0 * np.log(np.diagonal(L, axis1=1, axis2=2)).sum(axis=1)
        except np.linalg.LinAlgError:  # one is singular to round-off: LU for the chunk
            sign, logdet = np.linalg.slogdet(G)
            out[k:k + m] = np.where(sign > 0.0, logdet, -np.inf)
    return out


def _log_gram_sparse(model: Model, p: np.ndarray, t: np.ndarray, q: np.ndarray,
                     act: np.ndarray) -> np.ndarray:
    """:func:`log_gram` of a large mechanism from Phi_q's nonzeros alone: J J^T as a sparse
    matrix per sample and log det from its sparse LU (a chain of 32 loops: the dense path
    copied 115 MB per chunk of samples and took a third of the run)."""
    pat = model.phi_q_pattern
    colind, row = (np.asarray(x, dtype=np.int64) for x in pat.get_ccs())
    shape = (pat.size1(), pat.size2())
    out = np.empty(t.size)
    for k, m, outs in mapped_chunks(model, "phi_q_nz_fn", p, t, q):
        nz = np.asarray(outs[0]).reshape(row.size, -1)[:, :m]  # (nonzero, sample)
        banded = banded_log_gram(model, act, nz)
        if banded is not None:  # a narrow band: a banded Cholesky per sample
            out[k:k + m] = banded
            continue
        nz = nz.T
        for j in range(m):
            J = csc_matrix((nz[j], row, colind), shape=shape)[act]
            try:
                d = splu((J @ J.T).tocsc(), permc_spec="MMD_AT_PLUS_A").U.diagonal()
            except RuntimeError:  # exactly singular
                out[k + j] = -np.inf
                continue
            out[k + j] = float(np.sum(np.log(np.abs(d)))) if np.all(d != 0.0) else -np.inf
    return out
