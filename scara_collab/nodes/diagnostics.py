"""``/diagnostics``: the nodes' health on the standard topic, as ROS diagnostic tools expect.

Each node keeps its own status topic (``~/status``, ``~/stats``: one typed
:mod:`scara_collab.nodes.protocol` status each) and also publishes the same status, once a
second of sim time, in a ``diagnostic_msgs/DiagnosticArray`` on ``/diagnostics``, where
``rqt_robot_monitor``, the diagnostic aggregator or Foxglove's diagnostics panel find it.
"""
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node

from scara_collab.nodes.qos import DEFAULT

TOPIC = 'diagnostics'


class Diagnostics:
    """The ``/diagnostics`` publisher of one node.

    :param node: the node whose statuses it publishes (stamped with its clock).
    :param own: the node's own status publisher (``~/status``), which gets each status too.
    """

    def __init__(self, node: Node, own=None):
        """Create the publisher."""
        self.node, self.own = node, own
        self.pub = node.create_publisher(DiagnosticArray, TOPIC, DEFAULT)

    def publish(self, *statuses: DiagnosticStatus) -> None:
        """Publish ``statuses`` on the node's own topic, one by one, and as one array, now."""
        if self.own is not None:
            for status in statuses:
                self.own.publish(status)
        msg = DiagnosticArray()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.status = list(statuses)
        self.pub.publish(msg)
