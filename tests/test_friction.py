"""Dry friction (stick/slip, event-located) against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

import cmm_dae as cd

from refs import for_method

MASS, AMP, HZ, FS, FK = 1.0, 2.0, 0.5, 1.0, 0.6
W = 2 * math.pi * HZ


def block(static=FS, kinetic=FK) -> cd.Mechanism:
    """A block on a horizontal rail (prismatic joint X), pushed along it by a harmonic
    force; dry friction in the rail."""
    body = cd.Body("block", MASS, 0.01, (0, 0), {"P": (0, 0)}, guess=(0, 0, 0))
    rail = cd.Joint("X", "prismatic", "ground.O", "block.P", axis=(1.0, 0.0),
                    friction=cd.Friction(static, kinetic))
    push = cd.Load("push", cd.Law("harmonic", amplitude=AMP, frequency=HZ), joint="X")
    return cd.Mechanism("stick-slip block", [body], [rail], ground={"O": (0, 0)},
                        initial=cd.Initial({"X": 0.0}, {"X": 0.0}), loads=[push])


def closed_form(t_end: float) -> list[tuple[str, float]]:
    """Switches of the block: stuck while |F| <= Fs, sliding against Fk otherwise, with
    the velocity of each slide in closed form, its zero found by brentq; at a zero it
    sticks if |F| <= Fs there, else it slides back the other way."""
    F = lambda t: AMP * math.sin(W * t)  # noqa: E731
    out, t, sliding = [("stick", 0.0)], 0.0, False
    while True:
        if not sliding:  # stuck from t: slip when |F| reaches Fs
            grid = np.linspace(t, t_end, 20001)
            over = np.flatnonzero(np.abs(AMP * np.sin(W * grid)) > FS)
            if over.size == 0:
                return out
            i = over[0]
            t = brentq(lambda x: abs(F(x)) - FS, grid[i - 1], grid[i], xtol=1e-15)
        s = 1.0 if F(t) > 0 else -1.0
        out.append(("slip", t))

        def v(x, ts=t, s=s):  # m v' = F - Fk s from rest at ts
            return (AMP / W * (math.cos(W * ts) - math.cos(W * x)) - FK * s * (x - ts)) / MASS

        grid = np.linspace(t + 1e-9, t_end, 20001)
        zero = np.flatnonzero(s * np.array([v(x) for x in grid]) <= 0.0)
        if zero.size == 0:
            return out
        j = zero[0]
        t = brentq(v, grid[j - 1], grid[j], xtol=1e-15)
        sliding = abs(F(t)) > FS
        if not sliding:
            out.append(("stick", t))


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_stick_slip_block_against_closed_form(method):
    ref = closed_form(4.0)
    assert len(ref) >= 5
    dt = 1e-3
    res = cd.simulate(block(), 4.0, method=method,
                      **for_method(method, rtol=1e-11, atol=1e-13, dt=dt))
    got = [(e.kind, e.t) for e in res.events]
    assert [k for k, _ in got] == [k for k, _ in ref]
    err = np.abs(np.array([t for _, t in got]) - np.array([t for _, t in ref]))
    if method == "ida":
        assert np.max(err) <= 1e-9
        # audit: the push's work = kinetic energy + friction loss
        fine = cd.simulate(block(), 4.0, rtol=1e-11, atol=1e-13, output_dt=1e-3)
        assert np.max(np.abs(fine.energy().residual)) <= 1e-8
        assert fine.energy().friction_loss[-1] > 0.1
    else:  # switches at the end of the crossing step, first order
        assert np.max(err) <= 3 * dt
    # the friction series: the force carried while stuck, -Fk sign(v) while slipping
    fr, vel = res.joint("X").friction, res.joint("X").velocity
    # the fixed-step run keeps the sample at the end of the step that crossed a switch
    # (stuck beyond Fs, or the old slip direction with the reversed rate): off by at most
    # one step's change of the push or of the rate
    moving = np.abs(vel) > (1e-6 if method == "ida" else (AMP + FK) / MASS * dt)
    over = 1e-9 if method == "ida" else AMP * W * dt
    assert np.all(np.abs(fr) <= FS + over)
    assert np.allclose(fr[moving], -FK * np.sign(vel[moving]), rtol=0, atol=1e-12)
    stuck = res.t < ref[1][1] - 1e-3
    assert np.allclose(fr[stuck], -AMP * np.sin(W * res.t[stuck]), atol=1e-9)


def test_shipped_stick_slip_model_is_this_block():
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "models" / "stick_slip_block.toml"
    res = cd.run_dae(cd.load(path), 4.0, rtol=1e-11, atol=1e-13)
    ref = closed_form(4.0)
    assert [e.kind for e in res.events] == [k for k, _ in ref]
    assert max(abs(e.t - t) for e, (_, t) in zip(res.events, ref, strict=True)) <= 1e-9


def test_friction_input_errors(tmp_path):
    with pytest.raises(cd.ModelError, match=r"\[joints\.X\] friction: expected static >= "
                       r"kinetic >= 0 \(N\), got static = 0\.5, kinetic = 0\.6"):
        block(0.5, 0.6)
    with pytest.raises(cd.ModelError, match=r"kinetic >= 0"):
        block(1.0, -0.1)
