"""state_publisher: /robot_description for late subscribers; /tf against FK of /joint_states.

The TF test needs tf2_msgs (no PyPI wheel: ``./scripts/build_interfaces`` builds it, CI does);
it composes the transforms itself, as a TF listener would, from ``world`` to each tool.
"""
import numpy as np
import pytest
from ros_harness import Graph
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf_listener import by_child, pose_in

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
