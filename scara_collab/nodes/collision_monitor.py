"""Collision monitor: the runtime safety net behind the planners.

On every ``/joint_states`` message it computes the arm-to-arm capsule surface distance,
publishes it on ``/collision_monitor/min_distance``, and latches ``/emergency_stop`` true
(transient local; the bridge holds both arms) when it falls below the safety margin.
``/collision_monitor/clear`` (std_srvs/Trigger) releases the stop once the arms are apart
again. Capsule markers coloured by distance go to ``/collision_monitor/capsules``.
"""
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Point
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, ColorRGBA, Float64, Header
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from scara_collab.core import collision
from scara_collab.core.model import load_cell
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes.runner import run_node

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)


class CollisionMonitor(Node):
    """Watch the arm-to-arm distance and stop both arms if the margin is broken."""

    def __init__(self, **kwargs):
        super().__init__('collision_monitor', **kwargs)
        self.declare_parameter('profile', '')
        self.declare_parameter('safety_margin', -1.0)  # < 0: the cell's margin
        self.declare_parameter('marker_rate', 10.0)
        self.cell = load_cell(self.get_parameter('profile').value or None)
        margin = float(self.get_parameter('safety_margin').value)
        self.margin = self.cell.safety_margin if margin < 0 else margin
        self.marker_period = 1.0 / float(self.get_parameter('marker_rate').value)
        self.stopped = False
        self.last = float('inf')
        self.minimum = float('inf')
        self._next_marker = 0.0
        self.dist_pub = self.create_publisher(Float64, '~/min_distance', 10)
        self.estop_pub = self.create_publisher(Bool, '/emergency_stop', LATCHED)
        self.status_pub = self.create_publisher(DiagnosticStatus, '~/status', 10)
        self.marker_pub = self.create_publisher(MarkerArray, '~/capsules', 10)
        self.create_subscription(JointState, '/joint_states', self._on_state,
                                 QoSProfile(depth=1))
        self.create_service(Trigger, '~/clear', self._on_clear)
        self.estop_pub.publish(Bool(data=False))
        lockstep.join(self)  # sim time waits while this node computes
        self.get_logger().info(f'watching {self.cell.leader.name} vs '
                               f'{self.cell.follower.name}, margin {self.margin} m')

    def _on_state(self, msg: JointState) -> None:
        a, b = self.cell.arms
        try:
            qa, _ = conv.joint_state_arrays(msg, a.joint_names)
            qb, _ = conv.joint_state_arrays(msg, b.joint_names)
        except conv.MessageError as exc:
            self.get_logger().warning(f'ignoring joint_states: {exc}', throttle_duration_sec=5.0)
            return
        pairs = collision.arm_pair_distances(a, qa, b, qb)
        d = float(pairs.min())
        self.last, self.minimum = d, min(self.minimum, d)
        self.dist_pub.publish(Float64(data=d))
        stamp = conv.to_sec(msg.header.stamp)
        if d < self.margin and not self.stopped:
            self.stopped = True
            self.estop_pub.publish(Bool(data=True))
            i, j = np.unravel_index(np.argmin(pairs), pairs.shape)
            parts = ('link 1', 'link 2', 'quill')
            text = (f'margin broken: {a.name} {parts[i]} to {b.name} {parts[j]} {d:.4f} m < '
                    f'{self.margin} m at t={stamp:.3f} s; emergency stop')
            self.get_logger().error(text)
            self.status_pub.publish(conv.status('collision_monitor', 'ERROR', text,
                                                {'distance': f'{d:.4f}', 'time': f'{stamp:.3f}'}))
        if stamp >= self._next_marker:
            self._next_marker = stamp + self.marker_period
            self.marker_pub.publish(self._markers(qa, qb, d, msg.header))

    def _on_clear(self, req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        if self.last < self.margin:
            res.success = False
            res.message = f'arms still {self.last:.3f} m apart (< {self.margin} m); not cleared'
            return res
        self.stopped = False
        self.estop_pub.publish(Bool(data=False))
        res.success, res.message = True, 'emergency stop cleared'
        self.get_logger().info(res.message)
        return res

    def _markers(self, qa, qb, d: float, header: Header) -> MarkerArray:
        colour = (ColorRGBA(r=0.9, g=0.1, b=0.1, a=0.6) if d < self.margin else
                  ColorRGBA(r=0.95, g=0.6, b=0.1, a=0.5) if d < 2 * self.margin else
                  ColorRGBA(r=0.1, g=0.8, b=0.2, a=0.4))
        out = MarkerArray()
        header = Header(stamp=header.stamp, frame_id='world')
        k = 0
        for arm, q in zip(self.cell.arms, (qa, qb)):
            starts, ends, radii = collision.arm_capsules(arm, q)
            for s, e, r in zip(starts, ends, radii):
                m = Marker(header=header, ns=f'{arm.name}_capsules', id=k,
                           type=Marker.LINE_STRIP, action=Marker.ADD, color=colour)
                m.scale.x = 2 * float(r)
                m.points = [Point(x=float(s[0]), y=float(s[1]), z=float(s[2])),
                            Point(x=float(e[0]), y=float(e[1]), z=float(e[2]))]
                m.pose.orientation.w = 1.0
                out.markers.append(m)
                k += 1
        return out


def main(args=None) -> None:
    """Run the collision monitor: ``ros2 run scara_collab collision_monitor``."""
    run_node(CollisionMonitor, args)
