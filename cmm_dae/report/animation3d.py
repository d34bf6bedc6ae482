"""Animations of a spatial run in 3D (matplotlib's mplot3d), for :mod:`.animation`.

Each body is drawn as the lines between its points in its frame (a closed polygon through
three or more, in the model's order; a body with a single point is drawn from it to its
centroid, so that a pendulum's bob shows its swing and not a still dot); the joints' points
are among these points. Ground points are black triangles and every metamorphic joint is a
square, red while locked and green while free, as in the planar drawing. The axes are
scaled equally (a cube around everything drawn), seen obliquely from a fixed camera; the
ground axis nearest to gravity is drawn vertical, so that gravity pulls down the screen
(where it points along +axis, that axis and the one across the screen are drawn reversed:
a half turn of the view, never a mirror image).

:class:`Scene3D` has the planar scene's interface (``idx``, ``figure()`` giving the figure
and ``update(k)``), so the GIF and the HTML player of :mod:`.animation` draw it alike: the
HTML report's player shows the same mplot3d frames, rendered as PNG images.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import CmmError
from ..core.figures import pyplot

if TYPE_CHECKING:  # pragma: no cover
    from ..results.result import Result

#: Camera elevation, deg, and azimuth, deg, by the axis drawn vertical: an oblique view
#: of all three axes in which the right-handed frame's next axis (``ACROSS``) runs mostly
#: left to right and the third comes toward the viewer.
ELEVATION = 22.0
AZIMUTH = {"x": -60.0, "y": 30.0, "z": -60.0}
ACROSS = {"x": "y", "y": "x", "z": "x"}


def frame_indices(res: Result, max_frames: int) -> np.ndarray:
    """Sample indices of the frames: at most ``max_frames``, spread evenly over the run.

    Parameters
    ----------
    res : Result
        The run.
    max_frames : int
        Most frames (a whole number >= 1, else a CmmError).

    Returns
    -------
    ndarray of int
        Increasing indices into ``res.t``.
    """
    if not (isinstance(max_frames, int) and max_frames >= 1):
        raise CmmError(f"frames: expected a whole number >= 1, got {max_frames!r}")
    n = res.t.size
    return np.unique(np.linspace(0, n - 1, min(max_frames, n)).round().astype(int))


def rotations(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions ``quat`` (..., 4) as (w, x, y, z):
    a body point ``p`` (its frame, m) is at ``origin + R @ p`` in the ground's frame."""
    q = np.asarray(quat, float)
    # (renormalised: a stored quaternion rounded to a few digits still rotates rigidly)
    w, x, y, z = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def draw_bodies(scene, res, title, body_lines: dict, closed: dict, k: int, put):
    """Frame ``k`` of an animation (either space): the title (mechanism, time,
    configuration) and each body's outline through its points, closed where it has three
    or more, drawn by ``put(line, points)``; returns the frame's configuration."""
    i = scene.idx[k]
    cfg = res.configurations[res.configuration[i]]
    title.set_text(f"{res.layout.mechanism}   t = {res.t[i]:.3f} s\n{cfg.describe()}")
    for b, line in body_lines.items():
        pts = scene.tracks[b][k]
        put(line, np.vstack([pts, pts[:1]]) if closed[b] else pts)
    return cfg


class Scene3D:
    """World coordinates (m) of everything drawn of a spatial run, at the frames' samples.

    Parameters
    ----------
    res : Result
        A spatial run (``res.layout.space == "spatial"``).
    max_frames : int
        Most frames, spread evenly over the run's samples.

    Attributes
    ----------
    idx : ndarray of int
        The frames' sample indices.
    tracks : dict
        Body -> (frames, k, 3) world positions of the points it is drawn through, m.
    markers : dict
        Metamorphic joint -> (frames, 3) world position of its second point, m.
    lo, hi : ndarray, shape (3,)
        The corners of the cube shown, m (equal sides).
    """

    def __init__(self, res: Result, max_frames: int) -> None:
        self.res = res
        lay = res.layout
        if lay.space != "spatial":
            raise CmmError(f"the 3D animation draws spatial runs; {lay.mechanism!r} is "
                           f"{lay.space}")
        self.idx = frame_indices(res, max_frames)
        self.origins, self.rot = {}, {}
        for b in lay.bodies:
            pose = res.body(b).pose[self.idx]
            self.origins[b], self.rot[b] = pose[:, :3], rotations(pose[:, 3:7])
        self.tracks = {b: np.stack([self.world(b, p) for p in self.outline(b)], axis=1)
                       for b in lay.bodies}
        self.markers = {}
        for j in lay.metamorphic:
            body, pt = lay.connects[j][1].split(".", 1)
            self.markers[j] = self.world(body, pt if body == "ground"
                                         else lay.body_points[body][pt])
        pts = [tr.reshape(-1, 3) for tr in self.tracks.values()]
        pts += [np.asarray(list(lay.ground.values()), float).reshape(-1, 3)]
        allpts = np.vstack(pts)
        allpts = allpts[np.all(np.isfinite(allpts), axis=1)]  # (a failed run's NaN tail)
        if not allpts.size:
            allpts = np.zeros((1, 3))
        lo, hi = allpts.min(axis=0), allpts.max(axis=0)
        # one half-side for all three axes (with a margin): equal scaling, and a flat
        # mechanism (the four-bar in its plane) still gets a cube, not a sliver
        half = 0.55 * (float(max(hi - lo)) or 1.0)
        centre = 0.5 * (lo + hi)
        self.lo, self.hi = centre - half, centre + half

    def outline(self, body: str) -> list[np.ndarray]:
        """The points (body frame, m) a body is drawn through: its points in the model's
        order, and its centroid after a single point."""
        lay = self.res.layout
        pts = [np.asarray(p, float) for p in lay.body_points[body].values()]
        if len(pts) < 2:
            pts.append(np.asarray(lay.centroids[lay.bodies.index(body)], float))
        return pts

    def world(self, body: str, p) -> np.ndarray:
        """(frames, 3) world positions, m, of the point ``p`` of ``body`` (its frame, m;
        for the ground, a ground point's name)."""
        if body == "ground":
            return np.broadcast_to(np.asarray(self.res.layout.ground[p], float),
                                   (self.idx.size, 3))
        return self.origins[body] + self.rot[body] @ np.asarray(p, float)

    def _vertical(self) -> tuple[str, bool]:
        """The ground axis drawn vertical (the one nearest to gravity; z without gravity)
        and whether it is drawn upside down (gravity along +axis)."""
        g = np.asarray(self.res.layout.gravity, float)
        if g.size != 3 or not np.any(g):
            return "z", False
        k = int(np.argmax(np.abs(g)))
        return "xyz"[k], bool(g[k] > 0)

    def figure(self):
        """The figure, and ``update(k)`` moving every artist to frame ``k`` (returning the
        artists it moved, for blitting)."""
        res, lay = self.res, self.res.layout
        plt = pyplot()
        fig = plt.figure(figsize=(7.0, 5.0))
        # white panes and faint grid lines: the GIF's 64 colours are left to the bodies
        # (grey panes took most of the palette and turned tab:blue grey); a 3D axes reads
        # its grid's style from rcParams when it is made
        with plt.rc_context({"grid.color": "0.88", "grid.linewidth": 0.6}):
            ax = fig.add_subplot(projection="3d")
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_pane_color((1.0, 1.0, 1.0, 0.0))
        vertical, flip = self._vertical()
        ax.view_init(elev=ELEVATION, azim=AZIMUTH[vertical], vertical_axis=vertical)
        # gravity along +axis: that axis and the one across the screen are drawn reversed,
        # a half turn of the view about the line of sight (reversing the vertical one
        # alone would show the mechanism's mirror image)
        turned = {vertical, ACROSS[vertical]} if flip else set()
        for k, axis in enumerate("xyz"):
            lim = (self.hi[k], self.lo[k]) if axis in turned else (self.lo[k], self.hi[k])
            getattr(ax, f"set_{axis}lim")(*lim)
        ax.set_box_aspect((1.0, 1.0, 1.0))  # equal ranges: equal scaling
        ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]")
        ax.tick_params(labelsize=7)
        g = np.asarray(list(lay.ground.values()), float).reshape(-1, 3)
        ax.plot(g[:, 0], g[:, 1], g[:, 2], "k^", ms=9, label="ground")
        body_lines = {b: ax.plot([], [], [], "-o", lw=3, ms=4, label=b)[0]
                      for b in self.tracks}
        marks = {j: ax.plot([], [], [], "s", ms=11, mfc="none", mew=2.5)[0]
                 for j in self.markers}
        title = ax.set_title("\n", fontsize=9)  # two lines, as the planar title
        if self.markers:
            ax.plot([], [], [], "s", mfc="none", mew=2.5, color="red", label="locked joint")
            ax.plot([], [], [], "s", mfc="none", mew=2.5, color="green", label="free joint")
        ax.legend(loc="center left", bbox_to_anchor=(1.05, 0.5), fontsize=7)
        # (tight_layout does not know a 3D axes' extent: the margins are set by hand)
        fig.subplots_adjust(left=0.0, right=0.8, bottom=0.02, top=0.9)
        closed = {b: tr.shape[1] > 2 for b, tr in self.tracks.items()}

        def update(k: int):
            cfg = draw_bodies(self, res, title, body_lines, closed, k,
                              lambda line, p: line.set_data_3d(p[:, 0], p[:, 1], p[:, 2]))
            for j, mk in marks.items():
                p = self.markers[j][k]
                mk.set_data_3d([p[0]], [p[1]], [p[2]])
                mk.set_color("red" if j in cfg.locked else "green")
            return [title, *body_lines.values(), *marks.values()]

        return fig, update
