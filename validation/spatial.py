"""The spatial examples against their independent references, at rtol 1e-8, 1e-10 and
1e-12 (``tests/spatial_refs.py``: minimal-coordinate equations and closed forms, numpy and
scipy only), the planar four-bar against its spatial file, both IDA paths, and the
sensitivities through the carton fold's lock against central differences.

    python validation/spatial.py          # about 1 min
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import cmm_dae as cd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import spatial_refs  # noqa: E402 - the tests' references, found on the path just set

RTOLS = (1e-8, 1e-10, 1e-12)


def wrapped(x: np.ndarray) -> float:
    """Largest angle difference, wrapped to (-pi, pi] (rad)."""
    return float(np.max(np.abs(np.angle(np.exp(1j * x)))))


def references() -> None:
    print("reference errors (10 s; energy residual J; wall s):")
    print(f"{'example':22s} {'rtol':>6s} {'error':>10s} {'energy':>9s} {'events':>6s} "
          f"{'steps':>6s} {'wall':>6s}")
    for name in ("spherical_pendulum", "bennett_linkage", "rsur_four_bar", "carton_fold"):
        mech = cd.load(cd.example(name))
        for rtol in RTOLS:
            t0 = time.perf_counter()
            res = cd.run_dae(mech, 10.0, rtol=rtol)
            wall = time.perf_counter() - t0
            if name == "spherical_pendulum":
                bob = mech.bodies["bob"]
                ref, _ = spatial_refs.pendulum(bob.mass, bob.inertia[0], res.t)
                err = float(np.max(np.abs(res.data["q"][:, :3] - ref)))  # m
            elif name == "bennett_linkage":
                err = float(np.max(np.abs(spatial_refs.bennett(
                    res.joint("J1").position, res.joint("J2").position))))
            elif name == "rsur_four_bar":
                ph = res.joint("D").position
                err = wrapped(spatial_refs.rsur(res.joint("A").position, ph) - ph)
            else:  # in the first locked phase
                t1, t2 = res.events[0].t, res.events[1].t if len(res.events) > 1 else 10.0
                sel = (res.t > t1 + 1e-9) & (res.t < t2 - 1e-9)
                ph = res.joint("D").position[sel]
                err = wrapped(spatial_refs.carton_locked(res.joint("A").position[sel], ph)
                              - ph)
            print(f"{name:22s} {rtol:6.0e} {err:10.2e} "
                  f"{np.max(np.abs(res.energy().residual)):9.1e} {len(res.events):6d} "
                  f"{res.stats.steps:6d} {wall:6.2f}")


def planar_in_space() -> None:
    for rtol in (1e-10, 1e-12):
        a = cd.run_dae(cd.load(cd.example("four_bar")), 2.0, rtol=rtol)
        b = cd.run_dae(cd.load(cd.example("four_bar_spatial")), 2.0, rtol=rtol)
        pos = max(float(np.max(np.abs(a.data["q"][:, 3 * i:3 * i + 2]
                                      - b.data["q"][:, 12 * i:12 * i + 2]))) for i in range(3))
        eff = float(np.max(np.abs(a.driver("A").effort - b.driver("A").effort)))
        print(f"four-bar, planar file vs spatial file at rtol {rtol:.0e}: centroids "
              f"{pos:.1e} m, driver torque {eff:.1e} N m")


def paths_and_lock() -> None:
    mech = cd.load(cd.example("carton_fold"))
    py, c = (cd.run_dae(mech, 10.0, compiled=x) for x in (False, True))
    print(f"carton fold 10 s, C and Python IDA paths: q bit for bit "
          f"{np.array_equal(py.data['q'], c.data['q'])}, steps {py.stats.steps} / "
          f"{c.stats.steps}, events {len(py.events)} / {len(c.events)}")
    locks = [cd.run_dae(mech, 0.2, rtol=r).events[0].t for r in RTOLS]
    print("carton fold, E's lock instant at rtol 1e-8 / 1e-10 / 1e-12: "
          + " / ".join(f"{t:.12f}" for t in locks) + " s")
    for dt in (1e-3, 1e-4):
        it = cd.run_iterative(mech, 0.2, dt=dt)
        print(f"  fixed-step algorithm dt {dt:.0e}: lock at {it.events[0].t:.6f} s "
              f"({it.events[0].t - locks[-1]:+.1e} s)")
    params = ["joints.E.limits.lower", "bodies.L2.mass", "bodies.L3.inertia.zz"]
    sens = cd.sensitivities(mech, params, 0.3, rtol=1e-10)
    for i, path in enumerate(params):
        v0, h = sens.values[i], 1e-4 * abs(sens.values[i])
        up, down = (cd.run_dae(cd.with_params(mech, {path: v0 + s * h}), 0.3, rtol=1e-12)
                    for s in (1, -1))
        fd = (up.events[0].t - down.events[0].t) / (2 * h)
        print(f"  d t_lock / d {path}: exact {sens.event_times[0, i]:.9g}, central "
              f"difference {fd:.9g} (relative {abs(sens.event_times[0, i] / fd - 1):.1e})")


if __name__ == "__main__":
    references()
    planar_in_space()
    paths_and_lock()
