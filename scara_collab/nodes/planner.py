"""Planner node (executables ``left_planner`` and ``right_planner``): one per arm.

Parameter ``mode``: ``line`` (straight lines only), ``joint``, or ``line_or_joint`` (default:
the line, or a joint move when the goal is reachable but the straight line is not).

Keeps its arm's state from ``/joint_states``; on ``/<robot>/target`` (PointStamped, frame
``world`` or ``<robot>_base``; a non-zero stamp is the requested start time) it plans the
straight Cartesian move (or a joint move, parameter ``mode``) from the current state, schedules
it against the other arm's committed motion (heard on ``/<other>/joint_trajectory``) by the
priority rule of :mod:`scara_collab.core.planning`, and publishes ``/<robot>/joint_trajectory``
stamped with its start, ``/<robot>/planned_path`` and ``/<robot>/planner_status`` (OK, WARN
when delayed, ERROR with the reason when refused; the arm then stays where it is).

A target that arrives while the arm's own move is still running is queued and planned when
that move ends (the bridge replaces a running trajectory, so it is not published earlier).
The follower re-times its not-yet-started move when a new leader move would conflict with it.
When the other arm's resting pose blocks a move (no delay helps until that arm moves again),
the planner reports WARN "waiting", retries whenever the other arm commits a new move, and
refuses after ``max_wait`` seconds.
"""
from typing import Optional

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core.kinematics import IKError
from scara_collab.core.model import load_cell
from scara_collab.core.planning import MODES, Plan, plan_path, schedule, Timeline
from scara_collab.core.trajectory import path_metrics
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes.params import declare_config
from scara_collab.nodes.runner import run_node


LATEST = QoSProfile(depth=1)


def _lateness(msg: DiagnosticStatus) -> float:
    """Seconds by which the bridge started a trajectory after its stamp (0 if on time)."""
    values = conv.status_values(msg)
    if msg.level != DiagnosticStatus.OK or 'start' not in values or 'stamp' not in values:
        return 0.0
    stamp = float(values['stamp'])
    return float(values['start']) - stamp if stamp > 0 else 0.0


class Planner(Node):
    """Motion planner of one arm."""

    def __init__(self, robot: str = 'scara_left', node_name: Optional[str] = None, **kwargs):
        super().__init__(node_name or f'{robot.split("_")[-1]}_planner', **kwargs)
        cfg = declare_config(self, ('controllers',))['controllers']
        self.declare_parameter('robot', robot)
        self.declare_parameter('profile', '')
        self.declare_parameter('mode', 'line_or_joint')
        self.declare_parameter('start_lead', 0.05)
        self.declare_parameter('planning_buffer', 0.03)
        self.declare_parameter('max_delay', 30.0)
        self.declare_parameter('max_wait', 60.0)
        self.cell = load_cell(self.get_parameter('profile').value or None)
        robot = self.get_parameter('robot').value
        names = [a.name for a in self.cell.arms]
        if robot not in names:
            raise ValueError(f'parameter robot must be one of {names}, got {robot!r}')
        self.arm = self.cell.arm(robot)
        self.other = next(a for a in self.cell.arms if a.name != robot)
        self.leader = self.arm is self.cell.leader
        self.mode = self.get_parameter('mode').value
        if self.mode not in MODES:
            raise ValueError(f'parameter mode must be one of {MODES}, got {self.mode!r}')
        self.traj_cfg = cfg['trajectory']
        self.lead = float(self.get_parameter('start_lead').value)
        self.margin = self.cell.safety_margin + float(self.get_parameter('planning_buffer').value)
        self.max_delay = float(self.get_parameter('max_delay').value)
        self.max_wait = float(self.get_parameter('max_wait').value)

        self.q: Optional[np.ndarray] = None
        self.q_stamp = 0.0  # sim time of the state in self.q
        self.q_other: Optional[np.ndarray] = None
        self.mine: Optional[Plan] = None            # my committed move
        self.pending_target = None                  # (xyz, frame, asked) of my move
        self.theirs: Optional[Timeline] = None      # the other arm's committed move
        self.theirs_before: Optional[Timeline] = None  # ... and the one it replaced
        self.queued = None                          # (xyz, frame, stamp) after my move
        self.waiting = None                         # (xyz, frame, asked): blocked target

        r, o = self.arm.name, self.other.name
        self.traj_pub = self.create_publisher(JointTrajectory, f'/{r}/joint_trajectory', 10)
        self.path_pub = self.create_publisher(Path, f'/{r}/planned_path', 10)
        self.status_pub = self.create_publisher(DiagnosticStatus, f'/{r}/planner_status', 10)
        # only the latest state matters: a backlog of old ones would make plans start stale
        self.create_subscription(JointState, '/joint_states', self._on_state, LATEST)
        self.create_subscription(PointStamped, f'/{r}/target', self._on_target, 10)
        self.create_subscription(JointTrajectory, f'/{o}/joint_trajectory', self._on_other, 10)
        self.create_subscription(DiagnosticStatus, f'/{o}/execution_status',
                                 self._on_other_execution, 10)
        self.create_subscription(DiagnosticStatus, f'/{r}/execution_status',
                                 self._on_own_execution, 10)
        lockstep.join(self)  # sim time waits while this node computes
        self.get_logger().info(f'{r} planner ready ({self.mode} moves, '
                               f'{"leader" if self.leader else "follower, yields to " + o})')

    # --- helpers ----------------------------------------------------------------------------
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _status(self, level: str, message: str, **values) -> None:
        if level == 'ERROR':
            self.get_logger().warning(message)
        self.status_pub.publish(conv.status(f'{self.arm.name}/planner', level, message, values))

    def _other_timeline(self, now: float) -> Timeline:
        if self.theirs is not None and self.theirs.end > now:
            return self.theirs
        return Timeline.hold(now, self.q_other)

    def _publish(self, plan: Plan, note: str) -> None:
        t = plan.traj
        self.traj_pub.publish(conv.trajectory_msg(self.arm.joint_names, t.t, t.q, t.qd, t.qdd,
                                                  start=plan.start))
        self.path_pub.publish(conv.path_msg(t.p, plan.start))
        self._publish_status(plan, note)

    def _publish_status(self, plan: Plan, note: str) -> None:
        t = plan.traj
        level = 'WARN' if plan.delay > 0 else 'OK'
        msg = note + (f'; delayed by {plan.delay:.2f} s for {self.other.name}'
                      if plan.delay > 0 else '')
        self._status(level, msg, start=f'{plan.start:.3f}', duration=f'{t.duration:.3f}',
                     delay=f'{plan.delay:.3f}', end=f'{plan.end:.3f}')

    # --- callbacks --------------------------------------------------------------------------
    def _on_state(self, msg: JointState) -> None:
        try:
            self.q, _ = conv.joint_state_arrays(msg, self.arm.joint_names)
            self.q_other, _ = conv.joint_state_arrays(msg, self.other.joint_names)
            self.q_stamp = conv.to_sec(msg.header.stamp)
        except conv.MessageError as exc:
            self.get_logger().warning(f'ignoring joint_states: {exc}', throttle_duration_sec=5.0)
            return
        if self.queued is not None and (self.mine is None or self.q_stamp >= self.mine.end):
            xyz, frame, stamp = self.queued
            self.queued = None
            self._plan(xyz, frame, stamp)

    def _on_target(self, msg: PointStamped) -> None:
        frame, xyz, stamp = conv.point_stamped(msg)
        if self.q is None or self.q_other is None:
            self._status('ERROR', 'refused: no joint state yet (is the bridge up?)')
            return
        if not conv.finite(xyz):
            self._status('ERROR', f'refused: non-finite target {xyz.tolist()}')
            return
        frames = {'world': 'world', f'{self.arm.name}_base': 'base',
                  f'{self.arm.name}_base_link': 'base'}
        if frame not in frames:
            self._status('ERROR', f'refused: unknown frame {frame!r}; use world or '
                         f'{self.arm.name}_base')
            return
        self.waiting = None  # a new target supersedes one that was waiting
        if self.mine is not None and self.mine.end > self._now():
            # the bridge replaces a running trajectory: hold this one until mine has ended
            self.queued = (xyz, frames[frame], stamp)
            self._status('OK', f'queued behind the running move (ends t={self.mine.end:.3f} s)',
                         target=xyz.tolist())
            return
        self._plan(xyz, frames[frame], stamp)

    def _plan(self, xyz: np.ndarray, frame: str, stamp: float,
              asked: Optional[float] = None) -> None:
        now = self._now()
        start = max(stamp, now + self.lead) if stamp > 0 else now + self.lead
        asked = start if asked is None else asked  # when the move was first wanted
        try:
            traj = plan_path(self.arm, self.q, xyz, frame, self.mode,
                             dt=self.traj_cfg['sample_period'],
                             dls_threshold=self.traj_cfg['dls_threshold'],
                             dls_max_damping=self.traj_cfg['dls_max_damping'])
        except IKError as exc:
            self._status('ERROR', f'refused: {exc}', target=xyz.tolist())
            return
        start = max(start, self._now() + self.lead)  # planning took (sim) time too
        plan = schedule(self.arm, traj, start, self.other, self._other_timeline(start),
                        self.margin, self.leader, self.max_delay)
        if plan is None:
            self._wait(xyz, frame, asked)
            return
        if plan.start - asked > 1e-9:  # count the time spent waiting, not just the last delay
            plan = Plan(plan.traj, plan.start, plan.start - asked)
        self.waiting = None
        self.mine, self.pending_target = plan, (xyz, frame, asked)
        kind = 'line' if path_metrics(traj).max_deviation < 1e-4 else 'joint move'
        self._publish(plan, f'moving to {np.round(xyz, 4).tolist()} ({kind}, '
                      f'{traj.duration:.2f} s)')

    def _on_other_execution(self, msg: DiagnosticStatus) -> None:
        """Track what the bridge really runs for the other arm.

        A refused trajectory is forgotten (the prior one runs on); one the bridge started
        late is shifted to its actual start.
        """
        if msg.level == DiagnosticStatus.ERROR and 'refused' in msg.message:
            self.theirs = self.theirs_before
            return
        late = _lateness(msg)
        if late > 0 and self.theirs is not None:
            self.theirs = self.theirs.shifted(late)

    def _on_own_execution(self, msg: DiagnosticStatus) -> None:
        """Re-base my move if the bridge started it late, and announce its real end."""
        late = _lateness(msg)
        if late <= 0 or self.mine is None:
            return
        values = conv.status_values(msg)
        if abs(float(values['stamp']) - self.mine.start) > 1e-3:
            return  # not my current move
        self.mine = Plan(self.mine.traj, float(values['start']), self.mine.delay + late)
        self._publish_status(self.mine, f'started {late:.3f} s late by the bridge')

    def _wait(self, xyz: np.ndarray, frame: str, asked: float) -> None:
        """Wait for the other arm: it blocks the move even after its committed motion."""
        now = self._now()
        since = asked
        if now - since > self.max_wait:
            self.waiting = None
            self._status('ERROR', f'refused: {self.other.name} has blocked the move for '
                         f'{now - since:.1f} s', target=xyz.tolist())
            return
        self.waiting = (xyz, frame, asked)
        self._status('WARN', f'waiting for {self.other.name} to clear: no start within '
                     f'{self.max_delay:.0f} s keeps {self.margin:.2f} m', target=xyz.tolist())

    def _on_other(self, msg: JointTrajectory) -> None:
        try:
            stamp, t, q, _, _ = conv.trajectory_arrays(msg, self.other.joint_names)
        except conv.MessageError:
            return  # the bridge refuses and reports it; nothing committed
        now = self._now()
        start = stamp if stamp > 0 else now
        if t[0] > 0 and self.q_other is not None:
            t, q = np.concatenate(([0.0], t)), np.vstack([self.q_other, q])
        self.theirs_before, self.theirs = self.theirs, Timeline(start + t, q)
        if self.waiting is not None:  # the other arm moves: maybe it clears the way
            xyz, frame, asked = self.waiting
            self._plan(xyz, frame, 0.0, asked)
            return
        if self.leader or self.mine is None or self.mine.start <= now:
            return
        # follower: my committed move has not started; does the new leader move hit it?
        replan = schedule(self.arm, self.mine.traj, self.mine.start, self.other, self.theirs,
                          self.margin, leader=False, max_delay=self.max_delay)
        if replan is None:
            self.mine = None
            self.traj_pub.publish(conv.trajectory_msg(
                self.arm.joint_names, np.array([0.0]), self.q.reshape(1, 3)))
            self._wait(*self.pending_target)
        elif replan.delay > 0:
            asked = self.pending_target[2]
            self.mine = Plan(replan.traj, replan.start, replan.start - asked)
            self._publish(self.mine, f're-timed for a new {self.other.name} move')


def main_left(args=None) -> None:
    """Run the left (leader) planner: ``ros2 run scara_collab left_planner``."""
    run_node(lambda: Planner(robot='scara_left', node_name='left_planner'), args)


def main_right(args=None) -> None:
    """Run the right (follower) planner: ``ros2 run scara_collab right_planner``."""
    run_node(lambda: Planner(robot='scara_right', node_name='right_planner'), args)
