"""``state_publisher``: the cell's description and transforms, as robot_state_publisher does.

Publishes ``/robot_description`` (std_msgs/String, transient local: a late subscriber such as
RViz or Foxglove gets it) with the cell's URDF from the one model
(:func:`scara_collab.core.model.load_cell`), and, when ``tf2_msgs`` loads (it has no PyPI
wheel: ``scripts/build_interfaces`` builds it into the venv; a ROS install has it;
:mod:`scara_collab.nodes.optional_interfaces`), ``/tf_static`` (transient local, once: the
bases, the belt, the bins, and each safety scanner of ``config/people.yaml``: ``world`` ->
``scanner_a``, at its pose on the floor and the scan height, the frame of its ``LaserScan``)
and ``/tf`` (the six arm joints' transforms for every ``/joint_states``, stamped with it),
computed by :mod:`scara_collab.core.frames`. Without
``tf2_msgs`` it says so once and publishes the description only. Joint states with other
names, non-finite values or a stamp off the sim clock are refused at the door, like every
consumer's.
"""
from typing import List, Optional, Tuple

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from scara_collab.core.config import load_config
from scara_collab.core.frames import rotation, Tree
from scara_collab.core.model import load_cell
from scara_collab.core.scan_tracking import scanners_from_config
from scara_collab.nodes import conversions as conv
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.optional_interfaces import optional_interface
from scara_collab.nodes.qos import DEFAULT, LATCHED, LATEST
from scara_collab.nodes.runner import run_node

#: no PyPI wheel: built by scripts/build_interfaces, or from a ROS install
TF_MESSAGE = optional_interface('tf2_msgs.msg', 'TFMessage')
TFMessage = TF_MESSAGE.type


def scanner_frames(people: dict) -> List[Tuple[str, str, np.ndarray]]:
    """Return ``('world', scanner, pose (4, 4))`` of each safety scanner of the people config.

    The frame's origin is the scanner's position at the scan height, its x axis the scanner's
    yaw (the ``LaserScan`` angles are measured from it), z up.

    >>> pose = scanner_frames(load_config('people'))[0][2]
    >>> pose[:3, 3].tolist(), pose[:2, 0].round(4).tolist()
    ([-6.0, -7.0, 0.3], [0.7071, 0.7071])
    """
    out = []
    for g in scanners_from_config(people):
        pose = np.eye(4)
        pose[:3, :3] = rotation(np.array([0.0, 0.0, 1.0]), g.yaw)
        pose[:3, 3] = (g.x, g.y, g.height)
        out.append(('world', g.name, pose))
    return out


class StatePublisher(Node):
    """The description and transform publisher (see the module docstring)."""

    def __init__(self, **kwargs):
        """Publish the description (and the static transforms); follow ``/joint_states``.

        :param kwargs: passed to :class:`rclpy.node.Node` (``context``, ``cli_args``).
        """
        super().__init__('state_publisher', **kwargs)
        self.declare_parameter('profile', '')
        self.cell = load_cell(self.get_parameter('profile').value or None)
        self.tree = Tree.of(self.cell.urdf)
        self.stamps = conv.StampGate()  # joint states must carry the sim clock's time
        self.description_pub = self.create_publisher(String, 'robot_description', LATCHED)
        self.description_pub.publish(String(data=self.cell.urdf))
        self.tf_pub: Optional[object] = None
        if TFMessage is None:
            TF_MESSAGE.say_absent(self.get_logger(), '/robot_description only, no /tf')
            return
        fixed = self.tree.static() + scanner_frames(load_config('people'))
        static = self.create_publisher(TFMessage, 'tf_static', LATCHED)
        static.publish(TFMessage(transforms=[
            conv.transform_stamped(parent, child, pose, 0.0) for parent, child, pose in fixed]))
        self._static = static  # kept: a latched publisher must live on
        self.tf_pub = self.create_publisher(TFMessage, 'tf', DEFAULT)
        self.create_subscription(JointState, 'joint_states', guarded(self, self._on_state),
                                 LATEST)
        self.get_logger().info(f'publishing /tf for {len(self.tree.moving_joints)} joints and '
                               f'/tf_static for {len(fixed)} fixed ones')

    def _on_state(self, msg: JointState) -> None:
        if not conv.admit_state(self, self.stamps, msg):
            return
        names = self.tree.moving_joints
        q, _ = conv.joint_state_arrays(msg, names)  # refuses unknown names, non-finite values
        stamp = conv.to_sec(msg.header.stamp)
        self.tf_pub.publish(TFMessage(transforms=[
            conv.transform_stamped(parent, child, pose, stamp)
            for parent, child, pose in self.tree.moving(dict(zip(names, q)))]))


def main(args=None) -> None:
    """Run the state publisher (``ros2 run scara_collab state_publisher``)."""
    run_node(StatePublisher, args)


if __name__ == '__main__':
    main()
