"""Where IFToMM A01's extra IDA steps come from: the same scikit-sundae IDA, the same
tolerances and output grid, on five formulations of the same pendulum.

1. the minimal residual (angle from +x, rate);
2. the same ODE with the mass's Cartesian position and velocity added as differential
   unknowns (what the error test of a centroid formulation sees, without constraints);
3. the GGL DAE of one body with its reference point at the pivot (linear constraints);
4. the GGL DAE of one body with its reference point at the mass, as cmm_dae writes it
   (centroid coordinates, nonlinear constraints), here written out by hand;
5. cmm_dae's ``run_dae`` on ``models/iftomm_a01_pendulum.toml``.

Steps are counted the same way everywhere (the root function runs once per step). The
mass's largest position error is against the exact elliptic solution.

    python validation/a01_steps.py              # 50 s at rtol 1e-11, atol 1e-13
    python validation/a01_steps.py --t-end 200 --rtol 1e-10
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import cmm_dae as cd
from cmm_dae.description import iftomm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from iftomm import _ida_on  # noqa: E402  (the validation script beside this one)

OUT = Path(__file__).resolve().parent / "out"
G = iftomm.G


def _solve(res, y0, yp0, grid, rtol, atol, algebraic=()):
    """IDA on a residual, steps counted as in ``iftomm.py``: (solution, accepted steps)."""
    sol, steps = _ida_on(res, y0, yp0, grid, rtol, atol, algebraic)
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol, steps


def _error(t: np.ndarray, xy: np.ndarray) -> float:
    return float(np.max(np.hypot(*(xy - iftomm.a01_reference(t)).T)))


def minimal(grid, rtol, atol):
    def res(t, y, yp, r):
        r[0] = yp[0] - y[1]
        r[1] = yp[1] + G * np.cos(y[0])

    sol, n = _solve(res, np.zeros(2), np.array([0.0, -G]), grid, rtol, atol)
    return n, _error(sol.t, np.column_stack([np.cos(sol.y[:, 0]), np.sin(sol.y[:, 0])]))


def cartesian_ode(grid, rtol, atol):
    def res(t, y, yp, r):
        th, w = y[0], y[1]
        a = -G * np.cos(th)
        c, s = np.cos(th), np.sin(th)
        r[0] = yp[0] - w
        r[1] = yp[1] - a
        r[2] = yp[2] + s * w
        r[3] = yp[3] - c * w
        r[4] = yp[4] + c * w * w + s * a
        r[5] = yp[5] + s * w * w - c * a

    y0 = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    sol, n = _solve(res, y0, np.array([0.0, -G, 0.0, 0.0, 0.0, -G]), grid, rtol, atol)
    return n, _error(sol.t, sol.y[:, 2:4])


# GGL unknowns: q (3), v (3), lambda (2), mu (2); the multipliers' tolerances as cmm_dae's
def _ggl_atol(atol):
    return np.concatenate([np.full(6, atol), np.full(2, 1e-2), np.full(2, 1e3)])


def ggl_pivot(grid, rtol, atol):
    """Reference point at the pivot: q = (x, y, phi), centroid at (x, y) + (cos, sin)."""
    def res(t, y, yp, r):
        x, yy, ph, vx, vy, w, l1, l2, m1, m2 = y
        c, s = np.cos(ph), np.sin(ph)
        acx = yp[3] - s * yp[5] - w * w * c  # the centroid's acceleration
        acy = yp[4] + c * yp[5] - w * w * s
        r[0] = yp[0] - vx - m1
        r[1] = yp[1] - vy - m2
        r[2] = yp[2] - w
        r[3] = acx + l1
        r[4] = acy + G + l2
        r[5] = -s * acx + c * (acy + G)  # moments about the pivot (inertia 0)
        r[6], r[7], r[8], r[9] = x, yy, vx, vy

    yp0 = np.zeros(10)
    yp0[5] = -G
    sol, n = _solve(res, np.zeros(10), yp0, grid, rtol, _ggl_atol(atol), range(6, 10))
    ph = sol.y[:, 2]
    return n, _error(sol.t, np.column_stack([np.cos(ph), np.sin(ph)]))


def ggl_centroid(grid, rtol, atol):
    """Reference point at the mass: q = (x, y, phi) of the centroid, pivot at (0, 0)."""
    def res(t, y, yp, r):
        x, yy, ph, vx, vy, w, l1, l2, m1, m2 = y
        c, s = np.cos(ph), np.sin(ph)  # Phi = (x - cos phi, y - sin phi)
        r[0] = yp[0] - vx - m1
        r[1] = yp[1] - vy - m2
        r[2] = yp[2] - w - (s * m1 - c * m2)
        r[3] = yp[3] + l1
        r[4] = yp[4] + G + l2
        r[5] = s * l1 - c * l2  # inertia 0
        r[6], r[7] = x - c, yy - s
        r[8], r[9] = vx + s * w, vy - c * w

    y0 = np.zeros(10)
    y0[0] = 1.0
    yp0 = np.zeros(10)
    yp0[4] = yp0[5] = -G
    sol, n = _solve(res, y0, yp0, grid, rtol, _ggl_atol(atol), range(6, 10))
    return n, _error(sol.t, sol.y[:, :2])


def cmm(t_end, rtol, atol):
    res = cd.run_dae(cd.load(cd.example("iftomm_a01_pendulum")), t_end, rtol=rtol, atol=atol,
                     output_dt=0.1)
    pose = res.body("bob").pose
    xy = pose[:, :2] + np.column_stack([np.cos(pose[:, 2]), np.sin(pose[:, 2])])
    return res.stats.steps, _error(res.t, xy)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--t-end", type=float, default=50.0, help="simulated time, s")
    ap.add_argument("--rtol", type=float, default=1e-11)
    ap.add_argument("--atol", type=float, default=None, help="default: 1e-2 rtol")
    args = ap.parse_args()
    atol = args.rtol * 1e-2 if args.atol is None else args.atol
    grid = np.linspace(0.0, args.t_end, int(round(args.t_end / 0.1)) + 1)
    rows = [("minimal residual (angle, rate)", *minimal(grid, args.rtol, atol)),
            ("same ODE + Cartesian position, velocity", *cartesian_ode(grid, args.rtol, atol)),
            ("GGL DAE, reference point at the pivot", *ggl_pivot(grid, args.rtol, atol)),
            ("GGL DAE, reference point at the mass", *ggl_centroid(grid, args.rtol, atol)),
            ("cmm_dae run_dae", *cmm(args.t_end, args.rtol, atol))]
    base = rows[0][1]
    lines = [f"A01 over {args.t_end:g} s, rtol {args.rtol:g}, atol {atol:g}", "",
             "| formulation | IDA steps | / minimal | max position error [m] |",
             "|---|---:|---:|---:|"]
    lines += [f"| {name} | {n} | {n / base:.2f} | {e:.2e} |" for name, n, e in rows]
    text = "\n".join(lines)
    print(text)
    OUT.mkdir(exist_ok=True)
    (OUT / "a01_steps.md").write_text(text + "\n")
    print(f"wrote {OUT / 'a01_steps.md'}")


if __name__ == "__main__":
    main()
