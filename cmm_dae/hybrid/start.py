"""Consistent initial values by the package's own linear algebra.

Positions by Newton from the known joint coordinates and the pose guesses, velocities from
the velocity constraints and the known joint rates, accelerations and multipliers from the
KKT system. A loop that cannot close, or a redundant or singular constraint set, is an
:class:`AssemblyError` naming the joints and the residual; nothing is least-squared silently.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import AssemblyError, ModelError, Problem
from ..core.memo import once, recent
from ..core.records import Event, EventKind
from ..core.scipy_late import least_squares
from ..equations import rank
from ..equations.kinematics import redundant_rows
from ..equations.model import Model
from ..equations.spatial import initial_guess as spatial_guess
from ..equations.spatial import velocity_guess
from .policy import resting_rate, stick_or_slip
from .state import HybridState, idle_slide
from .zones import initial_zones

#: Position residual (m or rad) below which a loop counts as closed.
CLOSE_TOL = 1e-10


def initial_guess(model: Model) -> np.ndarray:
    """Centroid coordinates from the bodies' frame-pose guesses (zeros where none)."""
    q = np.zeros(model.nq)
    if model.mech.spatial:
        return spatial_guess(model)
    for i, b in enumerate(model.mech.bodies.values()):
        x, y, th = b.guess if b.guess is not None else (0.0, 0.0, 0.0)
        c, s = np.cos(th), np.sin(th)
        cx, cy = b.centroid
        q[3 * i:3 * i + 3] = (x + c * cx - s * cy, y + s * cx + c * cy, th)
    return q


def _labels(model: Model, rows, known: list[str]) -> list[str]:
    out = []
    for i in rows:
        if i < len(model.rows):
            r = model.rows[i]
            out.append(f"{r.kind} {r.name}" if r.kind != "joint" else f"joint {r.name}")
        else:
            out.append(f"[initial] joints.{known[i - len(model.rows)]}")
    return out


def _once(model: Model, key: tuple, compute):
    """``compute()`` once per model and key (:func:`~cmm_dae.core.memo.once`): the start's
    assembly, rank checks and redundant rows depend on the model, the parameters and the
    given values alone (a 0.01-s run of a chain of 32 loops spent half its time assembling
    the same start again)."""
    return once(model, ("start", *key), compute)


def assemble_positions(model: Model, t: float, p: np.ndarray, known: dict[str, float],
                       q_guess: np.ndarray) -> np.ndarray:
    """Solve the position equations plus ``c_j(q) = known[j]`` for q, once per model and
    inputs (:func:`_solve_positions`); a fresh copy each call."""
    key = ("q", float(t), p.tobytes(), tuple(known.items()), q_guess.tobytes())
    return _once(model, key, lambda: _solve_positions(model, t, p, known, q_guess)).copy()


def _solve_positions(model: Model, t: float, p: np.ndarray, known: dict[str, float],
                     q_guess: np.ndarray) -> np.ndarray:
    """Solve the position equations plus ``c_j(q) = known[j]`` for q.

    Raises
    ------
    ModelError
        The number of equations does not match the number of coordinates.
    AssemblyError
        The loop does not close (residual named) or the equations are singular.
    """
    act = model.active_rows(p)
    names = list(known)
    kidx = [model.jidx[n] for n in names]
    vals = np.array([known[n] for n in names])
    n_eq = len(act) + len(names)

    def wrong_count(dof: int) -> ModelError:
        return ModelError(Problem(
            "initial", "joints",
            f"the mechanism has {dof} free degree(s) of freedom at t = {t:g} s "
            f"({model.nq} coordinates, {len(act)} constraint rows, "
            f"{len(act) - (model.nq - dof)} of them redundant), so [initial] joints must "
            f"name {dof} non-driven joint coordinate(s); it names {len(names)}"
            + (f" ({', '.join(names)})" if names else "")), model.mech.source)

    # (in space the free motion no coordinate names starts from the bodies' guessed poses)
    if n_eq < model.nq and not model.mech.spatial:
        raise wrong_count(model.nq - len(act))

    def fun(q):
        con, c, c_q = model.kinematics(q, t, p)
        r = np.concatenate([con.phi[act], c[kidx] - vals])
        J = np.vstack([con.Phi_q[act], c_q[kidx]])
        return r, J

    q = np.array(q_guess, float)
    r, J = fun(q)
    if np.max(np.abs(r), initial=0.0) > 1e-6:  # (fewer rows than coordinates: "trf")
        sol = least_squares(lambda x: fun(x)[0], q, jac=lambda x: fun(x)[1],
                            method="lm" if n_eq >= model.nq else "trf",
                            xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
        q = sol.x
    for _ in range(20 if n_eq >= model.nq else 60):  # Newton polish to machine precision
        # (fewer rows than coordinates: the least change, Gauss-Newton's minimum norm)
        r, J = fun(q)
        if np.max(np.abs(r), initial=0.0) < 1e-14:
            break
        try:  # more rows than coordinates: a redundant set, solved in least squares
            step = (np.linalg.solve(J, r) if J.shape[0] == J.shape[1]
                    else np.linalg.lstsq(J, r, rcond=None)[0])
        except np.linalg.LinAlgError:
            break
        if not np.max(np.abs(fun(q - step)[0]), initial=0.0) < np.max(np.abs(r)):
            break  # no closer (a loop that cannot close: its residual, not a divergence's)
        q = q - step
    r, J = fun(q)
    res = float(np.max(np.abs(r), initial=0.0))
    if n_eq > model.nq:  # redundant rows, or too many coordinates named: count by rank
        r = rank.rank(model.kinematics(q, t, p)[0].Phi_q[act])
        if len(names) != model.nq - r:
            raise wrong_count(model.nq - r)
    if res > CLOSE_TOL:
        worst = np.argsort(-np.abs(r))[:4]
        labels = sorted(set(_labels(model, act[worst[worst < len(act)]], names)))
        raise AssemblyError(
            f"the mechanism cannot be assembled at t = {t:g} s: the loop through "
            f"{', '.join(labels) or 'the given coordinates'} does not close "
            f"(largest residual {res:.3g} m or rad). Check the lengths, the [initial] joint "
            "coordinates and the bodies' pose guesses.",
            joints=[lab.split()[-1] for lab in labels], residual=res)
    check_rank(model, J, act, names, t)
    return q


def check_rank(model: Model, J: np.ndarray, act, names: list[str], t: float) -> None:
    """Raise AssemblyError naming the rows of a singular (redundant) square system."""
    U, s, _ = np.linalg.svd(J)
    if s.size and s[-1] < rank.RANK_TOL * s[0]:
        w = U[:, s.size - 1]
        rows = np.flatnonzero(np.abs(w) > 0.05 * np.max(np.abs(w)))
        idx = list(act) + list(range(len(model.rows), len(model.rows) + len(names)))
        labels = sorted(set(_labels(model, [idx[i] for i in rows], names)))
        raise AssemblyError(
            f"the constraint equations are redundant or singular at t = {t:g} s "
            f"(smallest singular value {s[-1]:.3g}, largest {s[0]:.3g}); involved: "
            f"{', '.join(labels)}. A redundant joint, a dead point or a coordinate "
            "that does not fix the free motion can cause this.",
            joints=[lab.split()[-1] for lab in labels], residual=float(s[-1]))


def assemble_velocities(model: Model, q: np.ndarray, t: float, p: np.ndarray,
                        rates: dict[str, float]) -> np.ndarray:
    """Solve ``Phi_q v = -Phi_t`` plus ``c_j' = rates[j]`` for v, once per model and
    inputs (a dense solve of the coordinates' size: 1.4 ms a run with 32 loops); a fresh
    copy each call."""
    key = ("v", float(t), q.tobytes(), p.tobytes(), tuple(rates.items()))
    return _once(model, key, lambda: _solve_velocities(model, q, t, p, rates)).copy()


def _solve_velocities(model: Model, q: np.ndarray, t: float, p: np.ndarray,
                      rates: dict[str, float]) -> np.ndarray:
    """Solve ``Phi_q v = -Phi_t`` plus ``c_j' = rates[j]`` for v."""
    act = model.active_rows(p)
    names = list(rates)
    kidx = [model.jidx[n] for n in names]
    con, _, c_q = model.kinematics(q, t, p)
    J = np.vstack([con.Phi_q[act], c_q[kidx]])
    rhs = np.concatenate([-con.Phi_t[act], [rates[n] for n in names]])
    if J.shape[0] < J.shape[1] and model.mech.spatial:
        # the free motion no rate names: the bodies' guessed velocities, made consistent
        # by the least change in kinetic energy's metric
        vg = velocity_guess(model, q)
        w = 1.0 / np.sqrt(model.mass)
        return vg + w * np.linalg.lstsq(J * w, rhs - J @ vg, rcond=None)[0]
    if J.shape[0] < J.shape[1]:
        raise ModelError(Problem("initial", "velocities", f"expected {model.nq - len(act)} "
                                 f"joint rates, got {len(names)}"), model.mech.source)
    _once(model, ("vrank", float(t), q.tobytes(), p.tobytes(), tuple(names)),
          lambda: check_rank(model, J, act, names, t))
    if J.shape[0] == J.shape[1]:
        return np.linalg.solve(J, rhs)
    v = np.linalg.lstsq(J, rhs, rcond=None)[0]  # redundant rows: consistent, least squares
    return v


def start_spec(mech) -> tuple[dict[str, float], dict[str, float]]:
    """The joint coordinates (rad, m) and rates the start is assembled from: the
    non-driven ``[initial] joints`` with their rates (0 unless given), or the rates of
    ``[initial] velocities`` alone when they name as many other joints."""
    ini = mech.initial
    # a joint named within the stop tolerance of a stop starts exactly on it
    known = {k: (v if mech.joints[k].stops is None else mech.joints[k].stops.snap(v))
             for k, v in ini.joints.items() if k not in mech.drivers}
    rates = {k: 0.0 for k in known}
    rates.update({k: v for k, v in ini.velocities.items() if k not in mech.drivers})
    if len(ini.velocities) and set(ini.velocities) != set(known) and \
            len(ini.velocities) == len(known):
        rates = dict(ini.velocities)
    return known, rates


def start_state(model: Model, hs: HybridState, t0: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray, list[Event]]:
    """Consistent positions and velocities at t0, with joints that start pressed on a stop
    locked (a ``lock`` event each)."""
    mech = model.mech
    known, rates = start_spec(mech)

    def assemble() -> tuple[np.ndarray, np.ndarray]:
        q = assemble_positions(model, t0, hs.p, known, initial_guess(model))
        return q, assemble_velocities(model, q, t0, hs.p, rates)
    # the model's own start: every run of it assembles the same (0.7 ms with 32 loops)
    q, v = (x.copy() for x in recent(model, "assembled", (t0, hs.p.tobytes()), assemble))
    hs.zones = initial_zones(model, q)
    c0 = model.joint_rates(q, v)[0]
    beyond = []
    limited = mech.limited_joints
    for name in limited:
        lim = mech.joints[name].stops
        val = float(c0[model.jidx[name]])
        if lim.outside(val):
            beyond.append(Problem("initial", "joints", f"joint '{name}' assembles at {val:.9g}, "
                                  f"outside its limits [{lim.lower}, {lim.upper}]"))
    if beyond:
        raise ModelError(beyond, mech.source)
    # A joint that assembles exactly on one of its limits (named in [initial] joints or
    # not) is a candidate for a start on the stop; one moving into it is the run's first
    # impact (events.start_triggers).
    stops = {}
    for name in limited:
        lim = mech.joints[name].stops
        side = lim.on(float(c0[model.jidx[name]]))
        if side is not None:
            stops[name] = side
    events: list[Event] = []
    cd0 = model.joint_rates(q, v)[1]
    for name, side in stops.items():
        if abs(cd0[model.jidx[name]]) > resting_rate(cd0):
            continue  # moving in: an impact before the first step; moving out: free
        trial = {**hs.locked, name: side}
        if hs.lock_force(q, v, t0, name, trial) > 0.0:
            before = hs.current()
            hs.locked = trial
            events.append(Event(t=t0, kind=EventKind.LOCK, joint=name, side=side, before=before,
                                after=hs.current()))
        elif mech.joints[name].lands:  # said, not silent: a wrong `side` looks just so
            events.append(Event(t=t0, kind=EventKind.LIFT_OFF, joint=name, side=side,
                                before=hs.current(), after=hs.current(),
                                note="starts on its curve and leaves it at once (the contact "
                                     "would have to pull: is `side` the side it keeps to?)"))
    for name in model.frictional:  # dry friction: moving joints slip, resting ones stick
        if name in hs.locked or idle_slide(model, name, hs.locked):
            continue
        k = model.jidx[name]
        if cd0[k] != 0.0:
            hs.slip = {**hs.slip, name: 1 if cd0[k] > 0 else -1}
        else:  # the same decision as when a slipping joint comes to rest
            events.append(stick_or_slip(hs, q, v, t0, name).event)
    return q, v, events


def redundant_base_rows(model: Model, t0: float = 0.0) -> tuple[int, ...]:
    """Joint and driver rows redundant at the start (indices into ``model.all_rows``): the
    mechanism assembled with no lock, and the rows that depend on the others there."""
    mech = model.mech
    known = {k: v for k, v in mech.initial.joints.items() if k not in mech.drivers}
    q = assemble_positions(model, t0, model.params(), known, initial_guess(model))
    return _once(model, ("redundant", float(t0)), lambda: redundant_rows(model, q, t0))
