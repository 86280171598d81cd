"""Planner node (executables ``left_planner`` and ``right_planner``): one per arm.

Parameter ``mode``: ``line`` (straight lines only), ``joint``, or ``line_or_joint`` (default:
the line, or a joint move when the goal is reachable but the straight line is not). The
planner's own parameters (``robot`` and ``profile``, read only; ``mode`` and the times of
:data:`TIMES`, which may change while it runs) are checked at start and on every change: an
invalid value stops the node, or is refused, with the reason.

Keeps its arm's state from ``/joint_states``; on ``/<robot>/target`` (PointStamped, frame
``world`` or ``<robot>_base``; a non-zero stamp is the requested start time) it plans the
straight Cartesian move (or a joint move, parameter ``mode``) from the current state, schedules
it against the other arm's committed motion (heard on ``/<other>/joint_trajectory`` and
``/<other>/execution_status``, kept by the committed-motion model's rules:
:class:`scara_collab.core.motion.Heard`) by the priority rule of
:mod:`scara_collab.core.planning`, and publishes ``/<robot>/joint_trajectory`` stamped with its
start, ``/<robot>/planned_path`` and ``/<robot>/planner_status`` (OK, WARN
when delayed, ERROR with the reason when refused; the arm then stays where it is).

A move may come as a plan instead, on ``/<robot>/target_trajectory`` (JointTrajectory: the
sorting job offers the trajectory it planned with the planners' settings to choose the move;
:func:`scara_collab.core.planning.offered_move`). The planner checks it and takes it as its
plan when it starts where the arm is (within ``trajectory.offer_tolerance``) and the mode is
``line_or_joint`` (the job's); otherwise it plans the move to the plan's last point. Either
way it schedules it against the other arm as above: the priority rule is applied here, once.
A plan that is not one (missing velocities, outside the joint limits, malformed) is refused.

Every status names its move (:mod:`scara_collab.nodes.protocol`): the id is
``<robot>/<request>``, the request being the target's stamp in ns (the receipt time for a
target stamped zero), and it goes to the bridge in the trajectory's ``header.frame_id``. The
planner is idempotent: a target it already has (same stamp, e.g. re-sent after a lost
status) is not planned again, its current status is published again.

A target that arrives while the arm's own move is still running is queued and planned when
that move ends (the bridge replaces a running trajectory, so it is not published earlier);
a queued or waiting target replaced by a newer one is reported ``superseded``.
The follower re-times its not-yet-started move when a new leader move would conflict with it.
When the other arm's resting pose blocks a move (no delay helps until that arm moves again),
the planner reports WARN "waiting", retries whenever the other arm commits a new move, and
refuses after ``max_wait`` seconds.
"""
from collections import OrderedDict
from typing import Callable, NamedTuple, Optional, Sequence, Tuple

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core.config import load_config, Rule
from scara_collab.core.kinematics import fk, IKError
from scara_collab.core.model import load_cell
from scara_collab.core.motion import Heard, Lateness
from scara_collab.core.planning import (MODES, offered_move, path_options, Plan, plan_path,
                                        schedule, starts_at)
from scara_collab.core.trajectory import path_metrics, Trajectory
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.faults import declare_faults, FaultyPublisher
from scara_collab.nodes.params import declare_checked, declare_config
from scara_collab.nodes.qos import DEFAULT, EVENTS
from scara_collab.nodes.runner import guarded, run_node

HISTORY = 64  # requests whose last status is kept, to answer a re-sent one
#: the planner's own time parameters and their defaults, s: a move starts at least
#: ``planning_lead`` after it is planned (plus the most the bridge started one of this
#: planner's moves late among its last 20: the latency measured, not assumed), waits at most
#: ``max_delay`` for the other arm's committed motion, and is refused after ``max_wait``
#: blocked by its resting pose
TIMES = {'planning_lead': 0.05, 'max_delay': 30.0, 'max_wait': 60.0}


def _rules(robots: Sequence[str]) -> Tuple[Rule, ...]:
    """Return the checks of the planner's own parameters (``robots``: the cell's arm names)."""
    return (Rule('robot', 'str', lambda v: v in robots, f'must be one of {list(robots)}'),
            Rule('profile', 'text'),
            Rule('mode', 'str', lambda v: v in MODES, f'must be one of {MODES}'),
            *(Rule(key, 'positive') for key in TIMES))


class Asked(NamedTuple):
    """A move asked for: where to, the plan offered with it (or None), and its request id.

    ``time``: the requested start while it is queued (0 = as soon as possible); once it is
    planned or waiting, when it was first wanted (a wait counts into its delay).
    """

    xyz: np.ndarray
    frame: str
    time: float
    offer: Optional[Trajectory]
    request: int


class Answers:
    """The planner's last status of each request, so a re-sent one is answered, not re-planned.

    Keeps the last ``HISTORY`` requests; a target stamped zero gets its receipt time as its
    request id (:meth:`request_of`), unique even for two in the same nanosecond.

    :param publish: sends a :class:`~scara_collab.nodes.protocol.PlannerStatus`.
    """

    def __init__(self, publish: Callable[[proto.PlannerStatus], None]):
        """Remember nothing yet."""
        self._publish = publish
        self._last: 'OrderedDict[int, proto.PlannerStatus]' = OrderedDict()
        self._last_auto = 0

    def request_of(self, stamp_ns: int, now_ns: int) -> int:
        """Return the request id of a target: its stamp, or (stamped zero) the receipt time."""
        if stamp_ns:
            return stamp_ns
        self._last_auto = max(now_ns, self._last_auto + 1)
        return self._last_auto

    def send(self, st: proto.PlannerStatus) -> None:
        """Publish ``st`` and keep it as its request's last answer."""
        if st.request:
            self._last[st.request] = st
            self._last.move_to_end(st.request)
            while len(self._last) > HISTORY:
                self._last.popitem(last=False)
        self._publish(st)

    def again(self, request: int) -> bool:
        """Publish the last status of ``request`` again; return False if it is new."""
        st = self._last.get(request)
        if st is not None:
            self._publish(st)
        return st is not None

    def kind(self, request: int) -> str:
        """Return the kind of move (``line``, ``joint move``) last reported for ``request``."""
        st = self._last.get(request)
        return '' if st is None else st.kind


class Planner(Node):
    """Motion planner of one arm."""

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
        self.traj_cfg = cfg['trajectory']
        self.margin = self.cell.safety_margin + float(cfg['planning_buffer'])
        self._set_params(params)

        self.q: Optional[np.ndarray] = None
        self.q_stamp = 0.0  # sim time of the state in self.q
        self.q_other: Optional[np.ndarray] = None
        self.mine: Optional[Plan] = None            # my committed move
        self.mine_id = ''                           # ... its move id
        self.pending_target: Optional[Asked] = None  # my committed move's
        # how late the bridge has started my moves lately: added to the planning lead
        self.lateness = Lateness()
        # the other arm's committed motion, as heard
        self.theirs = Heard(self.other.name, dt=1.0 / float(
            load_config('simulation')['physics_rate']))
        self.queued: Optional[Asked] = None         # one to plan after mine
        self.waiting: Optional[Asked] = None        # one blocked by the other arm

        r, o = self.arm.name, self.other.name
        faults = declare_faults(self)
        self.traj_pub = self.create_publisher(JointTrajectory, f'/{r}/joint_trajectory', 10)
        self.path_pub = self.create_publisher(Path, f'/{r}/planned_path', 10)
        status_pub = FaultyPublisher(self, faults, self.create_publisher(
            DiagnosticStatus, f'/{r}/planner_status', EVENTS))
        self.answers = Answers(lambda st: status_pub.publish(st.to_msg()))
        # every state, each in turn: with a depth of 1, the callback of one takes the newest,
        # and a queued move would start at one state or the next by timing
        self.create_subscription(JointState, '/joint_states', guarded(self, self._on_state),
                                 DEFAULT)
        self.create_subscription(PointStamped, f'/{r}/target', guarded(self, self._on_target),
                                 10)
        self.create_subscription(JointTrajectory, f'/{r}/target_trajectory',
                                 guarded(self, self._on_offer), 10)
        self.create_subscription(JointTrajectory, f'/{o}/joint_trajectory',
                                 guarded(self, self._on_other), 10)
        self.create_subscription(DiagnosticStatus, f'/{o}/execution_status',
                                 guarded(self, self._on_other_execution), EVENTS)
        self.create_subscription(DiagnosticStatus, f'/{r}/execution_status',
                                 guarded(self, self._on_own_execution), EVENTS)
        lockstep.join(self)  # sim time waits while this node computes
        self.get_logger().info(f'{r} planner ready ({self.mode} moves, '
                               f'{"leader" if self.leader else "follower, yields to " + o})')

    # --- helpers ----------------------------------------------------------------------------
    def _now(self) -> float:  # the node clock, s (bench/graph.py reads it too)
        return conv.now(self)

    def _set_params(self, params: dict) -> None:
        """Take the values of the dynamic parameters (at start and on a change)."""
        self.mode = params['mode']
        self.lead, self.max_delay, self.max_wait = (float(params[k]) for k in TIMES)

    def _status(self, state: str, request: int, reason: str = '', plan: Optional[Plan] = None,
                kind: str = '') -> None:
        st = proto.PlannerStatus(
            self.arm.name, state, proto.move_id(self.arm.name, request), request, reason=reason,
            start=None if plan is None else plan.start, end=None if plan is None else plan.end,
            delay=0.0 if plan is None else plan.delay, kind=kind)
        if state == 'refused':
            self.get_logger().warning(st.text())
        self.answers.send(st)

    def _publish(self, plan: Plan, request: int, note: str = '') -> None:
        t = plan.traj
        self.mine, self.mine_id = plan, proto.move_id(self.arm.name, request)
        self.traj_pub.publish(conv.trajectory_msg(self.arm.joint_names, t.t, t.q, t.qd, t.qdd,
                                                  start=plan.start, frame_id=self.mine_id))
        self.path_pub.publish(conv.path_msg(t.p, plan.start))
        kind = 'line' if path_metrics(t).max_deviation < 1e-4 else 'joint move'
        self._status('planned', request, note, plan, kind)

    def _request_of(self, stamp) -> int:
        return self.answers.request_of(proto.stamp_ns(stamp), self.get_clock().now().nanoseconds)

    # --- callbacks --------------------------------------------------------------------------
    def _on_state(self, msg: JointState) -> None:
        if not conv.admit_state(self, self.stamps, msg):
            return
        try:
            self.q, _ = conv.joint_state_arrays(msg, self.arm.joint_names)
            self.q_other, _ = conv.joint_state_arrays(msg, self.other.joint_names)
            self.q_stamp = conv.to_sec(msg.header.stamp)
        except conv.MessageError as exc:
            self.get_logger().warning(f'ignoring joint_states: {exc}', throttle_duration_sec=5.0)
            return
        if self.queued is not None and (self.mine is None or self.q_stamp >= self.mine.end):
            queued, self.queued = self.queued, None
            self._plan(*queued)

    def _supersede(self, held: Optional[Asked], why: str) -> None:
        if held is not None:
            self._status('superseded', held.request, why)

    def _on_target(self, msg: PointStamped) -> None:
        frame_id, xyz, stamp = conv.point_stamped(msg)
        request = self._request_of(msg.header.stamp)
        if not self.answers.again(request):
            self._take(request, xyz, frame_id, stamp)

    def _on_offer(self, msg: JointTrajectory) -> None:
        """Take a move offered as a plan (see the module docstring)."""
        request = self._request_of(msg.header.stamp)
        if self.answers.again(request):
            return
        try:
            stamp, *arrays = conv.trajectory_arrays(msg, self.arm.joint_names)
            offer = offered_move(self.arm, *arrays)
        except ValueError as exc:  # conv.MessageError too
            self._status('refused', request, f'offered trajectory: {exc}')
            return
        self._take(request, fk(self.arm, offer.q[-1]), 'world', stamp, offer)

    def _take(self, request: int, xyz: np.ndarray, frame_id: str, stamp: float,
              offer: Optional[Trajectory] = None) -> None:
        """Plan, queue or refuse the move ``request`` to ``xyz`` (``offer``: a plan of it)."""
        if self.q is None or self.q_other is None:
            self._status('refused', request, 'no joint state yet (is the bridge up?)')
            return
        if not conv.finite(xyz):
            self._status('refused', request, f'non-finite target {xyz.tolist()}')
            return
        try:
            frame = conv.target_frame(frame_id, self.arm.name)
        except conv.MessageError as exc:
            self._status('refused', request, str(exc))
            return
        # a new target supersedes one that was waiting or queued
        self._supersede(self.waiting, f'replaced by request {request}')
        self._supersede(self.queued, f'replaced by request {request}')
        self.waiting = self.queued = None
        if self.mine is not None and self.mine.end > self._now():
            # the bridge replaces a running trajectory: hold this one until mine has ended
            self.queued = Asked(xyz, frame, stamp, offer, request)
            self._status('queued', request, f'behind the running move (ends '
                         f't={self.mine.end:.3f} s)')
            return
        self._plan(xyz, frame, stamp, offer, request)

    def _plan(self, xyz: np.ndarray, frame: str, stamp: float, offer: Optional[Trajectory],
              request: int, asked: Optional[float] = None) -> None:
        now = self._now()
        lead = self.lead + self.lateness.worst  # what the bridge's starts have measured
        start = max(stamp, now + lead) if stamp > 0 else now + lead
        asked = start if asked is None else asked  # when the move was first wanted
        if (offer is not None and self.mode == 'line_or_joint'
                and starts_at(offer, self.q, self.traj_cfg['offer_tolerance'])):
            traj = offer  # the job's plan of this move: not planned again
        else:
            try:
                traj = plan_path(self.arm, self.q, xyz, frame, self.mode,
                                 **path_options(self.traj_cfg))
            except (IKError, ValueError) as exc:
                self._status('refused', request, str(exc))
                return
        now = self._now()
        start = max(start, now + lead)  # planning took (sim) time too
        # from now on (the past is past); the leader leaves out a follower move that waits to
        # start at or after its own start (the priority rule: that one yields)
        other = self.theirs.motion(now, self.q_other, before=start if self.leader else None)
        plan = schedule(self.arm, traj, start, self.other, other, self.margin, self.leader,
                        self.max_delay)
        if plan is None:
            self._wait(Asked(xyz, frame, asked, offer, request))
            return
        if plan.start - asked > 1e-9:  # count the time spent waiting, not just the last delay
            plan = Plan(plan.traj, plan.start, plan.start - asked)
        self.waiting = None
        self.pending_target = Asked(xyz, frame, asked, offer, request)
        self._publish(plan, request)

    def _on_other_execution(self, msg: DiagnosticStatus) -> None:
        """Track what the bridge really runs for the other arm.

        A refused trajectory is forgotten (the prior one runs on); one the bridge started
        late is shifted to its actual start.
        """
        st = proto.ExecutionStatus.from_msg(msg)
        self.theirs.status(st.state, st.move, self._now(), st.start, self.q_other)

    def _on_own_execution(self, msg: DiagnosticStatus) -> None:
        """Re-base my move if the bridge started it late, and announce its real end."""
        st = proto.ExecutionStatus.from_msg(msg)
        if self.mine is None or st.move != self.mine_id:
            return  # not my current move
        if st.state == 'accepted' and st.stamp:
            self.lateness.add(st.late)
        if st.state == 'accepted' and st.late > 0:
            self.mine = Plan(self.mine.traj, st.start, self.mine.delay + st.late)
            _, request = proto.parse_move_id(st.move)
            self._status('planned', request, f'started {st.late:.3f} s late by the bridge',
                         self.mine, self.answers.kind(request))
        elif st.state in ('refused', 'preempted', 'held'):
            self.mine = None  # nothing of mine runs: the next target is planned at once

    def _wait(self, move: Asked) -> None:
        """Wait for the other arm: it blocks ``move`` even after its committed motion."""
        asked, request = move.time, move.request
        now = self._now()
        if now - asked > self.max_wait:
            self.waiting = None
            self._status('refused', request, f'{self.other.name} has blocked the move for '
                         f'{now - asked:.1f} s')
            return
        first = self.waiting is None or self.waiting.request != request
        self.waiting = move
        if first:
            self._status('waiting', request, f'{self.other.name} blocks it: no start within '
                         f'{self.max_delay:.0f} s keeps {self.margin:.2f} m')

    def _on_other(self, msg: JointTrajectory) -> None:
        try:
            stamp, t, q, _, _ = conv.trajectory_arrays(msg, self.other.joint_names)
        except conv.MessageError:
            return  # the bridge refuses and reports it; nothing committed
        now = self._now()
        if self.theirs.trajectory(msg.header.frame_id, stamp, t, q, now, self.q_other) is None:
            return  # it would have ended: the bridge refuses it
        if self.waiting is not None:  # the other arm moves: maybe it clears the way
            xyz, frame, asked, offer, request = self.waiting
            self._plan(xyz, frame, 0.0, offer, request, asked)
            return
        if self.leader or self.mine is None or self.mine.start <= now:
            return
        # follower: my committed move has not started; does the new leader move hit it?
        replan = schedule(self.arm, self.mine.traj, self.mine.start, self.other,
                          self.theirs.motion(now, self.q_other), self.margin, leader=False,
                          max_delay=self.max_delay)
        asked, request = self.pending_target.time, self.pending_target.request
        if replan is None:
            self.mine = None
            self.traj_pub.publish(conv.trajectory_msg(
                self.arm.joint_names, np.array([0.0]), self.q.reshape(1, 3),
                frame_id=proto.hold_id(self.arm.name)))
            self._wait(self.pending_target)
        elif replan.delay > 0:
            self._publish(Plan(replan.traj, replan.start, replan.start - asked), request,
                          f're-timed for a new {self.other.name} move')


def main_left(args=None) -> None:
    """Run the left (leader) planner: ``ros2 run scara_collab left_planner``."""
    run_node(lambda: Planner(robot='scara_left', node_name='left_planner'), args)


def main_right(args=None) -> None:
    """Run the right (follower) planner: ``ros2 run scara_collab right_planner``."""
    run_node(lambda: Planner(robot='scara_right', node_name='right_planner'), args)
