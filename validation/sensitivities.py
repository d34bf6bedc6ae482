"""Sensitivities of every shipped model against central finite differences, and their cost.

For each model and a set of its parameters (a mass, every stop, restitution, spring,
friction level, driver speed, gravity, a link length, a ground point's height):
d t_event / d p, and the joint positions and driving efforts on the output grid (its
times more than 20 ms from any event), against
Richardson-extrapolated central differences of runs at rtol 1e-12, from two windows
(relative steps 1e-3 and 1e-4): the smaller disagreement is reported with, in brackets, how
far the two references differ from each other (their own noise). A parameter whose event
sequence changes inside a window is reported as such, not averaged. Errors are relative to
the largest value of each quantity over the parameter's column ("abs" where that is below
1e-7: a quantity the parameter does not move). Cost: wall time of ``sensitivities`` over that of a
plain run at the same tolerance, medians of alternating runs in one process.

Writes validation/out/sensitivities/summary.md.
Run: python validation/sensitivities.py [--t-end 4] [--only points] [MODEL ...]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

import cmm_dae as cd
from cmm_dae.description.params import param_value, path_problem, with_params

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(__file__).resolve().parent / "out" / "sensitivities"
#: (a larger step budget: one perturbed run of the preloaded mechanism took 522,569 IDA
#: steps at rtol 1e-12 around 2.66 s, where its neighbours took 2,200)
TIGHT = {"rtol": 1e-12, "atol": 1e-14, "max_steps": 4_000_000}
SENS = {"rtol": 1e-10, "atol": 1e-12}
#: the runs' output step (run_dae's default), s
OUTPUT_DT = 0.01
#: relative steps of the two difference windows (each Richardson-extrapolated from h, h/2)
REL_STEPS = (1e-3, 1e-4)
#: models whose reference horizon is shorter (the Test Set's squeezer problem ends at
#: 0.03 s; the squeezer meets a dead point at 0.19 s)
T_END = {"andrews_squeezer": 0.03}
#: models whose runs fail at the tightest absolute tolerance (the squeezer's start at
#: atol 1e-13 and below)
TIGHT_FOR = {"andrews_squeezer": {"rtol": 1e-12, "atol": 1e-12, "max_steps": 4_000_000}}
#: models whose sensitivity runs need a looser absolute tolerance: the squeezer's pivot
#: heights fail on IDA's first step (3e-15 s) at atol 1e-12, the state with them at the
#: edge where its own runs fail too (atol 1e-13)
SENS_FOR = {"andrews_squeezer": {"rtol": 1e-10, "atol": 1e-11}}


def parameters(m: cd.Mechanism) -> list[str]:
    """A representative set of a model's parameters."""
    out = [f"bodies.{next(iter(m.bodies))}.mass"]
    for n, j in m.joints.items():
        if j.limits is not None:
            out += [f"joints.{n}.limits.{s}" for s in ("lower", "upper")
                    if getattr(j.limits, s) is not None]
            if j.restitution:
                out.append(f"joints.{n}.restitution")
        if j.spring is not None:
            out.append(f"joints.{n}.spring.stiffness")
        if j.friction is not None:
            out += [f"joints.{n}.friction.static", f"joints.{n}.friction.kinetic"]
    out += [f"drivers.{n}.speed" for n, d in m.drivers.items()
            if d.motion == "constant_speed"]
    if m.gravity[1]:
        out.append("gravity.y")
    # geometry: the far point of the first link joined to another link (its length) and
    # the first ground point something is attached at (a pivot's or a guide's height)
    inner = next((j for j in m.joints.values() if "ground" not in
                  (j.first.split(".")[0], j.second.split(".")[0])), None)
    if inner is not None:
        body, pt = inner.first.split(".", 1)
        out.append(f"bodies.{body}.points.{pt}.x")
    grounded = next((r for j in m.joints.values() for r in (j.first, j.second)
                     if r.startswith("ground.")), None)
    if grounded is not None:
        out.append(f"ground.points.{grounded.split('.', 1)[1]}.y")
    return [p for p in out if path_problem(m, p) is None]


def quantities(r: cd.Result, grid: np.ndarray) -> dict[str, np.ndarray]:
    return {"events": np.array([e.t for e in r.events]),
            "positions": np.concatenate([r.resample(grid, r.joint(j).position)
                                         for j in r.layout.joints]),
            "efforts": np.concatenate([r.resample(grid, r.driver(d).effort)
                                       for d in r.layout.drivers]) if r.layout.drivers
            else np.zeros(0)}


def check(path: Path, t_end: float, only: str = "",
          chosen: list[str] | None = None) -> list[str]:
    mech = cd.load(path)
    params = chosen or [p for p in parameters(mech) if only in p]
    if not params:
        return []
    sens = SENS_FOR.get(path.stem, SENS)
    try:
        s = cd.sensitivities(mech, params, t_end, **sens)
    except cd.CmmError as e:
        if len(params) > 1:  # one at a time: which of them it is, and the others compared
            return [line for p in params for line in check(path, t_end, chosen=[p])]
        return [f"| {path.stem} | `{params[0]}` | not available: "
                f"{str(e).splitlines()[-1][:140]} | | | |"]
    res = s.result
    # the output grid's own times (not the samples a crossing of a singular position adds
    # where IDA handed over, which other runs do not have), away from events
    on_grid = np.abs(res.t / OUTPUT_DT - np.round(res.t / OUTPUT_DT)) < 1e-7
    grid = np.unique(res.t[on_grid & (res.away_from_events(res.t, 0.02) if res.events
                                      else True)])
    def columns(series: list[np.ndarray]) -> np.ndarray:
        """(samples of every series stacked, parameters) on the grid."""
        if not series:
            return np.zeros((0, len(params)))
        return np.concatenate([np.stack([res.resample(grid, x[:, i])
                                         for i in range(len(params))], axis=1)
                               for x in series])

    ours = {"events": s.event_times,
            "positions": columns([s.joint(j).position for j in res.layout.joints]),
            "efforts": columns([s.driver(d).effort for d in res.layout.drivers])}
    walls_s, walls_r = [], []
    for _ in range(3):  # alternating, medians
        t0 = time.perf_counter()
        cd.sensitivities(mech, params, t_end, **sens)
        walls_s.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        cd.run_dae(mech, t_end, **sens)
        walls_r.append(time.perf_counter() - t0)
    ratio = statistics.median(walls_s) / statistics.median(walls_r)
    lines = []
    tight = TIGHT_FOR.get(path.stem, TIGHT)
    for i, p in enumerate(params):
        x = param_value(mech, p)
        windows = []  # Richardson estimates from two step sizes: their spread is the
        problem = ""  # reference's own noise
        for rel in REL_STEPS:
            h = rel * max(abs(x), 1e-2)
            try:
                varied = [(with_params(mech, {p: x + hh}), with_params(mech, {p: x - hh}))
                          for hh in (h, h / 2)]
            except cd.ModelError as e:
                problem = (f"+-{h:.2g} leaves the model invalid "
                           f"({str(e).splitlines()[-1].strip()[:90]})")
                break
            fds, seqs = [], []
            for hh, (mp, mm) in zip((h, h / 2), varied, strict=True):
                try:
                    rp = cd.run_dae(mp, t_end, **tight)
                    rm = cd.run_dae(mm, t_end, **tight)
                except cd.SolverError as e:
                    problem = (f"a difference run at +-{hh:.2g} failed "
                               f"({str(e).split(';')[0][:100]})")
                    break
                seqs += [[(e.kind, e.joint) for e in r.events] for r in (rp, rm)]
                qp, qm = quantities(rp, grid), quantities(rm, grid)
                fds.append({k: (qp[k] - qm[k]) / (2 * hh) if qp[k].shape == qm[k].shape
                            else None for k in qp})
            if problem:
                break
            if any(sq != [(e.kind, e.joint) for e in res.events] for sq in seqs):
                problem = f"event sequence changes within +-{h:.2g}"
                break
            windows.append({k: (4 * fds[1][k] - fds[0][k]) / 3 for k in fds[0]})
        if problem:
            lines.append(f"| {path.stem} | `{p}` | {problem}: not compared | | | |")
            continue
        errs = []
        for k in ("events", "positions", "efforts"):
            mine = ours[k][:, i]
            if windows[0][k].size == 0:
                errs.append("-")
                continue
            scale = max(np.max(np.abs(w[k])) for w in windows)
            err = min(np.max(np.abs(mine - w[k])) for w in windows)
            spread = np.max(np.abs(windows[0][k] - windows[1][k]))
            if scale > 1e-7:
                errs.append(f"{err / scale:.1e} ({spread / scale:.0e})")
            else:
                errs.append(f"{err:.1e} abs ({spread:.0e})")
        lines.append(f"| {path.stem} | `{p}` | {len(res.events)} events | {errs[0]} | "
                     f"{errs[1]} | {errs[2]} |")
    lines.append(f"| {path.stem} | cost | sensitivities / plain run = {ratio:.2f} "
                 f"({ratio / len(params):.2f} per parameter, {len(params)} parameters) "
                 "| | | |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="*", help="model files (default: every shipped model)")
    ap.add_argument("--t-end", type=float, default=4.0, help="simulated time, s (4)")
    ap.add_argument("--only", default="", metavar="TEXT",
                    help="only the parameters whose path contains TEXT (e.g. points); "
                         "writes summary-TEXT.md")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    paths = [Path(m) for m in args.models] or sorted((ROOT / "models").glob("*.toml"))
    lines = ["# Sensitivities against finite differences", "",
             f"{args.t_end:g} s per run; sensitivities at rtol {SENS['rtol']:g}, differences "
             f"of runs at rtol {TIGHT['rtol']:g}, Richardson-extrapolated, two windows; "
             "errors relative to the largest value of each column, in brackets the spread "
             "between the two references.", "",
             "| model | parameter | run | d t_event | positions | driving efforts |",
             "|---|---|---|---|---|---|"]
    for p in paths:
        rows = check(p, T_END.get(p.stem, args.t_end), args.only)
        print("\n".join(rows), flush=True)
        lines += rows
    name = f"summary-{args.only}.md" if args.only else "summary.md"
    (OUT / name).write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT / name}")


if __name__ == "__main__":
    main()
