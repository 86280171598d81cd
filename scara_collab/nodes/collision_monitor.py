"""Collision monitor: the safety net behind the bridge's admission, the separation's source.

On every ``/joint_states`` message it computes the arm-to-arm capsule surface distance and
publishes it on ``/collision_monitor/min_distance``. It stops both arms, in ISO 10218's two
ways (:data:`scara_collab.nodes.protocol.STOP_KINDS`):

- a **protective stop** (``/protective_stop`` true, transient local; the bridge brakes both
  arms at their acceleration limits and holds them, dropping their moves) when the arms'
  committed motion is predicted to break the margin sooner than they can brake (it follows
  what the bridge runs by the committed-motion model's rules,
  :class:`scara_collab.core.motion.Heard`, and stops once the predicted first breach is
  nearer than the braking time plus ``stop_latency`` plus how old the states have lately been
  when they came: :mod:`scara_collab.core.safety`), when a
  joint state is unusable (non-finite, missing joints), or when no valid state has come for
  ``stale_after`` sim seconds (seen at two looks in a row, ``stale_after / 2`` apart). It is
  released by the monitor itself once the cause is gone: valid states for ``resume_after``
  sim seconds, the arms at rest and at least the margin apart (the job then plans again from
  where the arms are);
- an **emergency stop** (``/emergency_stop`` true, transient local) when the measured distance
  falls below the margin, or when anyone else publishes ``/emergency_stop`` true. It holds until
  ``/collision_monitor/clear`` (std_srvs/Trigger, idempotent) releases it, once the arms are
  apart again and the state is fresh.

Every stop's begin and end goes to ``~/stops`` (:class:`~scara_collab.nodes.protocol.StopEvent`)
for the run's summary. ``~/status`` (:class:`~scara_collab.nodes.protocol.MonitorStatus`, 1 Hz
and on every change) carries the smallest distance seen and when: the run's one source of the
minimum separation. Capsule markers coloured by distance go to ``~/capsules`` while something
subscribes to it. Its own parameters (:data:`PARAMETERS`) are checked at start and on every
change; only ``marker_rate``, ``stop_latency`` and ``resume_after`` may change while it runs.
"""
from typing import List, Optional

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Point
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, ColorRGBA, Float64, Header
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import Marker, MarkerArray

from scara_collab.core import collision
from scara_collab.core.config import load_config, Rule
from scara_collab.core.model import load_cell
from scara_collab.core.move_time import Lateness
from scara_collab.core.stop_rules import BreachForecast, StopChange, StopLatch
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.diagnostics import Diagnostics
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.params import declare_checked
from scara_collab.nodes.qos import DEFAULT, EVENTS, LATCHED
from scara_collab.nodes.runner import run_node
from scara_collab.nodes.sim_timer import every

PARTS = ('link 1', 'link 2', 'quill')
#: the monitor's own parameters and their defaults
PARAMETERS = {
    'profile': '',
    'safety_margin': -1.0,  # m; < 0: the cell's margin
    'marker_rate': 10.0,    # Hz of sim time, at most, for ~/capsules
    'stale_after': 0.2,     # sim s without a valid state: stop
    # s from a state to the bridge braking on the stop it causes: a state period (10 ms at
    # simulation.yaml's state_rate, 100 Hz), the lockstep window (20 ms, one period of its
    # clock_rate, 50 Hz) and the monitor's own turn
    'stop_latency': 0.05,
    'resume_after': 0.3,    # sim s of valid states, arms at rest and apart: a protective stop ends
}
RULES = (Rule('profile', 'text'), Rule('safety_margin', 'number'),
         Rule('marker_rate', 'positive'), Rule('stale_after', 'positive'),
         Rule('stop_latency', 'nonneg'), Rule('resume_after', 'positive'))
#: the parameters that may change while the monitor runs (the margin and the watch's period
#: may not)
DYNAMIC = ('marker_rate', 'stop_latency', 'resume_after')
#: rad/s or m/s: an arm this slow on every joint is at rest (a protective stop may end)
AT_REST = 0.02


class CollisionMonitor(Node):
    """Watch the arm-to-arm distance and stop both arms if the margin is broken."""

    def __init__(self, **kwargs):
        """Declare and check the parameters, load the cell and create the watch.

        :param kwargs: passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``).
        :raises ConfigError: a marker rate, stale time, latency or margin out of range.
        """
        super().__init__('collision_monitor', **kwargs)
        self.stamps = conv.StampGate()  # joint states must carry the sim clock's time
        params = declare_checked(self, PARAMETERS, RULES, dynamic=DYNAMIC,
                                 on_change=self._set_params)
        self.cell = load_cell(params['profile'] or None)
        margin = float(params['safety_margin'])
        self.margin = self.cell.safety_margin if margin < 0 else margin
        self.stale_after = float(params['stale_after'])
        self.stops = StopLatch(float(params['resume_after']))  # the standing stop, its counts
        self._set_params(params)
        dt = 1.0 / float(load_config('simulation')['physics_rate'])
        self.forecast = BreachForecast(self.cell.arms, self.margin, dt)
        self._q = {arm.name: None for arm in self.cell.arms}  # the last valid state
        # how old the states are when they come (sim s): added to stop_latency
        self.state_age = Lateness(window=50)
        self.last: Optional[float] = None
        self.last_time: Optional[float] = None  # sim time of the last valid state
        self._stale_since: Optional[float] = None  # the watch's first stale look
        self.minimum: Optional[float] = None
        self.minimum_time: Optional[float] = None
        self._next_marker = 0.0
        self._published_min: Optional[float] = None
        self.dist_pub = self.create_publisher(Float64, '~/min_distance', 10)
        self.estop_pub = self.create_publisher(Bool, 'emergency_stop', LATCHED)
        self.protective_pub = self.create_publisher(Bool, 'protective_stop', LATCHED)
        self.stops_pub = self.create_publisher(DiagnosticStatus, '~/stops', EVENTS)
        self.status_pub = self.create_publisher(DiagnosticStatus, '~/status', 10)
        self.diagnostics = Diagnostics(self, self.status_pub)  # and on /diagnostics
        self.marker_pub = self.create_publisher(MarkerArray, '~/capsules', 10)
        # every state (a depth of 1 would skip one whenever the monitor is a state behind)
        self.create_subscription(JointState, 'joint_states', guarded(self, self._on_state),
                                 DEFAULT)
        self.create_service(Trigger, '~/clear', guarded(self, self._on_clear, True))
        # anyone may ask for an emergency stop (the monitor's own true comes back here too)
        self.create_subscription(Bool, 'emergency_stop', guarded(self, self._on_estop), LATCHED)
        for arm in self.cell.arms:
            self.create_subscription(
                JointTrajectory, f'{arm.name}/joint_trajectory',
                guarded(self, lambda msg, n=arm.name: self._on_trajectory(n, msg)), 10)
            self.create_subscription(
                DiagnosticStatus, f'{arm.name}/execution_status',
                guarded(self, self._on_execution), 50)
            self.create_subscription(
                DiagnosticStatus, f'{arm.name}/trajectory_clock',
                guarded(self, self._on_clock), EVENTS)
        every(self, self.stale_after / 2, self._watch)  # on the sim clock
        every(self, 1.0, self._publish_status)
        self.estop_pub.publish(Bool(data=False))
        self.protective_pub.publish(Bool(data=False))
        lockstep.join(self)  # sim time waits while this node computes
        self.get_logger().info(f'watching {self.cell.leader.name} vs '
                               f'{self.cell.follower.name}, margin {self.margin} m')

    def _set_params(self, params: dict) -> None:
        """Take the values of the dynamic parameters (at start and on a change)."""
        self.marker_period = 1.0 / float(params['marker_rate'])
        self.latency = float(params['stop_latency'])
        self.stops.resume_after = float(params['resume_after'])

    @property
    def stopped(self) -> bool:
        """True while a stop (either kind) stands."""
        return self.stops.stopped

    def _stop(self, kind: str, text: str) -> None:
        """Stop both arms: ``kind`` protective or emergency (an emergency overrides the other)."""
        self._publish_stops(self.stops.stop(kind, text, conv.now(self)))

    def _end_stop(self, why: str) -> None:
        """Release the standing stop (its end goes to ``~/stops``)."""
        self._publish_stops(self.stops.end(why, conv.now(self)))

    def _publish_stops(self, changes: List[StopChange]) -> None:
        """Say each stop that begins or ends: the latched flag, ``~/stops``, the log, status."""
        for c in changes:
            pub = self.estop_pub if c.kind == 'emergency' else self.protective_pub
            pub.publish(Bool(data=c.state == 'begin'))
            self.stops_pub.publish(proto.StopEvent(c.kind, c.state, round(c.time, 6), c.text,
                                                   c.since).to_msg())
            if c.state == 'begin':
                log = self.get_logger().error if c.kind == 'emergency' else \
                    self.get_logger().warning
                log(f'{c.text}; {c.kind} stop')
            else:
                self.forecast.again = True
                self.get_logger().info(f'{c.kind} stop released: {c.text}')
            self._publish_status()

    def _on_estop(self, msg: Bool) -> None:
        """Take an emergency stop asked for by anyone (an outside request)."""
        if msg.data and self.stops.kind != 'emergency':
            self._stop('emergency', 'emergency stop requested on /emergency_stop')

    # --- what the bridge runs --------------------------------------------------------------
    def _on_trajectory(self, robot: str, msg: JointTrajectory) -> None:
        try:
            stamp, t, q, _, _ = conv.trajectory_arrays(msg, self.cell.arm(robot).joint_names)
        except conv.MessageError:
            return  # the bridge refuses it too
        self.forecast.on_trajectory(robot, msg.header.frame_id, stamp, t, q, conv.now(self),
                                    self._q[robot])

    def _on_execution(self, msg: DiagnosticStatus) -> None:
        st = proto.ExecutionStatus.from_msg(msg)
        self.forecast.on_status(st.robot, st.state, st.move, conv.now(self), st.start,
                                self._q.get(st.robot))

    def _on_clock(self, msg: DiagnosticStatus) -> None:
        clock = proto.TrajectoryClock.from_msg(msg)
        self.forecast.on_clock(clock.robot, clock.lag)

    # --- the watch ---------------------------------------------------------------------------
    def _on_state(self, msg: JointState) -> None:
        if not conv.admit_state(self, self.stamps, msg):
            return  # not the simulator's state: the watchdog stops the arms if no valid one comes
        a, b = self.cell.arms
        try:
            qa, va = conv.joint_state_arrays(msg, a.joint_names)
            qb, vb = conv.joint_state_arrays(msg, b.joint_names)
        except conv.MessageError as exc:  # fail closed: a state we cannot check stops the arms
            self._stop('protective', f'unusable joint state: {exc}')
            self.stops.unsettled()
            return
        pairs = collision.arm_pair_distances(a, qa, b, qb)
        d = float(pairs.min())
        stamp = conv.to_sec(msg.header.stamp)
        now = conv.now(self)
        if now > 0:
            self.state_age.add(now - stamp)
        self._q[a.name], self._q[b.name] = qa, qb
        # the watchdog runs on sim time: a state heard before the first /clock has no time
        self.last, self.last_time = d, (now if now > 0 else None)
        if self.minimum is None or d < self.minimum:
            self.minimum, self.minimum_time = d, stamp
            if self._published_min is None or d < self._published_min - 5e-4:
                self._published_min = d  # a new minimum is news: the run summary reads it
                self._publish_status()
        self.dist_pub.publish(Float64(data=d))
        if d < self.margin:
            i, j = np.unravel_index(np.argmin(pairs), pairs.shape)
            self._stop('emergency', f'margin broken: {a.name} {PARTS[i]} to {b.name} '
                       f'{PARTS[j]} {d:.4f} m < {self.margin} m at t={stamp:.3f} s')
        elif not self.stopped:
            latency = self.latency + self.state_age.worst  # as configured, and as measured
            why = self.forecast.reason_to_stop(stamp, (qa, qb), (va, vb), latency)
            if why is not None:
                self._stop('protective', why)
        elif self.stops.kind == 'protective':
            at_rest = all(np.max(np.abs(v)) < AT_REST for v in (va, vb))
            self._publish_stops(self.stops.calm(stamp, d >= self.margin, at_rest, d))
        if stamp >= self._next_marker:
            self._next_marker = stamp + self.marker_period
            if self.marker_pub.get_subscription_count():  # markers only for a listener
                self.marker_pub.publish(self._markers(qa, qb, d, msg.header))

    def _watch(self) -> None:
        """Fail closed when the valid states stop coming (sim time runs on without them).

        Stale at two looks in a row (``stale_after / 2`` apart): after the monitor itself is
        held up (starting, descheduled), the clock that wakes this timer can be taken before
        the state that came with it; one look would stop the arms for the monitor's delay,
        not for missing states.
        """
        now = conv.now(self)
        if self.last_time is None or now - self.last_time <= self.stale_after:
            self._stale_since = None
        elif self._stale_since is None:
            self._stale_since = now  # look again at the next tick, after the queued states
        elif now > self._stale_since:
            self._stop('protective', f'no valid joint state for {now - self.last_time:.3f} s '
                       '(sim)')
            self.stops.unsettled()

    def _on_clear(self, req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        fresh = self.last_time is not None and conv.now(self) - self.last_time <= self.stale_after
        if not self.stopped:
            res.success, res.message = True, 'no stop to clear'
        elif self.last is None or not fresh or self.last < self.margin:
            res.success = False
            res.message = ('no fresh joint state; not cleared' if not fresh or self.last is None
                           else f'arms still {self.last:.3f} m apart (< {self.margin} m); '
                           'not cleared')
        else:
            kind = self.stops.kind
            self._end_stop('cleared on request (/collision_monitor/clear)')
            res.success, res.message = True, f'{kind} stop cleared'
            self.get_logger().info(res.message)
            self._publish_status()
        return res

    def status(self) -> proto.MonitorStatus:
        """Return the monitor's figures so far."""
        return proto.MonitorStatus(round(conv.now(self), 6), self.last, self.minimum,
                                   self.minimum_time, self.margin, self.stopped,
                                   self.stops.reason, self.stops.kind,
                                   self.stops.counts['protective'],
                                   self.stops.counts['emergency'])

    def _publish_status(self) -> None:
        self.diagnostics.publish(self.status().to_msg())

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
