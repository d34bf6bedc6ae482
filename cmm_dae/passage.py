"""Singular positions IDA stepped over without noticing, found where a branch rule needs them.

IDA integrates through a singular position on the branch of the motion whenever its steps
happen to straddle the instant (at rtol 1e-8 it does so at most of them): the motion is
smooth there, only the constraint Jacobian loses rank for an instant. That is right for
``branch = "continue"``, but a branch rule has to be applied *at* the instant, so with a rule
every segment's samples are searched for a passage: a dip of the constraints'
singular-value ratio that the cubic Hermite interpolant of the samples (positions and their
rates) takes close to zero. The run then goes back to the last sample before it and crosses
it as if IDA had stopped there.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from .equations import Model
from .integrator import Recorder, SegmentEnd
from .kinematics import singular_ratio
from .singular_instant import hermite

#: A sample whose singular-value ratio is a local minimum below this is looked at closely.
WATCH_RATIO = 0.3
#: ... and the motion passes a singular position where the interpolant's ratio falls below
#: this (it falls linearly to zero at the instant; elsewhere a well-posed mechanism stays
#: far above it).
PASSAGE_RATIO = 1e-3
#: The crossing starts from the last sample before the passage whose ratio is at least
#: this (closer, the Gauss steps' nodes would sit where round-off rules the accelerations).
START_RATIO = 0.01
#: Points per sample interval at which the interpolant's ratio is evaluated.
POINTS = 64


def missed_passage(model: Model, p: np.ndarray, t: np.ndarray, q: np.ndarray,
                   v: np.ndarray) -> int | None:
    """The sample to cross from, or None when the samples pass no singular position.

    Parameters
    ----------
    model, p : Model, ndarray
        The equations and the configuration's parameters.
    t : ndarray, (n,)
        Sample times of one IDA segment, s, its start first (distinct and increasing).
    q, v : ndarray, (n, nq)
        Positions and velocities there.

    Returns
    -------
    int or None
        Index of the last sample before the first passage (with a singular-value ratio of
        at least :data:`START_RATIO` where there is one), None if there is none.
    """
    n = t.size
    if n < 2:
        return None
    r = np.array([singular_ratio(model, q[i], float(t[i]), p) for i in range(n)])
    s = np.linspace(0.0, 1.0, POINTS + 1)[1:-1]
    for i in range(n):
        lo, hi = max(i - 1, 0), min(i + 1, n - 1)
        if not (r[i] < WATCH_RATIO and r[i] <= r[lo] and r[i] <= r[hi]):
            continue
        for a in range(lo, hi):  # the intervals on either side of the dipping sample
            if t[a + 1] <= t[a]:
                continue
            ends = (t[a], q[a], v[a], t[a + 1], q[a + 1], v[a + 1])

            def at(x: float, ends: tuple = ends) -> float:  # x: fraction of the interval
                tx = float(ends[0] + x * (ends[3] - ends[0]))
                return singular_ratio(model, hermite(*ends, tx)[0], tx, p)

            rs = np.array([at(x) for x in s])
            k = int(np.argmin(rs))
            # the ratio dips in a V to zero: the grid may step over its tip, a bounded
            # search between the grid's neighbours finds it
            lo_s, hi_s = s[max(k - 1, 0)], s[min(k + 1, s.size - 1)]
            best = minimize_scalar(at, bounds=(lo_s, hi_s), method="bounded",
                                   options={"xatol": 1e-9})
            if min(float(rs[k]), float(best.fun)) < PASSAGE_RATIO:
                j = a
                while j > 0 and r[j] < START_RATIO:
                    j -= 1
                return j
    return None


def passage_cut(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                rec: Recorder, n0: int, end: SegmentEnd) -> tuple[int, SegmentEnd] | None:
    """Where a segment would be cut back to cross a singular position its samples pass.

    Parameters
    ----------
    model, p : Model, ndarray
        The equations and the configuration's parameters.
    t, q, v : float, ndarray, ndarray
        The segment's start (s, positions, velocities).
    rec : Recorder
        The run's samples; the segment's are those from index ``n0`` on.
    n0 : int
        Index of the segment's first sample in ``rec``.
    end : SegmentEnd
        How the segment ended.

    Returns
    -------
    tuple of (int, SegmentEnd) or None
        The number of samples to keep and the segment's new end (reason ``"singular"``,
        at the last sample before the first passage), None when the samples pass none.
        Nothing is changed: the caller truncates ``rec``.
    """
    ts, qs, vs = rec.since(n0)
    ts, qs, vs = [np.concatenate([[a], b]) for a, b in ((t, ts), (q, qs), (v, vs))] \
        if ts.size else (np.array([t]), q[None], v[None])
    if end.t > ts[-1]:
        ts, qs, vs = (np.append(ts, end.t), np.vstack([qs, end.q]), np.vstack([vs, end.v]))
    j = missed_passage(model, p, ts, qs, vs)
    if j is None:
        return None
    return n0 + j, SegmentEnd(float(ts[j]), qs[j].copy(), vs[j].copy(), (), "singular")


def watch_segment(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                  rec: Recorder, n0: int, end: SegmentEnd) -> SegmentEnd:
    """With a branch rule: the segment cut back to the last sample before a singular
    position IDA stepped over (its samples beyond dropped, its end event forgotten: IDA
    meets it again), to be crossed there; else the segment's end as it was."""
    cut = passage_cut(model, p, t, q, v, rec, n0, end)
    if cut is None:
        return end
    rec.truncate(cut[0])
    return cut[1]
