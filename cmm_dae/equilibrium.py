"""Static-equilibrium start: parameters (or the free coordinates themselves) solved so that
the coordinates named in ``[initial] joints`` start with zero acceleration.

The paper (section 4.1) notes that the double-folded mechanism's joint D jumps at t = 0
because its spring is unloaded there, and that the jump disappears when the spring's
initial deformation comes from a static analysis: this is that analysis, for any scalar
model parameters (as many as free coordinates), by Newton's method (MINPACK hybrd) on the
accelerations of a KKT solve at the assembled initial state.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import root

from .errors import AssemblyError, CmmError, ModelError, Problem
from .mechanism import Initial, Mechanism

#: Largest acceleration residual (rad/s^2 or m/s^2) accepted as equilibrium.
EQ_TOL = 1e-9


def free_accelerations(mech: Mechanism) -> np.ndarray:
    """Accelerations of the coordinates named in ``[initial] joints`` at t = 0."""
    from .assembly import start_state
    from .equations import Model
    from .events import HybridState

    model = Model(mech)
    hs = HybridState(model)
    q, v, _ = start_state(model, hs)
    a, _, _ = model.kkt(q, v, 0.0, hs.p)
    cdd = model.joint_accelerations(q, v, a, 0.0)
    return np.array([cdd[model.jidx[k]] for k in mech.initial.joints if k not in mech.drivers])


def solve_equilibrium(mech: Mechanism) -> tuple[Mechanism, dict[str, float]]:
    """The mechanism with its ``[initial] equilibrium`` solved, and the solved values.

    Returns the mechanism unchanged (and an empty dict) when it asks for none.

    Raises
    ------
    ModelError
        A path that is not a parameter, or no equilibrium found (the residual named).
    """
    from .params import param_value, with_params

    eq = mech.initial.equilibrium
    if not eq:
        return mech, {}
    plain = Initial(mech.initial.joints, mech.initial.velocities)
    known = [k for k in mech.initial.joints if k not in mech.drivers]
    paths = [f"initial.joints.{k}" for k in known] if eq == "position" else list(eq)
    base = mech.replace(initial=plain)
    try:
        x0 = np.array([param_value(base, p) for p in paths])
    except ModelError as e:  # name the [initial] key, not a sweep's
        raise ModelError([Problem("initial", "equilibrium", str(p)) for p in e.problems],
                         mech.source) from None

    def f(x: np.ndarray) -> np.ndarray:
        return free_accelerations(with_params(base, dict(zip(paths, x, strict=True))))

    try:
        sol = root(f, x0, method="hybr", options={"xtol": 1e-14})
        res = f(sol.x)
    except (AssemblyError, CmmError, np.linalg.LinAlgError, ValueError) as e:
        # the search left the valid range (a mass through zero, a loop that opens)
        what = " ".join(str(e).split())
        raise ModelError(Problem("initial", "equilibrium", f"no static equilibrium found for "
                                 f"{', '.join(paths)}: the search reached {what}"),
                         mech.source) from None
    worst = float(np.max(np.abs(res), initial=0.0))
    if np.any(np.abs(sol.x - x0) > 1e6 * (1.0 + np.abs(x0))):
        raise ModelError(Problem("initial", "equilibrium", f"no static equilibrium found for "
                                 f"{', '.join(paths)}: the search ran off to "
                                 f"{', '.join(f'{x:.3g}' for x in sol.x)} (from "
                                 f"{', '.join(f'{x:.3g}' for x in x0)}), where every "
                                 "acceleration vanishes only in the limit"), mech.source)
    if not np.all(np.isfinite(sol.x)) or worst > EQ_TOL:
        raise ModelError(Problem("initial", "equilibrium", f"no static equilibrium found for "
                                 f"{', '.join(paths)} (acceleration residual {worst:.3g} "
                                 f"after {sol.nfev} evaluations: {sol.message})"),
                         mech.source)
    values = dict(zip(paths, map(float, sol.x), strict=True))
    return with_params(base, values), values
