"""The drivers' peak efforts over IDA's steps, not the output grid: where each driver's
multiplier sits in IDA's unknowns, its extremes over a segment's steps (at each step's
end and where IDA's interpolant turns inside a step; the compiled segment's watch_step
does the same in C), and those kept with their states for post-processing."""

from __future__ import annotations

import numpy as np

from ..equations.model import Model
from .csegment import Extremes
from .suppress import Interpolant

__all__ = ["Tracker", "driver_watch", "keep_extremes"]


class Tracker:
    """The largest and smallest values of y's entries ``watch`` over IDA's steps (at each
    step's end, and where IDA's interpolant ``dky`` turns inside a step), with their times
    and first ``ncol`` entries of y: what the compiled segment's watch_step keeps."""

    def __init__(self, watch: np.ndarray, ncol: int, dky: Interpolant | None, t0: float):
        w = len(watch)
        self.watch, self.ncol, self.dky = watch, ncol, dky
        self.value = np.tile([-np.inf, np.inf], w)
        self.t, self.y = np.full(2 * w, np.nan), np.full((2 * w, ncol), np.nan)
        self.t_last = t0  # (s) the last step's end
        self.d_last: np.ndarray | None = None  # the watched rates there

    def _offer(self, rows: np.ndarray, t: float, y: np.ndarray) -> None:
        x = np.repeat(y[self.watch], 2)
        better = np.zeros(x.size, bool)
        better[rows] = np.where(rows % 2 == 0, x[rows] > self.value[rows],
                                x[rows] < self.value[rows])
        if better.any():
            self.value[better], self.t[better] = x[better], t
            self.y[better] = y[:self.ncol]

    def add(self, t1: float, y1: np.ndarray) -> None:
        """IDA's step to t1 (s), y1 at its end."""
        if not self.watch.size:
            return
        t0, self.t_last = self.t_last, t1
        self._offer(np.arange(self.value.size), t1, y1)
        d0, self.d_last = self.d_last, None  # (the last step's end rate, as segment.c)
        if not t1 > t0:
            return
        d0 = self.dky(t0, 1)[self.watch] if d0 is None else d0
        d1 = self.d_last = self.dky(t1, 1)[self.watch]
        for i in range(self.watch.size):
            for j in range(2):
                a, b, da = t0, t1, d0[i]
                if not (da > 0 > d1[i] if j == 0 else da < 0 < d1[i]):
                    continue
                for _ in range(60):  # bisection on the derivative, as in segment.c
                    m = 0.5 * (a + b)
                    if not a < m < b:
                        break
                    if (self.dky(m, 1)[self.watch[i]] > 0) == (da > 0):
                        a = m
                    else:
                        b = m
                m = 0.5 * (a + b)
                self._offer(np.array([2 * i + j]), m, self.dky(m))

    def extremes(self) -> Extremes:
        return Extremes(self.value.copy(), self.t.copy(), self.y.copy())


def driver_watch(model: Model) -> np.ndarray:
    """Where each driver's multiplier sits in IDA's y (drivers whose row IDA does not
    carry are left out): their extremes over IDA's steps give the efforts' peaks."""
    u = model.ida
    return np.array([u.lam.start + int(np.flatnonzero(u.rows == r[0])[0])
                     for d in model.driver_names
                     if (r := model.rows_of("driver", d)) and r[0] in u.rows], dtype=int)


def keep_extremes(rec, model: Model, r, t_last: float, c: int) -> None:
    """A segment's extremes of the watched multipliers over IDA's steps (``r.extremes``),
    those up to ``t_last`` (what the segment keeps) that beat the run's so far, added to
    ``rec`` with their states (converted only where they do)."""
    ext = getattr(r, "extremes", None)
    if ext is None or not ext.t.size:
        return
    t = np.where(ext.t <= t_last, ext.t, np.nan)
    rows = np.flatnonzero(rec.better_peaks(ext.value, t))
    if rows.size:
        Q, V = model.ida.centroids(ext.y[rows])
        rec.add_peaks(rows, ext.value, t, Q, V, c)
