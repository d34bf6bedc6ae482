"""cmm_dae against the code a user would pick instead, at equal accuracy (``cmm-dae bench
--peers``).

The peer is MuJoCo (the optional extra ``peers``), tuned as its users tune it for a
closed-loop linkage: the RK4 integrator at a fixed step h, the loops closed by soft
equality constraints whose time constant is 2 h (the shortest MuJoCo advises), no contacts.
The problem is IFToMM A02 with N four-bar loops (``cmm_dae.description.iftomm``), whose
crank tip has an independent reference (the one-degree-of-freedom reduction, DOP853 at
rtol 1e-13). Each code's error is the largest distance of the first crank's tip from that
reference over the run.

Equal accuracy: MuJoCo's error at its step sets the target; cmm_dae runs a ladder of
tolerances and the cheapest one whose error is no larger is timed against MuJoCo, side by
side in one process (best of ``repeat`` warm runs each). cmm_dae is timed as a user calls
it, ``run_dae(mechanism)``: warm runs reuse the model of the mechanism run before, as
``run_dae`` does (:mod:`cmm_dae.simulation.cache`); the first run of a new mechanism
object, which builds it, is reported too (MuJoCo's times include compiling its XML).
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import time
from typing import Any

import numpy as np

from ..core.errors import CmmError
from ..description import iftomm
from ..simulation.runner import run_dae
from .bench import best_times
from .mujoco_a02 import start_state

__all__ = ["COLUMNS", "RATIO_NOTE", "RTOLS", "a02_mujoco", "cheapest", "columns", "compare_a02",
           "chain_row", "error_a02", "header", "mujoco_available", "peer", "peers_table"]

#: The tolerances cmm_dae tries, loosest first (atol = 1e-2 rtol as in any run).
RTOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)


def peer(module: str, name: str) -> Any:
    """The peer code's Python module (``import_module(module)``), or a CmmError that says
    how to get it (the optional extra ``peers``); ``name`` is how a user calls it."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise CmmError(f"the comparison with {name} needs {name}: pip install "
                       "'cmm_dae[peers]'") from e


def _mujoco() -> Any:
    return peer("mujoco", "MuJoCo")


def mujoco_available() -> bool:
    """Whether MuJoCo can be imported here."""
    return importlib.util.find_spec("mujoco") is not None


#: MuJoCo's loop closures as its users tune them for accuracy: impedance 0.9999 (its
#: default 0.9 .. 0.95 leaves the closures soft: 2.1e-2 m of error on A02 with 8 loops at
#: h 1e-2 against 1.7e-3 tuned; 4.3e-4 against 7.4e-6 at 1e-3), time constant 2 h
SOLIMP = "0.9999 0.9999 0.001"

#: MuJoCo's steps (s) of the comparison: a loose point and a tight one (error below 1e-6 m
#: on A02 with 8 loops).
STEPS = (1e-2, 1e-4)


def _a02_xml(n: int, h: float) -> str:
    """MJCF of A02 with ``n`` loops in MuJoCo's x-z plane (gravity along -z): each crank a
    child of the world on a hinge about y, each coupler a child of the crank to its left,
    its right end connected to the next crank's tip by an equality of time constant 2 h
    and impedance :data:`SOLIMP`; a sensor reads the first crank's tip. Rods of 1 kg and
    1 m along their body's x axis (inertia 1/12 kg m^2 about y)."""
    inertial = ('<inertial pos="0.5 0 0" mass="1" '
                f'diaginertia="1e-9 {iftomm.ROD_I!r} {iftomm.ROD_I!r}"/>')
    down = f'quat="{math.cos(-math.pi / 4)!r} 0 {math.sin(-math.pi / 4)!r} 0"'  # x -> +z
    back = f'quat="{math.cos(math.pi / 4)!r} 0 {math.sin(math.pi / 4)!r} 0"'    # z -> +x
    bodies = []
    for i in range(n + 1):
        coupler = (f'<body name="coupler{i + 1}" pos="1 0 0" {back}>'
                   f'<joint name="L{i + 1}" type="hinge" axis="0 1 0"/>{inertial}</body>'
                   if i < n else "")
        bodies.append(f'<body name="crank{i}" pos="{i} 0 0" {down}>'
                      f'<joint name="G{i}" type="hinge" axis="0 1 0"/>{inertial}'
                      f'<site name="tip{i}" pos="1 0 0"/>{coupler}</body>')
    closures = "".join(f'<connect body1="coupler{i}" body2="crank{i}" anchor="1 0 0" '
                       f'solref="{2 * h!r} 1" solimp="{SOLIMP}"/>' for i in range(1, n + 1))
    return (f'<mujoco><option timestep="{h!r}" integrator="RK4" gravity="0 0 -9.81"/>'
            f'<worldbody>{"".join(bodies)}</worldbody><equality>{closures}</equality>'
            '<sensor><framepos objtype="site" objname="tip0"/></sensor></mujoco>')


def a02_mujoco_prepared(n: int, t_end: float, h: float = 1e-2):
    """A02 with ``n`` loops in MuJoCo, compiled now (outside any timing, as cmm_dae's build
    is): a function that runs it for ``t_end`` s at step ``h`` with MuJoCo's batched
    ``rollout`` and returns the times (s) and the first crank's tip (x, height) in m at
    every step."""
    mujoco = _mujoco()
    from mujoco import rollout

    model = mujoco.MjModel.from_xml_string(_a02_xml(n, h))
    state = start_state(mujoco, model, n)
    steps = int(round(t_end / h))
    work = mujoco.MjData(model)

    def run() -> tuple[np.ndarray, np.ndarray]:
        _, sensed = rollout.rollout(model, work, state[None, :], nstep=steps)
        # each step's sensors are read before the step: the states at 0, h, .. t_end - h
        return h * np.arange(steps), sensed[0][:, [0, 2]]
    return run


def a02_mujoco(n: int, t_end: float, h: float = 1e-2) -> tuple[np.ndarray, np.ndarray]:
    """A02 with ``n`` loops in MuJoCo for ``t_end`` s at step ``h`` (compiled and run):
    the times (s) and the first crank's tip (x, height) in m at every step."""
    return a02_mujoco_prepared(n, t_end, h)()


a02_mujoco.prepare = a02_mujoco_prepared  # (chain_row times the run alone)


def cheapest(error_at, target: float, rtols: tuple[float, ...]
             ) -> tuple[float | None, float]:
    """Equal accuracy: the loosest of ``rtols`` whose run's error ``error_at(rtol)`` (None
    for a run that failed) is no larger than ``target``, and that error (None and NaN
    where none is)."""
    for rtol in rtols:
        err = error_at(rtol)
        if err is not None and err <= target:
            return rtol, err
    return None, math.nan


#: What the tables' time ratio is.
RATIO_NOTE = ("time ratio: cmm_dae's wall time over MuJoCo's, best of warm runs side by "
              "side; MuJoCo as its users tune it: RK4, loops closed by equality constraints "
              f"of time constant 2 h and impedance {SOLIMP}, the model compiled outside the "
              "timing (as cmm_dae's build is), its steps in one call (its batched rollout, or "
              "mj_step's nstep)")


def header(peer: str = "MuJoCo") -> str:
    """The columns every comparison shares, against ``peer``: its step and error,
    cmm_dae's tolerance and error, the time ratio."""
    return (f"{peer + ' h':>8}  {peer + ' err':>10}  {'cmm_dae rtol':>12}  "
            f"{'cmm_dae err':>11}  {'time ratio':>10}")


#: The columns of the comparisons with MuJoCo (:func:`header`).
COLUMNS = header()


def _step(h: float) -> str:
    """A step (s) as the tables print it: one digit where that is exact (1e-02), else two
    (2.5e-03, which one digit would round to 3e-03)."""
    one = f"{h:.0e}"
    return one if float(one) == h else f"{h:.1e}"


def columns(row: dict, peer: str = "mujoco") -> str:
    """A comparison row's peer step and error (``row[peer + "_error"]``), cmm_dae's
    tolerance ("none" where none reached the peer's error) and error, and the time ratio,
    under :func:`header`."""
    rtol = f"{row['rtol']:.0e}" if row["rtol"] is not None else "none"
    return (f"{_step(row['h']):>8}  {row[peer + '_error']:>10.2e}  {rtol:>12}  "
            f"{row['cmm_dae_error']:>11.2e}  {row['ratio']:>10.2f}")


def error_a02(t: np.ndarray, tip: np.ndarray, n: int) -> float:
    """The largest distance (m) of A02's first crank tip ``tip`` (len(t), 2) from the
    reference at the times ``t`` (s), ``n`` loops."""
    return float(np.max(np.linalg.norm(tip - iftomm.a02_reference(n, t), axis=1)))


def chain_row(n: int, name: str, run_peer, *, t_end: float, h: float, repeat: int,
              rtols: tuple[float, ...]) -> dict:
    """A02 with ``n`` loops run by a peer, ``run_peer(n, t_end, h) -> (t, tip)``, and by
    cmm_dae at the cheapest of ``rtols`` reaching its error: ``loops``, ``h``,
    ``<name>_error`` (m), ``rtol`` (None where none did), ``cmm_dae_error`` (m), the best
    wall times ``<name>_s`` and ``cmm_dae_s`` (s), alternating, ``ratio``, cmm_dae's
    over the peer's, and ``path``: "C" where its runs used the compiled segment (cached,
    or built by ``compiled="auto"`` before its first run), else "Python"."""
    mech = iftomm.a02_four_bar(n)
    prepare = getattr(run_peer, "prepare", None)  # its model compiled outside the timing
    peer_run = prepare(n, t_end, h) if prepare else (lambda: run_peer(n, t_end, h))
    err_peer = error_a02(*peer_run(), n)

    def error_at(rtol: float) -> float | None:
        res = run_dae(mech, t_end, rtol=rtol, throw=False)
        return error_a02(res.t, iftomm.crank_tip(res), n) if res.success else None

    chosen, err = cheapest(error_at, err_peer, rtols)
    row = {"loops": n, "h": h, f"{name}_error": err_peer, "rtol": chosen,
           "cmm_dae_error": err}
    # side by side: best-of-repeat timings, the two codes' runs alternating
    (row[f"{name}_s"], _), (row["cmm_dae_s"], res) = best_times(
        [peer_run, None if chosen is None else lambda: run_dae(mech, t_end, rtol=chosen)],
        repeat)
    row["path"] = "-" if res is None else "C" if res.meta.get("compiled") else "Python"
    row["ratio"] = row["cmm_dae_s"] / row[f"{name}_s"]
    return row


def compare_a02(n: int, *, t_end: float = 2.0, h: float = 1e-2, repeat: int = 3,
                rtols: tuple[float, ...] = RTOLS) -> dict:
    """One row of the comparison on A02 with ``n`` loops.

    Returns
    -------
    dict
        ``loops``; MuJoCo's ``h`` (s), error (m) and best wall time (s); cmm_dae's chosen
        ``rtol`` (None when no tolerance of ``rtols`` reached MuJoCo's error), its error
        (m) and best wall time (s); ``ratio`` = cmm_dae's time over MuJoCo's (above 1:
        MuJoCo is faster); ``cmm_dae_first_s`` and ``first_ratio``: the same for the first
        run of a new mechanism object (its model built in the run).
    """
    row = chain_row(n, "mujoco", a02_mujoco, t_end=t_end, h=h, repeat=repeat, rtols=rtols)
    chosen = row["rtol"]
    first = math.nan
    if chosen is not None:  # a new mechanism object: its model is built in the run
        fresh = iftomm.a02_four_bar(n)
        t0 = time.perf_counter()
        run_dae(fresh, t_end, rtol=chosen)
        first = time.perf_counter() - t0
    row["cmm_dae_first_s"] = first
    row["first_ratio"] = first / row["mujoco_s"]
    return row


def peers_table(rows: list[dict]) -> str:
    """The comparison as text, one line per problem size."""
    lines = ["A02 four-bar chain, 2 s, equal accuracy (largest crank-tip error against the "
             "reference)",
             f"{'loops':>5}  {COLUMNS}  {'first run':>9}  {'path':>6}"]
    lines += [f"{r['loops']:>5}  {columns(r)}  {r['first_ratio']:>9.2f}  {r['path']:>6}"
              for r in rows]
    lines.append(f"{RATIO_NOTE}; first run: cmm_dae's run that builds the model, over "
                 "MuJoCo's; path: where cmm_dae's runs went, C (the compiled segment, "
                 "cached or built by the default before a first run where that is short) "
                 "or Python")
    return "\n".join(lines)
