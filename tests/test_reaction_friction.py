"""Friction from the reaction: mu r |F| on a pin, mu |N| on a guide, solved with the motion."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import cmm_dae as cd

G = 9.81

# ------------------------------------------------------------------ a pendulum on a pin
M, L, JC, R, MUS, MUK = 1.0, 0.2, 0.004, 0.05, 0.3, 0.3   # kg, m, kg m^2, m (pin), -, -
JO = JC + M * L * L


def _pin_pendulum() -> cd.Mechanism:
    return cd.from_dict({
        "mechanism": {"name": "pendulum on a pin with friction", "gravity": [0.0, -G]},
        "ground": {"points": {"O": [0.0, 0.0]}},
        "bodies": {"rod": {"mass": M, "inertia": JC, "centroid": [L, 0.0],
                           "points": {"O": [0.0, 0.0]}}},
        "joints": {"O": {"type": "revolute", "connects": ["ground.O", "rod.O"],
                         "friction": {"mu_static": MUS, "mu_kinetic": MUK, "radius": R}}},
        "initial": {"joints": {"O": 0.0}, "velocities": {"O": 0.0}}})


def _alpha(th: float, w: float, s: float) -> float:
    """The angular acceleration with the friction torque mu r |F| it causes: J_O a =
    -m g l cos th - s mu r |F|, F = m (l a e_t - l w^2 e_r) + (0, m g) the pin's force,
    solved exactly by Newton's method at every evaluation."""
    a = -M * G * L * math.cos(th) / JO
    for _ in range(60):
        F = math.sqrt((M * L * a) ** 2 + (M * L * w * w) ** 2 + (M * G) ** 2
                      + 2 * M * M * G * L * (a * math.cos(th) - w * w * math.sin(th)))
        f = JO * a + M * G * L * math.cos(th) + s * MUK * R * F
        fp = JO + s * MUK * R * (M * M * L * L * a + M * M * G * L * math.cos(th)) / F
        step = f / fp
        a -= step
        if abs(step) <= 1e-16 * (1.0 + abs(a)):
            break
    return a


@functools.cache
def _reference(t_end: float):
    """DOP853 (rtol 1e-13) from each turning point to the next; at one the pendulum sticks
    where gravity's torque m g l |cos th| is within mu_s r m g (the pin's reaction at rest
    is its weight), else it swings back."""
    t, th = 0.0, 0.0
    segments, events = [], []
    while t < t_end:
        if L * abs(math.cos(th)) <= MUS * R:
            events.append((t, "stick"))
            segments.append((t, t_end, None, th))
            break
        s = -1.0 if math.cos(th) > 0 else 1.0
        events.append((t, "slip"))

        def turn(_, y):
            return y[1]
        turn.terminal, turn.direction = True, -s
        sol = solve_ivp(lambda _, y, s=s: [y[1], _alpha(y[0], y[1], s)], (t, t_end),
                        [th, 0.0], method="DOP853", rtol=1e-13, atol=1e-15,
                        dense_output=True, events=turn, first_step=1e-6)
        segments.append((t, sol.t[-1], sol.sol, None))
        t, th = sol.t[-1], sol.y[0, -1]
        if sol.status != 1:
            break

    def theta(tq: np.ndarray) -> np.ndarray:
        out = np.empty(tq.size)
        for i, x in enumerate(tq):
            a, b, sol, held = next(sg for sg in segments if sg[0] <= x <= sg[1])
            out[i] = sol(x)[0] if sol is not None else held
        return out
    return theta, events


def test_pendulum_on_a_pin_against_the_implicit_friction_reference():
    """A rod released from the horizontal on a pin of radius 5 cm (mu 0.3): each swing
    loses mu r |F| times its angle, F the pin's reaction, which holds the friction torque
    it causes. Against an ODE reference that solves that implicit friction at every step:
    the angle within 2e-9 rad (measured 4.6e-10), the seven turning points and the stick
    at the eighth (3.437 s) within 1e-9 s (measured 7.6e-11), the energy audit within 1e-8 J
    of about 2 J lost (measured 7.3e-10)."""
    theta, events = _reference(6.0)
    res = cd.run_dae(_pin_pendulum(), 6.0, rtol=1e-11, output_dt=0.01)
    assert [e.kind for e in res.events] == [k for _, k in events]
    assert len(events) == 8 and events[-1][1] == "stick"
    assert max(abs(e.t - x) for e, (x, _) in zip(res.events, events, strict=True)) <= 1e-9
    assert np.max(np.abs(res.joint("O").position - theta(res.t))) <= 2e-9
    e = res.energy()
    assert e.friction_loss[-1] > 1.9 and np.max(np.abs(e.residual)) <= 1e-8
    # while it slips, the friction reported is mu r |F| of the reported reaction
    slipping = res.configuration == res.configuration[1]
    F = np.linalg.norm(res.joint("O").force, axis=1)
    fr = res.joint("O").friction
    assert np.max(np.abs(np.abs(fr[slipping]) - MUK * R * F[slipping])) <= 1e-9


def test_iterative_algorithm_on_the_pin():
    """The paper's fixed-step algorithm (first order) on the same pendulum: the same
    switches up to the stick at 3.437 s, each within 1e-3 s at dt 1e-4 (measured 5e-4),
    the angle within 5e-3 rad. (At dt 1e-3 the last turning point comes out as a slip.)"""
    theta, events = _reference(6.0)
    res = cd.run_iterative(_pin_pendulum(), 3.6, dt=1e-4)
    assert [e.kind for e in res.events] == [k for _, k in events]
    assert max(abs(e.t - x) for e, (x, _) in zip(res.events, events, strict=True)) <= 1e-3
    assert np.max(np.abs(res.joint("O").position - theta(res.t))) <= 5e-3


# ------------------------------------------------------------------ a block on a guide
MB, P, BETA, MUS_B, MUK_B = 2.0, 30.0, math.radians(30.0), 0.5, 0.4


def _block(push: float) -> cd.Mechanism:
    return cd.from_dict({
        "mechanism": {"name": "block on a guide", "gravity": [0.0, -G]},
        "ground": {"points": {"O": [0.0, 0.0]}},
        "bodies": {"block": {"mass": MB, "inertia": 0.01, "points": {"P": [0.0, 0.0]}}},
        "joints": {"X": {"type": "prismatic", "connects": ["ground.O", "block.P"],
                         "axis": [1.0, 0.0],
                         "friction": {"mu_static": MUS_B, "mu_kinetic": MUK_B}}},
        "loads": {"push": {"body": "block", "point": "P", "law": "constant", "value": push,
                           "direction": [math.cos(BETA), -math.sin(BETA)],
                           "frame": "global"}},
        "initial": {"joints": {"X": 0.0}, "velocities": {"X": 0.0}}})


@pytest.mark.parametrize("method", ["ida", "iterative"])
def test_block_pushed_at_an_angle_against_the_closed_form(method):
    """A 2 kg block pushed along a guide by 30 N at 30 deg below the horizontal: the
    guide's normal reaction is the weight plus the push's normal part, N = m g + P sin b,
    and it slides with a = (P cos b - mu_k N) / m. IDA: the position within 1e-12 m of
    x = a t^2 / 2, the friction -mu_k N and the normal reaction N to 1e-9 N; the
    fixed-step algorithm (first order) within 1e-3 m at dt 1e-4."""
    N = MB * G + P * math.sin(BETA)
    a = (P * math.cos(BETA) - MUK_B * N) / MB
    if method == "ida":
        res = cd.run_dae(_block(P), 1.0, rtol=1e-10)
        tol = 1e-12
    else:
        res = cd.run_iterative(_block(P), 1.0, dt=1e-4)
        tol = 1e-3
    assert [(e.kind, e.side) for e in res.events] == [("slip", "positive")]
    x = res.joint("X")
    assert np.max(np.abs(x.position - 0.5 * a * res.t**2)) <= tol
    if method == "ida":
        assert np.max(np.abs(x.friction[1:] + MUK_B * N)) <= 1e-9
        assert np.max(np.abs(x.force[1:, 1] - N)) <= 1e-9
        assert np.max(np.abs(res.energy().residual)) <= 1e-9


def test_block_held_by_static_friction_from_the_reaction():
    """10 N at 30 deg: its 8.66 N along the guide is within mu_s (m g + P sin b) = 12.3 N,
    so the block sticks and the friction holds the push exactly; with constant levels of
    the same size as mu_k N it would not tell the two pushes apart."""
    res = cd.run_dae(_block(10.0), 0.5, rtol=1e-10)
    assert [e.kind for e in res.events] == ["stick"]
    assert np.max(np.abs(res.joint("X").position)) == 0.0
    assert np.max(np.abs(res.joint("X").friction + 10.0 * math.cos(BETA))) <= 1e-9


# ------------------------------------------------------------------ the model file
@pytest.mark.parametrize("friction,key,text", [
    ({"mu_static": 0.2, "mu_kinetic": 0.3, "radius": 0.01}, "friction",
     "mu_static >= mu_kinetic"),
    ({"mu_static": 0.3, "mu_kinetic": 0.2}, "friction.radius", "pin radius > 0"),
    ({"mu_static": 0.3, "mu_kinetic": 0.2, "radius": -0.01}, "friction.radius",
     "got radius = -0.01"),
])
def test_friction_table_errors_name_the_key(friction, key, text):
    """Coefficients out of order, a pin without a radius and a negative radius: each a
    ModelError naming the joint's table, the key and what was expected."""
    d = {"mechanism": {"name": "pin", "gravity": [0.0, -G]},
         "ground": {"points": {"O": [0.0, 0.0]}},
         "bodies": {"rod": {"mass": 1.0, "inertia": 0.01, "centroid": [0.2, 0.0],
                            "points": {"O": [0.0, 0.0]}}},
         "joints": {"O": {"type": "revolute", "connects": ["ground.O", "rod.O"],
                          "friction": friction}}}
    with pytest.raises(cd.ModelError) as e:
        cd.from_dict(d)
    assert "joints.O" in str(e.value) and key in str(e.value) and text in str(e.value)


def test_a_guide_has_no_radius():
    """A prismatic joint's friction from its reaction needs no radius and refuses one; its
    coefficients are parameters for sweeps."""
    d = _block(P)
    bad = cd.from_dict({
        "mechanism": {"name": "b", "gravity": [0.0, -G]},
        "ground": {"points": {"O": [0.0, 0.0]}},
        "bodies": {"block": {"mass": MB, "inertia": 0.01, "points": {"P": [0.0, 0.0]}}},
        "joints": {"X": {"type": "prismatic", "connects": ["ground.O", "block.P"],
                         "axis": [1.0, 0.0], "friction": {"mu_static": 0.5}}}})
    assert bad.joints["X"].friction.from_reaction
    with pytest.raises(cd.ModelError, match="it has no radius"):
        cd.from_dict({
            "mechanism": {"name": "b", "gravity": [0.0, -G]},
            "ground": {"points": {"O": [0.0, 0.0]}},
            "bodies": {"block": {"mass": MB, "inertia": 0.01, "points": {"P": [0.0, 0.0]}}},
            "joints": {"X": {"type": "prismatic", "connects": ["ground.O", "block.P"],
                             "axis": [1.0, 0.0],
                             "friction": {"mu_static": 0.5, "radius": 0.01}}}})
    # a parameter of the mechanism all the same (sweeps, design)
    assert cd.with_params(d, {"joints.X.friction.mu_kinetic": 0.3}).joints["X"].friction \
        .mu_kinetic == 0.3


def test_shipped_double_folded_with_pin_friction():
    """The shipped variant with friction from the reaction in every undriven joint: the
    stop is reached and left as in the frictionless cycle (2.68 s and 7.53 s against 2.63
    and 7.29), joints stick and slip on the way, the driver does 0.18 J more work, nearly
    all of it lost to friction, and the audit closes to 1e-7 J (measured 6e-8)."""
    plain = cd.run_dae(cd.load(cd.example("double_folded")), 10.0)
    res = cd.run_dae(cd.load(cd.example("double_folded_pin_friction")), 10.0)
    assert res.success and sorted(res.meta["frictional"]) == ["B", "C", "D", "E"]
    stop = [(e.kind, round(e.t, 2)) for e in res.events if e.joint == "E"
            and e.kind in ("limit", "release")]
    assert stop == [("limit", 2.68), ("release", 7.53)]
    assert {e.kind for e in res.events} >= {"stick", "slip"}
    e, e0 = res.energy(), plain.energy()
    assert np.max(np.abs(e.residual)) <= 1e-7
    assert e.driver_work[-1] - e0.driver_work[-1] > e.friction_loss[-1] > 0.17


# ------------------------------------------------------------------ sensitivities
def _pushed_block() -> cd.Mechanism:
    """A block on a guide pushed by a harmonic force at an angle: the normal reaction, and
    with it the friction levels, change along the push."""
    return cd.from_dict({
        "mechanism": {"name": "block pushed at an angle", "gravity": [0.0, -G]},
        "ground": {"points": {"O": [0.0, 0.0]}},
        "bodies": {"block": {"mass": 1.0, "inertia": 0.01, "points": {"P": [0.0, 0.0]}}},
        "joints": {"X": {"type": "prismatic", "connects": ["ground.O", "block.P"],
                         "axis": [1.0, 0.0],
                         "friction": {"mu_static": 0.12, "mu_kinetic": 0.08}}},
        "loads": {"push": {"body": "block", "point": "P", "law": "harmonic", "mean": 0.0,
                           "amplitude": 3.0, "frequency": 0.5, "phase": 0.0,
                           "direction": [0.8, -0.6], "frame": "global"}},
        "initial": {"joints": {"X": 0.0}, "velocities": {"X": 0.0}}})


@pytest.mark.parametrize("mech,paths", [
    (_pushed_block(), ["joints.X.friction.mu_static", "joints.X.friction.mu_kinetic"]),
    (cd.with_params(_pin_pendulum(), {"joints.O.friction.mu_static": 0.35}),
     ["joints.O.friction.mu_kinetic", "joints.O.friction.radius"]),
], ids=["block", "pin"])
def test_sensitivities_through_stick_and_slip_against_finite_differences(mech, paths):
    """d t_event / d p through the stick, slip and reversals of friction that grows with
    the reaction (the KKT system's derivative includes the friction's dependence on the
    multipliers, the static threshold its reaction): against central differences (h 1e-5
    relative, runs at rtol 1e-12) within 2e-5 of the largest derivative (measured 1e-7 on
    the block, 7e-6 on the pin's radius, where the differences' noise is that size)."""
    from cmm_dae.description.params import param_value

    s = cd.sensitivities(mech, paths, 4.0, rtol=1e-11)
    kinds = [e.kind for e in s.result.events]
    assert "stick" in kinds and kinds.count("slip") >= 4
    for i, path in enumerate(paths):
        x0 = param_value(mech, path)
        h = 1e-5 * abs(x0)
        ts = [np.array([e.t for e in cd.run_dae(cd.with_params(mech, {path: x}), 4.0,
                                               rtol=1e-12).events]) for x in (x0 + h, x0 - h)]
        fd = (ts[0] - ts[1]) / (2 * h)
        scale = np.max(np.abs(fd))
        assert scale > 0.1
        assert np.max(np.abs(s.event_times[:, i] - fd)) <= 2e-5 * scale
