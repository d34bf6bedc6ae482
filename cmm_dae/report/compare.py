"""Comparison of two Results (IDA vs the iterative algorithm), reports and figures.

The report knows only :class:`Result`: it never reaches back into the equations or the
solvers, so it works for any two runs of the same mechanism.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import CmmError, ModelError, Problem
from ..results.result import Result
from . import plots
from .animation import html_animation

if TYPE_CHECKING:  # pragma: no cover
    from ..studies.precision import WorkPrecision


#: Relative level below which a series counts as round-off (against the largest series of
#: its unit in the same comparison).
NOISE = 1e-9
NOISE_NOTE = (f"Relative errors are left out ('-') for series at round-off level (below "
              f"{NOISE:g} of the largest series of the same unit; moments also of the "
              "largest force times the mechanism's size): they are zero in exact "
              "arithmetic.")
ENERGY_NOTE = ("`E lost` is the kinetic energy lost at the event. It can be negative at a "
               "plastic impact under a prescribed driver: the driver's impulse does work on "
               "the mechanism at the impact, so the mechanism alone may gain energy even "
               "though the collision itself dissipates.")


@dataclass
class SeriesDiff:
    """Difference of one series between two results on the common grid."""

    name: str
    unit: str
    max_abs: float
    rms: float
    scale: float
    #: Below this scale the series is round-off (it should be zero): no relative error.
    floor: float = 0.0

    @property
    def meaningful(self) -> bool:
        """Whether the series is above round-off, so that a relative error means something."""
        return self.scale > self.floor

    @property
    def max_rel(self) -> float:
        """max |diff| / max |a|; NaN for a series at round-off level (see ``floor``)."""
        return self.max_abs / self.scale if self.meaningful else math.nan

    def rel_text(self) -> str:
        return f"{self.max_rel:.2e}" if self.meaningful else "-"


@dataclass
class EventMatch:
    """The k-th event of a (kind, joint, side) in both results."""

    kind: str
    joint: str
    side: str
    t_a: float | None
    t_b: float | None

    @property
    def dt(self) -> float | None:
        return None if self.t_a is None or self.t_b is None else self.t_b - self.t_a


@dataclass
class Comparison:
    """Result of :func:`compare`: differences on a common grid, matched events, timings.

    Points closer than two grid steps to an event of either result are left out of the
    differences (the series jump there; the event table compares the jump times).
    """

    a: Result
    b: Result
    t: np.ndarray
    mask: np.ndarray
    series: list[SeriesDiff]
    events: list[EventMatch]
    extra_figures: dict[str, Path] = field(default_factory=dict)
    work_precision: WorkPrecision | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def same_event_sequence(self) -> bool:
        return all(m.t_a is not None and m.t_b is not None for m in self.events)

    def table(self) -> str:
        """Plain-text summary."""
        la, lb = self.a.stats.method or "a", self.b.stats.method or "b"
        lines = [f"{'series':<34} {'max |diff|':>12} {'RMS diff':>12} {'max |' + la + '|':>12}"
                 f" {'rel':>9}"]
        for s in self.series:
            lines.append(f"{s.name + ' [' + s.unit + ']':<34} {s.max_abs:12.4g} {s.rms:12.4g} "
                         f"{s.scale:12.4g} {s.rel_text():>9}")
        if not all(s.meaningful for s in self.series):
            lines.append(NOISE_NOTE)
        lines.append("")
        lines.append(f"{'event':<28} {'t ' + la + ' [s]':>14} {'t ' + lb + ' [s]':>14} "
                     f"{'diff [s]':>11}")
        for m in self.events:
            ta = f"{m.t_a:14.9f}" if m.t_a is not None else f"{'-':>14}"
            tb = f"{m.t_b:14.9f}" if m.t_b is not None else f"{'-':>14}"
            d = f"{m.dt:11.3e}" if m.dt is not None else f"{'-':>11}"
            lines.append(f"{m.kind + ' ' + m.joint + ' ' + m.side:<28} {ta} {tb} {d}")
        lines.append("")
        for r, lab in ((self.a, la), (self.b, lb)):
            s = r.stats
            lines.append(f"{lab:<10} wall {s.wall_time * 1e3:9.1f} ms, {s.steps} steps, "
                         f"{s.nfev} residual / {s.njev} Jacobian evaluations, "
                         f"{len(r.events)} events, {r.t.size} samples")
        return "\n".join(lines)

    def write_report(self, out: str | Path, *, animation: bool = True,
                     frames: int = 80) -> Path:
        """Write ``report.md`` and ``report.html`` with PNG figures into ``out``.

        Parameters
        ----------
        out : str or Path
            The folder (created if needed).
        animation : bool
            Put an interactive animation of run ``a`` (guide, stops, locked joints drawn)
            into ``report.html``.
        frames : int
            Frames of that animation.

        Returns
        -------
        Path
            ``report.md``.
        """

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        figs = plots.comparison_figures(self.a, self.b, self.t, self.mask, out)
        figs.update(self.extra_figures)
        name = self.a.layout.mechanism
        la, lb = self.a.stats.method, self.b.stats.method
        md = [f"# {name}: {la} vs {lb}", "",
              f"Model: `{self.a.layout.source}`. Differences on a common grid of "
              f"{self.t.size} points ({int(self.mask.sum())} used, away from events).", "",
              "## Differences", "", "| series | max abs diff | RMS diff | max abs (a) | rel |",
              "|---|---:|---:|---:|---:|"]
        for s in self.series:
            md.append(f"| {s.name} [{s.unit}] | {s.max_abs:.4g} | {s.rms:.4g} | {s.scale:.4g} | "
                      f"{s.max_rel:.2e} |")
        md += ["", "## Events", "", f"| event | t {la} [s] | t {lb} [s] | difference [s] |",
               "|---|---:|---:|---:|"]
        for m in self.events:
            md.append(f"| {m.kind} {m.joint} ({m.side}) | "
                      f"{'-' if m.t_a is None else f'{m.t_a:.9f}'} | "
                      f"{'-' if m.t_b is None else f'{m.t_b:.9f}'} | "
                      f"{'-' if m.dt is None else f'{m.dt:.3e}'} |")
        md += ["", "## Cost", "", "| method | wall time [ms] | steps | residual evals | "
               "Jacobian evals | events |", "|---|---:|---:|---:|---:|---:|"]
        for r in (self.a, self.b):
            s = r.stats
            md.append(f"| {s.method} | {s.wall_time * 1e3:.1f} | {s.steps} | {s.nfev} | "
                      f"{s.njev} | {len(r.events)} |")
        if self.work_precision:
            md += ["", "## Work-precision", "", "| method | setting | wall time [s] | "
                   "max driving-effort error |", "|---|---|---:|---:|"]
            for row in self.work_precision.rows:
                err = f"{row.error:.3e}" if row.success else f"failed: {row.status}"
                md.append(f"| {row.method} | {row.setting} | {row.wall:.4g} | {err} |")
        if self.notes:
            md += ["", "## Notes", ""] + [f"- {n}" for n in self.notes]
        md += ["", "## Event log", "", ENERGY_NOTE, "", f"### {la}", "", "```",
               self.a.event_table(), "```", "", f"### {lb}", "", "```", self.b.event_table(),
               "```", "", "## Figures", ""]
        for title, path in figs.items():
            md += [f"### {title}", "", f"![{title}]({Path(path).name})", ""]
        (out / "report.md").write_text("\n".join(md))
        page = _markdown_to_html(md, name)
        if animation:

            player = html_animation(self.a, max_frames=frames)
            page = page.replace("\n</body>", f"\n<h2>Animation ({html.escape(la)})</h2>\n"
                                f"<p>{_caption(self.a)}</p>\n{player}</body>", 1)
        (out / "report.html").write_text(page)
        return out / "report.md"


def _caption(res: Result) -> str:
    """What the report's animation of ``res`` shows (a spatial run: a 3D view)."""
    if res.layout.space == "spatial":
        return ("A 3D view (equal scales on the three axes, gravity pointing down the "
                "screen): each body as the lines between its points, ground points as "
                "black triangles; locked metamorphic joints red, free ones green.")
    return "Locked metamorphic joints red, free ones green; the guides and stops in grey."


def compare(a: Result, b: Result, *, dt: float | None = None) -> Comparison:
    """Compare two Results of the same mechanism.

    Parameters
    ----------
    a, b : Result
        Typically ``run_dae`` (a) and ``run_iterative`` (b).
    dt : float or None
        Common grid spacing, s (default: the coarser median output spacing).

    Returns
    -------
    Comparison
    """
    for name, r in (("a", a), ("b", b)):
        if not isinstance(r, Result):
            raise TypeError(f"compare expects two cmm_dae.Result objects (run_dae, "
                            f"run_iterative or Result.load), got {type(r).__name__} for {name}")
    if a.layout.joints != b.layout.joints or a.layout.bodies != b.layout.bodies:
        raise CmmError("the two results are of different mechanisms")
    t_end = min(a.t[-1], b.t[-1])
    if dt is not None and not (isinstance(dt, int | float) and not isinstance(dt, bool)
                               and math.isfinite(dt) and dt > 0):
        raise ModelError(Problem("compare", "dt", f"expected a positive step in s or None, "
                                 f"got {dt!r}"))
    if dt is None:
        steps = [np.median(np.diff(np.unique(r.t))) for r in (a, b) if np.unique(r.t).size > 1]
        dt = max(steps) if steps else t_end
    n = int(math.floor(t_end / dt + 1e-9))
    t = dt * np.arange(n + 1)
    mask = a.away_from_events(t, 2 * dt, b)
    series: list[SeriesDiff] = []

    def add(name: str, unit: str, ya: np.ndarray, yb: np.ndarray, turn: bool = False
            ) -> None:
        d = plots.difference(a, b, t, ya, yb, turn)[mask]
        scale = float(np.max(np.abs(ya), initial=0.0))
        series.append(SeriesDiff(name, unit, float(np.max(np.abs(d), initial=0.0)),
                                 float(np.sqrt(np.mean(d**2))) if d.size else 0.0, scale))

    types = dict(zip(a.layout.joints, a.layout.joint_types, strict=True))
    spatial = a.layout.space == "spatial"
    for name in a.layout.drivers:
        unit = "N m" if a.layout.coordinate_unit(name) == "rad" else "N"
        add(f"driver {name} effort", unit, a.driver(name).effort, b.driver(name).effort)
    for name in a.watched_joints():
        rev = a.layout.coordinate_unit(name) == "rad"
        ja, jb = a.joint(name), b.joint(name)
        if types[name] not in ("spherical", "universal"):  # (no coordinate: zeros)
            add(f"joint {name} position", "rad" if rev else "m", ja.position, jb.position,
                spatial and rev)
        for lab, unit, get in a.layout.joint_components():
            add(f"joint {name} {lab}", unit, get(ja), get(jb))
    # A series whose scale is round-off against the largest series of its unit (a revolute
    # joint's torque, a force component along a frictionless guide) has no relative error.
    top: dict[str, float] = {}
    for sd in series:
        top[sd.unit] = max(top.get(sd.unit, 0.0), sd.scale)
    # Where every moment is round-off (no driver: A02's pins carry 2.7e-15 N m against
    # 18 N), the largest force times the mechanism's size is the scale moments are
    # measured against (the report showed a 150 % "error" of the pins' torques).
    if "N m" in top and "N" in top:
        top["N m"] = max(top["N m"], top["N"] * _size(a))
    for sd in series:
        sd.floor = max(NOISE * top[sd.unit], 1e-300)
    return Comparison(a, b, t, mask, series, match_events(a, b))


def _size(res: Result) -> float:
    """The mechanism's size, m: the largest distance of a body point from its body frame's
    origin or of a ground point from the origin (1 m when there is none)."""
    pts = [p for pts in res.layout.body_points.values() for p in pts.values()]
    pts += list(res.layout.ground.values())
    return max((math.hypot(*p) for p in pts), default=1.0) or 1.0


def match_events(a: Result, b: Result) -> list[EventMatch]:
    """Pair the k-th occurrence of each (kind, joint, side) in both event logs."""
    def keyed(res):
        out: dict[tuple, list[float]] = {}
        for e in res.events:
            out.setdefault((e.kind, e.joint, e.side), []).append(e.t)
        return out

    ka, kb = keyed(a), keyed(b)
    rows = []
    for key in dict.fromkeys(list(ka) + list(kb)):
        la, lb = ka.get(key, []), kb.get(key, [])
        for i in range(max(len(la), len(lb))):
            rows.append(EventMatch(*key, la[i] if i < len(la) else None,
                                   lb[i] if i < len(lb) else None))
    rows.sort(key=lambda m: m.t_a if m.t_a is not None else m.t_b)
    return rows


def _markdown_to_html(md: list[str], title: str) -> str:
    """A small, dependency-free rendering of the report's own Markdown subset."""
    body, in_code, in_table = [], False, False
    for line in md:
        if line.startswith("```"):
            body.append("</pre>" if in_code else "<pre>")
            in_code = not in_code
            continue
        if in_code:
            body.append(html.escape(line))
            continue
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if set("".join(cells)) <= set("-:"):
                continue
            if not in_table:
                body.append("<table>")
                in_table = True
                body.append("<tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in cells)
                            + "</tr>")
            else:
                body.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells)
                            + "</tr>")
            continue
        if in_table:
            body.append("</table>")
            in_table = False
        if line.startswith("!["):
            alt, src = line[2:].split("](")
            body.append(f'<img src="{html.escape(src[:-1])}" alt="{html.escape(alt)}" '
                        'style="max-width:100%">')
        elif line.startswith("### "):
            body.append(f"<h3>{html.escape(line[4:])}</h3>")
        elif line.startswith("## "):
            body.append(f"<h2>{html.escape(line[3:])}</h2>")
        elif line.startswith("# "):
            body.append(f"<h1>{html.escape(line[2:])}</h1>")
        elif line:
            body.append(f"<p>{html.escape(line).replace('`', '')}</p>")
    if in_table:
        body.append("</table>")
    css = ("body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:"
           "collapse}td,th{border:1px solid #999;padding:2px 6px;text-align:right}"
           "pre{background:#f4f4f4;padding:6px;overflow-x:auto}")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
            f"</title><style>{css}</style></head><body>\n" + "\n".join(body) + "\n</body></html>")
