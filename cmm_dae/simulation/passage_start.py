"""Where the crossing of a singular position IDA stepped over starts: the last sample before
it whose singular-value ratio is at least :data:`START_RATIO` (:mod:`.passage`)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["START_RATIO", "predicted_start", "start_before"]

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
