"""The multipliers out of IDA's local error test on the Python path: SUNDIALS'
``IDASetSuppressAlg`` on scikit-sundae's IDA, which has no binding for it.

The GGL form's multipliers are index-2 variables. In IDA's error test they were either
held to a tolerance (and after a cam follower's bounce, with a first step of 1e-12 s, their
round-off of order eps / h^2 kept the steps of the shipped valve train at 2e-12 s until the
run's budget was spent) or given a huge absolute tolerance, which took them out of Newton's
convergence test as well (and the double-folded mechanism at rtol 1e-12 then stalled at
steps of 1e-6 s in 2 of 8 nearby starts: its accelerations, which depend on the
multipliers, were not converged). ``IDASetSuppressAlg`` does what is needed: the algebraic
unknowns (IDASetId 0) stay in Newton's test and leave the error test. The compiled segment
calls it in C; here it is called on the memory of scikit-sundae's solver object.

scikit-sundae keeps that memory in a Cython attribute (``cdef void* mem``, the first field
after the object header and the type's method table). The layout is checked before use
(the type's size; then IDA's own answer for the time and step count just set), and
pyproject.toml pins the scikit-sundae releases it was read from (1.2.x): another layout
raises a clear error instead of touching memory.

Only where a unilateral contact lands and bounces (:func:`suppressed`, for both paths).
Elsewhere the multipliers stay in the error test as before: out of it, IDA's masked norm
changed its step choices enough to fall from order 4 to order 1 and stay there on other
shipped models (the slider-crank with a stop: 11,120 steps over 10 s at rtol 1e-8 against
1,080, a stall at 1e-12; taking out the works whose rates read the multipliers mended that
but trapped the double-folded mechanism at rtol 1e-10 or 1e-12, and cost the valve train's
energy audit its accuracy), and where the forces depend on the multipliers (friction from
the reaction) the curved slot's energy audit closed to 1.3e-6 J instead of 1e-6 J."""

from __future__ import annotations

import ctypes
import functools

import sksundae
from sksundae import _cy_ida

from .csegment import sundials_library

__all__ = ["start_suppressed", "suppress_algebraic", "suppressed"]

_PTR = ctypes.sizeof(ctypes.c_void_p)
#: where ``mem`` lies in the Cython object: after ob_refcnt, ob_type and __pyx_vtab
_MEM_OFFSET = 3 * _PTR
#: the Cython type's size in scikit-sundae 1.2: header, vtab, 9 pointers and an index,
#: the AuxData and four Python objects
_SIZE = 2 * _PTR + _PTR + 9 * _PTR + 8 + _PTR + 4 * _PTR


@functools.cache
def _ida() -> ctypes.CDLL:
    lib = ctypes.CDLL(str(sundials_library("ida")))
    lib.IDASetSuppressAlg.argtypes = [ctypes.c_void_p, ctypes.c_int]
    lib.IDAGetCurrentTime.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)]
    lib.IDAGetNumSteps.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_long)]
    return lib


def _memory(solver) -> int:
    """The address of IDA's memory inside scikit-sundae's solver (after ``init_step``)."""
    cy = getattr(solver, "_IDA__IDA", None)
    if not isinstance(cy, _cy_ida.IDA) or _cy_ida.IDA.__basicsize__ != _SIZE:
        raise RuntimeError(f"scikit-sundae {sksundae.__version__}: its IDA object is not "
                           "laid out as cmm_dae reads it")
    mem = ctypes.c_void_p.from_address(id(cy) + _MEM_OFFSET).value
    if not mem:
        raise RuntimeError("scikit-sundae's IDA has no memory yet (init_step first)")
    return mem


def suppress_algebraic(solver, t0: float) -> None:
    """Leave the algebraic unknowns (IDASetId 0: the multipliers) out of the local error
    test of ``solver`` (a scikit-sundae IDA on which ``init_step(t0, ...)`` was just
    called); they stay in Newton's convergence test. Checks that the memory read is
    IDA's: its current time is ``t0`` and it has taken no step."""
    mem, lib = _memory(solver), _ida()
    t, n = ctypes.c_double(), ctypes.c_long()
    if (lib.IDAGetCurrentTime(mem, ctypes.byref(t)) != 0 or t.value != t0
            or lib.IDAGetNumSteps(mem, ctypes.byref(n)) != 0 or n.value != 0):
        raise RuntimeError("scikit-sundae's IDA memory is not where cmm_dae reads it")
    if lib.IDASetSuppressAlg(mem, 1) != 0:
        raise RuntimeError("IDASetSuppressAlg failed")


def start_suppressed(solver, t0: float, y0, yp0, suppress: bool = True) -> None:
    """With ``suppress``: ``solver.init_step(t0, y0, yp0)`` (IDA's memory set up) and
    :func:`suppress_algebraic`; its next ``solve`` or ``step`` call re-initialises IDA at
    the same start and keeps the option. Without: nothing (no second initialisation)."""
    if suppress:
        solver.init_step(t0, y0, yp0)
        suppress_algebraic(solver, t0)


def suppressed(model) -> bool:
    """Whether a run of ``model`` takes the multipliers out of IDA's error test: where a
    unilateral contact lands and bounces (its restarts begin with steps of 1e-12 s) and no
    friction from the reaction makes the forces depend on them."""
    return not model.reacting and any(j.lands for j in model.joints.values())
