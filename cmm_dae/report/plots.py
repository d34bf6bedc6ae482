"""Figures in the style of the paper (Figs. 16-19, 23), difference plots, event timelines,
work-precision diagrams and animations. Matplotlib with the Agg backend (no screen needed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.figures import pyplot
from ..results.result import Result

STYLE = {0: dict(color="tab:blue", lw=1.6), 1: dict(color="tab:red", lw=1.0, ls="--")}


def _label(res: Result) -> str:
    m = res.stats.method
    return {"ida": "IDA (index-2 DAE)", "iterative": "iterative algorithm"}.get(m, m or "run")


def _event_lines(ax, res: Result) -> None:
    for e in res.events:
        ax.axvline(e.t, color="0.6", lw=0.6, ls=":")


def difference(a: Result, b: Result, t: np.ndarray, ya: np.ndarray, yb: np.ndarray,
               turn: bool = False) -> np.ndarray:
    """``a``'s series ``ya`` less ``b``'s ``yb``, both resampled at the times ``t`` (s); a
    spatial hinge's angle (``turn``), measured within pi of its range's middle, unwrapped to
    resample and the difference wrapped into (-pi, pi]."""
    if turn:
        ya, yb = np.unwrap(ya), np.unwrap(yb)
    d = a.resample(t, ya) - b.resample(t, yb)
    return np.angle(np.exp(1j * d)) if turn else d


def _unit(res: Result, joint: str) -> str:
    return res.layout.coordinate_unit(joint)


def _stacked(results: list[Result], names: list[str], series, labels, height: float,
             path: Path) -> Path:
    """One panel per name, every result on it: ``series(result, name)`` against time;
    ``labels(name)`` gives (ylabel, title)."""
    r0 = results[0]
    plt = pyplot()
    fig, axes = plt.subplots(len(names), 1, figsize=(8, height * len(names)), squeeze=False)
    for ax, name in zip(axes[:, 0], names, strict=True):
        for k, r in enumerate(results):
            ax.plot(r.t, series(r, name), label=_label(r), **STYLE[k % 2])
        _event_lines(ax, r0)
        ylabel, title = labels(name)
        ax.set(xlabel="time [s]", ylabel=ylabel, title=title)
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def driving_effort(results: list[Result], path: Path) -> Path:
    """Driving torque/force vs time for each result (paper Figs. 16 and 23)."""
    r0 = results[0]

    def labels(name):
        unit = "N m" if _unit(r0, name) == "rad" else "N"
        what = "torque" if unit == "N m" else "force"
        return (f"driving {what} [{unit}]",
                f"{r0.layout.mechanism}: driving {what} at joint {name}")

    return _stacked(results, r0.layout.drivers, lambda r, n: r.driver(n).effort, labels,
                    3.2, path)


def joint_motion(results: list[Result], joints: list[str], path: Path) -> Path:
    """Relative motion of the metamorphic joints vs time (paper Fig. 17)."""
    r0 = results[0]
    return _stacked(results, joints, lambda r, n: r.joint(n).position,
                    lambda n: (f"joint {n} [{_unit(r0, n)}]",
                               f"relative motion of metamorphic joint {n}"), 2.8, path)


def joint_forces(results: list[Result], joint: str, path: Path) -> Path:
    """Constraint force components and torque of one joint vs time (paper Figs. 18-19)."""
    r0 = results[0]
    plt = pyplot()
    comps = [(f"{lab} [{unit}]", get) for lab, unit, get in r0.layout.joint_components()]
    fig, axes = plt.subplots(len(comps), 1, figsize=(8, 2.5 * len(comps)), sharex=True)
    # Components that are zero in exact arithmetic (a revolute joint's torque) are drawn as
    # zero, not as 1e-26 round-off blown up by the axis scaling.
    scale = max(float(np.max(np.abs(r.joint(joint).force), initial=0.0)) for r in results)
    for ax, (lab, get) in zip(axes, comps, strict=True):
        ys = [get(r.joint(joint)) for r in results]
        noise = all(float(np.max(np.abs(y), initial=0.0)) <= 1e-9 * max(scale, 1e-300)
                    for y in ys)
        for k, (r, y) in enumerate(zip(results, ys, strict=True)):
            ax.plot(r.t, np.zeros_like(y) if noise else y, label=_label(r), **STYLE[k % 2])
        if noise:
            ax.text(0.01, 0.9, "zero (round-off level in both runs)", transform=ax.transAxes,
                    fontsize=8)
        _event_lines(ax, r0)
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"{r0.layout.mechanism}: constraint force/torque of joint {joint}\n"
                      "(first body on the second; torque about the second body's connect "
                      "point)", fontsize=10)
    axes[0].legend()
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def differences(a: Result, b: Result, t: np.ndarray, mask: np.ndarray, path: Path) -> Path:
    """Differences a - b of the driving efforts and metamorphic-joint coordinates on the
    common grid ``t`` (s), left out where ``mask`` is False (near events)."""

    names = [("driver", n) for n in a.layout.drivers] + \
        [("joint", n) for n in a.watched_joints()]  # never empty: watched falls back to all
    plt = pyplot()
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 2.6 * max(1, len(names))),
                             squeeze=False, sharex=True)
    for ax, (kind, n) in zip(axes[:, 0], names, strict=True):
        if kind == "driver":
            ya, yb = a.driver(n).effort, b.driver(n).effort
            unit = "N m" if _unit(a, n) == "rad" else "N"
            lab = f"driver {n} effort"
        else:
            ya, yb = a.joint(n).position, b.joint(n).position
            unit, lab = _unit(a, n), f"joint {n} position"
        d = difference(a, b, t, ya, yb,
                       a.layout.space == "spatial" and unit == "rad" and kind != "driver")
        ax.plot(t, np.where(mask, d, np.nan), color="k", lw=1.0)
        _event_lines(ax, a)
        ax.set_ylabel(f"diff [{unit}]")
        ax.set_title(f"{lab}: {_label(a)} minus {_label(b)} (near events left out)")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def timeline(results: list[Result], path: Path) -> Path:
    """Configuration bands and events of each result along time."""
    labels: list[str] = []
    for r in results:  # only configurations a run was in: the legend lists nothing else
        for i in r.entered_configurations():
            c = r.configurations[i]
            txt = c.describe()
            if txt not in labels:
                labels.append(txt)
    plt = pyplot()
    colors = plt.cm.tab10(np.arange(len(labels)) % 10)
    fig, ax = plt.subplots(figsize=(9, 1.2 + 0.7 * len(results)))
    for row, r in enumerate(results):
        cfg = r.configuration
        start = 0
        for i in range(1, r.t.size + 1):
            if i == r.t.size or cfg[i] != cfg[start]:
                c = r.configurations[cfg[start]]
                txt = c.describe()
                ax.barh(row, r.t[min(i, r.t.size - 1)] - r.t[start], left=r.t[start],
                        color=colors[labels.index(txt)], height=0.6)
                start = i
        for e in r.events:
            ax.plot(e.t, row, "kv", ms=5)
    ax.set_yticks(range(len(results)), [_label(r) for r in results])
    handles = [plt.Rectangle((0, 0), 1, 1, color=colors[i]) for i in range(len(labels))]
    # below the time axis and its label, whatever the band's height (a fixed fraction of
    # the axes put it over the label on one-run timelines)
    import matplotlib.transforms
    below = matplotlib.transforms.offset_copy(ax.transAxes, fig=fig, y=-34, units="points")
    ax.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0),
              bbox_transform=below, ncol=min(3, len(labels)), fontsize=8)
    ax.set(xlabel="time [s]", title=f"{results[0].layout.mechanism}: configurations "
           "(bands) and events (triangles)")
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def comparison_figures(a: Result, b: Result, t: np.ndarray, mask: np.ndarray,
                       out: Path) -> dict[str, Path]:
    """Every figure of a comparison report of ``a`` and ``b`` (its common grid ``t`` and
    ``mask``), written into ``out``."""
    res = [a, b]
    figs = {}
    if a.layout.drivers:  # an undriven mechanism has no driving effort to draw
        figs["Driving effort (paper Figs. 16, 23)"] = driving_effort(res, out / "driving.png")

    watched = a.watched_joints()
    if watched:
        figs["Relative motion of the metamorphic joints (paper Fig. 17)"] = joint_motion(
            res, watched, out / "joints.png")
        for j in watched:
            figs[f"Constraint force/torque of joint {j} (paper Figs. 18-19)"] = joint_forces(
                res, j, out / f"forces_{j}.png")
    figs["Differences"] = differences(a, b, t, mask, out / "differences.png")
    figs["Event timeline"] = timeline(res, out / "timeline.png")
    return figs


def work_precision(rows: list, path: Path, title: str) -> Path:
    """Error vs wall time, one line per method (rows of a
    :class:`~cmm_dae.studies.WorkPrecision`; failed or exact runs are left out)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 5))
    for k, method in enumerate(dict.fromkeys(r.method for r in rows)):
        pts = [r for r in rows if r.method == method and np.isfinite(r.error) and r.error > 0]
        if not pts:
            continue
        ax.loglog([p.wall for p in pts], [p.error for p in pts], "o-",
                  label=method, color=f"C{k}")
        for p in pts:
            ax.annotate(p.setting, (p.wall, p.error), fontsize=7,
                        textcoords="offset points", xytext=(4, 4))
    import matplotlib.ticker
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set(xlabel="wall time [s]", ylabel="max driving-effort error [N m]")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
