"""scipy's optimizers, splines, quadrature and special functions, imported on first use.

``import cmm_dae`` had taken 0.6 s, as much as the rest of a fresh process's first run:
scipy.interpolate, scipy.optimize, scipy.integrate and scipy.special were 0.2-0.3 s of
it, and a run needs them only where a spline is built, a start is assembled from rough
guesses, a singular position is crossed, an equilibrium or a design is solved, the
energy is audited, or an IFToMM reference is computed. Each function here imports its
scipy routine when first called and passes the call on unchanged (same arguments, same
result). scipy itself, a required dependency, is imported at the top of the modules that
use scipy.linalg and scipy.sparse, so a missing scipy still fails ``import cmm_dae``."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

__all__ = ["brentq", "cubic_spline", "cumulative_simpson", "ellipj", "ellipk", "least_squares",
           "minimize", "minimize_scalar", "root", "solve_ivp"]


def _late(module: str, name: str) -> Callable[..., Any]:
    """A function that calls ``module.name`` with its arguments, importing ``module`` on
    its first call."""
    def call(*args: Any, **kwargs: Any) -> Any:
        return getattr(importlib.import_module(module), name)(*args, **kwargs)

    call.__name__ = call.__qualname__ = name
    call.__doc__ = f"``{module}.{name}(*args, **kwargs)``, imported on the first call."
    return call


cubic_spline = _late("scipy.interpolate", "CubicSpline")
least_squares = _late("scipy.optimize", "least_squares")
root = _late("scipy.optimize", "root")
minimize = _late("scipy.optimize", "minimize")
minimize_scalar = _late("scipy.optimize", "minimize_scalar")
brentq = _late("scipy.optimize", "brentq")
cumulative_simpson = _late("scipy.integrate", "cumulative_simpson")
solve_ivp = _late("scipy.integrate", "solve_ivp")
ellipj = _late("scipy.special", "ellipj")
ellipk = _late("scipy.special", "ellipk")
