"""Tooth forces of gear pairs over a run's samples, and the bearing loads they add
(post-processing; the formulas are :func:`cmm_dae.equations.gearing.tooth`)."""

from __future__ import annotations

import numpy as np

from ..description.mechanism import GROUND
from ..equations.gearing import tooth
from ..equations.model import Model

__all__ = ["tooth_forces"]


def tooth_forces(model: Model, q: np.ndarray, pts: np.ndarray, lam: np.ndarray,
                 jforce: np.ndarray, jtorque: np.ndarray) -> np.ndarray:
    """Tooth force (n, n_gears, 2) of each gear pair on its second joint's gear (or rack),
    N, global axes; ``jforce`` and ``jtorque`` (the joints' reported forces, (n, nj, 2)
    and (n, nj)) are corrected in place for it.

    ``pts`` (n, nj, 2) are the joints' second points (an axle's centre), ``lam`` the
    multipliers of every row (model.all_rows)."""
    n = q.shape[0]
    out = np.zeros((n, len(model.mech.gears), 2))

    def angle(body: str) -> np.ndarray:
        return np.zeros(n) if body == GROUND else q[:, 3 * model.bidx[body] + 2]

    for g, name in enumerate(model.mech.gears):
        lam_g = lam[:, model.all_rows_of("gear", name)[0]]
        (fx, fy), fixes = tooth(model, name, lam_g, lambda k: (pts[:, k, 0], pts[:, k, 1]),
                                angle)
        out[:, g, 0], out[:, g, 1] = fx, fy
        for k, dfx, dfy, dm in fixes:  # the bearings carry the tooth force as well
            jforce[:, k, 0] -= dfx
            jforce[:, k, 1] -= dfy
            jtorque[:, k] -= dm
    return out
