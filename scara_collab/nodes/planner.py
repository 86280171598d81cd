"""Planner node (``left_planner``, ``right_planner``): one per arm, a thin shell.

:class:`scara_collab.core.arm_planner.ArmPlanner` makes every decision; the node turns messages
into its observations and publishes the commands it returns. Topics (relative), statuses and
parameters: ``docs/interface.md``; a parameter out of range is refused with the reason.
"""
from typing import List, Optional

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core import moves
from scara_collab.core.arm_planner import (ArmPlanner, planner_parameters, PlannerCommand,
                                           PlannerSettings, SendMove, Status, TIMES)
from scara_collab.core.config import load_config
from scara_collab.core.model import load_cell
from scara_collab.nodes import conversions as conv, lockstep, protocol as proto
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.params import declare_checked, declare_config
from scara_collab.nodes.qos import DEFAULT, EVENTS
from scara_collab.nodes.runner import run_node


class Planner(Node):
    """Motion planner of one arm: messages in and out of its :class:`ArmPlanner`."""

    def __init__(self, robot: str = 'scara_left', node_name: Optional[str] = None, **kwargs):
        """Check the parameters, load the cell, create the topics of ``robot`` (the default).

        :raises ConfigError: an unknown robot or mode, or a time parameter that is not > 0.
        """
        super().__init__(node_name or f'{robot.split("_")[-1]}_planner', **kwargs)
        self.stamps = conv.StampGate()  # joint states must carry the sim clock's time
        cfg = declare_config(self, ('controllers',))['controllers']
        params = declare_checked(
            self, *planner_parameters(robot, load_config('cell')['robots']['names']),
            dynamic=('mode', *TIMES), on_change=lambda p: setattr(
                self.planner, 'settings', PlannerSettings.of(p, self.cell.safety_margin, cfg)))
        self.cell = load_cell(params['profile'] or None)
        self.arm = self.cell.arm(params['robot'])
        self.other = next(a for a in self.cell.arms if a is not self.arm)
        self.planner = ArmPlanner(
            self.arm, self.other, self.arm is self.cell.leader,
            PlannerSettings.of(params, self.cell.safety_margin, cfg), lambda: conv.now(self),
            dt=1.0 / float(load_config('simulation')['physics_rate']))
        r, o = self.arm.name, self.other.name
        self.traj_pub = self.create_publisher(JointTrajectory, f'{r}/joint_trajectory', 10)
        self.path_pub = self.create_publisher(Path, f'{r}/planned_path', 10)
        self.status_pub = self.create_publisher(DiagnosticStatus, f'{r}/planner_status',
                                                EVENTS)
        # every state, each in turn (a depth of 1 would take the newest, and a queued move
        # would start at one state or the next by timing)
        for kind, topic, callback, depth in (
                (JointState, 'joint_states', self._on_state, DEFAULT),
                (PointStamped, f'{r}/target', self._on_target, 10),
                (JointTrajectory, f'{r}/target_trajectory', self._on_offer, 10),
                (JointTrajectory, f'{o}/joint_trajectory', self._on_other, 10),
                (DiagnosticStatus, f'{o}/execution_status', self._on_other_execution, EVENTS),
                (DiagnosticStatus, f'{r}/execution_status', self._on_own_execution, EVENTS),
                (DiagnosticStatus, f'{r}/trajectory_clock', self._on_clock, EVENTS),
                (DiagnosticStatus, f'{o}/trajectory_clock', self._on_clock, EVENTS)):
            self.create_subscription(kind, topic, guarded(self, callback), depth)
        # sim time waits while this node computes, and for the bridge's word on each move it
        # sent: a trajectory and the answer travel on two topics, and under a heavy load the
        # large trajectory came 0.47 s of sim time after the answer that let the bridge step on
        self.lockstep = lockstep.join(self)
        self.get_logger().info(f'{r} planner ready ({params["mode"]} moves, ' + (
            'leader)' if self.arm is self.cell.leader else f'follower, yields to {o})'))

    def _send(self, commands: List[PlannerCommand]) -> None:
        """Publish what the planner decided, in its order."""
        for cmd in commands:
            if isinstance(cmd, Status):
                st = proto.PlannerStatus.of(self.arm.name, cmd)
                if cmd.state == 'refused' and not cmd.repeated:
                    self.get_logger().warning(st.text())
                self.status_pub.publish(st.to_msg())
                continue
            msg = conv.move_msg(self.arm.name, self.arm.joint_names, cmd)
            self.traj_pub.publish(msg)
            if self.lockstep is not None:  # until the bridge accepts or refuses it
                self.lockstep.await_reply(('move', msg.header.frame_id))
            if isinstance(cmd, SendMove):
                self.path_pub.publish(conv.path_msg(cmd.plan.traj.p, cmd.plan.start))

    def _on_state(self, msg: JointState) -> None:
        if conv.admit_state(self, self.stamps, msg):
            q = [conv.joint_state_arrays(msg, a.joint_names)[0] for a in (self.arm, self.other)]
            self._send(self.planner.on_joint_state(*q, conv.to_sec(msg.header.stamp)))

    def _on_target(self, msg: PointStamped) -> None:
        xyz, stamp, frame, error = conv.target_of(msg, self.arm.name)  # refused with a reason
        self._send(self.planner.on_target(conv.request_id(msg.header.stamp), stamp, xyz, frame,
                                          error))

    def _on_offer(self, msg: JointTrajectory) -> None:
        arrays, error = conv.offer_of(msg, self.arm.joint_names)  # refused with the reason
        self._send(self.planner.on_offer(conv.request_id(msg.header.stamp), *arrays,
                                         error=error))

    def _on_other(self, msg: JointTrajectory) -> None:
        stamp, t, q, _, _ = conv.trajectory_arrays(msg, self.other.joint_names)
        self._send(self.planner.on_other_trajectory(msg.header.frame_id, stamp, t, q))

    def _on_other_execution(self, msg: DiagnosticStatus) -> None:
        st = proto.ExecutionStatus.from_msg(msg)
        self._send(self.planner.on_other_execution(st.state, st.move, st.start))

    def _on_own_execution(self, msg: DiagnosticStatus) -> None:
        st = proto.ExecutionStatus.from_msg(msg)
        if self.lockstep is not None and st.state in ('accepted', 'refused'):
            self.lockstep.reply(('move', st.move))  # the bridge has the move (or a hold)
        if (request := moves.request_of(self.arm.name, st.move)) is not None:  # not a hold
            self._send(self.planner.on_own_execution(st.state, request, st.start, st.stamp,
                                                     st.end))

    def _on_clock(self, msg: DiagnosticStatus) -> None:
        clock = proto.TrajectoryClock.from_msg(msg)
        if clock.robot == self.arm.name:
            self.planner.on_clock(own=clock.lag)
        elif clock.robot == self.other.name:
            self.planner.on_clock(other=clock.lag)


def main_left(args=None) -> None:
    """Run the left (leader) planner: ``ros2 run scara_collab left_planner``."""
    run_node(lambda: Planner(robot='scara_left', node_name='left_planner'), args)


def main_right(args=None) -> None:
    """Run the right (follower) planner: ``ros2 run scara_collab right_planner``."""
    run_node(lambda: Planner(robot='scara_right', node_name='right_planner'), args)
