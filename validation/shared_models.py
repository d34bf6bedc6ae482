"""Every value a model takes as an input, checked: a variant run on its structure's shared
model against the same mechanism built anew.

For each shipped model and each of its :func:`~cmm_dae.equations.values.value_paths`,
the value is changed (by 7 %, or 0.05 rad for an angle), the base run first (its model
kept), then the variant run on a variant of that model, then the same mechanism with
every kept model forgotten (built from scratch): the two runs must give the same events
(kind, joint, time within 1e-12 s), positions, velocities, joint forces and
driver efforts within 1e-12 of their scale. A value
the builder folded into a function instead of reading it from ``p`` shows as a variant
that runs with the base's number. Run::

    python validation/shared_models.py                 # every shipped model, 0.3 s runs
    python validation/shared_models.py --t-end 1 --compiled
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import cmm_dae as cd
from cmm_dae.description.params import param_value
from cmm_dae.equations.values import value_paths
from cmm_dae.simulation import cache

ROOT = Path(__file__).resolve().parents[1]


def changed(mech: cd.Mechanism, path: str) -> float:
    x = param_value(mech, path)
    return x + 0.05 if path.endswith((".angle", ".rest", ".initial", ".phase")) else 1.07 * x


def compare(a: cd.Result, b: cd.Result) -> float:
    """The largest difference of two runs (positions scaled, event times), inf where their
    events differ in kind or joint or their samples in number."""
    ka = [(e.kind, e.joint) for e in a.events]
    kb = [(e.kind, e.joint) for e in b.events]
    if ka != kb or a.data["q"].shape != b.data["q"].shape:
        return np.inf
    gaps = []
    for key in ("q", "v", "jforce", "effort"):  # the motion and post-processing's forces
        x, y = np.asarray(a.data[key]), np.asarray(b.data[key])
        scale = 1.0 + float(np.max(np.abs(y), initial=0.0))
        gaps.append(float(np.max(np.abs(x - y), initial=0.0)) / scale)
    return max(gaps + [abs(x.t - y.t) for x, y in zip(a.events, b.events, strict=True)])


def check(path_of_model: Path, t_end: float, compiled: bool | str) -> list[tuple]:
    mech = cd.load(path_of_model)
    rows = []
    for path in value_paths(mech):
        try:
            var = cd.with_params(mech, {path: changed(mech, path)})
        except cd.CmmError:  # (a principal moment beyond the other two's sum, say)
            rows.append((path, "not a mechanism", 0.0))
            continue
        cache.clear()
        kw = dict(throw=False, compiled=compiled)
        cd.run_dae(mech, t_end, **kw)
        shared, fresh = [], []
        for out in (shared, fresh):
            try:
                out.append(cd.run_dae(var, t_end, **kw))
            except cd.CmmError as e:  # (a Bennett linkage whose length changed locks)
                out.append(str(e))
            cache.clear()
        if isinstance(shared[0], str) or isinstance(fresh[0], str):
            rows.append((path, "refused", 0.0 if shared == fresh else np.inf))
        else:
            rows.append((path, shared[0].status.value, compare(shared[0], fresh[0])))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--t-end", type=float, default=0.3)
    ap.add_argument("--compiled", action="store_true", help="the C path (default: Python)")
    ap.add_argument("models", nargs="*", help="model files (default: every shipped one)")
    a = ap.parse_args(argv)
    files = [Path(m) for m in a.models] or sorted((ROOT / "models").glob("*.toml"))
    bad, n, t0 = 0, 0, time.perf_counter()
    for f in files:
        rows = check(f, a.t_end, bool(a.compiled))
        worst = max((r[2] for r in rows if isinstance(r[2], float)), default=0.0)
        skipped = sum(r[1] == "not a mechanism" for r in rows)
        print(f"{f.stem}: {len(rows)} values ({skipped} changed to no mechanism), worst "
              f"difference {worst:.1e}")
        for path, status, diff in rows:
            n += 1
            if not isinstance(diff, float) or diff > 1e-12:
                bad += 1
                print(f"    {path}: {status}, {diff}")
    print(f"{n} variants, {bad} differing from a fresh build, {time.perf_counter() - t0:.0f} s")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
