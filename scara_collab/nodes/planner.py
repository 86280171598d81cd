"""Planner node (executables ``left_planner`` and ``right_planner``): one per arm.

A thin shell around :class:`scara_collab.core.arm_planner.ArmPlanner`, which makes every
decision (planning, scheduling against the other arm by the priority rule, queueing behind the
running move, waiting for the other arm, re-timing, answering a re-sent request): the node
turns messages into its observations and publishes the commands it returns.

Topics (relative: a namespace moves the whole cell):

* in: ``joint_states`` (both arms' joints); ``<robot>/target`` (PointStamped, frame
  ``world`` or ``<robot>_base``; a non-zero stamp is the requested start time);
  ``<robot>/target_trajectory`` (JointTrajectory: a plan of the move, as the sorting job
  offers it); ``<other>/joint_trajectory`` and ``<other>/execution_status`` (the other arm's
  committed motion, kept by :class:`scara_collab.core.motion.Heard`);
  ``<robot>/execution_status`` (the bridge's word on this arm's moves: a late start);
* out: ``<robot>/joint_trajectory`` stamped with its start, the move's id in
  ``header.frame_id`` (:mod:`scara_collab.nodes.protocol`; ``<robot>/hold`` for a hold);
  ``<robot>/planned_path``; ``<robot>/planner_status`` (OK, WARN when delayed or waiting,
  ERROR with the reason when refused; the arm then stays where it is).

Every status names its move: the id is ``<robot>/<request>``, the request being the target's
stamp in ns (the receipt time for a target stamped zero).

Parameter ``mode``: ``line`` (straight lines only), ``joint``, or ``line_or_joint`` (default:
the line, or a joint move when the goal is reachable but the straight line is not). The
planner's own parameters (``robot`` and ``profile``, read only; ``mode`` and the times of
:data:`TIMES`, which may change while it runs) are checked at start and on every change: an
invalid value stops the node, or is refused, with the reason.
"""
from typing import List, Optional, Sequence, Tuple

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core.arm_planner import (ArmPlanner, Command, HoldArm, PlannerSettings,
                                           SendMove, Status)
from scara_collab.core.config import load_config, Rule
from scara_collab.core.model import load_cell
from scara_collab.core.planning import MODES
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.faults import declare_faults, FaultyPublisher
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.params import declare_checked, declare_config
from scara_collab.nodes.qos import DEFAULT, EVENTS
from scara_collab.nodes.runner import run_node

#: the planner's own time parameters and their defaults, s: a move starts at least
#: ``send_margin`` after it is sent (a move asked for now: ``controllers.yaml``
#: ``planning_lead`` after its receipt; both plus the most the bridge started one of this
#: planner's moves late among its last 20: the latency measured, not assumed); a move waits at
#: most ``max_delay`` for the other arm's committed motion, and is refused after ``max_wait``
#: blocked by its resting pose. In lockstep a trajectory is sent a few clock ticks ahead for
#: the run to be repeatable (the default, the planning lead); in real time
#: (``--lockstep off``) the launcher sets ``send_margin`` to
#: :data:`scara_collab.graph.REALTIME_SEND_MARGIN`.
TIMES = {'send_margin': 0.05, 'max_delay': 30.0, 'max_wait': 60.0}


def _rules(robots: Sequence[str]) -> Tuple[Rule, ...]:
    """Return the checks of the planner's own parameters (``robots``: the cell's arm names)."""
    return (Rule('robot', 'str', lambda v: v in robots, f'must be one of {list(robots)}'),
            Rule('profile', 'text'),
            Rule('mode', 'str', lambda v: v in MODES, f'must be one of {MODES}'),
            *(Rule(key, 'positive') for key in TIMES))


class Planner(Node):
    """Motion planner of one arm: messages in and out of its :class:`ArmPlanner`."""

    def __init__(self, robot: str = 'scara_left', node_name: Optional[str] = None, **kwargs):
        """Declare and check the parameters, load the cell and create the topics of ``robot``.

        :param robot: the arm this planner plans for (the ``robot`` parameter's default).
        :param node_name: default ``<left|right>_planner`` from ``robot``.
        :param kwargs: passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``).
        :raises ConfigError: an unknown robot or mode, or a time parameter that is not > 0.
        """
        super().__init__(node_name or f'{robot.split("_")[-1]}_planner', **kwargs)
        self.stamps = conv.StampGate()  # joint states must carry the sim clock's time
        cfg = declare_config(self, ('controllers',))['controllers']
        params = declare_checked(
            self, {'robot': robot, 'profile': '', 'mode': 'line_or_joint', **TIMES},
            _rules(load_config('cell')['robots']['names']), dynamic=('mode', *TIMES),
            on_change=self._set_params)
        self.cell = load_cell(params['profile'] or None)
        self.arm = self.cell.arm(params['robot'])
        self.other = next(a for a in self.cell.arms if a is not self.arm)
        self.leader = self.arm is self.cell.leader
        self.trajectory_cfg = cfg['trajectory']
        self.margin = self.cell.safety_margin + float(cfg['planning_buffer'])
        self.planning_lead = float(cfg['planning_lead'])
        self.planner = ArmPlanner(
            self.arm, self.other, self.leader, self._settings(params), self._now,
            dt=1.0 / float(load_config('simulation')['physics_rate']))

        r, o = self.arm.name, self.other.name
        faults = declare_faults(self)
        self.traj_pub = self.create_publisher(JointTrajectory, f'{r}/joint_trajectory', 10)
        self.path_pub = self.create_publisher(Path, f'{r}/planned_path', 10)
        self.status_pub = FaultyPublisher(self, faults, self.create_publisher(
            DiagnosticStatus, f'{r}/planner_status', EVENTS))
        # every state, each in turn: with a depth of 1, the callback of one takes the newest,
        # and a queued move would start at one state or the next by timing
        self.create_subscription(JointState, 'joint_states', guarded(self, self._on_state),
                                 DEFAULT)
        self.create_subscription(PointStamped, f'{r}/target', guarded(self, self._on_target),
                                 10)
        self.create_subscription(JointTrajectory, f'{r}/target_trajectory',
                                 guarded(self, self._on_offer), 10)
        self.create_subscription(JointTrajectory, f'{o}/joint_trajectory',
                                 guarded(self, self._on_other), 10)
        self.create_subscription(DiagnosticStatus, f'{o}/execution_status',
                                 guarded(self, self._on_other_execution), EVENTS)
        self.create_subscription(DiagnosticStatus, f'{r}/execution_status',
                                 guarded(self, self._on_own_execution), EVENTS)
        lockstep.join(self)  # sim time waits while this node computes
        self.get_logger().info(f'{r} planner ready ({params["mode"]} moves, '
                               f'{"leader" if self.leader else "follower, yields to " + o})')

    @property
    def q(self) -> Optional[np.ndarray]:
        """This arm's last measured joints, ``(3,)``; None before the first joint state."""
        return self.planner.joints

    def _now(self) -> float:  # the node clock, s (bench/graph.py reads it too)
        return conv.now(self)

    def _settings(self, params: dict) -> PlannerSettings:
        return PlannerSettings(params['mode'], planning_lead=self.planning_lead,
                               margin=self.margin, trajectory=self.trajectory_cfg,
                               **{k: float(params[k]) for k in TIMES})

    def _set_params(self, params: dict) -> None:
        """Take the values of the dynamic parameters (on a change)."""
        self.planner.settings = self._settings(params)

    # --- commands out -----------------------------------------------------------------------
    def _send(self, commands: List[Command]) -> None:
        """Publish what the planner decided, in its order."""
        for cmd in commands:
            if isinstance(cmd, SendMove):
                t, start = cmd.plan.traj, cmd.plan.start
                self.traj_pub.publish(conv.trajectory_msg(
                    self.arm.joint_names, t.t, t.q, t.qd, t.qdd, start=start,
                    frame_id=proto.move_id(self.arm.name, cmd.request)))
                self.path_pub.publish(conv.path_msg(t.p, start))
            elif isinstance(cmd, HoldArm):
                self.traj_pub.publish(conv.trajectory_msg(
                    self.arm.joint_names, np.array([0.0]), cmd.q.reshape(1, 3),
                    frame_id=proto.hold_id(self.arm.name)))
            elif isinstance(cmd, Status):
                st = proto.PlannerStatus(
                    self.arm.name, cmd.state, proto.move_id(self.arm.name, cmd.request),
                    cmd.request, reason=cmd.reason, start=cmd.start, end=cmd.end,
                    delay=cmd.delay, kind=cmd.kind)
                if cmd.state == 'refused' and not cmd.repeated:
                    self.get_logger().warning(st.text())
                self.status_pub.publish(st.to_msg())

    # --- messages in ------------------------------------------------------------------------
    def _on_state(self, msg: JointState) -> None:
        if not conv.admit_state(self, self.stamps, msg):
            return
        try:
            q, _ = conv.joint_state_arrays(msg, self.arm.joint_names)
            q_other, _ = conv.joint_state_arrays(msg, self.other.joint_names)
        except conv.MessageError as exc:
            self.get_logger().warning(f'ignoring joint_states: {exc}', throttle_duration_sec=5.0)
            return
        self._send(self.planner.on_joint_state(q, q_other, conv.to_sec(msg.header.stamp)))

    def _on_target(self, msg: PointStamped) -> None:
        frame_id, xyz, stamp = conv.point_stamped(msg)
        try:
            frame, frame_error = conv.target_frame(frame_id, self.arm.name), ''
        except conv.MessageError as exc:
            frame, frame_error = '', str(exc)
        self._send(self.planner.on_target(proto.stamp_ns(msg.header.stamp), stamp, xyz, frame,
                                          frame_error))

    def _on_offer(self, msg: JointTrajectory) -> None:
        """Take a move offered as a plan (see the module docstring)."""
        stamp_ns = proto.stamp_ns(msg.header.stamp)
        try:
            stamp, t, q, qd, qdd = conv.trajectory_arrays(msg, self.arm.joint_names)
        except conv.MessageError as exc:
            self._send(self.planner.on_offer(stamp_ns, conv.to_sec(msg.header.stamp),
                                             error=str(exc)))
            return
        self._send(self.planner.on_offer(stamp_ns, stamp, t, q, qd, qdd))

    def _on_other(self, msg: JointTrajectory) -> None:
        try:
            stamp, t, q, _, _ = conv.trajectory_arrays(msg, self.other.joint_names)
        except conv.MessageError:
            return  # the bridge refuses and reports it; nothing committed
        self._send(self.planner.on_other_trajectory(msg.header.frame_id, stamp, t, q))

    def _on_other_execution(self, msg: DiagnosticStatus) -> None:
        """Pass on the bridge's status of the other arm's move."""
        st = proto.ExecutionStatus.from_msg(msg)
        self._send(self.planner.on_other_execution(st.state, st.move, st.start))

    def _on_own_execution(self, msg: DiagnosticStatus) -> None:
        """Pass on the bridge's status of this arm's moves (a hold or another's is ignored)."""
        st = proto.ExecutionStatus.from_msg(msg)
        try:
            _, request = proto.parse_move_id(st.move)
        except proto.ProtocolError:
            return  # the planner's hold, or a raw command: no request of this arm
        if proto.move_id(self.arm.name, request) != st.move:
            return
        self._send(self.planner.on_own_execution(st.state, request, st.start, bool(st.stamp),
                                                 st.late))


def main_left(args=None) -> None:
    """Run the left (leader) planner: ``ros2 run scara_collab left_planner``."""
    run_node(lambda: Planner(robot='scara_left', node_name='left_planner'), args)


def main_right(args=None) -> None:
    """Run the right (follower) planner: ``ros2 run scara_collab right_planner``."""
    run_node(lambda: Planner(robot='scara_right', node_name='right_planner'), args)
