"""Velocity- and position-level geometry of the constraints in force: projections onto
them, the impact map, and the rows that become dependent at a dead point or a lock-up."""

from __future__ import annotations

import functools
import weakref

import casadi as ca
import numpy as np
from scipy.linalg import qr
from scipy.linalg.lapack import dpbtrf

from . import banded, bandsvd, rank
from .build import Constraints
from .minnorm import QR_ROWS, SPARSE_FILL, SPARSE_ROWS, MinNorm, SparseRows  # noqa: F401
from .model import Model
from .unknowns import ground_pins

_STRUCTURES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def active_nonzeros(model: Model, act: np.ndarray, every: bool = False
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """The structural nonzeros (rows, columns; row-major) of Phi_q's active rows ``act``
    from its pattern, kept per model and row set (None below :data:`banded.BANDED_FROM`
    rows unless ``every``): the dense matrix's took 4.3 of 25 s on A02 with 64 loops."""
    if act.size < banded.BANDED_FROM and not every:
        return None
    per_model = _STRUCTURES.setdefault(model.shared, {})  # (a pattern: the structure's)
    key = act.tobytes()
    if key not in per_model:
        pat = model.phi_q_pattern
        colind, row = (np.asarray(x, dtype=np.int64) for x in pat.get_ccs())
        col = np.repeat(np.arange(pat.size2()), np.diff(colind))
        where = np.full(pat.size1(), -1)
        where[act] = np.arange(act.size)
        keep = where[row] >= 0
        ri, ci = where[row[keep]], col[keep]
        order = np.lexsort((ci, ri))
        per_model[key] = (ri[order], ci[order])
        # where each of them is in Phi_q's nonzeros (CSC order: model.phi_q_nz_fn)
        per_model[("csc", key)] = np.flatnonzero(keep)[order]
    return per_model[key]


def _csc_index(model: Model, act: np.ndarray) -> np.ndarray:
    """Where the active rows' nonzeros, in :func:`active_nonzeros`' order (which must have
    found them), are among Phi_q's nonzeros in ``model.phi_q_nz_fn``'s CSC order."""
    return _STRUCTURES[model.shared][("csc", act.tobytes())]


def active_values_at(model: Model, act: np.ndarray, q: np.ndarray, t: float,
                      p: np.ndarray) -> np.ndarray:
    """The active rows' Phi_q nonzeros at one state, evaluated alone (:func:`_csc_index`)."""
    return np.asarray(model.mapped("phi_q_nz_fn", 1)(q, t, p)[0]).ravel()[
        _csc_index(model, act)]


def active_constraints(model: Model, q: np.ndarray, t: float, p: np.ndarray,
                       act: np.ndarray) -> Constraints:
    """The rows ``act`` of the constraints at (q, t); their Phi_q as :class:`SparseRows`
    from its nonzeros alone where the rows are many (:func:`active_nonzeros`; A02 with 64
    loops: the dense 386 x 387 Phi_q took 5.4 of a 14-s run's crossings), else dense."""
    nz = active_nonzeros(model, act)
    if nz is None:
        con = model.constraints(q, t, p)
        return Constraints(con.phi[act], con.Phi_q[act], con.Phi_t[act])
    banded.constraints_nz_function(model)  # (built once)
    phi, vals, Phi_t = model.mapped("con_nz_fn", 1)(q, t, p)
    return Constraints(phi[act], SparseRows(vals[_csc_index(model, act)], *nz,
                                            (act.size, model.nq)), Phi_t[act])


def _newton(model: Model, q: np.ndarray, t: float, p: np.ndarray, act: np.ndarray,
            rcond: float | None) -> tuple[np.ndarray, Constraints | None]:
    """Minimum-norm Newton iterations onto the rows ``act``: q, and the constraints'
    rows there (:func:`active_constraints`; None when the iterations ran out after a last
    correction)."""
    # round-off in the constraint values grows with the coordinates' size (7e-15 m on
    # A02 with 40 loops, whose pivots reach x = 40 m): a fixed 1e-15 was never met there
    # and every projection ran all its iterations
    tol = 1e-15 * max(1.0, float(np.max(np.abs(q), initial=0.0)))
    r_prev = np.inf
    solver: MinNorm | None = None
    for _ in range(10):
        con = active_constraints(model, q, t, p, act)
        r = con.phi
        r_max = float(np.max(np.abs(r), initial=0.0))
        if r_max < tol or (r_max < 10 * tol and not r_max < r_prev):
            return q, con  # met, or no longer falling at round-off level
        # the last factorization while it still converges fast (a simplified Newton
        # step); a new one where it did not shrink the residual tenfold
        if solver is None or not r_max < 0.1 * r_prev:
            solver = MinNorm(con.Phi_q, rcond)
        r_prev = r_max
        q = q - solver.solve(r)
    return q, None


def project_state(model: Model, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray,
                  rcond: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Minimal-norm projection of (q, v) onto the active position and velocity
    constraints: Newton on the positions, then the velocities' linear correction with the
    Jacobian at the projected positions (``rcond``: singular values below it relative to
    the largest count as zero, for a projection at a singular position)."""
    q, con = _newton(model, q, t, p, model.active_rows(p), rcond)
    # a fresh factorization, not the Newton iteration's last one: next to a singular
    # position the Jacobian's pseudo-inverse is large and the last correction moves it
    # (reusing it left A02 N = 1 over 20 s at rtol 1e-10 8.1e-6 -> 1.9e-5 m off); the
    # constraints at the projected q, where Newton evaluated them last, are reused
    return q, project_velocities(model, q, v, t, p, rcond, con)


def project_positions(model: Model, q: np.ndarray, t: float, p: np.ndarray,
                      rcond: float | None = None) -> np.ndarray:
    """Minimal-norm Newton projection of q onto the active position constraints
    (``rcond`` as in :func:`project_state`)."""
    return _newton(model, q, t, p, model.active_rows(p), rcond)[0]


def project_velocities(model: Model, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray,
                       rcond: float | None = None, con: Constraints | None = None
                       ) -> np.ndarray:
    """Minimal-norm correction of v onto ``Phi_q v + Phi_t = 0`` (active rows; ``rcond``
    as in :func:`project_state`; ``con``: their :func:`active_constraints` at (q, t)
    where known)."""
    act = model.active_rows(p)
    if con is None:
        con = active_constraints(model, q, t, p, act)
    J = con.Phi_q
    return v - MinNorm(J, rcond).solve(J @ v + con.Phi_t)


def singular_ratio(model: Model, q: np.ndarray, t: float, p: np.ndarray) -> float:
    """Smallest over largest singular value of the active constraint rows at q (0 when
    they are dependent), without the singular vectors. Where the rows are many and banded
    once reordered (a long chain), from their band (:mod:`~.bandsvd`: as accurate as the
    SVD at O(rows^2 band); from their Gram matrix's band where the ratio is not small),
    else by the dense SVD."""
    act = model.active_rows(p)
    st = _svd_band(model, act) if 0 < act.size <= model.nq else None
    if st is not None:  # (Phi_q's nonzeros alone: the dense Phi_q took 5 % of a run)
        vals, band = active_values_at(model, act, q, t, p), gram_band(model, act)
        low = banded.lower_blocks(band, vals[:, None]) if band is not None else None
        r = bandsvd.ratio(st, vals, low)
        if r is not None:
            return r
    return rank.ratio(model.constraints(q, t, p).Phi_q[act])


def _svd_band(model: Model, act: np.ndarray) -> bandsvd.BandSVD | None:
    """The band structure of the active rows' Jacobian (:func:`bandsvd.structure`); None
    for a wide band (more than :data:`banded.BAND_SHARE` of the rows), see :func:`_kept`."""
    def build(rows: np.ndarray, cols: np.ndarray) -> bandsvd.BandSVD | None:
        st = bandsvd.structure(rows, cols, act.size, model.nq)
        return st if st.kl + st.ku <= 2 * banded.BAND_SHARE * act.size else None
    return _kept(model, act, "svd band", build)


def gram_band(model: Model, act: np.ndarray) -> banded.BandedSchur | None:
    """The banded structure of the active rows' Gram matrix (:func:`banded.structure` with
    unit masses); None for a wide band, see :func:`_kept`."""
    return _kept(model, act, "band", lambda rows, cols: banded.structure(rows, cols, act.size))


def _kept(model: Model, act: np.ndarray, kind: str, build):
    """``build(rows, cols)`` of the active rows' structural nonzeros, kept per model, row
    set and ``kind``; None for fewer than :data:`banded.BANDED_FROM` rows."""
    nz = active_nonzeros(model, act)
    if nz is None:
        return None
    per_model = _STRUCTURES[model.shared]  # filled by active_nonzeros
    key = (kind, act.tobytes())
    if key not in per_model:
        per_model[key] = build(*nz)
    return per_model[key]


def gram_function(model: Model) -> ca.Function:
    """``gram(q, t, p)``: the constraint Jacobian's Gram matrix ``Phi_q Phi_q^T`` (m x m)
    with 1 on the diagonal of the inactive lock rows (whose rows are zero), so that its
    determinant is that of the active rows' Gram matrix; built once per model (as
    ``model.gram_fn``, for :meth:`~cmm_dae.equations.model.Model.mapped`). The product in
    CasADi follows Phi_q's sparsity: the double-folded mechanism's stepped-over screen
    formed it in numpy from the dense Jacobians of 1000 samples."""
    fn = getattr(model, "gram_fn", None)
    if fn is None:
        sy = model.sym
        G = sy["Phi_q"] @ sy["Phi_q"].T + ca.diag(sy["free"])
        if model.theta_paths:
            G = ca.substitute(G, model.theta, ca.DM(model.theta0))
        fn = model.gram_fn = ca.Function("gram", [sy["q"], sy["t"], sy["p"]],
                                         [ca.densify(G)])
    return fn


def log_gram(model: Model, act: np.ndarray, nz: np.ndarray, scale: np.ndarray | None = None
             ) -> np.ndarray | None:
    """log det(J J^T) (``J diag(scale) J^T`` with ``scale``, per coordinate) of the active
    rows ``act`` at many states at once, from Phi_q's nonzeros ``nz`` (nonzeros in the CSC
    order of ``model.phi_q_nz_fn``, states: its mapped evaluation's layout): the Gram
    matrices in their banded structure (:func:`gram_band`), each factored by a banded
    Cholesky (LAPACK dpbtrf); -inf where one is not positive definite (singular to
    round-off). None where the structure is not banded (32 loops: a sparse LU each)."""
    band = gram_band(model, act) if act.size <= model.nq else None
    if band is None:
        return None
    n, m = nz.shape[1], band.m
    # the states' matrices as the blocks of one block-diagonal band matrix, factored by
    # one call (one call per state: 20 us each, most of it the call, on A02 with 8 loops);
    # a block that is not positive definite stops the factorization: -inf for it, and on
    # from the next
    big = banded.lower_blocks(band, nz[_csc_index(model, act)], scale)
    out = np.empty(n)
    start = 0
    while start < n:
        c, info = dpbtrf(big[:, start * m:], lower=1)
        stop = n if info == 0 else start + (info - 1) // m  # blocks factored
        out[start:stop] = 2.0 * np.log(c[0, :(stop - start) * m].reshape(-1, m)).sum(axis=1)
        if info == 0:
            break
        out[stop] = -np.inf
        start = stop + 1
    return out


def rank_drop(model: Model, q: np.ndarray, t: float, p: np.ndarray, r0: float) -> int:
    """How many singular values of the active rows' Jacobian have collapsed at q, the
    singular instant, against ``r0``, the ratio where the approach to it was seen: those
    below a tenth of ``r0`` times the largest (at least 1)."""
    return rank.collapsed(model.constraints(q, t, p).Phi_q[model.active_rows(p)], r0)


def collapsed_rows(model: Model, q: np.ndarray, t: float, p: np.ndarray, r0: float
                   ) -> tuple[int, list[str]]:
    """:func:`rank_drop` and the rows of :func:`dependent_rows` (``tol = 1``) from one SVD
    at q (each took its own: 4 and 8.7 ms with 32 loops); on a banded mechanism from the
    Gram matrix's band (:func:`~.rank.collapsed_band`: 3.2 against 7.4 ms with 32 loops
    for the dense eigenpairs below the threshold, 46 against 125 ms with 128)."""
    act = model.active_rows(p)
    dense = functools.cache(lambda: model.constraints(q, t, p).Phi_q[act])  # (on demand)
    band = gram_band(model, act) if act.size <= model.nq else None
    if band is not None:  # a long chain: the Gram matrix's largest and smallest eigenpairs
        low = banded.lower_blocks(band, active_values_at(model, act, q, t, p)[:, None])
        got = rank.collapsed_band(low, band.perm, dense, r0)
        if got is not None:
            return got[0], _row_labels(model, act, got[1], got[0])
    U, s, _ = np.linalg.svd(dense(), full_matrices=False)
    drop = rank.count_collapsed(s, r0)
    return drop, _row_labels(model, act, U, drop)


def row_names(labels: list[str], limit: int = 12) -> str:
    """The constraint rows' labels for a message: all of them up to ``limit``, else the
    first ones and how many more (A02 with 40 loops has 102 at its singular positions)."""
    if len(labels) <= limit:
        return ", ".join(labels)
    return f"{', '.join(labels[:limit - 2])} and {len(labels) - limit + 2} more"


def dependent_rows(model: Model, q: np.ndarray, t: float, p: np.ndarray,
                   tol: float = 1e-6, drop: int = 1) -> tuple[list[str], float]:
    """Constraint rows that (nearly) depend on each other at q: the joints, drivers and
    locks of a dead point or a lock-up. Returns (labels, smallest/largest singular value);
    no labels when the rows are independent. ``drop``: how many singular values collapse
    there (:func:`rank_drop`); the rows are those of all their left singular vectors (with
    32 collapsing at once, as on a chain of 32 loops, the last vector alone is any mix of
    them, and which rows it named changed with the instant's last digits)."""
    act = model.active_rows(p)
    J = model.constraints(q, t, p).Phi_q[act]
    U, s, _ = np.linalg.svd(J, full_matrices=False)
    if J.shape[0] > J.shape[1]:
        s = np.concatenate([s, np.zeros(J.shape[0] - J.shape[1])])
    ratio = float(s[-1] / s[0]) if s.size and s[0] > 0 else 0.0
    if ratio > tol:
        return [], ratio
    return _row_labels(model, act, U, drop), ratio


def _row_labels(model: Model, act: np.ndarray, U: np.ndarray, drop: int) -> list[str]:
    """The labels of the active rows ``act`` that the last ``drop`` of the left singular
    vectors ``U`` (rows x min(rows, coordinates)) weigh."""
    k = U.shape[1]
    w = np.linalg.norm(U[:, max(k - drop, 0):k], axis=1)
    labels: list[str] = []
    for i in np.flatnonzero(w > 0.05 * w.max()):
        r = model.rows[act[i]]
        lab = f"{r.kind} {r.name}" if r.kind != "joint" else f"joint {r.name}"
        if lab not in labels:
            labels.append(lab)
    return labels


def redundant_rows(model: Model, q: np.ndarray, t: float, tol: float = 1e-9
                   ) -> tuple[int, ...]:
    """Joint and driver rows that depend on the others at q (a redundant constraint set:
    a parallelogram with a third crank, say): indices into ``model.all_rows``, found by a
    QR factorisation with column pivoting of the rows' Jacobian (transposed).

    The rows of the joints that pin planar bodies to the ground are kept (they are
    independent of each other: one joint per body): IDA integrates those bodies by their
    angle, which needs both rows of the pin; so are a spatial body's own six rows. The
    dependent rows are then picked among the others,
    projected on what the pins leave free; their number is the whole set's rank deficit."""
    A = np.asarray(model.base_fn(q, t, model.params())).reshape(model.n_base, model.nq)
    if A.shape[0] == 0:
        return ()
    _, R, piv = qr(A.T, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > tol * d[0])) if d.size and d[0] > 0 else 0
    pins = set(ground_pins(model.mech).values())
    # (a spatial body's own rows are kept too: a joint's rows are the redundant ones)
    keep = [i for i, r in enumerate(model.all_rows[:model.n_base])
            if r.kind == "joint" and r.name in pins or r.kind == "body"]
    if rank == A.shape[0] or not keep or rank < len(keep):
        return tuple(sorted(int(i) for i in piv[rank:]))
    kept = set(keep)
    rest = np.array([i for i in range(A.shape[0]) if i not in kept], dtype=int)
    Qk, _ = np.linalg.qr(A[keep].T)  # an orthonormal basis of the pins' rows
    B = A[rest] - (A[rest] @ Qk) @ Qk.T
    _, _, piv_r = qr(B.T, mode="economic", pivoting=True)
    return tuple(sorted(int(i) for i in rest[piv_r[rank - len(keep):]]))
