"""Automation manager: the sorting job.

Watches ``/conveyor/items`` and ``/joint_states``; assigns items to arms; sends each arm to
where its item *will be* when the tool arrives (intercept on the moving belt); grasps,
carries the item to the arm's bin of the item's class, releases; counts what the bridge
reports on ``/conveyor/events`` (sorted, wrong bin, missed, dropped). Modes: ``single`` (the
leader alone), ``collaborative`` (both arms, each preferring its half of the belt and taking
the other half's urgent items when the other arm is busy), ``mirrored`` (items arrive in
mirror pairs; the leader's moves go through ``/collab/target`` so the follower replicates
them). The right arm yields to the left in the shared zone through the planners' rule.

Services ``/automation_manager/start`` and ``/stop`` (std_srvs/Trigger); parameter
``auto_start``. ``/automation_manager/stats`` (DiagnosticStatus, 1 Hz sim time): mode,
sorted, missed, wrong_bin, dropped, spawned, items_per_minute, min_separation_m,
mirror_error_max_m, first_item_time, running.
"""
import time
from typing import Dict, Optional

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from scara_collab.core import sorting
from scara_collab.core.kinematics import IKError
from scara_collab.core.model import load_cell
from scara_collab.core.planning import plan_path
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes.params import declare_config
from scara_collab.nodes.runner import run_node

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
COUNTED = ('spawned', 'sorted', 'wrong_bin', 'missed', 'dropped')


class ArmJob:
    """What one arm is doing.

    ``phase`` is one of idle, to_item, grasping, to_bin, releasing, to_park.
    """

    def __init__(self, robot: str):
        self.robot = robot
        self.phase = 'idle'
        self.item: Optional[sorting.SeenItem] = None
        self.ends: Dict[str, Optional[float]] = {}  # planner end time per robot moved
        self.starts: Dict[str, float] = {}  # planner start time per robot moved
        self.asked = 0.0
        self.comparable: Optional[bool] = None
        self.target: Optional[np.ndarray] = None
        self.delayed = False  # a planner delayed this move (the arms are not in step)
        self.failures: Dict[int, int] = {}

    def reset(self) -> None:
        self.phase, self.item, self.ends, self.delayed = 'idle', None, {}, False
        self.starts = {}
        self.comparable = None  # did this move start with the arms mirrored?

    def in_step(self) -> bool:
        """Return True while every arm of the job runs a move with the same start and end."""
        starts, ends = list(self.starts.values()), list(self.ends.values())
        return (self.phase in ('to_item', 'to_bin') and len(starts) == len(ends) > 1
                and None not in ends and max(starts) - min(starts) < 1e-6
                and max(ends) - min(ends) < 1e-6)


class AutomationManager(Node):
    """Run the sorting job."""

    def __init__(self, **kwargs):
        super().__init__('automation_manager', **kwargs)
        cfg = declare_config(self, ('automation',))['automation']
        self.declare_parameter('profile', '')
        self.declare_parameter('auto_start', False)
        self.declare_parameter('tick', 0.02)
        self.mode = cfg['mode']
        self.cell = load_cell(self.get_parameter('profile').value or None)
        self.z_pick = sorting.pick_height(self.cell, cfg['pick_clearance'])
        self.drop_clearance = cfg['drop_clearance']
        self.lead = cfg['start_lead']
        self.move_timeout = cfg['move_timeout']
        self.grasp_reach = cfg['grasp_reach']
        lead, foll = self.cell.leader, self.cell.follower
        active = {'single': [lead], 'collaborative': [lead, foll], 'mirrored': [lead]}
        self.jobs = [ArmJob(a.name) for a in active[self.mode]]
        self.running = False
        self.q: Dict[str, np.ndarray] = {}
        self.q_stamp = 0.0  # sim time of the states in self.q
        self.items: Dict[int, sorting.SeenItem] = {}
        self.claimed: Dict[int, str] = {}
        self.counts = {k: 0 for k in COUNTED}
        self.per_arm = {a.name: 0 for a in self.cell.arms}  # sorted by each arm
        self.give_ups = 0
        self.unmirrored = 0  # mirrored mode: moves the two planners did not plan alike
        self.first_item: Optional[float] = None
        self.min_sep = float('inf')
        self.mirror_max: Optional[float] = None
        self.estop = False
        self._rtf = (None, None, 1.0)  # (wall, sim, factor): sim seconds per wall second
        self._parked_idle = False

        self.target_pub = {a.name: self.create_publisher(PointStamped, f'/{a.name}/target', 10)
                           for a in self.cell.arms}
        self.collab_pub = self.create_publisher(PointStamped, '/collab/target', 10)
        self.stats_pub = self.create_publisher(DiagnosticStatus, '~/stats', 10)
        self.grippers = {a.name: self.create_client(SetBool, f'/{a.name}/gripper')
                         for a in self.cell.arms}
        for a in self.cell.arms:
            self.create_subscription(DiagnosticStatus, f'/{a.name}/planner_status',
                                     lambda m, n=a.name: self._on_planner(n, m), 10)
        self.create_subscription(MarkerArray, '/conveyor/items', self._on_items, 10)
        self.create_subscription(DiagnosticStatus, '/conveyor/events', self._on_event, 100)
        self.create_subscription(JointState, '/joint_states', self._on_state, QoSProfile(depth=1))
        self.create_subscription(Float64, '/collision_monitor/min_distance', self._on_distance,
                                 10)
        self.create_subscription(Float64, '/replication_manager/mirror_error', self._on_mirror,
                                 10)
        self.create_subscription(Bool, '/emergency_stop', self._on_estop, LATCHED)
        self.create_service(Trigger, '~/start', self._on_start)
        self.create_service(Trigger, '~/stop', self._on_stop)
        self.create_timer(float(self.get_parameter('tick').value), self._tick)
        self.create_timer(1.0, self._publish_stats)
        if self.get_parameter('auto_start').value:
            self.running = True
        self.lockstep = lockstep.join(self)  # sim time waits while this node computes
        self.get_logger().info(f'sorting job ready: mode {self.mode}, arms '
                               f'{[j.robot for j in self.jobs]}')

    # --- inputs -----------------------------------------------------------------------------
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_items(self, msg: MarkerArray) -> None:
        top = self.cell.belt.top_z + self.cell.item_size / 2
        self.items = {i: sorting.SeenItem(i, cls, xyz, stamp)
                      for i, (cls, xyz, stamp) in conv.item_positions(msg).items()
                      if abs(xyz[2] - top) <= 0.02}  # not held, falling or in a bin

    def _on_event(self, msg: DiagnosticStatus) -> None:
        kind = msg.name
        if kind in self.counts:
            self.counts[kind] += 1
        robot = conv.status_values(msg).get('robot', '')
        if kind == 'sorted' and robot in self.per_arm:
            self.per_arm[robot] += 1
        if kind == 'spawned' and self.first_item is None:
            self.first_item = float(conv.status_values(msg).get('time', self._now()))

    def _on_state(self, msg: JointState) -> None:
        for a in self.cell.arms:
            try:
                self.q[a.name] = conv.joint_state_arrays(msg, a.joint_names)[0]
            except conv.MessageError:
                return
        self.q_stamp = conv.to_sec(msg.header.stamp)

    def _on_distance(self, msg: Float64) -> None:
        self.min_sep = min(self.min_sep, msg.data)

    def _on_mirror(self, msg: Float64) -> None:
        job = self.jobs[0]  # mirrored mode: the leader's job drives both arms
        if self.mode != 'mirrored' or not job.in_step():
            return
        if job.comparable is None:  # first sample of the move: did it start mirrored?
            job.comparable = msg.data < 0.01
            self.unmirrored += not job.comparable
        if job.comparable:
            self.mirror_max = max(self.mirror_max or 0.0, msg.data)

    def _on_estop(self, msg: Bool) -> None:
        self.estop = bool(msg.data)
        if self.estop:
            self.get_logger().error('emergency stop: the job pauses')

    def _on_start(self, req, res):
        self.running = True
        res.success, res.message = True, f'sorting job running ({self.mode})'
        self.get_logger().info(res.message)
        return res

    def _on_stop(self, req, res):
        self.running = False
        res.success, res.message = True, 'sorting job stopped; arms finish their moves'
        self.get_logger().info(res.message)
        return res

    def _on_planner(self, robot: str, msg: DiagnosticStatus) -> None:
        values = conv.status_values(msg)
        for job in self.jobs:
            if robot not in job.ends:
                continue
            if msg.level == DiagnosticStatus.ERROR:
                self._give_up(job, f'{robot} planner: {msg.message}')
            elif 'end' in values:
                job.ends[robot] = float(values['end'])
                job.starts[robot] = float(values['start'])
                job.delayed = job.delayed or float(values['delay']) > 0
            else:  # waiting or queued: that arm's move is not committed (any more)
                job.ends[robot] = None
                job.starts.pop(robot, None)

    # --- the job ----------------------------------------------------------------------------
    def _tick(self) -> None:
        wall, now = time.monotonic(), self._now()
        w0, s0, factor = self._rtf
        if w0 is not None and wall - w0 > 0.5:
            self._rtf = (wall, now, 0.7 * factor + 0.3 * max((now - s0) / (wall - w0), 0.1))
        elif w0 is None:
            self._rtf = (wall, now, factor)
        if not self.running or self.estop or len(self.q) < len(self.cell.arms):
            return
        if not self._parked_idle:  # arms this job does not use wait above a bin, off the belt
            self._parked_idle = True
            used = {j.robot for j in self.jobs} | (
                {a.name for a in self.cell.arms} if self.mode == 'mirrored' else set())
            for arm in self.cell.arms:
                if arm.name not in used:
                    park = sorting.drop_point(self.cell, arm.name, self.cell.item_classes[0],
                                              self.drop_clearance)
                    self.target_pub[arm.name].publish(
                        conv.make_point_stamped(park, 'world', now + self.lead))
        for job in self.jobs:
            if job.phase == 'idle':
                self._pick_next(job, now)
            elif job.phase in ('to_item', 'to_bin', 'to_park'):
                if any(e is None for e in job.ends.values()):
                    # an arm with an item waits longer for the other arm to clear the way to
                    # its bin: giving up would put the item down where it is (collaborative;
                    # in mirrored mode both arms wait on the same move, and 3x measured worse)
                    longer = job.phase == 'to_bin' and self.mode == 'collaborative'
                    limit = self.move_timeout * (3.0 if longer else 1.0)
                    if now - job.asked > limit:
                        self._give_up(job, 'no plan from the planner in time')
                elif min(now, self.q_stamp) >= max(job.ends.values()):  # seen to have ended
                    self._arrived(job, now)

    def _arrived(self, job: ArmJob, now: float) -> None:
        if job.phase == 'to_park':
            job.reset()
        elif job.phase == 'to_bin':
            self._grip(job, False)
        else:  # at the item? a late start (the arm yielded) leaves it short of the item
            seen = self.items.get(job.item.id)
            if seen is None:
                self._give_up(job, f'item {job.item.id} is no longer on the belt')
                return
            off = sorting.predict(self.cell, seen, now)[:2] - job.target[:2]
            if np.hypot(*off) <= self.grasp_reach:
                self._grip(job, True)
            elif not self._chase(job, seen, now):
                self._give_up(job, f'item {seen.id} got away ({np.hypot(*off):.3f} m)')

    def _chase(self, job: ArmJob, item: sorting.SeenItem, now: float) -> bool:
        # The node's clock stands still while this computes (its callbacks wait). In lockstep
        # the bridge waits too; otherwise sim time runs on in the other processes: estimate it
        # from wall time and the observed real-time factor, and compute again from a later
        # start if the plan went stale.
        rate = 0.0 if self.lockstep is not None else self._rtf[2]
        wall0, now0, extra = time.monotonic(), self._now(), 0.0
        for _ in range(3):
            start = now0 + extra + self.lead
            hit = sorting.intercept(self.cell, self.cell.arm(job.robot), self.q[job.robot],
                                    item, start, self.z_pick, self._plan_fn(job.robot))
            if hit is None:
                return False
            extra = (time.monotonic() - wall0) * rate
            if now0 + extra + 0.5 * self.lead <= hit.start:
                break
        else:
            return False
        job.item, job.phase, job.asked, job.delayed = item, 'to_item', now, False
        self._send(job, hit.target, hit.start)
        return True

    def _plan_fn(self, robot: str):
        arm = self.cell.arm(robot)

        def plan(q0, target):
            try:
                return plan_path(arm, q0, target, mode='line_or_joint')
            except IKError as exc:
                raise ValueError(str(exc)) from None
        return plan

    def _pick_next(self, job: ArmJob, now: float) -> None:
        arm = self.cell.arm(job.robot)
        others_busy = any(j.phase != 'idle' for j in self.jobs if j is not job)
        free = [it for i, it in self.items.items()
                if i not in self.claimed and job.failures.get(i, 0) < 2]
        if self.mode == 'mirrored':  # the leader takes its half; the partner is mirrored
            side = np.sign(arm.base_position[1] - self.cell.belt.centre_y)
            free = [it for it in free if np.sign(it.position[1]) == side]
        own = None if self.mode == 'single' else True
        start = now + self.lead
        for item in sorting.order_candidates(self.cell, arm, free, start, self.z_pick, own,
                                             steal=others_busy)[:2]:
            if not self._chase(job, item, now):
                continue
            self.claimed[item.id] = job.robot
            if self.mode == 'mirrored':
                partner = sorting.mirror_partner(self.cell, item, list(self.items.values()))
                if partner is not None:
                    self.claimed[partner.id] = self.cell.follower.name
            return

    def _send(self, job: ArmJob, target: np.ndarray, start: float) -> None:
        job.target = np.asarray(target, dtype=float)
        msg = conv.make_point_stamped(target, 'world', start)
        if self.mode == 'mirrored':
            job.ends = {a.name: None for a in self.cell.arms}
            job.starts, job.comparable = {}, None
            self.collab_pub.publish(msg)
        else:
            job.ends, job.starts = {job.robot: None}, {}
            self.target_pub[job.robot].publish(msg)

    def _grip(self, job: ArmJob, grasp: bool) -> None:
        job.phase = 'grasping' if grasp else 'releasing'
        robots = list(job.ends) if self.mode == 'mirrored' else [job.robot]
        for robot in robots:
            future = self.grippers[robot].call_async(SetBool.Request(data=grasp))
            if robot == job.robot:
                future.add_done_callback(lambda f, j=job, g=grasp: self._gripped(j, g, f))

    def _gripped(self, job: ArmJob, grasp: bool, future) -> None:
        res = future.result()
        if not grasp:
            if job.item is not None:
                self.claimed.pop(job.item.id, None)
            job.reset()
            return
        if res is None or not res.success:
            job.failures[job.item.id] = job.failures.get(job.item.id, 0) + 1
            self.get_logger().info(f'{job.robot}: grasp of item {job.item.id} failed '
                                   f'({res.message if res else "no answer"}); retrying')
            self.claimed.pop(job.item.id, None)
            job.reset()
            return
        drop = sorting.drop_point(self.cell, job.robot, job.item.cls, self.drop_clearance)
        job.phase, job.asked, job.delayed = 'to_bin', self._now(), False
        self._send(job, drop, 0.0)  # the bin does not move: start as soon as planned

    def _give_up(self, job: ArmJob, why: str) -> None:
        self.get_logger().warning(f'{job.robot}: {why}')
        self.give_ups += 1
        if job.item is not None:
            self.claimed.pop(job.item.id, None)
            job.failures[job.item.id] = job.failures.get(job.item.id, 0) + 1
        if job.phase == 'to_bin':  # holding an item it cannot carry: put it down here
            for robot in (job.ends if self.mode == 'mirrored' else [job.robot]):
                self.grippers[robot].call_async(SetBool.Request(data=False))
        parking = job.phase == 'to_park'
        job.reset()
        if parking:  # the park move itself failed: stay idle rather than retry it forever
            return
        # wait clear of the shared zone, above the first bin, so the other arm is not blocked
        park = sorting.drop_point(self.cell, job.robot, self.cell.item_classes[0],
                                  self.drop_clearance)
        job.phase, job.asked = 'to_park', self._now()
        self._send(job, park, 0.0)

    # --- stats ------------------------------------------------------------------------------
    def stats(self) -> Dict[str, object]:
        """Return the job's figures so far (also published on ``~/stats``)."""
        now = self._now()
        minutes = (now - self.first_item) / 60.0 if self.first_item is not None else 0.0
        rate = self.counts['sorted'] / minutes if minutes > 0 else 0.0
        return {'mode': self.mode, **self.counts, 'items_per_minute': round(rate, 3),
                'min_separation_m': None if self.min_sep == float('inf') else
                round(self.min_sep, 4),
                'mirror_error_max_m': self.mirror_max, 'first_item_time': self.first_item,
                **{f'sorted_by_{r}': n for r, n in self.per_arm.items()},
                'give_ups': self.give_ups,
                **({'unmirrored_moves': self.unmirrored} if self.mode == 'mirrored' else {}),
                'running': self.running, 'time': round(now, 3)}

    def _publish_stats(self) -> None:
        s = self.stats()
        text = (f'{s["sorted"]} sorted, {s["missed"]} missed, {s["items_per_minute"]:.1f}/min')
        self.stats_pub.publish(conv.status('automation_manager', 'OK', text, s))


def main(args=None) -> None:
    """Run the sorting job: ``ros2 run scara_collab automation_manager``."""
    run_node(AutomationManager, args)


if __name__ == '__main__':
    main()
