"""The rank of the active constraint rows, in one place: their singular-value ratio, their
numerical rank, whether they are dependent, the free motion they leave (null space) and how
many singular values collapsed at a singular instant. One threshold each, named here.

Every decision of the package that depends on the constraints' rank goes through these:
the lock-up and jam tests of the event policy, the counts of the assembly, the free
coordinates of the fixed-step algorithm, the equilibrium start's free motion, the
singular-position logic of both integrators."""

from __future__ import annotations

import numpy as np
from scipy.linalg import null_space as _null_space
from scipy.linalg.lapack import dsbev

__all__ = ["BANDED_TRUSTED", "COLLAPSE", "RANK_TOL", "band_ratio", "collapsed", "dependent",
           "null_space", "rank", "ratio"]

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


#: A ratio from :func:`band_ratio` is trusted down to this: its eigenvalues are those of
#: J J^T, the squares of J's singular values, exact to round-off of the largest, so a ratio
#: r comes out with a relative error of about 1e-16 / r^2 (6.5e-9 at r = 7e-5 on A02 with
#: 32 loops); below it the SVD's own ratio is taken (where a singular instant is located).
BANDED_TRUSTED = 1e-4


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


def band_ratio(lower: np.ndarray) -> float:
    """:func:`ratio` of the rows J from the lower band (LAPACK's storage: ``lower[i - j, j]``
    for i >= j) of their Gram matrix J J^T, reordered to a narrow band: the square root of
    its extreme eigenvalues' ratio (LAPACK's dsbev, O(rows^2 band) against the SVD's
    O(rows^3): 72 ms for the 770 rows of A02 with 128 loops). Trusted down to
    :data:`BANDED_TRUSTED`."""
    # all eigenvalues in one call (dsbev: one reduction to tridiagonal form, then its
    # QR iteration) took a third of the time of the two selected ones (dsbevx, a
    # reduction each): 1.6 against 5.1 ms on A02 with 32 loops
    w, _, info = dsbev(lower, compute_v=0, lower=1)
    if info != 0:
        return 0.0
    lo, hi = float(w[0]), float(w[-1])
    return float(np.sqrt(lo / hi)) if hi > 0.0 and lo > 0.0 else 0.0


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
    s = singular_values(J)
    return max(int(np.sum(s < COLLAPSE * r0 * s[0])), 1) if s.size else 1
