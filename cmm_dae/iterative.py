"""The paper's fixed-step iterative algorithm (section 3, Fig. 10) on the same equations.

At each step ``t_n -> t_n + dt``:

1. the differential variables (the free joint coordinates of the current configuration)
   advance with the previous step's rates: ``c_j += c_j' dt``, ``c_j' += c_j'' dt``;
2. the dependent coordinates follow from the position equations (Newton);
3. the velocities from the velocity equations;
4. accelerations, driving efforts and constraint forces from the KKT system.

Limits crossed within a step switch the configuration at the step's end (clamp onto the
stop and the same impact map as the IDA path); a lock force that changes sign releases the
joint at the step's end. The Result has the same shape as ``run_dae``'s.
"""

from __future__ import annotations

import math
import time

import numpy as np

from . import events as ev
from .assembly import start_state
from .equations import Model
from .errors import CmmError, ModelError, Problem, SolverError
from .mechanism import Mechanism
from .post import build_result
from .result import Event, Result, Stats


def _free_coordinates(model: Model, hs: ev.HybridState, q: np.ndarray, t: float,
                      prefer: list[str]) -> list[str]:
    """Choose the differential variables: non-driven, unlocked joint coordinates that span
    the free motion best (column-pivoted QR on their rates over the null space of the
    active constraints), the user's [initial] choice first when it is well conditioned."""
    free = model.free(hs.p)[0]
    act = np.flatnonzero(free == 0.0)
    _, Phi_q, _ = model.phi(q, t, hs.p)
    J = np.asarray(Phi_q)[act]
    _, s, Vt = np.linalg.svd(J)
    rank = int(np.sum(s > 1e-10 * s[0])) if s.size else 0
    N = Vt[rank:].T  # null space: the free motions
    dof = N.shape[1]
    if dof == 0:
        return []
    _, _, c_q = model.coord(q, np.zeros(model.nq))
    C = np.asarray(c_q) @ N
    cand = [n for n in model.joint_names if n not in model.mech.drivers and n not in hs.locked]
    pref = [n for n in prefer if n in cand]
    if len(pref) == dof:
        sub = C[[model.jidx[n] for n in pref]]
        sv = np.linalg.svd(sub, compute_uv=False)
        if sv[-1] > 1e-6 * max(1.0, sv[0]):
            return pref
    rows = C[[model.jidx[n] for n in cand]]
    # greedy pivoting: pick the coordinate with the largest remaining rate component
    chosen: list[int] = []
    R = rows.copy()
    for _ in range(dof):
        k = int(np.argmax(np.linalg.norm(R, axis=1)))
        chosen.append(k)
        u = R[k] / np.linalg.norm(R[k])
        R = R - np.outer(R @ u, u)
    return [cand[k] for k in chosen]


class _Stepper:
    """Kinematic solves of one configuration with fixed differential variables."""

    def __init__(self, model: Model, hs: ev.HybridState, coords: list[str]):
        self.model, self.hs, self.coords = model, hs, coords
        self.kidx = [model.jidx[n] for n in coords]
        free = model.free(hs.p)[0]
        self.act = np.flatnonzero(free == 0.0)

    def positions(self, q0: np.ndarray, t: float, targets: np.ndarray) -> np.ndarray:
        model, p = self.model, self.hs.p
        q = q0.copy()
        for _ in range(25):
            phi, Phi_q, _, c, c_q = model.kin(q, t, p)
            r = np.concatenate([np.asarray(phi).ravel()[self.act],
                                np.asarray(c).ravel()[self.kidx] - targets])
            if np.max(np.abs(r), initial=0.0) < 1e-13:
                return q
            J = np.vstack([np.asarray(Phi_q)[self.act], np.asarray(c_q)[self.kidx]])
            q = q - np.linalg.solve(J, r)
        phi, Phi_q, _, c, c_q = model.kin(q, t, p)
        r = np.concatenate([np.asarray(phi).ravel()[self.act],
                            np.asarray(c).ravel()[self.kidx] - targets])
        if np.max(np.abs(r), initial=0.0) > 1e-9:
            labels, ratio = ev.dependent_rows(model, q0, t, p, tol=1.0)
            raise SolverError(f"dead point near t = {t:.6g} s: the position equations do not "
                              f"converge (residual {np.max(np.abs(r)):.3g}); the constraints "
                              f"of {', '.join(labels)} are nearly dependent at the last "
                              f"position (singular-value ratio {ratio:.1e}): the mechanism "
                              "cannot follow its driver here")
        return q

    def velocities(self, q: np.ndarray, t: float, rates: np.ndarray) -> np.ndarray:
        model, p = self.model, self.hs.p
        _, Phi_q, Phi_t, _, c_q = model.kin(q, t, p)
        J = np.vstack([np.asarray(Phi_q)[self.act], np.asarray(c_q)[self.kidx]])
        rhs = np.concatenate([-np.asarray(Phi_t).ravel()[self.act], rates])
        return np.linalg.solve(J, rhs)


def run_iterative(mech: Mechanism, t_end: float = 10.0, *, dt: float = 0.01,
                  output_every: int = 1, v_lock: float = 1e-6, max_events: int = 1000,
                  throw: bool = True, model: Model | None = None) -> Result:
    """The paper's fixed-step iterative algorithm from t = 0 to ``t_end``.

    Parameters
    ----------
    mech : Mechanism
    t_end : float
        End time, s.
    dt : float
        Fixed step, s (the paper uses 0.01 s).
    output_every : int
        Keep every k-th step in the Result (events are always kept).
    v_lock : float
        A rebound slower than this (rad/s or m/s) locks the joint.
    max_events : int
        Stop with :class:`SolverError` after this many events.
    throw : bool
        Raise on failure (True) or return the partial Result with its ``status``.
    model : Model or None
        A prebuilt model of ``mech``.

    Returns
    -------
    Result
        Same shape as :func:`cmm_dae.run_dae`'s; ``stats.steps`` counts the fixed steps.
    """
    problems = []
    if not (isinstance(t_end, int | float) and math.isfinite(t_end) and t_end > 0):
        problems.append(Problem("run", "t_end", f"expected a positive end time in s, "
                                f"got {t_end!r}"))
    if not (isinstance(dt, int | float) and math.isfinite(dt) and dt > 0):
        problems.append(Problem("run", "dt", f"expected a positive step in s, got {dt!r}"))
    if not (isinstance(output_every, int) and output_every >= 1):
        problems.append(Problem("run", "output_every", f"expected an integer >= 1, "
                                f"got {output_every!r}"))
    if problems:
        raise ModelError(problems)
    wall0 = time.perf_counter()
    model = model or Model(mech)
    from .structure import force_constraint_joints, labeller

    stats = Stats(build_time=time.perf_counter() - wall0, method="iterative")
    hs = ev.HybridState(model, labeller(mech), force_held=force_constraint_joints(mech))
    q, v, events = start_state(model, hs)
    T, Q, V, C = [0.0], [q], [v], [hs.current()]
    status, err = "success", None
    n_steps = int(round(t_end / dt))
    if abs(n_steps * dt - t_end) > 1e-9 * t_end:
        n_steps = int(math.ceil(t_end / dt))
    prefer = [k for k in mech.initial.joints if k not in mech.drivers]
    try:
        coords = _free_coordinates(model, hs, q, 0.0, prefer)
        st = _Stepper(model, hs, coords)
        a, _, _ = model.kkt(q, v, 0.0, hs.p)
        t = 0.0
        for n in range(1, n_steps + 1):
            t_new = min(n * dt, t_end)
            h = t_new - t
            c, cd, cdd, _ = (np.asarray(x).ravel() for x in model.post1(q, v, a, t))
            k = st.kidx
            targets = c[k] + cd[k] * h  # the paper's step: rates of the previous instant
            rates = cd[k] + cdd[k] * h
            q = st.positions(q + v * h, t_new, targets)
            v = st.velocities(q, t_new, rates)
            t = t_new
            stats.steps += 1
            pre = (t, q, v, hs.current())
            try:
                changed = _switch(model, hs, q, v, t, v_lock, events)
            except CmmError:
                for lst, x in zip((T, Q, V, C), pre, strict=True):  # keep the last state
                    lst.append(x)
                raise
            if changed:
                for lst, x in zip((T, Q, V, C), pre, strict=True):  # the pre-event sample
                    lst.append(x)
                q, v = changed
                if len(events) > max_events:
                    raise SolverError(f"max_events = {max_events} reached at t = {t:.6g} s")
                coords = _free_coordinates(model, hs, q, t, coords + prefer)
                st = _Stepper(model, hs, coords)
            a, _, _ = model.kkt(q, v, t, hs.p)
            if n % output_every == 0 or n == n_steps or changed:
                T.append(t)
                Q.append(q)
                V.append(v)
                C.append(hs.current())
    except (CmmError, np.linalg.LinAlgError, KeyboardInterrupt) as e:
        status = (f"stopped at t = {T[-1]:.6g} s: {e}" if not isinstance(e, KeyboardInterrupt)
                  else "interrupted (KeyboardInterrupt)")
        err = e
    nq = model.nq
    res = build_result(model, np.array(T), np.array(Q).reshape(-1, nq),
                       np.array(V).reshape(-1, nq), np.array(C, int), hs.configurations,
                       hs.params, events, stats, status)
    stats.wall_time = time.perf_counter() - wall0  # the whole run, post-processing included
    if err is not None and (throw or isinstance(err, ModelError)):
        raise SolverError(status, result=res, configuration=hs.configurations[hs.current()],
                          last_event=events[-1] if events else None) from err
    return res


def _switch(model: Model, hs: ev.HybridState, q: np.ndarray, v: np.ndarray, t: float,
            v_lock: float, events: list[Event]) -> tuple[np.ndarray, np.ndarray] | None:
    """Configuration changes at the end of a step: limits crossed (clamp + impact map) and
    locks whose force changed sign (release). Returns the new (q, v) or None."""
    changed = False
    c, cd, _ = (np.asarray(x).ravel() for x in model.coord(q, v))
    for joint, side, kind in ev.event_list(hs):
        k = model.jidx[joint]
        if (kind == "gap") == (joint in hs.locked):
            continue  # an earlier switch of this step changed this joint already
        if kind == "gap":
            L = hs.limit_value(joint, side)
            beyond = (L - c[k]) if side == "lower" else (c[k] - L)
            toward = (cd[k] <= 0.0) if side == "lower" else (cd[k] >= 0.0)
            # round-off leaves a just-released joint a hair beyond its stop: not a crossing
            if not (beyond > 1e-12 * (1.0 + abs(L)) and toward):
                continue
            out = ev.at_limit(hs, q, v, t, joint, side, v_lock, None)  # clamps, impact map
            q, v = out.q, out.v
            events.extend(out.jammed)
            events.append(out.event)
            if out.released_at_once:
                _, lam, _ = model.kkt(q, v, t, hs.p)
                events.append(ev.release(hs, q, v, t, joint, hs.push(lam, joint)))
            changed = True
        else:
            _, lam, _ = model.kkt(q, v, t, hs.p)
            push = hs.push(lam, joint)
            if push < 0.0:
                events.append(ev.release(hs, q, v, t, joint, push))
                changed = True
        c, cd, _ = (np.asarray(x).ravel() for x in model.coord(q, v))
    return (q, v) if changed else None
