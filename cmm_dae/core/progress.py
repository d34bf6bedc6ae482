"""One text progress bar on stderr, for long runs (simulated time) and sweeps (runs)."""

from __future__ import annotations

import sys
import time


class Bar:
    """A progress bar written to stderr, redrawn at most every ``every`` seconds of wall time.

    Parameters
    ----------
    total : float
        The value at completion (simulated seconds, or a number of runs).
    label : str
        Shown before the bar.
    unit : str
        Unit of ``total`` in the text ("s" of simulated time, "runs").
    enabled : bool
        False: every call does nothing (so callers need no branches).
    """

    def __init__(self, total: float, label: str, unit: str, *, enabled: bool = True,
                 every: float = 0.1) -> None:
        self.total, self.label, self.unit = float(total), label, unit
        self.enabled, self.every = enabled, every
        self.t0 = self.last = time.perf_counter()
        self.value = 0.0
        self.closed = False

    def update(self, value: float, *, force: bool = False) -> None:
        """Move the bar to ``value`` (redrawn when ``every`` seconds have passed)."""
        self.value = value
        if not self.enabled or self.closed:
            return
        now = time.perf_counter()
        if not force and now - self.last < self.every:
            return
        self.last = now
        frac = min(max(value / self.total, 0.0), 1.0) if self.total > 0 else 1.0
        rate = value / max(now - self.t0, 1e-9)
        done = f"{value:.4g}/{self.total:.4g} {self.unit}"
        sys.stderr.write(f"\r{self.label} [{'#' * int(30 * frac):<30}] {done} "
                         f"({rate:.3g} {self.unit}/s wall)")
        sys.stderr.flush()

    def close(self) -> None:
        """Draw the final state and end the line."""
        if self.enabled and not self.closed:
            self.update(self.value, force=True)
            sys.stderr.write("\n")
            sys.stderr.flush()
        self.closed = True
