"""How the double-folded mechanism's switching times move with the spring stiffness at D
and the stop position at E (a 12 x 9 grid, 108 runs), and sweep throughput: runs per second
per core on the local process pool and on a dask LocalCluster, measured in one run.

Writes validation/out/sweep_double_folded/: sweep.csv, switching_times.png, summary.md.
Run: python validation/sweep_double_folded.py
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

import cmm_dae as cd
from cmm_dae.report import plots

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(__file__).resolve().parent / "out" / "sweep_double_folded"


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    mech = cd.load(ROOT / "models" / "double_folded.toml")
    k0 = mech.joints["D"].spring.stiffness
    ks = list(np.round(k0 * np.array([0.3, 0.4, 0.5, 0.6, 0.7, 0.85, 1.0, 1.2, 1.5, 2.0, 3.0,
                                      4.0]), 6))
    stops = list(np.round(np.linspace(0.235, 0.26, 9), 5))
    grid = {"joints.D.spring.stiffness": ks, "joints.E.limits.upper": stops}
    cores = os.cpu_count() or 1
    t0 = time.perf_counter()
    table = cd.sweep(mech, grid, t_end=10.0, workers=cores)
    wall_local = time.perf_counter() - t0
    table.to_csv(OUT / "sweep.csv")
    lines = ["# Double-folded mechanism: switching times over a parameter grid", "",
             f"{len(table)} runs (spring stiffness at D x stop position at E), 10 s each, "
             "IDA rtol 1e-8.", ""]
    ok = [r for r in table.rows if r["status"] == "success"]
    lines.append(f"- successful runs: {len(ok)} of {len(table)}; others: "
                 + (", ".join(f"case {r['case']}: {r['status']} ({r['message'][:80]})"
                              for r in table.rows if r["status"] != "success") or "none"))
    # throughput, local vs LocalCluster, same cases
    rate_local = len(table) / wall_local / cores
    rate_dask = None
    try:
        import distributed

        with distributed.LocalCluster(n_workers=cores, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster, \
                distributed.Client(cluster) as client:
            cd.sweep(mech, {"joints.D.spring.stiffness": ks[:2]}, t_end=10.0, client=client)
            t0 = time.perf_counter()
            t2 = cd.sweep(mech, grid, t_end=10.0, client=client)
            wall_dask = time.perf_counter() - t0
        rate_dask = len(t2) / wall_dask / cores
        same = [{k: v for k, v in r.items() if k != "wall_s"} for r in t2.rows] == \
            [{k: v for k, v in r.items() if k != "wall_s"} for r in table.rows]
        lines.append(f"- dask LocalCluster table identical to the local one: {same}")
    except ImportError:
        lines.append("- dask.distributed not installed: no LocalCluster measurement")
    lines.append(f"- throughput on {cores} cores: local pool {rate_local:.1f} runs/s/core "
                 f"({wall_local:.2f} s for {len(table)} runs)"
                 + (f"; LocalCluster {rate_dask:.1f} runs/s/core" if rate_dask else ""))
    # figure: switching times vs stiffness, one line per stop position
    fig, axes = plots.plt.subplots(1, 2, figsize=(11, 4.5), sharey=False)
    cmap = plots.plt.cm.viridis(np.linspace(0, 1, len(stops)))
    for j, s in enumerate(stops):
        rows = [r for r in ok if r["joints.E.limits.upper"] == s]
        k = [r["joints.D.spring.stiffness"] for r in rows]
        axes[0].plot(k, [r.get("t_limit_E_1", np.nan) for r in rows], "o-", color=cmap[j],
                     ms=3, label=f"stop {s:.4f} m")
        axes[1].plot(k, [r.get("t_release_E_1", np.nan) for r in rows], "o-", color=cmap[j],
                     ms=3)
    for ax, what in zip(axes, ("E locks (slider reaches the stop)", "E releases"),
                        strict=True):
        ax.axvline(k0, color="0.5", ls=":", lw=1)
        ax.set(xscale="log", xlabel="torsional stiffness at D [N m/rad]",
               ylabel="time [s]", title=what)
        ax.grid(alpha=0.3, which="both")
        ax.xaxis.set_minor_formatter(plots.matplotlib.ticker.NullFormatter())
    axes[0].axhline(2.63, color="r", ls="--", lw=1, label="paper: 2.63 s")
    axes[1].axhline(7.3, color="r", ls="--", lw=1, label="paper: 7.3 s")
    axes[0].legend(fontsize=7, ncol=2)
    axes[1].legend(fontsize=7)
    fig.suptitle("double-folded mechanism: switching times vs spring stiffness at D, "
                 "one line per stop position (dotted: Table 2's k)", fontsize=10)
    fig.tight_layout()
    fig.savefig(OUT / "switching_times.png", dpi=110)
    plots.plt.close(fig)
    base = [r for r in ok if abs(r["joints.D.spring.stiffness"] - k0) < 1e-6]
    lines += ["", "At Table 2's stiffness:", "", "| stop [m] | locks [s] | releases [s] |",
              "|---:|---:|---:|"]
    for r in base:
        lines.append(f"| {r['joints.E.limits.upper']:.5f} | {r.get('t_limit_E_1', np.nan):.4f} "
                     f"| {r.get('t_release_E_1', np.nan):.4f} |")
    (OUT / "summary.md").write_text("\n".join(lines))
    print("\n".join(lines))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
