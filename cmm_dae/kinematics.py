"""Velocity- and position-level geometry of the constraints in force: projections onto
them, the impact map, and the rows that become dependent at a dead point or a lock-up."""

from __future__ import annotations

import numpy as np

from .equations import Model


# ------------------------------------------------------------------- geometry
def project_positions(model: Model, q: np.ndarray, t: float, p: np.ndarray,
                      rcond: float | None = None) -> np.ndarray:
    """Minimal-norm Newton projection of q onto the active position constraints
    (``rcond``: singular values below it relative to the largest count as zero, for a
    projection at a singular position)."""
    act = model.active_rows(p)
    for _ in range(10):
        con = model.constraints(q, t, p)
        r = con.phi[act]
        if np.max(np.abs(r), initial=0.0) < 1e-15:
            break
        # least squares: a new lock may make the rows dependent until a jam is resolved
        q = q - np.linalg.lstsq(con.Phi_q[act], r, rcond=rcond)[0]
    return q


def project_velocities(model: Model, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray,
                       rcond: float | None = None) -> np.ndarray:
    """Minimal-norm correction of v onto ``Phi_q v + Phi_t = 0`` (active rows; ``rcond``
    as in :func:`project_positions`)."""
    act = model.active_rows(p)
    con = model.constraints(q, t, p)
    J = con.Phi_q[act]
    r = J @ v + con.Phi_t[act]
    return v - np.linalg.lstsq(J, r, rcond=rcond)[0]


def impact_map(model: Model, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray,
               lock_row: int | None, target: float) -> tuple[np.ndarray, np.ndarray]:
    """Post-impact velocities and impulses.

    Solves ``[[M, Phi_q^T], [Phi_q, D]] [v+; Lambda] = [M v-; b]`` where drivers keep their
    prescribed velocity, locked joints keep 0 and the new lock row asks ``c'+ = target``.
    Returns (v+, Lambda) with Lambda the impulse of each row (N s or N m s).
    """
    con = model.constraints(q, t, p)
    b = -con.Phi_t  # drivers keep their velocity, locks keep 0
    b[model.free_rows(p) != 0.0] = 0.0
    if lock_row is not None:
        b[lock_row] = target
    A = model.kkt_matrix(con.Phi_q, p)
    sol = np.linalg.solve(A, np.concatenate([model.mass * v, b]))
    return sol[:model.nq], sol[model.nq:]


def singular_ratio(model: Model, q: np.ndarray, t: float, p: np.ndarray) -> float:
    """Smallest over largest singular value of the active constraint rows at q (0 when
    they are dependent): :func:`dependent_rows`' measure alone, without the singular
    vectors (several times cheaper on large constraint sets)."""
    act = model.active_rows(p)
    J = model.constraints(q, t, p).Phi_q[act]
    if J.size == 0:
        return 0.0
    s = np.linalg.svd(J, compute_uv=False)
    if J.shape[0] > J.shape[1]:
        return 0.0
    return float(s[-1] / s[0]) if s[0] > 0 else 0.0


def dependent_rows(model: Model, q: np.ndarray, t: float, p: np.ndarray,
                   tol: float = 1e-6) -> tuple[list[str], float]:
    """Constraint rows that (nearly) depend on each other at q: the joints, drivers and
    locks of a dead point or a lock-up. Returns (labels, smallest/largest singular value);
    no labels when the rows are independent."""
    act = model.active_rows(p)
    J = model.constraints(q, t, p).Phi_q[act]
    U, s, _ = np.linalg.svd(J)
    if J.shape[0] > J.shape[1]:
        s = np.concatenate([s, np.zeros(J.shape[0] - J.shape[1])])
    ratio = float(s[-1] / s[0]) if s.size and s[0] > 0 else 0.0
    if ratio > tol:
        return [], ratio
    w = np.abs(U[:, -1])
    labels = []
    for i in np.flatnonzero(w > 0.05 * w.max()):
        r = model.rows[act[i]]
        lab = f"{r.kind} {r.name}" if r.kind != "joint" else f"joint {r.name}"
        if lab not in labels:
            labels.append(lab)
    return labels, ratio



def redundant_rows(model: Model, q: np.ndarray, t: float, tol: float = 1e-9
                   ) -> tuple[int, ...]:
    """Joint and driver rows that depend on the others at q (a redundant constraint set:
    a parallelogram with a third crank, say): indices into ``model.all_rows``, found by a
    QR factorisation with column pivoting of the rows' Jacobian (transposed)."""
    from scipy.linalg import qr

    A = np.asarray(model.base_fn(q, t)).reshape(model.n_base, model.nq)
    if A.shape[0] == 0:
        return ()
    _, R, piv = qr(A.T, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > tol * d[0])) if d.size and d[0] > 0 else 0
    return tuple(sorted(int(i) for i in piv[rank:]))
