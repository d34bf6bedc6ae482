"""The KKT system of the equations of motion, in one place: ``[[M, Phi_q^T], [Phi_q, D]]
[q''; lambda] = [Q; gamma]`` (M the diagonal mass matrix, D 1 on the inactive lock rows).

* :func:`blocks` builds it for CasADi symbols (compiled event functions, the fixed-step
  algorithm's compiled step, sensitivities); :func:`matrix` for numbers.
* :class:`Solver` solves one state (a model's :meth:`~cmm_dae.equations.model.Model.kkt`):
  dense LAPACK with the configuration's constant blocks built once, or a sparse LU of
  fixed pattern for large systems (:data:`KKT_SPARSE_FROM`).
* :func:`batch` solves every sample of a run at once for post-processing: the Schur
  complement ``S lam = Phi_q M^-1 Q - gamma``, ``S = Phi_q M^-1 Phi_q^T - D`` (m x m),
  batched dense, or banded from Phi_q's nonzeros for a large mechanism (:mod:`.banded`);
  the whole matrix where a sample's complement is singular.
* :func:`impact_map` solves the same matrix for the velocities and impulses of an impact.

Friction that grows with the reaction makes the system nonlinear: the solves here are
corrected by :func:`cmm_dae.equations.reaction.solve`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.linalg.lapack import dgesv
from scipy.sparse.linalg import splu

from .banded import batch_from_nonzeros, for_model, kkt_nz_function

__all__ = ["KKT_SPARSE_FROM", "LDL_ROWS", "SINGULAR", "Solver", "SparseKKT", "Symbolic",
           "accelerations", "batch", "blocks", "impact_map", "matrix", "solve_symbolic", "symbolic"]


def blocks(mass, Phi_q, free):
    """The KKT matrix ``[[M, Phi_q^T], [Phi_q, D]]`` for CasADi expressions (``mass`` the
    diagonal of M, ``free`` that of D: 1 on inactive lock rows)."""
    return ca.blockcat([[ca.diag(mass), Phi_q.T], [Phi_q, ca.diag(free)]])


@dataclass(frozen=True)
class Symbolic:
    """The KKT system of one state for CasADi symbols, ``A z = b`` (see
    :func:`symbolic`); :meth:`unpack` gives the accelerations and multipliers from z."""

    A: Any
    b: Any
    Phi_q: Any
    Qf: Any
    mass: Any
    schur: bool

    def unpack(self, z) -> tuple[Any, Any]:
        """(q'', lambda) from a solution ``z`` of the system."""
        if self.schur:
            return (self.Qf - self.Phi_q.T @ z) / self.mass, z
        nq = self.mass.numel()
        return z[:nq], z[nq:]

    def solve(self) -> tuple[Any, Any]:
        """(q'', lambda) as expressions, by :func:`solve_symbolic`."""
        return self.unpack(solve_symbolic(self.A, self.b))


def symbolic(model: Any, q, v, t, p, schur: bool = False) -> Symbolic:
    """The KKT system at (q, v, t) in configuration ``p`` for CasADi symbols: the whole
    matrix :func:`blocks`, right-hand side ``[Q; gamma]``; or with ``schur`` (every mass
    positive) the Schur complement ``S = Phi_q M^-1 Phi_q^T - D``, right-hand side
    ``Phi_q M^-1 Q - gamma``, for the multipliers alone (m x m instead of nq + m)."""
    Phi_q, Qf, gamma = model.kkt_fn(q, v, t, p)
    free = model.free_fn(p)
    mass = model.mass_fn(p)  # (the masses are values at p's tail)
    if schur:
        PM = Phi_q @ ca.diag(1.0 / mass)
        return Symbolic(PM @ Phi_q.T - ca.diag(free), PM @ Qf - gamma, Phi_q, Qf, mass, True)
    return Symbolic(blocks(mass, Phi_q, free), ca.vertcat(Qf, gamma), Phi_q, Qf, mass,
                    False)


def solve_symbolic(A, b):
    """``A^-1 b`` in a CasADi graph, by QR: no pivoting order fixed when the graph is built
    (an LU's would be chosen for the values of the first call), and defined for every
    nonsingular A the graph meets."""
    return ca.solve(A, b, "qr")


#: Size of the KKT matrix (coordinates plus constraint rows) from which :meth:`Solver.solve`
#: factors it as a sparse matrix (SuperLU, partial pivoting as LAPACK's dense LU); below
#: it, dense LAPACK. Set from validation/speed.py's KKT comparison (see its table).
KKT_SPARSE_FROM = 160

SINGULAR = "singular KKT matrix (a dead point or redundant constraints)"


class SparseKKT:
    """``[[M, Phi_q^T], [Phi_q, D]]`` as a CSC matrix of fixed pattern: the structural
    nonzeros of Phi_q (CasADi's sparsity) and both diagonals, so that each solve only
    gathers the values (no pattern search on the dense Jacobian). The whole KKT matrix,
    not the Schur complement the outputs use (:func:`batch`): these single solves
    serve the crossings of singular positions, where the complement's condition number is
    the square of the constraint Jacobian's."""

    def __init__(self, sparsity: ca.Sparsity, nq: int):
        jr, jc = (np.asarray(x, dtype=np.int64) for x in sparsity.get_triplet())
        m = sparsity.size1()
        n = nq + m
        self.jr, self.jc = jr, jc
        d_m, d_f = np.arange(nq), nq + np.arange(m)
        rows = np.concatenate([d_m, nq + jr, jc, d_f])
        cols = np.concatenate([d_m, jc, nq + jr, d_f])
        # where each (row, col) entry lands in CSC order: built once from its positions
        order = sp.csc_matrix((np.arange(1, rows.size + 1, dtype=float), (rows, cols)),
                               shape=(n, n))
        order.sort_indices()
        self.perm = order.data.astype(np.int64) - 1
        self.indices, self.indptr, self.n = order.indices, order.indptr, n

    def solve(self, mass: np.ndarray, Phi_q: np.ndarray | None, free: np.ndarray,
              rhs: np.ndarray, vals: np.ndarray | None = None) -> np.ndarray:
        """The solution at Phi_q, or at its nonzeros ``vals`` (CSC order, CasADi's)."""
        if vals is None:
            vals = Phi_q[self.jr, self.jc]
        data = np.concatenate([mass, vals, vals, free])[self.perm]
        A = sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))
        try:
            return splu(A, permc_spec="COLAMD").solve(rhs)
        except RuntimeError as e:  # "Factor is exactly singular"
            raise np.linalg.LinAlgError(SINGULAR) from e


def matrix(mass: np.ndarray, Phi_q: np.ndarray, free: np.ndarray) -> np.ndarray:
    """The KKT matrix for numbers (dense)."""
    nq, m = mass.size, free.size
    A = np.zeros((nq + m, nq + m))
    A[:nq, :nq] = np.diag(mass)
    A[:nq, nq:] = Phi_q.T
    A[nq:, :nq] = Phi_q
    A[nq:, nq:] = np.diag(free)
    return A


class Solver:
    """Single-state KKT solves of one model: dense LAPACK on a copy of the configuration's
    constant blocks (M, D: built once per configuration), or, from
    :data:`KKT_SPARSE_FROM` on, a sparse LU on Phi_q's fixed pattern."""

    def __init__(self, model: Any, phi_q_sparsity: ca.Sparsity):
        self.model = model
        self.sparse = model.nq + model.m >= KKT_SPARSE_FROM
        self._sparsity = phi_q_sparsity
        self._sparse: SparseKKT | None = None
        self._templates: dict[bytes, np.ndarray] = {}

    def solve(self, Phi_q: np.ndarray, Qf: np.ndarray, gamma: np.ndarray, p: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """Accelerations and multipliers from the evaluated parts at parameters ``p``."""
        model = self.model
        nq = model.nq
        if self.sparse:
            return self.solve_nonzeros(None, Qf, gamma, p, Phi_q)
        rhs = np.concatenate([Qf, gamma])
        key = p[:model.n_switches].tobytes()  # the configuration, not callable loads
        tpl = self._templates.get(key)
        if tpl is None:
            tpl = self._templates[key] = matrix(model.mass, np.zeros_like(Phi_q),
                                                model.free_rows(p))
        A = tpl.copy()
        A[:nq, nq:] = Phi_q.T
        A[nq:, :nq] = Phi_q
        # LAPACK directly: half the overhead of numpy.linalg.solve on these small systems
        _, _, sol, info = dgesv(A, rhs)
        if info != 0:
            raise np.linalg.LinAlgError(SINGULAR)
        return sol[:nq], sol[nq:]

    def solve_nonzeros(self, vals: np.ndarray | None, Qf: np.ndarray, gamma: np.ndarray,
                       p: np.ndarray, Phi_q: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`solve` by the sparse LU from Phi_q's nonzeros ``vals`` (CasADi's CSC
        order), or from the dense ``Phi_q`` where ``vals`` is None."""
        model, nq = self.model, self.model.nq
        if self._sparse is None:
            self._sparse = SparseKKT(self._sparsity, nq)
        sol = self._sparse.solve(model.mass, Phi_q, model.free_rows(p),
                                 np.concatenate([Qf, gamma]), vals)
        return sol[:nq], sol[nq:]


def accelerations(model: Any, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(q'', lambda) at one state, as :meth:`~cmm_dae.equations.model.Model.kkt` gives
    them; where the KKT matrix is solved sparse (:data:`KKT_SPARSE_FROM`) from Phi_q's
    nonzeros alone, never the dense Phi_q (A02 with 64 loops: 2.9 s of a 14-s run's
    crossings, most of it evaluating and copying the dense matrix)."""
    solver = model._kkt
    if not solver.sparse or model.reacting:
        return model.kkt(q, v, t, p)[:2]
    p = model.fill(p, t, q, v)
    kkt_nz_function(model)
    vals, Qf, gamma = model.mapped("kkt_nz_fn", 1)(q, v, t, p)
    return solver.solve_nonzeros(vals, Qf, gamma, p)


def impact_map(model: Any, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray,
               lock_row: int | None, target: float) -> tuple[np.ndarray, np.ndarray]:
    """Post-impact velocities and impulses: solves ``[[M, Phi_q^T], [Phi_q, D]] [v+;
    Lambda] = [M v-; b]`` where drivers keep their
    prescribed velocity, locked joints keep 0 and the new lock row asks ``c'+ = target``.
    Returns (v+, Lambda) with Lambda the impulse of each row (N s or N m s).
    """
    con = model.constraints(q, t, p)
    b = -con.Phi_t  # drivers keep their velocity, locks keep 0
    b[model.free_rows(p) != 0.0] = 0.0
    if lock_row is not None:
        b[lock_row] = target
    A = matrix(model.mass, con.Phi_q, model.free_rows(p))
    sol = np.linalg.solve(A, np.concatenate([model.mass * v, b]))
    return sol[:model.nq], sol[model.nq:]


def batch(model: Any, t: np.ndarray, q: np.ndarray, v: np.ndarray, P: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Accelerations (n, nq) and multipliers (n, m) at every sample.

    ``P`` holds the parameter vector of each sample's configuration, shape (n, 2 K).
    Friction from the reaction (``model.reacting``) is solved with it sample by sample
    (:func:`cmm_dae.equations.reaction.solve`) where a reacting joint slips.
    """
    a, lam = _linear_batch(model, t, q, v, P)
    if model.reacting:
        slots = [model.slip_slot(j) for j in model.reacting]
        failed = []
        for i in np.flatnonzero(np.any(P[:, slots] != 0.0, axis=1)):
            try:
                a[i], lam[i], _ = model.kkt(q[i], v[i], float(t[i]), P[i])
            except np.linalg.LinAlgError:  # the run's states stand; this one's forces not
                a[i], lam[i] = np.nan, np.nan
                failed.append(float(t[i]))
        if failed:
            warnings.warn(f"friction from the reaction could not be solved at {len(failed)} "
                          f"sample(s), the first at t = {failed[0]:.9g} s: their "
                          "accelerations and forces are NaN", RuntimeWarning, stacklevel=2)
    return a, lam


#: Largest number of constraint rows whose Schur complement is factored symbolically for
#: the compiled post-processing (an LDL^T costs about m^3 / 3 instructions: with it the
#: chain of 32 loops, 194 rows, took 368 s to build; larger systems keep LAPACK's LU).
LDL_ROWS = 40


def schur_functions(model: Any) -> None:
    """``model.schur_fn`` (q, v, t, p) -> (S, r): ``S = Phi_q M^-1 Phi_q^T - D``, ``r = Phi_q
    M^-1 Q - gamma``; ``model.acc_fn`` (q, v, t, p, lambda) -> ``M^-1 (Q - Phi_q^T
    lambda)``; built once on Phi_q's sparsity; ``post_kkt_fn`` (q, v, t, p) -> (a, lambda),
    S by LDL^T (stable: S is positive definite but for -1 alone on inactive rows), in C,
    up to :data:`LDL_ROWS` rows (None above)."""
    if getattr(model, "schur_fn", None) is not None:
        return
    args = [model.sym[x] for x in ("q", "v", "t", "p")]
    system = symbolic(model, *args, schur=True)
    lam = ca.SX.sym("lam", model.m)
    model.schur_fn = ca.Function("schur", args, [ca.densify(system.A), ca.densify(system.b)])
    model.acc_fn = ca.Function("acc", [*args, lam], [ca.densify(system.unpack(lam)[0])])
    model.post_kkt_fn = None
    if model.m <= LDL_ROWS:
        sol = ca.ldl_solve(system.b, *ca.ldl(system.A, False))
        model.post_kkt_fn = ca.Function("post_kkt", args, [
            ca.densify(system.unpack(sol)[0]), ca.densify(sol)])


def _schur_batch(model: Any, t: np.ndarray, q: np.ndarray, v: np.ndarray, P: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """(a, lambda) of every sample by :func:`schur_functions`; None if one is singular."""
    n, m = t.size, model.m
    schur_functions(model)
    if model.post_kkt_fn is not None:
        # in C where compiled (5.2x on the double-folded mechanism), else on CasADi's
        # virtual machine: the same numbers on both paths; a singular S gives inf or nan
        out = model.mapped("post_kkt_fn", n)(q.T, v.T, t, P.T)
        a, lam = (np.asarray(x).reshape(-1, n).T for x in out)
        if np.all(np.isfinite(lam)):
            return a, lam
    S, r = model.mapped("schur_fn", n)(q.T, v.T, t, P.T)
    S = np.asarray(S).reshape(m, n, m).transpose(1, 0, 2)
    try:
        lam = np.linalg.solve(S, np.asarray(r).reshape(-1, n).T[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return None
    a = model.mapped("acc_fn", n)(q.T, v.T, t, P.T, lam.T)[0]
    return np.asarray(a).reshape(-1, n).T, lam


def _linear_batch(model: Any, t: np.ndarray, q: np.ndarray, v: np.ndarray, P: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`batch` without friction from the reaction."""
    n, nq, m = t.size, model.nq, model.m
    if m and np.all(model.mass > 0.0):
        # a small or not banded mechanism by the Schur complement's functions, a banded
        # one from Phi_q's nonzeros (A02, 32 loops: 2 % of the dense Jacobian's entries)
        got = _schur_batch(model, t, q, v, P) if for_model(model) is None else \
            batch_from_nonzeros(model, t, q, v, P)
        if got is not None:
            return got
    Phi_q, Qf, gamma = model.mapped("kkt_fn", n)(q.T, v.T, t, P.T)
    Phi_q = np.asarray(Phi_q).reshape(m, n, nq).transpose(1, 0, 2)
    # a mapped output is (rows, n); with n = 1 it comes back 1-D: reshape, not transpose
    Qf = np.asarray(Qf).reshape(-1, n).T
    gamma = np.asarray(gamma).reshape(-1, n).T
    free = np.asarray(model.mapped("free_fn", n)(P.T)[0]).reshape(-1, n).T
    if m == 0:  # no constraint at all (a free body): M a = Q
        return Qf / model.mass, np.zeros((n, 0))
    if np.all(model.mass > 0.0):
        # The Schur complement on the diagonal mass matrix: a = M^-1 (Q - Phi_q^T lam) with
        # (Phi_q M^-1 Phi_q^T - D) lam = Phi_q M^-1 Q - gamma, m x m instead of (nq + m)^2
        # (about 3x faster on the double-folded mechanism); an inactive lock row (zero in
        # Phi_q) reads -lam = 0. Point masses (zero inertia) need the whole KKT matrix.
        lam = _schur_multipliers(model, Phi_q, Qf, gamma, free)
        if lam is not None:
            return (Qf - np.einsum("nrk,nr->nk", Phi_q, lam)) / model.mass, lam
        # a singular sample: the whole matrix, sample by sample, below
    A = np.zeros((n, nq + m, nq + m))
    d = np.arange(nq + m)
    A[:, d[:nq], d[:nq]] = model.mass
    A[:, :nq, nq:] = Phi_q.transpose(0, 2, 1)
    A[:, nq:, :nq] = Phi_q
    A[:, d[nq:], d[nq:]] = free
    rhs = np.concatenate([Qf, gamma], axis=1)
    try:
        sol = np.linalg.solve(A, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:  # a singular sample (the state a run failed at): the
        sol = np.array([np.linalg.lstsq(Ai, bi, rcond=None)[0]  # rest still count
                        for Ai, bi in zip(A, rhs, strict=True)])
    return sol[:, :nq], sol[:, nq:]


def _schur_multipliers(model: Any, Phi_q: np.ndarray, Qf: np.ndarray, gamma: np.ndarray,
                       free: np.ndarray) -> np.ndarray | None:
    """Multipliers (n, m) from the dense Schur complement, batched; None when a sample's
    complement is singular (a banded mechanism gets here only after its banded solve of
    the same values failed: :func:`~.banded.batch_from_nonzeros`)."""
    PM = Phi_q / model.mass
    S = PM @ Phi_q.transpose(0, 2, 1)
    d = np.arange(model.m)
    S[:, d, d] -= free
    rhs = np.einsum("nrk,nk->nr", PM, Qf) - gamma
    try:
        return np.linalg.solve(S, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return None
