"""A fresh process each, side by side: cmm_dae against MuJoCo on IFToMM A02 (2 s).

What a user pays who starts a new Python process per run (a script, a job on a cluster):
cmm_dae imports, builds the model and runs (its compiled libraries cached by an earlier
run: the script makes one first); MuJoCo imports, compiles its MJCF (written beforehand,
closures tuned as in ``cmm-dae bench --peers``) and rolls out at h 1e-2. Whole processes
are timed, alternating, the best of ``--repeat`` each.

    python validation/fresh_process.py                  # 8 and 32 loops, 3 each
    python validation/fresh_process.py --loops 8 --repeat 5
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CMM = """
import sys
import cmm_dae as cd
from cmm_dae.description import iftomm
cd.simulate(iftomm.a02_four_bar(int(sys.argv[1])), 2.0, rtol=float(sys.argv[2]))
"""

def wall(args: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, *args], check=True, capture_output=True, timeout=600)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--loops", type=int, nargs="+", default=[8, 32])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--rtol", type=float, default=1e-5,
                    help="cmm_dae's rtol (1e-5: MuJoCo's error at h 1e-2, or better)")
    args = ap.parse_args(argv)
    from cmm_dae.studies import mujoco_a02, peers

    # MuJoCo's process runs that module by its path: it imports nothing of cmm_dae
    mj = mujoco_a02.__file__
    with tempfile.TemporaryDirectory() as tmp:
        cmm = Path(tmp) / "cmm.py"
        cmm.write_text(CMM)
        print(f"{'loops':>5}  {'MuJoCo s':>9}  {'cmm_dae s':>9}  {'ratio':>6}")
        for n in args.loops:
            xml = Path(tmp) / f"a02_{n}.xml"
            xml.write_text(peers._a02_xml(n, 1e-2))
            wall([str(cmm), str(n), str(args.rtol)])  # the libraries built and cached
            a, b = [], []
            for _ in range(args.repeat):
                a.append(wall([str(mj), str(n), str(xml), "1e-2"]))
                b.append(wall([str(cmm), str(n), str(args.rtol)]))
            print(f"{n:>5}  {min(a):9.3f}  {min(b):9.3f}  {min(b) / min(a):6.2f}")
    print("best of the fresh processes, alternating; ratio: cmm_dae's over MuJoCo's")
    return 0


if __name__ == "__main__":
    sys.exit(main())
