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

from typing import Any

__all__ = ["brentq", "cubic_spline", "cumulative_simpson", "ellipj", "ellipk", "least_squares",
           "minimize", "minimize_scalar", "root", "solve_ivp"]


def cubic_spline(*args: Any, **kwargs: Any) -> Any:
    """``scipy.interpolate.CubicSpline(*args, **kwargs)``."""
    from scipy.interpolate import CubicSpline

    return CubicSpline(*args, **kwargs)


def least_squares(*args: Any, **kwargs: Any) -> Any:
    """``scipy.optimize.least_squares(*args, **kwargs)``."""
    from scipy.optimize import least_squares as f

    return f(*args, **kwargs)


def root(*args: Any, **kwargs: Any) -> Any:
    """``scipy.optimize.root(*args, **kwargs)``."""
    from scipy.optimize import root as f

    return f(*args, **kwargs)


def minimize(*args: Any, **kwargs: Any) -> Any:
    """``scipy.optimize.minimize(*args, **kwargs)``."""
    from scipy.optimize import minimize as f

    return f(*args, **kwargs)


def minimize_scalar(*args: Any, **kwargs: Any) -> Any:
    """``scipy.optimize.minimize_scalar(*args, **kwargs)``."""
    from scipy.optimize import minimize_scalar as f

    return f(*args, **kwargs)


def brentq(*args: Any, **kwargs: Any) -> Any:
    """``scipy.optimize.brentq(*args, **kwargs)``."""
    from scipy.optimize import brentq as f

    return f(*args, **kwargs)


def cumulative_simpson(*args: Any, **kwargs: Any) -> Any:
    """``scipy.integrate.cumulative_simpson(*args, **kwargs)``."""
    from scipy.integrate import cumulative_simpson as f

    return f(*args, **kwargs)


def solve_ivp(*args: Any, **kwargs: Any) -> Any:
    """``scipy.integrate.solve_ivp(*args, **kwargs)``."""
    from scipy.integrate import solve_ivp as f

    return f(*args, **kwargs)


def ellipj(*args: Any, **kwargs: Any) -> Any:
    """``scipy.special.ellipj(*args, **kwargs)``."""
    from scipy.special import ellipj as f

    return f(*args, **kwargs)


def ellipk(*args: Any, **kwargs: Any) -> Any:
    """``scipy.special.ellipk(*args, **kwargs)``."""
    from scipy.special import ellipk as f

    return f(*args, **kwargs)
