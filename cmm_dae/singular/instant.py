"""Where a motion passes a singular position: the signed smallest singular value of the
constraint Jacobian along a crossing's Gauss steps (:mod:`cmm_dae.singular`), and the
cubic Hermite interpolant those steps are read through."""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from ..core.scipy_late import brentq, minimize_scalar
from ..equations.kinematics import active_constraints
from ..equations.minnorm import SPARSE_ROWS, SparseRows
from ..equations.model import Model

__all__ = ["grid_bracket", "hermite", "interval_minimum", "null_vectors",
           "parabola_minimum", "singular_instant"]


def hermite(t0: float, q0: np.ndarray, v0: np.ndarray, t1: float, q1: np.ndarray,
            v1: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """The cubic Hermite interpolant of q with q' = v between two step ends, and its
    derivative, at t (both O(h^4) and O(h^3) accurate on a smooth motion)."""
    h = t1 - t0
    s = (t - t0) / h
    s2, s3 = s * s, s * s * s
    q = (2 * s3 - 3 * s2 + 1) * q0 + (s3 - 2 * s2 + s) * h * v0 + (3 * s2 - 2 * s3) * q1 \
        + (s3 - s2) * h * v1
    dq = (6 * s2 - 6 * s) / h * (q0 - q1) + (3 * s2 - 4 * s + 1) * v0 + (3 * s2 - 2 * s) * v1
    return q, dq


def null_vectors(model: Model, p: np.ndarray, q: np.ndarray, t: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The left (over all constraint rows, zero on the inactive ones) and right singular
    vectors of the active constraint Jacobian's smallest singular value at q: by the dense
    SVD, or on a long chain by inverse iteration on ``J J^T`` from J's nonzeros
    (:func:`_smallest_sparse`: A02 with 128 loops, 770 x 771 rows, 150 ms each by the SVD,
    3 s of a 2-s run's crossings)."""
    act = model.active_rows(p)
    J = active_constraints(model, q, t, p, act).Phi_q
    large = isinstance(J, SparseRows) and J.shape[0] >= SPARSE_ROWS
    got = _smallest_sparse(J) if large else None
    if got is None:
        Jd = J.toarray() if isinstance(J, SparseRows) else J
        U, _, Vt = np.linalg.svd(Jd)
        k = min(Jd.shape) - 1
        got = U[:, k], Vt[k]
    w = np.zeros(model.m)
    w[act] = got[0]
    return w, got[1]


def _smallest_sparse(J: SparseRows, iterations: int = 30
                     ) -> tuple[np.ndarray, np.ndarray] | None:
    """The smallest singular value's left and right vectors (u, n with J n = sigma u,
    sigma >= 0) of a wide sparse J by inverse iteration on ``J J^T`` (sparse LU); None
    where it does not settle (the dense SVD then)."""
    m, nq = J.shape
    A = sp.csr_matrix((J.vals, (J.rows, J.cols)), shape=(m, nq))
    try:
        lu = spl.splu((A @ A.T).tocsc())
    except RuntimeError:  # exactly singular: the dense SVD
        return None
    # at the instant itself the collapsing singular values are round-off (A02 with 128
    # loops: 128 of them below 1e-12 of the largest): no vector of theirs is better than
    # another, and the SVD's choice is kept
    floor = 1e-26 * float(np.max(np.abs(J.vals))) ** 2
    u = np.ones(m) / np.sqrt(m)
    lam = np.inf
    for _ in range(iterations):
        x = lu.solve(u)
        norm = float(np.linalg.norm(x))
        if not np.isfinite(norm) or norm == 0.0:
            return None
        u_new = x / norm
        lam_new = 1.0 / norm  # |J^T u|^2 for the converged u
        if lam_new <= floor:
            return None
        if abs(lam_new - lam) <= 1e-13 * lam_new and abs(float(u_new @ u)) > 1.0 - 1e-14:
            u = u_new
            break
        u, lam = u_new, lam_new
    else:
        return None
    n = A.T @ u
    size = float(np.linalg.norm(n))
    return (u, n / size) if size > 0.0 else None


def _signed(model: Model, p: np.ndarray, w: np.ndarray, n: np.ndarray, q: np.ndarray,
            t: float) -> float:
    """``w . (Phi_q n)``: the smallest singular value with a sign, for w, n held fixed;
    it passes zero where the motion passes the singular position."""
    act = model.active_rows(p)
    return float(w[act] @ (active_constraints(model, q, t, p, act).Phi_q @ n))


def singular_instant(model: Model, p: np.ndarray, ends: list, t_guess: float) -> float:
    """The instant the motion through the step ends ``ends`` [(t, q, v)] passes the
    singular position: the root of the signed smallest singular value along their
    Hermite interpolant nearest ``t_guess``, with the null vectors taken again at the root
    (their error then enters squared); ``t_guess`` where no step brackets one."""
    i = int(np.argmin([abs(e[0] - t_guess) for e in ends]))
    t_s = t_guess
    w, n = null_vectors(model, p, ends[i][1], ends[i][0])
    for _ in range(3):
        g = [_signed(model, p, w, n, e[1], e[0]) for e in ends]
        brackets = [k for k in range(len(ends) - 1) if g[k] * g[k + 1] <= 0.0 and
                    ends[k + 1][0] > ends[k][0]]
        if not brackets:
            return t_s
        k = min(brackets, key=lambda k: abs(0.5 * (ends[k][0] + ends[k + 1][0]) - t_s))
        a, b = ends[k], ends[k + 1]
        if g[k] == 0.0 or g[k + 1] == 0.0:
            t_s = a[0] if g[k] == 0.0 else b[0]
        else:
            t_s = brentq(lambda tt, a=a, b=b, w=w, n=n: _signed(
                model, p, w, n, hermite(*a, *b, tt)[0], tt), a[0], b[0], xtol=1e-15,
                rtol=4.0 * np.finfo(float).eps)
        w, n = null_vectors(model, p, hermite(*a, *b, t_s)[0], t_s)
    return t_s


def parabola_minimum(f, pts: dict[float, float], lo: float, hi: float, xatol: float = 1e-9,
                     most: int = 8) -> float | None:
    """Successive parabolic interpolation of ``f`` in [lo, hi] from the points ``pts``
    (x -> f(x), at least three; the evaluations are added to it): the minimum's x once a
    step is shorter than ``xatol``, None where a parabola is not convex or leaves the
    interval, or after ``most`` steps. For a singular-value ratio's square near a passage
    (:mod:`cmm_dae.simulation.passage`), which is a parabola about its minimum."""
    for _ in range(most):
        (x0, f0), (x1, f1), (x2, f2) = sorted(sorted(pts.items(), key=lambda e: e[1])[:3])
        den = (x1 - x0) * (f1 - f2) - (x1 - x2) * (f1 - f0)
        if not den < 0.0:  # not a convex parabola through the three
            return None
        xv = x1 - 0.5 * ((x1 - x0) ** 2 * (f1 - f2) - (x1 - x2) ** 2 * (f1 - f0)) / den
        if not lo <= xv <= hi:
            return None
        best = min(pts, key=pts.__getitem__)
        if xv in pts or abs(xv - best) <= xatol:
            return best
        pts[xv] = f(xv)
    return None


def grid_bracket(s: np.ndarray, grid: np.ndarray) -> tuple[int, float, float]:
    """The lowest point of a measure ``grid`` at the increasing fractions ``s`` of an
    interval (strictly inside it), and the fractions of its neighbours, the interval's
    ends where it has none: (index, lower, upper)."""
    k = int(np.argmin(grid))
    return (k, float(s[k - 1]) if k > 0 else 0.0,
            float(s[k + 1]) if k < s.size - 1 else 1.0)


def interval_minimum(at, s: np.ndarray, grid: np.ndarray) -> tuple[float, float]:
    """The smallest singular-value ratio ``at(x)`` on the samples' interpolant between two
    samples and where it lies (fraction x of the interval), from a measure ``grid`` of it
    at the increasing fractions ``s`` whose smallest value lies where the ratio's does
    (:mod:`cmm_dae.simulation.passage`)."""
    k, lo_s, hi_s = grid_bracket(s, grid)
    # the ratio dips in a V to zero: the grid may step over its tip, a search between the
    # grid's neighbours finds it. On the ratio's square, a parabola there (and smooth where
    # it stays clear of zero), successive parabolas through the three best points converge
    # in 4-6 ratios (A02 with 8 and 32 loops), Brent's bounded search took 9-10 with the
    # grid point's; Brent where the parabolas do not close in
    def square(x: float) -> float:
        return at(float(x)) ** 2

    pts = {float(x): square(x) for x in (lo_s, s[k], hi_s)}
    if parabola_minimum(square, pts, lo_s, hi_s) is None:
        opt = minimize_scalar(square, bounds=(lo_s, hi_s), method="bounded",
                              options={"xatol": 1e-9})
        pts[float(opt.x)] = float(opt.fun)
    x = min(pts, key=pts.__getitem__)
    return x, math.sqrt(pts[x])
