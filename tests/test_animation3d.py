"""The 3D animation of spatial runs (GIF, the HTML report's player, ``cmm-dae animate``),
and the planar drawing left as it was."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import cmm_dae as cd
from cmm_dae.core.errors import CmmError
from cmm_dae.core.figures import pyplot
from cmm_dae.report import animation
from cmm_dae.report.animation import _Scene, animate, html_animation
from cmm_dae.report.animation3d import Scene3D

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
PLANAR_CAPTION = "Locked metamorphic joints red, free ones green; the guides and stops in grey."

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def bennett():
    """The Bennett linkage swinging for 0.6 s (skew axes: every coordinate moves)."""
    return cd.run_dae(cd.load(MODELS / "bennett_linkage.toml"), 0.6)


@pytest.fixture(scope="module")
def four_bars():
    """The four-bar as a spatial file and as the planar file, both IDA over 0.3 s."""
    return (cd.run_dae(cd.load(MODELS / "four_bar_spatial.toml"), 0.3),
            cd.run_dae(cd.load(MODELS / "four_bar.toml"), 0.3))


def _rotate(quat: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``q p q*`` by Hamilton products (not through a rotation matrix): the point ``p``
    turned by the unit quaternion ``quat`` = (w, x, y, z)."""
    def mul(a, b):
        aw, av, bw, bv = a[0], np.asarray(a[1:]), b[0], np.asarray(b[1:])
        return np.concatenate([[aw * bw - av @ bv], aw * bv + bw * av + np.cross(av, bv)])

    conj = quat * np.array([1.0, -1.0, -1.0, -1.0])
    return mul(mul(quat, np.concatenate([[0.0], p])), conj)[1:]


def test_drawn_points_are_the_posed_body_points(bennett):
    """Every drawn point of every frame is the body's point moved by the body's pose,
    computed here independently from the quaternion (rtol 1e-12; atol 1e-14 m, links of
    0.1 m, for coordinates that are zero)."""
    scene = Scene3D(bennett, 9)
    assert scene.idx.size == 9 and scene.idx[0] == 0 and scene.idx[-1] == bennett.t.size - 1
    for body, pts in bennett.layout.body_points.items():
        pose = bennett.body(body).pose
        assert scene.tracks[body].shape == (9, len(pts), 3)
        for k, i in enumerate(scene.idx):
            for m, p in enumerate(pts.values()):
                want = pose[i, :3] + _rotate(pose[i, 3:], np.asarray(p, float))
                np.testing.assert_allclose(scene.tracks[body][k, m], want, rtol=1e-12,
                                           atol=1e-14)


@pytest.mark.parametrize("model", ["bennett_linkage", "four_bar_spatial"])
def test_joints_points_meet_where_drawn(model):
    """The two points each joint connects are drawn at one place (the constraints hold to
    the run's tolerance): the drawing reads the poses the way the solver meant them."""
    res = cd.run_dae(cd.load(MODELS / f"{model}.toml"), 0.4)
    scene = Scene3D(res, 20)
    lay = res.layout
    for joint, ends in lay.connects.items():
        (b1, p1), (b2, p2) = (e.split(".", 1) for e in ends)
        at = [scene.world(b, p if b == "ground" else lay.body_points[b][p])
              for b, p in ((b1, p1), (b2, p2))]
        assert np.max(np.abs(at[0] - at[1])) < 1e-7, joint


def test_spatial_four_bar_is_drawn_as_the_planar_one(four_bars):
    """The four-bar's spatial file is drawn where the planar file's drawing puts it (in the
    plane z = 0), and the axes are scaled equally: one cube around it."""
    spatial, planar = four_bars
    s3, s2 = Scene3D(spatial, 12), _Scene(planar, 12)
    assert np.array_equal(s3.idx, s2.idx)
    for body in planar.layout.bodies:
        np.testing.assert_allclose(s3.tracks[body][..., :2], s2.tracks[body], atol=1e-9)
        assert np.max(np.abs(s3.tracks[body][..., 2])) < 1e-12
    assert np.allclose(s3.hi - s3.lo, (s3.hi - s3.lo)[0])


def test_view_is_equal_and_gravity_points_down(bennett):
    """Equal ranges on the three axes; the Bennett linkage's gravity is +y: y is drawn
    vertical and reversed, with x (a half turn of the view, not a mirror image), z not;
    the spherical pendulum's -z needs no turn. The title carries the time."""
    plt = pyplot()
    fig, update = Scene3D(bennett, 4).figure()
    try:
        ax = fig.axes[0]
        assert ax.name == "3d"
        lims = [ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()]
        widths = [abs(b - a) for a, b in lims]
        assert np.allclose(widths, widths[0])
        assert [a > b for a, b in lims] == [True, True, False]
        update(3)
        assert f"t = {bennett.t[-1]:.3f} s" in ax.get_title()
    finally:
        plt.close(fig)
    pend = cd.run_dae(cd.load(MODELS / "spherical_pendulum.toml"), 0.2)
    scene = Scene3D(pend, 3)
    # a single point: drawn to the centroid, 0.5 m below the pivot in the bob's frame
    assert scene.tracks["bob"].shape == (3, 2, 3)
    np.testing.assert_allclose(np.linalg.norm(scene.tracks["bob"][:, 1], axis=1), 0.5,
                               rtol=1e-9)
    fig, _ = scene.figure()
    try:
        ax = fig.axes[0]
        assert all(a < b for a, b in (ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()))
    finally:
        plt.close(fig)


def test_gif_of_a_spatial_run(bennett, tmp_path):
    """``animate`` writes the frames asked for at the asked rate, the bodies drawn in
    colour; a file type other than GIF is refused as for a planar run."""
    path = animate(bennett, tmp_path / "b.gif", max_frames=6, fps=5)
    im = Image.open(path)
    assert path.stat().st_size > 1000 and im.n_frames == 6 and im.info["duration"] == 200
    assert im.size == (560, 400)
    im.seek(3)
    rgb = np.asarray(im.convert("RGB")).reshape(-1, 3).astype(int)
    blue = np.sum((rgb[:, 2] > 150) & (rgb[:, 0] < 80))  # link1 (tab:blue)
    orange = np.sum((rgb[:, 0] > 200) & (rgb[:, 1] > 100) & (rgb[:, 1] < 160)
                    & (rgb[:, 2] < 60))  # link2 (tab:orange)
    assert blue > 50 and orange > 50
    with pytest.raises(CmmError, match="GIF"):
        animate(bennett, tmp_path / "b.mp4")
    with pytest.raises(CmmError, match="frames"):
        Scene3D(bennett, 0)


def test_metamorphic_joint_marked_in_3d(tmp_path):
    """A limited spatial joint is a metamorphic one: its square follows its second point
    (link1.A, on the ground's J1 throughout)."""
    text = (MODELS / "bennett_linkage.toml").read_text().replace(
        "[initial]", "[joints.J1.limits]\nlower = 0.5\n\n[initial]")
    (tmp_path / "stop.toml").write_text(text)
    res = cd.run_dae(cd.load(tmp_path / "stop.toml"), 0.4)
    assert any(e.kind == "limit" for e in res.events)
    scene = Scene3D(res, 10)
    np.testing.assert_allclose(scene.markers["J1"], np.tile(res.layout.ground["J1"], (10, 1)),
                               atol=1e-8)
    assert animate(res, tmp_path / "s.gif", max_frames=4).stat().st_size > 1000


def test_report_of_a_spatial_run_has_the_3d_animation(four_bars, tmp_path):
    """The comparison report of a spatial run (IDA against the fixed-step algorithm) is
    written with its animation, and compares each component of the 3-vector forces and
    moments."""
    spatial = four_bars[0]
    ref = cd.run_iterative(cd.load(MODELS / "four_bar_spatial.toml"), 0.3, dt=0.01)
    cmp = cd.compare(spatial, ref)
    names = {s.name for s in cmp.series}
    assert {"joint B force z", "joint B torque x", "joint B torque z"} <= names
    assert "joint B torque" not in names
    cmp.write_report(tmp_path, frames=5)
    page = (tmp_path / "report.html").read_text()
    assert page.count("data:image/png;base64,") == 5
    assert "Animation" in page and "A 3D view" in page and PLANAR_CAPTION not in page
    assert "force z" in cmp.table()


def test_planar_drawing_does_not_touch_the_3d_scene(four_bars, monkeypatch, tmp_path):
    """A planar run is drawn by the planar scene alone (the 3D one failing changes
    nothing), with the planar caption and the planar series of the comparison."""
    planar = four_bars[1]

    def boom(*a, **k):
        raise AssertionError("a planar run reached the 3D scene")

    monkeypatch.setattr(animation, "Scene3D", boom)
    assert Image.open(animate(planar, tmp_path / "p.gif", max_frames=3)).n_frames == 3
    assert html_animation(planar, max_frames=2).count("data:image/png;base64,") == 2
    cmp = cd.compare(planar, planar)
    assert [s.name for s in cmp.series[1:5]] == [
        "joint A position", "joint A force x", "joint A force y", "joint A torque"]
    cmp.write_report(tmp_path / "rep", frames=2)
    assert f"<p>{PLANAR_CAPTION}</p>" in (tmp_path / "rep" / "report.html").read_text()
    with pytest.raises(CmmError, match="spatial"):
        Scene3D(planar, 2)


def test_cli_animates_a_spatial_model_and_a_saved_result(tmp_path):
    """``cmm-dae animate`` on the Bennett linkage's model file, and on a saved run."""
    def cli(*args):
        return subprocess.run([sys.executable, "-m", "cmm_dae.cli", *args],
                              capture_output=True, text=True, cwd=ROOT, timeout=300)

    r = cli("animate", "models/bennett_linkage.toml", "--t-end", "0.3", "--frames", "4",
            "--fps", "10", "--out", str(tmp_path / "b.gif"))
    assert r.returncode == 0, r.stderr
    im = Image.open(tmp_path / "b.gif")
    assert im.n_frames == 4 and im.info["duration"] == 100
    cd.run_dae(cd.load(MODELS / "spherical_pendulum.toml"), 0.3).save(tmp_path / "p.npz")
    r = cli("animate", str(tmp_path / "p.npz"), "--frames", "3", "--out",
            str(tmp_path / "p.gif"))
    assert r.returncode == 0, r.stderr
    assert Image.open(tmp_path / "p.gif").n_frames == 3
