"""What the screen for singular positions IDA stepped over costs a run: the same warm run
with the screen and with it taken out, alternating in one process (medians).

The screen (``simulation.crossing.log_stepped_over``) searches every IDA segment's samples
for a dip of the constraints' singular-value ratio. Taken out here by replacing it with a
function that logs nothing, so that the difference of the medians is its whole cost,
including what post-processing then solves itself (on a banded chain the screen's measure
comes from post-processing's own factorizations of the samples). Two mechanisms:

- the hanging chain of four-bar loops (``cmm_dae.description.library.four_bar_chain``)
  swinging from rest, its first rocker from -13 to +54 degrees: it never nears a singular
  position, so every millisecond of the screen is a false alarm's;
- IFToMM A02 (its crank turns): it passes two singular positions in 2 s, which IDA steps
  over at loose tolerances; there the screen has real work (the passages' instants).

    python validation/screen_cost.py
    python validation/screen_cost.py --loops 32 128 --rtol 1e-4 1e-6 --python
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import cmm_dae as cd
from cmm_dae.description import iftomm
from cmm_dae.description.library import four_bar_chain
from cmm_dae.simulation import runner


def _nothing_logged(*args, **kwargs) -> list:
    return []


def share(mech: cd.Mechanism, rtol: float, compiled: bool, rounds: int = 7
          ) -> tuple[float, float, int, int]:
    """Median warm run with and without the screen (s), IDA's steps and the events."""
    first = cd.run_dae(mech, 2.0, rtol=rtol, compiled=compiled)
    screen = runner.log_stepped_over
    times: dict[bool, list[float]] = {True: [], False: []}
    try:
        for _ in range(rounds):
            for on in (True, False):
                runner.log_stepped_over = screen if on else _nothing_logged
                t0 = time.perf_counter()
                cd.run_dae(mech, 2.0, rtol=rtol, compiled=compiled)
                times[on].append(time.perf_counter() - t0)
    finally:
        runner.log_stepped_over = screen
    return (statistics.median(times[True]), statistics.median(times[False]),
            first.stats.steps, len(first.events))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--loops", type=int, nargs="+", default=[32, 128])
    ap.add_argument("--rtol", type=float, nargs="+", default=[1e-3, 1e-4, 1e-6])
    ap.add_argument("--python", action="store_true",
                    help="the Python path (default: the compiled segment, built first)")
    args = ap.parse_args(argv)
    print("| mechanism | loops | rtol | steps | events | with screen (ms) | without (ms) "
          "| screen's share |\n|---|---|---|---|---|---|---|---|")
    for n in args.loops:
        for name, mech in (("swinging chain", four_bar_chain(n, swing=0.94)),
                           ("A02", iftomm.a02_four_bar(n))):
            for rtol in args.rtol:
                on, off, steps, events = share(mech, rtol, not args.python)
                print(f"| {name} | {n} | {rtol:.0e} | {steps} | {events} | {on * 1e3:.1f} | "
                      f"{off * 1e3:.1f} | {100.0 * (on - off) / on:.1f} % |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
