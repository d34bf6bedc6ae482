"""The cost of parameter variants: a sweep of 8 values of a spring's stiffness, and of 8
values of a crank's length, of the double-folded mechanism against 8 warm runs of the base,
and the files each sweep adds to the compiled-library cache; this working tree and an
earlier revision side by side, each in fresh subprocesses with a cache of its own.

Each job builds the base's compiled segment first (``compiled=True``, as a machine where the
mechanism ran before has it), then times 8 warm runs of the base and the two sweeps under
the default ``compiled="auto"``: one ``run_dae`` per variant of ``with_params``, as a user's
loop or ``cmm_dae.sweep`` (one worker) does. The two versions must find the same events
(1e-9 s) in every variant. Run::

    python validation/variants.py                   # against 96af113 (before lifting)
    python validation/variants.py --before HEAD~2 --rounds 5
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from before_after import ROOT, unpack  # noqa: E402

#: The last commit before the constants of the compiled functions became their inputs.
BEFORE_LIFTING = "96af113"

JOB = r"""
import json, os, sys, time
import numpy as np
import cmm_dae as cd
mech = cd.load(sys.argv[1])
t_end = float(sys.argv[2])
cache = os.environ["CMM_DAE_CACHE"]
cd.run_dae(mech, t_end, compiled=True)
def files():
    return len(os.listdir(cache))
t0 = time.perf_counter()
for _ in range(8):
    cd.run_dae(mech, t_end)
warm = time.perf_counter() - t0
k = mech.joints["D"].spring.stiffness
out = {"warm8": warm}
for name, path, values in (
        ("stiffness", "joints.D.spring.stiffness", k * np.linspace(0.6, 1.4, 8)),
        ("crank", "bodies.crank.points.B.x", np.linspace(0.076, 0.084, 8))):
    before = files()
    t0 = time.perf_counter()
    runs = [cd.run_dae(cd.with_params(mech, {path: float(x)}), t_end) for x in values]
    out[name] = {"wall": time.perf_counter() - t0, "files": files() - before,
                 "compiled": sum(bool(r.meta["compiled"]) for r in runs),
                 "events": [[[e.kind, e.joint, e.t] for e in r.events] for r in runs]}
before = files()
t0 = time.perf_counter()
table = cd.sweep(mech, {"joints.D.spring.stiffness": list(k * np.linspace(0.5, 1.5, 8))},
                 t_end=t_end, workers=1)
out["sweep"] = {"wall": time.perf_counter() - t0, "files": files() - before,
                "ok": sum(r["status"] == "success" for r in table.rows)}
print(json.dumps(out))
"""


def job(src: Path, model: Path, t_end: float) -> dict:
    with tempfile.TemporaryDirectory(prefix="cmm_variants_") as cache:
        env = {"PYTHONPATH": str(src), "PATH": "/usr/bin:/bin", "CMM_DAE_CACHE": cache,
               "HOME": cache}
        out = subprocess.run([sys.executable, "-c", JOB, str(model), str(t_end)],
                             capture_output=True, text=True, env=env, cwd=cache)
        if out.returncode:
            raise SystemExit(f"the job failed ({src}):\n{out.stderr[-3000:]}")
        return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", default=BEFORE_LIFTING, help="git revision to compare with")
    ap.add_argument("--model", default=str(ROOT / "models" / "double_folded.toml"))
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=3, help="alternating jobs per version")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="cmm_before_") as tmp:
        old_src = unpack(a.before, Path(tmp))
        rows: dict[str, list[dict]] = {"before": [], "now": []}
        for _ in range(a.rounds):
            rows["before"].append(job(old_src, Path(a.model), a.t_end))
            rows["now"].append(job(ROOT, Path(a.model), a.t_end))
    print(f"{Path(a.model).name}, {a.t_end} s runs; medians of {a.rounds} alternating jobs "
          f"per version (before = {a.before})\n")
    print("| version | sweep | cost / 8 warm runs | cache files added | runs in C |")
    print("|---|---|---|---|---|")
    for ver, jobs in rows.items():
        for name in ("stiffness", "crank", "sweep"):
            ratio = statistics.median(j[name]["wall"] / j["warm8"] for j in jobs)
            files = max(j[name]["files"] for j in jobs)
            comp = jobs[-1][name].get("compiled", "-")
            print(f"| {ver} | {name} | {ratio:.2f}x | {files} | {comp} |")
    gap = max(abs(x[2] - y[2])
              for name in ("stiffness", "crank")
              for ea, eb in zip(rows["before"][-1][name]["events"],
                                rows["now"][-1][name]["events"], strict=True)
              for x, y in zip(ea, eb, strict=True))
    same = all([[e[:2] for e in r] for r in rows["before"][-1][n]["events"]]
               == [[e[:2] for e in r] for r in rows["now"][-1][n]["events"]]
               for n in ("stiffness", "crank"))
    print(f"\nsame event kinds in every variant: {same}; largest event-time difference "
          f"between the versions: {gap:.2e} s")


if __name__ == "__main__":
    main()
