"""Benchmarks of the shipped models: build time, wall time per simulated second, steps,
evaluations, events and peak memory, for IDA and the paper's iterative algorithm, measured
side by side in one run (``cmm-dae bench``; validation/benchmark.py adds the
minimal-coordinate DOP853 model and the work-precision study)."""

from __future__ import annotations

import gc
import time
import tracemalloc
from pathlib import Path

from .equations import Model
from .loader import load
from .runner import simulate


def _best(fn, repeat: int) -> tuple[float, object]:
    """Best wall time of ``repeat`` warm runs (the first run warms caches and is dropped)."""
    res = fn()
    best = float("inf")
    for _ in range(repeat):
        gc.collect()
        t = time.perf_counter()
        res = fn()
        best = min(best, time.perf_counter() - t)
    return best, res


def _peak(fn) -> float:
    """Peak Python-side memory (numpy arrays included) of one run, MiB."""
    gc.collect()
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


def bench_models(models: list[Path], *, t_end: float = 10.0, rtol: float = 1e-8,
                 dt: float = 0.01, repeat: int = 3) -> list[dict]:
    """One row per model and method."""
    rows = []
    for path in models:
        mech = load(path)
        t0 = time.perf_counter()
        model = Model(mech)
        build = time.perf_counter() - t0
        runs = {
            "IDA": lambda m=mech, mo=model: simulate(m, t_end, rtol=rtol, atol=rtol * 1e-2,
                                                      model=mo),
            "iterative": lambda m=mech, mo=model: simulate(m, t_end, method="iterative", dt=dt,
                                                            model=mo),
        }
        for method, fn in runs.items():
            wall, res = _best(fn, repeat)
            rows.append({"model": path.stem, "method": method, "build_s": build,
                         "wall_s": wall, "wall_per_sim_s": wall / t_end,
                         "steps": res.stats.steps, "nfev": res.stats.nfev,
                         "njev": res.stats.njev, "events": len(res.events),
                         "peak_MiB": _peak(fn), "drift": res.drift[0]})
    return rows


def table(rows: list[dict]) -> str:
    head = (f"{'model':<20} {'method':<10} {'build [ms]':>10} {'wall [ms]':>10} "
            f"{'ms per sim s':>12} {'steps':>7} {'res.ev':>7} {'jac.ev':>7} {'events':>6} "
            f"{'peak MiB':>9} {'|Phi| max':>10}")
    out = [head, "-" * len(head)]
    for r in rows:
        out.append(f"{r['model']:<20} {r['method']:<10} {r['build_s'] * 1e3:10.1f} "
                   f"{r['wall_s'] * 1e3:10.1f} {r['wall_per_sim_s'] * 1e3:12.2f} "
                   f"{r['steps']:7d} {r['nfev']:7d} {r['njev']:7d} {r['events']:6d} "
                   f"{r['peak_MiB']:9.2f} {r['drift']:10.2e}")
    return "\n".join(out)
