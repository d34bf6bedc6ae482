"""Point masses (inertia 0) where the joints fix the body's rotation: the IFToMM A01
pendulum against its exact elliptic-function solution; a free massless rotation refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipj, ellipk

import cmm_dae as cd

G, L = 9.81, 1.0


def a01_pendulum() -> cd.Mechanism:
    """1 kg point mass on a massless 1 m rod, released from the horizontal (IFToMM A01)."""
    bob = cd.Body("bob", 1.0, 0.0, (L, 0.0), {"O": (0.0, 0.0)}, guess=(0.0, 0.0, 0.0))
    pivot = cd.Joint("O", "revolute", "ground.O", "bob.O")
    return cd.Mechanism("A01 pendulum", [bob], [pivot], ground={"O": (0.0, 0.0)},
                        gravity=(0.0, -G), initial=cd.Initial({"O": 0.0}, {"O": 0.0}))


def exact_angle(t: np.ndarray) -> np.ndarray:
    """Released at rest from the horizontal: amplitude pi/2 about the bottom, so
    sin(phi/2) = k sn(K - sqrt(g/L) t, k) with k = sin(pi/4) (phi from the bottom)."""
    k = math.sin(math.pi / 4)
    sn = ellipj(ellipk(k**2) - math.sqrt(G / L) * t, k**2)[0]
    return -math.pi / 2 + 2 * np.arcsin(k * sn)


def test_a01_point_mass_against_the_exact_solution():
    res = cd.run_dae(a01_pendulum(), 10.0, rtol=1e-11, atol=1e-13)
    assert res.success
    err = np.max(np.abs(res.joint("O").position - exact_angle(res.t)))
    assert err <= 1e-7
    e = res.energy()
    assert np.max(np.abs(e.kinetic + e.potential - e.potential[0])) <= 1e-8
    # the tip, the benchmark's reference point: (L cos, L sin) of the angle
    tip = res.body("bob").pose[:, :2] + L * np.column_stack(
        [np.cos(res.joint("O").position), np.sin(res.joint("O").position)])
    assert np.max(np.abs(tip - L * np.column_stack([np.cos(exact_angle(res.t)),
                                                    np.sin(exact_angle(res.t))]))) <= 1e-7


def test_default_atol_follows_rtol_on_a01():
    """atol defaults to 1e-2 of rtol: a fixed 1e-10 capped the accuracy where a coordinate
    passes zero (over 50 s at rtol 1e-11: 1.47e-6 m with atol 1e-10; measured 2.14e-7 m
    with the default, 1e-13). Reference: the exact elliptic solution."""
    res = cd.run_dae(a01_pendulum(), 50.0, rtol=1e-11, output_dt=0.1)
    assert res.meta["tolerances"]["atol"] == pytest.approx(1e-13, rel=1e-12)
    tip = L * np.column_stack([np.cos(res.joint("O").position),
                               np.sin(res.joint("O").position)])
    ref = L * np.column_stack([np.cos(exact_angle(res.t)), np.sin(exact_angle(res.t))])
    assert np.max(np.hypot(*(tip - ref).T)) <= 5e-7
    # an explicit atol is kept; the default rtol gives the former 1e-10
    assert cd.run_dae(a01_pendulum(), 0.1, atol=1e-9).meta["tolerances"]["atol"] == 1e-9
    assert cd.run_dae(a01_pendulum(), 0.1).meta["tolerances"]["atol"] == pytest.approx(1e-10)


def test_a01_with_the_iterative_algorithm():
    res = cd.run_iterative(a01_pendulum(), 1.0, dt=1e-4, output_every=100)
    assert np.max(np.abs(res.joint("O").position - exact_angle(res.t))) <= 5e-3


def test_free_massless_rotation_is_refused():
    """A point mass hanging from a moving body by one revolute joint: nothing fixes its
    angle and it has no inertia, so its acceleration is undetermined."""
    arm = cd.Body("arm", 1.0, 0.1, (0.5, 0.0), {"O": (0, 0), "T": (1.0, 0.0)})
    bob = cd.Body("bob", 0.2, 0.0, (0.0, 0.0), {"P": (0.0, 0.0)}, guess=(1.0, 0.0, 0.0))
    mech = cd.Mechanism("arm and bob", [arm, bob],
                        [cd.Joint("O", "revolute", "ground.O", "arm.O"),
                         cd.Joint("P", "revolute", "arm.T", "bob.P")],
                        ground={"O": (0, 0)}, initial=cd.Initial({"O": 0.0, "P": 0.0}))
    with pytest.raises(cd.AssemblyError, match=r"rotation of point mass 'bob' \(inertia 0\) "
                       r"is not fixed by its joints"):
        cd.run_dae(mech, 0.1)
