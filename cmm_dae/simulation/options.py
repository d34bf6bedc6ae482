"""The options of a run, checked once for every method: all problems reported at once as
one :class:`~cmm_dae.core.errors.ModelError` under ``[run]``."""

from __future__ import annotations

import math
from typing import Any

from ..core.errors import ModelError, Problem
from ..description.mechanism import Mechanism
from ..hybrid import policy as ev
from ..integrators.contract import RunOptions

#: The integration methods, by name (the classes are the runner's).
METHOD_NAMES = ("ida", "iterative")
#: The defaults of the options that belong to one method (``simulate``, ``run_dae`` and
#: ``run_iterative`` take them from here): another value with the other method is refused
#: (but ``compiled``, which both read: IDA's segments, the fixed step, in C).
IDA_DEFAULTS = {"rtol": 1e-8, "atol": None, "output_dt": 0.01, "linsolver": "auto",
                "compiled": "auto"}
ITERATIVE_DEFAULTS = {"dt": 0.01, "output_every": 1}

#: Most memory the output samples of one run may take (their post-processed arrays), bytes.
MAX_OUTPUT_BYTES = 4 * 2**30
#: Default run-wide step budget per simulated second (at least 500,000 in all).
STEPS_PER_SECOND = 50_000
#: IDA's step budget grows with tighter tolerances as (1e-8 / rtol) ** STEPS_TIGHTENING (a
#: variable-order BDF's steps grow about as rtol ** -1/5): the shipped valve train needs
#: 163,000 steps a simulated second at rtol 1e-12 and stopped on the budget at 2.77 s
STEPS_TIGHTENING = 0.25
#: Default most events per simulated second (at least 1000 in all). A cam follower that
#: lifts off, bounces and lands once a turn has about six events a turn: the shipped valve
#: train at 400 rad/s has 382 a second, and a 10-s run of it ended at 2.6 s on a fixed
#: 1000. An event storm the Zeno rule does not hold still ends the run.
EVENTS_PER_SECOND = 1000


def _is_num(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


#: atol's default as a share of rtol: tighter with rtol (a fixed atol caps the accuracy
#: where a coordinate passes zero)
ATOL_PER_RTOL = 1e-2


def default_atol(rtol: float) -> float:
    """IDA's absolute tolerance where none is given: :data:`ATOL_PER_RTOL` of ``rtol``."""
    return ATOL_PER_RTOL * rtol


def check_options(mech: Mechanism, method: str, t_end: Any, *, rtol: Any, atol: Any,
                  output_dt: Any, dt: Any, output_every: Any, max_events: Any, v_lock: Any,
                  max_steps: Any, linsolver: Any = "auto", compiled: Any = "auto",
                  model: Any = None) -> RunOptions:
    """Every run option checked up front; one :class:`ModelError` lists all problems,
    under ``[run]``: bad values, options of the other method given another value than
    their default (they would be ignored), a prebuilt ``model`` of another mechanism."""
    bad: list[Problem] = []
    if method in METHOD_NAMES:
        given = {"rtol": rtol, "atol": atol, "output_dt": output_dt, "linsolver": linsolver,
                 "compiled": compiled, "dt": dt, "output_every": output_every}
        other, defaults = (("ida", IDA_DEFAULTS) if method == "iterative"
                           else ("iterative", ITERATIVE_DEFAULTS))
        bad += [Problem("run", k, f"applies to method=\"{other}\" only; this run is "
                        f"method=\"{method}\"") for k, d in defaults.items()
                if given[k] is not d and given[k] != d and k != "compiled"]  # (both's)
    if linsolver not in ("auto", "dense", "sparse"):
        bad.append(Problem("run", "linsolver", f"expected 'auto', 'dense' or 'sparse', "
                           f"got {linsolver!r}"))
    if not (isinstance(compiled, bool) or compiled == "auto"):
        bad.append(Problem("run", "compiled", f"expected True, False or 'auto', got "
                           f"{compiled!r}"))
    if model is not None and getattr(model, "mech", None) != mech:
        name = getattr(getattr(model, "mech", None), "name", type(model).__name__)
        what = (f"of another mechanism ({name!r})" if name != mech.name else
                f"of another mechanism of the same name ({name!r}: a value differs)")
        bad.append(Problem("run", "model", f"a model {what}, not of this one: build it with "
                           "cmm_dae.Model(mech), or take model.variant(mech) where only "
                           "values that are inputs differ"))

    def need(ok: bool, key: str, msg: str, value: Any) -> bool:
        if not ok:
            bad.append(Problem("run", key, f"{msg}, got {value!r}"))
        return ok

    if method not in METHOD_NAMES:
        bad.append(Problem("run", "method", f"expected one of {', '.join(METHOD_NAMES)}, "
                           f"got {method!r}"))
    ok_t = need(_is_num(t_end) and math.isfinite(t_end) and t_end > 0, "t_end",
                "expected a positive, finite end time in s", t_end)
    if ok_t and method == "ida" and t_end < ev.ZENO_DT:
        # IDA's first steps would be ~1e-24 s, where the index-2 Newton matrix (mass / h
        # beside the constraint rows) cannot be solved: it failed at t = 0 on a four-bar
        # below 1e-13 s. Shorter than the events' resolution, such a run says nothing.
        ok_t = need(False, "t_end", f"expected at least {ev.ZENO_DT:g} s with IDA (the "
                    "run's time resolution; the fixed-step algorithm takes any end time)", t_end)
    ok_rtol = need(_is_num(rtol) and 1e-15 <= rtol <= 1e-2, "rtol",
                   "expected 1e-15 <= rtol <= 1e-2", rtol)
    if atol is None and ok_rtol:
        atol = default_atol(rtol)
    need((atol is None and not ok_rtol) or (_is_num(atol) and 0 < atol <= 1e-2), "atol",
         "expected 0 < atol <= 1e-2 or None", atol)
    ok_out = need(output_dt is None or (_is_num(output_dt) and math.isfinite(output_dt)
                                        and output_dt > 0),
                  "output_dt", "expected a positive step in s or None", output_dt)
    ok_dt = need(_is_num(dt) and math.isfinite(dt) and dt > 0, "dt",
                 "expected a positive step in s", dt)
    ok_every = need(isinstance(output_every, int) and not isinstance(output_every, bool)
                    and output_every >= 1, "output_every", "expected an integer >= 1",
                    output_every)
    def budget(value: Any, key: str, least: int, per_second: int, floor: int) -> tuple:
        """A count limit (an integer >= least, or None: per_second of t_end, at least
        floor) and whether it is good."""
        ok = need(value is None or (isinstance(value, int) and not isinstance(value, bool)
                                    and value >= least),
                  key, f"expected an integer >= {least} or None", value)
        if ok_t and ok and value is None:
            value = max(floor, int(min(per_second * t_end, 2**62)))
        return value, ok

    max_events, _ = budget(max_events, "max_events", 0, EVENTS_PER_SECOND, 1000)
    need(_is_num(v_lock) and math.isfinite(v_lock) and v_lock >= 0, "v_lock",
         "expected a speed >= 0 (rad/s or m/s)", v_lock)
    tight = (max(1.0, (1e-8 / rtol) ** STEPS_TIGHTENING)
             if method == "ida" and _is_num(rtol) and 0.0 < rtol < 1e-8 else 1.0)
    max_steps, ok_steps = budget(max_steps, "max_steps", 1, int(STEPS_PER_SECOND * tight),
                                 int(500_000 * tight))
    if ok_t and ok_dt and ok_steps and method == "iterative":
        n = t_end / dt
        if n > max_steps:
            bad.append(Problem("run", "dt", f"{dt!r} s would take {n:.3g} fixed steps to "
                               f"t_end = {t_end!r} s, more than max_steps = {max_steps}; "
                               "take a larger step or raise max_steps"))
    if ok_t and ok_out and ok_dt and ok_every and not bad:
        n = (t_end / output_dt if method == "ida" and output_dt is not None else
             t_end / dt / output_every if method == "iterative" else 0.0)
        nb, nj = len(mech.bodies), len(mech.joints)
        per = 8 * (9 * nb + 2 * nj + 2 * len(mech.drivers) + 7 * nj + 8)
        if n * per > MAX_OUTPUT_BYTES:
            key = "output_dt" if method == "ida" else "output_every"
            bad.append(Problem("run", key, f"{n:.3g} output samples would take "
                               f"{n * per / 2**30:.3g} GiB, more than the "
                               f"{MAX_OUTPUT_BYTES / 2**30:g} GiB cap; sample more coarsely"))
    if bad:
        raise ModelError(bad)
    return RunOptions(float(t_end), float(rtol), float(atol),
                      None if output_dt is None else float(output_dt), float(dt),
                      output_every, max_events, float(v_lock), int(max_steps))


def branch_rule(mech: Mechanism, branch: Any) -> tuple[str, int] | None:
    """The checked branch option: None for "continue", else (joint, +1 or -1)."""
    if isinstance(branch, str) and branch == "continue":
        return None
    ok = (isinstance(branch, tuple | list) and len(branch) == 2 and branch[0] in mech.joints
          and branch[1] in (1, -1) and not isinstance(branch[1], bool))
    if not ok:
        raise ModelError(Problem("run", "branch", f"expected \"continue\" or (joint, +1 or "
                                 f"-1) with a joint of the mechanism "
                                 f"({', '.join(mech.joints)}), got {branch!r}"))
    return str(branch[0]), int(branch[1])
