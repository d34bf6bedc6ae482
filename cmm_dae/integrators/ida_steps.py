"""IDA's stepping helpers for :mod:`.ida`: output grids, SUNDIALS' messages to the logger,
IDA's own steps kept in lists, the limits that tell a crawl or a stall, and the message of
a failure."""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import io
import logging
import math
import os
import re
import sys
import tempfile
from types import SimpleNamespace

import numpy as np

from ..core.errors import Status
from ..core.memo import recent
from ..equations.kinematics import project_state, row_names, singular_ratio
from ..equations.model import Model
from ..hybrid import policy as ev
from .contract import RunOptions
from .extremes import Tracker
from .suppress import Interpolant, TrapCheck
from .tolerances import lambda_scale

__all__ = ["CRAWL_STEP", "FALLING_RATIO", "IN_PLACE_STEPS", "OUTGROWN", "ROUNDOFF_ATOL",
           "SLOW_STEPS", "SPARSE_FILL", "SPARSE_FROM", "failure", "ida_class", "quiet_sundials",
           "segment_start", "segment_times", "sparse_solver"]

#: A failure where the constraints' singular-value ratio is below this and falling along
#: the motion is handed to the singular-position crossing (which says "dead point" if it
#: finds no singular instant ahead): at rtol 1e-12 IDA gave up on A02 at ratios up to
#: 0.052, 0.05 s before the instant.
FALLING_RATIO = 0.1


def ida_class() -> type:
    """scikit-sundae's IDA, imported where a Python-path solver is made (the compiled
    segment calls SUNDIALS itself: its runs never import scikit-sundae, nor the
    scipy.optimize that pulls in: 0.2 s of a fresh process)."""
    from sksundae.ida import IDA

    return IDA


def segment_start(model: Model, q: np.ndarray, v: np.ndarray, t0: float, p: np.ndarray,
                  first: bool) -> tuple:
    """A segment's start: (q, v) projected onto the constraints (a state taken from IDA's
    interpolant at a root satisfies them only to the tolerance, and restarting from it
    makes mu ~ Phi / h blow up as h shrinks), the accelerations and multipliers there,
    and for the run's ``first`` segment the run's force scale
    (:func:`~.tolerances.lambda_scale`; None after). Every run of a model from the same
    start (a sweep's, a benchmark's) projects and solves the same: the first segment's
    start is kept per model for its last starts (2.6 ms a run with 32 loops), not with
    Python load laws (they may keep state)."""
    def compute() -> tuple:
        qp, vp = project_state(model, q, v, t0, p)
        a, lam, Phi_q = model.kkt(qp, vp, t0, p)
        return qp, vp, a, lam, (lambda_scale(model, p, t0, qp, vp, (a, lam, Phi_q))
                                if first else None)
    if not first or model.callables:
        return compute()
    got = recent(model, "first start", (t0, q.tobytes(), v.tobytes(), p.tobytes()), compute)
    return (*(x.copy() for x in got[:4]), got[4])  # (the kept arrays stay unchanged)


def _output_times(opts: RunOptions, t0: float) -> np.ndarray:
    if opts.output_dt is None:
        return np.array([opts.t_end])
    n = int(math.floor(opts.t_end / opts.output_dt + 1e-9))
    # An output time just after a segment start (an event a hair before a grid time) is
    # left out: IDA restarting toward an output 6e-11 s away failed on the double-folded
    # mechanism and the run ended as a dead point. The event's own sample stands in.
    after = t0 + ev.ZENO_DT * max(1.0, opts.t_end)
    # the grid from a multiple or two before that on (the same products k output_dt):
    # built from k = 1 at every segment, it grew with the events times the grid
    k0 = max(1, min(n + 1, int(math.floor(after / opts.output_dt)) - 1))
    grid = opts.output_dt * np.arange(k0, n + 1)
    grid = grid[grid > after]
    if grid.size == 0 or grid[-1] < opts.t_end - 1e-12 * opts.t_end:
        grid = np.append(grid, opts.t_end)
    return grid


# the logger users know (cmm_dae.integrators.ida), where these helpers lived first
_LOG = logging.getLogger("cmm_dae.integrators.ida")
# scikit-sundae's reports of SUNDIALS' failures, and SUNDIALS' own logger's lines
_SUNDIALS_LINE = re.compile(r"^\[(\w+, Error: -?\d+|WARNING|ERROR)\]")


class _SundialsOut(io.TextIOBase):
    """Standard output while IDA runs: scikit-sundae prints SUNDIALS' failure messages
    (``[IDAHandleFailure, Error: -4] ...``, about 20 in an A02 run that succeeds) with
    ``print``; those lines go to the logger ``cmm_dae.integrators.ida`` at debug level, every other
    line (a user's load law printing) to the real standard output."""

    def __init__(self, out):
        self.out, self.part = out, ""

    def write(self, text: str) -> int:
        lines = (self.part + text).split("\n")
        self.part = lines.pop()
        for line in lines:
            if _SUNDIALS_LINE.match(line):
                _LOG.debug("%s", line)
            elif line and self.out is not None:
                self.out.write(line + "\n")
        return len(text)

    def flush(self) -> None:
        if self.part and not _SUNDIALS_LINE.match(self.part) and self.out is not None:
            self.out.write(self.part)
        self.part = ""


def _libc_fflush():
    """C's ``fflush(NULL)``, where the C library can be reached (else nothing)."""
    try:
        return ctypes.CDLL(None).fflush
    except (OSError, AttributeError):  # pragma: no cover - not a POSIX C library
        return None


_FFLUSH = _libc_fflush()
_CAPTURE: list = []  # one temporary file, reused, that takes C's stdout while IDA runs


@contextlib.contextmanager
def quiet_sundials():
    """A context in which SUNDIALS' own messages go to the logger, not to stdout: those
    scikit-sundae prints (Python's stdout) and those SUNDIALS' C logger writes straight
    to file descriptor 1 ("[WARNING] ... root functions identically 0" after a lift-off);
    any other output passes through to the real stdout."""
    out = _SundialsOut(sys.stdout)
    fd = _redirect_fd1()
    try:
        with contextlib.redirect_stdout(out):
            yield
    finally:
        out.flush()
        _restore_fd1(fd, out)


def _redirect_fd1() -> int | None:
    """Point file descriptor 1 at the capture file; the saved descriptor (None where that
    is not possible)."""
    if _FFLUSH is None:
        return None
    try:
        sys.stdout.flush()
        _FFLUSH(None)
        if not _CAPTURE:
            _CAPTURE.append(tempfile.TemporaryFile())  # noqa: SIM115 (kept for the process)
            # closed at exit (else Python warns of an unclosed file as it shuts down)
            atexit.register(_CAPTURE[0].close)
        saved = os.dup(1)
        os.dup2(_CAPTURE[0].fileno(), 1)
        return saved
    except (OSError, ValueError, io.UnsupportedOperation):
        return None


def _restore_fd1(saved: int | None, out: _SundialsOut) -> None:
    """Back to the saved stdout; what C wrote meanwhile sorted as :class:`_SundialsOut`
    sorts Python's."""
    if saved is None:
        return
    _FFLUSH(None)
    os.dup2(saved, 1)
    os.close(saved)
    cap = _CAPTURE[0]
    cap.seek(0)
    text = cap.read().decode(errors="replace")
    cap.seek(0)
    cap.truncate()
    if text:
        out.write(text if text.endswith("\n") else text + "\n")
        out.flush()


def segment_times(opts: RunOptions, t0: float, t_stop: float) -> np.ndarray:
    """t0 and the output times of a segment from t0 to ``t_stop`` (a break, or the end),
    ``t_stop`` last."""
    outs = _output_times(opts, t0)
    if t_stop < opts.t_end:
        outs = np.append(outs[outs < t_stop - 1e-12 * max(1.0, t_stop)], t_stop)
    return np.concatenate([[t0], outs])


#: IDA's first step is a thousandth of the way to the first tout it is given: the first
#: tout of a segment lies this far ahead (s), or at its end where that is nearer, whatever
#: the output grid. 10 s ahead, a restart at rtol 1e-12 began with 1e-2 s and failed; 0.01
#: left the curved slot's energy audit at 1.3e-6 J (1e-3: 9.3e-7) and 0.003 took the
#: slotted link 92,709 steps at rtol 1e-12 on one path (1e-3: 18,777 and 19,051).
FIRST_TOUT = 0.001


def first_tout(t0: float, t_stop: float) -> float:
    """The tout of IDA's first call in a segment from t0 to t_stop (s)."""
    return min(t_stop, t0 + FIRST_TOUT)


def _own_steps(solver, tspan: np.ndarray, y0: np.ndarray, yp0: np.ndarray,
               interrupted=lambda: None, grid: bool = False,
               watch: np.ndarray | None = None, ncol: int = 0, trapped=lambda: None,
               after_step=lambda t, nst: False, dip=None, g0: np.ndarray | None = None):
    """IDA stepping on its own from tspan[0] to tspan[-1] (the end as stop time; a root,
    the stop time or a failure ends it): its steps, or with ``grid`` the output times
    ``tspan[1:]`` read from IDA's interpolant after the step that passes them (and the
    instant of a root or failure), as the compiled segment does. Never ``solve`` on the
    grid: IDA looks for roots at each output time as at a step, so a grazing contact was
    found or missed depending on the grid. Kept in lists: scikit-sundae grows its output
    arrays by 500 rows at a time with a copy of all rows before (its cost per step grew
    with the run: 54 us per step over 100 s, 135 over 1000 s). A Ctrl-C between two
    steps ends it as a root would, ``interrupted()`` told, the samples so far kept. The
    extremes of the entries ``watch`` of y over the steps come back as ``extremes``. IDA
    stuck at order 1 (:class:`~.suppress.TrapCheck`) ends it too, ``trapped()`` told, as
    does ``after_step(t, nst)`` returning True (given each step's end and IDA's count).
    ``dip(t0, t1, g0, y1, dky) -> (found, g1)``, where given, looks for a gap that dipped
    beyond its stop inside each step (:mod:`.dips`; ``g0``: the event values at the
    start): one found ends the segment there as a root would."""
    t_end = float(tspan[-1])
    first = solver.init_step(float(tspan[0]), y0, yp0)
    ts, ys = [first.t], [first.y]
    x, nxt = first, 1
    watch = np.zeros(0, int) if watch is None else watch
    dky = Interpolant(solver, y0.size) if grid or watch.size or dip is not None else None
    t_prev = float(tspan[0])
    track = Tracker(watch, ncol, dky, float(tspan[0]))
    trap, nst = TrapCheck(solver), 0
    try:
        while True:
            # IDA's first step from first_tout (segment.c says why)
            x = solver.step(t_end if nst else first_tout(float(tspan[0]), t_end),
                            method="onestep", tstop=t_end)
            nst += 1
            dipped = False
            if x.status in (0, 1) and dip is not None:  # (first, as segment.c's dip_step)
                found, g0 = dip(t_prev, x.t, g0, x.y, dky)
                if found is not None:
                    info = np.zeros((1, g0.size))
                    info[0, found[1]] = -1  # (every gap that crossed at that instant)
                    x = SimpleNamespace(t=found[0], y=dky(found[0]), status=2, message="",
                                        i_events=info, nfev=x.nfev, njev=x.njev)
                    dipped = True
            if x.status == 0 and (after_step(x.t, n := trap.steps()) or trap(n, trapped)):
                x = SimpleNamespace(t=x.t, y=x.y, status=2, message="", i_events=None,
                                    nfev=x.nfev, njev=x.njev)
            if x.status >= 0 and not dipped:
                track.add(x.t, x.y)
            t_prev = x.t
            if not grid:
                ts.append(x.t)
                ys.append(x.y)
            else:
                at = x.status in (0, 1)  # a step or the end: its time may be an output
                while nxt < tspan.size - 1 + at and (tspan[nxt] <= x.t if at
                                                     else tspan[nxt] < x.t):
                    ts.append(float(tspan[nxt]))
                    ys.append(dky(float(tspan[nxt])))
                    nxt += 1
                if not at:  # the instant of a root or a failure
                    ts.append(x.t)
                    ys.append(x.y)
            if x.status != 0:
                break
    except KeyboardInterrupt:
        interrupted()
        # a root return (status 2) that the caller reads as the interruption
        return SimpleNamespace(t=np.array(ts), y=np.array(ys), status=2, message="",
                               i_events=None, nfev=x.nfev, njev=x.njev,
                               extremes=track.extremes(), steps=trap.steps())
    return SimpleNamespace(t=np.array(ts), y=np.array(ys), status=x.status,
                           message=x.message, i_events=x.i_events, nfev=x.nfev,
                           njev=x.njev, extremes=track.extremes(), steps=trap.steps())


#: A joint that moves this much (rad or m) in an average step of the run makes a spent
#: step budget a fast motion, not a crawl (Andrews' squeezer spun up to 7,900 rad/s by
#: 0.74 s, 0.012 rad a step; a grazing contact crawls at 1e-8 a step).
FAST_STEP = 1e-3


def stall_message(model, t: float, q: np.ndarray, v: np.ndarray, max_steps: int,
                  steps: int) -> str:
    """What a spent step budget at (t, q, v) says: the run's average step (s) and, where
    a joint moves at least :data:`FAST_STEP` in one (a fast motion, not tiny steps), that
    joint and its rate."""
    h = t / max(steps, 1)
    head = f"stalled at t = {t:.9g} s: more than {max_steps} IDA steps in this run"
    names = model.joint_names
    rates = np.abs(model.joint_rates(q, v)[1][:len(names)]) if names else np.zeros(0)
    k = int(np.argmax(rates)) if rates.size else -1
    if k >= 0 and np.isfinite(rates[k]) and rates[k] * h >= FAST_STEP:
        unit = "rad" if model.mech.joints[names[k]].type == "revolute" else "m"
        return (f"{head}, {h:.2g} s each on average, and joint '{names[k]}' moves at "
                f"{rates[k]:.4g} {unit}/s ({rates[k] * h:.2g} {unit} a step): a fast motion, "
                "not tiny steps; raise max_steps or end the run earlier")
    return (f"{head} ({h:.2g} s each on average: a run this long needs more, or the "
            "steps became tiny: a grazing contact, a near-singular position or forces too "
            "stiff for the tolerances); raise max_steps to go on")


#: Smallest absolute tolerance of positions and velocities, relative to the largest of
#: each at a segment's start (10 units of round-off): IDA's Newton iteration cannot meet
#: a tolerance below the round-off of the state it solves for.
ROUNDOFF_ATOL = 10.0 * np.finfo(float).eps

#: Factor by which the round-off floor must exceed a segment's absolute tolerance for an
#: IDA failure to count as the state having outgrown it (see ``_roundoff_atol``).
OUTGROWN = 100.0

#: Consecutive IDA steps that leave t where it was, or move it by less than
#: :data:`CRAWL_STEP` of the run's time scale, after which the segment ends as a failure at
#: that state. Next to a singular position IDA halved its step below t's spacing and then
#: took about a million steps in place (A02 at rtol 1e-10 from t0 = 0, where a step floor
#: relative to t0 is zero); whether that happened hung on round-off, and it ran for an
#: hour. Started 0.05 rad from it at rtol 1e-11, IDA took steps of 2e-19 s that did move t,
#: 500,000 of them, where a different rounding had made it fail at once. The failure goes
#: to the crossing like any other.
IN_PLACE_STEPS = 50
#: A step shorter than this many units of round-off of the run's time scale counts as in
#: place (about 1e-15 s on a 1-s run; IDA's steps there are 1e-7 s and more).
CRAWL_STEP = 16.0
#: Steps after which a segment that has not yet covered one step from its accelerations
#: (``_first_step``, the order-1 step its tolerances allow) counts as crawling, a failure
#: retried with that first step. IDA's own first step comes from y' alone; after a cam
#: follower's landing at rtol 1e-12 it was 4e-15 s, where the index-2 Newton matrix
#: (mass / h^2 beside the constraint rows) is solved with noise in the multipliers, and
#: its steps stayed near 1e-13 s for 500,000 steps or grew back, as rounding fell.
SLOW_STEPS = 200


def failure(model: Model, hs, p: np.ndarray, ratio0: float, crawled: bool,
            v_fail: np.ndarray, r, tt: float, q: np.ndarray) -> tuple[str, Status, float]:
    """The message and status of IDA's failure at (tt, q) in the configuration of ``hs``
    (parameters ``p``; ``ratio0`` the constraints' singular-value ratio at the segment's
    start, ``v_fail`` the velocities at the failure), and the ratio there."""
    cfg = hs.configurations[hs.current()].label
    # the constraint rows' conditioning at the failure against the segment's start: a
    # dead point shows as a collapse of the smallest singular value (units mix, so
    # only the ratio of the two says anything)
    labels, ratio = ev.dependent_rows(model, q, tt, p, tol=1.0)

    def falls() -> bool:  # the ratio falls along the motion: a singular position ahead
        h = 1e-6 / max(float(np.max(np.abs(v_fail), initial=0.0)), 1e-300)
        return singular_ratio(model, q + v_fail * h, tt + h, p) < ratio

    # (also a failure very near one, ahead or just past it: the policy tells which). A
    # ratio that is only low is no dead point where it was as low at the segment's start:
    # Andrews' squeezer runs at 3e-3 throughout, and IDA failing on its stiff spring at
    # rtol 1e-3 was reported as a dead point; nor where it falls only locally from a value
    # above the start's (the squeezer with its spring 1e4 times stiffer, at rtol 1e-2)
    if ratio < 0.2 * ratio0 or (ratio < 0.01 and ratio < 0.5 * ratio0) or (
            ratio < FALLING_RATIO and ratio < ratio0 and falls()):
        what = (f"dead point at t = {tt:.6g} s: the constraints of {row_names(labels)} "
                f"become dependent (singular-value ratio {ratio:.1e}), so the mechanism "
                "cannot follow its drivers through this position")
        status = Status.DEAD_POINT
    else:
        what = (f"IDA could not continue at t = {tt:.9g} s (no dead point found: the "
                "forces may be too stiff for these tolerances; another rtol may pass)")
        status = Status.INTEGRATOR
    ida = (f"{IN_PLACE_STEPS} steps too short to move t (a crawl)" if crawled
           else f"{r.message} (status {r.status})")
    return f"{what}; configuration '{cfg}'; IDA: {ida}", status, ratio


#: IDA's unknowns from which linsolver="auto" is sparse, where at most SPARSE_FILL of the
#: Jacobian is nonzero. Dense over sparse wall time at rtol 1e-6 / 1e-10: A02, 6 loops (98
#: unknowns, 4.4 %) 1.00 / 0.88; 8 (130, 3.3 %) 1.05 / 1.09; 12 (194) 1.11 / 1.27; 32
#: (514) 1.19-1.86; the shipped models (50-70 unknowns, 7-9 %) 0.93-1.11.
SPARSE_FROM, SPARSE_FILL = 120, 0.05


def sparse_solver(model: Model, linsolver: str) -> bool:
    """Whether IDA (and the compiled segment) use the sparse linear solver: asked for, or
    ``"auto"`` on a large sparse system (:data:`SPARSE_FROM`, :data:`SPARSE_FILL`). The
    sparse solver needs every nonzero in CasADi's pattern: Python load laws add derivatives
    outside it, so they keep the dense one."""
    u = model.ida
    return not model.callables and (
        linsolver == "sparse" or (linsolver == "auto" and u.N >= SPARSE_FROM
                                  and u.jac_pattern.nnz() <= SPARSE_FILL * u.N**2))
