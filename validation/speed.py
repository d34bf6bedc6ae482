"""The speed figures, all measured in one run on this machine, as ratios.

1. Double-folded 10-s cycle at rtol 1e-8: the working tree (default path, and
   ``compiled=True``) against the version before the speed work, in alternating fresh
   subprocesses (``before_after.py``), with the events and driving torque compared.
2. Where the default path's time goes now: a profile split by part.
3. The paper's iterative algorithm: cost per step against an IDA step, same model.
4. Growth of wall time per simulated second with size on chains of 8, 16 and 32 four-bar
   loops.
5. Peak memory of a long run against the Result's own arrays (``memory.py``).

Writes validation/out/speed/speed.md. Run: python validation/speed.py  (a few minutes)
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import io
import pstats
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "out" / "speed"
sys.path.insert(0, str(HERE))
import before_after  # noqa: E402
import memory  # noqa: E402

import cmm_dae as cd  # noqa: E402
from cmm_dae.bench import chain_growth, chain_table  # noqa: E402

#: profile entries (file fragment, function) -> part
PARTS = [
    ("_solver.py", "solve", "scikit-sundae's wrapper and IDA's C loop"),
    ("ida.py", "resfn", "residual"), ("ida.py", "_jacobian", "Jacobian"),
    ("ida.py", "eventsfn", "event functions"),
    ("post.py", "build_result", "post-processing"),
]


def profile_shares(mech: cd.Mechanism, model: cd.Model) -> list[tuple[str, float]]:
    """Shares of the default path's time by part (cProfile, exclusive of sub-parts)."""
    run = lambda: cd.run_dae(mech, 10.0, model=model)  # noqa: E731
    run()
    prof = cProfile.Profile()
    prof.enable()
    run()
    prof.disable()
    st = pstats.Stats(prof)
    total = sum(v[2] for v in st.stats.values())  # all self times
    cum = {}
    for (file, _, func), (_, _, tt, ct, _) in st.stats.items():
        for frag, name, part in PARTS:
            if file.endswith(frag) and func == name:
                # the wrapper's share is its own time; the others' their whole subtree
                cum[part] = cum.get(part, 0.0) + (tt if part.startswith("scikit") else ct)
    shares = [(part, cum.get(part, 0.0) / total) for part in dict.fromkeys(
        p for _, _, p in PARTS)]
    shares.append(("everything else (hybrid loop, start, policy)",
                   max(0.0, 1.0 - sum(s for _, s in shares))))
    return shares


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--memory-t-end", type=float, default=1000.0)
    a = ap.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    lines = ["# Speed", "", f"Python {sys.version.split()[0]}, {sys.platform}; ratios "
             "measured side by side in this run.", ""]

    lines += ["## 1. Double-folded 10-s cycle, rtol 1e-8: before / after", "", "```"]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        before_after.main(["--before", before_after.BEFORE_SPEED, "--compiled",
                           "--rounds", str(a.rounds)])
    lines += [buf.getvalue().rstrip(), "```", ""]
    print("\n".join(lines[-4:]), flush=True)

    mech = cd.load(cd.example("double_folded"))
    model = cd.Model(mech)
    lines += ["## 2. Profile of the default path after the change", "",
              "| part | share |", "|---|---:|"]
    for part, share in profile_shares(mech, model):
        lines.append(f"| {part} | {100 * share:.0f} % |")
    lines.append("")

    def per_step(**kw) -> float:
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            r = cd.simulate(mech, 10.0, model=model, **kw)
            best = min(best, time.perf_counter() - t0)
        return best / r.stats.steps

    cd.simulate(mech, 0.1, model=model, compiled=True)  # the one-off build
    ida, comp = per_step(), per_step(compiled=True)
    it = per_step(method="iterative", dt=1e-3)
    lines += ["## 3. Cost per step, double-folded 10 s", "",
              f"- IDA (default path): {ida * 1e6:.1f} us per step",
              f"- IDA compiled: {comp * 1e6:.1f} us per step ({ida / comp:.2f}x less)",
              f"- iterative algorithm, dt 1e-3: {it * 1e6:.1f} us per step, "
              f"{it / ida:.2f} x an IDA step", ""]
    print("\n".join(lines[-6:]), flush=True)

    rows, expo = chain_growth()
    lines += ["## 4. Chains of four-bar loops (default options, 1 s)", "", "```",
              chain_table(rows, expo), "```", ""]
    print("\n".join(lines[-6:]), flush=True)

    lines += [f"## 5. Memory, double-folded {a.memory_t_end:g} s", "", "```"]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        memory.main(["--t-end", str(a.memory_t_end)])
    lines += [buf.getvalue().rstrip(), "```", ""]
    print("\n".join(lines[-4:]), flush=True)
    (OUT / "speed.md").write_text("\n".join(lines))
    print(f"wrote {OUT / 'speed.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
