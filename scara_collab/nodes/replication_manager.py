"""Replication manager: leader-follower mirroring across the belt.

On ``/collab/target`` (PointStamped, frame ``world`` or ``<leader>_base``) it sends the leader's
target to ``/<leader>/target`` and the mirrored target ``P_R = B_R + diag(1, -1, 1)(P_L - B_L)``
to ``/<follower>/target`` with one common future start stamp, so both arms start at the same
sim instant (unless the follower's planner must delay it for safety, which its status says).
``/replication_manager/enable`` (SetBool) turns mirroring on and off; off, only the leader
moves. From ``/joint_states`` it measures the mirror error (follower tool vs the mirror of the
leader's tool) and publishes it on ``/replication_manager/mirror_error`` while mirroring is on;
``/replication_manager/status`` reports each replicated target.
"""
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from std_srvs.srv import SetBool

from scara_collab.core.kinematics import base_to_world, fk
from scara_collab.core.mirror import mirror_point
from scara_collab.core.model import load_cell
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes.runner import run_node


class ReplicationManager(Node):
    """Mirror the leader's targets onto the follower."""

    def __init__(self, **kwargs):
        super().__init__('replication_manager', **kwargs)
        self.declare_parameter('profile', '')
        self.declare_parameter('start_lead', 0.5)
        self.declare_parameter('enabled', True)
        self.cell = load_cell(self.get_parameter('profile').value or None)
        self.lead = float(self.get_parameter('start_lead').value)
        if not self.lead > 0:
            raise ValueError(f'start_lead must be > 0 s, got {self.lead}')
        self.enabled = bool(self.get_parameter('enabled').value)
        lead, foll = self.cell.leader, self.cell.follower
        self.lead_pub = self.create_publisher(PointStamped, f'/{lead.name}/target', 10)
        self.foll_pub = self.create_publisher(PointStamped, f'/{foll.name}/target', 10)
        self.status_pub = self.create_publisher(DiagnosticStatus, '~/status', 10)
        self.error_pub = self.create_publisher(Float64, '~/mirror_error', 10)
        self.create_subscription(PointStamped, '/collab/target', self._on_target, 10)
        self.create_subscription(JointState, '/joint_states', self._on_state,
                                 QoSProfile(depth=1))
        self.create_service(SetBool, '~/enable', self._on_enable)
        lockstep.join(self)  # sim time waits while this node computes
        self.get_logger().info(f'replicating {lead.name} -> {foll.name} '
                               f'({"on" if self.enabled else "off"})')

    def _status(self, level: str, message: str, **values) -> None:
        if level != 'OK':
            self.get_logger().warning(message)
        self.status_pub.publish(conv.status('replication_manager', level, message, values))

    def _on_enable(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        self.enabled = bool(req.data)
        res.success, res.message = True, f'mirroring {"on" if self.enabled else "off"}'
        self._status('OK', res.message)
        return res

    def _on_target(self, msg: PointStamped) -> None:
        frame, xyz, stamp = conv.point_stamped(msg)
        lead, foll = self.cell.leader, self.cell.follower
        if not conv.finite(xyz):
            self._status('ERROR', f'refused: non-finite target {xyz.tolist()}')
            return
        if frame in (f'{lead.name}_base', f'{lead.name}_base_link'):
            xyz = base_to_world(lead, xyz)
        elif frame != 'world':
            self._status('ERROR', f'refused: unknown frame {frame!r}; use world or '
                         f'{lead.name}_base')
            return
        now = self.get_clock().now().nanoseconds * 1e-9
        start = stamp if stamp > now else now + self.lead
        self.lead_pub.publish(conv.make_point_stamped(xyz, 'world', start))
        if not self.enabled:
            self._status('OK', f'mirroring off: {lead.name} only', start=f'{start:.3f}')
            return
        mirrored = mirror_point(lead, foll, xyz)
        self.foll_pub.publish(conv.make_point_stamped(mirrored, 'world', start))
        self._status('OK', f'{lead.name} -> {np.round(xyz, 4).tolist()}, {foll.name} -> '
                     f'{np.round(mirrored, 4).tolist()} at t={start:.3f} s',
                     start=f'{start:.3f}', leader=xyz.tolist(), follower=mirrored.tolist())

    def _on_state(self, msg: JointState) -> None:
        if not self.enabled:
            return
        lead, foll = self.cell.leader, self.cell.follower
        try:
            ql, _ = conv.joint_state_arrays(msg, lead.joint_names)
            qf, _ = conv.joint_state_arrays(msg, foll.joint_names)
        except conv.MessageError:
            return
        err = np.linalg.norm(fk(foll, qf) - mirror_point(lead, foll, fk(lead, ql)))
        self.error_pub.publish(Float64(data=float(err)))


def main(args=None) -> None:
    """Run the replication manager: ``ros2 run scara_collab replication_manager``."""
    run_node(ReplicationManager, args)
