"""cmm_dae against MuJoCo and Exudyn on the Bennett linkage, a spatial mechanism, at equal
accuracy (part of ``cmm-dae bench --peers``).

The problem is the shipped ``bennett_linkage``: three links and the ground joined by four
revolute joints with skew axes (mobility 1, three redundant constraint rows), released from
rest at J1 = 1 rad under gravity, 2 s. Each code's error is the largest difference of its
J1 angle (rad) from a reference at the samples it delivers (every 0.01 s, or every step
where its step is longer).

The reference is MuJoCo's own run at a tiny step (:data:`REFERENCE_STEP`), not a cmm_dae
run; :func:`compare_bennett` checks it against cmm_dae at rtol 1e-12 and against the
closed form tan(th1/2) tan(th2/2) = sin((beta+alpha)/2) / sin((beta-alpha)/2), and
reports both gaps (measured 2.8e-11 rad and 9.4e-11 over 2 s; Exudyn at h 2e-5 agrees with
it to 9e-9 rad, its own h^2 error: ``validation/peers_bennett.py``).

The peers, as their users tune them for a closed loop:

- MuJoCo: the links a kinematic tree of hinges from the ground (J1, J2, J3), the loop closed
  at J4 by one ``connect`` equality (a point: on this linkage it pins the one-DOF motion;
  the axis is implied, and two connects along J4's axis measured 2.5x worse), RK4 at the
  fixed step h, impedance :data:`~cmm_dae.studies.peers.SOLIMP` and time constant
  :data:`TIME_CONSTANT` h (4 h measured 1.6-2.1x more accurate than the advised 2 h from
  h 5e-2 to 2.5e-3, and 8 h worse again); compiled outside the timing, its steps in one
  batched ``rollout``.
- Exudyn: its minimal-coordinate kinematic tree (the same three hinges) with the loop
  closed by a ``GenericJoint`` holding J4's point of link3 on J4's axis (the two closure
  equations left once the redundant ones are dropped, as Exudyn's users close a Bennett
  loop); generalized-alpha (index 3, its default spectral radius 0.9) at the fixed step h,
  its dense solver, a modified Newton whose Jacobian is renewed every step at relative
  tolerance 1e-6 (1.5-2x faster than its defaults at the same error); assembled outside
  the timing. In absolute coordinates with four revolute joints it needs the full-pivot LU
  for the redundant rows: slower (1.3x at h 1e-3) and ten times less accurate at h 1e-2.

Equal accuracy and timing are those of :mod:`.peers`: the loosest cmm_dae rtol whose error
is no larger than the peer's, both runs timed side by side (best of ``repeat`` warm runs).
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import CmmError
from ..description.library import example
from ..description.loader import load
from ..description.mechanism import Mechanism
from ..simulation.runner import run_dae
from .bench import best_times
from .peers import RTOLS, SOLIMP, _mujoco, cheapest, columns, header
from .peers_exudyn import _exudyn, exudyn_available

__all__ = ["EXUDYN_STEPS", "GRID", "MUJOCO_STEPS", "REFERENCE_STEP", "TIME_CONSTANT",
           "bennett_exudyn", "bennett_exudyn_prepared", "bennett_mujoco",
           "bennett_mujoco_prepared", "bennett_reference", "bennett_relation",
           "bennett_row", "bennett_table", "compare_bennett", "error_j1", "start_angles"]

#: The tree's hinges, ground first, and the joint that closes the loop.
CHAIN = ("J1", "J2", "J3")
CLOSURE = "J4"
#: MuJoCo's closure time constant, in steps h.
TIME_CONSTANT = 4.0
#: MuJoCo's steps (s): error 1.3e-3 rad (loose) and 1.4e-7 rad (tight).
MUJOCO_STEPS = (5e-2, 2.5e-3)
#: Exudyn's steps (s): error 2.1e-3 rad (loose) and 8.7e-7 rad (tight).
EXUDYN_STEPS = (1e-2, 2e-4)
#: MuJoCo's step (s) for the reference (2.8e-11 rad from cmm_dae at rtol 1e-12 over
#: 2 s, closed-form residual 9.4e-11; at 1e-5 2.0e-11 and 2.4e-11 in twice the time).
REFERENCE_STEP = 2e-5
#: The samples (s) the errors are taken at: cmm_dae's default output grid.
GRID = 0.01
#: The peers' settings, as the table prints them.
SETTINGS = {"mujoco": f"RK4, 1 connect, solref {TIME_CONSTANT:g}h, solimp {SOLIMP.split()[0]}",
            "exudyn": "gen-alpha 0.9, tree + 2 closure rows, Jacobian each step"}
_NAMES = {"mujoco": "MuJoCo", "exudyn": "Exudyn"}


def _frame(x, z) -> np.ndarray:
    """The rotation whose columns are x, z cross x, z: a joint's frame from its common
    normal ``x`` and its axis ``z`` (unit, orthogonal)."""
    x, z = np.asarray(x, float), np.asarray(z, float)
    return np.column_stack([x, np.cross(z, x), z])


def _twist(mech: Mechanism, body: str) -> float:
    """A link's twist (rad): from its first joint's axis z to its second's, about x."""
    z, zb = np.asarray(mech.axis(f"{body}.z")), np.asarray(mech.axis(f"{body}.zB"))
    return math.atan2(float(np.cross(z, zb) @ mech.axis(f"{body}.x")), float(z @ zb))


def _links(mech: Mechanism) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The tree's links in order: (body, where its joint sits in the parent's frame (m),
    the rotation from the parent's frame to the link's at joint angle 0). Each link's frame
    must be its joint's Denavit-Hartenberg frame (joint at the origin, axis z, reference x),
    as the shipped model's are; anything else is refused rather than built wrong."""
    links = []
    for name in CHAIN:
        j = mech.joints[name]
        body, point = j.second.split(".")
        if (not np.allclose(mech.point(j.second), 0.0) or
                not np.allclose(mech.axis(j.axes[1]), (0, 0, 1)) or
                not np.allclose(mech.axis(j.reference[1]), (1, 0, 0))):
            raise CmmError(f"the Bennett peers need {body}'s frame on joint {name} (origin "
                           f"at {point}, z its axis, x its reference)")
        links.append((body, np.asarray(mech.point(j.first), float),
                      _frame(mech.axis(j.reference[0]), mech.axis(j.axes[0]))))
    return links


def _ratio(mech: Mechanism) -> float:
    alpha, beta = _twist(mech, "link1"), _twist(mech, "link2")
    return math.sin((beta + alpha) / 2) / math.sin((beta - alpha) / 2)


def bennett_relation(mech: Mechanism, th1: np.ndarray, th2: np.ndarray) -> np.ndarray:
    """How far the joint angles ``th1``, ``th2`` (rad) are from the closed form:
    tan(th1/2) tan(th2/2) - sin((beta+alpha)/2) / sin((beta-alpha)/2), alpha and beta the
    twists of link1 and link2 (dimensionless; 0 on the linkage)."""
    return np.tan(np.asarray(th1) / 2) * np.tan(np.asarray(th2) / 2) - _ratio(mech)


def start_angles(mech: Mechanism) -> np.ndarray:
    """J1, J2, J3 (rad) at the start, from J1 alone by the closed form: th2 from th1, and
    th3 = -th1 (a Bennett linkage's opposite joint angles are equal and opposite)."""
    th1 = float(mech.initial.joints[CHAIN[0]])
    return np.array([th1, 2 * math.atan(_ratio(mech) / math.tan(th1 / 2)), -th1])


def _mjcf(mech: Mechanism, h: float) -> str:
    """MJCF of the linkage at step ``h`` (see the module's text); hinge angle = joint angle."""
    def vec(v) -> str:
        return " ".join(repr(float(x)) for x in v)

    tip = mech.joints[CLOSURE]
    inner = f'<site name="tip" pos="{vec(mech.point(tip.first))}"/>'
    for joint, (body, pos, rot) in reversed(list(zip(CHAIN, _links(mech), strict=True))):
        b = mech.bodies[body]
        inner = (f'<body name="{body}" pos="{vec(pos)}" xyaxes="{vec(rot[:, 0])} '
                 f'{vec(rot[:, 1])}"><joint name="{joint}" type="hinge" axis="0 0 1"/>'
                 f'<inertial pos="{vec(b.centroid)}" '
                 f'mass="{b.mass!r}" diaginertia="{vec(b.inertia)}"/>{inner}</body>')
    return (f'<mujoco><option timestep="{h!r}" integrator="RK4" gravity="{vec(mech.gravity)}"/>'
            f'<worldbody><site name="pivot" pos="{vec(mech.point(tip.second))}"/>{inner}'
            f'</worldbody><equality><connect site1="tip" site2="pivot" '
            f'solref="{TIME_CONSTANT * h!r} 1" solimp="{SOLIMP}"/></equality></mujoco>')


def bennett_mujoco_prepared(h: float, t_end: float = 2.0, mech: Mechanism | None = None):
    """The linkage in MuJoCo at step ``h`` (s), compiled now (outside any timing): a
    function that runs it for ``t_end`` s in one ``rollout`` and returns the times (s) and
    the angles J1, J2, J3 (rad; (n, 3)) at the start and after every step."""
    mujoco = _mujoco()
    from mujoco import rollout

    mech = mech or load(example("bennett_linkage"))
    model = mujoco.MjModel.from_xml_string(_mjcf(mech, h))
    data = mujoco.MjData(model)
    data.qpos[:] = start_angles(mech)  # at rest, the loop closed
    mujoco.mj_forward(model, data)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state, spec)
    steps, q0, work = int(round(t_end / h)), data.qpos.copy(), mujoco.MjData(model)

    def run() -> tuple[np.ndarray, np.ndarray]:
        states, _ = rollout.rollout(model, work, state[None, :], nstep=steps)
        # the states after each step: time, then qpos (the three hinges)
        return h * np.arange(steps + 1), np.vstack([q0, states[0, :, 1:4]])
    return run


def bennett_mujoco(h: float, t_end: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bennett_mujoco_prepared`, compiled and run: times (s), angles (rad, (n, 3))."""
    return bennett_mujoco_prepared(h, t_end)()


def _exudyn_settings(exu, h: float, t_end: float):
    s = exu.SimulationSettings()
    ti = s.timeIntegration
    ti.numberOfSteps, ti.endTime, ti.verboseMode = int(round(t_end / h)), t_end, 0
    # a fresh Jacobian each step saves Newton iterations (6.6 a step with the defaults),
    # and 1e-6 is far below the step's own error: 1.5-2x faster, the error the same
    ti.newton.modifiedNewtonJacUpdatePerStep = True
    ti.newton.relativeTolerance = 1e-6
    s.solution.file.write = False
    s.solution.sensors.writePeriod = h
    s.show.computationTime = s.show.statistics = False
    s.linearSolver.solverType = exu.LinearSolverType.EXUdense
    return s


def bennett_exudyn_prepared(h: float, t_end: float = 2.0, mech: Mechanism | None = None):
    """The linkage in Exudyn at step ``h`` (s), assembled now (outside any timing): a
    function that runs it for ``t_end`` s and returns the times (s) and the angles J1, J2,
    J3 (rad; (n, 3)) at the start and after every step."""
    exu = _exudyn()
    it = exu.itemInterface
    mech = mech or load(example("bennett_linkage"))
    links = _links(mech)
    bodies = [mech.bodies[b] for b, _, _ in links]
    sc = exu.SystemContainer()
    mbs = sc.AddSystem()
    node = mbs.AddNode(it.NodeGenericODE2(
        referenceCoordinates=[0.0] * 3, initialCoordinates=list(start_angles(mech)),
        initialCoordinates_t=[0.0] * 3, numberOfODE2Coordinates=3))
    tree = mbs.AddObject(it.ObjectKinematicTree(
        nodeNumber=node, jointTypes=[exu.JointType.RevoluteZ] * 3, linkParents=[-1, 0, 1],
        jointTransformations=exu.Matrix3DList([rot for _, _, rot in links]),
        jointOffsets=exu.Vector3DList([pos for _, pos, _ in links]),
        linkInertiasCOM=exu.Matrix3DList([np.diag(b.inertia) for b in bodies]),
        linkCOMs=exu.Vector3DList([list(b.centroid) for b in bodies]),
        linkMasses=[b.mass for b in bodies], gravity=list(mech.gravity)))
    tip = mech.joints[CLOSURE]
    ground = mbs.AddObject(it.ObjectGround())
    on_link = mbs.AddMarker(it.MarkerKinematicTreeRigid(
        objectNumber=tree, linkNumber=2, localPosition=list(mech.point(tip.first))))
    pivot = mbs.AddMarker(it.MarkerBodyRigid(bodyNumber=ground,
                                             localPosition=list(mech.point(tip.second))))
    # the point held on J4's axis: the translations across the axis (its frame's x, y)
    mbs.AddObject(it.GenericJoint(
        markerNumbers=[pivot, on_link], constrainedAxes=[1, 1, 0, 0, 0, 0],
        rotationMarker0=_frame(mech.axis(tip.reference[1]), mech.axis(tip.axes[1]))))
    sensor = mbs.AddSensor(it.SensorNode(nodeNumber=node, storeInternal=True,
                                         outputVariableType=exu.OutputVariableType.Coordinates,
                                         writeToFile=False))
    mbs.Assemble()
    settings = _exudyn_settings(exu, h, t_end)

    def run() -> tuple[np.ndarray, np.ndarray]:
        exu.SolveDynamic(mbs, settings)
        data = mbs.GetSensorStoredData(sensor)
        return data[:, 0], data[:, 1:4]
    return run


def bennett_exudyn(h: float, t_end: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bennett_exudyn_prepared`, assembled and run: times (s), angles (rad, (n, 3))."""
    return bennett_exudyn_prepared(h, t_end)()


def bennett_reference(t_end: float = 2.0, h: float = REFERENCE_STEP
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The reference: MuJoCo at step ``h`` (s; it must divide :data:`GRID`), every
    :data:`GRID` s: times (s) and the angles J1, J2, J3 (rad, (n, 3))."""
    t, q = bennett_mujoco(h, t_end)
    every = int(round(GRID / h))
    return t[::every], q[::every]


def error_j1(t: np.ndarray, j1: np.ndarray, reference: tuple[np.ndarray, np.ndarray]
             ) -> float:
    """The largest difference (rad) of the J1 angles ``j1`` at the times ``t`` (s,
    multiples of :data:`GRID`) from ``reference`` (:func:`bennett_reference`)."""
    k = np.rint(np.asarray(t) / GRID).astype(int)
    if not np.allclose(k * GRID, t, rtol=0.0, atol=1e-9) or k[-1] >= len(reference[0]):
        raise CmmError("the samples must be multiples of the reference's grid, within it")
    return float(np.max(np.abs(np.asarray(j1) - reference[1][k, 0])))


def bennett_row(code: str, h: float, reference: tuple[np.ndarray, np.ndarray], *,
                mech: Mechanism, t_end: float = 2.0, repeat: int = 3,
                rtols: tuple[float, ...] = RTOLS) -> dict:
    """One row: the peer ``code`` ("mujoco" or "exudyn") at step ``h`` (s) and cmm_dae at
    the loosest of ``rtols`` reaching its error, timed side by side. Both are sampled every
    max(h, GRID) s (cmm_dae's ``output_dt``) and measured there against ``reference``.

    Returns
    -------
    dict
        ``code``, ``h`` (s), ``<code>_error`` (rad), ``rtol`` (None where none reached it),
        ``cmm_dae_error`` (rad), best wall times ``<code>_s`` and ``cmm_dae_s`` (s),
        ``ratio`` = cmm_dae's over the peer's, and ``path`` ("C" or "Python", cmm_dae's).
    """
    prepare = {"mujoco": bennett_mujoco_prepared, "exudyn": bennett_exudyn_prepared}[code]
    peer_run = prepare(h, t_end, mech)  # compiled outside the timing
    dt = max(h, GRID)
    every = int(round(dt / h))
    t, q = peer_run()
    err_peer = error_j1(t[::every], q[::every, 0], reference)

    def error_at(rtol: float) -> float | None:
        res = run_dae(mech, t_end, rtol=rtol, output_dt=dt, throw=False)
        return error_j1(res.t, res.joint(CHAIN[0]).position, reference) \
            if res.success else None

    chosen, err = cheapest(error_at, err_peer, rtols)
    row = {"code": code, "h": h, f"{code}_error": err_peer, "rtol": chosen,
           "cmm_dae_error": err}
    (row[f"{code}_s"], _), (row["cmm_dae_s"], res) = best_times(  # the runs alternating
        [peer_run,
         None if chosen is None else lambda: run_dae(mech, t_end, rtol=chosen, output_dt=dt)],
        repeat)
    row["path"] = "-" if res is None else "C" if res.meta.get("compiled") else "Python"
    row["ratio"] = row["cmm_dae_s"] / row[f"{code}_s"]
    return row


def compare_bennett(*, t_end: float = 2.0, repeat: int = 3, rtols: tuple[float, ...] = RTOLS,
                    mujoco_steps: tuple[float, ...] = MUJOCO_STEPS,
                    exudyn_steps: tuple[float, ...] = EXUDYN_STEPS,
                    reference_step: float = REFERENCE_STEP) -> dict:
    """The comparison: MuJoCo's rows at ``mujoco_steps``, Exudyn's at ``exudyn_steps``
    (where Exudyn is installed), over ``t_end`` s.

    Returns
    -------
    dict
        ``rows`` (:func:`bennett_row`'s), ``reference_step`` (s), ``reference_gap``: the
        reference's largest J1 difference from cmm_dae at rtol 1e-12 (rad), and
        ``reference_relation``: its largest closed-form residual (dimensionless);
        ``exudyn``: whether Exudyn ran.
    """
    mech = load(example("bennett_linkage"))
    reference = bennett_reference(t_end, reference_step)
    tight = run_dae(mech, t_end, rtol=1e-12)
    out = {"reference_step": reference_step,
           "reference_gap": error_j1(tight.t, tight.joint(CHAIN[0]).position, reference),
           "reference_relation": float(np.max(np.abs(bennett_relation(
               mech, reference[1][:, 0], reference[1][:, 1])))),
           "exudyn": exudyn_available(), "t_end": t_end}
    kw = {"mech": mech, "t_end": t_end, "repeat": repeat, "rtols": rtols}
    out["rows"] = [bennett_row("mujoco", h, reference, **kw) for h in mujoco_steps]
    if out["exudyn"]:
        out["rows"] += [bennett_row("exudyn", h, reference, **kw) for h in exudyn_steps]
    return out


def bennett_table(result: dict) -> str:
    """:func:`compare_bennett`'s result as text, one line per peer and step."""
    lines = [f"Bennett linkage (spatial, four skew revolute joints), {result['t_end']:g} s "
             "from rest, equal accuracy (largest J1 angle error against the reference, rad)",
             f"{'accuracy':>8}  {'peer':>6}  {header('peer')}  {'path':>6}  peer settings"]
    for r in result["rows"]:
        err = r[f"{r['code']}_error"]
        level = "loose" if err >= 1e-4 else "tight" if err <= 1e-6 else "medium"
        lines.append(f"{level:>8}  {_NAMES[r['code']]:>6}  {columns(r, r['code'])}  "
                     f"{r['path']:>6}  {SETTINGS[r['code']]}")
    lines.append(f"reference: MuJoCo at h {result['reference_step']:.0e}; from cmm_dae at "
                 f"rtol 1e-12 {result['reference_gap']:.1e} rad at most, closed-form "
                 f"residual {result['reference_relation']:.1e}")
    if not result["exudyn"]:
        lines.append("Exudyn is not installed (pip install 'cmm_dae[peers]'): no Exudyn rows")
    lines.append("time ratio: cmm_dae's wall time over the peer's, best of warm runs side by "
                 "side, the peer's model compiled or assembled outside the timing; both "
                 "sampled every max(h, 0.01) s")
    return "\n".join(lines)
