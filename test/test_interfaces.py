"""The interface packages ``./scripts/build_interfaces`` builds: ROS 2 Jazzy's definitions.

The type hashes (REP-2011) the middleware announces for tf2_msgs/msg/TFMessage and
FollowJointTrajectory's feedback message are Jazzy's, so other Jazzy nodes (RViz, Foxglove,
controllers) match these types. Skipped when the packages are not built.
"""
import time

import pytest
import rclpy

from scara_collab.records.transforms import TF_HASH

try:
    from control_msgs.action import FollowJointTrajectory
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None

pytestmark = pytest.mark.skipif(
    TFMessage is None, reason='tf2_msgs, control_msgs not built (./scripts/build_interfaces)')

#: Jazzy's hash of control_msgs/action/FollowJointTrajectory_FeedbackMessage
FEEDBACK_HASH = 'RIHS01_80398fcb9674a79081a9906e2ccf0c804dd7cb15e22e362e606ee87186beab71'


def announced(node, msg_type, topic: str, timeout: float = 10.0) -> str:
    """Publish ``msg_type`` on ``topic``; return the type hash the graph announces for it."""
    node.create_publisher(msg_type, topic, 1)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        infos = node.get_publishers_info_by_topic(topic)
        if infos:
            return str(infos[0].topic_type_hash)
        time.sleep(0.05)
    return ''


def test_the_built_types_announce_jazzys_type_hashes():
    """The graph announces Jazzy's hashes for TFMessage and FollowJointTrajectory feedback."""
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('test_interfaces', context=context)
    try:
        assert announced(node, TFMessage, '/test_interfaces/tf') == TF_HASH
        feedback = FollowJointTrajectory.Impl.FeedbackMessage
        assert announced(node, feedback, '/test_interfaces/feedback') == FEEDBACK_HASH
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
