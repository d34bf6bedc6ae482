"""Targets of a design study (:func:`cmm_dae.studies.design`): an event's time or a series' value
at a time, equal to a value or bounded, measured with its gradient from one run with
sensitivities."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.errors import CmmError, ModelError, Problem
from ..description.mechanism import Mechanism
from ..sensitivity.run import Sensitivities

__all__ = ["Target", "parse_target"]


#: The kinds of events (as in the event log) a target may name.
KINDS = ("limit", "lock", "bounce", "release", "stick", "slip", "zone", "landing",
         "lift-off")
#: The series a target may name: (table, series) -> accessor names.
_SERIES = {("joint", "position"), ("joint", "velocity"), ("joint", "acceleration"),
           ("joint", "torque"), ("driver", "effort")}


@dataclass(frozen=True)
class Target:
    """A constraint of a design study.

    An event target names an event by ``event`` ("KIND JOINT", e.g. ``"limit E"`` or
    ``"release E"``) and its ``occurrence`` (1 = the first such event); a series target
    names ``series`` ("joint E position", "driver A effort") at time ``t`` (s). Either
    asks for ``value`` (equality) or bounds it by ``min`` and/or ``max`` (s for an event,
    the series' unit otherwise).
    """

    event: str | None = None
    occurrence: int = 1
    series: str | None = None
    t: float | None = None
    value: float | None = None
    min: float | None = None
    max: float | None = None

    @property
    def label(self) -> str:
        what = (f"{self.event} #{self.occurrence} time" if self.event is not None
                else f"{self.series} at t = {self.t:g} s")
        if self.value is not None:
            return f"{what} = {self.value:g}"
        parts = [f">= {self.min:g}" if self.min is not None else "",
                 f"<= {self.max:g}" if self.max is not None else ""]
        return f"{what} {' and '.join(p for p in parts if p)}"

    def measure(self, s: Sensitivities) -> tuple[float, np.ndarray]:
        """The targeted quantity and its gradient (P,) in one sensitivity run."""
        res = s.result
        if self.event is not None:
            kind, joint = self.event.split(" ", 1)
            hits = [i for i, e in enumerate(res.events) if e.kind == kind and e.joint == joint]
            if len(hits) < self.occurrence:
                seq = ", ".join(f"{e.kind} {e.joint} at {e.t:.4g} s" for e in res.events)
                raise CmmError(f"target '{self.label}': the run has {len(hits)} '{kind} "
                               f"{joint}' event(s) (events: {seq or 'none'}); a target "
                               "needs its event in every run of the study")
            i = hits[self.occurrence - 1]
            return float(res.events[i].t), s.event_times[i].copy()
        table, name, what = self.series.split(" ")
        res_series = getattr(getattr(res, table)(name), what)
        sens_series = getattr(getattr(s, table)(name), what)
        val = float(res.resample(np.array([self.t]), res_series)[0])
        grad = np.array([res.resample(np.array([self.t]), sens_series[:, k])[0]
                         for k in range(sens_series.shape[1])])
        return val, grad


def parse_target(x: Any, i: int, mech: Mechanism) -> Target:
    if isinstance(x, Target):
        t = x
    elif isinstance(x, Mapping):
        allowed = {"event", "occurrence", "series", "t", "value", "min", "max"}
        extra = set(x) - allowed
        if extra:
            raise ModelError(Problem("design", f"constraints[{i}]", "unknown key(s) "
                                     f"{', '.join(sorted(extra))}; expected "
                                     f"{', '.join(sorted(allowed))}"), mech.source)
        t = Target(**x)
    else:
        raise ModelError(Problem("design", f"constraints[{i}]", f"expected a table (dict) "
                                 f"or a Target, got {x!r}"), mech.source)
    key = f"constraints[{i}]"
    if (t.event is None) == (t.series is None):
        raise ModelError(Problem("design", key, "expected exactly one of 'event' or "
                                 "'series'"), mech.source)
    if t.event is not None:
        parts = str(t.event).split(" ")
        if len(parts) != 2 or parts[1] not in mech.joints or parts[0] not in KINDS:
            raise ModelError(Problem("design", key, f"'event' must be 'KIND JOINT' with KIND "
                                     f"one of {', '.join(KINDS)} and a joint of the "
                                     f"mechanism (e.g. 'limit E'), got {t.event!r}"),
                             mech.source)
        if not isinstance(t.occurrence, int) or t.occurrence < 1:
            raise ModelError(Problem("design", key, "'occurrence' must be an integer >= 1"),
                             mech.source)
    else:
        parts = str(t.series).split(" ")
        table = {"joint": mech.joints, "driver": mech.drivers}
        if len(parts) != 3 or (parts[0], parts[2]) not in _SERIES or \
                parts[1] not in table.get(parts[0], {}):
            raise ModelError(Problem("design", key, "'series' must be 'joint NAME "
                                     "position|velocity|acceleration|torque' or 'driver "
                                     f"NAME effort', got {t.series!r}"), mech.source)
        if not isinstance(t.t, int | float) or isinstance(t.t, bool):
            raise ModelError(Problem("design", key, "a series target needs a time 't' in s"),
                             mech.source)
    vals = [t.value, t.min, t.max]
    if all(v is None for v in vals) or (t.value is not None and
                                        (t.min is not None or t.max is not None)):
        raise ModelError(Problem("design", key, "expected 'value', or 'min' and/or 'max'"),
                         mech.source)
    for v in vals:
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float)
                              or not math.isfinite(v)):
            raise ModelError(Problem("design", key, f"expected finite numbers, got {v!r}"),
                             mech.source)
    return t
