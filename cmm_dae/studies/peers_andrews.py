"""cmm_dae against MuJoCo on Andrews' squeezing mechanism at equal accuracy (part of
``cmm-dae bench --peers``).

The problem is the stiff benchmark of Hairer & Wanner (the Test Set for IVP Solvers'
"andrews", IFToMM A03; the shipped model ``andrews_squeezer``): seven bodies, three loops
closed at point E, a motor torque of 0.033 N m and a spring of 4530 N/m, 0.03 s from
rest. The error of either code is the largest difference of its seven coordinates at
0.03 s from the Test Set's reference values (rad).

MuJoCo is set up as its users would: the seven bodies as a tree of hinges about z (K1-K2,
K3, K5-K4, K7-K6 from the ground), point E of K2 tied to E of K3, K4 and K6 by soft
``connect`` equalities of time constant 2 h, the spring a spatial tendon, the motor an
applied joint force, RK4 at the fixed step h. The bodies are defined in their initial
posture, so that the hinges start at zero and the equalities hold there.
"""

from __future__ import annotations

from ..description.library import example
from ..description.loader import load
from ..description.mechanism import Mechanism
from ..simulation.runner import run_dae
from .bench import best_times
from .peers import COLUMNS, RATIO_NOTE, RTOLS, SOLIMP, _mujoco, cheapest, columns

__all__ = ["ANDREWS_003", "ANDREWS_Y0", "andrews_mujoco", "andrews_table",
           "compare_andrews"]

#: The benchmark's initial coordinates (rad; all rates zero): the Test Set's y(0).
ANDREWS_Y0 = {"beta": -0.0617138900142764496358948458001, "Theta": 0.0,
              "gamma": 0.455279819163070380255912382449,
              "Phi": 0.222668390165885884674473185609,
              "delta": 0.487364979543842550225598953530,
              "Omega": -0.222668390165885884674473185609,
              "epsilon": 1.23054744454982119249735015568}
#: The Test Set's reference y(0.03) (PSIDE at tolerance 1e-14), rad.
ANDREWS_003 = {"beta": 0.1581077119629904e2, "Theta": -0.1575637105984298e2,
               "gamma": 0.4082224013073101e-1, "Phi": -0.5347301163226948,
               "delta": 0.5244099658805304, "Omega": 0.5347301163226948,
               "epsilon": 0.1048080741042263e1}
#: (body, joint, parent body or "" for the ground, where its joint sits on the parent)
_TREE = (("K1", "beta", "", "O"), ("K2", "Theta", "K1", "P"), ("K3", "gamma", "", "B"),
         ("K5", "delta", "", "A"), ("K4", "Phi", "K5", "F"), ("K7", "epsilon", "", "A"),
         ("K6", "Omega", "K7", "G"))


def _xml(mech: Mechanism, h: float) -> str:
    """MJCF of the squeezer at step ``h`` (see the module's text)."""
    def site(name: str, xy) -> str:
        return f'<site name="{name}" pos="{xy[0]!r} {xy[1]!r} 0"/>'

    sites = {"K2": site("E2", mech.bodies["K2"].points["E"]),
             "K3": site("E3", mech.bodies["K3"].points["E"])
             + site("D", mech.bodies["K3"].points["D"]),
             "K4": site("E4", mech.bodies["K4"].points["E"]),
             "K6": site("E6", mech.bodies["K6"].points["E"])}
    xml: dict[str, str] = {}
    for body, joint, parent, at in reversed(_TREE):  # children first
        b = mech.bodies[body]
        pos = mech.ground[at] if not parent else mech.bodies[parent].points[at]
        inner = "".join(xml.pop(c) for c, _, p, _ in _TREE if p == body)
        xml[body] = (f'<body name="{body}" pos="{pos[0]!r} {pos[1]!r} 0" '
                     f'euler="0 0 {ANDREWS_Y0[joint]!r}">'
                     f'<joint name="{joint}" type="hinge" axis="0 0 1"/>'
                     f'<inertial pos="{b.centroid[0]!r} {b.centroid[1]!r} 0" mass="{b.mass!r}" '
                     f'diaginertia="{b.inertia!r} {b.inertia!r} {b.inertia!r}"/>'
                     f'{sites.get(body, "")}{inner}</body>')
    spring = mech.elements["spring"]
    soft = f'solref="{2 * h!r} 1" solimp="{SOLIMP}"'
    closures = "".join(f'<connect site1="E2" site2="{s}" {soft}/>' for s in ("E3", "E4", "E6"))
    return (f'<mujoco><compiler angle="radian"/>'
            f'<option timestep="{h!r}" integrator="RK4" gravity="0 0 0"/>'
            f'<worldbody>{site("C", mech.ground["C"])}{"".join(xml.values())}</worldbody>'
            f'<tendon><spatial stiffness="{spring.stiffness!r}" '
            f'springlength="{spring.rest!r}"><site site="C"/><site site="D"/></spatial>'
            f'</tendon><equality>{closures}</equality></mujoco>')


def andrews_mujoco_prepared(h: float, t_end: float = 0.03):
    """The squeezer in MuJoCo at step ``h``, compiled now (outside any timing, as cmm_dae's
    build is): a function that runs it for ``t_end`` s (its steps in one ``mj_step`` call)
    and returns its seven coordinates at the end (rad, the benchmark's: absolute for K1,
    K3, K5, K7, relative for K2, K4, K6)."""
    mujoco = _mujoco()
    mech = load(example("andrews_squeezer"))
    model = mujoco.MjModel.from_xml_string(_xml(mech, h))
    steps = int(round(t_end / h))

    def run() -> dict[str, float]:
        data = mujoco.MjData(model)
        data.qfrc_applied[model.joint("beta").dofadr[0]] = mech.loads["motor"].law.value
        mujoco.mj_step(model, data, nstep=steps)
        return {j: ANDREWS_Y0[j] + float(data.qpos[model.joint(j).qposadr[0]])
                for j in ANDREWS_Y0}
    return run


def andrews_mujoco(h: float, t_end: float = 0.03) -> dict[str, float]:
    """The squeezer in MuJoCo for ``t_end`` s at step ``h`` (compiled and run): its seven
    coordinates at the end (rad, as :func:`andrews_mujoco_prepared`)."""
    return andrews_mujoco_prepared(h, t_end)()


def _error(y: dict[str, float]) -> float:
    return max(abs(y[k] - v) for k, v in ANDREWS_003.items())


def compare_andrews(h: float, *, repeat: int = 3, rtols: tuple[float, ...] = RTOLS
                    ) -> dict:
    """One row of the comparison on the squeezer: MuJoCo at step ``h`` (its error, rad,
    and best wall time, s) and cmm_dae at the loosest of ``rtols`` whose error is no
    larger (``rtol`` None where none is), side by side; ``ratio`` = cmm_dae's time over
    MuJoCo's (above 1: MuJoCo is faster)."""
    mech = load(example("andrews_squeezer"))
    mujoco_run = andrews_mujoco_prepared(h)  # compiled outside the timing
    err_mj = _error(mujoco_run())

    def error_at(rtol: float) -> float | None:  # None: too loose for the stiff spring
        res = run_dae(mech, 0.03, rtol=rtol, output_dt=None, throw=False)
        return (_error({k: float(res.joint(k).position[-1]) for k in ANDREWS_003})
                if res.success else None)

    chosen, err = cheapest(error_at, err_mj, rtols)
    row = {"h": h, "mujoco_error": err_mj, "rtol": chosen, "cmm_dae_error": err}
    (row["mujoco_s"], _), (row["cmm_dae_s"], _) = best_times(  # the runs alternating
        [mujoco_run,
         None if chosen is None else lambda: run_dae(mech, 0.03, rtol=chosen, output_dt=None)],
        repeat)
    row["ratio"] = row["cmm_dae_s"] / row["mujoco_s"]
    return row


def andrews_table(rows: list[dict]) -> str:
    """The squeezer's comparison as text, one line per MuJoCo step."""
    lines = ["Andrews' squeezer, 0.03 s, equal accuracy (largest error of the seven "
             "coordinates at 0.03 s against the Test Set, rad)",
             COLUMNS]
    lines += [columns(r) for r in rows]
    lines.append(RATIO_NOTE)
    return "\n".join(lines)
