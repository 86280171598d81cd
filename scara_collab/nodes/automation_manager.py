"""Automation manager: the sorting job's node, a thin shell around the core's job.

The job is :class:`scara_collab.core.job.SortingJob`.

It turns messages into the job's observations and the job's commands into messages; every
decision is the core's (see :mod:`scara_collab.core.job` for the phases, deadlines and
retries, :mod:`scara_collab.nodes.protocol` for the statuses):

* in: ``/conveyor/items`` (items resting on the belt), ``/joint_states``,
  ``/<robot>/planner_status`` and ``/<robot>/execution_status`` (about its moves, by request
  id), ``/<robot>/joint_trajectory`` (the planners' moves: the other arm's booked motion),
  ``/conveyor/events`` (counts; confirms grasps and releases), ``/emergency_stop`` and
  ``/protective_stop`` (the job pauses while either stands); with a person in the cell
  ``/separation_monitor/status`` (the persons it sees: a tick at T takes the statuses of the
  instants before T, which came before its clock) and ``/<robot>/trajectory_clock``;
* out: a move as the job planned it on ``/<robot>/target_trajectory`` (JointTrajectory: the
  planner takes it instead of planning the move again), or as a point on ``/<robot>/target``
  (PointStamped) when the job has no plan of it; in mirrored mode on
  ``/collab/target_trajectory`` or ``/collab/target``; either way the stamp is the requested
  start and the move's id (:mod:`scara_collab.nodes.protocol`); ``/<robot>/gripper`` calls
  (std_srvs/SetBool; each answer goes back to the job with its request's token, a lost one is
  asked again). Its lockstep answer waits for the planners' status of each move it sent and
  for the bridge's answer to each gripper call (at most ``lockstep.REPLY_WAIT`` wall seconds
  each): the bridge cannot step before it has gripped, so the next ``/clock`` always finds the
  reply taken (docs/realtime.md, *Repeatable runs*). With ``state_sync`` (the default; the
  launcher turns it off in real time) a tick at sim time T decides on the joint state stamped
  T: the bridge sends it right after the clock of T, on another topic, so the tick waits for it
  (and the lockstep answer with it) when it comes second, unless the states have stopped
  coming.

Services ``~/start`` and ``~/stop`` (std_srvs/Trigger, idempotent: starting a running job
succeeds; a start before every endpoint the job uses is matched is refused, naming what is
missing, since the first targets would be lost: ask again); parameter ``auto_start`` (the job
starts once the graph is connected); ``~/stats`` (:class:`~scara_collab.nodes.protocol.JobStats`,
1 Hz sim time). Modes: ``single`` (the leader alone), ``collaborative`` (both arms, each
preferring its half of the belt), ``mirrored`` (items arrive in mirror pairs; the leader's moves
go through the replication manager so the follower replicates them).
"""
from collections import deque
from typing import Callable, Deque, List

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from scara_collab.core import moves, sorting
from scara_collab.core.config import load_config, Rule
from scara_collab.core.job import GripCommand, JobSettings, MoveCommand, SortingJob
from scara_collab.core.kinematics import IKError
from scara_collab.core.model import load_cell
from scara_collab.core.planning import path_options, plan_path
from scara_collab.core.ssm import Person, SsmParams
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.diagnostics import Diagnostics
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.params import declare_checked, declare_config
from scara_collab.nodes.qos import DEFAULT, LATCHED
from scara_collab.nodes.runner import run_node
from scara_collab.nodes.sim_timer import every
from scara_collab.nodes.state_sync import StateSync


def log_to(logger) -> Callable[[str, str], None]:
    """Return ``log(level, text)`` for the job: ``'warn'`` a warning, else info."""
    def log(level: str, text: str) -> None:
        # one call site per severity: rclpy refuses a call site whose severity changes
        if level == 'warn':
            logger.warning(text)
        else:
            logger.info(text)
    return log


class AutomationManager(Node):
    """Run the sorting job (see the module docstring)."""

    def __init__(self, **kwargs):
        """Declare the parameters, build the job and create its topics, clients and timers.

        :param kwargs: passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``).
        :raises ValueError: a configuration the job refuses.
        """
        super().__init__('automation_manager', **kwargs)
        self.stamps = conv.StampGate()  # joint states must carry the sim clock's time
        cfg = declare_config(self, ('automation', 'controllers', 'people'))
        params = declare_checked(
            self, {'profile': '', 'auto_start': False, 'tick': 0.02, 'state_sync': True},
            (Rule('profile', 'text'), Rule('auto_start', 'bool'), Rule('tick', 'positive'),
             Rule('state_sync', 'bool')))
        self.cell = load_cell(params['profile'] or None)
        self.settings = JobSettings.from_config(self.cell, cfg['automation'],
                                                controllers=cfg['controllers'])
        self.mode = self.settings.mode
        options = path_options(cfg['controllers']['trajectory'])  # the planners' own

        def plan(robot, q0, target):
            try:
                return plan_path(self.cell.arm(robot), q0, target, mode='line_or_joint',
                                 **options)
            except IKError as exc:
                raise ValueError(str(exc)) from None

        self.job = SortingJob(self.cell, self.settings, plan, log_to(self.get_logger()),
                              people=SsmParams.from_config(cfg['people']))
        self.column = float(cfg['people']['monitor']['column_height'])  # a person seen, m
        self.target_pub = {a.name: self.create_publisher(PointStamped, f'{a.name}/target', 10)
                           for a in self.cell.arms}
        self.plan_pub = {a.name: self.create_publisher(JointTrajectory,
                                                       f'{a.name}/target_trajectory', 10)
                         for a in self.cell.arms}
        self.collab_pub = self.create_publisher(PointStamped, 'collab/target', 10)
        self.collab_plan_pub = self.create_publisher(JointTrajectory,
                                                     'collab/target_trajectory', 10)
        self.stats_pub = self.create_publisher(DiagnosticStatus, '~/stats', 10)
        self.diagnostics = Diagnostics(self, self.stats_pub)  # and on /diagnostics
        self.grippers = {a.name: self.create_client(SetBool, f'{a.name}/gripper')
                         for a in self.cell.arms}
        self.status_subs = {}
        for a in self.cell.arms:
            self.status_subs[a.name] = (
                self.create_subscription(DiagnosticStatus, f'{a.name}/planner_status',
                                         guarded(self, self._on_planner), 50),
                self.create_subscription(DiagnosticStatus, f'{a.name}/execution_status',
                                         guarded(self, self._on_execution), 50),
                self.create_subscription(JointTrajectory, f'{a.name}/joint_trajectory',
                                         guarded(self, lambda msg, n=a.name:
                                                 self._on_trajectory(n, msg)), 10))
            # published only while the cell scales speeds (a person in it): not waited for
            self.create_subscription(DiagnosticStatus, f'{a.name}/trajectory_clock',
                                     guarded(self, self._on_clock), 50)
        # every state and item list, each in turn: with a depth of 1, the callback of one
        # takes the newest (one published after the next /clock, if the node is behind), and
        # the tick sees it or not by timing (docs/realtime.md, *Repeatable runs*)
        self.world_subs = (
            self.create_subscription(MarkerArray, 'conveyor/items',
                                     guarded(self, self._on_items), DEFAULT),
            self.create_subscription(DiagnosticStatus, 'conveyor/events',
                                     guarded(self, self._on_event), 100),
            self.create_subscription(JointState, 'joint_states', guarded(self, self._on_state),
                                     DEFAULT))
        # with a person in the cell: the persons the separation monitor sees (not waited for).
        # A tick at T takes those of the instants before T: the monitor says the status of T
        # after the clock of T, so whether it comes before the tick of T would be timing
        self.separations: Deque[proto.SeparationStatus] = deque()
        self.create_subscription(DiagnosticStatus, 'separation_monitor/status',
                                 guarded(self, self._on_separation), DEFAULT)
        self._stops = {'emergency': False, 'protective': False}  # the job pauses under either
        for kind in self._stops:
            self.create_subscription(Bool, f'{kind}_stop', guarded(
                self, lambda msg, k=kind: self._on_estop(k, msg)), LATCHED)
        self.create_service(Trigger, '~/start', guarded(self, self._on_start, service=True))
        self.create_service(Trigger, '~/stop', guarded(self, self._on_stop, service=True))
        # on the sim clock, before joining the lockstep: each answer follows the tick's work
        self.sync = StateSync(self._decide, 1.0 / float(load_config('simulation')['state_rate']),
                              params['state_sync'])  # each tick on the state of its instant
        every(self, float(params['tick']), lambda: self.sync.on_tick(self._now()))
        every(self, 1.0, self._publish_stats)
        # auto_start: the job starts on the first tick that finds the graph connected
        self.start_pending = params['auto_start']
        self.lockstep = lockstep.join(self)  # sim time waits while this node computes
        self.sync.lockstep = self.lockstep
        self.get_logger().info(f'sorting job ready: mode {self.mode}, lanes '
                               f'{[lane.robot for lane in self.job.lanes]}')

    # --- plumbing ---------------------------------------------------------------------------
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # --- inputs -----------------------------------------------------------------------------
    def _on_items(self, msg: MarkerArray) -> None:
        self.job.on_items([sorting.SeenItem(i, cls, xyz, stamp)
                           for i, (cls, xyz, stamp) in conv.item_positions(msg).items()
                           if sorting.on_belt(self.cell, xyz)])  # not held, falling, binned

    def _on_event(self, msg: DiagnosticStatus) -> None:
        ev = proto.ItemEvent.from_msg(msg)
        self.job.on_item_event(ev.kind, ev.item, ev.robot)

    def _on_state(self, msg: JointState) -> None:
        if not conv.admit_state(self, self.stamps, msg):
            return
        for a in self.cell.arms:
            q, _ = conv.joint_state_arrays(msg, a.joint_names)  # refuses non-finite states
            self.job.on_arm_state(a.name, q)
        self.sync.on_state(conv.to_sec(msg.header.stamp))

    def _on_planner(self, msg: DiagnosticStatus) -> None:
        st = proto.PlannerStatus.from_msg(msg)
        self.job.on_planner(st.robot, st.request, st.state, st.start, st.end, st.reason)
        if self.lockstep is not None:
            self.lockstep.reply((st.robot, st.request))

    def _on_execution(self, msg: DiagnosticStatus) -> None:
        st = proto.ExecutionStatus.from_msg(msg)
        if st.robot in self.job.sorted_by:  # the cell's arms: what the arm is committed to
            self.job.on_arm_status(st.robot, st.state, st.move, st.start)
        try:
            robot, request = moves.parse_move_id(st.move)
        except moves.MoveIdError:
            return  # not a move of the job's (a raw command, a planner's hold)
        state, reason = st.state, st.reason
        if state == 'preempted' and not moves.planners_move(robot, st.by):
            # someone else's trajectory took the arm over: the move failed, plan again
            state, reason = 'refused', f'taken over by move {st.by or "(no id)"}'
        self.job.on_execution(robot, request, state, st.start, st.end, reason, st.stamp)

    def _on_trajectory(self, robot: str, msg: JointTrajectory) -> None:
        try:
            owner, request = moves.parse_move_id(msg.header.frame_id)
        except moves.MoveIdError:
            owner, request = robot, None
        if owner != robot:  # not a planner's move of a request of this arm: a raw one, a hold
            request = None  # (the bridge runs it on this arm all the same)
        stamp, t, q, _, _ = conv.trajectory_arrays(msg, self.cell.arm(robot).joint_names)
        self.job.on_trajectory(robot, msg.header.frame_id, request, stamp, t, q)

    def _on_clock(self, msg: DiagnosticStatus) -> None:
        clock = proto.TrajectoryClock.from_msg(msg)
        if clock.robot in self.job.sorted_by:
            self.job.on_clock(clock.robot, clock.lag)

    def _on_separation(self, msg: DiagnosticStatus) -> None:
        self.separations.append(proto.SeparationStatus.from_msg(msg))

    def _take_separations(self, now: float) -> None:
        """Hand the job the monitor's statuses of the instants before ``now``, in order."""
        while self.separations and self.separations[0].time < now - 1e-9:
            self._separation(self.separations.popleft())

    def _separation(self, st: proto.SeparationStatus) -> None:
        hindered = bool(st.persons) and not st.fault and any(
            s < 1.0 for s in st.scale.values())
        self.job.on_persons([Person(np.array([p.x, p.y]), np.array([p.vx, p.vy]), p.radius,
                                    self.column, p.id) for p in st.persons],
                            hindered, st.time)

    def _on_estop(self, kind: str, msg: Bool) -> None:
        was = any(self._stops.values())
        self._stops[kind] = bool(msg.data)
        self.job.on_estop(any(self._stops.values()))
        if msg.data and not was:
            self.get_logger().warning(f'{kind} stop: the job pauses')
        elif was and not any(self._stops.values()):
            self.get_logger().info(f'{kind} stop released: the job plans again from where the '
                                   'arms are')

    def missing_links(self) -> List[str]:
        """Return the topics and services the job needs that are not matched yet.

        A message published before the other side has matched its endpoint is lost (DDS
        discovery takes a while, longer on a busy machine), so the job does not start before
        every endpoint it uses is matched: its targets, the planners' and the bridge's
        statuses, the grippers, the items and the joint states.
        """
        missing = []
        for lane in self.job.lanes:
            pubs = ((self.collab_pub, self.collab_plan_pub) if len(lane.robots) > 1 else
                    (self.target_pub[lane.robot], self.plan_pub[lane.robot]))
            missing += [f'{pub.topic_name} (no subscriber)' for pub in pubs
                        if pub.get_subscription_count() == 0]
            for robot in lane.robots:
                missing += [f'{sub.topic_name} (no publisher)'
                            for sub in self.status_subs[robot] if sub.get_publisher_count() == 0]
                if not self.grippers[robot].service_is_ready():
                    missing.append(f'{self.resolve_service_name(self.grippers[robot].srv_name)}'
                                   ' (no server)')
        missing += [f'{sub.topic_name} (no publisher)'
                    for sub in self.world_subs if sub.get_publisher_count() == 0]
        return missing

    def _on_start(self, req, res):
        missing = self.missing_links()
        if missing and not self.job.running:
            res.success = False
            res.message = f'not connected yet: {", ".join(missing)}'
            return res
        fresh = self.job.start(self._now())
        res.success = True
        res.message = f'sorting job {"running" if fresh else "already running"} ({self.mode})'
        self.get_logger().info(res.message)
        return res

    def _on_stop(self, req, res):
        self.start_pending = False
        was = self.job.stop()
        res.success = True
        res.message = ('sorting job stopped; arms holding items bring them to their bins'
                       if was else 'sorting job was not running')
        self.get_logger().info(res.message)
        return res

    # --- the job ----------------------------------------------------------------------------
    def _decide(self) -> None:
        """Run the job's tick and send what it decided."""
        self._take_separations(self._now())
        if self.start_pending:
            missing = self.missing_links()
            if missing:
                self.get_logger().warning(f'auto_start: waiting for {", ".join(missing)}',
                                          throttle_duration_sec=5.0)
                return
            self.start_pending = False
            self.job.start(self._now())
            self.get_logger().info(f'sorting job running ({self.mode})')
        for cmd in self.job.tick(self._now()):
            if isinstance(cmd, MoveCommand):
                self._send_move(cmd)
            elif isinstance(cmd, GripCommand):
                key = ('gripper', cmd.robot, cmd.token)
                if self.lockstep is not None:  # the grip acts before the bridge steps on
                    self.lockstep.await_reply(key)
                future = self.grippers[cmd.robot].call_async(SetBool.Request(data=cmd.grasp))
                future.add_done_callback(lambda f, t=cmd.token, k=key: self._on_grip(t, k, f))

    def _on_grip(self, token: int, key: tuple, future) -> None:
        """Hand the gripper's answer to the job; a failed call is a lost one (asked again)."""
        try:
            res = future.result()
        except Exception:  # noqa: B902 - a failed call is a lost answer: the job asks again
            return
        if res is None:  # cancelled
            return
        self.job.on_grip(token, res.success, res.message)
        if self.lockstep is not None:
            self.lockstep.reply(key)

    def _send_move(self, cmd: MoveCommand) -> None:
        """Publish a move: the job's plan of it, else its target point."""
        if cmd.plan is not None:
            t = cmd.plan
            msg = conv.trajectory_msg(self.cell.arm(cmd.robot).joint_names, t.t, t.q, t.qd,
                                      t.qdd)
            pub = self.collab_plan_pub if cmd.mirrored else self.plan_pub[cmd.robot]
        else:
            msg = conv.make_point_stamped(cmd.target, 'world')
            pub = self.collab_pub if cmd.mirrored else self.target_pub[cmd.robot]
        msg.header.stamp = conv.time_from_ns(cmd.request)  # exact: it is the move's id
        pub.publish(msg)
        if self.lockstep is not None:  # sim time waits for the planners' replies
            # a mirrored move: the replication manager passes the request on to both planners
            for robot in ([a.name for a in self.cell.arms] if cmd.mirrored else [cmd.robot]):
                self.lockstep.await_reply((robot, cmd.request))

    # --- stats ------------------------------------------------------------------------------
    def stats(self) -> proto.JobStats:
        """Return the job's figures so far (also published on ``~/stats``)."""
        now = self._now()
        job = self.job
        return proto.JobStats(
            mode=self.mode, running=job.running, time=round(now, 3), start_time=job.start_time,
            counts={k: job.counts.get(k, 0) for k in proto.COUNTED},
            sorted_by=dict(job.sorted_by), items_per_minute=round(job.rate(now), 3),
            give_ups=job.decisions.give_ups, retries=job.protocol.retries, phases=job.phases(),
            last_give_up=job.decisions.last_give_up,
            missed_due_to_person=job.missed_due_to_person)

    def _publish_stats(self) -> None:
        self.diagnostics.publish(self.stats().to_msg())


def main(args=None) -> None:
    """Run the sorting job: ``ros2 run scara_collab automation_manager``."""
    run_node(AutomationManager, args)


if __name__ == '__main__':
    main()
