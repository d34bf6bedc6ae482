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

import numpy as np

from .csegment import sundials_library

__all__ = ["Interpolant", "TrapCheck", "start_suppressed", "suppress_algebraic", "suppressed"]

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
    lib.IDAGetDky.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_int, ctypes.c_void_p]
    lib.IDAGetNumErrTestFails.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_long)]
    lib.IDAGetLastOrder.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)]
    return lib


#: steps over which IDA's order-1 trap is judged (as segment.c's TRAP_WINDOW)
TRAP_WINDOW = 500


class TrapCheck:
    """IDA stuck at order 1 with an error-test failure at nearly every step (at least 4/5
    of :data:`TRAP_WINDOW` steps), as the compiled segment judges it: round-off in the
    error estimate of a slow velocity beside fast ones keeps the higher orders looking
    worse (the slider-crank with a stop at rtol 1e-12: 300,081 failures in 301,821 steps,
    h doubling and halving about 1e-6 s)."""

    def __init__(self, solver):
        self.mem, self.lib = _memory(solver), _ida()
        self.nst = self.nef = 0

    def steps(self) -> int:
        """IDA's own count of its steps in the segment (as the compiled segment reports
        it: a root return or the stop time is no step of its own)."""
        n = ctypes.c_long()
        self.lib.IDAGetNumSteps(self.mem, ctypes.byref(n))
        return n.value

    def __call__(self, nst: int, trapped=lambda: None) -> bool:
        """Whether IDA, now at its step ``nst`` of the segment (:meth:`steps`), is
        trapped (then ``trapped()`` is told)."""
        if nst - self.nst < TRAP_WINDOW:
            return False
        nef, k = ctypes.c_long(), ctypes.c_int()
        self.lib.IDAGetNumErrTestFails(self.mem, ctypes.byref(nef))
        self.lib.IDAGetLastOrder(self.mem, ctypes.byref(k))
        stuck = k.value == 1 and nef.value - self.nef >= TRAP_WINDOW * 4 // 5
        self.nst, self.nef = nst, nef.value
        if stuck:
            trapped()
        return stuck


@functools.cache
def _vectors() -> tuple[ctypes.CDLL, ctypes.c_void_p]:
    """SUNDIALS' serial vectors and a context of cmm_dae's own for the vectors it wraps
    (SUNDIALS 7 as scikit-sundae builds it: 32-bit indices, no MPI)."""
    core = ctypes.CDLL(str(sundials_library("core")))
    nvec = ctypes.CDLL(str(sundials_library("nvecserial")))
    ctx = ctypes.c_void_p()
    if core.SUNContext_Create(0, ctypes.byref(ctx)) != 0:
        raise RuntimeError("SUNContext_Create failed")
    nvec.N_VMake_Serial.restype = ctypes.c_void_p
    nvec.N_VMake_Serial.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
    nvec.N_VDestroy.argtypes = [ctypes.c_void_p]
    return nvec, ctx


class Interpolant:
    """IDA's own interpolant of y over its last step (``IDAGetDky``), as the compiled
    segment reads its output times, for a scikit-sundae solver stepping on its own: the
    output times then add no root checks of their own (IDA looks for roots at an output
    time as at a step), so the events do not depend on the grid."""

    def __init__(self, solver, n: int):
        self.mem, self.lib = _memory(solver), _ida()
        nvec, ctx = _vectors()
        self.buf = np.empty(n)
        self.vec = nvec.N_VMake_Serial(n, self.buf.ctypes.data, ctx)
        if not self.vec:
            raise MemoryError("N_VMake_Serial failed")
        self._free = nvec.N_VDestroy

    def __call__(self, t: float, k: int = 0) -> np.ndarray:
        """y at t (s), within IDA's last step (k = 1: its derivative)."""
        if self.lib.IDAGetDky(self.mem, t, k, self.vec) != 0:
            raise RuntimeError(f"IDAGetDky failed at t = {t!r} s")
        return self.buf.copy()

    def __del__(self) -> None:
        if getattr(self, "vec", None):
            self._free(self.vec)


def _memory(solver) -> int:
    """The address of IDA's memory inside scikit-sundae's solver (after ``init_step``)."""
    import sksundae
    from sksundae import _cy_ida

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
