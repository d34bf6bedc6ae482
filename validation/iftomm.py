"""The IFToMM benchmarks A01 (simple pendulum) and A02 (N four-bar mechanism).

Writes the benchmark's own metrics in its table form to ``validation/out/iftomm.md``:
the error of the reference point against an independent reference (A01: the exact
elliptic-function solution; A02: the one-DOF reduction on the parallelogram branch), the
drift of the total energy, the cost (wall time per simulated second, steps) and, for A01,
the steps of the same IDA on a minimal-coordinate residual of the pendulum, measured in
the same run.

    python validation/iftomm.py                 # A01 2000 s, A02 N = 1, 10, 40 over 20 s
    python validation/iftomm.py --quick         # A01 200 s, A02 N = 1, 10 over 20 s
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import sksundae as sun

import cmm_dae as cd
from cmm_dae.description import iftomm

OUT = Path(__file__).resolve().parent / "out"


def _ida_on(res, y0: np.ndarray, yp0: np.ndarray, grid: np.ndarray, rtol: float,
            atol=None, algebraic=()):
    """scikit-sundae's IDA on a residual, counting its steps (the root function runs once
    a step, as in cmm_dae, and at output times, which are not steps): (solution, steps).
    atol defaults to 1e-2 rtol, as cmm_dae's."""
    steps, last = [0], [-1.0]
    outs = set(grid.tolist())

    def events(t, y, yp, out):
        if t > last[0] and t not in outs:
            last[0] = t
            steps[0] += 1
        out[0] = 1.0

    events.terminal, events.direction = [False], [0]
    solver = sun.ida.IDA(res, rtol=rtol, atol=rtol * 1e-2 if atol is None else atol,
                         eventsfn=events, num_events=1, max_num_steps=100_000_000,
                         algebraic_idx=list(algebraic) or None)
    return solver.solve(grid, y0, yp0), steps[0]


def minimal_a01(t_end: float, rtol: float) -> tuple[int, float, float]:
    """The same IDA on the pendulum's minimal residual (angle from +x, rate): steps, wall
    time and the mass's largest position error against the exact solution."""
    g = iftomm.G

    def res(t, y, yp, r):
        r[0] = yp[0] - y[1]
        r[1] = yp[1] + g * np.cos(y[0])

    grid = np.linspace(0.0, t_end, int(t_end / 0.1) + 1)
    t0 = time.perf_counter()
    sol, steps = _ida_on(res, np.array([0.0, 0.0]), np.array([0.0, -g]), grid, rtol)
    wall = time.perf_counter() - t0
    pos = np.column_stack([np.cos(sol.y[:, 0]), np.sin(sol.y[:, 0])])
    return steps, wall, float(np.max(np.hypot(*(pos - iftomm.a01_reference(sol.t)).T)))


def minimal_a02(n: int, t_end: float, rtol: float, atol: float | None = None,
                cuts: tuple[float, ...] = ()) -> tuple[int, float]:
    """The same IDA on A02's one-DOF residual (crank angle, rate): steps and the tip's
    largest error against the DOP853 reference (atol: rtol / 100 by default). ``cuts``:
    times (s) from which a fresh IDA goes on from the state reached, as a cmm_dae run
    restarts after each crossing (its output grid then the multiples of 0.01 s within
    each piece, and its end)."""
    inertia = (n + 1) / 3.0 + n
    weight = ((n + 1) / 2.0 + n) * iftomm.G

    def res(t, y, yp, r):
        r[0] = yp[0] - y[1]
        r[1] = yp[1] + weight * np.cos(y[0]) / inertia

    bounds = [0.0, *[c for c in cuts if 0.0 < c < t_end], t_end]
    y, steps, worst = np.array([np.pi / 2, -1.0]), 0, 0.0
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        grid = (np.linspace(0.0, t_end, int(t_end / 0.01) + 1) if len(bounds) == 2
                else np.append(np.arange(a, b, 0.01), b))
        sol, k = _ida_on(res, y, np.array([y[1], -weight * np.cos(y[0]) / inertia]), grid,
                         rtol, atol=atol)
        tip = np.column_stack([np.cos(sol.y[:, 0]), np.sin(sol.y[:, 0])])
        worst = max(worst, float(np.max(np.hypot(
            *(tip - iftomm.a02_reference(n, sol.t)).T))))
        y, steps = sol.y[-1].copy(), steps + k
    return steps, worst


def run_a01(t_end: float, rtol: float) -> dict:
    mech = cd.load(cd.example("iftomm_a01_pendulum"))
    t0 = time.perf_counter()
    res = cd.run_dae(mech, t_end, rtol=rtol, atol=rtol * 1e-2, output_dt=0.1)
    wall = time.perf_counter() - t0
    err = np.hypot(*(res.body("bob").pose[:, :2] + np.column_stack(
        [np.cos(res.body("bob").pose[:, 2]), np.sin(res.body("bob").pose[:, 2])])
        - iftomm.a01_reference(res.t)).T)
    e = res.energy()
    total = e.kinetic + e.potential
    m_steps, m_wall, m_err = minimal_a01(t_end, rtol)
    return dict(problem="A01", case="simple pendulum", t_end=t_end, rtol=rtol,
                error=float(err.max()), energy=float(np.max(np.abs(total - total[0]))),
                wall_per_s=wall / t_end, steps=res.stats.steps, events=len(res.events),
                minimal_steps=m_steps, minimal_error=m_err, minimal_wall_per_s=m_wall / t_end)


def run_a02(n: int, t_end: float, rtol: float) -> dict:
    mech = iftomm.a02_four_bar(n)
    t0 = time.perf_counter()
    res = cd.run_dae(mech, t_end, rtol=rtol, atol=rtol * 1e-2, throw=False)
    wall = time.perf_counter() - t0
    err = np.hypot(*(iftomm.crank_tip(res) - iftomm.a02_reference(n, res.t)).T)
    e = res.energy()
    total = e.kinetic + e.potential
    m_steps, m_err = minimal_a02(n, t_end, rtol)
    return dict(problem="A02", case=f"N = {n}", t_end=float(res.t[-1]), rtol=rtol,
                minimal_steps=m_steps, minimal_error=m_err,
                error=float(err.max()), energy=float(np.max(np.abs(total - total[0]))),
                wall_per_s=wall / max(res.t[-1], 1e-300), steps=res.stats.steps,
                events=sum(ev.kind == "singular" for ev in res.events),
                status=str(res.status))


def table(rows: list[dict]) -> str:
    out = ["| problem | case | simulated [s] | rtol | max error of the reference point [m] | "
           "max energy drift [J] | wall per simulated s [s] | IDA steps | singular "
           "positions crossed | status |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        out.append(f"| {r['problem']} | {r['case']} | {r['t_end']:g} | {r['rtol']:g} | "
                   f"{r['error']:.2e} | {r['energy']:.2e} | {r['wall_per_s']:.3g} | "
                   f"{r['steps']} | {r['events']} | {r.get('status', 'success')} |")
    for r in rows:
        if r["problem"] == "A02":
            out += ["", f"A02 {r['case']}, the same IDA on the one-DOF residual (crank angle, "
                    f"rate) at rtol {r['rtol']:g}: {r['minimal_steps']} steps (cmm_dae / "
                    f"minimal = {r['steps'] / r['minimal_steps']:.2f}), error "
                    f"{r['minimal_error']:.2e} m."]
    a01 = [r for r in rows if r["problem"] == "A01"]
    for r in a01:
        out += ["", f"A01, the same IDA on the minimal-coordinate residual (angle, rate) at "
                f"rtol {r['rtol']:g}: {r['minimal_steps']} steps (cmm_dae / minimal = "
                f"{r['steps'] / r['minimal_steps']:.2f}), error {r['minimal_error']:.2e} m, "
                f"wall per simulated s {r['minimal_wall_per_s']:.3g} s."]
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="A01 200 s; A02 N = 1, 10 only")
    ap.add_argument("--a01-rtol", type=float, default=1e-11)
    ap.add_argument("--a02-rtol", type=float, default=1e-10)
    args = ap.parse_args()
    rows = [run_a01(200.0 if args.quick else 2000.0, args.a01_rtol)]
    print(table(rows), flush=True)
    for n in (1, 10) if args.quick else (1, 10, 40):
        rows.append(run_a02(n, 20.0, args.a02_rtol))
        print(table(rows[-1:]).split("\n")[2], flush=True)
    OUT.mkdir(exist_ok=True)
    (OUT / "iftomm.md").write_text("# IFToMM A01 and A02\n\n" + table(rows) + "\n")
    print(f"wrote {OUT / 'iftomm.md'}")


if __name__ == "__main__":
    main()
