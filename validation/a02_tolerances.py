"""A02's accuracy against the tolerance: where the error of a run through singular positions
comes from, and how much it moves with the last bit of atol.

For IFToMM A02 (one and ten four-bar loops, 10 s) at rtol 1e-8 .. 1e-12, each with atol =
rtol / 100 and that value times 1 +- 1e-7: the crank tip's largest error against the
one-degree-of-freedom reference (DOP853), IDA's steps, the singular positions crossed; the
largest change of the total energy across a crossing (from the last sample before its
instant to the first after it) and within the IDA segments between them; and the same IDA
on the minimal-coordinate residual (crank angle and rate, no singular position) at the
same tolerances, once in one run and once restarted at the run's singular instants (a fresh
IDA from each, as the run restarts after each crossing: what restarting alone does to the
error). Writes ``validation/out/a02_tolerances.md``.

    python validation/a02_tolerances.py            # N = 1 and 10 (about 2 min)
    python validation/a02_tolerances.py --loops 1
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from iftomm import OUT, minimal_a02  # noqa: E402

import cmm_dae as cd  # noqa: E402
from cmm_dae.description import iftomm  # noqa: E402

RTOLS = (1e-8, 1e-10, 1e-11, 1e-12)
#: atol = rtol / 100 times these: its last bits
ATOL_FACTORS = (1.0, 1.0 + 1e-7, 1.0 - 1e-7)


def energy_changes(res: cd.Result) -> tuple[float, float]:
    """The largest |change| of kinetic + potential energy (J) across one crossing and
    within one stretch of IDA segments between crossings (or from the start or to the end)."""
    e = res.energy()
    total = e.kinetic + e.potential
    across, within, last = 0.0, 0.0, 0
    for ev in res.events:
        if ev.kind != "singular":
            continue
        before = int(np.searchsorted(res.t, ev.t)) - 1  # the last sample before the instant
        after = int(np.searchsorted(res.t, ev.t, side="right"))  # the first after it
        if before < 0 or after >= res.t.size:
            continue
        across = max(across, abs(total[after] - total[before]))
        within = max(within, abs(total[before] - total[last]))
        last = after
    within = max(within, abs(total[-1] - total[last]))
    return across, within


def rows(n: int, t_end: float) -> list[dict]:
    mech = iftomm.a02_four_bar(n)
    out = []
    for rtol in RTOLS:
        for f in ATOL_FACTORS:
            atol = rtol * 1e-2 * f
            res = cd.run_dae(mech, t_end, rtol=rtol, atol=atol, output_dt=None, throw=False)
            err = float(np.max(np.hypot(*(iftomm.crank_tip(res)
                                          - iftomm.a02_reference(n, res.t)).T)))
            across, within = energy_changes(res)
            out.append(dict(n=n, rtol=rtol, factor=f, status=res.status.value,
                            t=float(res.t[-1]), error=err, steps=res.stats.steps,
                            crossings=sum(e.kind == "singular" for e in res.events),
                            across=across, within=within,
                            minimal=minimal_a02(n, t_end, rtol, atol)[1],
                            restarted=minimal_a02(n, t_end, rtol, atol, tuple(
                                e.t for e in res.events if e.kind == "singular"))[1]))
            print(_row(out[-1]), flush=True)
    return out


HEADER = ("| N | rtol | atol / (rtol/100) | status | tip error (m) | steps | crossings | "
          "max dE across a crossing (J) | max dE between crossings (J) | minimal-coordinate "
          "IDA's tip error (m) | the same restarted at the run's singular instants (m) |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|")


def _row(r: dict) -> str:
    return (f"| {r['n']} | {r['rtol']:.0e} | {r['factor']!r} | {r['status']} | "
            f"{r['error']:.2e} | {r['steps']} | {r['crossings']} | {r['across']:.1e} | "
            f"{r['within']:.1e} | {r['minimal']:.2e} | {r['restarted']:.2e} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--loops", type=int, nargs="+", default=[1, 10])
    ap.add_argument("--t-end", type=float, default=10.0)
    args = ap.parse_args(argv)
    print(HEADER)
    table = [r for n in args.loops for r in rows(n, args.t_end)]
    OUT.mkdir(exist_ok=True)
    (OUT / "a02_tolerances.md").write_text(
        f"# A02 over {args.t_end:g} s: error against the tolerance\n\n{HEADER}\n"
        + "\n".join(_row(r) for r in table) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
