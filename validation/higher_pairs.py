"""The shipped mechanisms with higher pairs: the cam valve train (a unilateral contact
that lifts off and lands), the slotted link (a pin that runs to the ends of its slot) and
the curved slot (the same in a bowed spline slot with friction mu |N|). Writes
docs/cam_valve_train.png, docs/slotted_link.png and docs/curved_slot.png and prints the
figures quoted in docs/higher_pairs.md.

    python validation/higher_pairs.py
"""

from __future__ import annotations

import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import cmm_dae as cd  # noqa: E402

DOCS = Path(__file__).resolve().parent.parent / "docs"


def _marks(ax, res, kinds, color="0.6", scale=1.0) -> None:
    for ev in res.events:
        if ev.kind in kinds:
            ax.axvline(ev.t * scale, color=color, lw=0.6, ls="--")


def _both(name: str, t_end: float, output_dt: float, dt: float):
    """The shipped example ``name`` run by IDA (timed) and by the fixed-step algorithm:
    (IDA's result, its wall time in s, the fixed-step result)."""
    mech = cd.load(cd.example(name))
    t0 = time.perf_counter()
    res = cd.run_dae(mech, t_end, output_dt=output_dt)
    wall = time.perf_counter() - t0
    return res, wall, cd.run_iterative(mech, t_end, dt=dt)


def valve_train() -> None:
    res, wall, it = _both("cam_valve_train", 0.05, 2e-5, 1e-5)
    kinds = [e.kind for e in res.events]
    e = res.energy()
    print(f"cam valve train, 0.05 s: {kinds.count('lift-off')} lift-offs, "
          f"{kinds.count('bounce')} bounces, {kinds.count('landing')} landings; "
          f"impact losses {e.impact_losses[-1]:.4f} J, audit residual "
          f"{np.max(np.abs(e.residual)):.1e} J; {wall:.2f} s wall")
    pairs = [(a.t, b.t) for a, b in zip(res.events, it.events, strict=False)
             if a.kind == b.kind]
    print(f"  fixed-step (dt 1e-5) events: {len(it.events)} against {len(res.events)}, "
          f"first 10 within {max(abs(a - b) for a, b in pairs[:10]):.1e} s")
    # the cam's surface under the tappet (the tip's height while touching)
    th = -np.pi / 2 + 400.0 * res.t
    e_, R = 0.004, 0.02
    surface = e_ * np.sin(th) + np.sqrt(R**2 - (e_ * np.cos(th)) ** 2)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    a1.plot(res.t * 1e3, surface * 1e3, color="saddlebrown", lw=1, label="cam surface")
    a1.plot(res.t * 1e3, res.joint("G").position * 1e3, label="tappet tip")
    a1.set_ylabel("height [mm]")
    a1.legend(loc="upper right")
    a2.plot(res.t * 1e3, np.hypot(*res.joint("K").force.T))
    a2.set_ylabel("contact force [N]")
    a2.set_xlabel("t [ms]")
    for ax in (a1, a2):
        _marks(ax, res, ("lift-off",), "tab:red", 1e3)
        _marks(ax, res, ("landing",), "tab:green", 1e3)
    a1.set_title("cam valve train at 400 rad/s: lift-off (red), bounces, landing (green)")
    fig.tight_layout()
    fig.savefig(DOCS / "cam_valve_train.png", dpi=110)
    print(f"wrote {DOCS / 'cam_valve_train.png'}")


def slotted_link(name: str = "slotted_link", title: str = "slotted link") -> None:
    res, wall, it = _both(name, 4.0, 2e-3, 1e-4)
    e = res.energy()
    gap = max(abs(a.t - b.t) for a, b in zip(res.events, it.events, strict=True))
    print(f"{title}, 4 s: {len(res.events)} events, audit residual "
          f"{np.max(np.abs(e.residual)):.1e} J; {wall:.2f} s wall; fixed-step (dt 1e-4) "
          f"events within {gap:.1e} s")
    for ev in res.events:
        cfg = res.configurations[ev.after]
        print(f"  {ev.t:9.6f} s  {ev.kind:8s} {ev.side:6s} -> {cfg.describe()}, "
              f"mobility {cfg.dof}")
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    a1.plot(res.t, res.joint("K").position, label="pin along the slot")
    for lim in res.layout.limits["K"]:
        a1.axhline(lim, color="0.2", lw=2)
    a1.set_ylabel("K [m]")
    a2.plot(res.t, np.degrees(res.joint("A").position), label="arm")
    a2.plot(res.t, np.degrees(res.joint("B").position), label="slotted link")
    a2.set_ylabel("angle [deg]")
    a2.legend(loc="upper right")
    a3.plot(res.t, np.hypot(*res.joint("K").force.T), label="slot force on the pin")
    a3.plot(res.t, np.abs(res.load("motor").value), label="|motor torque| [N m]")
    a3.set_ylabel("[N], [N m]")
    a3.set_xlabel("t [s]")
    a3.legend(loc="upper right")
    for ax in (a1, a2, a3):
        _marks(ax, res, ("limit",), "tab:red")
        _marks(ax, res, ("release",), "tab:green")
    _marks(a1, res, ("slip",), "tab:orange")
    a1.set_title(f"{title}: the pin locks at the slot's ends (red), leaves (green)"
                 + (", slips (orange)" if "slip" in [e.kind for e in res.events] else ""))
    fig.tight_layout()
    fig.savefig(DOCS / f"{name}.png", dpi=110)
    print(f"wrote {DOCS / f'{name}.png'}")


if __name__ == "__main__":
    valve_train()
    slotted_link()
    slotted_link("curved_slot", "curved slot, friction mu |N|")
