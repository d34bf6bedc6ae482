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

1. locates the singular instant along the motion (the minimum of the smallest-to-largest
   singular value ratio of the active constraint rows, the ratio falling linearly to it);
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
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from ..core.errors import SolverError, Status
from ..equations import rank
from ..equations.kinematics import dependent_rows, rank_drop, row_names
from ..equations.model import Model
from .branches import choose_branch, other_branches
from .gauss import GL_C, accurate_step, gl2_step, project
from .instant import singular_instant

#: Gauss steps from the last good state to the singular instant.
SUBSTEPS = 6
#: Smallest singular-value ratio wanted at a Gauss node (fewer steps where it would be less).
NODE_RATIO = 5e-5
#: ... where a crossing with :data:`NODE_RATIO` failed from every start: on long chains the
#: ratio falls so slowly (A02 with 48 loops: 0.045 / s, 0.01 at its best) that keeping the
#: nodes above NODE_RATIO took one Gauss step of 0.1 s over the instant (velocities off by
#: 1e-4), and every earlier start lay 0.2-0.5 s back. Nodes nearer the instant carry more
#: of the round-off the near-singular solve amplifies (A02 with 32 loops at rtol 1e-8: the
#: crank tip 1.6e-6 m off instead of 2.6e-7), hence only as the last resort.
FINE_NODE_RATIO = 5e-6
#: ... and, after a failure just past the singular instant, at least this ratio, where
#: the integrators restart reliably.
END_RATIO = 0.03
#: Below this singular-value ratio a failure just past a singular instant is crossed too.
PAST_RATIO = 0.1
#: A failure moving away from a singular position the segment started after is only a way
#: out if the ratio back where it extrapolates to zero is below this share of the ratio at
#: the failure.
LEAVING_RATIO = 0.25
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

    @property
    def t0(self) -> float:
        """Time of the state handed over, s."""
        return self.ends[0][0]

    def start_for(self, t: float) -> int:
        """The step end a sample at t inside the crossing is stepped from: the nearer end
        of its step, never the singular instant (where the accelerations are
        undetermined; a branch switch repeats that instant, and its second entry, with
        the new velocities, serves the step after it)."""
        e = self.ends
        k = next((k for k in range(len(e) - 1) if e[k][0] <= t < e[k + 1][0]), len(e) - 2)
        k = max(k, 0)
        near_end = abs(e[k + 1][0] - t) < abs(t - e[k][0])
        at_singular = [abs(e[i][0] - self.t_singular) <= 1e-12 * max(1.0, abs(t))
                       for i in (k, k + 1)]
        if at_singular[0] or (near_end and not at_singular[1]):
            return k + 1
        return k

    def state_at(self, model: Model, p: np.ndarray, t: float
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities at t inside the crossing: one Gauss step (forwards or
        backwards) from the step end :meth:`start_for` picks, as accurate as the
        crossing's own steps, projected onto the constraints (the steps' ends are not:
        on a long way out they drift by up to 2e-7 m at rtol 1e-10)."""
        t0, q0, v0 = self.ends[self.start_for(t)]
        if t != t0:
            q0, v0, _ = gl2_step(model, p, t0, q0, v0, t - t0, model.kkt(q0, v0, t0, p)[0])
        return project(model, p, q0, v0, t)[:2]


def _ratio(model: Model, q: np.ndarray, t: float, p: np.ndarray) -> float:
    return rank.ratio(model.constraints(q, t, p).Phi_q[model.active_rows(p)])


def _ratio_rate(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                a0: np.ndarray, r0: float) -> float:
    """Rate of the singular-value ratio (1/s) from ``r0`` at (t, q) along the second-order
    path ahead, over a probe in which the fastest coordinate moves by 1e-6."""
    probe = 1e-6 / max(float(np.max(np.abs(v), initial=0.0)), 1e-300)
    return (_ratio(model, q + v * probe + 0.5 * a0 * probe * probe, t + probe, p) - r0) / probe


def _collapsed_behind(model: Model, p: np.ndarray, t: float, q_back: np.ndarray,
                      tau_back: float, r0: float) -> bool:
    """Whether the ratio at ``q_back``, where it extrapolates to zero ``tau_back`` (s)
    before t, has collapsed below :data:`LEAVING_RATIO` times ``r0``: a singular position
    behind, not a ratio that is only low (as on long chains)."""
    return _ratio(model, q_back, t - tau_back, p) < LEAVING_RATIO * r0


def leaves_singular(model: Model, p: np.ndarray, t: float, q: np.ndarray,
                    v: np.ndarray) -> bool:
    """Whether the motion at (t, q, v) moves away from a singular position just behind it
    (the singular-value ratio rising and, where it extrapolates to zero on the
    second-order path back, collapsed): where IDA's failure is the crossing's to take."""
    r0 = _ratio(model, q, t, p)
    vnorm = float(np.max(np.abs(v), initial=0.0))
    if not (0.0 < r0 < PAST_RATIO and vnorm > 0.0):
        return False
    a0 = model.kkt(q, v, t, p)[0]
    rate = _ratio_rate(model, p, t, q, v, a0, r0)
    if not rate > 0.0:
        return False
    tau = r0 / rate
    return _collapsed_behind(model, p, t, q - v * tau + 0.5 * a0 * tau * tau, tau, r0)


def _instant_ahead(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                   a0: np.ndarray, tau: float, nsub: int) -> float:
    """Time from t to the singular instant along the Gauss steps themselves, s (``tau``
    from the second-order path ahead is good to its error, too rough to end a step at the
    instant where the crossing starts far from it): ``nsub`` steps of ``tau / nsub`` and
    two beyond bracket it; their signed smallest singular value's root."""
    h = tau / nsub
    qq, vv, tt, guess = q, v, t, a0
    ends = [(t, q, v)]
    try:
        for _ in range(nsub + 2):
            qq, vv, guess = gl2_step(model, p, tt, qq, vv, h, guess)
            tt += h
            ends.append((tt, qq, vv))
    except np.linalg.LinAlgError:
        return tau
    return singular_instant(model, p, ends, t + tau) - t


def step_over(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
              t_end: float, rule: tuple[str, int] | None = None, *, rtol: float = 1e-8,
              atol: float = 1e-10, t_min: float = -math.inf,
              node_ratio: float = NODE_RATIO) -> Crossing:
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
    labels, r0 = dependent_rows(model, q, t, p, tol=1.0)
    a0 = model.kkt(q, v, t, p)[0]
    vnorm = float(np.max(np.abs(v), initial=0.0))

    def path(tau: float) -> np.ndarray:  # the motion ahead, to second order
        return q + v * tau + 0.5 * a0 * tau * tau

    def dead(why: str) -> SolverError:
        return SolverError(f"dead point at t = {t:.9g} s: the constraints of "
                           f"{row_names(labels) or 'the mechanism'} become dependent "
                           f"(singular-value ratio {r0:.1e}) and {why}",
                           status=Status.DEAD_POINT)

    if vnorm == 0.0:
        raise dead("the mechanism is at rest there")
    # the ratio falls about linearly to the singular instant: its rate gives the scale
    rate = _ratio_rate(model, p, t, q, v, a0, r0)
    past = rate >= 0.0
    leaving = False
    if past and not r0 < PAST_RATIO:
        raise dead("the motion does not approach a singular position: it cannot go on")
    if past and rule is not None:
        raise dead("the integrator had stepped across the instant before it failed, so "
                   "the branch rule cannot be applied there; a tighter rtol stops it "
                   "before the instant")
    if past:
        # the integrator stepped across the singular instant itself and failed just
        # beyond it: the instant lies behind, where the ratio extrapolates to zero; only
        # the way out is left to cross
        tau_back = r0 / max(rate, 1e-300)
        tau, r_min, t_s = 0.0, r0, t - min(tau_back, t)
        # an instant behind the segment's start (or the run's) was not stepped across
        # in it: the motion only leaves a near-singular position (a run started next to
        # one, or IDA failing again on the way out of one crossed already), if there is
        # one back there: the ratio where it extrapolates to zero must have collapsed (a
        # ratio that is only low, as on long chains, is no singular position)
        leaving = t - tau_back < max(t_min, 0.0) and _collapsed_behind(
            model, p, t, path(-tau_back), tau_back, r0)
        nsub = 0
        h = max(tau_back, 1e-9 * max(1.0, abs(t))) / 2.0
        h_ok = h = min(h, accurate_step(model, p, t, q, v, h, a0, rtol, atol))
    else:
        tau_lin = r0 / -rate
        opt = minimize_scalar(lambda s: _ratio(model, path(s), t + s, p),
                              bounds=(0.0, 3.0 * tau_lin), method="bounded",
                              options={"xatol": 1e-6 * tau_lin})
        tau = float(opt.x)
        r_min = float(opt.fun)
        if not 0.0 < tau < 2.9 * tau_lin:
            raise dead("no singular instant was found ahead")
        t_s = t + tau
        # Gauss steps of tau / nsub: the singular instant is a step end; then on until
        # the constraints are as well conditioned as where the integrator stopped, AFTER
        # times over (it stopped because they were not well conditioned enough for it).
        # More steps where the integrator stopped far from the singular instant
        # (accuracy); few where it came close, so that no Gauss node falls where the
        # accelerations are dominated by the round-off the near-singular solve amplifies
        # (the node nearest it lies 0.211 h away, where the ratio is about
        # r0 * 0.211 / nsub).
        h_ok = accurate_step(model, p, t, q, v, tau / SUBSTEPS, a0, rtol, atol)
        nsub = min(max(SUBSTEPS, math.ceil(tau / h_ok)), int(r0 * 0.211 / node_ratio))
        if rule is not None or nsub >= 2:
            # A step must end at the instant itself: a branch rule is applied there, and
            # a Gauss node must not fall next to it. tau from the second-order path was
            # 3e-4 s off on A02 with 40 loops at rtol 1e-11 (0.09 s ahead), a node then
            # came within round-off range of the instant and the velocities jumped by
            # 1.8e-5 (a dead point); along the Gauss steps themselves 8e-9.
            nsub = max(nsub, 1)
            tau = _instant_ahead(model, p, t, q, v, a0, tau, nsub)
        if nsub >= 2 or rule is not None:
            h = tau / nsub
        else:
            # The integrator came so close that even a step ending at the singular
            # instant would put a node in the round-off zone: one step over it instead,
            # long enough for both nodes to lie beyond it at a safe ratio (the
            # collocation polynomial spans the instant; the accelerations are not
            # needed there).
            nsub = 0
            h = (tau + 20.0 * node_ratio / -rate) / GL_C[0]
            h_ok = min(h_ok, h)
    # Constant steps on the way out, unless the way out (to a ratio where the integrators
    # restart reliably) would take more than 100 of them: then growing ones.
    target = max(AFTER * r0, END_RATIO, 4.0 * r0) if past else max(AFTER * r0, 0.2 * END_RATIO)
    if rule is not None:
        # a crossing the branch rule asked for may start where IDA was still doing well
        # (the samples before a position it stepped over): out to twice that ratio
        target = min(target, max(2.0 * r0, AFTER * END_RATIO))
    way_out = (target - r0) / max(abs(rate), 1e-300) + tau
    grow = 1.0 if way_out <= 100 * h else 1.1
    # never longer than the accurate step (but at most MAX_STEPS_OUT steps out)
    h_max = max(h_ok, way_out / MAX_STEPS_OUT)
    qq, vv, tt, guess = q, v, t, a0
    switched = False
    r_prev = 0.0
    taken: list[float] = []
    ends = [(t, q, v)]
    try:
        for k in range(nsub + MAX_STEPS_OUT + 200):
            if tt + h > t_end:
                h = t_end - tt
            qq, vv, guess = gl2_step(model, p, tt, qq, vv, h, guess)
            taken.append(h)
            tt += h
            ends.append((tt, qq, vv))
            if k == nsub - 1 and rule is not None:  # at the singular instant: which way
                qs, vs, _ = project(model, p, qq, vv, tt, rcond=SINGULAR_RCOND)
                others = other_branches(model, p, tt, qs, vs)
                vnew, switched = choose_branch(model, vs, others, qs, rule, tt)
                if switched:  # else the motion goes on undisturbed
                    qq, vv = qs, vnew
                    ends.append((tt, qq, vv))  # the same instant again: the new branch
            if k >= nsub - 1:
                r_now = _ratio(model, qq, tt, p)
                # out at the target, or where the conditioning is best (it turns down
                # before the target when the integrator gave up far from the position)
                if tt >= t_end or r_now >= target or (k > nsub and r_now < r_prev):
                    break
                r_prev = r_now
                if (k - nsub) % RECHECK == RECHECK - 1:
                    # the step the local error allows here, as the conditioning recovers:
                    # started a hair past the instant (the integrator had stepped across
                    # it), A02 at rtol 1e-8 kept 1e-5 s steps for 1941 steps
                    h_max = max(h_max, min(accurate_step(model, p, tt, qq, vv, h, guess,
                                                          rtol, atol), 0.25 * way_out))
                h = min(h * grow, max(h, h_max))
    except np.linalg.LinAlgError as e:
        raise dead(f"the motion cannot be continued through it ({e})") from None
    q1, v1, dq = project(model, p, qq, vv, tt)
    act = model.active_rows(p)
    closes = float(np.max(np.abs(model.constraints(q1, tt, p).phi[act]), initial=0.0))
    jump = float(np.max(np.abs(v1 - vv), initial=0.0)) / vnorm
    r1 = _ratio(model, q1, tt, p)
    scale = max(float(np.max(np.abs(q1), initial=0.0)), 1.0)
    if closes > 1e-10 * scale:
        raise dead(f"beyond it the constraints cannot be satisfied (residual {closes:.1e}): "
                   "the mechanism cannot follow its drivers through this position")
    if jump > 1e-5 or dq > 1e-6 * scale or (tt < t_end and r1 < r0):
        raise dead(f"the motion cannot continue through it (velocity change "
                   f"{jump:.1e} relative, singular-value ratio {r1:.1e} after it)")
    # counted where the Gauss steps reach the instant (the second-order path ahead is
    # off there by its error, enough to miss most of a large rank drop)
    drop = rank_drop(model, ends[nsub][1] if nsub >= 1 else path(tau), t_s, p, r0)
    if drop > 1:  # the rows of every collapsing singular value, not of the last alone
        labels = dependent_rows(model, q, t, p, tol=1.0, drop=drop)[0]
    if not past:  # the instant along the Gauss steps, not the second-order path ahead
        t_s = singular_instant(model, p, ends, t_s)
    elif t_s > 0.0 and not leaving:  # behind: one Gauss step back twice as far brackets it
        back = max(t - 2.0 * (t - t_s), 0.0)
        try:
            qb, vb, _ = gl2_step(model, p, t, q, v, back - t, a0)
            t_s = singular_instant(model, p, [(back, qb, vb)] + ends, t_s)
        except np.linalg.LinAlgError:
            pass  # the extrapolated instant stands
    if past and not leaving and not max(t_min, 0.0) <= t_s <= t:
        # No instant behind inside the segment: the integrator did not step across one
        # (after A02's third crossing with 40 loops at rtol 1e-11 IDA failed 4e-8 s into
        # its restart, where the ratio peaks; the instant "behind" came out at 14.4 s).
        raise dead("the integrator failed without having stepped across a singular "
                   "position: it cannot go on")
    return Crossing(t - tau_back if past and leaving else t_s, tt, q1, v1, labels, drop,
                    r_min, jump, switched, tuple(taken), nsub, tuple(ends),
                    instant=not (past and leaving))
