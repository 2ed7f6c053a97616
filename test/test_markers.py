"""
The stage's markers, checked as a screenshot would be: one tick rendered top-down.

The outlines in the MarkerArray are compared with the body poses of a static solution
transformed independently here (scipy's convex hull, explicit rotation), and a matplotlib
rendering of the markers is probed pixel by pixel at places computed from those poses.
"""

import math

import matplotlib
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism, mechanism_from_dict
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.node.publish.markers import MarkerScene

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

SCALE = 100.0


@pytest.fixture(scope="module")
def stage():
    mech = load_mechanism("microstage")
    snap = Simulation(mech).static(1.35e-6).snapshot
    return mech, snap


def _expected_outline(mech, body_index, pose):
    """Return the outline of one body drawn at ``pose``, computed without the module."""
    body = mech.bodies[body_index]
    pts = [(0.0, 0.0)] + [f.position for h in mech.hinges for f in (h.a, h.b)
                          if f.body == body.name]
    pts = np.unique(np.array(pts), axis=0)
    if np.linalg.matrix_rank(pts - pts.mean(axis=0), tol=1e-12) == 2:
        pts = pts[ConvexHull(pts).vertices]
    else:  # collinear: the outline is the bar between the two extreme points
        pts = pts[[0, -1]]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return pts @ np.array([[c, s], [-s, c]]) + pose[:2]


def test_outlines_and_hinge_discs_follow_the_magnified_body_poses(stage):
    mech, snap = stage
    scene = MarkerScene(mech, frame_prefix="stage1/", display_scale=SCALE)
    msg = scene.message(snap.poses, snap.wrenches, snap.drive_force, stamp_ns=1_500_000_000)
    rest = np.array([b.pose for b in mech.bodies])
    shown = rest + SCALE * (snap.poses - rest)
    bodies = [m for m in msg.markers if m.ns == "bodies"]
    assert len(bodies) == len(mech.bodies)
    for k, m in enumerate(bodies):
        got = np.array([[p.x, p.y] for p in m.points])
        want = _expected_outline(mech, k, shown[k])
        # Same vertex set (the marker closes its polygon by repeating the first point).
        assert len(got) in (len(want), len(want) + 1)
        for w in want:
            assert np.min(np.linalg.norm(got - w, axis=1)) < 1e-12
    discs = [m for m in msg.markers if m.ns == "hinges"]
    for h, m in zip(mech.hinges, discs):
        k = mech.body_index(h.b.body)
        centre = _expected_outline_point(shown[k], h.b.position)
        assert (m.pose.position.x, m.pose.position.y) == pytest.approx(tuple(centre), abs=1e-12)
    # Magnified: body4's outline moved by SCALE x its output displacement along x.
    moved = bodies[mech.body_index("body4")].points[0].x - _expected_outline(
        mech, mech.body_index("body4"), rest[mech.body_index("body4")])[0][0]
    assert moved == pytest.approx(SCALE * snap.output, rel=1e-6)
    assert {m.header.frame_id for m in msg.markers} == {"stage1/stage"}
    assert msg.markers[0].header.stamp.sec == 1 and msg.markers[0].header.stamp.nanosec == 5e8
    arrow = [m for m in msg.markers if m.ns == "drive"]
    assert len(arrow) == 1 and arrow[0].points[1].x > arrow[0].points[0].x  # pushes along +x


def _expected_outline_point(pose, point):
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([pose[0] + c * point[0] - s * point[1], pose[1] + s * point[0] + c * point[1]])


def test_rendered_top_view_shows_each_body_where_its_pose_puts_it(stage, tmp_path):
    mech, snap = stage
    msg = MarkerScene(mech, display_scale=SCALE).message(snap.poses, snap.wrenches,
                                                         snap.drive_force, 0)
    rest = np.array([b.pose for b in mech.bodies])
    shown = rest + SCALE * (snap.poses - rest)
    colours = plt.get_cmap("tab10")
    fig, ax = plt.subplots(figsize=(6, 6), dpi=100)
    for k, m in enumerate(m for m in msg.markers if m.ns == "bodies"):
        xy = np.array([[p.x, p.y] for p in m.points])
        ax.plot(xy[:, 0], xy[:, 1], color=colours(k), linewidth=4, antialiased=False,
                solid_capstyle="butt")
    ax.set_aspect("equal")
    ax.set_xlim(-0.035, 0.035)
    ax.set_ylim(-0.01, 0.05)
    ax.axis("off")
    fig.canvas.draw()
    image = np.asarray(fig.canvas.buffer_rgba())[:, :, :3]
    fig.savefig(tmp_path / "markers_top_view.png")
    height = image.shape[0]
    for k in range(len(mech.bodies)):
        outline = _expected_outline(mech, k, shown[k])
        mid = 0.5 * (outline[0] + outline[1])  # middle of the first edge, drawn by body k
        px, py = ax.transData.transform(mid)
        pixel = image[int(round(height - py)), int(round(px))] / 255.0
        assert pixel == pytest.approx(colours(k)[:3], abs=0.02), mech.bodies[k].name
    plt.close(fig)


def test_hinges_are_coloured_by_load_and_the_most_loaded_is_red(stage):
    mech, snap = stage
    msg = MarkerScene(mech).message(snap.poses, snap.wrenches, snap.drive_force, 0)
    discs = [m for m in msg.markers if m.ns == "hinges"]
    loads = np.abs(snap.wrenches[:, 0]) / 1e-3 + np.hypot(snap.wrenches[:, 1], snap.wrenches[:, 2])
    top = int(np.argmax(loads))
    assert (discs[top].color.r, discs[top].color.g) == (1.0, 0.0)
    low = int(np.argmin(loads))
    assert discs[low].color.g > discs[top].color.g


def _with_shape(shape):
    import yaml

    from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
    data = yaml.safe_load(resolve_mechanism_path("microstage").read_text())
    data["bodies"][3]["shape"] = shape
    return mechanism_from_dict(data, "stage.yaml")


def test_a_shape_in_the_mechanism_file_is_the_outline():
    mech = _with_shape({"rectangle": [-0.015, -0.003, 0.015, 0.003]})
    msg = MarkerScene(mech).message(np.array([b.pose for b in mech.bodies]),
                                    np.zeros((len(mech.hinges), 3)), 0.0, 0)
    body4 = [m for m in msg.markers if m.ns == "bodies"][3]
    xy = {(round(p.x, 9), round(p.y, 9)) for p in body4.points}
    assert xy == {(-0.015, 0.021), (0.015, 0.021), (0.015, 0.027), (-0.015, 0.027)}


@pytest.mark.parametrize("shape, problem", [
    ({"rectangle": [0, 0, 0, 1]}, "no area"),
    ({"polygon": [[0, 0], [1, 0]]}, "at least 3 points"),
    ({"circle": 1}, "rectangle"),
    ([1, 2], "expected"),
])
def test_bad_shapes_name_the_key(shape, problem):
    with pytest.raises(ConfigError, match=r"bodies\[3\]\.shape") as err:
        _with_shape(shape)
    assert problem in str(err.value)
