"""The stepped-over screen's measure of the constraints' singular-value ratio at many
states at once: log det(J J^T) of the active rows' Jacobian J, which dips where the ratio
dips (:mod:`.passage`), evaluated in chunks of one mapped CasADi function.

On a banded mechanism whose rows are all active (a chain of loops) the measure is
log det(J M^-1 J^T) instead, the mass-weighted Gram matrix (its smallest eigenvalues
collapse with J's smallest singular values as J J^T's do): that is the Schur complement
post-processing factors at every sample to solve for the multipliers, so the screen takes
the samples' measure from that very solve (:func:`sample_measure`) and the run keeps its
accelerations and multipliers for post-processing, which then does not solve them again
(A02 with 32 loops: the screen's own factorizations of the samples took a tenth of a
run)."""

from __future__ import annotations

import numpy as np
from scipy.sparse import csc_matrix
from scipy.sparse.linalg import splu

from ..equations import banded
from ..equations.codegen import map_width
from ..equations.kinematics import gram_band, gram_function
from ..equations.kinematics import log_gram as banded_log_gram
from ..equations.model import Model
from ..results.post import chunk_indices, chunk_size

__all__ = ["CHUNK", "log_gram", "mapped_chunks", "sample_measure", "weighted"]

#: Samples whose constraint Jacobians are screened in one mapped evaluation.
CHUNK = 256


def mapped_chunks(model: Model, name: str, p: np.ndarray, t: np.ndarray, q: np.ndarray):
    """``model.<name>`` (of q, t, p) over the samples in chunks of :data:`CHUNK`, one mapped
    evaluation each (the last chunk padded with its last sample, the padding dropped; fewer
    samples than a chunk make a chunk of :func:`~cmm_dae.equations.codegen.map_width`'s
    width, so that the maps built stay few): yields (first sample, samples in the chunk,
    the function's outputs)."""
    size = map_width(t.size, CHUNK)
    fn = model.mapped(name, size)
    P = np.repeat(p[:, None], size, axis=1)
    for k in range(0, t.size, size):
        m = min(size, t.size - k)
        qk = np.empty((model.nq, size))
        tk = np.empty(size)
        qk[:, :m], tk[:m] = q[k:k + m].T, t[k:k + m]
        qk[:, m:], tk[m:] = qk[:, m - 1:m], tk[m - 1]
        yield k, m, fn(qk, tk, P)


def weighted(model: Model, act: np.ndarray) -> bool:
    """Whether the screen's measure is log det(J M^-1 J^T), the Schur complement
    post-processing factors (see the module): a banded mechanism (for both), every row
    active, no callable load (post-processing evaluates those sample by sample) and no
    friction from the reaction (solved sample by sample where a joint slips)."""
    return (act.size == model.m and not model.callables and not model.reacting
            and banded.for_model(model) is not None and gram_band(model, act) is not None)


def sample_measure(model: Model, p: np.ndarray, t: np.ndarray, q: np.ndarray,
                   v: np.ndarray, act: np.ndarray
                   ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """The measure at a segment's samples (:func:`log_gram`) and, where it is the Schur
    complement's (:func:`weighted`), the samples' accelerations (n, nq) and multipliers
    (n, m) solved with it by post-processing's own batch, in its chunks (the same maps);
    None where they are not (then post-processing solves them)."""
    if not weighted(model, act):
        return log_gram(model, p, t, q, act), None
    n, size = t.size, chunk_size(model)
    a, lam, d = np.empty((n, model.nq)), np.empty((n, model.m)), np.empty(n)
    for i in range(0, n, size):
        k, idx = chunk_indices(i, n, size)
        logdet: list = []
        got = banded.batch_from_nonzeros(model, t[idx], q[idx], v[idx],
                                         np.repeat(p[None], idx.size, axis=0), logdet)
        if got is None or not logdet:  # a singular sample: the measure alone
            return log_gram(model, p, t, q, act), None
        a[i:i + k], lam[i:i + k], d[i:i + k] = got[0][:k], got[1][:k], logdet[0][:k]
    return d, (a, lam)


def log_gram(model: Model, p: np.ndarray, t: np.ndarray, q: np.ndarray,
             act: np.ndarray) -> np.ndarray:
    """log det(J J^T) of the active rows' Jacobian J at every sample (-inf where it is
    singular; J M^-1 J^T where :func:`weighted`): a measure that dips where the ratio
    dips, at a fraction of the SVDs' cost (1.4 against 11.6 ms on the double-folded
    cycle's 1005 samples, 96 against 487 ms on 102 samples of A02 with 40 loops),
    evaluated in chunks of one mapped function; from Phi_q's nonzeros alone where the
    Jacobian is banded or large."""
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
    scale = 1.0 / model.mass if weighted(model, act) else None
    for k, m, outs in mapped_chunks(model, "phi_q_nz_fn", p, t, q):
        nz = np.asarray(outs[0]).reshape(row.size, -1)[:, :m]  # (nonzero, sample)
        band = banded_log_gram(model, act, nz, scale)
        if band is not None:  # a narrow band: a banded Cholesky per sample
            out[k:k + m] = band
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
