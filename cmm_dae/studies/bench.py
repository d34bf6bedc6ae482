"""Benchmarks of the shipped models: build time, wall time per simulated second, steps,
evaluations, events and peak memory, for IDA (Python path and, where a C compiler is
present, the compiled segment) and the paper's iterative algorithm, measured side by side
in one run, with each method's time as a ratio to IDA's; and the growth of wall time with
size on a chain of four-bar loops (``cmm-dae bench``; validation/benchmark.py adds the
minimal-coordinate DOP853 model and the work-precision study)."""

from __future__ import annotations

import gc
import math
import time
import tracemalloc
from pathlib import Path

from ..description.library import four_bar_chain
from ..description.loader import load
from ..equations.model import Model
from ..integrators import csegment
from ..simulation.runner import simulate


def best_time(fn, repeat: int) -> tuple[float, object]:
    """Best wall time of ``repeat`` warm runs (the first run warms caches and is dropped)."""
    return best_times([fn], repeat)[0]


def best_times(fns: list, repeat: int) -> list[tuple[float, object]]:
    """:func:`best_time` of several functions side by side: each warmed once, then
    ``repeat`` rounds in which each runs once in turn, so that a slow spell of a shared
    machine falls on all of them (timed one after the other, a spell had moved a ratio
    by a third): (best wall time, last result) of each; (nan, None) for a None in
    ``fns`` (nothing to time: a peer's run with no cmm_dae setting to match it)."""
    res = [fn() if fn is not None else None for fn in fns]
    best = [float("inf") if fn is not None else math.nan for fn in fns]
    for _ in range(repeat):
        for i, fn in enumerate(fns):
            if fn is None:
                continue
            gc.collect()
            t = time.perf_counter()
            res[i] = fn()
            best[i] = min(best[i], time.perf_counter() - t)
    return list(zip(best, res, strict=True))


def _peak(fn) -> float:
    """Peak Python-side memory (numpy arrays included) of one run, MiB."""
    gc.collect()
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


def bench_models(models: list[Path], *, t_end: float = 10.0, rtol: float = 1e-8,
                 dt: float = 0.01, repeat: int = 3, compiled: bool = True) -> list[dict]:
    """One row per model and method ("IDA", "IDA compiled" when ``compiled`` and a C
    compiler works here (its one-off build is done before timing), "iterative");
    ``vs_IDA`` is IDA's wall time over the method's."""
    compiled = compiled and csegment.available() is None
    rows = []
    for path in models:
        mech = load(path)
        t0 = time.perf_counter()
        model = Model(mech)
        build = time.perf_counter() - t0
        runs = {
            "IDA": lambda m=mech, mo=model: simulate(m, t_end, rtol=rtol, model=mo,
                                                      compiled=False),
        }
        if compiled and not model.callables:
            runs["IDA compiled"] = lambda m=mech, mo=model: simulate(
                m, t_end, rtol=rtol, model=mo, compiled=True)
        runs["iterative"] = lambda m=mech, mo=model: simulate(m, t_end, method="iterative",
                                                               dt=dt, model=mo)
        ida_wall = None
        for method, fn in runs.items():
            wall, res = best_time(fn, repeat)
            ida_wall = wall if ida_wall is None else ida_wall
            rows.append({"model": path.stem, "method": method, "build_s": build,
                         "wall_s": wall, "wall_per_sim_s": wall / t_end,
                         "us_per_step": 1e6 * wall / max(res.stats.steps, 1),
                         "vs_IDA": ida_wall / wall,
                         "steps": res.stats.steps, "nfev": res.stats.nfev,
                         "njev": res.stats.njev, "events": len(res.events),
                         "peak_MiB": _peak(fn), "drift": res.drift[0]})
    return rows


def chain_growth(sizes: tuple[int, ...] = (8, 16, 32), *, t_end: float = 1.0,
                 rtol: float = 1e-8, repeat: int = 3) -> tuple[list[dict], float]:
    """Wall time per simulated second of a swinging chain of n four-bar loops
    (:func:`cmm_dae.description.library.four_bar_chain`, one DOF, no singular position) for each n,
    default options, and the growth exponent from the first size to the last (the slope
    of log wall time over log n)."""

    rows = []
    for n in sizes:
        mech = four_bar_chain(n)
        model = Model(mech)
        wall, res = best_time(lambda m=mech, mo=model: simulate(m, t_end, rtol=rtol,
                                                            model=mo), repeat)
        rows.append({"n": n, "unknowns": model.N, "wall_per_sim_s": wall / t_end,
                     "steps": res.stats.steps})
    a, b = rows[0], rows[-1]
    return rows, math.log(b["wall_per_sim_s"] / a["wall_per_sim_s"]) / math.log(b["n"] / a["n"])


def table(rows: list[dict]) -> str:
    head = (f"{'model':<20} {'method':<12} {'build [ms]':>10} {'wall [ms]':>10} "
            f"{'ms per sim s':>12} {'us/step':>8} {'x IDA':>6} {'steps':>7} {'res.ev':>7} "
            f"{'jac.ev':>7} {'events':>6} {'peak MiB':>9} {'|Phi| max':>10}")
    out = [head, "-" * len(head)]
    for r in rows:
        out.append(f"{r['model']:<20} {r['method']:<12} {r['build_s'] * 1e3:10.1f} "
                   f"{r['wall_s'] * 1e3:10.1f} {r['wall_per_sim_s'] * 1e3:12.2f} "
                   f"{r['us_per_step']:8.1f} {r['vs_IDA']:6.2f} "
                   f"{r['steps']:7d} {r['nfev']:7d} {r['njev']:7d} {r['events']:6d} "
                   f"{r['peak_MiB']:9.2f} {r['drift']:10.2e}")
    return "\n".join(out)


def chain_table(rows: list[dict], exponent: float) -> str:
    out = [f"{'loops':>5} {'unknowns':>8} {'ms per sim s':>12} {'steps':>6}"]
    out += [f"{r['n']:5d} {r['unknowns']:8d} {r['wall_per_sim_s'] * 1e3:12.1f} "
            f"{r['steps']:6d}" for r in rows]
    out.append(f"growth of wall time per simulated second: n^{exponent:.2f} "
               f"(n = {rows[0]['n']} to {rows[-1]['n']})")
    return "\n".join(out)
