"""Spatial mechanisms against independent references: the spherical pendulum's
minimal-coordinate equations, the Bennett linkage's closed-form input-output relation,
planar mechanisms written as spatial files against the planar model, energy balance, and
the checks of bad spatial input."""

from pathlib import Path

import numpy as np
import pytest
import spatial_refs
from scipy.spatial.transform import Rotation

import cmm_dae as cd
from cmm_dae.core.errors import ModelError

pytestmark = pytest.mark.timeout(120)

HERE = Path(__file__).parent
G = 9.81


def test_spherical_pendulum_follows_its_minimal_coordinate_equations():
    mech = cd.load(cd.example("spherical_pendulum"))
    res = cd.run_dae(mech, t_end=5.0, rtol=1e-10)
    assert res.status == "success"
    bob = mech.bodies["bob"]
    r_ref, a_ref = spatial_refs.pendulum(bob.mass, bob.inertia[0], res.t)
    centroid = res.data["q"][:, :3]
    assert np.max(np.abs(centroid - r_ref)) < 1e-8  # m (measured 9e-10 over 10 s)
    # the pivot's force on the bob is m (a - g) (Newton for the centroid), its moment zero
    F = res.joint("O").force
    g = np.array([0.0, 0.0, -G])
    assert np.max(np.abs(F - mech.bodies["bob"].mass * (a_ref - g))) < 1e-6  # N, of 10
    assert np.max(np.abs(res.joint("O").torque)) < 1e-9
    e = res.energy()
    assert np.max(np.abs(e.residual)) < 1e-8  # J


def test_body_pose_is_its_frame_as_a_unit_quaternion():
    mech = cd.load(cd.example("bennett_linkage"))
    res = cd.run_dae(mech, t_end=0.5, rtol=1e-10)
    for i, name in enumerate(res.layout.bodies):
        pose = res.body(name).pose
        assert np.allclose(np.linalg.norm(pose[:, 3:], axis=1), 1.0, rtol=0, atol=1e-14)
        E = res.data["q"][:, 12 * i + 3:12 * i + 12].reshape(-1, 3, 3)  # rows: axes
        # scipy's quaternions are (x, y, z, w); the body axes here are principal ones
        R = Rotation.from_quat(np.column_stack([pose[:, 4:], pose[:, 3]])).as_matrix()
        assert np.max(np.abs(R - E.transpose(0, 2, 1))) < 1e-9  # (unit vectors)
        c = np.array(mech.bodies[name].centroid)  # (R orthonormal, E so to 1e-9)
        assert np.max(np.abs(pose[:, :3] + R @ c - res.data["q"][:, 12 * i:12 * i + 3])) \
            < 1e-12


def test_bennett_linkage_keeps_its_closed_form_relation_and_its_energy():
    mech = cd.load(cd.example("bennett_linkage"))
    res = cd.run_dae(mech, t_end=10.0, rtol=1e-10)
    assert res.status == "success" and not res.events
    th1 = res.joint("J1").position
    rel = spatial_refs.bennett(th1, res.joint("J2").position)
    assert np.max(np.abs(rel)) < 1e-10  # (measured 7e-12)
    assert np.ptp(th1) > 0.7  # it swings (1 -> 0.29 rad)
    assert np.max(np.abs(res.energy().residual)) < 1e-8  # J (measured 5e-10)
    # 36 coordinates, 18 body rows, 20 joint rows, mobility 1: 3 rows redundant
    assert len(res.layout.redundant) == 3
    assert res.configurations[0].dof == 1


def _planar_vs_spatial(planar, spatial, t_end):
    # (at rtol 1e-12: both within 1e-10 of the motion, so of each other)
    a = cd.run_dae(cd.load(planar), t_end=t_end, rtol=1e-12)
    b = cd.run_dae(cd.load(spatial), t_end=t_end, rtol=1e-12)
    assert a.t.size == b.t.size and np.max(np.abs(a.t - b.t)) < 1e-8  # (event instants)
    for i, _ in enumerate(a.layout.bodies):
        qa, qb = a.data["q"][:, 3 * i:3 * i + 3], b.data["q"][:, 12 * i:12 * i + 12]
        assert np.max(np.abs(qa[:, :2] - qb[:, :2])) < 1e-10  # m
        assert np.max(np.abs(qb[:, 2])) < 1e-14  # stays in its plane
        th = np.arctan2(qb[:, 4], qb[:, 3])
        assert np.max(np.abs(np.angle(np.exp(1j * (th - qa[:, 2]))))) < 1e-9  # rad
    for j in a.layout.joints:
        fa, fb = a.joint(j).force, b.joint(j).force
        assert np.max(np.abs(fa - fb[:, :2])) < 1e-9 * max(1.0, np.max(np.abs(fa)))
        assert np.max(np.abs(a.joint(j).torque - b.joint(j).torque[:, 2])) < 1e-12
    return a, b


def test_a_planar_four_bar_written_in_space_gives_the_planar_results():
    a, b = _planar_vs_spatial(cd.example("four_bar"), cd.example("four_bar_spatial"), 2.0)
    assert np.max(np.abs(a.driver("A").effort - b.driver("A").effort)) < 1e-10  # N m
    assert len(b.layout.redundant) == 3  # the loop's out-of-plane closure


def test_a_spatial_stop_locks_as_the_planar_one():
    a, b = _planar_vs_spatial(cd.example("pendulum_stop"),
                              HERE / "models" / "pendulum_stop_spatial.toml", 1.0)
    (ea,), (eb,) = a.events, b.events
    assert ea.kind == eb.kind == "limit" and abs(ea.t - eb.t) < 1e-8  # s
    assert b.configurations[-1].dof == 0


def test_c_and_python_paths_agree_bit_for_bit_in_space(module_cache):
    mech = cd.load(cd.example("bennett_linkage"))
    py = cd.run_dae(mech, t_end=1.0, rtol=1e-10, compiled=False)
    c = cd.run_dae(mech, t_end=1.0, rtol=1e-10, compiled=True)
    assert c.meta["compiled"] and not py.meta["compiled"]
    assert np.array_equal(py.data["q"], c.data["q"])
    assert py.stats.steps == c.stats.steps


def test_fixed_step_algorithm_in_space():
    mech = cd.load(cd.example("bennett_linkage"))
    ida = cd.run_dae(mech, t_end=1.0, rtol=1e-12)
    errs = []
    for dt in (1e-3, 1e-4):
        it = cd.run_iterative(mech, t_end=1.0, dt=dt)
        k = np.searchsorted(it.t, 1.0 - 1e-9)
        errs.append(abs(it.joint("J1").position[k] - ida.joint("J1").position[-1]))
    assert errs[1] < errs[0] / 5  # first order, as in the plane (measured 10x)


def test_fixed_step_algorithm_advances_natural_coordinates_where_joints_have_none():
    """A ball joint's rotation has no joint coordinate: the step advances three of the
    bob's natural coordinates, chosen anew as they stop spanning its motion, and converges
    at first order on the spherical pendulum's equations over 2 s (two choices)."""
    mech = cd.load(cd.example("spherical_pendulum"))
    bob = mech.bodies["bob"]
    errs = []
    for dt in (2e-3, 2e-4):
        res = cd.run_iterative(mech, 2.0, dt=dt)
        assert res.status == "success"
        k = np.searchsorted(res.t, [0.5, 1.0, 1.5, 2.0 - 1e-9])
        ref, _ = spatial_refs.pendulum(bob.mass, bob.inertia[0], res.t[k])
        errs.append(np.max(np.abs(res.data["q"][k, :3] - ref)))
    assert errs[1] < errs[0] / 5 and errs[1] < 4e-3  # m (measured 3.07e-2 -> 2.23e-3)


BAD = {
    "axis of zero length": ('axes = { z = [0.0, 0.0, 1.0], x = [1.0, 0.0, 0.0] }',
                            'axes = { z = [0.0, 0.0, 0.0], x = [1.0, 0.0, 0.0] }',
                            "[ground] axes.z: expected a non-zero direction"),
    "inertia not positive definite": ("inertia = [1.0e-5, 3.0e-3, 3.0e-3]",
                                      "inertia = [1.0e-5, 3.0e-3, 3.0e-3, 0.01, 0.0, 0.0]",
                                      "[bodies.rod] inertia: the tensor is not positive"),
    "no such rigid body": ("inertia = [1.0e-5, 3.0e-3, 3.0e-3]",
                           "inertia = [1.0e-5, 3.0e-3, 1.0e-3]",
                           "[bodies.rod] inertia: a principal moment is not below"),
    "limit on a spherical joint": ('type = "revolute"', 'type = "spherical"',
                                   "[joints.O] limits: a spherical joint has no coordinate"),
    "a point in the plane": ("tip = [0.3, 0.0, 0.0]", "tip = [0.3, 0.0]",
                             "[bodies.rod.points] tip: expected a list of 3 numbers"),
    "an unknown axis": ('axis = ["ground.z", "rod.z"]', 'axis = ["ground.z", "rod.w"]',
                        "[joints.O] axis: body 'rod' has no axis 'w' (its axes: z, x)"),
    "a planar key": ('axis = ["ground.z", "rod.z"]',
                     'axis = ["ground.z", "rod.z"]\nangle = 0.1',
                     "[joints.O] angle: planar only"),
    "a restitution above 1": ("restitution = 0.0", "restitution = 2.0",
                              "[joints.O] restitution: expected a number in [0, 1]"),
    "a reference along the axis": ('axis = ["ground.z", "rod.z"]',
                                   'axis = ["ground.z", "rod.z"]\nreference = ["ground.z", '
                                   '"rod.x"]', "[joints.O] reference: 'ground.z' is parallel"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_spatial_input_names_the_key(case, tmp_path):
    old, new, message = BAD[case]
    text = (HERE / "models" / "pendulum_stop_spatial.toml").read_text()
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ModelError) as err:
        cd.load(path)
    assert message in str(err.value) and str(path) in str(err.value)


def test_universal_joint_with_parallel_arms_is_refused(tmp_path):
    text = (HERE / "models" / "pendulum_stop_spatial.toml").read_text()
    text = text.replace('type = "revolute"', 'type = "universal"').replace(
        'axis = ["ground.z", "rod.z"]', 'axes = ["ground.z", "rod.z"]').replace(
        "limits = { lower = -0.6 }\nrestitution = 0.0\n", "").replace(
        "[initial]\njoints = { O = 0.3 }\nvelocities = { O = 0.0 }\n", "")
    path = tmp_path / "universal.toml"
    path.write_text(text)
    with pytest.raises(ModelError, match=r"\[joints.O\] axes: the two arms are parallel"):
        cd.load(path)
    path.write_text(text.replace('axes = ["ground.z", "rod.z"]', 'axes = ["ground.z", "rod.x"]'))
    assert cd.load(path).joints["O"].rows == 4


def test_spatial_keys_in_a_planar_file_are_refused(tmp_path):
    text = cd.example("pendulum_stop").read_text()
    path = tmp_path / "planar.toml"
    path.write_text(text.replace('connects = ["ground.O", "rod.O"]',
                                 'connects = ["ground.O", "rod.O"]\nreference = ["a", "b"]'))
    with pytest.raises(ModelError, match=r"\[joints.O\] reference: spatial mechanisms only"):
        cd.load(path)


def test_rsur_four_bar_follows_its_closed_form_positions_and_energy():
    res = cd.run_dae(cd.load(cd.example("rsur_four_bar")), t_end=3.0, rtol=1e-10)
    th, ph = res.joint("A").position, res.joint("D").position
    ref = spatial_refs.rsur(th, ph)
    assert np.max(np.abs(np.angle(np.exp(1j * (ref - ph))))) < 1e-9  # rad (4e-11)
    assert np.ptp(th) > 6.0 and np.ptp(ph) > 1.5  # the crank turns, the rocker rocks
    assert np.max(np.abs(res.energy().residual)) < 1e-8  # J (measured 7e-9)
    assert not res.layout.redundant and res.configurations[0].dof == 1


def test_carton_fold_locks_into_a_spherical_four_bar():
    """The flap's crease E meets its stop and locks: mobility 2 -> 1, and the driven
    four-bar left then follows the spherical four-bar's closed form (its coupler arc the
    flap's and the coupler panel's, folded at the stop)."""
    mech = cd.load(cd.example("carton_fold"))
    res = cd.run_dae(mech, t_end=4.0, rtol=1e-10)
    assert res.status == "success"
    (lock,) = res.events
    assert lock.kind == "limit" and lock.joint == "E"
    assert [c.dof for c in res.configurations] == [2, 1]
    tight = cd.run_dae(mech, t_end=0.2, rtol=1e-12)
    assert abs(tight.events[0].t - lock.t) < 1e-9  # s (rtol 1e-10 against 1e-12)
    after = res.t > lock.t + 1e-9
    ph = res.joint("D").position[after]
    ref = spatial_refs.carton_locked(res.joint("A").position[after], ph)
    assert np.max(np.abs(ref - ph)) < 1e-9  # rad (measured 1.2e-11)
    assert np.max(np.abs(res.energy().residual)) < 1e-8  # J, the lock's loss booked


@pytest.mark.parametrize(("name", "mobility", "redundant"), [
    ("bennett_linkage", 1, 3), ("carton_fold", 2, 3), ("rsur_four_bar", 1, 0),
    ("spherical_pendulum", 3, 0), ("four_bar_spatial", 1, 3)])
def test_spatial_structure_is_the_rank_deficit(name, mobility, redundant):
    st = cd.structure(cd.load(cd.example(name)))
    # by hand: Bennett 4R (Grübler -2), a spherical 5R (2), RSUR 6 * 3 - 5 - 3 - 4 - 5,
    # the ball joint's 3, a four-bar whose parallel axes repeat its plane 3 times
    assert st.mobility == mobility and len(st.redundant) == redundant
    assert all(r.startswith("joint ") for r in st.redundant)
    assert f"mobility (rank of the constraint Jacobian at the start, drivers removed): " \
        f"{mobility}" in str(st)


def test_sensitivities_through_a_spatial_lock_agree_with_central_differences():
    mech = cd.load(cd.example("carton_fold"))
    params = ["joints.E.limits.lower", "bodies.L2.mass", "bodies.L3.inertia.zz"]
    sens = cd.sensitivities(mech, params, 0.3, rtol=1e-10)
    res = sens.result
    assert [e.kind for e in res.events] == ["limit"]
    for i, path in enumerate(params):
        v0 = sens.values[i]
        h = 1e-4 * abs(v0)  # central differences of runs at rtol 1e-12
        up, down = (cd.run_dae(cd.with_params(mech, {path: v0 + s * h}), t_end=0.3,
                               rtol=1e-12) for s in (1, -1))
        fd = (up.events[0].t - down.events[0].t) / (2 * h)
        assert abs(sens.event_times[0, i] - fd) < 1e-5 * abs(fd)  # (measured 3e-6 at most)
        for j in ("B", "E", "D"):
            fdj = (up.joint(j).position - down.joint(j).position) / (2 * h)
            ex = sens.joint(j).position[:, i]
            away = res.away_from_events(res.t, 0.01)
            assert np.max(np.abs(ex - fdj)[away]) < 1e-5 * np.max(np.abs(fdj))
    # its reactions are shared out over 3 redundant rows at minimum norm: not derived
    assert np.isnan(sens.joint("D").force).all() and "redundant" in sens.notes[0]


def test_force_sensitivities_through_a_spatial_stop_agree_with_central_differences():
    mech = cd.load(HERE / "models" / "pendulum_stop_spatial.toml")
    params = ["joints.O.limits.lower", "bodies.rod.mass"]
    sens = cd.sensitivities(mech, params, 0.5, rtol=1e-10)
    res = sens.result
    away = res.away_from_events(res.t, 0.01)
    for i, path in enumerate(params):
        v0 = sens.values[i]
        h = 1e-4 * abs(v0)
        up, down = (cd.run_dae(cd.with_params(mech, {path: v0 + s * h}), t_end=0.5,
                               rtol=1e-12) for s in (1, -1))
        for key in ("force", "torque"):
            fd = (getattr(up.joint("O"), key) - getattr(down.joint("O"), key)) / (2 * h)
            ex = getattr(sens.joint("O"), key)[..., i]
            assert np.max(np.abs(ex - fd)[away]) < 1e-6 * max(1.0, np.max(np.abs(fd)))


@pytest.mark.parametrize("name", ["spherical_pendulum", "bennett_linkage", "four_bar_spatial",
                                  "rsur_four_bar", "carton_fold"])
def test_shipped_spatial_examples_run_ten_seconds_at_the_default_settings(name):
    """Long runs at the defaults (rtol 1e-8): to the end, the energy booked to the
    tolerance's level (measured 4.4e-7 J at most, the spherical pendulum's)."""
    res = cd.run_dae(cd.load(cd.example(name)), 10.0)
    assert res.status == "success" and res.t[-1] == 10.0
    assert np.max(np.abs(res.energy().residual)) < 5e-6  # J
    assert max(res.drift) < 1e-6


def test_friction_from_the_reaction_on_a_spatial_hinge_as_in_the_plane(tmp_path):
    """mu r |F| on a hinge, |F| the pin's whole force (its three point rows' multipliers):
    a rod swinging about z comes to rest through the same slips as the planar file's."""
    fric = "friction = { mu_static = 0.3, mu_kinetic = 0.2, radius = 0.02 }"
    stop = "limits = { lower = -0.6 }"
    planar = cd.example("pendulum_stop").read_text()
    planar = planar.replace(planar[planar.index(stop):planar.index("[initial]")],
                            fric + "\n\n")
    spatial = (HERE / "models" / "pendulum_stop_spatial.toml").read_text().replace(
        stop + "\nrestitution = 0.0", fric)
    (tmp_path / "p.toml").write_text(planar)
    (tmp_path / "s.toml").write_text(spatial)
    a, b = _planar_vs_spatial(tmp_path / "p.toml", tmp_path / "s.toml", 3.0)
    assert [e.kind for e in a.events] == [e.kind for e in b.events]
    gaps = [abs(x.t - y.t) for x, y in zip(a.events, b.events, strict=True)]
    assert len(gaps) >= 4 and max(gaps) < 1e-8  # s
    assert np.max(np.abs(b.joint("O").friction - a.joint("O").friction)) < 1e-9  # N m


def test_cylindrical_joint_slides_and_turns_in_closed_form():
    """The collar's slide (the joint S:slide: a spring, gravity, a stop with restitution
    0.5) bounces when the closed-form oscillation says, and its angle turns on at 3 rad/s
    through the impacts (nothing acts about the shaft)."""
    mech = cd.load(cd.example("collar_on_shaft"))
    assert list(mech.joints) == ["S", "S:slide"] and mech.joints["S"].rows == 4
    res = cd.run_dae(mech, 1.0, rtol=1e-10)
    ref = spatial_refs.collar_bounces(4)
    assert [e.kind for e in res.events] == ["bounce"] * 4
    for ev, (t, vin) in zip(res.events, ref, strict=True):
        assert ev.joint == "S:slide" and abs(ev.t - t) < 1e-8  # s
        assert abs(ev.velocity_before - vin) < 1e-7  # m/s
        assert abs(ev.velocity_after + 0.5 * vin) < 1e-7
    theta = res.joint("S").position
    assert np.max(np.abs(np.angle(np.exp(1j * (theta - 3.0 * res.t))))) < 1e-8  # rad
    assert np.max(np.abs(res.energy().residual)) < 1e-8  # J, the impacts' losses booked
    assert cd.structure(mech).mobility == 2


def test_more_bad_spatial_input_is_named_once(tmp_path):
    text = (HERE / "models" / "pendulum_stop_spatial.toml").read_text()
    cases = {  # (what is replaced, by what, the one problem said)
        "space": ('space = "spatial"', 'space = "3d"',
                  "[mechanism] space: expected one of planar, spatial, got '3d'"),
        "point": ("O = [0.0, 0.0, 0.0] }", "O = [0.0, 0.0] }",
                  "[ground.points] O: expected a list of 3 numbers"),
        "stops": ("limits = { lower = -0.6 }", "limits = { lower = -0.6, upper = 6.0 }",
                  "[joints.O] limits: a spatial revolute joint's angle is measured within"),
        "rest": ("limits = { lower = -0.6 }\nrestitution = 0.0",
                 "limits = { lower = -0.6, upper = 1.0 }\nspring = { stiffness = 1.0, rest "
                 "= 4.0 }", "[joints.O] spring.rest: a spatial revolute joint's angle is"),
    }
    for old, new, said in cases.values():
        assert old in text
        (tmp_path / "bad.toml").write_text(text.replace(old, new, 1))
        with pytest.raises(ModelError) as err:
            cd.load(tmp_path / "bad.toml")
        assert len(err.value.problems) == 1 and said in str(err.value)


def test_sensitivity_to_a_full_tensors_entry_is_refused_by_name(tmp_path):
    text = (HERE / "models" / "pendulum_stop_spatial.toml").read_text().replace(
        "inertia = [1.0e-5, 3.0e-3, 3.0e-3]", "inertia = [1.0e-3, 3.0e-3, 3.0e-3, 0, 0, 1e-4]")
    (tmp_path / "full.toml").write_text(text)
    with pytest.raises(ModelError, match=r"bodies.rod.inertia.xy: an entry of a full"):
        cd.sensitivities(cd.load(tmp_path / "full.toml"), ["bodies.rod.inertia.xy"], 0.1)


def test_a_loop_that_cannot_close_in_space_reports_its_residual(tmp_path):
    """A universal joint whose arms can never be perpendicular: the assembly's residual,
    not a diverged Newton's (it said 8.6e33)."""
    text = cd.example("rsur_four_bar").read_text().replace(  # the coupler's length across
        'axes = ["coupler.y", "rocker.z"]', 'axes = ["coupler.x", "rocker.z"]').replace(
        "axes = { y = [0.0, 1.0, 0.0] }", "axes = { y = [0.0, 1.0, 0.0], x = [1.0, 0.0, 0.0] }")
    # (the global x axis, the rocker's: the coupler always runs 0.07 m or more along it)
    (tmp_path / "u.toml").write_text(text)
    with pytest.raises(cd.AssemblyError) as err:
        cd.run_dae(cd.load(tmp_path / "u.toml"), 0.1)
    assert 0.0 < err.value.residual < 1.0 and "joint C" in str(err.value)


def test_a_spatial_hinge_angle_is_continuous_about_its_spring_rest(tmp_path):
    """A rod on a torsional spring whose rest is 3 rad swings through pi (where an angle
    in (-pi, pi] would jump by 2 pi and the spring with it): as the planar file's."""
    spring = "spring = { stiffness = 2.0, rest = 3.0 }"
    planar = cd.example("pendulum_stop").read_text()
    planar = planar.replace(planar[planar.index("limits = {"):planar.index("[initial]")],
                            spring + "\n\n").replace("joints = { O = 0.3 }", "joints = { O = 2.2 }")
    spatial = (HERE / "models" / "pendulum_stop_spatial.toml").read_text().replace(
        "limits = { lower = -0.6 }\nrestitution = 0.0", spring).replace(
        "joints = { O = 0.3 }", "joints = { O = 2.2 }").replace(
        "rotation = [0.0, 0.0, 0.3]", "rotation = [0.0, 0.0, 2.2]")
    (tmp_path / "p.toml").write_text(planar)
    (tmp_path / "s.toml").write_text(spatial)
    a, b = _planar_vs_spatial(tmp_path / "p.toml", tmp_path / "s.toml", 2.0)
    c = b.joint("O").position
    assert c.max() > np.pi and np.max(np.abs(c - a.joint("O").position)) < 1e-9


WHEEL = """[mechanism]
name = "free wheel"
space = "spatial"
[ground]
points = { O = [0.0, 0.0, 0.0] }
axes = { z = [0.0, 0.0, 1.0], x = [1.0, 0.0, 0.0] }
[bodies.w]
mass = 1.0
inertia = [0.011, 0.011, 0.02]
points = { O = [0.0, 0.0, 0.0] }
axes = { z = [0.0, 0.0, 1.0], x = [1.0, 0.0, 0.0] }
[joints.R]
type = "revolute"
connects = ["ground.O", "w.O"]
axis = ["ground.z", "w.z"]
[initial]
joints = { R = 0.0 }
velocities = { R = 3.0 }
"""


@pytest.mark.parametrize("compiled", [False, True])
def test_the_fixed_step_turns_a_free_hinge_through_its_cut(tmp_path, compiled):
    """A wheel turning freely at 3 rad/s: the step's target past the angle's cut (pi from
    its middle) is the same position 2 pi back (the step had failed at 1.047 s, or written
    NaN in C with "success")."""
    (tmp_path / "w.toml").write_text(WHEEL)
    res = cd.run_iterative(cd.load(tmp_path / "w.toml"), 3.0, dt=1e-3, compiled=compiled)
    assert res.status == "success" and not np.isnan(res.data["q"]).any()
    theta = res.joint("R").position
    assert np.max(np.abs(np.angle(np.exp(1j * (theta - 3.0 * res.t))))) < 1e-12  # rad


def test_spatial_exports_units_and_an_angles_wrap(tmp_path):
    """CSV columns of a spatial result (forces, moments, poses by component), a
    cylindrical joint's angle driven in N m, and a compared angle's difference wrapped
    (the Bennett linkage's J2 passes its cut: 6.18 rad had been reported for 0.22)."""
    res = cd.run_dae(cd.load(cd.example("collar_on_shaft")), 0.2)
    assert res.watched_joints() == ["S", "S:slide"]  # the joint's angle and reaction too
    cols = res.columns()
    assert {"joint S torque z [N m]", "joint S:slide position [m]", "joint S position [rad]",
            "body collar qw"} <= set(cols)
    assert np.array_equal(cols["joint S force z [N]"], res.joint("S").force[:, 2])
    mech = cd.load(cd.example("bennett_linkage"))
    a = cd.run_dae(mech, 3.0)
    b = cd.run_iterative(mech, 3.0, dt=0.01)
    assert np.ptp(b.joint("J2").position) > 6.0  # it wraps
    row = {s.name: s for s in cd.compare(a, b).series}["joint J2 position"]
    assert row.max_abs < 0.5  # rad, the fixed step's first-order error (measured 0.22)


def test_a_joint_named_like_a_slide_is_kept_beside_a_revolute(tmp_path):
    """Only a cylindrical joint's own slide name is refused as a table: a joint named
    "O:slide" beside a revolute joint O is a joint of its own (it had been dropped)."""
    text = (HERE / "models" / "pendulum_stop_spatial.toml").read_text()
    text = text.replace("[joints.O]", "[bodies.bob]\nmass = 0.1\ninertia = [1e-5, 1e-5, 1e-5]"
                        "\npoints = { O = [0.0, 0.0, 0.0] }\nguess = { position = [0.3, 0.0, "
                        "0.0] }\n\n[joints.O]").replace("[initial]", '[joints."O:slide"]\n'
                        'type = "spherical"\nconnects = ["rod.tip", "bob.O"]\n\n[initial]')
    (tmp_path / "j.toml").write_text(text)
    assert list(cd.load(tmp_path / "j.toml").joints) == ["O", "O:slide"]
