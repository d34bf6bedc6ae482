"""Passing singular positions: where the constraint Jacobian loses rank for an instant.

At a singular position of a closed loop (a parallelogram four-bar with all its links on one
line, where it meets its anti-parallelogram branch) the constraint rows become dependent
for an instant: the mobility jumps, the KKT matrix is singular, and neither IDA's Newton
iteration nor the position equations of the fixed-step algorithm converge. The motion
itself is smooth there: in minimal coordinates it is an ordinary ODE, and the branch the
mechanism is on continues with its velocity.

Both integrators stop just before such a position (IDA fails to converge; the fixed-step
algorithm's Newton solve fails) and hand over their last good state. :func:`step_over`
then

1. locates the singular instant along the motion (:mod:`.approach`: the minimum of the
   smallest-to-largest singular value ratio of the active constraint rows, the ratio
   falling linearly to it);
2. crosses it with steps of the two-stage Gauss-Legendre method (order 4) on the
   accelerations of the KKT system. Gauss nodes lie inside each step, never at its ends,
   and the singular instant is a step boundary, so the accelerations are never asked for
   where they are undetermined;
3. projects positions and velocities back onto the constraints (minimum-norm corrections)
   and checks that the motion went on continuously: velocities that the projection has to
   change by more than round-off, or a position still singular, mean that the mechanism
   cannot go on (a dead point of its drivers, a lock-up), and that is still an error.

The event logged is of kind ``"singular"``, with the joints whose constraints became
dependent, the rank drop and the branch taken (``side = "continue"``: the branch of the
motion, by continuity of velocity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import SolverError
from ..equations.kinematics import dependent_rows, rank_drop
from ..equations.kkt import accelerations
from ..equations.model import Model
from .approach import (  # noqa: F401 (the crossing's thresholds, importable from here)
    END_RATIO,
    FINE_NODE_RATIO,
    NO_COLLAPSE,
    NODE_RATIO,
    PAST_RATIO,
    Plan,
    Start,
    leaves_singular,
    plan_ahead,
    plan_behind,
    ratio,
)
from .branches import choose_branch, other_branches
from .gauss import accurate_step, dense, gl2_step, project
from .instant import singular_instant

#: The crossing ends where the singular-value ratio is this many times the one at its start.
AFTER = 12.0
#: Relative singular value counted as zero by the projections at the singular instant.
SINGULAR_RCOND = 1e-8
#: Most Gauss steps on the way out at the accurate step length (longer steps beyond).
MAX_STEPS_OUT = 2000
#: Steps between two estimates of the accurate step on the way out.
RECHECK = 16


@dataclass(frozen=True)
class Crossing:
    """A singular position crossed: where, how, and the state after it."""

    t_singular: float
    t_after: float
    q: np.ndarray
    v: np.ndarray
    labels: list[str]
    rank_drop: int
    ratio_min: float
    velocity_jump: float
    switched: bool = False
    #: The Gauss steps taken from the state handed over (s), and how many of them end at
    #: the singular instant (0 when it lay behind): what the sensitivities replay.
    steps: tuple[float, ...] = ()
    n_before: int = 0
    #: The step ends [(t, q, v)] from the state handed over (the first) on (a branch
    #: switch repeats its instant with the new velocities): :meth:`state_at` steps from
    #: them.
    ends: tuple = ()
    #: False for a way out only: the motion leaves a near-singular position whose instant
    #: lies before the segment (the run's start, or an instant crossed and logged
    #: already); ``t_singular`` is then where that instant extrapolates to, and nothing
    #: is to be logged.
    instant: bool = True
    #: Per step of :attr:`ends`: its two stage accelerations' difference (K2 - K1; None
    #: for a branch switch's repeated instant), for :meth:`state_at`.
    dk: tuple = ()
    _accels: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def t0(self) -> float:
        """Time of the state handed over, s."""
        return self.ends[0][0]

    def interval(self, t: float) -> int:
        """The step (index into :attr:`ends` of its start) that holds the time t (s): the
        first of positive length reaching t, the first or last one for a t before or
        beyond them."""
        e = self.ends
        steps = [k for k in range(len(e) - 1) if e[k + 1][0] > e[k][0]]
        return next((k for k in steps if t <= e[k + 1][0]), steps[-1])

    def end_state(self, model: Model, p: np.ndarray, i: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The step end ``ends[i]`` projected onto the constraints and its accelerations
        there (q, v, a; kept once computed); None at the singular instant, where the
        accelerations are undetermined (the end :attr:`n_before` steps in, and its
        repetition after a branch switch)."""
        if self.n_before >= 1 and i in (self.n_before, self.n_before + int(self.switched)):
            return None
        if i not in self._accels:
            t, q, v = self.ends[i]
            q1, v1, _ = project(model, p, q, v, t)
            self._accels[i] = (q1, v1, accelerations(model, q1, v1, t, p)[0])
        return self._accels[i]

    def end_accel(self, model: Model, p: np.ndarray, i: int) -> np.ndarray | None:
        """The accelerations of :meth:`end_state` (None at the singular instant)."""
        got = self.end_state(model, p, i)
        return None if got is None else got[2]

    def state_at(self, model: Model, p: np.ndarray, t: float
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities at t inside the crossing: its step there read through
        (:func:`~cmm_dae.singular.gauss.dense`, as accurate as the step), projected onto
        the constraints (the steps' ends are not: on a long way out they drift by up to
        2e-7 m at rtol 1e-10)."""
        k = self.interval(t)
        (t0, q0, v0), (t1, q1, v1) = self.ends[k], self.ends[k + 1]
        q, v = dense(t0, q0, v0, self.end_accel(model, p, k), t1, q1, v1,
                     self.end_accel(model, p, k + 1), self.dk[k], t)
        return project(model, p, q, v, t)[:2]


def step_over(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
              t_end: float, rule: tuple[str, int] | None = None, *, rtol: float = 1e-8,
              atol: float = 1e-10, t_min: float = -math.inf,
              node_ratio: float = NODE_RATIO, method: str = "ida") -> Crossing:
    """Cross the singular position ahead of the state (t, q, v) on the branch of the motion
    (or the one just behind it that the integrator stepped across; or, where that lies
    before the segment, only carry the motion out of its neighbourhood).

    Parameters
    ----------
    model, p : Model, ndarray
        The equations and the configuration's parameters.
    t : float
        Time of the last good state, s.
    q, v : ndarray
        That state (positions, velocities).
    t_end : float
        End of the run, s (the crossing does not go beyond it).
    rule : (joint, sign) or None
        None: the branch of the motion. Else the branch on which that joint's coordinate
        moves with that sign (+1 or -1), the branch of the motion if it does (only where
        one loop is singular: a rank drop of 1).
    rtol, atol : float
        The run's tolerances: the Gauss steps are no longer than a step whose local error
        (by step doubling at the start) meets them, as IDA's steps do.
    t_min : float
        Start of the segment that ended at t, s: a singular instant the integrator
        stepped across lies after it (one before it was crossed already).
    node_ratio : float
        Smallest singular-value ratio wanted at a Gauss node (:data:`NODE_RATIO`, or
        :data:`FINE_NODE_RATIO` as a last resort).
    method : str
        The integrator that stopped there ("ida" or "iterative"), for messages.

    Returns
    -------
    Crossing
        ``instant`` False for a way out only (nothing to log).

    Raises
    ------
    SolverError
        With status ``dead point`` when no singular position lies ahead or the motion cannot
        continue through it.
    """
    st = Start.at(model, p, t, q, v, rule, method)
    if st.vnorm == 0.0:
        raise st.dead("the mechanism is at rest there")
    past = st.rate >= 0.0
    if past and not st.r0 < PAST_RATIO:
        raise st.dead("the motion does not approach a singular position: it cannot go on")
    if past and rule is not None:
        raise st.dead("the integrator had stepped across the instant before it failed, so "
                      "the branch rule cannot be applied there; a tighter "
                      f"{'dt' if method == 'iterative' else 'rtol'} stops it before the instant")
    plan = (plan_behind(st, rtol, atol, t_min) if past
            else plan_ahead(st, rtol, atol, node_ratio))
    try:
        tt, qq, vv, taken, ends, switched, dk = _march(st, plan, t_end, rtol, atol)
    except np.linalg.LinAlgError as e:
        raise st.dead(f"the motion cannot be continued through it ({e})") from None
    return _arrive(st, plan, tt, qq, vv, taken, ends, dk, switched, t_end, t_min, rtol)


def _march(st: Start, plan: Plan, t_end: float, rtol: float, atol: float) -> tuple:
    """The Gauss steps to the instant (a branch rule applied there) and out until the
    ratio reaches the target or turns down: (t, q, v) at the end, the steps taken, their
    ends (the start first), whether the branch was switched and the steps' stage
    accelerations' differences."""
    model, p, r0, rate, nsub = st.model, st.p, st.r0, st.rate, plan.nsub
    h, tau = plan.h, plan.tau
    # Constant steps on the way out, unless the way out (to a ratio where the integrators
    # restart reliably) would take more than 100 of them: then growing ones.
    target = (max(AFTER * r0, END_RATIO, 4.0 * r0) if plan.past
              else max(AFTER * r0, 0.2 * END_RATIO))
    if st.rule is not None:
        # a crossing the branch rule asked for may start where IDA was still doing well
        # (the samples before a position it stepped over): out to twice that ratio
        target = min(target, max(2.0 * r0, AFTER * END_RATIO))
    way_out = (target - r0) / max(abs(rate), 1e-300) + tau
    grow = 1.0 if way_out <= 100 * h else 1.1
    # never longer than the accurate step (but at most MAX_STEPS_OUT steps out)
    h_max = max(plan.h_ok, way_out / MAX_STEPS_OUT)
    qq, vv, tt, guess = st.q, st.v, st.t, st.a0
    switched = False
    r_prev, risen = 0.0, False
    taken: list[float] = []
    ends = [(st.t, st.q, st.v)]
    dk: list = []  # per step: its stage accelerations' difference (Crossing.dk)
    stage_accels: list = []
    for k in range(nsub + MAX_STEPS_OUT + 200):
        if tt + h > t_end:
            h = t_end - tt
        qq, vv, guess = gl2_step(model, p, tt, qq, vv, h, guess, accels=stage_accels)
        taken.append(h)
        tt += h
        ends.append((tt, qq, vv))
        dk.append(stage_accels[1] - stage_accels[0])
        if k == nsub - 1 and st.rule is not None:  # at the singular instant: which way
            qs, vs, _ = project(model, p, qq, vv, tt, rcond=SINGULAR_RCOND)
            others = other_branches(model, p, tt, qs, vs)
            vnew, switched = choose_branch(model, vs, others, qs, st.rule, tt)
            if switched:  # else the motion goes on undisturbed
                qq, vv = qs, vnew
                ends.append((tt, qq, vv))  # the same instant again: the new branch
                dk.append(None)
        if k >= nsub - 1:
            r_now = ratio(model, qq, tt, p)
            # out at the target, or where the conditioning is best (it turns down before
            # the target when the integrator gave up far from the position) once it has
            # risen past the instant: where the instant was predicted early (A02 with 10
            # loops at rtol 1e-12, the crossing started at a ratio of 0.047, 0.146 s ahead)
            # the ratio still falls at the predicted one, and stopping there, short of the
            # instant, read as a dead point
            risen = risen or (k > nsub - 1 and r_now > r_prev)
            if tt >= t_end or r_now >= target or (k > nsub and risen and r_now < r_prev):
                break
            r_prev = r_now
            if (k - nsub) % RECHECK == RECHECK - 1:
                # the step the local error allows here, as the conditioning recovers:
                # started a hair past the instant (the integrator had stepped across
                # it), A02 at rtol 1e-8 kept 1e-5 s steps for 1941 steps
                h_max = max(h_max, min(accurate_step(model, p, tt, qq, vv, h, guess,
                                                      rtol, atol), 0.25 * way_out))
            h = min(h * grow, max(h, h_max))
    return tt, qq, vv, taken, ends, switched, dk


def _arrive(st: Start, plan: Plan, tt: float, qq: np.ndarray, vv: np.ndarray,
            taken: list[float], ends: list, dk: list, switched: bool, t_end: float,
            t_min: float, rtol: float) -> Crossing:
    """The state after the crossing projected and checked (the motion went on: the
    constraints close, the velocities did not jump, the ratio recovered), the rank drop
    and the instant located along the Gauss steps: the :class:`Crossing`. ``dk``: the
    steps' stage accelerations' differences; ``rtol``: the run's (the steps' drift off
    the constraints is of its order)."""
    model, p, t, r0, nsub = st.model, st.p, st.t, st.r0, plan.nsub

    def failed(why: str) -> SolverError:
        # where the Gauss steps reached the "instant" the constraints had not collapsed
        # (the second-order path had: Andrews' squeezer at 1000 rad/s, 0.016 s ahead): no
        # singular position, IDA's own failure; else a dead point
        if not plan.past and nsub >= 1 and \
                ratio(model, ends[nsub][1], ends[nsub][0], p) > NO_COLLAPSE * r0:
            return st.not_singular("ahead")
        return st.dead(why)

    q1, v1, dq = project(model, p, qq, vv, tt)
    act = model.active_rows(p)
    closes = float(np.max(np.abs(model.constraints(q1, tt, p).phi[act]), initial=0.0))
    jump = float(np.max(np.abs(v1 - vv), initial=0.0)) / st.vnorm
    r1 = ratio(model, q1, tt, p)
    scale = max(float(np.max(np.abs(q1), initial=0.0)), 1.0)
    if closes > 1e-10 * scale:
        raise failed(f"beyond it the constraints cannot be satisfied (residual "
                     f"{closes:.1e}): the mechanism cannot follow its drivers through "
                     "this position")
    # the steps' own drift is no dead point: a velocity change or a position correction
    # up to the run's rtol (at least 1e-5 and 1e-6) is their error (A02 with one loop and
    # a branch rule at rtol 1e-3: positions corrected by 4.4e-6 after 72 steps, 1.3e-6 at
    # 1e-4, where it was called a dead point)
    if jump > max(1e-5, rtol) or dq > max(1e-6, rtol) * scale or (tt < t_end and r1 < r0):
        raise failed(f"the motion cannot continue through it (velocity change "
                     f"{jump:.1e} relative, position correction {dq:.1e}, singular-value "
                     f"ratio {r1:.1e} after it)")
    t_s = plan.t_s
    # counted where the Gauss steps reach the instant (the second-order path ahead is
    # off there by its error, enough to miss most of a large rank drop)
    drop = rank_drop(model, ends[nsub][1] if nsub >= 1 else st.path(plan.tau), t_s, p, r0)
    # the rows of every collapsing singular value, not of the last alone
    labels = (dependent_rows(model, st.q, t, p, tol=1.0, drop=drop)[0] if drop > 1
              else st.labels)
    if not plan.past:  # the instant along the Gauss steps, not the second-order path
        t_s = singular_instant(model, p, ends, t_s)
    elif t_s > 0.0 and not plan.leaving:  # behind: a Gauss step back twice as far
        back = max(t - 2.0 * (t - t_s), 0.0)
        try:
            qb, vb, _ = gl2_step(model, p, t, st.q, st.v, back - t, st.a0)
            t_s = singular_instant(model, p, [(back, qb, vb)] + ends, t_s)
        except np.linalg.LinAlgError:
            pass  # the extrapolated instant stands
    if plan.past and not plan.leaving and not max(t_min, 0.0) <= t_s <= t:
        # No instant behind inside the segment: the integrator did not step across one
        # (after A02's third crossing with 40 loops at rtol 1e-11 IDA failed 4e-8 s into
        # its restart, where the ratio peaks; the instant "behind" came out at 14.4 s).
        raise st.dead("the integrator failed without having stepped across a singular "
                      "position: it cannot go on")
    way_out_only = plan.past and plan.leaving
    return Crossing(t - plan.tau_back if way_out_only else t_s, tt, q1, v1, labels, drop,
                    plan.r_min, jump, switched, tuple(taken), nsub, tuple(ends),
                    instant=not way_out_only, dk=tuple(dk))
