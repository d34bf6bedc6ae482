"""The cost of a step of the paper's fixed-step algorithm against an IDA step, side by side
in one process: the double-folded mechanism over 10 s, IDA at its default tolerance
(compiled segment), the fixed-step algorithm at dt 1e-3 with its step in C
(``compiled=True``: ``integrators/cstep.py`` and the C loop ``fixedstep.c``) and on CasADi's
virtual machine (``compiled=False``, the path before). Alternating rounds, the best of 3
runs each, medians over the rounds; the two fixed-step paths must give the same events
and positions to 1e-12.

    python validation/fixed_step.py              # 5 rounds
    python validation/fixed_step.py --rounds 9 --model models/slotted_link.toml
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

import cmm_dae as cd

ROOT = Path(__file__).resolve().parent.parent


def per_step(run) -> tuple[float, cd.Result]:
    """Best of three warm runs: seconds per step, and the result."""
    res = run()
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        res = run()
        best = min(best, time.perf_counter() - t0)
    return best / res.stats.steps, res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default=str(ROOT / "models" / "double_folded.toml"))
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--rounds", type=int, default=5)
    a = ap.parse_args()
    mech = cd.load(a.model)
    model = cd.Model(mech)
    jobs = {"IDA": lambda: cd.run_dae(mech, a.t_end, model=model, compiled=True),
            "fixed step, C": lambda: cd.run_iterative(mech, a.t_end, dt=a.dt, model=model,
                                                      compiled=True),
            "fixed step, virtual machine": lambda: cd.run_iterative(
                mech, a.t_end, dt=a.dt, model=model, compiled=False)}
    per: dict[str, list[float]] = {k: [] for k in jobs}
    out: dict[str, cd.Result] = {}
    for _ in range(a.rounds):
        for name, run in jobs.items():
            s, out[name] = per_step(run)
            per[name].append(s)
    c, vm = out["fixed step, C"], out["fixed step, virtual machine"]
    same = [(e.kind, e.joint) for e in c.events] == [(e.kind, e.joint) for e in vm.events]
    gap = max((abs(x.t - y.t) for x, y in zip(c.events, vm.events, strict=True)), default=0.0)
    dq = float(np.max(np.abs(c.data["q"] - vm.data["q"])))
    ida = statistics.median(per["IDA"])
    print(f"{Path(a.model).name}, {a.t_end} s; medians of {a.rounds} alternating rounds "
          "(best of 3 warm runs each)\n")
    print("| path | us per step | steps | x an IDA step |\n|---|---:|---:|---:|")
    for name in jobs:
        med = statistics.median(per[name])
        print(f"| {name} | {med * 1e6:.1f} | {out[name].stats.steps} | {med / ida:.2f} |")
    print(f"\nC and virtual machine: same events {same}, largest event-time gap {gap:.1e} s, "
          f"largest position gap {dq:.1e}")
    if not (same and gap <= 1e-12 and dq <= 1e-12):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
