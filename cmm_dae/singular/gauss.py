"""Two-stage Gauss-Legendre steps (order 4) of the constrained motion, with their stages'
states projected onto the constraints: the integrator that carries a run across and out of
a singular position (:mod:`cmm_dae.singular`), and whose steps the sensitivities replay
(:mod:`cmm_dae.sensitivity.crossing`)."""

from __future__ import annotations

import math

import numpy as np

from ..equations.kinematics import project_state
from ..equations.kkt import accelerations
from ..equations.model import Model

#: Gauss-Legendre, two stages (order 4): nodes and coefficients.
_S3 = math.sqrt(3.0) / 6.0
GL_C = np.array([0.5 - _S3, 0.5 + _S3])
GL_A = np.array([[0.25, 0.25 - _S3], [0.25 + _S3, 0.25]])
GL_B = np.array([0.5, 0.5])

#: Share of the tolerance a Gauss step's local error may take (the steps of a crossing
#: follow each other without an error test of their own).
SAFETY = 0.25


def gl2_step(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
             h: float, guess: np.ndarray, stages: list | None = None,
             accels: list | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One two-stage Gauss-Legendre step of q' = v, v' = a(t, q, v).

    The accelerations are taken at the stage states projected onto the constraints: off
    them, near a singular position, the KKT accelerations are so sensitive to the
    constraint violation that a plain fixed-point iteration of the stages diverges. The
    iteration stops when the stage accelerations no longer change beyond their round-off
    (which the near-singular solve amplifies to about 1e-9 of their size). ``guess``
    predicts the stage accelerations (never the acceleration at the step's start, which
    may be the singular instant itself, where it is undetermined); returns q, v and the
    last stage's acceleration (the next step's guess). ``stages``, when given, receives
    the two projected stage states (t, q, v) of the last iteration; ``accels``, when
    given, the two stage accelerations (what :func:`dense` reads the step through)."""
    def acc(tt, qq, vv):
        q1, v1, _ = project(model, p, qq, vv, tt)
        return accelerations(model, q1, v1, tt, p)[0]

    K = np.array([guess, guess])  # stage accelerations
    scale = 1.0 + float(np.max(np.abs(guess)))
    for _ in range(12):
        V = v + h * (GL_A @ K)
        Qs = q + h * (GL_A @ V)
        Kn = np.array([acc(t + GL_C[i] * h, Qs[i], V[i]) for i in range(2)])
        change = float(np.max(np.abs(Kn - K)))
        K = Kn
        if change <= 1e-8 * scale:
            break
        if not change < 1e3 * scale:
            raise np.linalg.LinAlgError("the Gauss stages diverge")
    V = v + h * (GL_A @ K)
    if accels is not None:
        accels[:] = [K[0], K[1]]
    if stages is not None:
        Qs = q + h * (GL_A @ V)
        stages[:] = [(t + GL_C[i] * h, *project(model, p, Qs[i], V[i], t + GL_C[i] * h)[:2])
                     for i in range(2)]
    return q + h * (GL_B @ V), v + h * (GL_B @ K), K[1]


def _rows(s: float, order: int) -> np.ndarray:
    """The ``order``-th derivative in s of the monomials 1, s, ..., s^5 at s."""
    j = np.arange(6)
    coef = np.ones(6)
    for k in range(order):
        coef = coef * (j - k)
    return coef * np.where(j >= order, float(s) ** np.maximum(j - order, 0), 0.0)


def _weights(known: tuple[bool, bool]) -> np.ndarray:
    """Inverse of the conditions' matrix of :func:`dense` (6 x 6): q and q' at both ends,
    q'' at each end where ``known``, else the difference of q'' at the two Gauss nodes
    (their mean adds nothing: the step's v1 - v0 is h times it, exactly for a quintic,
    whose q'' Gauss' rule integrates exactly)."""
    rows = [_rows(0.0, 0), _rows(0.0, 1), _rows(1.0, 0), _rows(1.0, 1)]
    rows += [_rows(e, 2) for e, k in zip((0.0, 1.0), known, strict=True) if k]
    if not all(known):
        rows.append(_rows(GL_C[1], 2) - _rows(GL_C[0], 2))
    return np.linalg.inv(np.array(rows))


_WEIGHTS = {known: _weights(known) for known in ((True, True), (False, True), (True, False))}


def dense(t0: float, q0: np.ndarray, v0: np.ndarray, a0: np.ndarray | None, t1: float,
          q1: np.ndarray, v1: np.ndarray, a1: np.ndarray | None, dk: np.ndarray,
          t: float) -> tuple[np.ndarray, np.ndarray]:
    """A Gauss step's state at t (s) inside it, read from its ends: the quintic in t with
    the positions q, velocities v = q' and accelerations a = q'' of both ends; at an end
    where the acceleration is undetermined (the singular instant: None), the difference
    ``dk`` of the step's two stage accelerations (K2 - K1) instead. Returns (q, v).

    Its error is O(h^6) in q and O(h^5) in v, the order of the step's own local error: on
    A02 with 1 and 8 loops at rtol 1e-6 to 1e-10 the samples inside the crossings kept
    their error against the reference to three digits, against those of a Gauss step
    from the nearer end (about ten projected KKT solves each, 37 ms a sample with 32
    loops). The values may be states (nq,) or their tangents (nq, P): the quintic is
    linear in them."""
    h = t1 - t0
    s = (t - t0) / h
    W = _WEIGHTS[(a0 is not None, a1 is not None)]
    data = [q0, h * v0, q1, h * v1] + [h * h * a for a in (a0, a1) if a is not None]
    if a0 is None or a1 is None:
        data.append(h * h * dk)
    C = np.tensordot(W, np.array(data), axes=1)  # the quintic's coefficients in s
    return (np.tensordot(_rows(s, 0), C, axes=1),
            np.tensordot(_rows(s, 1), C, axes=1) / h)


def accurate_step(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                  h: float, guess: np.ndarray, rtol: float, atol: float) -> float:
    """The longest Gauss step from (t, q, v) whose local error meets the tolerances, s.

    The error of one step of ``h`` is estimated by step doubling (two steps of h / 2 are
    16 / 15 of the way to the exact solution, the method being of order 4) in IDA's
    weighted root-mean-square norm; the step then scales with the error's fifth root,
    from a tenth to ten times ``h``; where that is cut at a tenth, estimated again from
    there (a trial step far too long says little: on a way out from 0.6 rad past A02's
    singular position the cut estimate gave the same steps at every rtol, 7.1e-10 off the
    branch's velocities at rtol 1e-12)."""
    for _ in range(6):
        try:
            q1, v1, _ = gl2_step(model, p, t, q, v, h, guess)
            qa, va, g = gl2_step(model, p, t, q, v, 0.5 * h, guess)
            q2, v2, _ = gl2_step(model, p, t + 0.5 * h, qa, va, 0.5 * h, g)
        except np.linalg.LinAlgError:
            return h
        y1, y2 = np.concatenate([q1, v1]), np.concatenate([q2, v2])
        err = 16.0 / 15.0 * float(np.sqrt(np.mean(((y2 - y1) / (rtol * np.abs(y2) + atol))
                                                  ** 2)))
        if not err > 0.0:
            return 10.0 * h
        factor = (SAFETY / err) ** 0.2
        if factor >= 0.1:
            break
        h *= 0.1
    return h * float(np.clip(factor, 0.1, 10.0))


def project(model: Model, p: np.ndarray, q: np.ndarray, v: np.ndarray, t: float,
            rcond: float | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """Minimum-norm corrections onto the constraints (the kinematics' projections); the
    largest position change. At the singular instant itself pass ``rcond``: the
    collapsing singular value then counts as zero instead of amplifying the round-off
    (its inverse took 3.6e-5 J of 31 J of kinetic energy off a branch switch)."""
    q1, v1 = project_state(model, q, v, t, p, rcond)
    return q1, v1, float(np.max(np.abs(q1 - q), initial=0.0))
