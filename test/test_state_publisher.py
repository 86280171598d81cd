"""state_publisher: /robot_description for late subscribers; /tf against FK of /joint_states.

The TF tests need tf2_msgs (no PyPI wheel: ``./scripts/build_interfaces`` builds it, CI does);
they compose the transforms themselves, as a TF listener would, from ``world`` to each tool,
and place a safety scanner's rays from its frame as RViz does.
"""
import math
from pathlib import Path

import numpy as np
import pytest
from ros_harness import Graph
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf_listener import by_child, pose_in
import yaml

from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk
from scara_collab.core.model import parse_urdf
from scara_collab.nodes import conversions as conv
from scara_collab.nodes.qos import LATCHED

try:
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None


@pytest.fixture
def graph():
    """Yield the bridge (unthrottled, no feed) and the state publisher."""
    g = Graph()
    g.bridge = g.add_node_of('pybullet_bridge', real_time_factor=0.0, feed_interval=0.0,
                             lockstep_window=0.0, use_sim_time=True)
    g.publisher = g.add_node_of('state_publisher', use_sim_time=True)
    yield g
    g.close()


def test_the_description_reaches_a_late_subscriber_and_names_the_six_joints(graph):
    """Subscribed after it was published, ``/robot_description`` still arrives: the cell URDF."""
    got = graph.collect(String, '/robot_description', LATCHED)
    assert graph.spin_until(lambda: got, timeout=20)
    urdf = parse_urdf(got[-1].data)
    moving = [j.name for j in urdf.robot.joints if j.type != 'fixed']
    assert moving == [n for a in graph.bridge.cell.arms for n in a.joint_names]
    assert got[-1].data == graph.bridge.cell.urdf  # the one model


@pytest.mark.skipif(TFMessage is None, reason='tf2_msgs not built (./scripts/build_interfaces)')
def test_the_tf_chain_from_world_to_each_tool_is_fk_of_the_joint_states(graph):
    """Composed from ``/tf_static`` and ``/tf``, ``world`` -> ``<robot>_quill`` is FK to 1e-6 m."""
    static = graph.collect(TFMessage, '/tf_static', LATCHED)
    moving = graph.collect(TFMessage, '/tf', 100)
    states = graph.collect(JointState, '/joint_states', 100)
    cell = graph.bridge.cell
    q0 = graph.bridge.sim.arm_state(cell.leader.name)[0]
    graph.bridge.sim.execute(cell.leader.name, [0.5, 2.0], [q0, q0 + [0.5, -0.4, 0.2]])
    assert graph.spin_until(lambda: static and graph.bridge.sim.time > 1.2, timeout=60)
    assert graph.spin_until(lambda: moving and states and conv.to_sec(
        moving[-1].transforms[0].header.stamp) >= conv.to_sec(states[-1].header.stamp) - 1e-9,
        timeout=20)
    tree = by_child(t for m in static for t in m.transforms)
    by_stamp = {conv.to_sec(m.header.stamp): m for m in states}
    pairs = [(tf, by_stamp[t]) for tf in moving
             for t in [conv.to_sec(tf.transforms[0].header.stamp)] if t in by_stamp and t > 1.0]
    assert pairs, 'a /tf of a joint state the probe also heard, while the arm moves'
    tf, state = pairs[-1]
    tree.update(by_child(tf.transforms))
    for arm in cell.arms:
        q, _ = conv.joint_state_arrays(state, arm.joint_names)
        np.testing.assert_allclose(pose_in(tree, f'{arm.name}_quill')[:3, 3], fk(arm, q),
                                   atol=1e-6)
    assert {t.header.frame_id for m in static for t in m.transforms} == {'world'}


@pytest.mark.skipif(TFMessage is None, reason='tf2_msgs not built (./scripts/build_interfaces)')
def test_each_safety_scanner_has_a_static_frame_at_its_pose_and_scan_height(graph):
    """``world`` -> ``scanner_a``/``scanner_b`` put a ray where config/people.yaml's pose does.

    A range ``r`` at angle ``a`` of the scan, at ``(r cos a, r sin a, 0)`` in the scanner's
    frame, lands at ``(x + r cos(yaw + a), y + r sin(yaw + a), height)`` in the world.
    """
    static = graph.collect(TFMessage, '/tf_static', LATCHED)
    assert graph.spin_until(lambda: static, timeout=20)
    frames = by_child(t for m in static for t in m.transforms)
    scanner = load_config('people')['scanner']
    assert set(scanner['names']) <= set(frames)
    for name in scanner['names']:
        x, y, yaw = scanner[name]['pose']
        pose = pose_in(frames, name)
        for a, r in ((0.0, 2.0), (1.2, 5.5), (-2.0, 0.7)):
            ray = pose @ np.array([r * math.cos(a), r * math.sin(a), 0.0, 1.0])
            np.testing.assert_allclose(ray[:3], [x + r * math.cos(yaw + a),
                                                 y + r * math.sin(yaw + a), scanner['height']],
                                       atol=1e-9)


def test_the_rviz_config_shows_the_person_the_scan_and_the_rings_in_world():
    """config/cell.rviz has the person's, the scanners' and the monitor's displays.

    Its LaserScan display places each scan by the scan's frame: a scanner's, published above.
    """
    rviz = yaml.safe_load((Path(__file__).resolve().parents[1] / 'config' / 'cell.rviz')
                          .read_text())['Visualization Manager']
    assert rviz['Global Options']['Fixed Frame'] == 'world'
    shown = {d['Topic']['Value']: d['Class'] for d in rviz['Displays'] if 'Topic' in d}
    assert shown['/person/markers'] == 'rviz_default_plugins/MarkerArray'
    assert shown['/safety_scanner/scan'] == 'rviz_default_plugins/LaserScan'
    assert shown['/separation_monitor/markers'] == 'rviz_default_plugins/MarkerArray'
    assert shown['/conveyor/items'] == 'rviz_default_plugins/MarkerArray'  # and the cell's
