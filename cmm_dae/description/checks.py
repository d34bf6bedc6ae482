"""Semantic checks of a mechanism description: every problem found, each with its table
and key (``validate``), and the names the description may use. Works on any object shaped
like :class:`cmm_dae.Mechanism` (it is called while one is built)."""

from __future__ import annotations

import dataclasses
import inspect
import math
from collections.abc import Mapping
from typing import Any

from ..core.errors import Problem
from .joint_checks import (  # noqa: F401 (the names the description may use)
    CURVES,
    GROUND,
    JOINT_TYPES,
    SIDES,
    _check_ref,
    _finite,
    gear_problems,
    joint_problems,
)
from .parts import STOP_TOL
from .spatial import SPACES
from .spatial import problems as spatial_problems

MOTIONS = ("constant_speed", "polynomial", "harmonic", "table")


LAWS = ("constant", "polynomial", "harmonic", "table", "motor")


FRAMES = ("global", "body")


def _numbers(x: Any, key: str):
    """(dotted key, value) of every number inside a description record: dataclass
    fields, mappings, sequences (``[i]``); callables and strings are not numbers."""
    if isinstance(x, bool) or x is None or isinstance(x, str) or callable(x):
        return
    if isinstance(x, int | float):
        yield key, x
    elif dataclasses.is_dataclass(x):
        for f in dataclasses.fields(x):
            yield from _numbers(getattr(x, f.name), f"{key}.{f.name}" if key else f.name)
    elif isinstance(x, Mapping):
        for k, v in x.items():
            yield from _numbers(v, f"{key}.{k}" if key else str(k))
    elif isinstance(x, tuple | list):
        for i, v in enumerate(x):
            yield from _numbers(v, f"{key}[{i}]")
    else:
        try:  # a numpy scalar
            yield key, float(x)
        except (TypeError, ValueError):
            return


def non_finite(m: Any) -> list[Problem]:
    """Every NaN or infinite number of a mechanism, by table and key: the one check that
    every way into a Mechanism passes (the file loader, ``with_params``, sweeps, Python
    builders). A NaN stop compared False everywhere and was silently dropped."""
    out: list[Problem] = []
    tables = [("mechanism", "gravity", m.gravity), ("ground", "", m.ground),
              ("initial", "", m.initial)]
    for kind in ("bodies", "joints", "drivers", "loads", "elements", "gears"):
        tables += [(f"{'joints' if kind == 'gears' else kind}.{name}", "", rec)
                   for name, rec in getattr(m, kind).items()]
    for table, key, rec in tables:
        for k, val in _numbers(rec, key):
            if not math.isfinite(val):
                out.append(Problem(table, k, f"expected a finite number, got {val}"))
    return out



def validate(m: Any) -> list[Problem]:
    """All semantic problems of a mechanism (empty list when it is sound): the checks of
    each table, and every non-finite number (:func:`non_finite`) they did not report."""
    out: list[Problem] = []
    space = getattr(m, "space", "planar")
    if space not in SPACES:
        out.append(Problem("mechanism", "space", f"expected one of {', '.join(SPACES)}, "
                           f"got {space!r}"))
    if space == "spatial":
        out += spatial_problems(m)
    elif not all(_finite(g) for g in m.gravity) or len(m.gravity) != 2:
        out.append(Problem("mechanism", "gravity", f"expected two finite numbers, got {m.gravity}"))
    if not m.bodies:
        out.append(Problem("bodies", "", "a mechanism needs at least one body"))
    for kind in ("bodies", "joints", "drivers", "loads", "elements", "gears"):
        for name in getattr(m, kind):  # a dotted path (body.point, a parameter) splits at '.'
            if not isinstance(name, str) or not name or "." in name:
                out.append(Problem(f"{kind}.{name}", "", "a name must be a non-empty word "
                                   "without '.' (references such as 'body.point' split there)"))
    for name in m.ground:
        if not isinstance(name, str) or not name or "." in name:
            out.append(Problem("ground", f"points.{name}", "a point name must be a non-empty "
                               "word without '.'"))
    for name, b in m.bodies.items() if space != "spatial" else ():
        t = f"bodies.{name}"
        if name == GROUND:
            out.append(Problem(t, "", "'ground' is reserved for the frame"))
        if not (_finite(b.mass) and b.mass > 0):
            out.append(Problem(t, "mass", f"expected a positive mass in kg, got {b.mass}"))
        if not (_finite(b.inertia) and b.inertia >= 0):
            out.append(Problem(t, "inertia", "expected a centroidal inertia >= 0 in kg m^2 "
                               "(0: a point mass, whose rotation its joints must fix), "
                               f"got {b.inertia:.6g}" if _finite(b.inertia) else
                               "expected a centroidal inertia >= 0 in kg m^2, "
                               f"got {b.inertia}"))
    used_bodies: set[str] = set()
    for name, j in m.joints.items():
        if space != "spatial":
            out += joint_problems(m, f"joints.{name}", j)
        used_bodies.update((j.first_body, j.second_body))
    for name in m.bodies:
        if name not in used_bodies:
            out.append(Problem(f"bodies.{name}", "", "is connected by no joint"))
    for name, d in m.drivers.items():
        t = f"drivers.{name}"
        if name not in m.joints:
            out.append(Problem(t, "", f"drives unknown joint '{name}' "
                               f"(joints: {', '.join(m.joints) or 'none'})"))
        elif m.joints[name].stops is not None:
            jd = m.joints[name]
            what = "limits" if jd.limits else "a unilateral contact" if jd.lands else \
                "stops at its open curve's ends"
            out.append(Problem(t, "", f"joint '{name}' has {what}: a driven joint cannot "
                               "be metamorphic"))
        elif m.joints[name].friction is not None:
            out.append(Problem(t, "", f"joint '{name}' has friction: the driver would carry "
                               "it (put the friction on an undriven joint)"))
        out.extend(_check_driver(t, d))
    for name, ld in m.loads.items():
        out.extend(_check_load(m, f"loads.{name}", ld))
    for name, el in m.elements.items():
        t = f"elements.{name}"
        _check_ref(m, t, "connects", el.first, out)
        _check_ref(m, t, "connects", el.second, out)
        if el.first_body == el.second_body:
            out.append(Problem(t, "connects", f"both points are on body '{el.first_body}': "
                               "the element would do nothing"))
        held = next((jn for jn, j in m.joints.items() if j.type == "revolute"
                     and {j.first, j.second} == {el.first, el.second}), None)
        if held is not None:
            out.append(Problem(t, "connects", f"revolute joint '{held}' holds these two "
                               "points together: the element's length is always 0 and its "
                               "direction undefined (connect it to points apart)"))
        for key in ("stiffness", "rest", "damping"):
            val = getattr(el, key)
            if not (_finite(val) and val >= 0):
                out.append(Problem(t, key, f"expected a number >= 0, got {val}"))
        if not _finite(el.preload):
            out.append(Problem(t, "preload", f"expected a finite number, got {el.preload}"))
    for name, gr in m.gears.items():
        out += gear_problems(m, f"joints.{name}", gr)
    _check_initial(m, out)
    said = {(p.table, p.key.split("[")[0]) for p in out}
    return out + [p for p in non_finite(m) if (p.table, p.key.split("[")[0]) not in said]


def _check_law(t: str, law: Any, target: str) -> list[Problem]:
    out: list[Problem] = []
    if law.func is not None:
        if not callable(law.func):
            out.append(Problem(t, "law", f"expected a callable f(t, coordinate, rate), got "
                               f"{type(law.func).__name__}"))
        else:
            try:  # called with three numbers: refused here, not as a TypeError mid-run
                inspect.signature(law.func).bind(0.0, 0.0, 0.0)
            except TypeError as e:
                out.append(Problem(t, "law", f"expected a callable f(t, coordinate, rate) "
                                   f"of three arguments (s, m or rad, m/s or rad/s): {e}"))
            except ValueError:  # no signature to read (a builtin): called as it is
                pass
        if target != "joint":
            out.append(Problem(t, "law", "a callable law f(t, coordinate, rate) needs a "
                               "joint: only a load on a joint coordinate can use it"))
        return out
    if law.kind not in LAWS:
        out.append(Problem(t, "law", f"expected one of {', '.join(LAWS)}, got {law.kind!r}"))
        return out
    nums = {"constant": ("value",), "harmonic": ("mean", "amplitude", "frequency", "phase"),
            "motor": ("stall", "no_load_speed")}.get(law.kind, ())
    for key in nums:
        if not _finite(getattr(law, key)):
            out.append(Problem(t, key, f"expected a finite number, got {getattr(law, key)}"))
    if law.kind == "polynomial" and not law.coefficients:
        out.append(Problem(t, "coefficients", "expected at least one coefficient"))
    if law.kind == "harmonic" and _finite(law.frequency) and law.frequency < 0:
        out.append(Problem(t, "frequency", f"expected a frequency >= 0 Hz, got {law.frequency}"))
    if law.kind == "table":
        out.extend(_check_table(t, law.times, law.values))
    if law.kind == "motor":
        if target != "joint":
            out.append(Problem(t, "law", "a motor law needs a joint rate: only a load on a "
                               "joint coordinate can use it"))
        if _finite(law.no_load_speed) and not law.no_load_speed > 0:
            out.append(Problem(t, "no_load_speed", f"expected a positive speed (rad/s or "
                               f"m/s), got {law.no_load_speed}"))
    return out


def _check_load(m: Any, t: str, ld: Any) -> list[Problem]:
    out: list[Problem] = []
    if ld.joint is not None:
        if ld.body is not None or ld.point is not None:
            out.append(Problem(t, "joint", "a load acts on a joint or on a body, not both"))
        if ld.joint not in m.joints:
            out.append(Problem(t, "joint", f"unknown joint '{ld.joint}' "
                               f"(joints: {', '.join(m.joints) or 'none'})"))
    elif ld.body is None:
        out.append(Problem(t, "", "give 'joint' (a load on a joint coordinate) or 'body' "
                           "(a force at a point, or a moment)"))
    elif ld.body not in m.bodies:
        out.append(Problem(t, "body", f"unknown body '{ld.body}' "
                           f"(bodies: {', '.join(m.bodies) or 'none'})"))
    elif ld.point is not None and ld.point not in m.bodies[ld.body].points:
        out.append(Problem(t, "point", f"body '{ld.body}' has no point '{ld.point}' "
                           f"(its points: {', '.join(m.bodies[ld.body].points) or 'none'})"))
    if ld.target == "point":
        d = ld.direction
        if d is None or not (all(_finite(x) for x in d) and math.hypot(*d) > 1e-12):
            out.append(Problem(t, "direction", f"expected a non-zero direction [x, y], got {d}"))
        if ld.frame not in FRAMES:
            out.append(Problem(t, "frame", f"expected one of {', '.join(FRAMES)}, "
                               f"got {ld.frame!r}"))
    elif ld.direction is not None and (ld.joint is not None or m.space != "spatial"):
        out.append(Problem(t, "direction", "only a force at a body point has a direction"
                           + " (or a moment on a body of a spatial mechanism)"
                           * (m.space == "spatial")))
    out.extend(_check_law(t, ld.law, ld.target))
    z = ld.zone
    if z is not None:
        zj = z.joint if z.joint is not None else ld.joint
        if zj is None:
            out.append(Problem(t, "zone.joint", "a load on a body needs the zone's joint"))
        elif zj not in m.joints:
            out.append(Problem(t, "zone.joint", f"unknown joint '{zj}'"))
        elif z.lower is None and z.upper is None:
            out.append(Problem(t, "zone", "give 'lower', 'upper' or both"))
        elif z.lower is not None and z.upper is not None and not z.lower < z.upper:
            out.append(Problem(t, "zone", f"lower ({z.lower}) must be below upper ({z.upper})"))
        else:
            lim = m.joints[zj].limits
            lo = -math.inf if lim is None or lim.lower is None else lim.lower
            up = math.inf if lim is None or lim.upper is None else lim.upper
            zlo = -math.inf if z.lower is None else z.lower
            zup = math.inf if z.upper is None else z.upper
            if zup <= lo or zlo >= up:
                out.append(Problem(t, "zone", f"[{z.lower}, {z.upper}] lies outside the "
                                   f"limits [{lim.lower}, {lim.upper}] of joint '{zj}': "
                                   "the load could never act"))
    return out


def _check_driver(t: str, d: Any) -> list[Problem]:
    out: list[Problem] = []
    if d.motion not in MOTIONS:
        out.append(Problem(t, "motion", f"expected one of {', '.join(MOTIONS)}, got {d.motion!r}"))
    elif d.motion == "polynomial" and not d.coefficients:
        out.append(Problem(t, "coefficients", "expected at least one coefficient"))
    elif d.motion == "table":
        out.extend(_check_table(t, d.times, d.values))
    elif d.motion == "harmonic" and not d.frequency >= 0:
        out.append(Problem(t, "frequency", f"expected a frequency >= 0 Hz, got {d.frequency}"))
    return out


def _check_table(t: str, times: tuple, values: tuple) -> list[Problem]:
    if len(times) < 2 or len(times) != len(values):
        return [Problem(t, "times", "expected 'times' and 'values' of equal length >= 2, "
                        f"got {len(times)} and {len(values)}")]
    if any(b <= a for a, b in zip(times, times[1:], strict=False)):
        return [Problem(t, "times", "expected strictly increasing times")]
    if times[0] != 0.0:
        return [Problem(t, "times", f"the table must start at t = 0, starts at {times[0]}")]
    return []


def _check_equilibrium(m: Any, out: list[Problem]) -> None:
    eq = m.initial.equilibrium
    if not eq:
        return
    known = [k for k in m.initial.joints if k not in m.drivers]
    if isinstance(eq, str):
        if eq != "position":
            out.append(Problem("initial", "equilibrium", f"expected \"position\" or a list "
                               f"of parameter paths, got {eq!r}"))
        elif not known:
            out.append(Problem("initial", "equilibrium", "\"position\" solves the "
                               "coordinates named in [initial] joints: it names none"))
        return
    if len(eq) != len(known):
        out.append(Problem("initial", "equilibrium", f"{len(eq)} parameter(s) for "
                           f"{len(known)} free coordinate(s) ({', '.join(known) or 'none'}): "
                           "give one parameter per coordinate named in [initial] joints"))
    if len(set(eq)) != len(eq):
        out.append(Problem("initial", "equilibrium", "a parameter is listed twice"))


def _check_initial(m: Any, out: list[Problem]) -> None:
    _check_equilibrium(m, out)
    for key, table in (("joints", m.initial.joints), ("velocities", m.initial.velocities)):
        for jn, val in table.items():
            if jn not in m.joints:
                out.append(Problem("initial", f"{key}.{jn}", f"unknown joint '{jn}' "
                                   f"(joints: {', '.join(m.joints) or 'none'})"))
            elif not _finite(val):
                out.append(Problem("initial", f"{key}.{jn}",
                                   f"expected a finite number, got {val}"))
            elif key == "joints" and jn in m.drivers:
                v0 = m.drivers[jn].value0()
                if abs(val - v0) > 1e-12 * max(1.0, abs(v0)):
                    out.append(Problem("initial", f"joints.{jn}", f"joint '{jn}' is driven: its "
                                       f"driver gives {v0!r} at t = 0, the file says {val!r}"))
            elif key == "velocities" and jn in m.drivers:
                out.append(Problem("initial", f"velocities.{jn}", f"joint '{jn}' is driven: its "
                                   "velocity comes from its driver"))
            elif key == "joints" and m.joints[jn].limits is not None:
                lim = m.joints[jn].limits
                if lim.outside(val):
                    out.append(Problem("initial", f"joints.{jn}", f"{val} lies outside the "
                                       f"limits [{lim.lower}, {lim.upper}] of joint '{jn}' "
                                       f"(by {lim.beyond(val):.3g}; a start within "
                                       f"{STOP_TOL:g} times max(1, |stop|) of a stop is "
                                       "put on it)"))

