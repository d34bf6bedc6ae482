"""The rank of the active constraint rows, in one place: their singular-value ratio, their
numerical rank, whether they are dependent, the free motion they leave (null space) and how
many singular values collapsed at a singular instant. One threshold each, named here.

Every decision of the package that depends on the constraints' rank goes through these:
the lock-up and jam tests of the event policy, the counts of the assembly, the free
coordinates of the fixed-step algorithm, the equilibrium start's free motion, the
singular-position logic of both integrators."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.linalg import eigh, eigvals_banded, qr
from scipy.linalg import null_space as _null_space
from scipy.linalg.lapack import dpbtrs

from ..core.memo import once
from ..description.records import slide_base
from . import banded, bandsvd
from .model import Model

__all__ = ["COLLAPSE", "GRAM_FROM", "RANK_TOL", "collapsed", "collapsed_band", "collapsed_gram",
           "count_collapsed", "dependent", "loop_free", "null_space", "rank", "ratio"]

#: Relative size (to the largest) below which a singular value counts as zero: the
#: numerical rank, dependent rows, the null space. Rows this close to dependent cannot be
#: told from dependent ones in double precision after the products that built them.
RANK_TOL = 1e-9
#: A singular value has collapsed at a singular instant when it is below this fraction of
#: the ratio seen on the approach to it (times the largest).
COLLAPSE = 0.1


def singular_values(J: np.ndarray) -> np.ndarray:
    """Singular values of ``J``, largest first (none for an empty matrix)."""
    return np.linalg.svd(J, compute_uv=False) if J.size else np.zeros(0)


def ratio(J: np.ndarray) -> float:
    """Smallest over largest singular value of the rows ``J`` (n_rows, n_coords): 1 for no
    rows (nothing can be dependent), 0 for more rows than coordinates (they must be) or a
    zero matrix."""
    if J.shape[0] == 0:
        return 1.0
    if J.shape[0] > J.shape[1]:
        return 0.0
    s = singular_values(J)
    return float(s[-1] / s[0]) if s.size and s[0] > 0 else 0.0


def rank(J: np.ndarray, tol: float = RANK_TOL) -> int:
    """Numerical rank of ``J``: singular values above ``tol`` times the largest."""
    s = singular_values(J)
    return int(np.sum(s > tol * s[0])) if s.size and s[0] > 0 else 0


def dependent(J: np.ndarray) -> bool:
    """True when the rows of ``J`` are (numerically) dependent."""
    return rank(J) < J.shape[0]


def null_space(J: np.ndarray, n_coords: int | None = None) -> np.ndarray:
    """Orthonormal basis of the motions the rows ``J`` leave free, (n_coords, dof)."""
    if J.shape[0] == 0:
        return np.eye(J.shape[1] if n_coords is None else n_coords)
    return _null_space(J, rcond=RANK_TOL)


def collapsed(J: np.ndarray, r0: float) -> int:
    """How many singular values of ``J`` have collapsed (below :data:`COLLAPSE` times
    ``r0``, the ratio where the approach to a singular instant was seen, times the
    largest); at least 1."""
    return count_collapsed(singular_values(J), r0)


def count_collapsed(s: np.ndarray, r0: float) -> int:
    """:func:`collapsed` from the singular values ``s`` (largest first)."""
    return max(int(np.sum(s < COLLAPSE * r0 * s[0])), 1) if s.size else 1


#: :func:`collapsed_gram` counts from the Gram matrix's eigenvalues only where the
#: threshold is at least this (times the largest singular value): they are exact to
#: round-off times the largest eigenvalue, so their square roots are to 1e-8 of the
#: largest singular value, a thousandth of this.
GRAM_FROM = 1e-5


def collapsed_gram(J: np.ndarray, r0: float, top: float) -> tuple[int, np.ndarray] | None:
    """:func:`collapsed` from the eigenvalues of ``J J^T`` (rows no more than columns)
    below the threshold squared, ``top`` being its largest eigenvalue, with an
    orthonormal basis of their eigenvectors (rows, count): the left singular vectors of
    the collapsed singular values, only those computed (with 32 loops, 194 rows, 4 ms
    against 14 ms for the SVD with every vector). None where the threshold is below
    :data:`GRAM_FROM` or no eigenvalue is under it: the SVD decides."""
    if COLLAPSE * r0 < GRAM_FROM or not top > 0.0:
        return None
    w, V = eigh(J @ J.T, subset_by_value=(-np.inf, (COLLAPSE * r0) ** 2 * top))
    return (w.size, V) if w.size else None


#: :func:`collapsed_band` iterates a block where the last collapsed eigenvalue is at most
#: this fraction of the next (each iteration gains that factor on the basis; at a singular
#: instant round-off against 1e-6 of the largest or more), from this many rows on (every
#: banded system: A02's passages with 8 loops, 50 rows, 0.63 -> 0.55 ms, with 16, 98 rows,
#: 4.2-5.3 -> 0.93 ms against the dense eigensolver, the same counts and rows), this many
#: times.
BLOCK_GAP, BLOCK_FROM, BLOCK_ITERATIONS = 1e-4, 32, 2


def collapsed_band(low: np.ndarray, perm: np.ndarray, dense: Callable[[], np.ndarray],
                   r0: float) -> tuple[int, np.ndarray] | None:
    """:func:`collapsed_gram` of a long chain, from the band of its Gram matrix ``J J^T``:
    ``low`` in LAPACK's lower band storage of J's rows reordered by ``perm`` (new row i is
    row ``perm[i]``); ``dense()``: J itself, asked for only where this falls back on
    :func:`collapsed_gram`. The band's tridiagonal form (one reduction, O(rows^2 band))
    gives the largest eigenvalue, those under the threshold and the next above it by
    bisection (all of them, by ``eigvals_banded``, took 1.5 of 3 ms with 32 loops); where
    the next is far above the last counted one (:data:`BLOCK_GAP`), an orthonormal basis
    of their eigenvectors comes from inverse iteration of a block of that many vectors on
    the band's Cholesky factor (shifted by round-off), without a dense eigensolver (at
    A02's singular instants, 32 and 128 loops: 3.2 against 7.4 ms, 46 against 125 ms;
    the same counts and rows); else :func:`collapsed_gram`."""
    m = low.shape[1]
    if m < BLOCK_FROM:  # (no band this small)
        return collapsed_gram(dense(), r0, _top(low))
    tri = bandsvd.gram_tridiagonal(low)
    top = bandsvd.eigenvalue(tri, m) if tri is not None else None
    if top is None:
        return collapsed_gram(dense(), r0, _top(low))
    k = bandsvd.count_below(tri, (COLLAPSE * r0) ** 2 * top) if top > 0.0 else None
    after = bandsvd.eigenvalue(tri, k + 1) if k is not None and 0 < k < m else None
    # a gap: the k collapsed eigenvalues all at most BLOCK_GAP of the next (or round-off
    # below zero)
    if COLLAPSE * r0 < GRAM_FROM or after is None \
            or bandsvd.count_below(tri, BLOCK_GAP * after) != k:
        return collapsed_gram(dense(), r0, top)
    c = banded.shifted_cholesky(low, 1e-14 * top)  # (round-off: J may be singular)
    if c is None:
        return collapsed_gram(dense(), r0, top)
    # a fixed start (the same on every machine), without a symmetry a chain could share
    X = np.random.default_rng(0).standard_normal((m, k))
    for it in range(BLOCK_ITERATIONS):
        X, info = dpbtrs(c, X, lower=1)
        if info != 0:
            return collapsed_gram(dense(), r0, top)
        # orthonormal at the end only: between iterations columns of unit length keep
        # the block's conditioning (the collapsed values spread by a factor of a few, the
        # rest lie 1/BLOCK_GAP above them), and a QR took half of a passage's time with
        # 128 loops (770 x 128: 10 ms each)
        X = (qr(X, mode="economic", overwrite_a=True, check_finite=False)[0]
             if it == BLOCK_ITERATIONS - 1 else X / np.linalg.norm(X, axis=0))
    basis = np.empty((m, k))
    basis[perm] = X
    return k, basis


def _top(low: np.ndarray) -> float:
    """The largest eigenvalue of the symmetric band matrix in lower band storage ``low``."""
    lam = eigvals_banded(low, lower=True, select="i", select_range=(low.shape[1] - 1,
                                                                    low.shape[1] - 1))
    return float(lam[-1]) if lam.size else 0.0


def loop_free(model: Model, act: np.ndarray) -> bool:
    """Whether the active rows ``act`` belong to joints (with their locks and drivers)
    that close no loop: each joins two bodies that no chain of the others joins already.

    Such rows have full rank at every position: each joint's rows fix its second body's
    motion relative to its first in the directions the joint does not free, so the
    Jacobian of a tree is block triangular with blocks of full rank. No singular position
    can be passed there, and the stepped-over screen has nothing to look for (a cam
    follower in flight: 3181 of the valve train's 3819 segments over 10 s). Gear rows,
    rows of another kind, or a lock beside a driver on one joint count as a loop.
    Kept per model and set of rows."""
    # (a property of the structure: kept on the model its variants share)
    return once(model.shared, ("loop_free", act.tobytes()), lambda: _loop_free(model, act))


def _loop_free(model: Model, act: np.ndarray) -> bool:
    mech = model.mech
    kinds: dict[str, set[str]] = {}  # joint (a slide as its joint) -> kinds of its rows
    for i in act:
        row = model.rows[int(i)]
        if row.kind == "body":  # a spatial body's own rows (its axes orthonormal)
            continue
        if row.kind == "driver":
            name = mech.drivers[row.name].joint
        elif row.kind in ("joint", "lock"):
            name = row.name
        else:
            return False
        kinds.setdefault(slide_base(name) or name, set()).add(row.kind)
    root: dict[str, str] = {}

    def find(x: str) -> str:
        while root.get(x, x) != x:
            x = root[x]
        return x

    for name, k in kinds.items():
        joint = mech.joints.get(name)
        if joint is None or {"lock", "driver"} <= k:
            return False
        a, b = find(joint.first_body), find(joint.second_body)
        if a == b:  # a second chain between them: a loop
            return False
        root[a] = b
    return True
