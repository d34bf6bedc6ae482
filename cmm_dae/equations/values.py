"""A mechanism's numbers that its equations take as inputs: one model per structure.

A model's CasADi functions read the numbers below from the tail of the parameter vector
``p`` (:attr:`~.model.Model.value_paths`, values ``Model.w0``) instead of holding them as
constants, so that two mechanisms that differ only in them share one model: its symbolic
build, its functions and their maps, its compiled libraries (:meth:`.model.Model.variant`).
A parameter sweep, a design study or a finite difference then costs its runs, not a build
each (8 stiffness variants of the double-folded mechanism: 1.39x eight warm runs of the
base, against 3.87x when each built its model; ``validation/variants.py``).

Which numbers: those the model builder reads from the symbolic mechanism alone (masses,
planar and principal inertias, points, springs, dampers, kinetic friction, contact radii,
prismatic angles, drivers' law values, force elements, gravity). Not: the numbers the
event policy reads (stops, restitution, static friction, zones), load laws, gear ratios
(the tooth force's direction follows their sign and size), full inertia tensors (their
principal axes are an eigen-decomposition), the two points of a revolute joint that pins
an undriven body to the ground (IDA carries that body by its angle), a spatial spring's
rest (the hinge angle's centre), and a value that is exactly zero (it keeps terms out of
the equations, and so their sparsity). Those are part of the structure
(:func:`structure_key`): another value there is another model.
"""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np

from ..core.errors import ModelError, Problem
from ..description.mechanism import GROUND, Mechanism
from ..description.params import param_value, path_problem, symbolic
from . import build, kkt
from .unknowns import ground_pins

__all__ = ["parameters", "structure_key", "structure_of", "value_paths", "variant"]

#: The fields of each table whose values are inputs (see the module's docstring).
_JOINT = ("spring.stiffness", "spring.rest", "damper.damping", "angle", "friction.kinetic",
          "friction.mu_kinetic", "friction.radius", "curve.radius")
_DRIVER = ("initial", "speed", "amplitude", "frequency", "phase")
_ELEMENT = ("stiffness", "rest", "damping", "preload")


def _candidates(mech: Mechanism) -> list[tuple[str, float | None]]:
    """Every dotted path of the fields above, whether the mechanism has it or not, with
    its value where known to be a parameter with an effect (the points a joint, element or
    load uses: asked of ``path_problem`` one by one, 772 of them took 44 ms with 128
    loops), else None."""
    axes = ("x", "y", "z") if mech.spatial else ("x", "y")
    pinned = {r for name in ground_pins(mech).values()
              for r in (mech.joints[name].first, mech.joints[name].second)}
    used = {r for x in (*mech.joints.values(), *mech.elements.values())
            for r in (x.first, x.second)}
    used |= {f"{ld.body}.{ld.point}" for ld in mech.loads.values() if ld.point is not None}
    out: list[tuple[str, float | None]] = [(f"gravity.{a}", None) for a in axes]
    for b, body in mech.bodies.items():
        out.append((f"bodies.{b}.mass", None))
        if not mech.spatial:
            out.append((f"bodies.{b}.inertia", None))
        elif len(body.inertia) == 3:
            out += [(f"bodies.{b}.inertia.{e}", None) for e in ("xx", "yy", "zz")]
    points = [(f"bodies.{b}.points.{p}", f"{b}.{p}", xyz) for b, body in mech.bodies.items()
              for p, xyz in body.points.items()]
    points += [(f"{GROUND}.points.{p}", f"{GROUND}.{p}", xyz) for p, xyz in mech.ground.items()]
    out += [(f"{path}.{a}", float(xyz[k])) for path, ref, xyz in points
            if ref in used and ref not in pinned for k, a in enumerate(axes)]
    for j in mech.joints:
        out += [(f"joints.{j}.{f}", None) for f in _JOINT
                if not (mech.spatial and f == "spring.rest")]
    for d in mech.drivers:
        out += [(f"drivers.{d}.{f}", None) for f in _DRIVER]
    for e in mech.elements:
        out += [(f"elements.{e}.{f}", None) for f in _ELEMENT]
    return out


def value_paths(mech: Mechanism) -> tuple[str, ...]:
    """The dotted paths whose values ``mech``'s model takes as inputs: each a parameter
    with an effect (:func:`~cmm_dae.description.params.path_problem`) whose value is
    finite and not zero."""
    out = []
    for path, x in _candidates(mech):
        if x is None:
            if path_problem(mech, path) is not None:
                continue
            x = param_value(mech, path)
        if x == x and x not in (0.0, float("inf"), float("-inf")):
            out.append(path)
    return tuple(out)


def structure_key(mech: Mechanism, paths: tuple[str, ...]) -> str:
    """What makes ``mech``'s model: the mechanism with the values at ``paths`` (its
    :func:`value_paths`) left out, and the paths themselves (their order is the order of
    ``p``'s tail). Equal keys, one model; the start (``initial``), the name and the file
    are not part of it."""
    blank = symbolic(mech, {x: ca.SX.sym(f"w{k}") for k, x in enumerate(paths)})
    text = repr((paths, blank.space, blank.bodies, blank.joints, blank.ground, blank.drivers,
                 blank.gravity, blank.loads, blank.elements, blank.gears, blank.axes))
    return hashlib.sha256(text.encode()).hexdigest()


def parameters(model: Any, mech: Mechanism, theta: Sequence[str]) -> ca.SX:
    """The parameter vector ``p`` of a model under construction, a symbol: the
    configuration's switches and values, the callable loads' values, then the
    mechanism's values (its :func:`value_paths`; none in a model for sensitivities,
    whose parameters are the symbols ``theta``). Sets the model's ``theta_paths``,
    ``theta``, ``theta0``, ``value_paths``, ``w0``, the layout of p (``n_switches``,
    ``w_at``, ``n_params``), ``smech`` (the mechanism with those symbols) and
    ``shared``, and its bookkeeping (:func:`~.build.names`). Its ``structure`` (the
    :func:`structure_key`) is found where first asked (:func:`structure_of`)."""
    #: model parameters (dotted paths, checked by the caller) kept as the symbols
    #: ``theta`` in ``Model.sym`` (the equations for sensitivities); the compiled
    #: functions hold their values ``theta0``
    model.theta_paths = tuple(theta)
    model.theta = ca.SX.sym("theta", len(model.theta_paths))
    model.theta0 = np.array([param_value(mech, x) for x in model.theta_paths])
    model.value_paths = () if model.theta_paths else value_paths(mech)
    model.w0 = _values(mech, model.value_paths)
    model.smech = mech
    build.names(model, mech)
    nl, nz = len(model.locks), len(model.zoned)
    model._u0 = 2 * nl + nz + len(model.frictional)
    #: entries of ``p`` that make the configuration (the callable loads' values follow)
    model.n_switches = model._u0
    #: where the mechanism's values start in ``p``
    model.w_at = model._u0 + len(model.callables)
    model.n_params = model.w_at + len(model.value_paths)
    #: p with the values alone (the switches zero): for the functions of a state
    model._pw = np.concatenate([np.zeros(model.w_at), model.w0])
    #: the model whose functions this one shares (itself; :func:`variant`)
    model.shared = model
    p = ca.SX.sym("p", model.n_params)
    if model.theta_paths or model.value_paths:
        model.smech = symbolic(mech, {
            **{x: model.theta[i] for i, x in enumerate(model.theta_paths)},
            **{x: p[model.w_at + i] for i, x in enumerate(model.value_paths)}})
        build.names(model, mech)  # (again: the symbolic records)
    return p


def variant(model: Any, mech: Mechanism, key: str | None = None) -> Any:
    """A model of ``mech``, which has ``model``'s structure (:func:`structure_key`),
    sharing its functions, their maps and compiled libraries: only what holds the
    values is its own (the numeric records and masses, the values at p's tail, the KKT
    solver's matrices, the caches of its runs: a start, the structure's checks), but for
    a mechanism equal to ``model``'s in everything (a file loaded again), whose runs share
    those caches too. ``key``: ``mech``'s :func:`structure_key` where known. Raises a
    ModelError for a mechanism of another structure."""
    if key is None and not model.theta_paths:
        key = structure_key(mech, value_paths(mech))
    if model.theta_paths or key != structure_of(model):
        raise ModelError(Problem(
            "model", "variant", f"mechanism {mech.name!r} has another structure than the "
            f"model's ({model.mech.name!r}): a number it keeps as structure differs (stops, "
            "restitution, static friction, zones, load laws, gear ratios, full inertia "
            "tensors, a ground pin's points, a spatial spring's rest, a value zero in one "
            "of them) or its bodies, joints or loads do; build cmm_dae.Model(mech)"
            if not model.theta_paths else "a model for sensitivities has no variants"),
            mech.source)
    new = copy.copy(model)
    new.mech = mech
    new.w0 = _values(mech, model.value_paths)
    if not (np.array_equal(new.w0, model.w0) and mech.initial == model.mech.initial):
        for cache in ("_once", "_recent"):  # (else the same mechanism: its start too)
            new.__dict__.pop(cache, None)
    new._pw = np.concatenate([np.zeros(model.w_at), new.w0])
    build.names(new, mech)  # the numeric records and masses (its smech is the shared one)
    new._kkt = kkt.Solver(new, model.phi_q_pattern)
    return new


def structure_of(model: Any) -> str:
    """A model's :func:`structure_key`, found once (a run's cache sets it where it has
    found it already)."""
    got = model.__dict__.get("structure")
    if got is None:
        got = model.structure = structure_key(model.mech, model.value_paths)
    return got


def _values(mech: Mechanism, paths: tuple[str, ...]) -> np.ndarray:
    """The values of ``mech`` at ``paths`` (the tail of its models' ``p``)."""
    return np.array([param_value(mech, x) for x in paths], dtype=float)
