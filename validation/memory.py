"""Peak memory of a long run against the size of its Result's own arrays.

Each case runs in a fresh subprocess: the baseline is the resident set after importing the
package, building the model and a 0.1-s warm-up run; the peak is the process's high-water
resident set after the long run (``VmHWM``, reset to the baseline before the run where
Linux allows; ``ru_maxrss`` elsewhere). Reported: the peak's growth over the
baseline divided by the bytes of the Result's arrays (``Result.data``)::

    python validation/memory.py                      # double-folded, 1000 s, both paths
    python validation/memory.py --t-end 200 --model models/nipper_swing.toml
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

JOB = r"""
import json, resource, sys
import cmm_dae as cd

def rss_peak():  # bytes; Linux: this process image's own high-water mark (ru_maxrss also
    try:         # carries the parent's size across fork + exec)
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

mech = cd.load(sys.argv[1])
t_end, compiled = float(sys.argv[2]), sys.argv[3] == "1"
model = cd.Model(mech)
cd.run_dae(mech, 0.1, model=model, compiled=compiled)
try:  # the high-water mark back to the current size: the peak is the run's own
    open("/proc/self/clear_refs", "w").write("5")
except OSError:
    pass
base = rss_peak()
res = cd.run_dae(mech, t_end, model=model, compiled=compiled)
peak = rss_peak()
arrays = sum(a.nbytes for a in res.data.values())
print(json.dumps({"base": base, "peak": peak, "arrays": arrays, "n": int(res.t.size)}))
"""


def measure(model: Path, t_end: float, compiled: bool) -> dict:
    out = subprocess.run([sys.executable, "-c", JOB, str(model), str(t_end),
                          "1" if compiled else "0"], capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=str(ROOT / "models" / "double_folded.toml"))
    ap.add_argument("--t-end", type=float, default=1000.0)
    a = ap.parse_args(argv)
    print(f"model {Path(a.model).name}, {a.t_end:g} s, output every 0.01 s")
    for compiled in (False, True):
        r = measure(Path(a.model), a.t_end, compiled)
        grow = r["peak"] - r["base"]
        print(f"compiled={compiled!s:<5}  samples {r['n']}  Result arrays "
              f"{r['arrays'] / 2**20:7.1f} MiB  peak growth {grow / 2**20:7.1f} MiB  "
              f"ratio {grow / r['arrays']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
