"""Static-equilibrium start: parameters (or the free coordinates themselves) solved so that
the free motion does not accelerate at the start.

The paper (section 4.1) notes that the double-folded mechanism's joint D jumps at t = 0
because its spring is unloaded there, and that the jump disappears when the spring's
initial deformation comes from a static analysis of configuration 1: this is that
analysis, for any scalar model parameters (as many as the free motion has degrees of
freedom), by Newton's method (MINPACK hybrd). The free motion is what the constraints
(drivers' rows included) leave free: the null space N of their Jacobian. The residual is
N^T a, the accelerations of a KKT solve along an orthonormal basis of it, at the assembled
start. At rest (no driver moving) a lies in that space and N^T a = 0 is exactly N^T Q = 0:
no generalized force on any free direction, the static analysis. With drivers moving, the
inertial forces they cause count too (a kinetostatic start). Either way it does not depend
on which coordinates ``[initial] joints`` names. On the preloaded double-folded mechanism
joint D then moves 3.7e-5 rad in the first 0.3 s; zeroing the named coordinate's
acceleration (the earlier rule, which adds that coordinate's convective term) left a
9.2e-4 rad swing, and N^T Q = 0 with the driver moving 8.3e-4.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import AssemblyError, CmmError, ModelError, Problem
from ..core.scipy_late import root
from ..description.mechanism import Initial, Mechanism
from ..description.params import param_value, with_params
from ..equations import rank
from ..equations.model import Model
from .start import start_state
from .state import HybridState

#: Largest acceleration residual (rad/s^2 or m/s^2) accepted as equilibrium.
EQ_TOL = 1e-9


def free_motion(mech: Mechanism) -> tuple[np.ndarray, np.ndarray]:
    """At the assembled start: the accelerations of a KKT solve (centroid coordinates)
    and an orthonormal basis of the free motion (the null space of the active constraint
    Jacobian, drivers' rows included), (nq, dof)."""

    model = Model(mech)
    hs = HybridState(model)
    q, v, _ = start_state(model, hs)
    a, _, _ = model.kkt(q, v, 0.0, hs.p)
    J = model.constraints(q, 0.0, hs.p).Phi_q[model.active_rows(hs.p)]
    return a, rank.null_space(J, model.nq)


def static_residual(mech: Mechanism, basis: np.ndarray) -> np.ndarray:
    """The accelerations of the free motion at the start, along the columns of ``basis``
    (the free motion at the start of the search): ``basis^T P a`` with P the projector on
    the free motion here, which does not depend on how its basis is chosen."""
    a, N = free_motion(mech)
    return basis.T @ (N @ (N.T @ a))


def solve_equilibrium(mech: Mechanism) -> tuple[Mechanism, dict[str, float]]:
    """The mechanism with its ``[initial] equilibrium`` solved, and the solved values.

    Returns the mechanism unchanged (and an empty dict) when it asks for none.

    Raises
    ------
    ModelError
        A path that is not a parameter, or no equilibrium found (the residual named).
    """

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
        return static_residual(with_params(base, dict(zip(paths, x, strict=True))), basis)

    try:
        basis = free_motion(base)[1]
        if basis.shape[1] != len(paths):
            raise ModelError(Problem("initial", "equilibrium", f"{len(paths)} parameter(s) "
                                     f"for a free motion of {basis.shape[1]} degree(s) of "
                                     "freedom at the start: solve as many as it has"),
                             mech.source)
        sol = root(f, x0, method="hybr", options={"xtol": 1e-14})
        res = f(sol.x)
    except ModelError:
        raise
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
