"""The live 3D view: its scene from messages (no browser), and the page in headless Chromium.

The unit tests build the ``cell_viewer`` node in-process (a real viser server on a free port),
publish the messages of the ROS contract from a probe node and read the scene back: arm poses
against the independent FK of :mod:`scara_collab.core.kinematics`, capsules against
:mod:`scara_collab.core.collision`, items, paths, e-stop and stats; with a person, its markers,
the scan's returns against the ray geometry written out in the test, each arm's ``S_p`` ring
and speed factor; without one, a scene with nothing of them.

The acceptance test runs the bridge and the viewer in-process, loads the page in headless
Chromium (Debian's ``chromium``; swiftshader WebGL, driven over the DevTools protocol), takes
a screenshot with the arms shown and one with them hidden, and checks that the pixels where
the FK of the bridge's joint states puts each arm's links changed to the links' orange, while
the belt's inlet and the items did not. Without ``chromium`` on the PATH it skips and says so.
"""
import base64
import io
import json
import math
import os
from pathlib import Path
import shutil
import signal
import subprocess
import time
from types import SimpleNamespace
import urllib.request

from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Path as PathMsg
import numpy as np
from PIL import Image
import pytest
from ros_harness import Graph, params_args
from sensor_msgs.msg import JointState, LaserScan
from std_msgs.msg import Bool, Float64
from viser import transforms as vtf
from visualization_msgs.msg import Marker, MarkerArray

from scara_collab.core import collision, kinematics as kin
from scara_collab.core.config import load_config
from scara_collab.core.model import load_cell
from scara_collab.core.scan_tracking import scanners_from_config
from scara_collab.core.separation_monitor import nearest_person, PersonSeen
from scara_collab.core.ssm import Person
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.cell_viewer import (
    CellViewer, LATCHED, margin_colour, MARGIN_COLOURS, marker_shape,
    PATH_COLOURS)

CHROMIUM = shutil.which('chromium')
DIRECT = urllib.request.build_opener(urllib.request.ProxyHandler({}))  # no proxy for loopback
SIZE = (1200, 800)  # browser viewport, px
#: The viewer's scene is in (its GUI text arrived) and drawn: viser shows its 3D canvas at 5 %
#: opacity until the environment map is loaded (tens of seconds on a busy machine), then fades in.
SHOWN = ("document.body.innerText.includes('sim t =') && (() => { const c = Array.from("
         "document.querySelectorAll('canvas')).filter(c => c.width > 0); return c.length > 0 "
         "&& c.every(c => getComputedStyle(c).opacity === '1'); })()")
HIDE_TOASTS = ("if (!document.getElementById('no-toasts')) { const s = document.createElement("
               "'style'); s.id = 'no-toasts'; s.textContent = '.mantine-Notifications-root "
               "{display: none !important}'; document.head.appendChild(s); }")


# --- helpers ---------------------------------------------------------------------------------
@pytest.fixture
def graph():
    """Yield a graph with a cell viewer on a free port, drawing at 50 Hz."""
    g = Graph()
    g.viewer = g.add(CellViewer(context=g.context, cli_args=params_args(
        overrides={'port': 0, 'update_rate': 50.0})))
    yield g
    g.close()


def publish(g, msg_type, topic, msg, qos=10):
    """Publish ``msg`` on ``topic`` once the viewer subscribes; return the publisher."""
    pub = g.probe.create_publisher(msg_type, topic, qos)
    assert g.spin_until(lambda: pub.get_subscription_count() > 0, 10)
    pub.publish(msg)
    return pub


def joint_states(cell, q_left, q_right) -> JointState:
    """Return a JointState of both arms, leader joints first."""
    names = cell.leader.joint_names + cell.follower.joint_names
    pos = list(q_left) + list(q_right)
    return conv.joint_state(1.0, names, pos, [0.0] * 6, [0.0] * 6)


def drawn(g, q_left, q_right):
    """Publish joint states and spin until the viewer drew them."""
    frames = g.viewer.frames
    publish(g, JointState, '/joint_states', joint_states(g.viewer.cell, q_left, q_right))
    assert g.spin_until(lambda: g.viewer.frames > frames, 10), 'the arms were not redrawn'


def rgb(colour) -> tuple:
    """Return the first three channels of a colour as ints."""
    return tuple(int(v) for v in np.asarray(colour).ravel()[:3])


# --- the scene from messages (no browser) ----------------------------------------------------
def test_the_page_and_the_cell_are_served(graph):
    """The page is served, and each arm has its URDF joints and three capsules.

    The arms stay hidden until the first joint state.
    """
    viewer = graph.viewer
    with DIRECT.open(f'http://127.0.0.1:{viewer.port}/', timeout=10) as r:
        assert r.status == 200 and b'Viser' in r.read()
    scene = viewer.scene
    for arm in viewer.cell.arms:
        assert scene.urdfs[arm.name].actuated_joint_names == list(arm.joint_names)
        assert len(scene.capsules[arm.name]) == 3
    assert not scene.root['arms'].visible, 'arms are hidden until the first joint state'


@pytest.mark.parametrize('q_left, q_right, worst', [
    ((0.0, 1.5708, 0.0), (0.0, -1.5708, 0.0), 0),   # the bridge's home: far apart
    ((1.5708, 0.0, 0.3), (-1.5708, 0.0, 0.1), 2),   # both reach across the belt: overlap
    ((0.848, 0.0, 0.0), (-0.848, 0.0, 0.0), 1),     # mirrored, 0.15 m apart: inside 2 margins
])
def test_joint_states_pose_the_arms_and_colour_the_capsules(graph, q_left, q_right, worst):
    """Joint states pose the URDFs at the FK and colour the capsules by the margin.

    The capsules lie on the collision module's axes; the gap label is the arm distance.
    """
    drawn(graph, q_left, q_right)
    viewer, cell = graph.viewer, graph.viewer.cell
    scene = viewer.scene
    assert scene.root['arms'].visible
    qs = {cell.leader.name: np.array(q_left), cell.follower.name: np.array(q_right)}
    for arm in cell.arms:
        urdf = scene.urdfs[arm.name]
        np.testing.assert_allclose(urdf.cfg, qs[arm.name])
        tip = urdf.get_transform(f'{arm.name}_quill', 'world')[:3, 3]
        np.testing.assert_allclose(tip, kin.fk(arm, qs[arm.name]), atol=1e-9)
        starts, ends, radii = collision.arm_capsules(arm, qs[arm.name])
        for k, h in enumerate(scene.capsules[arm.name]):
            half = np.linalg.norm(ends[k] - starts[k]) / 2
            axis = vtf.SO3(np.asarray(h.wxyz)).apply(np.array([0.0, 0.0, half]))
            np.testing.assert_allclose(np.asarray(h.position) + axis, ends[k], atol=1e-6)
            np.testing.assert_allclose(np.asarray(h.position) - axis, starts[k], atol=1e-6)
    d = float(collision.arm_distance(cell.leader, qs[cell.leader.name], cell.follower,
                                     qs[cell.follower.name]))
    colours = {rgb(h.color) for hs in scene.capsules.values() for h in hs}
    assert rgb(MARGIN_COLOURS[worst]) in colours
    assert all(MARGIN_COLOURS.index(c) <= worst for c in colours)
    assert scene.gap_label.text == f'{d:.3f} m'
    assert rgb(scene.gap.colors[0, 0]) == margin_colour(d, cell.safety_margin)
    assert graph.spin_until(lambda: f'arm distance {d:.3f} m' in scene.status_md.content, 5)


def test_items_paths_estop_and_stats_are_shown(graph):
    """Items, planned paths, the e-stop, the monitor distance and the job stats are shown.

    Items are coloured by class and removed when gone.
    """
    viewer, cell = graph.viewer, graph.viewer.cell
    scene = viewer.scene
    red, blue = cell.item_classes
    items = [SimpleNamespace(id=4, cls=red, position=np.array([0.5, 0.1, 0.25])),
             SimpleNamespace(id=7, cls=blue, position=np.array([1.5, -0.2, 0.25]))]
    pub = publish(graph, MarkerArray, '/conveyor/items',
                  conv.item_markers(items, cell.item_classes, cell.item_size, 1.0))
    assert graph.spin_until(lambda: set(scene.items) == {4, 7}, 5)
    np.testing.assert_allclose(scene.items[7].position, [1.5, -0.2, 0.25])
    assert rgb(scene.items[4].color) != rgb(scene.items[7].color), 'coloured by class'
    pub.publish(conv.item_markers(items[1:], cell.item_classes, cell.item_size, 1.1))
    assert graph.spin_until(lambda: set(scene.items) == {7}, 5), 'a gone item is removed'

    line = np.linspace([3.2, -0.9, 0.4], [2.0, 0.0, 0.4], 11)
    publish(graph, PathMsg, '/scara_left/planned_path', conv.path_msg(line, 1.0))
    assert graph.spin_until(lambda: 'scara_left' in scene.paths, 5)
    segs = np.asarray(scene.paths['scara_left'].points)
    assert segs.shape == (10, 2, 3)
    np.testing.assert_allclose(segs[:, 0], line[:-1], atol=1e-6)
    np.testing.assert_allclose(segs[:, 1], line[1:], atol=1e-6)

    publish(graph, Bool, '/emergency_stop', Bool(data=True), LATCHED)
    publish(graph, Float64, '/collision_monitor/min_distance', Float64(data=0.0421))
    publish(graph, DiagnosticStatus, '/automation_manager/stats',
            proto.JobStats('collaborative', True, 3.0, 0.0, {'sorted': 3, 'missed': 0},
                           items_per_minute=30.0).to_msg())
    assert graph.spin_until(lambda: 'E-stop: ACTIVE' in scene.status_md.content
                            and 'monitor 0.042 m' in scene.status_md.content
                            and '| sorted | 3 |' in scene.stats_md.content, 5)
    assert scene.estop_label.visible


def test_bad_messages_are_ignored_and_the_viewer_keeps_going(graph):
    """Malformed states and paths draw nothing; a good state still draws."""
    viewer, cell = graph.viewer, graph.viewer.cell
    bad = joint_states(cell, (0.1, 0.2, 0.0), (0.0, 0.0, 0.0))
    bad.name = bad.name[:5]
    bad.position = bad.position[:5]
    pub = publish(graph, JointState, '/joint_states', bad)
    nan = joint_states(cell, (float('nan'), 0.2, 0.0), (0.0, 0.0, 0.0))
    pub.publish(nan)
    path = conv.path_msg(np.array([[1.0, 0.0, 0.4], [float('inf'), 0.0, 0.4]]), 1.0)
    publish(graph, PathMsg, '/scara_right/planned_path', path)
    wrong = conv.path_msg(np.array([[1.0, 0.0, 0.4], [2.0, 0.0, 0.4]]), 1.0, frame_id='map')
    publish(graph, PathMsg, '/scara_left/planned_path', wrong)
    graph.spin_until(lambda: False, 0.5)
    assert viewer.frames == 0 and not viewer.scene.paths
    drawn(graph, (0.1, 0.2, 0.0), (0.0, 0.0, 0.0))  # and a good message still works


# --- a person in the cell --------------------------------------------------------------------
def marker(kind, key, position, quat=(0.0, 0.0, 0.0, 1.0), scale=(0.2, 0.2, 0.5),
           colour=(0.95, 0.8, 0.6, 1.0), points=(), frame='world', ns='person'):
    """Return a ``Marker`` (ADD) of ``kind`` with id ``key``; ``quat`` is (x, y, z, w)."""
    m = Marker(type=kind, id=key, ns=ns, action=Marker.ADD)
    m.header.frame_id = frame
    (m.pose.position.x, m.pose.position.y, m.pose.position.z) = position
    (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
     m.pose.orientation.w) = quat
    m.scale.x, m.scale.y, m.scale.z = scale
    m.color.r, m.color.g, m.color.b, m.color.a = colour
    for x, y, z in points:
        m.points.append(conv.make_point_stamped((x, y, z)).point)
    return m


def marker_array(*markers) -> MarkerArray:
    """Return a DELETEALL, then ``markers``: as the bridge publishes a body."""
    return MarkerArray(markers=[Marker(action=Marker.DELETEALL)] + list(markers))


def person_status(persons, s_p, scale, stop=None, fault='') -> proto.SeparationStatus:
    """Return a separation status: per arm ``S_p`` and factor; the separation 1.5 m."""
    return proto.SeparationStatus(
        time=2.0, scale=dict(scale), stop=dict(stop or {r: False for r in scale}),
        cause={r: ('' if v == 1.0 else f'{r}: speed x {v:.2f}') for r, v in scale.items()},
        separation={r: 1.5 for r in s_p}, margin={r: 1.5 - v for r, v in s_p.items()},
        persons=tuple(persons), fault=fault)


HALF_TURN_ABOUT_Y = (0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4))  # z onto x


def test_marker_shapes_follow_rviz():
    """Markers become shapes by type, pose, scale and colour; what cannot be drawn is None."""
    cyl = marker_shape(marker(Marker.CYLINDER, 1, (1.0, 2.0, 0.9), HALF_TURN_ABOUT_Y,
                              colour=(1.0, 0.5, 0.0, 0.4)))
    assert cyl.kind == 'cylinder' and cyl.size == (0.2, 0.2, 0.5)
    np.testing.assert_allclose(vtf.SO3(np.array(cyl.wxyz)).apply(np.array([0.0, 0.0, 1.0])),
                               [1.0, 0.0, 0.0], atol=1e-12)
    assert cyl.colour == (255, 128, 0) and cyl.opacity == pytest.approx(0.4)
    unrotated = marker_shape(marker(Marker.SPHERE, 2, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0)))
    assert unrotated.kind == 'sphere' and unrotated.wxyz == (1.0, 0.0, 0.0, 0.0)
    pts = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0)]
    strip = marker_shape(marker(Marker.LINE_STRIP, 3, (0.0, 0.0, 0.0), points=pts))
    np.testing.assert_allclose(strip.segments, [[pts[0], pts[1]], [pts[1], pts[2]]])
    listed = marker_shape(marker(Marker.LINE_LIST, 4, (0.0, 0.0, 0.0), points=pts))
    np.testing.assert_allclose(listed.segments, [[pts[0], pts[1]]])
    assert marker_shape(marker(Marker.TEXT_VIEW_FACING, 5, (0.0, 0.0, 0.0))) is None
    assert marker_shape(marker(Marker.CUBE, 6, (float('nan'), 0.0, 0.0))) is None
    assert marker_shape(marker(Marker.LINE_STRIP, 7, (0.0, 0.0, 0.0), points=pts[:1])) is None


def test_the_nearest_person_is_nearest_to_a_dense_sampling_of_the_capsules():
    """Against the arm's capsule axes sampled every millimetre, less both radii."""
    cell = load_cell()
    arm, q = cell.leader, np.array([0.4, 1.2, 0.1])
    starts, ends, radii = collision.arm_capsules(arm, q)
    rng = np.random.default_rng(3)
    for _ in range(20):
        persons = [Person(rng.uniform([0.0, -4.0], [6.0, 1.0]), np.zeros(2),
                          float(rng.uniform(0.1, 0.4)), 2.0, k) for k in range(3)]
        gaps = []
        for p in persons:
            gap = math.inf
            for a, b, r in zip(starts, ends, radii):
                u = np.linspace(0.0, 1.0, int(np.linalg.norm(b - a) / 1e-3) + 2)[:, None]
                xy = (a + u * (b - a))[:, :2]  # the columns stand above every link
                gap = min(gap, float(np.linalg.norm(xy - p.position, axis=1).min()) - r)
            gaps.append(gap - p.radius)
        if sorted(gaps)[1] - sorted(gaps)[0] > 2e-3:  # a tie within the sampling is either
            assert nearest_person(arm, q, persons) is persons[int(np.argmin(gaps))]
    assert nearest_person(arm, q, []) is None


def test_a_person_its_scan_and_the_rings_of_s_p_are_shown(graph):
    """The person's markers, each scanner's returns and each arm's ``S_p`` ring are drawn.

    The markers by type, pose and scale, replaced by each array (DELETEALL first); the returns
    where the rays' ranges put them from the scanner's pose in config/people.yaml, no-returns
    and invalid ranges left out; per arm a ring of the column's radius plus ``S_p`` around the
    tracked person nearest to it, in the arm's colour, its factor and ``S_p`` in the panel.
    """
    viewer, cell = graph.viewer, graph.viewer.cell
    scene = viewer.scene
    home = ((0.0, 1.5708, 0.0), (0.0, -1.5708, 0.0))
    drawn(graph, *home)

    # the person: a leg (cylinder along x here), its two sphere ends, a line, a text not drawn
    body = [marker(Marker.CYLINDER, 0, (1.0, -3.0, 0.45), HALF_TURN_ABOUT_Y),
            marker(Marker.SPHERE, 1, (0.75, -3.0, 0.45), scale=(0.2, 0.2, 0.2)),
            marker(Marker.SPHERE, 2, (1.25, -3.0, 0.45), scale=(0.2, 0.2, 0.2)),
            marker(Marker.LINE_STRIP, 3, (0.0, 0.0, 0.0), ns='',
                   points=[(1.0, -3.0, 0.0), (1.0, -3.0, 1.8)]),
            marker(Marker.TEXT_VIEW_FACING, 4, (1.0, -3.0, 2.0))]
    pub = publish(graph, MarkerArray, '/person/markers', marker_array(*body))
    keys = {('person', 0), ('person', 1), ('person', 2), ('', 3)}
    assert graph.spin_until(lambda: set(scene.person) == keys, 5)
    leg = scene.person[('person', 0)][0]
    axis = vtf.SO3(np.asarray(leg.wxyz)).apply(np.array([0.0, 0.0, 0.25]))
    np.testing.assert_allclose(np.asarray(leg.position) + axis, [1.25, -3.0, 0.45], atol=1e-6)
    np.testing.assert_allclose(np.asarray(leg.position) - axis, [0.75, -3.0, 0.45], atol=1e-6)
    assert tuple(leg.scale) == pytest.approx((0.2, 0.2, 0.5))
    assert leg.radius == 0.5 and leg.height == 1.0  # the scale is the size, as in RViz
    np.testing.assert_allclose(scene.person[('person', 2)][0].position, [1.25, -3.0, 0.45])
    np.testing.assert_allclose(scene.person[('', 3)][0].points,
                               [[[1.0, -3.0, 0.0], [1.0, -3.0, 1.8]]], atol=1e-6)
    moved = [marker(Marker.CYLINDER, 0, (2.0, -3.0, 0.45), HALF_TURN_ABOUT_Y)]
    pub.publish(marker_array(*moved))
    assert graph.spin_until(lambda: set(scene.person) == {('person', 0)}, 5)
    assert scene.person[('person', 0)][0] is leg, 'a marker that moves keeps its handle'
    np.testing.assert_allclose(leg.position, [2.0, -3.0, 0.45], atol=1e-6)

    # the scan: three returns of scanner_a among no-returns, a NaN and one below range_min
    geometry = {g.name: g for g in scanners_from_config(load_config('people'))}['scanner_a']
    ranges = np.full(geometry.count, np.inf)
    hits = {100: 5.0, 270: 9.25, 400: 3.5}
    for i, r in hits.items():
        ranges[i] = r
    ranges[300], ranges[301] = np.nan, 0.01
    scan = LaserScan(angle_min=geometry.angle_min, angle_increment=geometry.angle_increment,
                     range_min=geometry.range_min, range_max=geometry.range_max,
                     ranges=ranges.astype(np.float32).tolist())
    scan.header.frame_id = 'scanner_a'
    publish(graph, LaserScan, '/safety_scanner/scan', scan)
    assert graph.spin_until(lambda: 'scanner_a' in scene.scans, 5)
    expected = [[geometry.x + r * math.cos(geometry.yaw + geometry.angle_min
                                           + i * geometry.angle_increment),
                 geometry.y + r * math.sin(geometry.yaw + geometry.angle_min
                                           + i * geometry.angle_increment),
                 geometry.height] for i, r in hits.items()]
    np.testing.assert_allclose(scene.scans['scanner_a'].points, expected, atol=1e-4)
    scan.header.frame_id = 'laser'  # not a scanner of config/people.yaml
    publish(graph, LaserScan, '/safety_scanner/scan', scan)
    graph.spin_until(lambda: False, 0.3)
    assert set(scene.scans) == {'scanner_a'}

    # the separation monitor: one person near each arm, each arm's ring around its own
    near_left = PersonSeen(3, 2.5, -3.2, 0.3, 0.0, 0.0)
    near_right = PersonSeen(8, 4.6, 2.6, 0.25, 0.0, 0.0)
    s_p = {cell.leader.name: 1.38, cell.follower.name: 2.41}
    status = person_status([near_left, near_right], s_p,
                           {cell.leader.name: 0.0, cell.follower.name: 0.52},
                           stop={cell.leader.name: True, cell.follower.name: False})
    spub = publish(graph, DiagnosticStatus, '/separation_monitor/status', status.to_msg())
    assert graph.spin_until(lambda: len(scene.rings) == 2 and len(scene.columns) == 2, 5)
    for k, (arm, person) in enumerate(zip(cell.arms, (near_left, near_right))):
        segs = np.asarray(scene.rings[arm.name].points, dtype=float)
        z = collision.arm_capsules(arm, viewer.q[arm.name])[0][1, 2]
        np.testing.assert_allclose(segs[..., 2], z, atol=1e-5)
        radial = np.linalg.norm(segs[..., :2] - [person.x, person.y], axis=-1)
        np.testing.assert_allclose(radial, person.radius + s_p[arm.name], atol=1e-5)
        assert rgb(scene.rings[arm.name].colors) == PATH_COLOURS[k]
        column = scene.columns[person.id]
        np.testing.assert_allclose(np.asarray(column.position)[:2], [person.x, person.y])
        assert column.scale[0] == pytest.approx(person.radius)
    text = lambda: scene.status_md.content  # noqa: E731
    assert graph.spin_until(lambda: f'| {cell.leader.name} | stop | 1.50 | 1.38 |' in text()
                            and f'| {cell.follower.name} | x 0.52 | 1.50 | 2.41 |' in text()
                            and '2 persons tracked' in text(), 5), text()

    # a scanner falls silent: every arm stops, nobody tracked, no ring
    spub.publish(person_status([], {}, {cell.leader.name: 0.0, cell.follower.name: 0.0},
                               fault='scanner_b silent for 0.1 s').to_msg())
    assert graph.spin_until(lambda: not scene.columns and not any(
        r.visible for r in scene.rings.values()), 5)
    assert graph.spin_until(lambda: 'every arm stopped**: scanner_b silent' in text(), 5)
    pub.publish(marker_array())  # the person has left
    assert graph.spin_until(lambda: not scene.person, 5)
    for part in ('person', 'scan', 'separation'):
        scene.set_visible(part, False)
        assert not scene.root[part].visible and not scene.show[part].value


def test_without_a_person_the_scene_is_as_it_was(graph):
    """Joint states, items and stats alone add no person, scan or ring, nor their checkboxes."""
    viewer = graph.viewer
    scene = viewer.scene
    nodes = set(viewer.server.scene._handle_from_node_name)  # viser's scene tree, by name
    drawn(graph, (0.0, 1.5708, 0.0), (0.0, -1.5708, 0.0))
    publish(graph, DiagnosticStatus, '/automation_manager/stats',
            proto.JobStats('collaborative', True, 3.0, 0.0, {'sorted': 3, 'missed': 0},
                           items_per_minute=30.0).to_msg())
    assert graph.spin_until(lambda: '| sorted | 3 |' in scene.stats_md.content, 5)
    assert set(viewer.server.scene._handle_from_node_name) == nodes
    assert not any(n.startswith(('/person', '/scan', '/separation')) for n in nodes)
    assert list(scene.show) == ['arms', 'capsules', 'paths', 'items', 'cell']
    assert set(scene.root) == set(scene.show)
    assert not (scene.person or scene.scans or scene.columns or scene.rings)
    assert 'Separation' not in scene.status_md.content


def test_invalid_parameters_are_refused_with_the_name():
    """An update rate of 0 and a port beyond 65535 are refused, naming the parameter."""
    g = Graph()
    try:
        with pytest.raises(ValueError, match='update_rate'):
            CellViewer(context=g.context, cli_args=params_args(
                overrides={'port': 0, 'update_rate': 0.0}))
        with pytest.raises(ValueError, match='port'):
            CellViewer(context=g.context, cli_args=params_args(overrides={'port': 70000}))
    finally:
        g.close()


# --- the page in headless Chromium -----------------------------------------------------------
class Chromium:
    """Headless Chromium driven over the DevTools protocol (websocket, one page)."""

    def __init__(self, exe: str, workdir: Path, size=SIZE):
        """Start headless Chromium on a free DevTools port and connect to its page."""
        from websockets.sync.client import connect  # viser's own dependency
        profile = workdir / 'chromium-profile'
        profile.mkdir(parents=True, exist_ok=True)
        (profile / 'DevToolsActivePort').unlink(missing_ok=True)  # a stale one from a reuse
        self.log_path = workdir / 'chromium.log'
        self._log = open(self.log_path, 'wb')
        # swiftshader: WebGL in software, so three.js renders without a GPU or a display
        self.proc = subprocess.Popen(
            [exe, '--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
             '--enable-unsafe-swiftshader', '--remote-debugging-port=0', '--no-first-run',
             '--hide-scrollbars', '--mute-audio', f'--user-data-dir={profile}',
             f'--window-size={size[0]},{size[1]}', 'about:blank'],
            stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            port = self._devtools_port(profile / 'DevToolsActivePort')
            with DIRECT.open(f'http://127.0.0.1:{port}/json/list', timeout=10) as r:
                page = next(t for t in json.load(r) if t['type'] == 'page')
            self.ws = connect(page['webSocketDebuggerUrl'], max_size=None, open_timeout=10)
        except Exception:
            self.close()
            raise
        self._id = 0
        self.send('Emulation.setDeviceMetricsOverride', width=size[0], height=size[1],
                  deviceScaleFactor=1, mobile=False)

    def _devtools_port(self, path: Path, timeout: float = 30.0) -> int:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.proc.poll() is not None:
                raise RuntimeError(f'chromium exited with {self.proc.returncode}; see '
                                   f'{self.log_path}')
            words = path.read_text().split() if path.exists() else []
            if len(words) >= 2:
                return int(words[0])
            time.sleep(0.05)
        raise TimeoutError(f'chromium did not open its DevTools port; see {self.log_path}')

    def send(self, method: str, timeout: float = 30.0, **params) -> dict:
        """Send one DevTools command and return its result, skipping events.

        :raises RuntimeError: the command failed.
        """
        self._id += 1
        self.ws.send(json.dumps({'id': self._id, 'method': method, 'params': params}))
        end = time.monotonic() + timeout
        while True:  # skip events until our answer
            msg = json.loads(self.ws.recv(timeout=max(0.1, end - time.monotonic())))
            if msg.get('id') == self._id:
                if 'error' in msg:
                    raise RuntimeError(f'{method}: {msg["error"]}')
                return msg.get('result', {})

    def evaluate(self, expression: str):
        """Evaluate a JavaScript ``expression`` in the page and return its value."""
        res = self.send('Runtime.evaluate', expression=expression, returnByValue=True)
        return res.get('result', {}).get('value')

    def open(self, url: str) -> None:
        """Navigate the page to ``url``."""
        self.send('Page.navigate', url=url)

    def screenshot(self) -> np.ndarray:
        """(H, W, 3) uint8 of the page, the software-rendering notice hidden."""
        self.evaluate(HIDE_TOASTS)
        data = self.send('Page.captureScreenshot', format='png')['data']
        return np.asarray(Image.open(io.BytesIO(base64.b64decode(data))).convert('RGB'))

    def settled(self, ready=lambda img: True, timeout: float = 40.0) -> np.ndarray:
        """Screenshot once ``ready(img)`` and two successive screenshots are identical."""
        end, last = time.monotonic() + timeout, None
        while time.monotonic() < end:
            img = self.screenshot()
            if last is not None and ready(img) and np.array_equal(img, last):
                return img
            last = img
            time.sleep(0.3)
        raise TimeoutError('the page did not settle')

    def close(self) -> None:
        """Close the websocket and stop the browser (SIGTERM, then SIGKILL)."""
        ws = getattr(self, 'ws', None)
        if ws is not None:
            ws.close()
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        self._log.close()


def project(points, position, look_at, fov: float, size=SIZE) -> np.ndarray:
    """World points (N, 3) -> pixels (N, 2) of a pinhole camera (three.js: vertical fov, z up)."""
    c = np.asarray(position, dtype=float)
    f = np.asarray(look_at, dtype=float) - c
    f /= np.linalg.norm(f)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    v = np.asarray(points, dtype=float) - c
    x, y, z = v @ r, v @ u, v @ f
    w, h = size
    t = math.tan(fov / 2)
    return np.stack([(1 + x / (z * t * w / h)) * w / 2, (1 - y / (z * t)) * h / 2], axis=-1)


def window(img: np.ndarray, uv, half: int = 2) -> np.ndarray:
    """Return the (2 half + 1)^2 pixels of ``img`` (H, W, C) around ``uv``, as (K, C) ints."""
    x, y = int(round(uv[0])), int(round(uv[1]))
    patch = img[y - half:y + half + 1, x - half:x + half + 1]
    return patch.reshape(-1, img.shape[-1]).astype(int)


@pytest.mark.skipif(CHROMIUM is None, reason='chromium is not installed (Debian: apt-get '
                    'install chromium; .ci/run installs it), so the page cannot be rendered')
def test_the_page_shows_both_arms_in_headless_chromium(tmp_path):
    """In headless Chromium the links show orange where the bridge's states put them.

    Hiding the arms changes those pixels; the belt inlet and the items do not change.
    """
    t0 = time.monotonic()
    from scara_collab.nodes.pybullet_bridge import PyBulletBridge
    g = Graph()
    browser = None
    try:
        bridge = g.add(PyBulletBridge(context=g.context, cli_args=params_args(
            'simulation', 'controllers', overrides={'real_time_factor': 0.0})))
        # a view from the front-left, the cell left of the side panel
        camera = dict(camera_position='[0.2,-5.2,5.6]', camera_look_at='[2.9,0.3,0.3]')
        viewer = g.add(CellViewer(context=g.context, cli_args=params_args(
            overrides=dict(port=0, use_sim_time='true', **camera))))
        assert g.spin_until(lambda: bridge.sim.time > 4.0 and viewer.frames > 0
                            and len(viewer.scene.items) >= 2, 60), 'no arms and items drawn'
        g.spin_until(lambda: False, 0.1)  # let the last states reach the scene
        # Nothing is spun from here on: the scene stands still while the browser renders it.
        scene = viewer.scene
        scene.set_visible('capsules', False)  # the arms alone make the difference
        browser = Chromium(CHROMIUM, tmp_path)
        browser.open(f'http://127.0.0.1:{viewer.port}/')
        # ~10 s on an idle 2-core machine; the environment map takes longer when it is busy
        shown = browser.settled(lambda img: browser.evaluate(SHOWN), timeout=90.0)
        scene.set_visible('arms', False)
        hidden = browser.settled(lambda img: not np.array_equal(img, shown))
        t_browser = time.monotonic() - t0
        for name, img in (('shown', shown), ('hidden', hidden)):
            Image.fromarray(img).save(tmp_path / f'viewer_{name}.png')
        print(f'\nscreenshots in {tmp_path} after {t_browser:.1f} s')

        cam = viewer.server.initial_camera
        changed = (np.abs(shown.astype(int) - hidden.astype(int)).max(axis=2) > 30)[..., None]
        for arm in viewer.cell.arms:
            # link midpoints from the bridge's joint states: link 1 at the shoulder height,
            # link 2 at the tool's z at d3 = 0
            shoulder, elbow, tool = kin.arm_points(arm, viewer.q[arm.name])
            link_2_z = arm.base_position[2] + arm.tool_z0
            mids = [(shoulder + elbow) / 2, np.append(((elbow + tool) / 2)[:2], link_2_z)]
            pixels = project(mids, cam.position, cam.look_at, cam.fov)
            for part, uv in zip(('link 1', 'link 2'), pixels):
                where = f'{arm.name} {part} at pixel {uv.round()}'
                assert 0 <= uv[0] < SIZE[0] and 0 <= uv[1] < SIZE[1], f'{where}: out of view'
                moved = window(changed, uv).mean()
                assert moved > 0.6, f'{where}: only {moved:.0%} changed when hidden'
                r, gr, b = np.median(window(shown, uv), axis=0)
                assert r > 150 and r - b > 80, f'{where}: not the links\u2019 orange {r, gr, b}'
        belt = viewer.cell.belt
        still = [(belt.x_start + 0.1, belt.centre_y, belt.top_z)] + [
            np.asarray(h.position) for h in scene.items.values()]
        for uv in project(still, cam.position, cam.look_at, cam.fov):
            # swiftshader's edges flicker by a pixel between frames: a few percent, no more
            moved = window(changed, uv, half=5).mean()
            assert moved < 0.2, f'{moved:.0%} changed at {uv.round()} (belt inlet, items)'
        assert changed.mean() < 0.1
        print(f'arms cover {changed.mean():.1%} of the view; test took '
              f'{time.monotonic() - t0:.1f} s')
    finally:
        if browser is not None:
            browser.close()
        g.close()
