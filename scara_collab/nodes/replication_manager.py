"""Replication manager: leader-follower mirroring across the belt, and the mirror error's source.

On ``/collab/target`` (PointStamped, frame ``world`` or ``<leader>_base``) it sends the leader's
target to ``/<leader>/target`` and the mirrored target ``P_R = B_R + diag(1, -1, 1)(P_L - B_L)``
to ``/<follower>/target`` with the *same* stamp: the stamp is the requested start and the
move's identity (:mod:`scara_collab.nodes.protocol`), so both planners plan the same request
and both arms start at the same sim instant (unless the follower's planner must delay it for
safety, which its status says). A target stamped zero gets ``now + collab_lead``.
On ``/collab/target_trajectory`` (the leader's move as the sorting job planned it,
JointTrajectory; :mod:`scara_collab.nodes.protocol`) it does the same with the plan: the
leader's goes on unchanged to ``/<leader>/target_trajectory``, the follower's is its mirror
image joint by joint (``(theta1, theta2, d3) -> (-theta1, -theta2, d3)``, exact for two arms
of the same geometry; otherwise the follower gets the mirrored end point), so neither planner
plans the pair's move again.
``~/enable`` (SetBool, idempotent) turns mirroring on and off; off, only the leader moves and
the node does not listen to ``/joint_states`` (the launcher starts it off, ``enabled:=false``,
in every mode but mirrored and idle: a collaborative job has no mirror error to measure).

The mirror error (follower tool vs the mirror image of the leader tool, from ``/joint_states``)
is measured here and only here. A replicated request is *in step* when the bridge accepted
both arms' moves for it with the same start (``/<robot>/execution_status``); while both run
such a pair, every state's error counts towards ``error_max``. Requests whose moves did not
start together are counted (``not_in_step``) with the reason. ``~/mirror_error`` (Float64)
carries the live error while mirroring is on, ``~/status``
(:class:`~scara_collab.nodes.protocol.MirrorStatus`, 1 Hz sim time) the figures.
"""
from typing import Dict, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core import moves
from scara_collab.core.config import Rule
from scara_collab.core.kinematics import base_to_world, fk
from scara_collab.core.mirror import is_joint_mirror, mirror_error, mirror_joints, mirror_point
from scara_collab.core.model import load_cell
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.diagnostics import Diagnostics
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.params import declare_checked
from scara_collab.nodes.qos import DEFAULT, EVENTS
from scara_collab.nodes.runner import run_node

SAME_START = 1e-6  # s: two starts closer than this are the same physics instant
MIRRORED_START = 0.005  # m: a pair that starts with a larger error did not start mirrored


class ReplicationManager(Node):
    """Mirror the leader's targets onto the follower; measure the in-step mirror error."""

    def __init__(self, **kwargs):
        """Declare and check the parameters, load the cell and create the topics and service.

        :param kwargs: passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``).
        :raises ConfigError: (a ``ValueError``) a ``collab_lead`` that is not > 0, an
            ``enabled`` that is not a bool.
        """
        super().__init__('replication_manager', **kwargs)
        self.stamps = conv.StampGate()  # joint states must carry the sim clock's time
        params = declare_checked(self, {'profile': '', 'collab_lead': 0.5, 'enabled': True},
                                 (Rule('profile', 'text'), Rule('collab_lead', 'positive'),
                                  Rule('enabled', 'bool')))
        self.cell = load_cell(params['profile'] or None)
        self.lead = float(params['collab_lead'])
        self.enabled = params['enabled']
        lead, foll = self.cell.leader, self.cell.follower
        # request -> {robot: (start, end)} as the bridge accepted them
        self.accepted: Dict[int, Dict[str, Tuple[float, float]]] = {}
        # (start, end, started mirrored?) of the pair both arms run in step
        self.in_step: Optional[Tuple[float, float, Optional[bool]]] = None
        self.current: Dict[str, Optional[str]] = {}  # robot -> move id the bridge runs
        self.error: Optional[float] = None
        self.error_max: Optional[float] = None
        self.error_max_time: Optional[float] = None
        self.in_step_moves = 0
        self.not_in_step = 0
        self.last_reason = ''
        self.lead_pub = self.create_publisher(PointStamped, f'{lead.name}/target', 10)
        self.foll_pub = self.create_publisher(PointStamped, f'{foll.name}/target', 10)
        self.offer_pubs = tuple(self.create_publisher(JointTrajectory,
                                                      f'{a.name}/target_trajectory', 10)
                                for a in (lead, foll))
        self.mirror_by_joints = is_joint_mirror(lead, foll)
        self.status_pub = self.create_publisher(DiagnosticStatus, '~/status', 10)
        self.diagnostics = Diagnostics(self, self.status_pub)  # and on /diagnostics
        self.error_pub = self.create_publisher(Float64, '~/mirror_error', 10)
        self.create_subscription(PointStamped, 'collab/target', guarded(self, self._on_target),
                                 10)
        self.create_subscription(JointTrajectory, 'collab/target_trajectory',
                                 guarded(self, self._on_offer), 10)
        self._state_sub = None  # /joint_states only while mirroring (nothing to measure else)
        self._set_enabled(self.enabled)
        for arm in self.cell.arms:
            self.create_subscription(DiagnosticStatus, f'{arm.name}/execution_status',
                                     guarded(self, self._on_execution), EVENTS)
        self.create_service(SetBool, '~/enable', guarded(self, self._on_enable, True))
        self.create_timer(1.0, guarded(self, self._publish_status))
        lockstep.join(self)  # sim time waits while this node computes
        self.get_logger().info(f'replicating {lead.name} -> {foll.name} '
                               f'({"on" if self.enabled else "off"})')

    def _set_enabled(self, on: bool) -> None:
        self.enabled = on
        if on and self._state_sub is None:
            self._state_sub = self.create_subscription(
                JointState, 'joint_states', guarded(self, self._on_state), DEFAULT)  # each
        elif not on and self._state_sub is not None:
            self.destroy_subscription(self._state_sub)
            self._state_sub = None
            self.error = None  # no live error while off

    def _on_enable(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        self._set_enabled(bool(req.data))
        res.success, res.message = True, f'mirroring {"on" if self.enabled else "off"}'
        self.get_logger().info(res.message)
        return res

    def _on_target(self, msg: PointStamped) -> None:
        frame_id, xyz, _ = conv.point_stamped(msg)
        lead, foll = self.cell.leader, self.cell.follower
        if not conv.finite(xyz):
            raise ValueError(f'non-finite target {xyz.tolist()}')
        if conv.target_frame(frame_id, lead.name) == 'base':
            xyz = base_to_world(lead, xyz)
        stamp = msg.header.stamp
        if conv.request_id(stamp) == 0:  # "now": one common start for both arms
            stamp = conv.to_time(conv.now(self) + self.lead)
        out = conv.make_point_stamped(xyz, 'world')
        out.header.stamp = stamp  # passed through exactly: it is the move's id
        self.lead_pub.publish(out)
        if not self.enabled:
            return
        mirrored = conv.make_point_stamped(mirror_point(lead, foll, xyz), 'world')
        mirrored.header.stamp = stamp
        self.foll_pub.publish(mirrored)

    def _on_offer(self, msg: JointTrajectory) -> None:
        """Pass the leader's plan on; offer the follower its mirror image (or the end point)."""
        lead, foll = self.cell.leader, self.cell.follower
        _, t, q, qd, qdd = conv.trajectory_arrays(msg, lead.joint_names)
        if conv.request_id(msg.header.stamp) == 0:  # "now": one common start for both arms
            msg.header.stamp = conv.to_time(conv.now(self) + self.lead)
        self.offer_pubs[0].publish(msg)
        if not self.enabled:
            return
        if self.mirror_by_joints and qd is not None and qdd is not None:
            out = conv.trajectory_msg(foll.joint_names, t, mirror_joints(q), mirror_joints(qd),
                                      mirror_joints(qdd))
            pub = self.offer_pubs[1]
        else:  # the follower's planner plans it
            out = conv.make_point_stamped(mirror_point(lead, foll, fk(lead, q[-1])), 'world')
            pub = self.foll_pub
        out.header.stamp = msg.header.stamp  # the same request: the move's id
        pub.publish(out)

    def _on_execution(self, msg: DiagnosticStatus) -> None:
        st = proto.ExecutionStatus.from_msg(msg)
        if st.state in ('preempted', 'held', 'refused', 'finished'):
            if self.current.get(st.robot) == st.move or st.state == 'held':
                self.current[st.robot] = None  # that arm no longer runs the pair's move
                self.in_step = None if st.state != 'finished' else self.in_step
            return
        if st.state != 'accepted':
            return
        self.current[st.robot] = st.move
        if not st.move:  # a trajectory without a request: not a replicated move
            self.in_step = None
            return
        robot, request = moves.parse_move_id(st.move)
        pair = self.accepted.setdefault(request, {})
        pair[robot] = (st.start, st.end)
        while len(self.accepted) > 32:
            self.accepted.pop(next(iter(self.accepted)))
        if len(pair) < len(self.cell.arms):
            self.in_step = None  # one arm runs a move the other does not (yet)
            return
        (s1, e1), (s2, e2) = pair.values()
        if abs(s1 - s2) < SAME_START and abs(e1 - e2) < 1e-3:  # same start, same motion
            self.in_step = (s1, max(e1, e2), None)
            self.in_step_moves += 1
        else:
            self.in_step = None
            self.not_in_step += 1
            self.last_reason = (f'request {request}: the moves run {s1:.3f}..{e1:.3f} and '
                                f'{s2:.3f}..{e2:.3f} s (the follower yielded or came late)')

    def _on_state(self, msg: JointState) -> None:
        if not self.enabled or not conv.admit_state(self, self.stamps, msg):
            return
        lead, foll = self.cell.leader, self.cell.follower
        ql, _ = conv.joint_state_arrays(msg, lead.joint_names)
        qf, _ = conv.joint_state_arrays(msg, foll.joint_names)
        err = float(mirror_error(lead, foll, fk(lead, ql), fk(foll, qf)))
        self.error = err
        self.error_pub.publish(Float64(data=err))
        t = conv.to_sec(msg.header.stamp)
        if self.in_step is not None and self.in_step[0] <= t:
            if self.in_step[2] is None:  # the pair's first state: did it start mirrored?
                self.in_step = (*self.in_step[:2], err <= MIRRORED_START)
                if not self.in_step[2]:
                    self.in_step_moves -= 1
                    self.not_in_step += 1
                    self.last_reason = (f'a pair started {err * 1e3:.1f} mm from mirrored at '
                                        f't={t:.3f} s (the arms came from unmirrored poses)')
            if t > self.in_step[1] or not self.in_step[2]:
                self.in_step = None
            elif self.error_max is None or err > self.error_max:
                self.error_max, self.error_max_time = err, t

    def status(self) -> proto.MirrorStatus:
        """Return the mirror figures so far."""
        return proto.MirrorStatus(self.enabled, round(conv.now(self), 3), self.error,
                                  self.error_max, self.error_max_time, self.in_step_moves,
                                  self.not_in_step, self.last_reason)

    def _publish_status(self) -> None:
        self.diagnostics.publish(self.status().to_msg())


def main(args=None) -> None:
    """Run the replication manager: ``ros2 run scara_collab replication_manager``."""
    run_node(ReplicationManager, args)
