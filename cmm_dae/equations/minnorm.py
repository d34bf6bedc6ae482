"""Minimum-norm solutions on the constraints in force (the projections of
:mod:`.kinematics`), from a dense Jacobian or from the nonzeros of its rows alone
(:class:`SparseRows`: a long chain's, whose dense Phi_q the projections of its singular
crossings would otherwise evaluate and copy at every stage of every Gauss step)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl
from scipy.linalg import solve_triangular

__all__ = ["QR_ROWS", "SPARSE_FILL", "SPARSE_ROWS", "MinNorm", "SparseRows"]

#: Rows from which :class:`MinNorm` factors by QR: measured side by side, ``lstsq`` took
#: 0.64x the time of QR and the triangular solve on 11 x 12 rows (the double-folded
#: mechanism's size), 1.25x on 30 x 33 and 1.8x on 120 x 123 (random full-rank matrices).
QR_ROWS = 30
#: Rows from which :class:`MinNorm` solves a sparse Jacobian (at most :data:`SPARSE_FILL`
#: of its entries nonzero) through the augmented system ``[[I, J^T], [J, 0]]`` by sparse
#: LU instead of a dense QR: on A02 with 32 loops (194 x 195 rows, 1.5 % nonzero) 0.8 ms
#: against 1.6 ms, the same solution to 2e-14 (the projections of its singular crossings
#: took 3.3 s of QR in a 7.7-s run). The augmented system's condition is J's, not its
#: square, as the normal equations' would be.
SPARSE_ROWS = 100
SPARSE_FILL = 0.05


@dataclass(frozen=True)
class SparseRows:
    """Rows of a Jacobian by their structural nonzeros: ``vals`` at (``rows``, ``cols``),
    row-major, of a ``shape`` matrix."""

    vals: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    shape: tuple[int, int]

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        return np.bincount(self.rows, self.vals * x[self.cols], minlength=self.shape[0])

    def toarray(self) -> np.ndarray:
        """The dense matrix."""
        out = np.zeros(self.shape)
        out[self.rows, self.cols] = self.vals
        return out


class MinNorm:
    """Minimum-norm solutions of ``J x = r`` for one constraint Jacobian ``J`` (dense, or
    :class:`SparseRows`).

    For :data:`QR_ROWS` rows or more with full row rank, from the QR factors of ``J^T``
    (``J = R^T Q^T``, so ``x = Q R^-T r``), factored once for several right-hand sides.
    Below that, where it is (numerically) rank deficient, has more rows than columns (a
    new lock can make the rows dependent until a jam is resolved) or ``rcond`` asks for a
    cut-off, numpy's SVD-based ``lstsq``.
    """

    def __init__(self, J: np.ndarray | SparseRows, rcond: float | None = None):
        self.rcond = rcond
        self.qr: tuple[np.ndarray, np.ndarray] | None = None
        self.lu = None
        m, n = J.shape
        self.n = n
        sparse = isinstance(J, SparseRows)
        self._J, self._sparse = (None, J) if sparse else (J, None)
        if rcond is None and SPARSE_ROWS <= m <= n:
            nonzeros = (J.rows, J.cols) if sparse else np.nonzero(J)
            self.lu = _augmented_lu(m, n, nonzeros, J.vals if sparse else J[nonzeros])
            if self.lu is not None:
                return
        if rcond is None and QR_ROWS <= m <= n:
            Q, R = np.linalg.qr(self.dense.T)
            d = np.abs(np.diag(R))
            # lstsq's own cut-off (eps max(m, n) of the largest singular value), with a
            # margin: |R_ii| bound the singular values only roughly
            if d.min() > 10.0 * np.finfo(float).eps * n * d.max():
                self.qr = (Q, R)

    @property
    def dense(self) -> np.ndarray:
        """The Jacobian, dense (made so on first use where it came as nonzeros)."""
        if self._J is None:
            self._J = self._sparse.toarray()
        return self._J

    def solve(self, r: np.ndarray) -> np.ndarray:
        """The minimum-norm x with ``J x = r`` (least squares where there is none)."""
        if self.lu is not None:
            x = self.lu.solve(np.concatenate([np.zeros(self.n), r]))[:self.n]
            if np.all(np.isfinite(x)):
                return x
        if self.qr is None:
            return np.linalg.lstsq(self.dense, r, rcond=self.rcond)[0]
        Q, R = self.qr
        return Q @ solve_triangular(R, r, trans="T")


def _augmented_lu(m: int, n: int, nonzeros: tuple[np.ndarray, np.ndarray],
                  vals: np.ndarray | None):
    """Sparse LU of ``[[I, J^T], [J, 0]]`` for a sparse m x n ``J`` (None where it is
    dense or the system exactly singular), its CSC arrays assembled directly: column
    j < n holds the 1 at row j and J's column j below it, column n + i J's row i.
    ``nonzeros``: J's (rows, columns) in row-major order, ``vals`` its values there."""
    ri, ci = nonzeros
    if ri.size > SPARSE_FILL * m * n:
        return None
    # J's columns in order (rj: their rows, ascending in each): np.nonzero(J.T)'s order,
    # without a second scan of the dense J
    order = np.argsort(ci, kind="stable")
    cj, rj = ci[order], ri[order]
    per_col = np.bincount(cj, minlength=n) + 1
    per_row = np.bincount(ri, minlength=m)
    indptr = np.concatenate([[0], np.cumsum(np.concatenate([per_col, per_row]))])
    indices = np.empty(indptr[-1], dtype=np.int32)
    data = np.empty(indptr[-1])
    # the identity's 1 first in each of the first n columns, then J's column below it
    starts = indptr[:n]
    indices[starts] = np.arange(n)
    data[starts] = 1.0
    # J's column entries: after the diagonal, in the order np.nonzero gave them
    within = np.arange(cj.size) - np.concatenate([[0], np.cumsum(per_col - 1)])[cj]
    pos = starts[cj] + 1 + within
    indices[pos] = n + rj
    data[pos] = vals[order]
    # J's rows as the last m columns (entries at rows ci)
    tail = indptr[n] + np.arange(ri.size)
    indices[tail] = ci
    data[tail] = vals
    K = sp.csc_matrix((data, indices, indptr), shape=(n + m, n + m))
    try:
        return spl.splu(K)
    except RuntimeError:  # exactly singular: dependent rows, least squares instead
        return None
