"""IDA's absolute tolerances on the multipliers of the GGL residual (:mod:`cmm_dae.integrators.ida`,
and the sensitivity pass, which replays the run with them): fixed values for ordinary
forces, grown with the mechanism's force scale where its forces are large."""

from __future__ import annotations

import math

import numpy as np

from ..equations.model import Model

__all__ = ["ATOL_LAMBDA", "ATOL_LAMBDA_SINGULAR", "ATOL_MU", "ATOL_WORK", "FORCE_REF",
           "lambda_atol", "lambda_scale", "natural_step", "tolerances"]

#: Absolute tolerances on the multipliers. Both are index-2 variables of the GGL form, in
#: IDA's error test but where a contact lands (:mod:`.suppress`: there in Newton's test
#: alone). mu (zero on the exact solution) gets a huge tolerance, which takes it out of the
#: test (with 1e-8 IDA fails at t = 0).
#: lambda, the constraint forces in N or N m, must still converge in the Newton iteration,
#: since the accelerations depend on it: with 1e3 the slider-crank with a stop needed 2.8x
#: the steps and 6x the residual evaluations at rtol 1e-8 (convergence failures); 1e-2 N
#: was the most robust value over the shipped models and rtol 1e-6 .. 1e-12.
ATOL_LAMBDA = 1e-2
ATOL_MU = 1e3
#: Absolute tolerance on the works IDA integrates with the motion, as a multiple of the
#: coordinates' (J per unit of atol). Left out of the error test (a huge atol, as SUNDIALS
#: leaves quadratures out by default) the works are not checked in Newton's iteration
#: either, and where they depend nonlinearly on the state (friction from a reaction) they
#: were not converged: a block's friction loss 3.4e-5 J off at rtol 1e-10. With the
#: coordinates' own atol they steered the steps (the compiled and Python paths 5e-9 N m
#: apart on the double-folded cycle). At 100 atol: 1.8e-9 J there, 239 steps against 224.
ATOL_WORK = 100.0
#: The multipliers' absolute tolerance once a singular position has been crossed.
ATOL_LAMBDA_SINGULAR = 1e3
#: Force scale (N) up to which those tolerances stand as they are; above it they grow with
#: the mechanism's force scale (:func:`lambda_scale`). In absolute terms they are what keeps
#: the multipliers' error test loose enough for index-2 variables: the pendulum on a stop,
#: its mass and inertia scaled by 1e5 (forces of 4e5 N), failed with 1e-2 N, where the
#: relative tolerance on the multipliers took over; the shipped models start below 200 N.
FORCE_REF = 1e3


def lambda_atol(relaxed: bool, scale: float) -> float:
    """The multipliers' absolute tolerance in IDA's error test: :data:`ATOL_LAMBDA`, or
    :data:`ATOL_LAMBDA_SINGULAR` once they are ``relaxed``, times the run's force
    ``scale`` (:func:`lambda_scale`)."""
    return (ATOL_LAMBDA_SINGULAR if relaxed else ATOL_LAMBDA) * scale


def lambda_scale(model: Model, p: np.ndarray, t: float, q: np.ndarray, v: np.ndarray,
                 solved: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> float:
    """Factor on the multipliers' absolute tolerances for a run from (t, q, v).

    The mechanism's force scale is the largest of its constraint forces, applied forces
    and inertia forces (``M a``) at that state (N, or N m for moments); the factor is that
    scale over :data:`FORCE_REF`, at least 1, so that the multipliers keep the same
    relative tolerance however large the forces are. ``solved``: :meth:`Model.kkt`'s
    (a, lambda, Phi_q) at that state where the caller has it, the linear solve's (a model
    without friction from the reaction), whose applied forces are then ``M a + Phi_q^T
    lambda``.
    """
    if solved is not None and not model.reacting:
        a, lam, Phi_q = solved
        qf = model.mass * a + Phi_q.T @ lam
    else:
        p = model.fill(p, t, q, v)
        Phi_q, qf, gamma = model._kkt_parts(q, v, t, p)
        try:
            a, lam, _ = model.kkt_from(Phi_q, qf, gamma, p)
        except np.linalg.LinAlgError:  # a singular start is the policy's to report
            return 1.0
    force = max(float(np.max(np.abs(x), initial=0.0)) for x in (lam, qf, model.mass * a))
    return max(1.0, force / FORCE_REF) if math.isfinite(force) else 1.0


def natural_step(z: np.ndarray, zdd: np.ndarray, rtol: float, atol: np.ndarray | float,
                 span: float) -> float:
    """A first step (s) for IDA from a consistent start: the one whose order-1 local error
    in the coordinates ``z``, h^2 / 2 |z''| in IDA's weighted RMS norm (weights
    1 / (rtol |z| + atol)), is the tolerance; at most 1e-3 ``span``, 0 when z'' = 0.

    IDA's own first step comes from y' alone: at tight tolerances it can be so short
    (4e-15 s after a cam follower's landing at rtol 1e-12) that the index-2 Newton matrix,
    mass / h^2 beside the constraint rows, is solved with noise in the multipliers."""
    if not z.size:
        return 0.0
    wt = 1.0 / (rtol * np.abs(z) + atol)
    norm = float(np.sqrt(np.mean((zdd * wt) ** 2)))
    return min(math.sqrt(2.0 / norm), 1e-3 * span) if norm > 0.0 else 0.0


def tolerances(u, rtol: float, atol: float) -> tuple[float, float, np.ndarray]:
    """IDA's (scale, rtol, atol vector) for the unknowns ``u`` (an
    :class:`~cmm_dae.equations.unknowns.Unknowns`) at a run's ``rtol``, ``atol``.

    The works (J) are in the error test loosely (:data:`ATOL_WORK`). IDA's norm is a mean
    over all N unknowns, so nw more with small errors would loosen the test on the motion
    by up to sqrt(N / (N - nw)): every other tolerance is scaled by its inverse (the
    scale), and the test on the motion reads as it did without them."""
    scale = math.sqrt((u.N - u.nw) / u.N) if u.N else 1.0
    vec = np.concatenate([np.full(2 * u.nz, atol), np.full(u.nw, ATOL_WORK * atol),
                          np.full(u.m, ATOL_LAMBDA), np.full(u.m, ATOL_MU)])
    vec[:2 * u.nz] *= scale
    vec[u.lam.start:] *= scale
    return scale, rtol * scale, vec
