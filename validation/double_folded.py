"""The planar double-folded metamorphic mechanism (paper section 4.1): IDA and the paper's
iterative algorithm (dt = 0.01 s, as the paper) over one and two working cycles.

Writes validation/out/double_folded/: the paper-style figures (driving torque, Fig. 16;
relative motion of D and E, Fig. 17; constraint force/torque of D and E, Figs. 18-19),
difference plots, the event timeline, the comparison report and summary.md with the
switching-time table (IDA, iterative, paper: 2.63 s and 7.3 s).

Run: python validation/double_folded.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import cmm_dae as cd

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(__file__).resolve().parent / "out" / "double_folded"
PAPER = {("limit", "E", 0): 2.63, ("release", "E", 0): 7.3, ("limit", "E", 1): 12.63,
         ("release", "E", 1): 17.3}


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    mech = cd.load(ROOT / "models" / "double_folded.toml")
    model = cd.Model(mech)
    lines = ["# Double-folded metamorphic mechanism: validation", ""]
    for cycles in (1, 2):
        t_end = 10.0 * cycles
        a = cd.run_dae(mech, t_end, rtol=1e-8, atol=1e-10, output_dt=0.01, model=model)
        b = cd.run_iterative(mech, t_end, dt=0.01, model=model)
        cmp = cd.compare(a, b)
        sub = OUT / f"{cycles}_cycle{'s' if cycles > 1 else ''}"
        cmp.write_report(sub)
        lines += [f"## {cycles} working cycle{'s' if cycles > 1 else ''} ({t_end:g} s)", "",
                  "| event | IDA (rtol 1e-8) [s] | iterative (dt 0.01) [s] | paper [s] |",
                  "|---|---:|---:|---:|"]
        count: dict[tuple, int] = {}
        for ea in a.events:
            k = (ea.kind, ea.joint)
            i = count.get(k, 0)
            count[k] = i + 1
            tb = [e.t for e in b.events if (e.kind, e.joint) == k]
            lines.append(f"| {ea.kind} {ea.joint} | {ea.t:.6f} | "
                         f"{tb[i] if i < len(tb) else float('nan'):.2f} | "
                         f"{PAPER.get((ea.kind, ea.joint, i), float('nan')):.2f} |")
        eff_a, eff_b = a.driver("A").effort, b.driver("A").effort
        s = {x.name: x for x in cmp.series}
        lines += ["", f"- driving torque (IDA): {eff_a.min():.4f} .. {eff_a.max():.4f} N m; "
                  f"(iterative): {eff_b.min():.4f} .. {eff_b.max():.4f} N m",
                  f"- max |IDA - iterative| driving torque away from switches: "
                  f"{s['driver A effort'].max_abs:.3e} N m "
                  f"({s['driver A effort'].max_rel:.2e} of the peak)",
                  f"- wall time: IDA {a.stats.wall_time * 1e3:.1f} ms ({a.stats.steps} steps), "
                  f"iterative {b.stats.wall_time * 1e3:.1f} ms ({b.stats.steps} steps)",
                  f"- IDA constraint drift: |Phi| <= {a.drift[0]:.2e}, "
                  f"|Phi'| <= {a.drift[1]:.2e}",
                  f"- configurations: {' -> '.join(a.configurations[c].label for c in _runs(a))}",
                  ""]
        if cycles == 1:
            D = a.joint("D").position
            i = int(np.searchsorted(a.t, 0.3))
            lines += ["### Start-up jump at D", "",
                      f"The spring at D is unloaded at t = 0 (rest = initial angle "
                      f"{mech.joints['D'].spring.rest:.6f} rad); gravity and the slider's "
                      f"inertia bend it at once: D moves by {D[i] - D[0]:+.4f} rad "
                      f"({np.degrees(D[i] - D[0]):+.2f} deg) in the first 0.3 s, then stays "
                      f"within {np.ptp(D[i:int(np.searchsorted(a.t, a.events[0].t))]):.4f} "
                      "rad until the slider meets E. The paper explains the jump the same "
                      "way: a spring pre-deflected by a static analysis at t = 0 removes it.",
                      ""]
    (OUT / "summary.md").write_text("\n".join(lines))
    print("\n".join(lines))
    print(f"wrote {OUT}")


def _runs(res):
    out = []
    for c in res.configuration:
        if not out or out[-1] != c:
            out.append(int(c))
    return out


if __name__ == "__main__":
    main()
