"""Where a crossing of a singular position starts and how it goes: the singular-value
ratio and its rate along the motion, the instant ahead (or behind, where the integrator
stepped across it), and the Gauss steps planned to it (:func:`plan_ahead`,
:func:`plan_behind`); :mod:`.step` takes those steps and checks the way out."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..core.errors import SolverError, Status
from ..core.scipy_late import minimize_scalar
from ..equations.kinematics import dependent_rows, row_names, singular_ratio
from ..equations.kkt import accelerations
from ..equations.model import Model
from .gauss import GL_C, accurate_step, gl2_step
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
#: A failure ahead of which the ratio, along the motion, stays above this share of its
#: value there is no singular position: the ratio of Andrews' squeezer is 3e-3 throughout
#: and dips a little; IDA failing on its stiff spring at rtol 1e-3 was crossed as one and
#: reported as a dead point. (Ahead of a singular position it falls to 1e-6 or less.)
NO_COLLAPSE = 0.25


#: The active constraint rows' singular-value ratio at (q, t): the kinematics' own.
ratio = singular_ratio


def ratio_rate(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                a0: np.ndarray, r0: float) -> float:
    """Rate of the singular-value ratio (1/s) from ``r0`` at (t, q) along the second-order
    path ahead, over a probe in which the fastest coordinate moves by 1e-6."""
    probe = 1e-6 / max(float(np.max(np.abs(v), initial=0.0)), 1e-300)
    return (ratio(model, q + v * probe + 0.5 * a0 * probe * probe, t + probe, p) - r0) / probe


def _collapsed_behind(model: Model, p: np.ndarray, t: float, q_back: np.ndarray,
                      tau_back: float, r0: float) -> bool:
    """Whether the ratio at ``q_back``, where it extrapolates to zero ``tau_back`` (s)
    before t, has collapsed below :data:`LEAVING_RATIO` times ``r0``: a singular position
    behind, not a ratio that is only low (as on long chains)."""
    return ratio(model, q_back, t - tau_back, p) < LEAVING_RATIO * r0


def leaves_singular(model: Model, p: np.ndarray, t: float, q: np.ndarray,
                    v: np.ndarray) -> bool:
    """Whether the motion at (t, q, v) moves away from a singular position just behind it
    (the singular-value ratio rising and, where it extrapolates to zero on the
    second-order path back, collapsed): where IDA's failure is the crossing's to take."""
    r0 = ratio(model, q, t, p)
    vnorm = float(np.max(np.abs(v), initial=0.0))
    if not (0.0 < r0 < PAST_RATIO and vnorm > 0.0):
        return False
    a0 = accelerations(model, q, v, t, p)[0]
    rate = ratio_rate(model, p, t, q, v, a0, r0)
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


@dataclass
class Start:
    """The state a crossing starts from, and what it tells of the instant ahead."""

    model: Model
    p: np.ndarray
    t: float
    q: np.ndarray
    v: np.ndarray
    rule: tuple[str, int] | None
    r0: float  #: the singular-value ratio there
    a0: np.ndarray  #: the accelerations there
    vnorm: float
    rate: float  #: the ratio's rate along the motion, 1/s (it falls about linearly)
    method: str = "ida"  #: the integrator that stopped here (its name in messages)

    @classmethod
    def at(cls, model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
           rule: tuple[str, int] | None, method: str = "ida") -> Start:
        r0 = ratio(model, q, t, p)
        a0 = accelerations(model, q, v, t, p)[0]
        vnorm = float(np.max(np.abs(v), initial=0.0))
        rate = ratio_rate(model, p, t, q, v, a0, r0) if vnorm > 0.0 else 0.0
        return cls(model, p, t, q, v, rule, r0, a0, vnorm, rate, method)

    @functools.cached_property
    def labels(self) -> list[str]:
        """The rows of the collapsing singular value's left singular vector: asked for
        where one value collapses (a crossing of several names the rows of all of them;
        the full SVD this takes cost 10 ms with 32 loops, 0.27 s with 128)."""
        return dependent_rows(self.model, self.q, self.t, self.p, tol=1.0)[0]

    def path(self, tau: float) -> np.ndarray:
        """The motion ahead (tau > 0, s) or behind, to second order."""
        return self.q + self.v * tau + 0.5 * self.a0 * tau * tau

    def not_singular(self, where: str) -> SolverError:
        """IDA's failure here, where no singular position lies ``where`` ("ahead"): the
        constraints' ratio is only low (see :data:`NO_COLLAPSE`)."""
        who, advice = (("the fixed-step algorithm", "its step; a smaller dt may pass")
                       if self.method == "iterative"
                       else ("IDA", "these tolerances; another rtol may pass"))
        return SolverError(f"{who} could not continue at t = {self.t:.9g} s and no singular "
                           f"position lies {where} (the constraints' singular-value ratio "
                           f"{self.r0:.1e} does not collapse there): the forces may be too "
                           f"stiff for {advice}", status=Status.INTEGRATOR)

    def dead(self, why: str) -> SolverError:
        return SolverError(f"dead point at t = {self.t:.9g} s: the constraints of "
                           f"{row_names(self.labels) or 'the mechanism'} become dependent "
                           f"(singular-value ratio {self.r0:.1e}) and {why}",
                           status=Status.DEAD_POINT)


@dataclass
class Plan:
    """How a crossing goes: ``nsub`` Gauss steps of ``h`` to the instant (0: one step
    over it, or none where it lies behind), then out at most ``h_ok`` a step."""

    past: bool  #: the instant lies behind (the integrator stepped across it)
    leaving: bool  #: ... and before the segment: only the way out is crossed
    tau: float  #: time to the instant ahead, s (0 behind)
    tau_back: float  #: time back to the instant behind, s (0 ahead)
    r_min: float  #: the ratio at the instant as first located
    t_s: float  #: the instant as first located, s
    nsub: int
    h: float
    h_ok: float


def plan_behind(st: Start, rtol: float, atol: float, t_min: float) -> Plan:
    """The integrator stepped across the singular instant itself and failed just beyond
    it: the instant lies behind, where the ratio extrapolates to zero; only the way out
    is left to cross."""
    t = st.t
    tau_back = st.r0 / max(st.rate, 1e-300)
    # an instant behind the segment's start (or the run's) was not stepped across in
    # it: the motion only leaves a near-singular position (a run started next to one,
    # or IDA failing again on the way out of one crossed already), if there is one back
    # there: the ratio where it extrapolates to zero must have collapsed (a ratio that
    # is only low, as on long chains, is no singular position)
    leaving = t - tau_back < max(t_min, 0.0) and _collapsed_behind(
        st.model, st.p, t, st.path(-tau_back), tau_back, st.r0)
    h = max(tau_back, 1e-9 * max(1.0, abs(t))) / 2.0
    h = min(h, accurate_step(st.model, st.p, t, st.q, st.v, h, st.a0, rtol, atol))
    return Plan(True, leaving, 0.0, tau_back, st.r0, t - min(tau_back, t), 0, h, h)


def plan_ahead(st: Start, rtol: float, atol: float, node_ratio: float) -> Plan:
    """The instant ahead along the motion, and the Gauss steps to it."""
    model, p, t, r0 = st.model, st.p, st.t, st.r0
    tau_lin = r0 / -st.rate
    # on the ratio's square, a parabola at its minimum, where the ratio is a V: Brent's
    # parabolic steps took 8-9 evaluations (an SVD each) on A02 with 1 to 32 loops at
    # rtol 1e-3 to 1e-10, against 21-25 on the V, the minimum found at least as low
    opt = minimize_scalar(lambda s: ratio(model, st.path(s), t + s, p) ** 2,
                          bounds=(0.0, 3.0 * tau_lin), method="bounded",
                          options={"xatol": 1e-6 * tau_lin})
    tau, r_min = float(opt.x), math.sqrt(float(opt.fun))
    if not 0.0 < tau < 2.9 * tau_lin:
        raise st.dead("no singular instant was found ahead")
    if r_min > NO_COLLAPSE * r0:
        raise st.not_singular("ahead")
    t_s = t + tau
    # Gauss steps of tau / nsub: the singular instant is a step end; then on until the
    # constraints are as well conditioned as where the integrator stopped, AFTER times
    # over (it stopped because they were not well conditioned enough for it). More steps
    # where the integrator stopped far from the singular instant (accuracy); few where it
    # came close, so that no Gauss node falls where the accelerations are dominated by
    # the round-off the near-singular solve amplifies (the node nearest it lies 0.211 h
    # away, where the ratio is about r0 * 0.211 / nsub).
    cap = int(r0 * 0.211 / node_ratio)
    if st.rule is None and cap < 2:
        # The integrator came so close that even a step ending at the singular instant
        # would put a node in the round-off zone: one step over it instead, long enough
        # for both nodes to lie beyond it at a safe ratio (the collocation polynomial
        # spans the instant; the accelerations are not needed there). Its length is set
        # by the nodes' distance from the instant and the steps out never shorten
        # (_march), so no accurate step is estimated: it would change no step, and its
        # step doubling took 3 of the 5 Gauss steps of a crossing of A02 with 8 loops at
        # rtol 1e-4.
        h = (tau + 20.0 * node_ratio / -st.rate) / GL_C[0]
        return Plan(False, False, tau, 0.0, r_min, t_s, 0, h, h)
    # A step must end at the instant itself: a branch rule is applied there, and a Gauss
    # node must not fall next to it. tau from the second-order path was 3e-4 s off on A02
    # with 40 loops at rtol 1e-11 (0.09 s ahead), a node then came within round-off range
    # of the instant and the velocities jumped by 1.8e-5 (a dead point); along the Gauss
    # steps themselves 8e-9.
    h_ok = accurate_step(model, p, t, st.q, st.v, tau / SUBSTEPS, st.a0, rtol, atol)
    nsub = max(min(max(SUBSTEPS, math.ceil(tau / h_ok)), cap), 1)
    tau = _instant_ahead(model, p, t, st.q, st.v, st.a0, tau, nsub)
    return Plan(False, False, tau, 0.0, r_min, t_s, nsub, tau / nsub, h_ok)
