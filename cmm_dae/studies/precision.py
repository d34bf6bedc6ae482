"""Convergence of the iterative algorithm and work-precision of both methods.

Both measure against a tight IDA reference on the same mechanism; errors are taken on the
coarsest grid, away from events (where the series jump and an O(dt) shift of the switching
time would dominate any pointwise error).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.errors import CmmError, ModelError, Problem, SolverError
from ..description.mechanism import Mechanism
from ..equations.model import Model
from ..results.result import Result
from ..simulation.runner import simulate


def _error(res: Result, ref: Result, t: np.ndarray, series: str) -> float:
    """Max abs difference of a series on grid t, away from the events of both runs."""
    dt = t[1] - t[0] if t.size > 1 else 1.0
    mask = res.away_from_events(t, 2 * dt, ref)
    kind, name = series.split(" ", 1)
    if kind == "driver":
        ya, yb = res.driver(name).effort, ref.driver(name).effort
    else:
        ya, yb = res.joint(name).position, ref.joint(name).position
    d = res.resample(t, ya) - ref.resample(t, yb)
    # no sample away from the events (events closer than the grid): nothing measured, not
    # an error of zero (a cam's rows all read 0 on a 0.01-s grid)
    return float(np.max(np.abs(d[mask]))) if mask.any() else math.nan


@dataclass
class Convergence:
    """Errors of the iterative algorithm over a dt sweep and the observed orders.

    errors[series] : list of max abs errors (one per dt); orders[series] : log2 ratios of
    successive errors divided by log2 of the dt ratios.
    """

    dts: list[float]
    errors: dict[str, list[float]]
    orders: dict[str, list[float]]
    walls: list[float]
    reference_rtol: float

    def table(self) -> str:
        names = list(self.errors)
        lines = [f"{'dt [s]':>10} {'wall [s]':>9} " + " ".join(f"{n:>24}" for n in names)]
        for i, dt in enumerate(self.dts):
            cells = []
            for n in names:
                o = f" (p={self.orders[n][i - 1]:.2f})" if i else ""
                cells.append(f"{self.errors[n][i]:>12.4e}{o:>12}")
            lines.append(f"{dt:10.3g} {self.walls[i]:9.3f} " + " ".join(cells))
        return "\n".join(lines)


def convergence(mech: Mechanism, dts: list[float], *, t_end: float = 1.0,
                ref_rtol: float = 1e-11, series: list[str] | None = None,
                model: Model | None = None) -> Convergence:
    """Run the iterative algorithm at each dt and measure its error against IDA.

    Parameters
    ----------
    mech : Mechanism
    dts : list of float
        Steps, s, typically dt, dt/2, dt/4, ...
    t_end : float
        End time, s.
    ref_rtol : float
        Tolerance of the IDA reference (atol is 1e-2 of it).
    series : list of str or None
        ``"driver NAME"`` or ``"joint NAME"``; default: every driver and every non-driven
        joint with a spring or limits.

    Returns
    -------
    Convergence
    """
    if not (isinstance(dts, list | tuple | np.ndarray) and len(dts) > 0 and all(
            isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
            and 0 < x <= t_end for x in dts)):
        raise ModelError(Problem("convergence", "dts", f"expected a non-empty list of steps "
                                 f"in (0, t_end = {t_end!r}] s, got {dts!r}"))
    model = model or Model(mech)
    grid_dt = max(dts)
    ref = simulate(mech, t_end, rtol=ref_rtol, output_dt=min(dts),
                   model=model)
    if series is None:
        series = [f"driver {n}" for n in mech.drivers] + [
            f"joint {n}" for n, j in mech.joints.items()
            if n not in mech.drivers and (j.spring is not None or j.limits is not None)]
    t = grid_dt * np.arange(int(math.floor(t_end / grid_dt + 1e-9)) + 1)
    errors: dict[str, list[float]] = {s: [] for s in series}
    walls = []
    for dt in dts:
        res = simulate(mech, t_end, method="iterative", dt=dt, model=model)
        walls.append(res.stats.wall_time)
        for s in series:
            errors[s].append(_error(res, ref, t, s))
    orders = {s: [math.log(e[i - 1] / e[i]) / math.log(dts[i - 1] / dts[i])
                  if e[i] > 0 and e[i - 1] > 0 else math.nan for i in range(1, len(dts))]
              for s, e in errors.items()}
    return Convergence(list(dts), errors, orders, walls, ref_rtol)


@dataclass(frozen=True)
class WorkPrecisionRow:
    """One run of a work-precision study: ``wall`` s, ``error`` in the driving effort
    (N m or N; NaN when the run failed, ``status`` then says why)."""

    method: str
    setting: str
    wall: float
    error: float
    events: int
    status: str = "success"

    @property
    def success(self) -> bool:
        return self.status == "success"


@dataclass(frozen=True)
class WorkPrecision:
    """Error in the driving effort against wall time for both methods (see
    :func:`work_precision`)."""

    rows: list[WorkPrecisionRow]
    reference_rtol: float
    driver: str
    t_end: float

    def table(self) -> str:
        lines = [f"{'method':<10} {'setting':<12} {'wall [s]':>9} {'error':>11}  status"]
        for r in self.rows:
            lines.append(f"{r.method:<10} {r.setting:<12} {r.wall:9.4f} {r.error:11.3e}  "
                         f"{r.status}")
        return "\n".join(lines)


def work_precision(mech: Mechanism, *, t_end: float = 10.0,
                   rtols: tuple[float, ...] = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
                   dts: tuple[float, ...] | None = None,
                   ref_rtol: float = 1e-12, driver: str | None = None,
                   model: Model | None = None, grid: float = 0.01) -> WorkPrecision:
    """Error in the driving effort against wall time, IDA over ``rtols`` and the iterative
    algorithm over ``dts`` (default: ``grid``, its half and its quarter, s); the
    reference is IDA at ``ref_rtol``; errors on the output ``grid`` (s) away from events.

    A run that fails part-way is a row with NaN error and its status; a failing reference
    run raises :class:`CmmError` saying which run it was.

    Returns
    -------
    WorkPrecision
    """
    if not mech.drivers:
        raise CmmError("a work-precision study measures the driving effort: the mechanism "
                       "has no driver")
    model = model or Model(mech)
    driver = driver or next(iter(mech.drivers))
    dts = (grid, grid / 2, grid / 4) if dts is None else dts
    try:
        ref = simulate(mech, t_end, rtol=ref_rtol, output_dt=grid,
                       model=model)
    except SolverError as e:
        raise CmmError(f"the work-precision reference run (IDA at rtol {ref_rtol:g}) failed: "
                       f"{e}") from e
    t = grid * np.arange(int(math.floor(t_end / grid + 1e-9)) + 1)
    runs = [("IDA", f"rtol {rt:g}", dict(method="ida", rtol=rt, atol=rt * 1e-2,
                                           output_dt=grid)) for rt in rtols]
    runs += [("iterative", f"dt {dt:g}", dict(method="iterative", dt=dt,
                                               output_every=max(1, int(round(grid / dt)))))
             for dt in dts]
    rows = []
    for method, setting, kw in runs:
        r = simulate(mech, t_end, model=model, throw=False, **kw)
        err = _error(r, ref, t, f"driver {driver}") if r.success else math.nan
        rows.append(WorkPrecisionRow(method, setting, r.stats.wall_time, err, len(r.events),
                                     str(r.status)))
    return WorkPrecision(rows, ref_rtol, driver, t_end)
