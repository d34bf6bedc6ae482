"""MuJoCo's IFToMM A02 chain set moving, as :mod:`.peers` times it, and as a script that
times MuJoCo alone in a fresh process (``validation/fresh_process.py`` runs this file by
its path, so that nothing of cmm_dae is imported, or timed, there):

    python mujoco_a02.py N MODEL.xml H      # N loops, the MJCF of peers._a02_xml, 2 s at H

It imports nothing but numpy; MuJoCo, an optional extra, is handed in or imported by the
script."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

__all__ = ["start_state"]


def start_state(mujoco: Any, model: Any, n: int) -> np.ndarray:
    """The full physics state of A02 with ``n`` loops (``model``: MuJoCo's compiled MJCF)
    at its start: the parallelogram turning at 1 rad/s, cranks +1 about y, couplers
    translating."""
    data = mujoco.MjData(model)
    for i in range(n + 1):
        data.qvel[model.joint(f"G{i}").dofadr[0]] = 1.0
        if i:
            data.qvel[model.joint(f"L{i}").dofadr[0]] = -1.0
    mujoco.mj_forward(model, data)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state, spec)
    return state


def _main(argv: list[str]) -> None:
    import mujoco
    from mujoco import rollout

    n, path, h = int(argv[0]), argv[1], float(argv[2])
    model = mujoco.MjModel.from_xml_path(path)
    rollout.rollout(model, mujoco.MjData(model), start_state(mujoco, model, n)[None, :],
                    nstep=int(round(2.0 / h)))


if __name__ == "__main__":
    _main(sys.argv[1:])
