"""Time this working tree against an earlier revision, side by side in one run.

The earlier revision is unpacked from git (``git archive``) into a temporary directory and
both versions run the same job in alternating fresh subprocesses (so neither warms the
other's caches and a busy machine slows both alike); each subprocess takes the best of
``--repeat`` warm runs. The script also checks that both give the same events (1e-9 s) and
the same driving effort (1e-9 N m) and prints the ratio of the medians::

    python validation/before_after.py                       # against version 1 (1d28c89)
    python validation/before_after.py --before HEAD~3 --model models/nipper_swing.toml
    python validation/before_after.py --before 695645f --compiled   # the speed work
    python validation/before_after.py --before 8e35cf9 --model a02:10 --t-end 2

With ``--compiled`` the working tree is also timed with ``compiled=True`` (the C segment,
built once into a temporary cache before the timed runs), as a third column; its default
runs (``compiled="auto"`` from 0.3 on) then find that build and run in C too, as they do on
a machine where the mechanism has run before. Without it the cache stays empty and the
default runs take the Python path, as on a machine without a C compiler (the jobs run
with ``CMM_DAE_AUTO_BUILD=0``: "auto" builds nothing). ``--floor``
(with ``--compiled``) adds the floor of any path through scikit-sundae's Python callbacks
that takes the same steps: the compiled time plus, per callback the default path makes
(residual, Jacobian and root-function calls, counted), scikit-sundae's own cost of calling
a Python function whose body does nothing (measured on a linear test DAE with and without
such a root function). It is a lower bound: the residual's and the Jacobian's wrappers
convert more arrays than the root function's.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: The last commit of version 1: before the run driver and event policy were rebuilt.
VERSION_1 = "1d28c89"
#: The last commit before the speed work (lean events, Schur post-processing, C segment).
BEFORE_SPEED = "695645f"

JOB = r"""
import json, sys, time, gc
import numpy as np
import cmm_dae as cd
if sys.argv[1].startswith("a02:"):  # IFToMM A02 with N loops, from the builder
    import importlib, pathlib  # the layer folders (0.3 on), else the flat module
    layers = (pathlib.Path(cd.__file__).parent / "description").is_dir()
    iftomm = importlib.import_module("cmm_dae.description.iftomm" if layers
                                     else "cmm_dae.iftomm")
    mech = iftomm.a02_four_bar(int(sys.argv[1][4:]))
else:
    mech = cd.load(sys.argv[1])
t_end, rtol, repeat = float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
kw = {"compiled": True} if sys.argv[5] == "1" else {}
method = sys.argv[6] if len(sys.argv) > 6 else "ida"
model = cd.Model(mech)
if method == "ida":
    run = lambda: cd.run_dae(mech, t_end, rtol=rtol, atol=rtol * 1e-2, model=model, **kw)
else:  # the iterative algorithm at dt = rtol (pass --rtol 1e-3 for dt 1e-3)
    run = lambda: cd.run_iterative(mech, t_end, dt=rtol, model=model)
res = run()
best = float("inf")
for _ in range(repeat):
    gc.collect()
    t0 = time.perf_counter()
    res = run()
    best = min(best, time.perf_counter() - t0)
drv = res.meta["drivers"][0] if res.meta["drivers"] else None
print(json.dumps({"wall": best, "events": [[e.kind, e.joint, e.t] for e in res.events],
                  "t": res.t.tolist(),
                  "effort": res.driver(drv).effort.tolist() if drv else [],
                  "steps": res.stats.steps}))
"""


FLOOR_JOB = r"""
import json, sys, time
import numpy as np
import sksundae as sun
import cmm_dae as cd
from cmm_dae.integrators import ida
mech = cd.load(sys.argv[1])
t_end, rtol, repeat = float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
counts = {"residual": 0, "jacobian": 0, "events": 0}
res0, jac0, ev0 = (ida.IdaIntegrator._residual, ida.IdaIntegrator._jacobian,
                   ida.IdaIntegrator._events)
def residual(self, t, y, yp, res):  # scikit-sundae reads the signatures: no *args
    counts["residual"] += 1
    return res0(self, t, y, yp, res)
def jacobian(self, t, y, yp, res, cj, JJ):
    counts["jacobian"] += 1
    return jac0(self, t, y, yp, res, cj, JJ)
def events(self, t, y, yp, out):
    counts["events"] += 1
    return ev0(self, t, y, yp, out)
ida.IdaIntegrator._residual, ida.IdaIntegrator._jacobian = residual, jacobian
ida.IdaIntegrator._events = events
cd.run_dae(mech, t_end, rtol=rtol, atol=rtol * 1e-2)
N = 40
lam = np.linspace(0.5, 2.0, N)
def res(t, y, yp, r):
    np.multiply(lam, y, out=r)
    r += yp
def jac(t, y, yp, r, cj, JJ):
    JJ[:] = np.diag(lam + cj)
def empty(t, y, yp, out):
    pass
calls = [0]
def counting(t, y, yp, out):
    calls[0] += 1
tspan = np.linspace(0.0, 40.0, 1001)
def solve(fn):
    kw = {"eventsfn": fn, "num_events": 1} if fn else {}
    s = sun.ida.IDA(res, jacfn=jac, rtol=1e-10, atol=1e-12, **kw)
    t0 = time.perf_counter()
    s.solve(tspan, np.ones(N), -lam)
    return time.perf_counter() - t0
solve(counting)
none = with_fn = float("inf")
for _ in range(max(repeat, 5)):
    none, with_fn = min(none, solve(None)), min(with_fn, solve(empty))
print(json.dumps({"counts": counts, "per_call": (with_fn - none) / calls[0]}))
"""


def floor_job(model: Path | str, t_end: float, rtol: float, repeat: int) -> dict:
    """Callback counts of the working tree's default path and scikit-sundae's cost per
    Python callback (s), in a fresh subprocess."""
    out = subprocess.run([sys.executable, "-c", FLOOR_JOB, str(model), str(t_end), str(rtol),
                          str(repeat)], capture_output=True, text=True, check=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}, cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def unpack(rev: str, where: Path) -> Path:
    """The package of revision ``rev`` as files under ``where``."""
    tar = where / "rev.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", "-o", str(tar), rev,
                    "cmm_dae"], check=True)
    with tarfile.open(tar) as tf:
        tf.extractall(where, filter="data")
    return where


def job(pythonpath: Path, model: Path | str, t_end: float, rtol: float, repeat: int,
        compiled: bool = False, cache: str = "", method: str = "ida") -> dict:
    """One subprocess timing ``repeat`` warm runs of the package at ``pythonpath``
    (``method="iterative"`` runs the iterative algorithm with dt = ``rtol``)."""
    # (no build of "auto" before a first run or after long ones: the cache holds only
    # what --compiled built)
    env = {"PYTHONPATH": str(pythonpath), "PATH": "/usr/bin:/bin", "CMM_DAE_CACHE": cache,
           "CMM_DAE_AUTO_BUILD": "0"}
    out = subprocess.run([sys.executable, "-c", JOB, str(model), str(t_end), str(rtol),
                          str(repeat), "1" if compiled else "0", method],
                         capture_output=True, text=True, env=env, check=True, cwd=pythonpath)
    return json.loads(out.stdout.strip().splitlines()[-1])


def differences(b: dict, n: dict) -> tuple[bool, float, float]:
    """Same event sequence?, largest event-time and driving-effort differences."""
    import numpy as np

    same_kinds = [e[:2] for e in b["events"]] == [e[:2] for e in n["events"]]
    dt_ev = max((abs(x[2] - y[2]) for x, y in zip(b["events"], n["events"], strict=False)),
                default=0.0)
    tb, tn = np.array(b["t"]), np.array(n["t"])
    if tb.shape == tn.shape and np.max(np.abs(tb - tn), initial=0.0) <= 1e-9:
        # the same samples (an event's sample may move with its event time by round-off)
        d_eff = float(np.max(np.abs(np.array(b["effort"]) - np.array(n["effort"])),
                             initial=0.0))
    else:
        print(f"the sample times differ ({len(b['t'])} and {len(n['t'])} samples)")
        d_eff = float("inf")
    return same_kinds, dt_ev, d_eff


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", default=VERSION_1, help=f"git revision (default {VERSION_1})")
    ap.add_argument("--model", default=str(ROOT / "models" / "double_folded.toml"),
                    help="a model file, or a02:N for IFToMM A02 with N loops (the builder)")
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--rtol", type=float, default=1e-8)
    ap.add_argument("--rounds", type=int, default=5, help="alternating subprocess pairs")
    ap.add_argument("--repeat", type=int, default=5, help="warm runs per subprocess")
    ap.add_argument("--compiled", action="store_true",
                    help="also time the working tree with compiled=True")
    ap.add_argument("--floor", action="store_true",
                    help="with --compiled: the floor of a path through scikit-sundae's "
                    "Python callbacks (compiled time + callbacks x their own cost)")
    a = ap.parse_args(argv)
    if a.floor and not a.compiled:
        ap.error("--floor needs --compiled (the floor is built on the compiled time)")
    model = a.model if a.model.startswith("a02:") else Path(a.model).resolve()
    names = ["before", "after"] + (["compiled"] if a.compiled else [])
    with tempfile.TemporaryDirectory() as tmp:
        old = unpack(a.before, Path(tmp))
        cache = str(Path(tmp) / "cache")
        if a.compiled:  # build the C segment before any timed round
            job(ROOT, model, 0.1, a.rtol, 0, True, cache)
        walls: dict[str, list[float]] = {name: [] for name in names}
        last: dict[str, dict] = {}
        floors: list[dict] = []
        for _ in range(a.rounds):
            for name in names:
                path = old if name == "before" else ROOT
                r = job(path, model, a.t_end, a.rtol, a.repeat, name == "compiled", cache)
                walls[name].append(r["wall"])
                last[name] = r
            if a.floor:
                floors.append(floor_job(model, a.t_end, a.rtol, a.repeat))
    med = {name: statistics.median(w) for name, w in walls.items()}
    print(f"model {getattr(model, 'name', model)}, t_end {a.t_end} s, rtol {a.rtol:g}; "
          f"{a.rounds} alternating rounds, best of {a.repeat} warm runs each")
    label = {"before": f"before ({a.before})", "after": "after (working tree)",
             "compiled": "after, compiled=True"}
    ok = True
    for name in names:
        print(f"{label[name]:<24} median {med[name] * 1e3:8.2f} ms  "
              f"[{', '.join(f'{w * 1e3:.1f}' for w in walls[name])}]  "
              f"steps {last[name]['steps']}")
    for name in names[1:]:
        same, dt_ev, d_eff = differences(last["before"], last[name])
        print(f"ratio before / {name}: {med['before'] / med[name]:.3f}; same event sequence: "
              f"{same}; largest event-time difference {dt_ev:.2e} s; largest "
              f"driving-effort difference {d_eff:.2e}")
        ok = ok and same and dt_ev <= 1e-9 and d_eff <= 1e-9
    if floors:
        counts = floors[-1]["counts"]
        # the smallest measured cost: noise only adds to it, and a floor is a lower bound
        per = min(f["per_call"] for f in floors)
        n = sum(counts.values())
        floor = med["compiled"] + n * per
        each = ", ".join(f"{f['per_call'] * 1e6:.2f}" for f in floors)
        print(f"scikit-sundae's own cost per Python callback (empty body, least of "
              f"{len(floors)}): {per * 1e6:.2f} us "
              f"[{each}]; the default path "
              f"makes {n} callbacks ({', '.join(f'{k} {v}' for k, v in counts.items())})")
        print(f"floor through Python callbacks (compiled + callbacks x that cost): "
              f"{floor * 1e3:.2f} ms; ratio before / floor: {med['before'] / floor:.3f}; "
              f"after / floor: {med['after'] / floor:.3f}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
