"""The singular values of a large constraint Jacobian from its band: a chain of loops has
Phi_q banded once its rows and columns are reordered, and LAPACK reduces a band matrix to
bidiagonal form in O(n^2 band) (``dgbbrd``) and takes a bidiagonal's singular values to
high relative accuracy (``dlasq1``; the extreme ones alone by bisection, ``dstebz``, from
:data:`BISECT_FROM` rows on), where the dense SVD costs O(n^3).

The two routines are not wrapped by ``scipy.linalg.lapack``; they are called through the
function pointers that ``scipy.linalg.cython_lapack`` exports (the LAPACK scipy itself is
built with). Where that is not available, :func:`ratio` returns None and the caller takes
the dense SVD.

Measured on the Jacobians of A02's crossings (194 x 195 rows with 32 loops, 770 x 771
with 128): the ratio within 3.6e-17 of the SVD's (both are backward stable: their error
is round-off times the largest singular value), in 2.3 against 4.3 ms with 32 loops and
30 against 138 ms with 128 (with dqds; 1.5 and 21 ms with bisection and Phi_q's
nonzeros evaluated alone).
"""

from __future__ import annotations

import ctypes
import functools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.linalg import cython_lapack, lapack
from scipy.sparse.csgraph import reverse_cuthill_mckee

from . import banded

__all__ = ["GRAM_RATIO_FROM", "BandSVD", "above", "count_below", "eigenvalue", "gram_ratio",
           "gram_tridiagonal", "ratio", "structure"]


@dataclass(frozen=True)
class BandSVD:
    """Where Phi_q's structural nonzeros go in LAPACK's band storage of its reordered rows
    and columns (``ab[j, ku + i - j]`` for new row i and column j, C order)."""

    rows: np.ndarray   # (nnz,) row of each structural nonzero (of the rows taken)
    cols: np.ndarray   # (nnz,) its column
    flat: np.ndarray   # (nnz,) its flat index in the band storage (n, kl + ku + 1)
    m: int
    n: int
    kl: int
    ku: int


def structure(rows: np.ndarray, cols: np.ndarray, m: int, n: int) -> BandSVD:
    """The band structure of an m x n matrix with structural nonzeros at (rows, cols): rows
    and columns ordered together by reverse Cuthill-McKee on the graph of the matrix and
    its transpose ([[0, J], [J^T, 0]]), each in the order it takes there."""
    a = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(m, n))
    order = np.asarray(reverse_cuthill_mckee(sp.bmat([[None, a], [a.T, None]]).tocsr(),
                                             symmetric_mode=True), dtype=int)
    rpos, cpos = np.empty(m, dtype=int), np.empty(n, dtype=int)
    rpos[order[order < m]] = np.arange(m)
    cpos[order[order >= m] - m] = np.arange(n)
    i, j = rpos[rows], cpos[cols]
    kl = int(max(np.max(i - j, initial=0), 0))
    ku = int(max(np.max(j - i, initial=0), 0))
    return BandSVD(rows, cols, j * (kl + ku + 1) + ku + i - j, m, n, kl, ku)


def _address(routine: str) -> int:
    """The address of a LAPACK routine that ``scipy.linalg.cython_lapack`` exports
    (KeyError, AttributeError or ValueError where it does not)."""
    cap = cython_lapack.__pyx_capi__[routine]
    name = ctypes.pythonapi.PyCapsule_GetName
    name.restype, name.argtypes = ctypes.c_char_p, [ctypes.py_object]
    pointer = ctypes.pythonapi.PyCapsule_GetPointer
    pointer.restype, pointer.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
    return pointer(cap, name(cap))


def _ints(*xs: int) -> list:
    """Integer arguments for LAPACK, which takes every one by reference."""
    return [ctypes.byref(ctypes.c_int(x)) for x in xs]


@functools.cache
def _lapack() -> tuple | None:
    """(dgbbrd, dlasq1) as ctypes functions, or None where scipy does not export them."""
    try:
        i, p = ctypes.POINTER(ctypes.c_int), ctypes.c_void_p
        gbbrd = ctypes.CFUNCTYPE(None, ctypes.c_char_p, i, i, i, i, i, p, i, p, p, p, i, p, i,
                                 p, i, p, i)(_address("dgbbrd"))
        lasq1 = ctypes.CFUNCTYPE(None, i, p, p, p, i)(_address("dlasq1"))
    except (AttributeError, KeyError, ValueError):
        return None
    return gbbrd, lasq1


def ratio(st: BandSVD, values: np.ndarray, gram: np.ndarray | None = None) -> float | None:
    """Smallest over largest singular value of the matrix whose structural nonzeros are
    ``values`` (at ``st.rows``, ``st.cols``); 0 for a zero matrix; None where LAPACK's
    routines are not available or fail (non-finite values): the dense SVD decides.
    ``gram``: the matrix's Gram matrix ``J J^T`` in LAPACK's lower band storage, whose
    extreme eigenvalues give the ratio first (:func:`gram_ratio`), kept where it is at
    least :data:`GRAM_RATIO_FROM`."""
    if gram is not None:
        r = gram_ratio(gram)
        if r is not None and r >= GRAM_RATIO_FROM:
            return r
    routines = _lapack()
    if routines is None or not np.all(np.isfinite(values)):
        return None
    gbbrd, lasq1 = routines
    m, n, kl, ku = st.m, st.n, st.kl, st.ku
    k = min(m, n)
    if k == 0:
        return 1.0
    ab = np.zeros((n, kl + ku + 1))  # Fortran's (kl + ku + 1, n)
    ab.flat[st.flat] = values
    d = np.empty(k)
    e = np.zeros(max(k - 1, 1))
    work = np.empty(max(2 * max(m, n), 4 * k))
    one = np.zeros(1)  # Q, P^T and C are not formed
    info = ctypes.c_int(0)

    gbbrd(b"N", *_ints(m, n, 0, kl, ku), ab.ctypes.data, *_ints(kl + ku + 1), d.ctypes.data,
          e.ctypes.data, one.ctypes.data, *_ints(1), one.ctypes.data, *_ints(1),
          one.ctypes.data, *_ints(1), work.ctypes.data, ctypes.byref(info))
    if info.value != 0:
        return None
    if k >= BISECT_FROM:
        return _extreme_ratio(d, e[:k - 1])
    lasq1(*_ints(k), d.ctypes.data, e.ctypes.data, work.ctypes.data, ctypes.byref(info))
    if info.value != 0:
        return None
    # dlasq1 leaves the singular values in decreasing order
    return float(d[-1] / d[0]) if d[0] > 0.0 else 0.0


#: Bidiagonals from this size on give their extreme singular values by bisection
#: (:func:`_extreme_ratio`), not all of them by dqds (``dlasq1``, O(k^2)): with 32 loops
#: (k = 194) 0.44 against 0.84 ms, with 128 (k = 770) 1.8 against 11 ms; with 8 (k = 50)
#: dqds is faster (82 against 110 us).
BISECT_FROM = 100


def _extreme_ratio(d: np.ndarray, e: np.ndarray) -> float | None:
    """Smallest over largest singular value of the upper bidiagonal with diagonal ``d`` and
    superdiagonal ``e``: the largest and the k-th largest eigenvalue of its Golub-Kahan
    form (zero diagonal, off-diagonal d1, e1, d2, ..., eigenvalues +-sigma), by LAPACK's
    bisection (``dstebz``) to full relative accuracy, as LAPACK's ``dbdsvdx`` takes them."""
    k = d.size
    off = np.empty(2 * k - 1)
    off[0::2], off[1::2] = d, e
    zero = np.zeros(2 * k)
    top, low = eigenvalue((zero, off), 2 * k), eigenvalue((zero, off), k + 1)
    if top is None or low is None:
        return None
    return max(low, 0.0) / top if top > 0.0 else 0.0


#: :func:`gram_ratio` is taken for the ratio from this value on: the Gram matrix's
#: eigenvalues are exact to round-off times the largest (with 128 loops, 770 rows, a bound
#: of 1e-13 of it), so the ratio to 1e-13 / (2 ratio^2) of itself, 5e-6 here; below, the
#: band's bidiagonal form decides (the ratio to round-off of the largest singular value).
GRAM_RATIO_FROM = 1e-4


@functools.cache
def _sbtrd():
    """LAPACK's ``dsbtrd`` (a symmetric band matrix to tridiagonal form) as a ctypes
    function, or None where scipy does not export it."""
    try:
        i, p = ctypes.POINTER(ctypes.c_int), ctypes.c_void_p
        return ctypes.CFUNCTYPE(None, ctypes.c_char_p, ctypes.c_char_p, i, i, p, i, p, p, p,
                                i, p, i)(_address("dsbtrd"))
    except (AttributeError, KeyError, ValueError):
        return None


def gram_tridiagonal(low: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The tridiagonal form (diagonal, off-diagonal) with the eigenvalues of the symmetric
    band matrix in LAPACK's lower band storage ``low`` (bw + 1, rows), by ``dsbtrd``
    (O(rows^2 band), no vectors); None where the routine is not available or fails."""
    sbtrd = _sbtrd()
    m = low.shape[1]
    if sbtrd is None or m == 0 or not np.all(np.isfinite(low)):
        return None
    ab = np.array(low, order="F")  # (overwritten)
    d, e, work, one = np.empty(m), np.zeros(max(m - 1, 1)), np.empty(m), np.zeros(1)
    info = ctypes.c_int(0)

    sbtrd(b"N", b"L", *_ints(m, ab.shape[0] - 1), ab.ctypes.data, *_ints(ab.shape[0]),
          d.ctypes.data, e.ctypes.data, one.ctypes.data, *_ints(1), work.ctypes.data,
          ctypes.byref(info))
    return (d, e[:m - 1]) if info.value == 0 else None


def eigenvalue(tri: tuple[np.ndarray, np.ndarray], i: int) -> float | None:
    """The i-th smallest eigenvalue (from 1) of the symmetric tridiagonal ``tri``
    (diagonal, off-diagonal), by LAPACK's bisection (``dstebz``) to full relative
    accuracy; None where it fails."""
    got = lapack.dstebz(tri[0], tri[1], 2, 0.0, 0.0, i, i, 2.0 * np.finfo(float).tiny, b"E")
    return float(got[1][0]) if got[-1] == 0 else None


def count_below(tri: tuple[np.ndarray, np.ndarray], x: float) -> int | None:
    """How many eigenvalues of the tridiagonal ``tri`` are at most ``x``: the Sturm counts
    of LAPACK's bisection (``dstebz``), exact whatever its tolerance, which is set to x
    so that the eigenvalues themselves are not refined (32 of them clustered at 1e-15
    took 2.4 ms to full accuracy); None where it fails."""
    d, e = tri
    got = lapack.dstebz(d, e, 1, -np.inf, x, 0, 0, max(abs(x), np.finfo(float).tiny), b"E")
    return int(got[0]) if got[-1] == 0 else None


def gram_ratio(low: np.ndarray) -> float | None:
    """The square root of the smallest over the largest eigenvalue of the symmetric
    positive semidefinite band matrix in LAPACK's lower band storage ``low`` (bw + 1,
    rows): a Gram matrix ``J J^T``'s, J's singular-value ratio. Reduced to tridiagonal
    form (:func:`gram_tridiagonal`, as the bidiagonal form of J, without J's columns and
    with half the work: 7 against 22 ms with 128 loops), its extreme eigenvalues by
    bisection. None where the routine is not available or fails."""
    tri = gram_tridiagonal(low)
    if tri is None:
        return None
    top, low = eigenvalue(tri, tri[0].size), eigenvalue(tri, 1)
    if top is None or low is None or not top > 0.0:
        return None
    return float(np.sqrt(max(low, 0.0) / top))


def above(low: np.ndarray, r: float) -> bool:
    """Whether the square root of the smallest over the largest eigenvalue of the symmetric
    positive semidefinite band matrix in LAPACK's lower band storage ``low`` (a Gram
    matrix ``J J^T``: J's singular-value ratio) is certainly above ``r``. The largest
    eigenvalue is at most the largest absolute row sum g (Gershgorin); a Cholesky
    factorization of the matrix less ``r^2 g`` succeeds only where every eigenvalue is
    above that, to its round-off (at most ``(bw + 1) eps g`` times a small constant, taken
    16): one factorization, O(rows band^2), against the ratio's O(rows^2 band). False
    where that is not shown (the ratio may still be above ``r``)."""
    a, m = np.abs(low), low.shape[1]
    rows = a[0].copy()
    for k in range(1, low.shape[0]):  # the band's rows, each entry on both sides
        rows[k:] += a[k, :m - k]
        rows[:m - k] += a[k, :m - k]
    g = float(rows.max(initial=0.0))
    if not (np.isfinite(g) and g > 0.0):
        return False
    shift = r * r * g + 16.0 * low.shape[0] * np.finfo(float).eps * g
    return banded.shifted_cholesky(low, -shift) is not None
