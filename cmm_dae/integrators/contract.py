"""The contract between the run driver (:mod:`cmm_dae.simulation.runner`) and an integrator.

An integrator only advances the state within the configuration in force, from a time to
the end of the run or to the next trigger, recording output samples on the way, and says
why it stopped in a :class:`SegmentEnd`. Everything else — options, model, initial state,
the event policy, failure wrapping, the Result — is the driver's, once for all methods
(as scipy's ``OdeSolver`` subclasses implement one step and ``solve_ivp`` the rest).
"""

from __future__ import annotations

import bisect
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..core.progress import Bar
from ..core.records import Stats
from ..equations.model import Model
from ..equations.unknowns import NW
from ..hybrid.state import ZENO_DT, HybridState, Policy, Transition, Trigger


@dataclass(frozen=True)
class RunOptions:
    """Checked run options (see :func:`cmm_dae.simulate` for their meaning and units)."""

    t_end: float
    rtol: float = 1e-8
    atol: float = 1e-10
    output_dt: float | None = 0.01
    dt: float = 0.01
    output_every: int = 1
    max_events: int = 1000  # (simulate's default: per simulated second)
    v_lock: float = 1e-6
    max_steps: int = 500_000
    #: a progress bar moved to the time reached (None: none)
    progress: Bar | None = None
    #: branch at a singular position: None (the branch of the motion) or (joint, +1 / -1)
    branch: tuple[str, int] | None = None
    #: IDA: run each segment in C (:mod:`cmm_dae.integrators.csegment`): True, False or
    #: "auto" (where it is built already; :func:`~cmm_dae.integrators.cbuild.choose`)
    compiled: bool | str = False
    #: IDA's linear solver: "dense", "sparse" (SuperLU_MT on CasADi's pattern) or "auto"
    linsolver: str = "auto"


@dataclass(frozen=True)
class SegmentEnd:
    """Where and why an integrator stopped.

    t : float
        Time reached, s.
    q, v : ndarray (nq,)
        State there (positions m/rad, velocities m/s, rad/s).
    triggers : tuple of Trigger
        What was detected at t (several at one instant are all listed), empty otherwise.
    reason : {"end", "event", "restart", "singular"}
        Reached ``t_end``; stopped at triggers; or stopped for a restart with nothing to
        switch (a driver breakpoint, or a state to re-initialise from); or stopped at the
        last good state before a singular position (the constraints collapse ahead).
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    triggers: tuple[Trigger, ...] = ()
    reason: Literal["end", "event", "restart", "singular"] = "end"


class Recorder:
    """Output samples (t, q, v, configuration index), appended in time order, and with
    each the works (J, :data:`~cmm_dae.equations.unknowns.WORKS`) done since the sample
    before it, where the integrator integrated them (NaN where it did not: the audit
    integrates those stretches over the samples).

    Kept as blocks of copies: a segment's rows are never views into the integrator's own
    output (which holds the multipliers too and would stay alive with them). Each block's
    first sample index is kept beside it, so that a sample or the samples since an index
    are found by bisection: walking every block from the first made each event's lookups
    grow with the run (the valve train at output_dt 1e-4, 3 s, 1147 events: 0.84 of a
    3.7-s run)."""

    def __init__(self) -> None:
        self._blocks: list[tuple[np.ndarray, ...]] = []
        self._starts: list[int] = []  # each block's first sample index
        self._single: list[tuple[float, np.ndarray, np.ndarray, int]] = []
        self._n = 0
        # accelerations and multipliers of runs of samples, solved already (first index,
        # a, lambda): the stepped-over screen's KKT solves, which post-processing reuses
        self._kkt: list[tuple[int, np.ndarray, np.ndarray]] = []
        # the states at which watched multipliers (the drivers') were largest and smallest
        # over the integrator's steps: (value, t, q, v, configuration) per row 2 i, 2 i + 1
        self._peaks: tuple[np.ndarray, ...] | None = None

    def better_peaks(self, value: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Which of a segment's extremes of the watched multipliers (rows 2 i: largest,
        2 i + 1: smallest, of the i-th; at times ``t``, NaN where none) beat the run's."""
        ok = np.isfinite(t)
        if self._peaks is None:
            return ok
        old = self._peaks[0]
        return ok & (np.isnan(old) | np.where(np.arange(t.size) % 2 == 0, value > old,
                                               value < old))

    def add_peaks(self, rows: np.ndarray, value: np.ndarray, t: np.ndarray, q: np.ndarray,
                  v: np.ndarray, c: int) -> None:
        """Keep the extremes ``rows`` (of :meth:`better_peaks`; ``q``, ``v`` their states,
        one row each) of a segment in configuration ``c`` as the run's."""
        if self._peaks is None:
            n = rows.size
            self._peaks = (np.full(n, np.nan), np.full(n, np.nan), np.zeros((n, q.shape[1])),
                           np.zeros((n, v.shape[1])), np.zeros(n, int))
        for a, b in zip(self._peaks, (value[rows], t[rows], q, v, c), strict=True):
            a[rows] = b

    def peaks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """The states (t, q, v, configuration) where the watched multipliers were
        extreme over the run's steps (those found), or None."""
        if self._peaks is None:
            return None
        keep = np.isfinite(self._peaks[1])
        return tuple(a[keep] for a in self._peaks[1:])

    def keep_kkt(self, n0: int, a: np.ndarray, lam: np.ndarray) -> None:
        """Keep the accelerations (k, nq) and multipliers (k, m) of the samples from index
        ``n0`` on, solved by the same batch post-processing would call
        (:func:`~cmm_dae.equations.kkt.batch`)."""
        if a.shape[0]:
            self._kkt.append((n0, a.copy(), lam.copy()))

    def kkt(self, nq: int, m: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The accelerations (n, nq) and multipliers (n, m) kept, NaN at the samples where
        none were (post-processing solves those); None where none were kept."""
        if not self._kkt:
            return None
        a, lam = np.full((self._n, nq), np.nan), np.full((self._n, m), np.nan)
        for n0, ak, lk in self._kkt:
            a[n0:n0 + ak.shape[0]], lam[n0:n0 + lk.shape[0]] = ak, lk
        return a, lam

    def __len__(self) -> int:
        return self._n

    def at(self, i: int) -> tuple[float, np.ndarray, np.ndarray, int]:
        """Sample i: time, positions, velocities, configuration index."""
        self._flush()
        if not 0 <= i < self._n:
            raise IndexError("no such sample")
        k = bisect.bisect_right(self._starts, i) - 1
        b, j = self._blocks[k], i - self._starts[k]
        return float(b[0][j]), b[1][j], b[2][j], int(b[3][j])

    @property
    def last_t(self) -> float:
        """Time of the last sample, s."""
        if self._single:
            return self._single[-1][0]
        return float(self._blocks[-1][0][-1])

    def add(self, t: float, q: np.ndarray, v: np.ndarray, c: int) -> None:
        self._single.append((t, np.array(q, dtype=float), np.array(v, dtype=float), c))
        self._n += 1

    def _flush(self) -> None:
        if self._single:
            t, q, v, c = zip(*self._single, strict=True)
            self._starts.append(self._n - len(t))
            self._blocks.append((np.array(t, dtype=float), np.array(q), np.array(v),
                                 np.array(c, dtype=int), np.full((len(t), NW), np.nan)))
            self._single = []

    def add_block(self, t: np.ndarray, q: np.ndarray, v: np.ndarray, c: int,
                  work: np.ndarray | None = None) -> None:
        """Samples of one configuration; ``work`` (n, NW): each one's works since the
        sample before it (J)."""
        if t.size == 0:
            return
        self._flush()
        self._starts.append(self._n)
        self._blocks.append((np.array(t, dtype=float), np.array(q, dtype=float),
                             np.array(v, dtype=float), np.full(t.size, c, dtype=int),
                             np.full((t.size, NW), np.nan) if work is None
                             else np.array(work, dtype=float).reshape(t.size, NW)))
        self._n += t.size

    def since(self, n0: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Times, positions and velocities of the samples from index ``n0`` on."""
        self._flush()
        rows: list[tuple] = []
        first = max(bisect.bisect_right(self._starts, n0) - 1, 0)
        for start, b in zip(self._starts[first:], self._blocks[first:], strict=True):
            if start + b[0].size > n0:
                k = max(n0 - start, 0)
                rows.append((b[0][k:], b[1][k:], b[2][k:]))
        if not rows:
            return np.zeros(0), np.zeros((0, 0)), np.zeros((0, 0))
        return tuple(np.concatenate([r[i] for r in rows]) for i in range(3))

    def truncate(self, n: int) -> None:
        """Drop the samples from index ``n`` on (a stretch the run takes again)."""
        self._flush()
        kept = [tuple(x[:min(n, start + b[0].size) - start] for x in b)
                for start, b in zip(self._starts, self._blocks, strict=True) if start < n]
        self._blocks, self._starts = kept, self._starts[:len(kept)]
        self._n = min(self._n, n)
        self._kkt = [(n0, a[:n - n0], lam[:n - n0]) for n0, a, lam in self._kkt if n0 < n]

    def arrays(self, nq: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        self._flush()
        if not self._blocks:
            return np.zeros(0), np.zeros((0, nq)), np.zeros((0, nq)), np.zeros(0, int)
        return tuple(np.concatenate([b[i] for b in self._blocks]).reshape(
            (self._n, nq) if i in (1, 2) else (self._n,)) for i in range(4))

    def works(self) -> np.ndarray:
        """Each sample's works (n, NW) in J since the sample before it (NaN: not
        integrated by the integrator)."""
        self._flush()
        if not self._blocks:
            return np.zeros((0, NW))
        return np.concatenate([b[4] for b in self._blocks])


class Integrator(ABC):
    """One integration method. Subclasses set :attr:`method`, implement
    :meth:`time_resolution` and :meth:`advance`; they may override :meth:`after_events`."""

    method: str = ""

    def __init__(self, model: Model, hs: HybridState, opts: RunOptions, stats: Stats):
        self.model, self.hs, self.opts, self.stats = model, hs, opts, stats
        self.policy = Policy(opts.v_lock, resolution=self.time_resolution(opts),
                             gap=self.gap_resolution(opts))
        if any(self.policy.gap):  # (else the state's default: leaving is never arriving)
            hs.gap_band = self.policy.gap

    @staticmethod
    @abstractmethod
    def time_resolution(opts: RunOptions) -> float:
        """Shortest time between two events this method resolves, s (the event policy's
        Zeno rule ends bounces that reach it)."""

    @staticmethod
    def gap_resolution(opts: RunOptions) -> tuple[float, float]:
        """Smallest gap to a stop at L this method tells from its own error, as (relative
        to |L|, absolute) in m or rad: the event policy locks a rebound that would rise
        less (default: no such rule)."""
        return 0.0, 0.0

    def output_times(self, t0: float, t1: float) -> np.ndarray:
        """The output grid's times strictly inside (t0, t1), s: the samples a crossing of
        a singular position records between its ends (none by default)."""
        return np.zeros(0)

    @staticmethod
    def _grid_inside(step: float, t0: float, t1: float) -> np.ndarray:
        """Multiples of ``step`` strictly inside (t0, t1), clear of both ends by the event
        resolution (s)."""
        k = np.arange(math.ceil(t0 / step), math.floor(t1 / step) + 1)
        times = k * step
        clear = ZENO_DT * max(1.0, abs(t1))
        return times[(times > t0 + clear) & (times < t1 - clear)]

    @abstractmethod
    def advance(self, t0: float, q: np.ndarray, v: np.ndarray, rec: Recorder) -> SegmentEnd:
        """Integrate in the configuration ``self.hs.locked`` from (t0, q, v) until
        ``t_end`` or the next trigger, adding output samples to ``rec`` (a sample at the
        trigger's time, before any switch, included); raise :class:`SolverError` with a
        status on failure."""

    def after_singular(self, t: float) -> None:  # noqa: B027
        """The run goes on from time ``t`` after a singular position was crossed."""

    def after_events(self, transitions: list[Transition]) -> None:  # noqa: B027
        """Told what the policy did at the last stop (default: nothing to adjust)."""

    def after_run(self, seconds: float) -> None:  # noqa: B027
        """Told that the run is over and how long it took (s, wall time; default:
        nothing to do; IDA may build its compiled segment for the next runs)."""
