"""The energy audit of a Result: work in (drivers, loads) against the change of kinetic and
potential energy and everything lost (dampers, impacts, friction), sample by sample.

The works and losses are the integrator's own quadratures where it computed them (IDA
integrates them with the motion: the audit then holds to the solver's tolerance on any
output grid); elsewhere (the fixed-step method, the windows of singular-position
crossings, result files from before) they are integrated over the samples."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.scipy_late import cumulative_simpson


@dataclass(frozen=True)
class Energy:
    """Energy audit (J), each (n,): see :meth:`Result.energy`."""

    t: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    spring: np.ndarray
    driver_work: np.ndarray
    damper_dissipation: np.ndarray
    impact_losses: np.ndarray
    residual: np.ndarray
    element: np.ndarray
    load_work: np.ndarray
    friction_loss: np.ndarray


def _cumulative(t: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Cumulative integral of samples f(t), Simpson between repeated (event) times."""
    out = np.zeros(t.size)
    cuts = [0] + [k + 1 for k in range(t.size - 1) if t[k + 1] == t[k]] + [t.size]
    base = 0.0
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        if b - a >= 3:
            out[a + 1:b] = base + cumulative_simpson(f[a:b], x=t[a:b])
        elif b - a == 2:
            out[a + 1] = base + 0.5 * (f[a] + f[a + 1]) * (t[a + 1] - t[a])
        out[a] = base if a == 0 or t[a] != t[a - 1] else out[a - 1]
        base = out[b - 1]
    return out


def _integrated(t: np.ndarray, powers: list[np.ndarray], steps: np.ndarray | None
                ) -> list[np.ndarray]:
    """Cumulative works of the sampled ``powers`` (W): each sample's step from the
    integrator's quadratures ``steps`` (n, len(powers)) where finite, else over the
    samples (:func:`_cumulative`)."""
    out = []
    for k, P in enumerate(powers):
        over = _cumulative(t, P)
        if steps is None or steps.shape != (t.size, len(powers)) or t.size == 0:
            out.append(over)
            continue
        inc = np.diff(over, prepend=0.0)
        own = steps[:, k]
        inc = np.where(np.isfinite(own), own, inc)
        inc[0] = 0.0
        out.append(np.cumsum(inc))
    return out


def energy_audit(res: Any) -> Energy:
    """Energy audit along the run (J): kinetic, potential (gravity), spring energy of
    the joint springs, energy of the force elements (spring and preload), cumulative
    driver work and load work, damper dissipation (joint and element dampers) and
    impact losses, and the balance residual
    ``work - (dT + dV_g + dV_s + dV_e + dissipation + impact losses)``.

    The works and losses are IDA's quadratures, integrated with the motion, so the
    residual measures the solver alone; where the integrator did not integrate them (the
    fixed-step method, crossings of singular positions) Simpson's rule over the samples
    between events (the integrands jump there) takes over, and the residual measures the
    output spacing too.
    """
    d, m = res.data, res.layout
    mass = np.asarray(m.masses)
    T = 0.5 * np.sum(mass * d["v"] ** 2, axis=1)
    g = np.asarray(m.gravity)
    q = d["q"]
    nb, dim = len(m.bodies), g.size
    nqb = q.shape[1] // max(nb, 1)  # (3 a planar body, 12 a spatial one)
    Vg = -sum(mass[nqb * i] * (q[:, nqb * i:nqb * i + dim] @ g) for i in range(nb))
    Vs = np.zeros(res.t.size)
    for name, (k, rest) in m.springs.items():
        Vs = Vs + 0.5 * k * (res.joint(name).position - rest) ** 2
    P_diss = np.zeros(res.t.size)
    for name, c in m.dampers.items():
        P_diss = P_diss + c * res.joint(name).velocity ** 2
    Ve = np.zeros(res.t.size)
    for k, (stiff, rest, damping, preload) in enumerate(m.elements.values()):
        L, Ld = d["elem_len"][:, k], d["elem_rate"][:, k]
        Ve = Ve + 0.5 * stiff * (L - rest) ** 2 + preload * L
        P_diss = P_diss + damping * Ld**2
    P_drv = np.zeros(res.t.size)
    for name in m.drivers:
        P_drv = P_drv + res.driver(name).effort * res.joint(name).velocity
    P_ld = np.sum(d["load_power"], axis=1) if "load_power" in d else np.zeros(res.t.size)
    P_fr = -np.sum(d["friction"] * d["cd"], axis=1) if "friction" in d \
        else np.zeros(res.t.size)
    # (the order of equations.unknowns.WORKS)
    work, lw, diss, fr_loss = _integrated(res.t, [P_drv, P_ld, P_diss, P_fr],
                                          d.get("work_step"))
    lost = np.zeros(res.t.size)
    after = d.get("event_sample", np.zeros(0, int))
    seen: dict[float, int] = {}
    for n, e in enumerate(res.events):
        if n < after.size:  # each event books its loss from the sample right after it
            i = int(after[n])
        else:  # a file written before event samples were kept: the k-th event at a
            k = seen.get(e.t, 0)  # time acts from its (k+1)-th sample on
            seen[e.t] = k + 1
            i = int(np.searchsorted(res.t, e.t, side="left")) + k + 1
        lost[min(i, res.t.size):] += e.energy_lost
    E = T + Vg + Vs + Ve
    resid = work + lw - (E - E[0]) - diss - lost - fr_loss
    return Energy(res.t, T, Vg, Vs, work, diss, lost, resid, Ve, lw, fr_loss)

