"""The double-folded mechanism with pin friction in every undriven joint
(models/double_folded_pin_friction.toml) against the frictionless one: the driving torque
and the events of both, and the energy the friction takes. Writes
docs/double_folded_pin_friction.png and prints the figures quoted in docs/paper_models.md.

    python validation/pin_friction.py
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import cmm_dae as cd  # noqa: E402

OUT = Path(__file__).resolve().parent.parent / "docs" / "double_folded_pin_friction.png"


def main() -> None:
    runs = {name: cd.run_dae(cd.load(cd.example(name)), 10.0)
            for name in ("double_folded", "double_folded_pin_friction")}
    fig, ax = plt.subplots(figsize=(8, 4))
    for (name, res), label in zip(runs.items(), ("frictionless", "pin friction (mu 0.15, r 4 mm)"),
                                  strict=True):
        ax.plot(res.t, res.driver("A").effort, label=label)
        e = res.energy()
        print(f"{name}: {len(res.events)} events, driver work {e.driver_work[-1]:.4f} J, "
              f"friction loss {e.friction_loss[-1]:.4f} J, audit residual "
              f"{np.max(np.abs(e.residual)):.1e} J, largest |torque| "
              f"{np.max(np.abs(res.driver('A').effort)):.4f} N m")
        for ev in res.events:
            print(f"  {ev.t:8.4f} s  {ev.kind:8s} {ev.joint} {ev.side}")
    for ev in runs["double_folded_pin_friction"].events:
        if ev.kind in ("limit", "release"):
            ax.axvline(ev.t, color="0.6", lw=0.8, ls="--")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("driving torque at A [N m]")
    ax.legend(loc="lower left")
    ax.set_title("double-folded mechanism: driving torque with and without pin friction")
    fig.tight_layout()
    fig.savefig(OUT, dpi=110)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
