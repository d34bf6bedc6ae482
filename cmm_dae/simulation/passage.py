"""Singular positions IDA stepped over without stopping, found afterwards in its samples.

IDA integrates through a singular position on the branch of the motion whenever its steps
happen to straddle the instant (at rtol 1e-8 it does so at most of them): the motion is
smooth there, only the constraint Jacobian loses rank for an instant. Every segment's
samples are searched for such a passage: a dip of the constraints' singular-value ratio
that the cubic Hermite interpolant of the samples (positions and their rates) takes close
to zero. Under ``branch = "continue"`` it is logged as it is (:func:`stepped_over`); a
branch rule has to be applied *at* the instant, so the run goes back to the last sample
before it and crosses it as if IDA had stopped there (:func:`watch_segment`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..equations.kinematics import singular_ratio
from ..equations.model import Model
from ..equations.rank import loop_free
from ..integrators.contract import Recorder, SegmentEnd
from ..singular.instant import grid_bracket, hermite
from ..singular.tip import interval_instant, sample_instant
from .measure import log_gram as _log_gram
from .measure import sample_measure
from .passage_start import (
    SampleRatios,
    dips,
    end_may_dip,
    falling_to_zero,
    predicted_start,
    start_before,
)

#: A sample whose singular-value ratio is a local minimum below this is looked at closely.
WATCH_RATIO = 0.3
#: ... and the motion passes a singular position where the interpolant's ratio falls below
#: this (it falls linearly to zero at the instant; elsewhere a well-posed mechanism stays
#: far above it).
PASSAGE_RATIO = 1e-3
#: Parts a sample interval is cut into where the interpolant's ratio is measured, twice:
#: over the interval, then over the two parts about its lowest point (29 points against
#: 63 at one level of 64 parts, the finest spacing 1/128 of the interval instead of 1/64).
POINTS = 16


#: A sample is looked at when log det(J J^T) there is at least this much below that of
#: one of its neighbours (the ratio at most 0.6 of the neighbour's: a passage gives a
#: third or less).
DIP = 2.0 * math.log(1.0 / 0.6)


@dataclass(frozen=True)
class Passage:
    """A singular position between two samples of a segment (indices into the samples
    searched, the segment's start first)."""

    #: the last sample before it whose ratio is at least :data:`.START_RATIO` (-1 where
    #: not searched: :func:`passages` with ``start=False``)
    start: int
    interval: int  #: it lies between samples ``interval`` and ``interval + 1``
    t: float  #: the singular instant on the samples' interpolant, s
    ratio: float  #: the interpolant's singular-value ratio there
    start_ratio: float  #: the ratio at sample ``start`` (see :func:`passages`)


def _on_grid(model: Model, p: np.ndarray, ends: tuple, s: np.ndarray, act: np.ndarray,
             exact) -> np.ndarray:
    """:func:`_on_grids` of one interval."""
    return _on_grids(model, p, [ends], s, act, [exact])[0]


def _on_grids(model: Model, p: np.ndarray, ends: list[tuple], s: np.ndarray, act: np.ndarray,
              exact: list) -> list[np.ndarray]:
    """A measure of the singular-value ratio on the samples' interpolant between two
    samples (each of ``ends``: t, q, v at each), at the fractions ``s`` of the interval,
    whose smallest value lies where the ratio's does: log det(J J^T) where it is defined
    (one evaluation for every interval's grid: one per interval cost 0.4 ms more with 8
    loops), else ``exact`` (each interval's ratio itself) at each point. Next to a
    passage both are ruled by the smallest singular value, falling to zero at the
    instant, and the other singular values change little over one interval."""
    if not 0 < act.size <= model.nq:
        return [np.array([at(float(x)) for x in s]) for at in exact]
    tx = [e[0] + s * (e[3] - e[0]) for e in ends]
    qx = np.vstack([hermite(*e, x[:, None])[0] for e, x in zip(ends, tx, strict=True)])
    return np.split(_log_gram(model, p, np.concatenate(tx), qx, act), len(ends))


def _refined_grid(model: Model, p: np.ndarray, ends: tuple, act: np.ndarray, exact,
                  s: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_on_grid` at the fractions ``s`` of :data:`POINTS` parts of the interval
    (``g`` there), then of :data:`POINTS` parts of the two about the lowest point:
    (fractions in increasing order, the measure there). Next to a passage the measure has
    a logarithm's dip to its instant, which the coarse point nearest it shows lowest, or
    its neighbour where the instant lies halfway: either way within the refined span."""
    k, lo, hi = grid_bracket(s, g)
    f = np.linspace(lo, hi, POINTS + 1)[1:-1]
    f = f[np.abs(f - s[k]) > 1e-3 / POINTS]  # (its middle is the coarse point)
    x, y = np.concatenate([s, f]), np.concatenate([g, _on_grid(model, p, ends, f, act, exact)])
    order = np.argsort(x)
    return x[order], y[order]


def passages(model: Model, p: np.ndarray, t: np.ndarray, q: np.ndarray, v: np.ndarray,
             first: bool = False, ends_open: bool = False, skip_last: bool = False,
             start: bool = True, keep=None) -> list[Passage]:
    """The singular positions the samples of one segment pass, in time order.

    Parameters
    ----------
    model, p : Model, ndarray
        The equations and the configuration's parameters.
    t : ndarray, (n,)
        Sample times of one IDA segment, s, its start first (distinct and increasing).
    q, v : ndarray, (n, nq)
        Positions and velocities there.
    first : bool
        Stop at the first one found.
    ends_open : bool
        Also take a dip below :data:`PASSAGE_RATIO` that reaches a sample itself, as at
        the end of a segment stopped short of the instant (else the interpolant's ratio
        must fall below half that at both ends of its interval).
    skip_last : bool
        Leave the last interval out (a segment that ended at a singular position: the
        crossing from there takes it; searched, its ratio runs down to the last sample
        and a bounded search follows it there in 29 evaluations).
    start : bool
        Find the sample a crossing of each would start from (:func:`start_before`), as
        a branch rule needs; without, a passage's ``start`` is -1 and its
        ``start_ratio`` the ratio a crossing starts from, :data:`START_RATIO`, or the
        largest ratio known at a sample before it, the segment's start among them, where
        that is lower (a mechanism whose ratio is low everywhere): the threshold its rank
        drop is counted against. The walk back took 4 of 27 exact ratios with 8 and 32
        loops, 11 of 34 with 128.
    keep : callable, optional
        ``keep(a, lam)``: given the samples' accelerations and multipliers where the
        screen solved them with its measure (:func:`.measure.sample_measure`).

    Returns
    -------
    list of Passage
        Where the samples' cubic Hermite interpolant takes the constraints' singular-value
        ratio below :data:`PASSAGE_RATIO`, next to a sample where the ratio has a local
        minimum below :data:`WATCH_RATIO`.
    """
    n = t.size
    act = model.active_rows(p)
    if n < 2 or loop_free(model, act):  # (no singular position where no loop closes)
        return []
    known = SampleRatios(model, p, t, q, act, exact_only=start)
    ratios, r, exceeds = known.exact, known.r, known.exceeds
    found: list[Passage] = []
    searched: set[int] = set()
    candidates, logdet = _candidates(model, p, t, q, v, act, r, keep)
    for i in sorted(dips(candidates, n, r, WATCH_RATIO, exceeds, known.upper)):
        lo, hi = max(i - 1, 0), min(i + 1, n - 1)
        best: tuple[float, float, int] | None = None  # (ratio, fraction, interval)
        # the intervals on either side of the dipping sample: the instant is where the
        # interpolant's ratio is smallest (next to the sample the other side's approaches
        # the sample's own ratio, which can be below PASSAGE_RATIO already). Newton's
        # method from the sample across both first (the motion through the singular
        # position itself); else both on the grid, then searched closely from the one
        # that dips lower, the other only where that finds no passage: its minimum is the
        # shared sample, onto which a bounded search took 30 ratios to converge (A02)
        sides = [(a, (t[a], q[a], v[a], t[a + 1], q[a + 1], v[a + 1])) for a in range(lo, hi)
                 if not (a in searched or t[a + 1] <= t[a] or (skip_last and a == n - 2))]
        searched.update(a for a, _ in sides)
        ats = [_ratio_at(model, p, ends) for _, ends in sides]
        tip = sample_instant(model, p, i, sides, act, ats)
        if tip is not None and (ends_open or (exceeds(tip[0], 2.0 * tip[2])
                                              and exceeds(tip[0] + 1, 2.0 * tip[2]))):
            sides, ats, best = [], [], (tip[2], tip[1], tip[0])
        s = np.linspace(0.0, 1.0, POINTS + 1)[1:-1]
        grids = _on_grids(model, p, [ends for _, ends in sides], s, act, ats) if sides else []
        sides = [(a, ends, at, s, g) for (a, ends), at, g in zip(sides, ats, grids, strict=True)]
        for a, ends, at, s, grid in sorted(sides, key=lambda side: float(np.min(side[4]))):
            x, r_min = interval_instant(  # (the coarse grid, refined where it is not enough)
                model, p, ends, act, at, s, grid, lambda s, g, ends=ends, at=at:
                _refined_grid(model, p, ends, act, at, s, g))
            # inside the interval, below both its ends (not an end that starts low and
            # rises, as a segment can right after a crossing), unless the segment may
            # have stopped short of the instant
            inside = ends_open or (exceeds(a, 2.0 * r_min) and exceeds(a + 1, 2.0 * r_min))
            if inside and (best is None or r_min < best[0]):
                best = (r_min, x, a)
            if best is not None and best[0] < PASSAGE_RATIO:
                break
        if best is not None and best[0] < PASSAGE_RATIO:
            r_min, x, a = best
            t_s = float(t[a] + x * (t[a + 1] - t[a]))
            if start:
                j = start_before(a, r, predicted_start(a, logdet, ratios))
                found.append(Passage(j, a, t_s, r_min, r(j)))
            else:
                found.append(Passage(-1, a, t_s, r_min, known.logged_start(a)))
            if first:
                return found
    return sorted(found, key=lambda ps: ps.t)


def _candidates(model: Model, p: np.ndarray, t: np.ndarray, q: np.ndarray, v: np.ndarray,
                act: np.ndarray, r, keep=None) -> tuple[list[int], np.ndarray | None]:
    """The samples where the ratio may dip to zero: the segment's ends, and local minima
    of log det(J J^T) well below one neighbour (every sample where the rows are none or
    more than the coordinates), and that log det at every sample (None there). ``r(i)``:
    the exact ratio at sample i; ``keep``: see :func:`passages`."""
    n = t.size
    if not 0 < act.size <= model.nq:
        return list(range(n)), None
    # Next to a passage the smallest singular value falls linearly to zero, so the sample
    # nearer the instant has at most a third of the farther neighbour's (a drop of 2 ln 3
    # in the log determinant, the other singular values unchanged); where the
    # determinant is flat, round-off makes local minima everywhere.
    d, solved = sample_measure(model, p, t, q, v, act)
    if solved is not None and keep is not None:
        keep(*solved)
    lo_d, hi_d = np.append(d[0], d[:-1]), np.append(d[1:], d[-1])
    dip = (d <= lo_d) & (d <= hi_d) & (d <= np.maximum(lo_d, hi_d) - DIP)
    candidates = sorted({int(i) for i in np.flatnonzero(dip[1:-1]) + 1}
                        | set(falling_to_zero(t, d)))
    # an end: where the ratio falls towards it and, on the two samples beside it extended
    # linearly, reaches zero within an interval of it; the determinant asked first
    for end, a, b in ((0, 1, 2), (n - 1, n - 2, n - 3)):
        if b < 0 or b >= n:  # two samples: the line through both
            a, b = end, a
        reach = max(abs(t[a] - t[b]), abs(t[end] - t[a]))
        if not end_may_dip(d, t, end, a, b, reach):
            continue
        if r(end) > r(a):  # rising towards the end (the third ratio not needed)
            continue
        slope = (r(b) - r(a)) / (t[b] - t[a])
        zero = t[a] - r(a) / slope if slope != 0.0 else math.inf
        if abs(zero - t[end]) <= reach:
            candidates.append(end)
    return candidates, d


def _ratio_at(model: Model, p: np.ndarray, ends: tuple):
    """The singular-value ratio on the samples' interpolant between two samples (``ends``:
    t, q, v at each), as a function of the fraction of the interval."""
    def at(x: float) -> float:
        tx = float(ends[0] + x * (ends[3] - ends[0]))
        return singular_ratio(model, hermite(*ends, tx)[0], tx, p)
    return at


def _samples(t: float, q: np.ndarray, v: np.ndarray, rec: Recorder, n0: int,
             end: SegmentEnd) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A segment's samples, its start first and its end last (neither is in ``rec``
    where the segment starts after an event or stops short of its last sample)."""
    ts, qs, vs = rec.since(n0)
    ts, qs, vs = [np.concatenate([[a], b]) for a, b in ((t, ts), (q, qs), (v, vs))] \
        if ts.size else (np.array([t]), q[None], v[None])
    if end.t > ts[-1]:
        ts, qs, vs = (np.append(ts, end.t), np.vstack([qs, end.q]), np.vstack([vs, end.v]))
    return ts, qs, vs


def _keeper(rec: Recorder, n0: int, t: float, q: np.ndarray, v: np.ndarray):
    """``keep`` for :func:`passages` on the samples of :func:`_samples` (the segment's
    start (t, q, v), then its samples in ``rec`` from ``n0`` on, then maybe its end):
    their solved accelerations and multipliers into ``rec``, the start's too where it is
    the sample before them (the run's start, or the state after an event), recorded in
    the same configuration."""
    k, i = len(rec) - n0, 1
    if 0 < n0 < len(rec):
        t0, q0, v0, c0 = rec.at(n0 - 1)
        if t0 == t and c0 == rec.at(n0)[3] and np.array_equal(q0, q) \
                and np.array_equal(v0, v):
            i = 0
    return lambda a, lam: rec.keep_kkt(n0 - 1 + i, a[i:1 + k], lam[i:1 + k])


def passage_cut(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                rec: Recorder, n0: int, end: SegmentEnd, last: bool = False,
                keep: bool = False) -> tuple[int, SegmentEnd] | None:
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
    last : bool
        Cut back before the last passage (where the integrator gave up next to one), not
        the first.
    keep : bool
        Keep the samples' accelerations and multipliers in ``rec`` where the screen
        solves them (:func:`passages`' ``keep``; once per segment).

    Returns
    -------
    tuple of (int, SegmentEnd) or None
        The number of samples to keep and the segment's new end (reason ``"singular"``,
        at the last sample before the passage), None when the samples pass none.
        Nothing is changed: the caller truncates ``rec``.
    """
    ts, qs, vs = _samples(t, q, v, rec, n0, end)
    found = passages(model, p, ts, qs, vs, first=not last, ends_open=True,
                     keep=_keeper(rec, n0, t, q, v) if keep else None)
    if not found:
        return None
    j = found[-1].start
    return n0 + j, SegmentEnd(float(ts[j]), qs[j].copy(), vs[j].copy(), (), "singular")


def stepped_over(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                 rec: Recorder, n0: int, end: SegmentEnd
                 ) -> list[tuple[Passage, int, np.ndarray, np.ndarray, float]]:
    """The singular positions IDA integrated through inside one segment, to be logged.

    Parameters are those of :func:`passage_cut`. Returns, in time order, each passage
    with the index in ``rec`` of the first sample after it, the interpolated positions
    and velocities at its instant and the ratio its rank drop is counted against (a
    crossing's start ratio, see :func:`passages`' ``start``). One in the segment's last
    interval is left out when the segment ended at a singular position: the crossing
    from there takes it.
    """
    if loop_free(model, model.active_rows(p)):  # (before the samples are gathered)
        return []
    ts, qs, vs = _samples(t, q, v, rec, n0, end)
    out = []
    for ps in passages(model, p, ts, qs, vs, skip_last=end.reason == "singular",
                       start=False, keep=_keeper(rec, n0, t, q, v)):
        after = n0 + ps.interval  # ts[k] is rec[n0 + k - 1]
        if after >= len(rec):
            continue
        a = ps.interval
        qs_, vs_ = hermite(ts[a], qs[a], vs[a], ts[a + 1], qs[a + 1], vs[a + 1], ps.t)
        out.append((ps, after, qs_, vs_, ps.start_ratio))
    return out


def watch_segment(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                  rec: Recorder, n0: int, end: SegmentEnd) -> SegmentEnd:
    """With a branch rule: the segment cut back to the last sample before a singular
    position IDA stepped over (its samples beyond dropped, its end event forgotten: IDA
    meets it again), to be crossed there; else the segment's end as it was."""
    cut = passage_cut(model, p, t, q, v, rec, n0, end, keep=True)
    if cut is None:
        return end
    rec.truncate(cut[0])
    return cut[1]
