"""Results of a run: time series, configurations, events, statistics; CSV and file export.

A :class:`Result` knows nothing of the solver that made it: IDA and the paper's iterative
algorithm fill the same object, so every report, plot and check works for both.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import STATUS_MESSAGES, CmmError, Status
from ..core.records import Configuration, Event, Stats
from ..description.records import slide_base
from ..description.spatial import quaternion
from .audit import Energy, energy_audit
from .export import columns, save, to_csv, to_dataframe
from .layout import Layout


@dataclass(frozen=True)
class JointSeries:
    """Time series of one joint (``n`` samples).

    position (n,) rad or m; velocity (n,); acceleration (n,); force (n, 2) N, of the first
    body on the second, global axes; torque (n,) N m, moment of the first body on the second
    about the second body's connect point (CCW +), lock torque/force included, drivers,
    springs and dampers excluded; friction (n,) N m or N along +coordinate on the second
    body: kinetic friction while slipping, the force carried while stuck (zero for a joint
    without friction). In a spatial mechanism force and torque are (n, 3), global axes
    (a spherical or universal joint's position is 0: it has no coordinate).
    """

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    friction: np.ndarray


@dataclass(frozen=True)
class DriverSeries:
    """Effort (n,) N m or N the driver applies to the second body in the + joint direction
    at the samples; ``low`` and ``high`` (N m or N) its extremes over the whole solution
    (every IDA step and event, not only the output grid, which can miss a short peak),
    at the times ``t_low`` and ``t_high`` (s)."""

    effort: np.ndarray
    low: float = float("nan")
    high: float = float("nan")
    t_low: float = float("nan")
    t_high: float = float("nan")


@dataclass(frozen=True)
class ElementSeries:
    """A force element: ``length`` (n,) m, its ``rate`` (n,) m/s and ``tension`` (n,) N
    (positive pulls the two points together)."""

    length: np.ndarray
    rate: np.ndarray
    tension: np.ndarray


@dataclass(frozen=True)
class GearSeries:
    """A gear pair: the tooth ``force`` (n, 2) N, global axes, of the first joint's gear on
    the second's, along the line of action; its ``magnitude`` (n,) N."""

    force: np.ndarray

    @property
    def magnitude(self) -> np.ndarray:
        return np.hypot(self.force[:, 0], self.force[:, 1])


@dataclass(frozen=True)
class LoadSeries:
    """An applied load: ``value`` (n,) N or N m (zero while outside its zone) and the
    ``power`` (n,) W it puts into the mechanism."""

    value: np.ndarray
    power: np.ndarray


@dataclass(frozen=True)
class BodySeries:
    """Pose (n, 3) x m, y m, theta rad of the body frame; velocity and acceleration alike.
    In a spatial mechanism pose is (n, 7): the frame's origin (m) and unit quaternion (w, x,
    y, z); velocity and acceleration (n, 6): the origin's (m/s, m/s^2) and the angular
    ones (rad/s, rad/s^2), global axes."""

    pose: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


def _spatial_body(lay, data, i: int) -> BodySeries:
    """A spatial body's frame: pose (n, 7) origin (m) and unit quaternion (w, x, y, z);
    velocity and acceleration (n, 6): the origin's (m/s, m/s^2) and the angular ones in
    global axes (rad/s, rad/s^2; omega = sum_k e_k x e_k' / 2 over the principal axes)."""
    q, v, a = (data[k][:, 12 * i:12 * i + 12] for k in ("q", "v", "a"))
    E, Ed, Edd = (x[:, 3:].reshape(-1, 3, 3) for x in (q, v, a))  # rows: e1, e2, e3
    R = np.asarray(lay.principal[i], float).reshape(3, 3)  # rows: the principal axes
    X = R @ np.asarray(lay.centroids[i], float)  # the centroid in principal coordinates
    om = 0.5 * np.cross(E, Ed).sum(axis=1)
    al = 0.5 * np.cross(E, Edd).sum(axis=1)
    rot = E.transpose(0, 2, 1) @ R  # the body frame's axes, columns
    pose = np.column_stack([q[:, :3] - np.einsum("nkj,k->nj", E, X), quaternion(rot)])
    vel = np.column_stack([v[:, :3] - np.einsum("nkj,k->nj", Ed, X), om])
    acc = np.column_stack([a[:, :3] - np.einsum("nkj,k->nj", Edd, X), al])
    return BodySeries(pose, vel, acc)


class _Series(dict):
    """A Result's series by name; a series it does not hold is a clear error (the states
    alone, kept when post-processing ran out of memory, have no forces or joint series)."""

    def __missing__(self, key: str) -> np.ndarray:
        if "lam" not in self:
            raise CmmError(f"this Result holds the sampled states only (t, q, v: "
                           f"post-processing ran out of memory), not '{key}'; run again with "
                           "a coarser output_dt")
        raise KeyError(key)


class Result:
    """Output of :func:`cmm_dae.run_dae` or :func:`cmm_dae.run_iterative`.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Output times, s (event times are always included, twice: before and after).
    configuration : ndarray, shape (n,)
        Index into ``configurations`` at each sample.
    configurations : list[Configuration]
    events : list[Event]
    stats : Stats
    status : Status
        How the run ended: ``Status.SUCCESS`` (equal to ``"success"``) or the kind of
        failure (``"lock-up"``, ``"dead point"``, ...; :data:`cmm_dae.STATUS_MESSAGES`).
    message : str
        The run's own sentence: where and why it stopped.
    """

    def __init__(self, meta: dict[str, Any], data: dict[str, np.ndarray],
                 configurations: list[Configuration], events: list[Event], stats: Stats,
                 status: Status | str = Status.SUCCESS, message: str = "success"):
        self.meta = meta
        self._layout: Layout | None = None
        self.data = _Series(data)
        self.configurations = configurations
        self.events = events
        self.stats = stats
        self.status = Status(status)
        self.message = message

    @property
    def layout(self) -> Layout:
        """The mechanism this result belongs to, typed (:class:`Layout`): names, masses,
        geometry. ``meta`` is its stored form, with what the run added."""
        if self._layout is None:
            self._layout = Layout.of(self.meta)
        return self._layout

    # ---------------------------------------------------------------- accessors
    @property
    def t(self) -> np.ndarray:
        return self.data["t"]

    @property
    def configuration(self) -> np.ndarray:
        return self.data["config"]

    @property
    def success(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def explanation(self) -> str:
        """What :attr:`status` means in general."""
        return STATUS_MESSAGES[self.status]

    # ------------------------------------------------------------ result-level helpers
    def resample(self, t_grid: np.ndarray, y: np.ndarray) -> np.ndarray:
        """A series ``y`` of this Result linearly interpolated onto ``t_grid`` (s). At an
        event time (samples before and after it) the post-event sample holds from that
        time on, and times just before it interpolate toward the pre-event one."""
        t = self.t
        y = np.asarray(y)
        first = np.insert(t[1:] != t[:-1], 0, True)  # first sample of each time
        last = np.append(t[1:] != t[:-1], True)  # last sample of each time
        pre = first & ~last  # the pre-event sample of a repeated time
        tt = np.where(pre, np.nextafter(t, -np.inf), t)
        keep = last | pre
        return np.interp(t_grid, tt[keep], y[keep])

    def away_from_events(self, t_grid: np.ndarray, margin: float,
                         *others: Result) -> np.ndarray:
        """Mask of the grid points farther than ``margin`` (s) from every event of this
        Result and of ``others`` (series jump there)."""
        mask = np.ones(np.shape(t_grid), bool)
        for r in (self, *others):
            for e in r.events:
                mask &= np.abs(t_grid - e.t) > margin
        return mask

    def watched_joints(self) -> list[str]:
        """The joints worth watching: metamorphic joints (limits: geometric constraints),
        joints with friction and sprung joints (force constraints, like the double-folded
        mechanism's D); all joints with a coordinate when there are none of these (a
        spherical or universal joint has none)."""
        out = list(self.layout.metamorphic)
        out += [j for j in self.layout.frictional if j not in out]
        out += [j for j in self.layout.springs if j not in out]
        # a cylindrical joint's slide: the joint itself too (its angle; its reaction)
        out = [x for j in out for x in ((slide_base(j), j) if slide_base(j)
                                         in self.layout.joints else (j,))]
        out = list(dict.fromkeys(out))
        lay = self.layout
        return out or [j for j, ty in zip(lay.joints, lay.joint_types, strict=True)
                       if ty not in ("spherical", "universal")] or list(lay.joints)

    def entered_configurations(self) -> list[int]:
        """Indices of the configurations the run was actually in, in order of first entry."""
        return list(dict.fromkeys(int(c) for c in self.configuration))

    def _index(self, kind: str, name: str) -> int:
        names = list(getattr(self.layout, kind, ()))
        if name not in names:
            what = "body" if kind == "bodies" else kind[:-1]
            raise CmmError(f"no {what} named {name!r} (known: {', '.join(names)})")
        return names.index(name)

    def joint(self, name: str) -> JointSeries:
        """Time series of joint ``name``."""
        k = self._index("joints", name)
        d = self.data
        fr = d["friction"][:, self.layout.slides.get(name, k)] if "friction" in d \
            else np.zeros(self.t.size)  # (a contact's friction: its slide's)
        return JointSeries(d["c"][:, k], d["cd"][:, k], d["cdd"][:, k], d["jforce"][:, k, :],
                           d["jtorque"][:, k], fr)

    def gear(self, name: str) -> GearSeries:
        """Time series of gear pair ``name`` (its tooth force)."""
        return GearSeries(self.data["gforce"][:, self._index("gears", name), :])

    def element(self, name: str) -> ElementSeries:
        """Time series of force element ``name``."""
        k = self._index("elements", name)
        d = self.data
        return ElementSeries(d["elem_len"][:, k], d["elem_rate"][:, k], d["elem_tension"][:, k])

    def load(self, name: str) -> LoadSeries:
        """Time series of applied load ``name``."""
        k = self._index("loads", name)
        return LoadSeries(self.data["load_value"][:, k], self.data["load_power"][:, k])

    def driver(self, name: str) -> DriverSeries:
        """Time series of the driver of joint ``name``."""
        k = self._index("drivers", name)
        e, t = self.data["effort"][:, k], self.t
        if "peak_effort" in self.data:  # the states where IDA's steps found the extremes
            e, t = (np.concatenate([e, self.data["peak_effort"][:, k]]),
                    np.concatenate([t, self.data["peak_t"]]))
        if not e.size:
            return DriverSeries(self.data["effort"][:, k])
        lo, hi = int(np.argmin(e)), int(np.argmax(e))
        return DriverSeries(self.data["effort"][:, k], float(e[lo]), float(e[hi]),
                            float(t[lo]), float(t[hi]))

    def body(self, name: str) -> BodySeries:
        """Time series of body ``name`` (its frame, not its centroid)."""
        i = self._index("bodies", name)
        if self.layout.space == "spatial":
            return _spatial_body(self.layout, self.data, i)
        cx, cy = self.layout.centroids[i]
        q, v, a = (self.data[k][:, 3 * i:3 * i + 3] for k in ("q", "v", "a"))
        th, om, al = q[:, 2], v[:, 2], a[:, 2]
        c, s = np.cos(th), np.sin(th)
        dx, dy = -(c * cx - s * cy), -(s * cx + c * cy)  # frame origin minus centroid
        pose = np.column_stack([q[:, 0] + dx, q[:, 1] + dy, th])
        vel = np.column_stack([v[:, 0] - om * dy, v[:, 1] + om * dx, om])
        acc = np.column_stack([a[:, 0] - al * dy - om**2 * dx, a[:, 1] + al * dx - om**2 * dy, al])
        return BodySeries(pose, vel, acc)

    @property
    def drift(self) -> tuple[float, float]:
        """Largest constraint residual over the run: (|Phi| in m or rad, |Phi'| in m/s or rad/s)."""
        return float(np.max(self.data["drift_pos"], initial=0.0)), \
            float(np.max(self.data["drift_vel"], initial=0.0))

    def __repr__(self) -> str:
        return (f"Result({self.layout.mechanism!r}, method={self.stats.method!r}, "
                f"n={self.t.size}, t=[{self.t[0]:g}, {self.t[-1]:g}] s, "
                f"events={len(self.events)}, status={self.status!r})")

    def energy(self) -> Energy:
        """Energy audit along the run (J); see :func:`cmm_dae.results.audit.energy_audit`."""
        return energy_audit(self)

    # ------------------------------------------------------------------ tables
    def event_table(self, limit: int | None = None) -> str:
        """The event log as printable text.

        Parameters
        ----------
        limit : int, optional
            At most this many events: the first and the last half of them, with a line
            saying how many were left out (a cam run of 10 s logs thousands). All where
            None.
        """
        first, last = list(self.events), []
        if limit is not None and len(first) > limit:  # the first and the last halves
            first, last = first[:limit - limit // 2], first[len(first) - limit // 2:]
        shown = first + last
        head = (f"{'t [s]':>12}  {'kind':<8} {'joint':<8} {'side':<6} "
                f"{'configuration before -> after':<58} {'v- -> v+':>22} {'impulse':>10} "
                f"{'E lost [J]':>11}")
        lines = [head, "-" * len(head)]
        impulses = [e.impulses.get(f"lock {e.joint}", 0.0) for e in shown]
        rows = []
        for e, imp in zip(shown, impulses, strict=True):
            cb, ca = (self._config_text(i) for i in (e.before, e.after))
            rows.append(f"{e.t:12.9f}  {e.kind:<8} {e.joint:<8} {e.side:<6} "
                        f"{cb + ' -> ' + ca:<58} {e.velocity_before:>10.4g} -> "
                        f"{e.velocity_after:<9.4g} {imp:>10.4g} {e.energy_lost:>11.4g}")
        if len(shown) < len(self.events):
            rows.insert(len(first), f"... {len(self.events) - len(shown)} events more (all "
                        "of them: cmm-dae events, or Result.event_table())")
        lines += rows
        if not self.events:
            lines.append("(no events)")
        if any(impulses):
            lines.append("(impulse: the lock row's multiplier impulse, N s or N m s; the stop "
                         "gives -impulse along the joint's coordinate)")
        singular = [e for e in shown if e.kind == "singular"]
        if singular:
            lines.append("(singular: v- -> v+ are the norm of all coordinates' velocities, m/s "
                         "and rad/s together, where the crossing began and ended; they are "
                         "continuous at the instant itself)")
        lines += [f"(singular at t = {e.t:.9f} s: {e.note})" for e in singular]
        # a negative loss beyond round-off (a stick's vanishing impulse leaves ~1e-16 J)
        if any(e.energy_lost < -1e-9 for e in shown) and self.layout.drivers:
            lines.append("(E lost < 0: the driver's impulse does work at the impact, so the "
                         "mechanism can gain kinetic energy there)")
        return "\n".join(lines)

    def _config_text(self, i: int) -> str:
        return self.configurations[i].describe()

    # ------------------------------------------------------------------ export
    def columns(self) -> dict[str, np.ndarray]:
        """Every series as named columns (SI units in the names); see
        :mod:`cmm_dae.results.export`."""

        return columns(self)

    def to_csv(self, path: str | Path) -> Path:
        """Write every series to a CSV file (one row per sample, a header naming each column
        with its unit, the configuration by its description)."""

        return to_csv(self, path)

    def to_dataframe(self) -> Any:
        """Every series as a :class:`pandas.DataFrame` (needs pandas: ``pip install
        'cmm_dae[dataframe]'``), one row per sample, columns named with their units."""

        return to_dataframe(self)

    def save(self, path: str | Path) -> Path:
        """Save the whole Result (arrays, configurations, events, stats) to an ``.npz`` file."""

        return save(self, path)
