"""cmm_dae against MuJoCo and Exudyn on the Bennett linkage (spatial), at equal accuracy.

Prints the table of ``cmm-dae bench --peers`` for the Bennett linkage (time ratios at a
loose and a tight accuracy for each peer), then what it rests on: each code's J1 error
against the step or tolerance (MuJoCo with its closure time constant at 2 h and at 4 h),
and the reference (MuJoCo at a tiny step) against two codes that share nothing with it:
cmm_dae at rtol 1e-12 and Exudyn at h 2e-5. Exits 1 if the reference is not at least ten
times closer to both than the smallest error the table reports. About 20 s.

    python validation/peers_bennett.py              # the table at best of 5, the ladders
    python validation/peers_bennett.py --repeat 3 --quick   # the table alone
"""

from __future__ import annotations

import argparse
import sys
import time

import cmm_dae as cd
from cmm_dae.studies import peers_bennett as pb
from cmm_dae.studies.peers import RTOLS

T_END = 2.0


def _peer_error(run, h: float, reference) -> tuple[float, float]:
    """(J1 error (rad) on the peer's max(h, 0.01) grid, wall time of the run (s))."""
    t0 = time.perf_counter()
    t, q = run()
    wall = time.perf_counter() - t0
    every = int(round(max(h, pb.GRID) / h))
    return pb.error_j1(t[::every], q[::every, 0], reference), wall


def ladders(reference) -> None:
    """Each code's error against its step or tolerance."""
    print("\nMuJoCo (RK4, one connect): J1 error (rad) against h, time constant 2 h | 4 h")
    for h in (5e-2, 2e-2, 1e-2, 5e-3, 2.5e-3, 1e-3):
        errs = []
        for tc in (2.0, 4.0):
            pb.TIME_CONSTANT = tc  # read when the MJCF is written
            errs.append(_peer_error(pb.bennett_mujoco_prepared(h, T_END), h, reference)[0])
        pb.TIME_CONSTANT = 4.0
        print(f"  h {h:7.1e}  {errs[0]:9.2e} | {errs[1]:9.2e}")
    print("Exudyn (generalized-alpha, kinematic tree): J1 error (rad) against h")
    for h in (1e-2, 5e-3, 1e-3, 2e-4):
        err, wall = _peer_error(pb.bennett_exudyn_prepared(h, T_END), h, reference)
        print(f"  h {h:7.1e}  {err:9.2e}  ({wall * 1e3:.0f} ms, first run)")
    print("cmm_dae (run_dae, output every 0.01 s): J1 error (rad) against rtol")
    mech = cd.load(cd.example("bennett_linkage"))
    for rtol in RTOLS:
        res = cd.run_dae(mech, T_END, rtol=rtol)
        err = pb.error_j1(res.t, res.joint("J1").position, reference)
        print(f"  rtol {rtol:7.0e}  {err:9.2e}  {res.stats.steps:6d} steps")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5, help="warm runs, best taken (5)")
    ap.add_argument("--quick", action="store_true", help="the table alone")
    args = ap.parse_args(argv)

    out = pb.compare_bennett(t_end=T_END, repeat=args.repeat)
    print(pb.bennett_table(out))
    for r in out["rows"]:
        print(f"  {r['code']:>6} h {r['h']:7.1e}: {r[r['code'] + '_s'] * 1e3:8.2f} ms, cmm_dae "
              f"{r['cmm_dae_s'] * 1e3:8.2f} ms ({r['path']}), ratio {r['ratio']:.2f}")
    smallest = min(min(r[f"{r['code']}_error"], r["cmm_dae_error"]) for r in out["rows"])
    gaps = {"cmm_dae at rtol 1e-12": out["reference_gap"]}
    if not args.quick:
        reference = pb.bennett_reference(T_END, pb.REFERENCE_STEP)
        ladders(reference)
        if out["exudyn"]:  # the reference against the other independent code
            gaps["Exudyn at h 2e-5"] = _peer_error(
                pb.bennett_exudyn_prepared(2e-5, T_END), 2e-5, reference)[0]
    print(f"\nreference: MuJoCo at h {pb.REFERENCE_STEP:.0e}; the smallest error reported "
          f"{smallest:.2e} rad")
    bad = False
    for name, gap in gaps.items():
        ok = gap <= 0.1 * smallest
        bad |= not ok
        print(f"  from {name}: {gap:.2e} rad {'ok' if ok else 'TOO FAR'}")
    print(f"  closed-form residual of the reference: {out['reference_relation']:.2e}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
