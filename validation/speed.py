"""The speed figures, all measured in one run on this machine, as ratios.

1. Double-folded 10-s cycle at rtol 1e-8: the working tree (default path, and
   ``compiled=True``) against the version before the speed work, in alternating fresh
   subprocesses (``before_after.py``), with the events and driving torque compared.
2. Where the default path's time goes now: a profile split by part.
3. The paper's iterative algorithm: cost per step against an IDA step, same model.
4. Growth of wall time per simulated second with size on chains of 8, 16 and 32 four-bar
   loops.
5. Peak memory of a long run against the Result's own arrays (``memory.py``).
6. The KKT solve (accelerations and multipliers at one state): sparse (SuperLU) against
   dense (LAPACK) LU by size, on A02's N-loop chains; where cmm_dae switches
   (``KKT_SPARSE_FROM``).

Writes validation/out/speed/speed.md. Run: python validation/speed.py  (a few minutes);
``--kkt-only`` runs part 6 alone.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import io
import math
import pstats
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "out" / "speed"
sys.path.insert(0, str(HERE))
import before_after  # noqa: E402
import memory  # noqa: E402

import cmm_dae as cd  # noqa: E402
from cmm_dae.description import iftomm  # noqa: E402
from cmm_dae.equations.kkt import KKT_SPARSE_FROM  # noqa: E402
from cmm_dae.studies.bench import chain_growth, chain_table  # noqa: E402

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


def kkt_sizes(loops=(4, 8, 10, 12, 14, 16, 20, 40), rounds: int = 3) -> list[str]:
    """Sparse over dense KKT solve time on A02 with each number of loops, the cranks at
    0.3 rad past the horizontal (best of ``rounds`` alternating 0.3-s batches each)."""
    out = [f"cmm_dae factors as sparse from size {KKT_SPARSE_FROM}.", "",
           "| loops | KKT size | dense [us] | sparse [us] | sparse / dense |",
           "|---:|---:|---:|---:|---:|"]
    for n in loops:
        model = cd.Model(iftomm.a02_four_bar(n))
        p = model.params()
        th = -math.pi + 0.3
        q = [[i + 0.5 * math.cos(th), 0.5 * math.sin(th), th] for i in range(n + 1)]
        q += [[i - 0.5 + math.cos(th), math.sin(th), 0.0] for i in range(1, n + 1)]
        q = [x for row in q for x in row]
        parts = model._kkt_parts(q, [0.0] * len(q), 0.0, p)
        best = {False: math.inf, True: math.inf}
        for _ in range(rounds):
            for mode in best:
                model.kkt_sparse = mode
                t0, k = time.perf_counter(), 0
                while time.perf_counter() - t0 < 0.3:
                    model.kkt_from(*parts, p)
                    k += 1
                best[mode] = min(best[mode], (time.perf_counter() - t0) / k)
        out.append(f"| {n} | {model.nq + model.m} | {best[False] * 1e6:.0f} | "
                   f"{best[True] * 1e6:.0f} | {best[True] / best[False]:.2f} |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--memory-t-end", type=float, default=1000.0)
    ap.add_argument("--kkt-only", action="store_true", help="part 6 alone (printed)")
    a = ap.parse_args(argv)
    if a.kkt_only:
        print("\n".join(kkt_sizes()))
        return 0
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

    # per step, side by side in alternating subprocesses: IDA and the iterative algorithm
    # (dt 1e-3) of this tree, and the iterative algorithm of the version before
    model_file = ROOT / "models" / "double_folded.toml"
    with tempfile.TemporaryDirectory() as tmp:
        old = before_after.unpack(before_after.BEFORE_SPEED, Path(tmp))
        cache = str(Path(tmp) / "cache")
        before_after.job(ROOT, model_file, 0.1, 1e-8, 0, True, cache)  # the one-off build
        per: dict[str, list[float]] = {}
        for _ in range(a.rounds):
            for name, path, kw in (
                    ("IDA", ROOT, {}), ("IDA compiled", ROOT, {"compiled": True}),
                    ("iterative", ROOT, {"method": "iterative"}),
                    ("iterative before", old, {"method": "iterative"})):
                rt = 1e-3 if "method" in kw else 1e-8
                r = before_after.job(path, model_file, 10.0, rt, 3, cache=cache, **kw)
                per.setdefault(name, []).append(r["wall"] / r["steps"])
    med = {k: statistics.median(v) for k, v in per.items()}
    lines += ["## 3. Cost per step, double-folded 10 s (medians of alternating subprocesses)",
              "",
              f"- IDA (default path, rtol 1e-8): {med['IDA'] * 1e6:.1f} us per step",
              f"- IDA compiled: {med['IDA compiled'] * 1e6:.1f} us per step "
              f"({med['IDA'] / med['IDA compiled']:.2f}x less)",
              f"- iterative algorithm, dt 1e-3: {med['iterative'] * 1e6:.1f} us per step, "
              f"{med['iterative'] / med['IDA']:.2f} x an IDA step",
              f"- the iterative algorithm before ({before_after.BEFORE_SPEED}): "
              f"{med['iterative before'] * 1e6:.1f} us per step, "
              f"{med['iterative before'] / med['IDA']:.2f} x an IDA step "
              f"({med['iterative before'] / med['iterative']:.2f}x the time of now)", ""]
    print("\n".join(lines[-7:]), flush=True)

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
    lines += ["## 6. KKT solve: sparse over dense LU by size (A02, N loops)", "",
              *kkt_sizes(), ""]
    print("\n".join(lines[-12:]), flush=True)
    (OUT / "speed.md").write_text("\n".join(lines))
    print(f"wrote {OUT / 'speed.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
