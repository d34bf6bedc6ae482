"""Animations of a run: a GIF file, or an interactive HTML player for the report.

Bodies are drawn as polygons through their points, ground points as triangles, the guide
of each prismatic joint as a grey line with its stops as bars, the stops of a limited
revolute joint as dashed rays (where the second body's link lies at each limit), the curve
of each contact joint (a circle, or the stretch of a line the point runs on) and the pitch
circles of gear pairs as brown lines, and every metamorphic joint as a square, red while
locked and green while free. The artists are created once and only moved from frame to
frame. A spatial run is drawn in 3D by :class:`.animation3d.Scene3D` (the same options,
the same GIF and player).
"""

from __future__ import annotations

import base64
import io
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image  # (matplotlib's own dependency)

from ..core.errors import CmmError
from ..core.figures import pyplot
from ..description.curves import spline
from ..description.parts import Curve
from ..equations.gearing import pinion_radius, pitch_radius
from .animation3d import Scene3D, draw_bodies, frame_indices

if TYPE_CHECKING:  # pragma: no cover
    from ..results.result import Result

#: Frames drawn by default: enough for the motion to read, few enough to render quickly.
DEFAULT_FRAMES = 120


class _Scene:
    """World coordinates of everything drawn, at the frames' sample indices."""

    def __init__(self, res: Result, max_frames: int) -> None:
        self.res = res
        lay = res.layout
        self.idx = frame_indices(res, max_frames)
        poses = {b: res.body(b).pose[self.idx] for b in lay.bodies}
        self.poses = poses
        self.tracks = {b: np.stack([self.world(b, xy) for xy in pts.values()], axis=1)
                       for b, pts in lay.body_points.items()}
        self.markers: dict[str, np.ndarray] = {}
        for j in lay.metamorphic:
            body, pt = lay.connects[j][1].split(".", 1)
            self.markers[j] = self.world(body, self._local(body, pt))
        pts = [tr.reshape(-1, 2) for tr in self.tracks.values()]
        pts += [np.asarray(list(lay.ground.values()), float).reshape(-1, 2)]
        self._extent(pts)
        self.guides = [self._guide(j) for j in lay.axes]
        # (a contact's limits are the ends of its curve, drawn with it)
        self.rays = [r for j in lay.limits
                     if j not in lay.axes and j not in lay.curves
                     for r in self._rays(j)]
        self.curves = [self._curve(j) for j in lay.curves]
        self.curves += [c for g in lay.gears.values() for c in self._pitch(g)]
        self._extent(pts + [g.reshape(-1, 2) for g, _ in self.guides]
                     + [c.reshape(-1, 2) for c in self.curves])

    def _extent(self, pts: list[np.ndarray]) -> None:
        allpts = np.vstack(pts)
        allpts = allpts[np.all(np.isfinite(allpts), axis=1)]
        self.lo, self.hi = allpts.min(axis=0), allpts.max(axis=0)
        self.size = float(max(self.hi - self.lo)) or 1.0

    def _local(self, body: str, pt: str):
        lay = self.res.layout
        return pt if body == "ground" else lay.body_points[body][pt]

    def angle(self, body: str) -> np.ndarray:
        return np.zeros(self.idx.size) if body == "ground" else self.poses[body][:, 2]

    def world(self, body: str, xy) -> np.ndarray:
        """(frames, 2) world positions of a body point (``xy`` a ground point's name)."""
        if body == "ground":
            return np.broadcast_to(np.asarray(self.res.layout.ground[xy], float),
                                   (self.idx.size, 2))
        P = self.poses[body]
        c, s = np.cos(P[:, 2]), np.sin(P[:, 2])
        x, y = xy
        return np.column_stack([P[:, 0] + c * x - s * y, P[:, 1] + s * x + c * y])

    def _guide(self, j: str) -> tuple[np.ndarray, np.ndarray]:
        """Guide line (frames, 2, 2) and stop bars (frames, k, 2, 2) of a prismatic joint."""
        lay = self.res.layout
        body, pt = lay.connects[j][0].split(".", 1)
        origin = self.world(body, self._local(body, pt))
        ax = np.asarray(lay.axes[j], float)
        ax = ax / np.hypot(*ax)
        th = self.angle(body)
        c, s = np.cos(th), np.sin(th)
        u = np.column_stack([c * ax[0] - s * ax[1], s * ax[0] + c * ax[1]])
        perp = np.column_stack([-u[:, 1], u[:, 0]])
        lo, up = lay.limits.get(j, [None, None])
        coord = self.res.joint(j).position[self.idx]
        ends = [v for v in (lo, up, float(coord.min()), float(coord.max())) if v is not None]
        a, b = min(ends), max(ends)
        pad = 0.1 * (b - a) if b > a else 0.05
        line = np.stack([origin + u * (a - pad), origin + u * (b + pad)], axis=1)
        half = 0.03 * self.size
        bars = [np.stack([origin + u * v - perp * half, origin + u * v + perp * half], axis=1)
                for v in (lo, up) if v is not None]
        return line, (np.stack(bars, axis=1) if bars else np.zeros((self.idx.size, 0, 2, 2)))

    def _curve(self, j: str) -> np.ndarray:
        """A contact joint's curve (frames, n, 2): its circle, or its line over the stretch
        the point runs on (and its limits), drawn from the first body's frame."""
        lay = self.res.layout
        cv = lay.curves[j]
        b1, p1 = lay.connects[j][0].split(".", 1)
        b2, p2 = lay.connects[j][1].split(".", 1)
        o = np.asarray(self._local(b1, p1) if b1 != "ground" else lay.ground[p1], float)
        if cv["kind"] == "circle":
            ang = np.linspace(0.0, 2.0 * math.pi, 73)
            local = o + cv["radius"] * np.column_stack([np.cos(ang), np.sin(ang)])
        elif cv["kind"] == "spline":
            local = o + spline(Curve("spline", points=tuple(map(tuple, cv["points"])),
                                     closed=cv.get("closed", True))).sample()
        else:
            u = np.asarray(cv["direction"], float) / np.hypot(*cv["direction"])
            # the point's place along the line, read in the first body's frame
            P = self.world(b2, self._local(b2, p2)) - self.world(b1, self._local(b1, p1))
            th = self.angle(b1)
            s = np.cos(th) * (P @ u) + np.sin(th) * (P[:, 1] * u[0] - P[:, 0] * u[1])
            ends = [float(s.min()), float(s.max())] + [
                v for v in lay.limits.get(j, []) if v is not None]
            a, b = min(ends), max(ends)
            pad = 0.15 * (b - a) if b > a else 0.05 * self.size
            local = o + np.outer([a - pad, b + pad], u)
        if b1 == "ground":
            return np.broadcast_to(local, (self.idx.size, *local.shape))
        return np.stack([self.world(b1, xy) for xy in local], axis=1)

    def _pitch(self, gear: list) -> list[np.ndarray]:
        """A gear pair's pitch circles (frames, 73, 2) about its axles (a pinion's alone
        beside a rack)."""
        lay = self.res.layout
        first, second, ratio = gear
        types = {j: j in lay.axes for j in (first, second)}  # prismatic?

        def centre(j: str) -> np.ndarray:
            body, pt = lay.connects[j][1].split(".", 1)
            return self.world(body, self._local(body, pt))

        ang = np.linspace(0.0, 2.0 * math.pi, 73)
        ring = np.column_stack([np.cos(ang), np.sin(ang)])
        if not any(types.values()):
            a, b = centre(first), centre(second)
            dist = np.hypot(*(b - a).T)[:, None, None]
            rb = pitch_radius(dist, ratio)
            return [a[:, None, :] + abs(ratio) * rb * ring, b[:, None, :] + rb * ring]
        pinion = first if types[second] else second
        return [centre(pinion)[:, None, :] + pinion_radius(ratio, types[second]) * ring]

    def _rays(self, j: str) -> list[np.ndarray]:
        """Dashed rays (frames, 2, 2): where the second body's link lies at each limit."""
        lay = self.res.layout
        b1 = lay.connects[j][0].split(".", 1)[0]
        b2, p2 = lay.connects[j][1].split(".", 1)
        if b2 == "ground":
            return []
        pj = np.asarray(lay.body_points[b2][p2], float)
        others = [np.asarray(v, float) for k, v in lay.body_points[b2].items() if k != p2]
        if not others:
            return []
        far = max(others, key=lambda v: float(np.hypot(*(v - pj))))
        d = far - pj
        phi, length = math.atan2(d[1], d[0]), float(np.hypot(*d))
        at = self.world(b2, pj)
        out = []
        for lim in lay.limits[j]:
            if lim is None:
                continue
            ang = self.angle(b1) + lim + phi
            out.append(np.stack([at, at + length * np.column_stack([np.cos(ang),
                                                                    np.sin(ang)])], axis=1))
        return out

    def figure(self):
        """The figure, and ``update(k)`` moving every artist to frame ``k``."""
        res, lay = self.res, self.res.layout
        fig, ax = pyplot().subplots(figsize=(7.0, 5.0))
        pad = 0.1 * self.size
        ax.set_xlim(self.lo[0] - pad, self.hi[0] + pad)
        ax.set_ylim(self.lo[1] - pad, self.hi[1] + pad)
        ax.set_aspect("equal")
        ax.set(xlabel="x [m]", ylabel="y [m]")
        ax.grid(alpha=0.2)
        g = np.asarray(list(lay.ground.values()), float).reshape(-1, 2)
        ax.plot(g[:, 0], g[:, 1], "k^", ms=9, label="ground")
        guide_lines = [ax.plot([], [], "-", color="0.6", lw=6, alpha=0.5, zorder=1)[0]
                       for _ in self.guides]
        bar_lines = [[ax.plot([], [], "-", color="0.1", lw=4, zorder=2)[0]
                      for _ in range(bars.shape[1])] for _, bars in self.guides]
        ray_lines = [ax.plot([], [], "--", color="0.4", lw=1)[0] for _ in self.rays]
        curve_lines = [ax.plot([], [], "-", color="saddlebrown", lw=2, zorder=2)[0]
                       for _ in self.curves]
        body_lines = {b: ax.plot([], [], "-o", lw=3, ms=4, label=b, zorder=3)[0]
                      for b in self.tracks}
        marks = {j: ax.plot([], [], "s", ms=11, mfc="none", mew=2.5, zorder=4)[0]
                 for j in self.markers}
        title = ax.set_title("\n", fontsize=9)  # two lines: room kept by tight_layout
        if self.markers:
            ax.plot([], [], "s", mfc="none", mew=2.5, color="red", label="locked joint")
            ax.plot([], [], "s", mfc="none", mew=2.5, color="green", label="free joint")
        ax.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=7)
        fig.tight_layout()
        closed = {b: tr.shape[1] > 2 for b, tr in self.tracks.items()}

        def update(k: int):
            cfg = draw_bodies(self, res, title, body_lines, closed, k,
                              lambda line, p: line.set_data(p[:, 0], p[:, 1]))
            for line, bars_, (gl, bars) in zip(guide_lines, bar_lines, self.guides, strict=True):
                line.set_data(gl[k, :, 0], gl[k, :, 1])
                for m, bl in enumerate(bars_):
                    bl.set_data(bars[k, m, :, 0], bars[k, m, :, 1])
            for line, ray in zip(ray_lines, self.rays, strict=True):
                line.set_data(ray[k, :, 0], ray[k, :, 1])
            for line, cv in zip(curve_lines, self.curves, strict=True):
                line.set_data(cv[k, :, 0], cv[k, :, 1])
            for j, mk in marks.items():
                mk.set_data([self.markers[j][k, 0]], [self.markers[j][k, 1]])
                mk.set_color("red" if j in cfg.locked else "green")
            return [title, *body_lines.values(), *guide_lines, *ray_lines, *curve_lines,
                    *marks.values(),
                    *(b for bl in bar_lines for b in bl)]

        return fig, update


def _frames(res: Result, max_frames: int, dpi: int):
    """Frames as RGB arrays, drawn by blitting: the axes, ticks, legend and ground are
    rendered once, and each frame only redraws the moving artists over that background
    (a spatial run's in 3D, a planar run's in its plane)."""
    scene = (Scene3D if res.layout.space == "spatial" else _Scene)(res, max_frames)
    fig, update = scene.figure()
    fig.set_dpi(dpi)
    try:
        moving = update(0)
        for art in moving:
            art.set_animated(True)
        fig.canvas.draw()
        background = fig.canvas.copy_from_bbox(fig.bbox)
        for k in range(scene.idx.size):
            fig.canvas.restore_region(background)
            for art in update(k):
                fig.draw_artist(art)
            yield np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    finally:
        pyplot().close(fig)


def gif_path(path: str | Path, key: str = "path") -> Path:
    """``path`` as a Path if it names a GIF file (the only format written), else a
    CmmError naming ``key``."""
    path = Path(path)
    if path.suffix.lower() != ".gif":
        raise CmmError(f"{key} {str(path)!r}: the animation is written as a GIF; give a file "
                       "name ending in .gif")
    return path


def animate(res: Result, path: str | Path, *, fps: int = 20,
            max_frames: int = DEFAULT_FRAMES, dpi: int = 80) -> Path:
    """Write a GIF of the mechanism moving (a spatial mechanism in a 3D view).

    Parameters
    ----------
    res : Result
        A run (IDA or iterative, complete or partial; planar or spatial).
    path : str or Path
        The ``.gif`` file to write.
    fps : int
        Frames per second of the GIF.
    max_frames : int
        Most frames, spread evenly over the run's samples.
    dpi : int
        Resolution (the figure is 7 x 5 in: 560 x 400 pixels at 80 dpi).

    Returns
    -------
    Path
    """
    if not (isinstance(fps, int) and fps >= 1):
        raise CmmError(f"fps: expected a whole number >= 1 of frames per second, got {fps!r}")
    path = gif_path(path)
    images = [Image.fromarray(f).convert("P", palette=Image.Palette.ADAPTIVE, colors=64)
              for f in _frames(res, max_frames, dpi)]
    images[0].save(path, save_all=True, append_images=images[1:], loop=0,
                   duration=round(1000 / fps), optimize=False)
    return path


def html_animation(res: Result, *, fps: int = 20, max_frames: int = DEFAULT_FRAMES,
                   dpi: int = 80) -> str:
    """An interactive player (play/pause, step, a time slider) as a self-contained HTML
    fragment, the frames embedded as PNG images; no network access needed to view it.
    A spatial run's frames are the 3D view of :func:`animate` (mplot3d), rendered alike."""
    urls = []
    for f in _frames(res, max_frames, dpi):
        buf = io.BytesIO()
        Image.fromarray(f).convert("P", palette=Image.Palette.ADAPTIVE, colors=64).save(
            buf, format="PNG", optimize=False)
        urls.append("data:image/png;base64," + base64.b64encode(buf.getvalue()).decode())
    uid = f"cmm{abs(hash((res.layout.mechanism, res.t.size))) % 10**8}"
    return _PLAYER.replace("UID", uid).replace("FRAMES", json.dumps(urls)).replace(
        "DELAY", str(round(1000 / max(fps, 1))))


_PLAYER = """<div id="UID" class="cmm-player">
<img id="UID-img" alt="animation of the mechanism" style="max-width:100%">
<div><button id="UID-play">play</button> <button id="UID-back">&#9664;</button>
<button id="UID-next">&#9654;</button>
<input id="UID-slider" type="range" min="0" value="0" style="width:60%"></div>
<script>
(function () {
  var frames = FRAMES, k = 0, timer = null;
  var img = document.getElementById("UID-img"), s = document.getElementById("UID-slider");
  var play = document.getElementById("UID-play");
  s.max = frames.length - 1;
  function show(i) { k = (i + frames.length) % frames.length; img.src = frames[k]; s.value = k; }
  function stop() { clearInterval(timer); timer = null; play.textContent = "play"; }
  play.onclick = function () {
    if (timer) { stop(); return; }
    play.textContent = "pause";
    timer = setInterval(function () { show(k + 1); }, DELAY);
  };
  document.getElementById("UID-back").onclick = function () { stop(); show(k - 1); };
  document.getElementById("UID-next").onclick = function () { stop(); show(k + 1); };
  s.oninput = function () { stop(); show(parseInt(s.value, 10)); };
  show(0);
})();
</script></div>
"""
