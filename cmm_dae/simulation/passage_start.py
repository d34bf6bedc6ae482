"""Where the crossing of a singular position IDA stepped over starts: the last sample before
it whose singular-value ratio is at least :data:`START_RATIO` (:mod:`.passage`); and the
walks that find the samples next to one: a segment's ends asked of the log determinant,
its dips followed down the exact ratio."""

from __future__ import annotations

import math

import numpy as np

from ..equations import banded, bandsvd
from ..equations.kinematics import active_values_at, gram_band, singular_ratio
from ..equations.model import Model
from ..singular.tip import ratio_above

__all__ = ["START_RATIO", "SampleRatios", "dips", "end_may_dip", "falling_to_zero",
           "predicted_start", "start_before"]

#: The crossing starts from the last sample before the passage whose ratio is at least
#: this (closer, the Gauss steps' nodes would sit where round-off rules the accelerations).
START_RATIO = 0.01


def start_before(a: int, r, guess: int | None = None) -> int:
    """The last sample at or before ``a`` whose ratio ``r(i)`` is at least :data:`START_RATIO`
    (0 where none is): 1, 2, 4, ... samples back, then the last gap halved, the ratio rising
    back from a passage (sample by sample, A02 with 128 loops took 146 ratios of 47 ms).
    A ``guess`` (:func:`predicted_start`) that is the answer is confirmed by two ratios;
    else the search goes on from it."""
    if r(a) >= START_RATIO or a == 0:
        return a
    below = a  # r(below) < START_RATIO
    if guess is not None and 0 <= guess < a:
        if r(guess) >= START_RATIO:
            if r(guess + 1) < START_RATIO:
                return guess
            return _halve(guess + 1, a, r)
        below = guess
    step = 1
    while (j := max(below - step, 0)) > 0 and r(j) < START_RATIO:
        below, step = j, 2 * step
    if r(j) < START_RATIO:
        return 0
    return _halve(j, below, r)


def _halve(j: int, below: int, r) -> int:
    """The last sample before ``below`` with ``r`` at least :data:`START_RATIO`, given
    ``r(j) >= START_RATIO > r(below)``."""
    while below - j > 1:
        mid = (j + below) // 2
        if r(mid) >= START_RATIO:
            j = mid
        else:
            below = mid
    return j


def predicted_start(a: int, logdet: np.ndarray | None, ratios: dict[int, float]
                     ) -> int | None:
    """Where :func:`start_before` will likely end, from log det(J J^T) at the samples
    (``logdet``, from the stepped-over screen): next to a passage the ratio changes as exp(kappa
    log det), kappa = 1 / (2 k) for k singular values collapsing together, fitted on the
    last two samples at or before ``a`` whose ratios are known (``ratios``: the dip's). None
    where that cannot be fitted."""
    if logdet is None:
        return None
    known = [i for i in sorted(ratios) if i <= a and ratios[i] > 0.0
             and np.isfinite(logdet[i])]
    if len(known) < 2 or logdet[known[-2]] == logdet[known[-1]]:
        return None
    i0, i1 = known[-2], known[-1]
    kappa = math.log(ratios[i0] / ratios[i1]) / (logdet[i0] - logdet[i1])
    if not kappa > 0.0:
        return None
    pred = math.log(ratios[i1]) + kappa * (logdet[:a + 1] - logdet[i1])
    reach = np.flatnonzero(pred >= math.log(START_RATIO))
    return int(reach[-1]) if reach.size else None


def falling_to_zero(t: np.ndarray, d: np.ndarray) -> list[int]:
    """The interior samples where ``d`` (log det(J J^T) at the samples ``t``) has a local
    minimum next to an interval that ``exp(d / 2)`` (the smallest singular value, where
    the others change little) falls to zero in by the line through the two samples
    before it, or rises from zero in by the line through the two after it. The samples'
    own drop (:data:`.passage.DIP`) assumes even steps: where IDA cut its step right after
    a passage, the last sample before it kept 0.65 of the ratio of the first after it,
    and the passage went unlogged (A02 with one loop at rtol 1e-8, atol 1e-10: 9
    singular events of 10; with atol 1.0000001e-10 all 10). Where k singular values
    collapse together ``exp(d / 2)`` falls as their k-th power, whose lines reach zero
    sooner: only local minima are asked, or every sample on the way down would be."""
    n = t.size
    if n < 3:
        return []
    with np.errstate(invalid="ignore", divide="ignore"):
        # the line through (ta, sa), (tb, sb) reaches zero by tc where
        # sb / sa <= (tc - tb) / (tc - ta), in logarithms (no overflow)
        dt = np.diff(t)
        half = 0.5 * np.diff(d)  # log(s[k + 1] / s[k])
        # fall[k]: the line through k, k + 1 at zero by k + 2; rise[k]: the line through
        # k + 2, k + 1 (backwards) at zero by k
        fall = half[:-1] <= np.log(dt[1:] / (dt[:-1] + dt[1:]))
        rise = -half[1:] <= np.log(dt[:-1] / (dt[:-1] + dt[1:]))
    out = []
    for i in np.flatnonzero((d[1:-1] <= d[:-2]) & (d[1:-1] <= d[2:])) + 1:
        # into the interval before the minimum or after it, from either side
        lines = [fall[k] for k in (i - 2, i - 1) if 0 <= k < n - 2] + \
            [rise[k] for k in (i - 1, i) if 0 <= k < n - 2]
        if any(lines):
            out.append(int(i))
    return out


def end_may_dip(d: np.ndarray, t: np.ndarray, end: int, a: int, b: int,
                reach: float) -> bool:
    """Whether the segment's end sample ``end`` may be next to a passage, asked of the log
    determinant ``d`` before the exact ratios are (they took 5 of a run's 11 on A02,
    whose ends are far from one): as the interior's candidates, where d falls towards the
    end and ``exp(d / 2)``, the smallest singular value where the others change little,
    on the line through samples ``a`` and ``b`` reaches zero within twice ``reach`` (s)
    of it. Where k singular values collapse together ``exp(d / 2)`` falls as their k-th
    power, whose line reaches zero sooner: the question errs towards asking the ratios."""
    if not d[end] < d[a]:  # level or rising towards the end (or a singular neighbour)
        return bool(d[end] == -np.inf)
    if d[end] == -np.inf:
        return True
    # relative to the end's (1 there), capped: no overflow where the end's is tiny
    ra, rb = (math.exp(min(0.5 * (d[x] - d[end]), 700.0)) for x in (a, b))
    slope = (rb - ra) / (t[b] - t[a])
    zero = t[a] - ra / slope if slope != 0.0 else math.inf
    return abs(zero - t[end]) <= 2.0 * reach


def dips(candidates: list[int], n: int, r, watch: float, exceeds=None, upper=None
         ) -> set[int]:
    """The candidates followed down the exact ratio ``r`` to its own local minimum (next
    to the determinant's, where the other singular values change fast), those below
    ``watch``. ``exceeds(j, x)``: whether r(j) > x, where it can be shown without r(j)
    (a neighbour shown above the candidate's ratio is not lower); ``upper(i)``: an upper
    bound on r(i) that may stand for it in those comparisons (exact where None)."""
    exceeds = exceeds or (lambda j, x: r(j) > x)
    upper = upper or r
    found: set[int] = set()
    for i in candidates:
        for _ in range(2):
            # shown above a bound on r(i), or else above r(i) itself: not lower
            lower = [j for j in (max(i - 1, 0), min(i + 1, n - 1))
                     if j != i and not exceeds(j, upper(i)) and not exceeds(j, r(i))]
            k = min(lower, key=r, default=i)
            if k == i or r(k) >= r(i):
                break
            i = k
        if upper(i) < watch or r(i) < watch:
            found.add(i)
    return found


class SampleRatios:
    """The exact ratios of a segment's samples (:mod:`.passage`), computed where they are
    needed, and bounds on them by one Cholesky each: from below
    (:func:`~cmm_dae.equations.bandsvd.above`) and from above
    (:func:`~cmm_dae.singular.tip.ratio_above`), from one evaluation of the sample's
    Jacobian nonzeros (a sample's bounds from both sides took two)."""

    def __init__(self, model: Model, p: np.ndarray, t: np.ndarray, q: np.ndarray,
                 act: np.ndarray, exact_only: bool):
        self.model, self.p, self.t, self.q, self.act = model, p, t, q, act
        # (a crossing's start is searched on exact ratios, whose walk back the dip's
        # give a first guess: there every comparison takes them)
        self.exact_only = exact_only
        self.exact: dict[int, float] = {}
        self.shown: dict[int, float] = {}  # sample -> a bound its ratio is shown above
        self.bounds: dict[int, float] = {}  # sample -> a bound its ratio is below
        self.bounding = True  # until a bound did not spare its exact ratio
        self.band = gram_band(model, act) if 0 < act.size <= model.nq else None
        self._vals: dict[int, np.ndarray] = {}  # sample -> its active rows' nonzeros

    def r(self, i: int) -> float:
        """The exact ratio at sample i."""
        if i not in self.exact:
            self.exact[i] = singular_ratio(self.model, self.q[i], float(self.t[i]), self.p)
            # (where a dip's bound does not spare its ratio, as where many singular values
            # collapse together and the bound stays up to twice the ratio, it costs more)
            self.bounding = self.bounding and i not in self.bounds
        return self.exact[i]

    def exceeds(self, i: int, x: float) -> bool:
        """Whether the ratio at sample i is above x: by one Cholesky where that shows it."""
        if i in self.exact or self.exact_only:
            return self.r(i) > x
        return self._above(i, x) or self.r(i) > x

    def upper(self, i: int) -> float:
        """An upper bound on the ratio at sample i (:func:`~.tip.ratio_above`: one
        Cholesky, where the exact ratio took 1.1 ms with 32 loops); the ratio itself
        where that cannot be had."""
        if i in self.exact or self.exact_only or (i not in self.bounds and not self.bounding):
            return self.r(i)
        got = self._bound(i)
        return self.r(i) if got is None else got

    def _values(self, i: int) -> np.ndarray:
        """The active rows' Jacobian nonzeros at sample i (kept)."""
        if i not in self._vals:
            self._vals[i] = active_values_at(self.model, self.act, self.q[i],
                                             float(self.t[i]), self.p)
        return self._vals[i]

    def _bound(self, i: int) -> float | None:
        """:func:`~.tip.ratio_above` at sample i (kept), None where it cannot be had (no
        band, or not factored)."""
        if i not in self.bounds and self.band is not None:
            got = ratio_above(self._values(i), self.band, self.model.nq)
            if got is not None:
                self.bounds[i] = got
        return self.bounds.get(i)

    def _above(self, i: int, x: float) -> bool:
        """Whether one Cholesky of the Gram band (:func:`~.bandsvd.above`: with 32 loops
        instead of the ratio's 0.9 ms) shows the ratio at sample i above x (kept: once
        each); False where it does not or there is no band."""
        if self.shown.get(i, -1.0) >= x:
            return True
        if self.band is not None and bandsvd.above(
                banded.lower_blocks(self.band, self._values(i)[:, None]), x):
            self.shown[i] = x
            return True
        return False

    def logged_start(self, a: int) -> float:
        """The ratio a logged passage in interval ``a`` counts its rank drop against
        (:func:`passages`' ``start``): :data:`START_RATIO`, or the largest ratio known at
        a sample up to a, the segment's start among them, where that is lower."""
        known = max((r for i, r in self.exact.items() if i <= a), default=0.0)
        if known >= START_RATIO:
            return START_RATIO
        # the segment's start: low everywhere? (one Cholesky shows it above where it is:
        # the same as its exact ratio would give)
        if 0 not in self.exact and self._above(0, START_RATIO):
            return START_RATIO
        # the largest of the samples' ratios the comparisons bounded (the dips' among
        # them) and the start's: exact where a bound does not show one below it (a chain
        # of 128 loops, whose ratio is below START_RATIO everywhere: 5 exact ratios,
        # 12 ms each)
        best = max(known, self.r(0))
        for i in sorted({*self.shown, *self.bounds}):
            if i <= a and i not in self.exact:
                bound = self._bound(i)
                if bound is None or bound > best:
                    best = max(best, self.r(i))
        return min(START_RATIO, best)
