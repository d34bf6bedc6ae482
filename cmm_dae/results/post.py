"""From states (t, q, v) to a Result: KKT solves for accelerations, efforts and forces.

Efforts and constraint forces always come from a KKT solve at (q, v, t), batched over all
samples (one mapped CasADi call and one batched ``numpy.linalg.solve``); never from an
integrator's loosely toleranced multipliers.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import Status
from ..description.spatial import principal
from ..equations import outputs
from ..equations.codegen import map_width
from ..equations.kkt import batch as batch_kkt
from ..equations.model import Model
from ..equations.reaction import level
from .result import Configuration, Event, Result, Stats


def _min_norm_reactions(model: Model, t: np.ndarray, q: np.ndarray, lam: np.ndarray,
                        P: np.ndarray) -> np.ndarray:
    """Multipliers over every row (the dropped redundant ones included): the generalized
    force of the joint and driver rows, ``Phi_q^T lambda``, is what the equations
    determine; among the multipliers of all those rows that give it, the one of minimum
    norm (a redundant set's reactions are not determined by rigid-body mechanics).

    The kept rows' multipliers (zero on the dropped rows) are one solution; the minimum-norm
    one is it less its part in the null space of ``B^T`` (B: every base row), whose basis
    has one vector per dropped row, ``[-(B_k B_k^T)^-1 B_k B_d^T; I]`` orthonormalised: a
    Cholesky solve of the kept rows' Gram matrix a sample, where a pseudo-inverse took an
    SVD a sample (the Bennett linkage's 38 x 36: half of its run). Near a singular position,
    where that Gram matrix is ill-conditioned, the pseudo-inverse is used."""
    n, nb = t.size, model.n_base
    B = np.asarray(model.mapped("base_fn", n)(q.T, t, P.T)).reshape(nb, n, model.nq).transpose(
        1, 0, 2)
    nkeep = nb - len(model.dropped)
    keep = np.array([i for i in range(nb) if i not in model.dropped], dtype=int)
    drop = np.array(model.dropped, dtype=int)
    x = np.zeros((n, nb))
    x[:, keep] = lam[:, :nkeep]
    Bk = B[:, keep, :]
    gram = Bk @ Bk.transpose(0, 2, 1)
    try:
        L = np.linalg.cholesky(gram)
        d = np.abs(np.diagonal(L, axis1=1, axis2=2))
        if d.size and not np.min(d) > 1e-6 * np.max(d):
            raise np.linalg.LinAlgError("ill-conditioned")  # (a singular position near)
        Y = np.linalg.solve(gram, Bk @ B[:, drop, :].transpose(0, 2, 1))
    except np.linalg.LinAlgError:
        return _pinv_reactions(model, B, t, q, lam, P, nkeep)
    N = np.zeros((n, nb, drop.size))
    N[:, keep, :] = -Y
    N[:, drop, np.arange(drop.size)] = 1.0
    Qn, _ = np.linalg.qr(N)
    x -= np.einsum("nrk,nk->nr", Qn, np.einsum("nrk,nr->nk", Qn, x))
    return np.concatenate([x, lam[:, nkeep:]], axis=1)


def _pinv_reactions(model: Model, B: np.ndarray, t: np.ndarray, q: np.ndarray,
                    lam: np.ndarray, P: np.ndarray, nkeep: int) -> np.ndarray:
    """:func:`_min_norm_reactions` by a pseudo-inverse a sample (any conditioning)."""
    n = t.size
    Phi_q = np.asarray(model.mapped("phi_fn", n)(q.T, t, P.T)[1]).reshape(
        model.m, n, model.nq).transpose(1, 0, 2)
    G = np.einsum("nrk,nr->nk", Phi_q[:, :nkeep, :], lam[:, :nkeep])
    # rcond: the redundant directions are zero only to round-off; cut them, not the small
    # but real singular values near a singular position
    lam_base = np.einsum("nrk,nk->nr", np.linalg.pinv(B.transpose(0, 2, 1), rcond=1e-10), G)
    return np.concatenate([lam_base, lam[:, nkeep:]], axis=1)


#: most samples post-processed at a time (bounds the memory of the per-sample matrices)
CHUNK = 2048
#: bytes of Phi_q per chunk for a large model (its chunks are shorter)
CHUNK_BYTES = 32 * 2**20


def chunk_indices(i: int, n: int, size: int) -> tuple[int, np.ndarray]:
    """The chunk of samples from i on (of n, chunks of ``size``): how many it holds (k)
    and the indices it is evaluated at, padded with its last sample to the width the
    mapped functions are built for (:func:`~cmm_dae.equations.codegen.map_width`)."""
    k = min(size, n - i)
    width = map_width(k, size)
    return k, np.concatenate([np.arange(i, i + k), np.full(width - k, i + k - 1)])


def chunk_size(model: Model) -> int:
    """Samples post-processed at a time: :data:`CHUNK`, or fewer (a power of two, at least
    16) where a chunk's Phi_q would pass :data:`CHUNK_BYTES`."""
    fit = CHUNK_BYTES // max(8 * model.m * model.nq, 1)
    return int(min(CHUNK, max(16, 1 << max(int(fit).bit_length() - 1, 0))))


def _samples(model: Model, t: np.ndarray, q: np.ndarray, v: np.ndarray, P: np.ndarray,
             active: np.ndarray, solved: tuple | None = None) -> dict[str, np.ndarray]:
    """The per-sample series of one chunk of samples (see :func:`build_result`);
    ``solved``: their accelerations and multipliers where the run solved them already
    (NaN where it did not: then the chunk's are solved here)."""
    n = t.size
    if solved is None:
        a, lam = batch_kkt(model, t, q, v, P)
    else:  # solved here only where the run did not (each sample's solve is its own),
        # padded to a width the maps are built for (not one map per count of them)
        a, lam = solved[0].copy(), solved[1].copy()
        lack = np.flatnonzero(~(np.isfinite(a).all(axis=1) & np.isfinite(lam).all(axis=1)))
        if lack.size:
            at = np.concatenate([lack, np.full(map_width(lack.size, n) - lack.size, lack[-1])])
            got = batch_kkt(model, t[at], q[at], v[at], P[at])
            a[lack], lam[lack] = got[0][:lack.size], got[1][:lack.size]
    outputs.series_function(model)  # (model.series_fn, built on first use)
    c, cd, cdd, *extras, phi, hvel = (
        np.asarray(x).reshape(-1, n).T
        for x in model.mapped("series_fn", n)(q.T, v.T, a.T, t, P.T))
    drift_pos = np.max(np.abs(phi) * active, axis=1, initial=0.0)
    drift_vel = np.max(np.abs(hvel) * active, axis=1, initial=0.0)

    if model.dropped:  # redundant rows: the reactions shared out at minimum norm
        lam = _min_norm_reactions(model, t, q, lam, P)
    # the joints' forces and moments, the teeth's, the drivers' efforts (equations.outputs)
    outputs.function(model)  # (model.outputs_fn, built on first use)
    jforce, jtorque, gforce, effort = (
        np.asarray(x).reshape(-1, n).T
        for x in model.mapped("outputs_fn", n)(q.T, P.T, lam.T))
    nj = len(model.joint_names)
    return {"a": a, "lam": lam, "c": c, "cd": cd, "cdd": cdd,
            "jforce": jforce.reshape(n, nj, model.dim), "gforce": gforce.reshape(n, -1, 2),
            "jtorque": jtorque.reshape(n, nj, 3) if model.dim == 3 else jtorque,
            "effort": effort, "drift_pos": drift_pos, "drift_vel": drift_vel,
            "elem_len": extras[0], "elem_rate": extras[1], "elem_tension": extras[2],
            "load_value": extras[3], "load_power": extras[4]}


def build_result(model: Model, t: np.ndarray, q: np.ndarray, v: np.ndarray,
                 config: np.ndarray, configurations: list[Configuration],
                 params: list[np.ndarray], events: list[Event], stats: Stats,
                 status: Status = Status.SUCCESS, message: str = "success",
                 event_sample: np.ndarray | None = None,
                 work: np.ndarray | None = None, solved: tuple | None = None,
                 peaks: tuple | None = None) -> Result:
    """Post-process sampled states into a :class:`Result`.

    Parameters
    ----------
    t : (n,) s; q, v : (n, nq) centroid coordinates and rates; config : (n,) indices into
    ``configurations``; params : the parameter vector of each configuration;
    event_sample : (n_events,) index of the sample holding the state right after each event;
    work : (n, 4) each sample's works (J) since the sample before it as the integrator
    integrated them (drivers, loads, dampers, kinetic friction; NaN where it did not);
    solved : the accelerations (n, nq) and multipliers (n, m) the run solved already by
    the same batch (the stepped-over screen's; NaN rows where it did not); peaks : (t, q,
    v, config) of states between samples where the drivers' efforts were extreme over the
    integrator's steps (their efforts are solved as the samples' are).

    Running out of memory here, after the run, keeps the run: the Result then holds the
    sampled states alone (``t``, ``q``, ``v``, configurations, events, works), its status
    ``numerical failure`` and its message says so (:meth:`Result.save` keeps them).
    """
    n = t.size
    work = (np.asarray(work, float).reshape(n, -1) if work is not None
            else np.full((n, 4), np.nan))
    event_sample = (np.asarray(event_sample, int) if event_sample is not None
                    else np.zeros(0, int))
    try:
        data = _series(model, t, q, v, config, configurations, params, solved)
    except MemoryError as e:
        data = {"t": t, "q": q, "v": v, "config": np.asarray(config, int)}
        message = (f"out of memory while post-processing {n} samples ({type(e).__name__}"
                   f"{': ' + str(e) if str(e) else ''}): the Result holds the sampled "
                   "states only (t, q, v, events; res.save keeps them); run again with a "
                   "coarser output_dt"
                   + ("" if status == Status.SUCCESS else f" (the run: {message})"))
        status = Status.NUMERICAL
    data["event_sample"], data["work_step"] = event_sample, work
    if peaks is not None and peaks[0].size and "effort" in data and model.driver_names:
        data["peak_t"] = peaks[0]
        data["peak_effort"] = _series(model, *peaks, configurations, params)["effort"]
    return Result(_meta(model), data, configurations, events, stats, status, message)


def _series(model: Model, t: np.ndarray, q: np.ndarray, v: np.ndarray, config: np.ndarray,
            configurations: list[Configuration], params: list[np.ndarray],
            solved: tuple | None = None) -> dict[str, np.ndarray]:
    """Every per-sample series of a Result (see :func:`build_result`)."""
    n = t.size
    P = np.array([params[c] for c in config]).reshape(n, -1)
    if model.callables:  # the callable loads' values at each sample
        P = np.array([model.fill(P[i], t[i], q[i], v[i]) for i in range(n)]).reshape(n, -1)
    free = np.array([model.free_rows(p) for p in params]).reshape(len(params), model.m)
    active = (free[config] == 0.0) if n else np.zeros((0, model.m), bool)
    # Sample by sample in chunks of CHUNK: the per-sample matrices (Phi_q, the Schur
    # complements) of a long run would otherwise take many times the Result's own size.
    size = chunk_size(model)

    def chunk(i: int) -> dict[str, np.ndarray]:
        k, idx = chunk_indices(i, n, size)
        out = _samples(model, t[idx], q[idx], v[idx], P[idx], active[idx],
                       None if solved is None else (solved[0][idx], solved[1][idx]))
        return {key: val[:k] for key, val in out.items()}

    ser: dict[str, np.ndarray] = {}
    for i in range(0, n, size):  # filled in place: no second copy of the series
        for key, val in chunk(i).items():
            if key not in ser:
                ser[key] = np.empty((n, *val.shape[1:]), dtype=val.dtype)
            ser[key][i:i + val.shape[0]] = val
    if not n:
        nj, ne, nld = (len(model.joint_names), len(model.element_names),
                       len(model.load_names))
        ser = {"a": np.zeros((0, model.nq)), "lam": np.zeros((0, len(model.all_rows))),
               **{k: np.zeros((0, len(model.jidx))) for k in ("c", "cd", "cdd")},
               "jforce": np.zeros((0, nj, model.dim)),
               "jtorque": np.zeros((0, nj) + (3,) * (model.dim == 3)),
               "gforce": np.zeros((0, len(model.mech.gears), 2)),
               "effort": np.zeros((0, len(model.driver_names))),
               "drift_pos": np.zeros(0), "drift_vel": np.zeros(0),
               **{k: np.zeros((0, ne)) for k in ("elem_len", "elem_rate", "elem_tension")},
               **{k: np.zeros((0, nld)) for k in ("load_value", "load_power")}}
    lam = ser["lam"]
    nj = len(model.joint_names)
    # Friction each joint carries (along +c, N or N m): the kinetic force while slipping,
    # the lock's force while stuck, and on a stop the part the stop could not give (a pull).
    friction = np.zeros((n, len(model.jidx)))  # (a contact's slide in its own column)
    # the multipliers of the rows in the equations (lam holds every row's once redundant
    # ones are shared out): the reactions friction grows with
    kept = lam[:, [i for i in range(len(model.all_rows)) if i not in model.dropped]].T
    for name in model.frictional:
        k = model.jidx[name]
        fk = level(model, name, kept, "kinetic") if n else 0.0
        s = P[:, model.slip_slot(name)] if n else np.zeros(0)
        row = model.n_base + model.locks.index(name)
        lock = -lam[:, row] if n else np.zeros(0)  # the lock row's force along +c
        side_of = np.array([dict(zip(c.locked, c.sides, strict=True)).get(name, "")
                            for c in configurations])  # per configuration, once
        sides = side_of[np.asarray(config, int)]
        stuck = sides == "stick"
        pull = ((sides == "lower") & (lock < 0)) | ((sides == "upper") & (lock > 0))
        friction[:, k] = np.where(s != 0, -fk * s, np.where(stuck | pull, lock, 0.0))

    data = {"t": t, "q": q, "v": v, "a": ser["a"], "lam": lam,
            "config": np.asarray(config, int), "c": ser["c"], "cd": ser["cd"],
            "cdd": ser["cdd"], "jforce": ser["jforce"], "jtorque": ser["jtorque"],
            "gforce": ser["gforce"],
            "effort": ser["effort"], "drift_pos": ser["drift_pos"], "drift_vel": ser["drift_vel"],
            "friction": friction,
            **{k: ser[k] for k in ("elem_len", "elem_rate", "elem_tension", "load_value",
                                   "load_power")}}
    return data


def _meta(model: Model) -> dict:
    """What a Result keeps of the mechanism (names, masses, geometry for drawings)."""
    mech = model.mech
    return {
        "mechanism": mech.name,
        "source": mech.source,
        "bodies": model.body_names,
        "centroids": [list(b.centroid) for b in mech.bodies.values()],
        "masses": model.mass.tolist(),
        "space": mech.space,
        # a spatial body's principal axes in its frame (rows of the 3 x 3 matrix's columns)
        "principal": [principal(b.inertia)[0].T.reshape(-1).tolist()
                      for b in mech.bodies.values()] if mech.spatial else [],
        "joints": model.joint_names,
        "joint_types": [j.type for j in mech.joints.values()],
        "drivers": model.driver_names,
        "rows": [f"{r.kind} {r.name}" for r in model.all_rows],
        # rows left out of the equations as redundant; their reactions (and those of the
        # rows they depend on) are the minimum-norm solution
        "redundant": [f"{model.all_rows[i].kind} {model.all_rows[i].name}"
                      for i in model.dropped],
        "gravity": list(mech.gravity),
        "springs": {n: [j.spring.stiffness, j.spring.rest] for n, j in mech.joints.items()
                    if j.spring is not None},
        "dampers": {n: j.damper.damping for n, j in mech.joints.items() if j.damper is not None},
        "metamorphic": mech.limited_joints,
        "elements": {n: [e.stiffness, e.rest, e.damping, e.preload]
                     for n, e in mech.elements.items()},
        "loads": model.load_names,
        # gear pairs by name: their joints and ratio (drawings)
        "gears": {n: [g.first, g.second, g.ratio] for n, g in mech.gears.items()},
        "frictional": [model.slides.get(n, n) for n in model.frictional],
        # unilateral contacts with friction: the column of their slide's coordinate
        "slides": {k: model.jidx[s] for s, k in model.slides.items()},
        "body_points": {n: {k: list(v) for k, v in b.points.items()}
                        for n, b in mech.bodies.items()},
        "ground": {k: list(v) for k, v in mech.ground.items()},
        "connects": {n: [j.first, j.second] for n, j in mech.joints.items()},
        # for drawings: guides of prismatic joints and the stops of metamorphic joints
        "axes": {n: list(j.axis) for n, j in mech.joints.items()
                 if j.type == "prismatic" and not mech.spatial},
        "limits": {n: [j.stops.lower, j.stops.upper] for n, j in mech.joints.items()
                   if j.stops is not None and not j.lands},
        # and the curves of contact joints, in their first body's frame
        "curves": {n: {"kind": j.curve.kind, "radius": j.curve.radius,
                       "direction": list(j.curve.direction), "side": j.side,
                       "unilateral": j.unilateral, "closed": j.curve.closed,
                       "points": [list(x) for x in j.curve.points]}
                   for n, j in mech.joints.items() if j.type == "contact"},
    }
