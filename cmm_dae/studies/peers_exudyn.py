"""cmm_dae against Exudyn on the A02 chain, at equal accuracy (``cmm-dae bench --peers``,
when Exudyn is installed: the optional extra ``peers``).

Exudyn is the open multibody code closest to cmm_dae's own formulation: planar rigid
bodies in redundant (absolute) coordinates, revolute joints as algebraic constraints, an
implicit integrator (generalized-alpha, index 3, Newton with its sparse LU, Eigen's) at a
fixed step ``h``. Its users' settings: the default integrator and spectral radius, the
sparse linear solver, no solution file. The problem and the error are those of
:mod:`cmm_dae.studies.peers` (the first crank tip's largest distance from the reduction's
DOP853 reference over 2 s); cmm_dae's cheapest tolerance reaching Exudyn's error is timed
against it side by side.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
from typing import Any

import numpy as np

from ..description import iftomm
from .peers import RTOLS, chain_row, columns, header, peer

__all__ = ["a02_exudyn", "compare_a02_exudyn", "exudyn_available", "exudyn_table"]


def _exudyn() -> Any:
    exudyn = peer("exudyn", "Exudyn")
    importlib.import_module("exudyn.itemInterface")
    return exudyn


def exudyn_available() -> bool:
    """Whether Exudyn can be imported here."""
    return importlib.util.find_spec("exudyn") is not None


def a02_exudyn(n: int, t_end: float, h: float = 1e-2) -> tuple[np.ndarray, np.ndarray]:
    """A02 with ``n`` loops in Exudyn for ``t_end`` s at step ``h``: the times (s) and the
    first crank's tip (x, y) in m at every step. Cranks start upright turning clockwise
    at 1 rad/s, couplers horizontal translating at 1 m/s (as
    :func:`cmm_dae.description.iftomm.a02_four_bar`); rods of 1 kg and 1 m."""
    exu = _exudyn()
    it = exu.itemInterface
    sc = exu.SystemContainer()
    mbs = sc.AddSystem()
    ground = mbs.AddObject(it.ObjectGround())

    def rod(centre: tuple, angle: float, velocity: tuple) -> int:
        node = mbs.AddNode(it.NodeRigidBody2D(referenceCoordinates=[*centre, angle],
                                              initialVelocities=list(velocity)))
        body = mbs.AddObject(it.ObjectRigidBody2D(mass=iftomm.ROD_M, inertia=iftomm.ROD_I,
                                                  nodeNumber=node))
        weight = mbs.AddMarker(it.MarkerBodyMass(bodyNumber=body))
        mbs.AddLoad(it.LoadMassProportional(markerNumber=weight,
                                            loadVector=[0.0, -iftomm.G, 0.0]))
        return body

    def end(body: int, x: float) -> int:  # a point on a rod's axis, from its centre
        return mbs.AddMarker(it.MarkerBodyPosition(bodyNumber=body, localPosition=[x, 0, 0]))

    half = iftomm.ROD_L / 2
    cranks = [rod((float(i), half), math.pi / 2, (half, 0.0, -1.0)) for i in range(n + 1)]
    for i, crank in enumerate(cranks):
        pivot = mbs.AddMarker(it.MarkerBodyPosition(bodyNumber=ground,
                                                    localPosition=[float(i), 0, 0]))
        mbs.AddObject(it.RevoluteJoint2D(markerNumbers=[pivot, end(crank, -half)]))
    for i in range(1, n + 1):
        coupler = rod((i - half, iftomm.ROD_L), 0.0, (iftomm.ROD_L, 0.0, 0.0))
        mbs.AddObject(it.RevoluteJoint2D(markerNumbers=[end(cranks[i - 1], half),
                                                        end(coupler, -half)]))
        mbs.AddObject(it.RevoluteJoint2D(markerNumbers=[end(cranks[i], half),
                                                        end(coupler, half)]))
    tip = mbs.AddSensor(it.SensorBody(bodyNumber=cranks[0], localPosition=[half, 0, 0],
                                      outputVariableType=exu.OutputVariableType.Position,
                                      storeInternal=True, writeToFile=False))
    mbs.Assemble()
    s = exu.SimulationSettings()
    s.timeIntegration.numberOfSteps = int(round(t_end / h))
    s.timeIntegration.endTime = t_end
    s.timeIntegration.verboseMode = 0
    s.solution.file.write = False
    s.solution.sensors.writePeriod = h
    s.show.computationTime = False
    s.show.statistics = False
    s.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    exu.SolveDynamic(mbs, s)
    data = mbs.GetSensorStoredData(tip)
    return data[:, 0], data[:, 1:3]


def compare_a02_exudyn(n: int, *, t_end: float = 2.0, h: float = 1e-2, repeat: int = 3,
                       rtols: tuple[float, ...] = RTOLS) -> dict:
    """One row of the comparison with Exudyn on A02 with ``n`` loops: ``loops``, Exudyn's
    ``h`` (s), ``exudyn_error`` (m) and ``exudyn_s`` (best wall time, s), cmm_dae's chosen
    ``rtol`` (None where none of ``rtols`` reached Exudyn's error), ``cmm_dae_error`` (m)
    and ``cmm_dae_s``, and ``ratio`` = cmm_dae's time over Exudyn's."""
    return chain_row(n, "exudyn", a02_exudyn, t_end=t_end, h=h, repeat=repeat, rtols=rtols)


def exudyn_table(rows: list[dict]) -> str:
    """The comparison with Exudyn as text, one line per problem size."""
    lines = ["A02 four-bar chain against Exudyn, 2 s, equal accuracy (largest crank-tip "
             "error against the reference)",
             f"{'loops':>5}  {header('Exudyn')}"]
    lines += [f"{r['loops']:>5}  {columns(r, 'exudyn')}" for r in rows]
    lines.append("time ratio: cmm_dae's wall time over Exudyn's (generalized-alpha at the "
                 "step h, its sparse solver), best of warm runs side by side")
    return "\n".join(lines)
