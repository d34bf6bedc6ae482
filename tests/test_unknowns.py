"""IDA's unknowns: a body pinned to the ground is carried by its angle alone.

Checked against things computed without cmm_dae: the minimal-coordinate residual of the
same pendulum on the same IDA (step counts), the exact elliptic solution (positions) and the
rod tension of a point mass released from the horizontal, 3 m g (-y) / L (energy)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

import cmm_dae as cd
from cmm_dae.description import iftomm
from cmm_dae.equations.model import Model

MODELS = Path(__file__).resolve().parents[1] / "models"
G = 9.81


def _minimal_steps(t_end: float, rtol: float, atol: float) -> int:
    """IDA's steps on the angle residual th'' = -g cos(th) (angle from +x), counted as
    cmm_dae counts them, by the step counter of ``validation/iftomm.py``."""
    spec = importlib.util.spec_from_file_location(
        "iftomm_validation", MODELS.parent / "validation" / "iftomm.py")
    val = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(val)

    def res(t, y, yp, r):
        r[0] = yp[0] - y[1]
        r[1] = yp[1] + G * np.cos(y[0])

    grid = np.linspace(0.0, t_end, int(round(t_end / 0.01)) + 1)
    sol, steps = val._ida_on(res, np.zeros(2), np.array([0.0, -G]), grid, rtol, atol)
    assert sol.success
    return steps


def test_a01_takes_the_steps_of_the_minimal_residual():
    """IFToMM A01 over 20 s at rtol 1e-11: cmm_dae's steps within 1.1x those of IDA on
    the minimal residual (measured 0.98x over 50 s; the centroid coordinates took 4.06x),
    the mass within 1e-7 m of the exact solution and the pin's tension (a reaction of
    rows IDA no longer has) within 1e-7 N of 3 m g (-y) / L."""
    mech = cd.load(MODELS / "iftomm_a01_pendulum.toml")
    model = Model(mech)
    assert model.ida.pinned == {"bob": "O"} and model.ida.N == 2  # angle and rate only
    res = cd.run_dae(mech, 20.0, rtol=1e-11, atol=1e-13, model=model)
    ref = _minimal_steps(20.0, 1e-11, 1e-13)
    assert res.stats.steps <= 1.1 * ref, (res.stats.steps, ref)
    P = res.body("bob").pose  # the frame at the pivot, the mass 1 m along it
    xy = P[:, :2] + np.column_stack([np.cos(P[:, 2]), np.sin(P[:, 2])])
    assert np.max(np.hypot(*(xy - iftomm.a01_reference(res.t)).T)) <= 1e-7
    tension = np.hypot(*res.joint("O").force.T)
    # of up to 29.4 N; measured 3.4e-8 N
    assert np.max(np.abs(tension - 3.0 * 1.0 * G * (-xy[:, 1]) / 1.0)) <= 1e-7


def test_centroid_coordinates_still_available_and_agree():
    """The same run with every body in centroid coordinates (``pinned_angles=False``):
    the same motion to the tolerance (rtol 1e-10: within 1e-7 m after 3 s)."""
    mech = cd.load(MODELS / "iftomm_a01_pendulum.toml")
    a = cd.run_dae(mech, 3.0, rtol=1e-10, output_dt=0.01)
    b = cd.run_dae(mech, 3.0, rtol=1e-10, output_dt=0.01,
                   model=Model(mech, pinned_angles=False))
    assert b.stats.steps > 2 * a.stats.steps  # the centroid run's extra steps
    assert np.max(np.abs(a.body("bob").pose - b.body("bob").pose)) <= 1e-7


def test_a_driven_pin_stays_in_centroid_coordinates():
    """A ground joint with a driver keeps its body in centroid coordinates (its angle is
    prescribed); the double-folded cycle's other bodies have no ground pin. Its IDA
    unknowns are the model's plus the two works it has (the driver's and the dampers')."""
    model = Model(cd.load(MODELS / "double_folded.toml"))
    assert not model.ida.reduced and model.ida.powered == (0, 2)
    assert model.ida.N == model.N + 2


def test_redundant_set_keeps_the_pins_rows():
    """A02 with a third crank on a parallelogram (redundant): the dropped row is not one of
    a pin's, so every crank is carried by its angle."""
    mech = iftomm.a02_four_bar(2)
    from cmm_dae.hybrid.start import redundant_base_rows

    model = Model(mech)
    drop = redundant_base_rows(model)
    pins = {r.name for r in model.all_rows if r.name.startswith("G")}
    assert all(model.all_rows[i].name not in pins for i in drop)
    m2 = Model(mech, drop=drop)
    assert set(m2.ida.pinned) == {"crank0", "crank1", "crank2"}
