"""The instant a long chain's motion passes a singular position, by Newton's method on
the signed smallest singular value, where the exact singular-value ratio is costly.

Between two samples the constraint Jacobian of a banded mechanism (a chain of loops) is
followed along the samples' interpolant. At a trial instant the left singular vectors of
its smallest singular values come from inverse iteration on its Gram matrix ``J J^T``
(a banded Cholesky, O(rows band^2)), the right one from ``J^T w``; with the two held
fixed, ``w . J(x) n`` is the smallest singular value with a sign, which passes zero at
the instant, and its slope is that value's derivative. Each Newton step takes the
vectors again at the new trial, so the steps converge quadratically to where the
smallest singular value is zero, where several of them are at once too (a chain of
identical loops loses as many ranks as it has loops at the same instant: the vectors are
then any mix of theirs, and ``w . J n`` still passes zero there).

At the instant found, ``|J^T w|`` (w of unit length) bounds the smallest singular value
from above and a few power iterations bound the largest from below, so their quotient
bounds the ratio from above; where that bound is not below :data:`TIP_RATIO` the exact
ratio (:func:`~cmm_dae.equations.kinematics.singular_ratio`, O(rows^2 band)) is taken
there. The instant is kept only where the ratio is below it (the motion passes the
singular position itself, and the ratio's minimum is there); else the caller searches
the ratio's minimum as before.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.linalg.lapack import dpbtrs

from ..core.memo import once
from ..equations import banded
from ..equations.kinematics import active_nonzeros, active_values_at, gram_band
from ..equations.model import Model
from .instant import grid_bracket, hermite, interval_minimum

__all__ = ["TIP_RATIO", "interval_instant", "largest_singular", "newton_tip", "ratio_above",
           "sample_instant", "tip_band", "tip_ratio"]

#: The exact ratio at the instant below which it is taken as the ratio's minimum (the
#: motion passes through the singular position; round-off leaves about 1e-14 there).
TIP_RATIO = 1e-9
#: Newton steps at most: from the coarse grid's point nearest the instant (at most 1/32 of
#: the interval from it), three steps reach round-off (A02 with 8 and 32 loops: the
#: smallest singular value 9.5e-5, 1.4e-8, 4.1e-15, and 1.2e-4, 6.1e-8, 8.7e-13 where 32
#: loops cross within 6e-9 s of each other at rtol 1e-3; a fourth step, from vectors that
#: round-off decides, goes up again).
STEPS = 8
#: The step (fraction of the interval) of the difference that gives the slope.
DIFF = 1e-6
#: Newton's steps stop where the smallest singular value is at most this many units of
#: round-off (of J's largest row norm): the instant, to the precision the vectors allow
#: (A02 reaches 5 to 2000 units there; a step more went up again).
FLOOR = 4096
#: Power iterations for the largest singular value's lower bound (its Rayleigh quotient
#: rises to it from below; A02's, 8 to 128 loops, are within 3.2e-3 of it after these).
POWER = 20
#: Inverse iterations for :func:`ratio_above`: where many singular values collapse together
#: (a chain of identical loops) and spread at a sample next to the instant, each one
#: draws the vector a factor (their spread) squared further to the least of them.
BOUND_ITERATIONS = 6
#: ... and power iterations for its largest singular value (A02, 8 to 128 loops: the bound
#: within 0.82 % of the ratio with these; 0.25 % with :data:`POWER`).
BOUND_POWER = 8

#: Inverse iterations a step (the collapsed singular values are 1e-3 or less of the
#: others there: each iteration gains that factor or more).
ITERATIONS = 2


def tip_band(model: Model, act: np.ndarray) -> banded.BandedSchur:
    """The banded structure of the active rows' Gram matrix (:func:`gram_band`'s, where it
    has one), else at any size and width (a small system's band is the whole matrix: a
    single loop's instant by Newton's method too, not on grids of exact ratios, 2.6 of
    7.1 ms a 2-s run of A02 with one loop), kept per model and row set."""
    band = gram_band(model, act)
    if band is not None:
        return band
    return once(model, ("tip band", act.tobytes()), lambda: banded.structure(
        *active_nonzeros(model, act, every=True), act.size, limited=False))


def interval_instant(model: Model, p: np.ndarray, ends: tuple, act: np.ndarray,
                     at: Callable[[float], float], s: np.ndarray, grid: np.ndarray,
                     refine: Callable | None = None) -> tuple[float, float]:
    """:func:`~.instant.interval_minimum` (the smallest singular-value ratio ``at(x)`` on
    the samples' interpolant between two samples, ``ends``: t, q, v at each, and its
    fraction x of the interval, from a measure ``grid`` of it at the fractions ``s``),
    found on a banded mechanism by :func:`newton_tip` from the grid's lowest point where
    the motion passes the singular position itself, the ratio there an upper bound (an
    exact ratio where the bound is not small enough): with 32 loops the search took six
    exact ratios of 2 ms each. ``refine(s, grid)``: a finer grid,
    asked for only where Newton's method from this one does not find the instant (and
    for the search it falls back on)."""
    band = tip_band(model, act) if 0 < act.size <= model.nq else None

    def values_at(x: float) -> np.ndarray:
        tx = float(ends[0] + x * (ends[3] - ends[0]))
        return active_values_at(model, act, hermite(*ends, tx)[0], tx, p)

    for _ in range(2 if band is not None else 0):
        k, lo, hi = grid_bracket(s, grid)
        got = newton_tip(values_at, band, model.nq, lo, hi, float(s[k]))
        if got is not None:
            x, sigma = got  # (an upper bound on the ratio, then the ratio where need be)
            r = tip_ratio(values_at(x), sigma, band, model.nq, lambda x=x: at(x))
            if r < TIP_RATIO:
                return x, r
        if refine is None:
            break
        s, grid, refine = *refine(s, grid), None
    if refine is not None:
        s, grid = refine(s, grid)
    return interval_minimum(at, s, grid)


def sample_instant(model: Model, p: np.ndarray, centre: int, sides: list[tuple[int, tuple]],
                   act: np.ndarray, ats: list[Callable[[float], float]]
                   ) -> tuple[int, float, float] | None:
    """The instant of a passage next to the sample ``centre`` (a dip of the ratio), by
    :func:`newton_tip` from that sample itself across the intervals beside it, without
    the grids :func:`interval_instant` starts from (with 8 loops each grid cost as much
    as the steps it saves).

    ``sides``: the intervals (index of their first sample, ``ends``: t, q, v at each)
    beside ``centre``, one or both; ``ats``: the ratio on each, as a function of the
    fraction of it. Returns (interval, fraction, ratio there) where the ratio is below
    :data:`TIP_RATIO` (shown as in :func:`interval_instant`), else None."""
    band = tip_band(model, act) if 0 < act.size <= model.nq else None
    if band is None or not sides:
        return None
    # x < 0 on the interval before the sample (fraction 1 + x), x >= 0 on the one after
    left = [(a, e, at) for (a, e), at in zip(sides, ats, strict=True) if a < centre]
    right = [(a, e, at) for (a, e), at in zip(sides, ats, strict=True) if a >= centre]

    def side(x: float) -> tuple[int, tuple, Callable, float]:
        a, ends, at = (left if x < 0.0 or not right else right)[0]
        return a, ends, at, (1.0 + x if a < centre else x)

    def values_at(x: float) -> np.ndarray:
        _, ends, _, f = side(x)
        tx = float(ends[0] + f * (ends[3] - ends[0]))
        return active_values_at(model, act, hermite(*ends, tx)[0], tx, p)

    got = newton_tip(values_at, band, model.nq, -1.0 if left else 0.0,
                     1.0 if right else 0.0, 0.0)
    if got is None:
        return None
    x, sigma = got
    a, _, at, f = side(x)
    r = tip_ratio(values_at(x), sigma, band, model.nq, lambda: at(f))
    return (a, f, r) if r < TIP_RATIO else None


def tip_ratio(vals: np.ndarray, sigma: float, band: banded.BandedSchur, nq: int,
              exact: Callable[[], float]) -> float:
    """The ratio at Newton's instant (J's structural nonzeros ``vals``, ``sigma`` an upper
    bound on its smallest singular value): ``sigma`` over a lower bound on the largest,
    J's largest row norm first (one product; enough at a passage, where sigma is
    round-off), then :func:`largest_singular`'s; ``exact()`` where neither shows it
    below :data:`TIP_RATIO`."""
    for bound in (_largest_row, lambda vals, band: largest_singular(vals, band, nq)):
        big = bound(vals, band)
        if big > 0.0 and sigma / big < TIP_RATIO:
            return sigma / big
    return exact()


def ratio_above(vals: np.ndarray, band: banded.BandedSchur, nq: int) -> float | None:
    """An upper bound on J's singular-value ratio (structural nonzeros ``vals``): ``|J^T
    w|`` (w of unit length from :func:`_left_vector`'s inverse iteration) over
    :func:`largest_singular`'s lower bound, close to the ratio where the smallest
    singular values are far below the rest (next to a passage: within 0.82 % on A02; J's
    largest row norm was 2.8 times below the largest singular value with 32 loops); one
    banded Cholesky and products, where the exact ratio reduces the band to tridiagonal
    form. None where it cannot be factored."""
    w = _left_vector(vals, band, BOUND_ITERATIONS)
    big = largest_singular(vals, band, nq, BOUND_POWER)
    if w is None or not big > 0.0:
        return None
    return float(np.linalg.norm(_jt(vals, band, w, nq))) / big


def _largest_row(vals: np.ndarray, band: banded.BandedSchur) -> float:
    """J's largest row norm: a lower bound on its largest singular value."""
    return float(np.sqrt(np.max(np.bincount(band.rows, weights=vals * vals), initial=0.0)))


def newton_tip(values_at: Callable[[float], np.ndarray], band: banded.BandedSchur,
               nq: int, lo: float, hi: float, x0: float) -> tuple[float, float] | None:
    """Where the smallest singular value of the banded Jacobian ``J(x)`` is zero, by
    Newton's method from ``x0`` inside ``[lo, hi]``.

    Parameters
    ----------
    values_at : callable
        x -> J(x)'s structural nonzeros (at ``band.rows``, ``band.cols``), x a fraction
        of the sample interval.
    band : BandedSchur
        The Gram matrix's banded structure (:func:`~cmm_dae.equations.banded.structure`).
    nq : int
        J's columns.
    lo, hi, x0 : float
        The bracket and the start (fractions of the interval).

    Returns
    -------
    tuple of float, or None
        The instant's fraction of the interval: the trial where the smallest singular
        value was least, once a step no longer lowers it; and ``|J^T w|`` there, an
        upper bound on that value. None where a step leaves the bracket, a Gram matrix
        cannot be factored or the steps do not settle.
    """
    x, best = x0, (np.inf, x0)
    for _ in range(STEPS):
        vals = values_at(x)
        w = _left_vector(vals, band)
        if w is None:
            return None
        u = _jt(vals, band, w, nq)
        norm = float(np.linalg.norm(u))  # the smallest singular value at x
        if not norm < best[0]:
            # at the instant the value is round-off (or the least of a near miss), the
            # vectors any mix of the collapsed ones, and a step from there lands further
            return best[1], best[0]
        best = (norm, x)
        if norm <= FLOOR * np.finfo(float).eps * _largest_row(vals, band):
            return x, norm  # round-off: a step from here lands anywhere near
        weights = w[band.rows] * (u[band.cols] / norm)  # w . J n = values . weights
        # (a forward difference: its error, h times the value's curvature, slows the
        # steps' quadratic convergence by a factor h only)
        h = DIFF * (hi - lo)
        slope = float((values_at(x + h) - vals) @ weights) / h
        if not np.isfinite(slope) or slope == 0.0:
            return None
        x -= norm / slope
        if not lo <= x <= hi:
            return None
    return None


def largest_singular(vals: np.ndarray, band: banded.BandedSchur, nq: int,
                     iterations: int = POWER) -> float:
    """A lower bound on the largest singular value of J (structural nonzeros ``vals`` at
    ``band.rows``, ``band.cols``; ``nq`` columns): ``|J^T x|`` for the unit x that
    ``iterations`` power iterations on ``J J^T`` reach from a fixed start."""
    x = 1.0 + 0.5 * np.sin(np.arange(band.m))
    for _ in range(iterations):
        x = np.bincount(band.rows, weights=vals * _jt(vals, band, x, nq)[band.cols],
                        minlength=band.m)  # J J^T x
        size = float(np.linalg.norm(x))
        if not size > 0.0:
            return 0.0
        x /= size
    return float(np.linalg.norm(_jt(vals, band, x, nq)))


def _jt(vals: np.ndarray, band: banded.BandedSchur, x: np.ndarray, nq: int) -> np.ndarray:
    """``J^T x`` for J with structural nonzeros ``vals`` (at ``band.rows``,
    ``band.cols``) and ``nq`` columns."""
    return np.bincount(band.cols, weights=vals * x[band.rows], minlength=nq)


def _left_vector(vals: np.ndarray, band: banded.BandedSchur, iterations: int = ITERATIONS
                 ) -> np.ndarray | None:
    """A unit vector in the span of ``J J^T``'s eigenvectors of its smallest eigenvalues
    (J's left singular vectors, in J's row order), by ``iterations`` of inverse iteration
    on the banded Gram matrix shifted by round-off times its largest diagonal entry
    (positive definite also where J is singular); None where it cannot be factored."""
    low = banded.lower_blocks(band, vals[:, None])
    c = banded.shifted_cholesky(low, 1e-14 * float(np.max(low[0])))
    if c is None:
        return None
    # (a fixed start without symmetry: a chain's identical loops give symmetric vectors)
    y = 1.0 + 0.5 * np.sin(np.arange(band.m))
    for _ in range(iterations):
        y, info = dpbtrs(c, y, lower=1)
        if info != 0:
            return None
        y /= np.linalg.norm(y)
    w = np.empty(band.m)
    w[band.perm] = y  # new row i is old row perm[i]
    return w
