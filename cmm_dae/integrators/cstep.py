"""The paper's fixed step in C: one whole step of a configuration (the position Newton
iteration, the velocity solve, the KKT solve and the event functions at its end) compiled
into a cached library, one per structure and configuration.

It is the step :class:`~cmm_dae.integrators.iterative._CompiledStep` evaluates on
CasADi's virtual machine, changed where CasADi cannot generate C: its rootfinder's Newton
iteration is unrolled (:data:`NEWTON_STEPS` iterations, each skipped once ``max |G| <
1e-13``, the rootfinder's own test) and the linear solves are CasADi's symbolic QR
(straight-line code) instead of LAPACK's LU; and every constant is read from the
parameters' tail (:mod:`~cmm_dae.equations.lifting`), so a parameter variant loads the
build of its structure. The positions meet the same tolerance and the velocities and
accelerations solve the same linear systems, so the step agrees with the virtual
machine's to round-off (the double-folded mechanism over 10 s at dt 1e-3: positions
5e-15, the driving torque 8e-15 N m apart); where it fails (Newton did not converge, a
singular matrix: a residual not below 1e-9) the Python step takes it again and says why,
as before.
"""

from __future__ import annotations

import ctypes
import hashlib
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np

from ..equations import kkt
from ..equations.codegen import (
    Buffered,
    NotBuiltError,
    addresses,
    build_library,
    c_compiler,
    function_key,
)
from ..equations.lifting import external, lift
from ..equations.model import Model
from ..hybrid import policy as ev
from . import coordinates

__all__ = ["NEWTON_STEPS", "NEWTON_TOL", "STEP_BUDGET", "CStep", "build"]

#: Newton iterations on the positions, and their tolerance on max |G| (the rootfinder's
#: ``max_iter`` and ``abstol`` in the virtual machine's step, the Python step's too).
NEWTON_STEPS, NEWTON_TOL = 25, 1e-13
#: Most CasADi instructions of a step's SX parts compiled under ``compiled="auto"`` (a
#: build of about 3 s; the Newton iteration's QR on the dense position Jacobian grows as
#: its cube), and with ``compiled=True`` (four times as many): larger mechanisms keep the
#: virtual machine's step.
STEP_BUDGET = 12_000


_SOURCE = Path(__file__).with_name("fixedstep.c")
_loop: ctypes.CDLL | None = None


def loop_driver() -> ctypes.CDLL:
    """The C loop over fixed steps (``fixedstep.c``), built once per machine."""
    global _loop
    if _loop is None:
        key = hashlib.sha256(_SOURCE.read_bytes()).hexdigest()[:20]
        lib = ctypes.CDLL(str(build_library(f"fix_{key}", [_SOURCE])))
        P, D, n, L = ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.c_int, \
            ctypes.c_long
        x = ctypes.c_double
        lib.cmm_fixed_run.restype = n
        lib.cmm_fixed_run.argtypes = [P, P, n, n, D, x, x, L, n, x, D, D, D, D,
                                      ctypes.POINTER(L), D, D, D, n, ctypes.POINTER(n)]
        _loop = lib
    return _loop


#: Samples the C loop writes before it returns to Python (progress and Ctrl-C act then).
CHUNK = 4096


class CStep:
    """A configuration's compiled step: ``step(q, v, a, t, tn, p)`` -> (q1, v1, a1,
    residual, event values), as :class:`~cmm_dae.integrators.iterative._CompiledStep`;
    :meth:`run` takes many of them in C."""

    def __init__(self, fn: ca.Function, values: np.ndarray, lib: Path, nev: int):
        self.fn = Buffered(fn)
        self.values = values
        self._pw = np.concatenate([np.full(fn.nnz_in(5) - values.size, np.nan), values])
        self._lib = ctypes.CDLL(str(lib))  # (kept loaded while its addresses are used)
        self._f, self._w = addresses(self._lib, "cmm_step")
        self.nev = nev

    def _with_values(self, p: np.ndarray) -> np.ndarray:
        """``p`` followed by the step's constants (one array, refilled: no copy a step)."""
        self._pw[:p.size] = p
        return self._pw

    def run(self, q: np.ndarray, v: np.ndarray, a: np.ndarray, t: float, n: int,
            p: np.ndarray, dt: float, t_end: float, n_end: int, every: int, rmax: float
            ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, float, int, tuple]:
        """Fixed steps n + 1 ... in C (``fixedstep.c``) until one the caller must take
        itself (a residual not below ``rmax``, a negative event value: flag 1), ``n_end``
        or :data:`CHUNK` samples (flag 0): (flag, q, v, a, t, n, (T, Q, V) samples)."""
        lib, D = loop_driver(), ctypes.POINTER(ctypes.c_double)
        q, v, a = (np.array(x, dtype=float) for x in (q, v, a))
        tt, nn, filled = ctypes.c_double(t), ctypes.c_long(n), ctypes.c_int(0)
        nq = q.size
        T, Q, V = np.empty(CHUNK), np.empty((CHUNK, nq)), np.empty((CHUNK, nq))
        pw = self._with_values(p)
        flag = lib.cmm_fixed_run(
            self._f, self._w, nq, self.nev, pw.ctypes.data_as(D), dt, t_end, n_end, every,
            rmax, q.ctypes.data_as(D), v.ctypes.data_as(D), a.ctypes.data_as(D),
            ctypes.byref(tt), ctypes.byref(nn), T.ctypes.data_as(D), Q.ctypes.data_as(D),
            V.ctypes.data_as(D), CHUNK, ctypes.byref(filled))
        k = filled.value
        return flag, q, v, a, tt.value, nn.value, (T[:k], Q[:k], V[:k])

    def __call__(self, q, v, a, t, tn, p):
        try:
            q1, v1, a1, r, vals = self.fn(q, v, a, t, tn, self._with_values(p))
        except RuntimeError:
            return q, v, a, np.inf, None
        r = float(r[0])
        return q1, v1, a1, (r if np.isfinite(r) else np.inf), vals[1:]


def _parts(model: Model, hs: ev.HybridState, kidx: list[int], act: list[int],
           triggers: list[ev.Trigger]) -> dict[str, tuple[ca.Function, int]]:
    """The step's SX parts, each with the index of its parameters' input: ``pre`` (the
    predicted positions, the targets and rates of the step's coordinates), ``met``
    (whether the positions' residual meets the tolerance), ``newton`` (one Newton
    iteration on the positions) and ``after`` (velocities, accelerations, the residual
    and the event values at the step's end). Their linear solves are CasADi's symbolic
    QR: straight-line code."""
    nq, npar, nk = model.nq, model.n_params, len(kidx)
    schur = bool(np.all(model.mass > 0.0) and model.m > 0)

    def rows(x, idx):
        return x[idx, :] if idx else type(x)(0, x.shape[1])

    S = ca.SX.sym
    q, v, a, t, tn, p = S("q", nq), S("v", nq), S("a", nq), S("t"), S("tn"), S("p", npar)
    h = tn - t
    c, cd, cdd, _ = model.post_fn(q, v, a, t, p)
    tar, rates = S("tar", nk), S("rates", nk)
    phi, Phi_q, Phi_t, cz, c_q = model.kin_fn(q, tn, p)
    g = ca.vertcat(rows(phi, act), coordinates.residual(rows(cz, kidx), tar,
                                                        coordinates.turning(model, kidx)))
    jac = ca.vertcat(rows(Phi_q, act), rows(c_q, kidx))
    r = ca.mmax(ca.fabs(g))
    v1 = ca.solve(jac, ca.vertcat(-rows(Phi_t, act), rates))
    system = kkt.symbolic(model, q, v1, tn, p, schur=schur)
    acc, lam = system.unpack(ca.solve(system.A, system.b))
    c1, cd1 = model.cvel_fn(q, v1, p)
    vals: list = [None] * len(triggers)
    ev.event_values(hs, c1, cd1, lam, triggers, vals, where=ca.if_else)
    return {
        "pre": (ca.Function("cmm_pre", [q, v, a, t, tn, p], [
            q + v * h, rows(c, kidx) + rows(cd, kidx) * h,
            rows(cd, kidx) + rows(cdd, kidx) * h]), 5),
        "met": (ca.Function("cmm_met", [q, tn, p, tar], [r < NEWTON_TOL]), 2),
        "newton": (ca.Function("cmm_newton", [q, tn, p, tar], [q - ca.solve(jac, g)]), 2),
        "after": (ca.Function("cmm_after", [q, tn, p, tar, rates], [
            v1, acc, r, ca.vertcat(0.0, *vals)]), 2)}


def step_function(model: Model, hs: ev.HybridState, coords: list[str],
                  triggers: list[ev.Trigger], budget: int = STEP_BUDGET
                  ) -> tuple[ca.Function, np.ndarray] | None:
    """The step as one MX function of (q, v, a, t, tn, p with the constants), and the
    constants; None where its SX parts are more than ``budget`` instructions."""
    kidx = [model.jidx[n] for n in coords]
    act = [int(i) for i in model.active_rows(hs.p)]
    parts = _parts(model, hs, kidx, act, triggers)
    if sum(f.n_instructions() for f, _ in parts.values()) > budget:
        return None
    at, lifted = model.n_params, {}
    for name, (f, ip) in parts.items():  # each reads its constants from p's tail in turn
        lifted[name] = lift(f, ip, at)
        at += lifted[name].values.size
    F = {k: x.fn for k, x in lifted.items()}
    M = ca.MX.sym
    nq = model.nq
    q, v, a, t, tn = M("q", nq), M("v", nq), M("a", nq), M("t"), M("tn")
    pw = M("p", at)

    def pp(name: str) -> ca.MX:  # the front of pw a part reads
        return pw[:F[name].nnz_in(parts[name][1])]

    q0, targets, rates = F["pre"](q, v, a, t, tn, pp("pre"))
    # Newton unrolled on z = [q; met]: an iteration whose residual met the tolerance sets
    # met and leaves q, and every later one is skipped whole (short-circuiting switches
    # in the generated C)
    zk, tk, pk = M("z", nq + 1), M("tar", targets.numel()), M("p", at)
    qk = zk[:nq]
    met = F["met"](qk, tn, pk[:F["met"].nnz_in(2)], tk)
    go = ca.Function("cmm_newton_go", [zk, tn, pk, tk], [ca.if_else(
        met, ca.vertcat(qk, 1.0), ca.vertcat(F["newton"](
            qk, tn, pk[:F["newton"].nnz_in(2)], tk), 0.0), True)])
    it = ca.Function("cmm_newton_it", [zk, tn, pk, tk], [ca.if_else(
        zk[nq], zk, go(zk, tn, pk, tk), True)])
    z = ca.vertcat(q0, 0.0)
    for _ in range(NEWTON_STEPS):
        z = it(z, tn, pw, targets)
    q1 = z[:nq]
    v1, acc, r, values = F["after"](q1, tn, pp("after"), targets, rates)
    fn = ca.Function("cmm_step", [q, v, a, t, tn, pw], [q1, v1, acc, r, values])
    return fn, np.concatenate([x.values for x in lifted.values()])


def build(model: Model, hs: ev.HybridState, coords: list[str], triggers: list[ev.Trigger],
          mode: bool | str, make: bool) -> CStep | str:
    """The configuration's compiled step from the cache, or built now with ``make``; else
    why not: not built (``make`` False), cannot be (no C compiler, a failed build) or is
    too large (:data:`STEP_BUDGET`; four times that with ``mode`` True)."""
    if c_compiler() is None:
        return "no C compiler"
    budget = 4 * STEP_BUDGET if mode is True else STEP_BUDGET
    got = step_function(model, hs, coords, triggers, budget)
    if got is None:  # (a spatial mechanism's 36 x 36 symbolic solves: 119,000)
        return f"the step is over {budget} instructions, too large to compile"
    fn, values = got
    try:
        lib = build_library(function_key([fn]), None, [fn], build=make)
        loop_driver()
    except NotBuiltError:
        return "not built"
    except (OSError, subprocess.SubprocessError, RuntimeError) as e:
        return f"its build failed: {e}"  # the virtual machine's step gives the same numbers
    return CStep(external("cmm_step", str(lib)), values, lib, len(triggers))
