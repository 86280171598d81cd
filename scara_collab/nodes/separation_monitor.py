"""Separation monitor node (``separation_monitor``): speed and separation monitoring, a thin shell.

:class:`scara_collab.core.separation_monitor.SeparationMonitor` makes every decision; the node
turns the scans and the arms' states into its observations and publishes what it decides. It
runs only in a cell with a person (``graph.job_nodes(people=True)``), where the bridge
simulates the person and the safety scanners.

- ``safety_scanner/scan`` (``sensor_msgs/LaserScan``): one message per scanner per scan, the
  scanner named by ``header.frame_id`` (``config/people.yaml``, ``scanner.names``); a frame it
  does not know, or a scan whose rays, angles or limits are not that scanner's, is refused
  with a throttled warning (a scanner whose scans are all refused falls silent, and every arm
  stops). The first ``monitor.teach_scans`` usable scans of every scanner are taught as the
  empty cell's contour. The scans of one instant (one ``header.stamp``) are observed together,
  with the arms' joints at that instant, once every scanner's and the arms' state of that
  instant have come, or without what is missing at the first decision half a scan period after
  that instant (the newest state before it standing for a late one); a scan of an instant
  already observed is refused (its scanner looks silent for it).
- ``safety_joint_states`` (``sensor_msgs/JointState``, the bridge's, with every scan, stamped
  as the scan): each arm joint's measured position and velocity; and ``planned_velocity``
  (``sensor_msgs/JointState``, velocities only, likewise): per arm joint the planned, unscaled
  velocity of largest size a reaction time and a scan period ahead. Each arm is weighed at both
  and the lower factor taken: an arm accelerating away from rest at the speed it reaches before
  a slowdown decided now takes hold, a braking one at the speed it has. A message refused by
  its stamp (:func:`scara_collab.nodes.conversions.admit_state`) is ignored; a non-finite one,
  one lacking an arm's joints or a state without velocities stops the arm it is of until a
  good one comes, and so does an arm whose newest state or planned velocity is older than
  ``stale_after`` (a scanner's silence). The monitor takes no ``joint_states`` (100 Hz): what
  it weighs comes once a scan, as a safety controller reads a robot's safe interface once a
  cycle.

At each step of sim time (:func:`scara_collab.nodes.sim_timer.every`, at most the state rate)
it observes the scans that have come and decides when there is something new to decide on:
scans of a new instant (at the scanners' rate), a fault, the end of one. At a scan instant
the decision (and the lockstep answer) waits for that instant's scans and states when they
come after its clock (:class:`scara_collab.nodes.scan_sync.ScanSync`, parameter ``scan_sync``,
on by default; the launcher turns it off in real time): the same seed, the same run.

It publishes each arm's factor on ``<robot>/speed_scaling`` (``std_msgs/Float64``, latched: at
start 0, then at every decision, so the bridge hears the monitor alive; wired, when it
changes), the decision on
``~/status`` (:class:`~scara_collab.nodes.protocol.SeparationStatus`, at every decision that
changes it, its time aside: with every scan while a person is seen; and at least once a sim
second) and once a sim second on ``/diagnostics``, and, while something subscribes, RViz
markers on ``~/markers``: each tracked person's column as a cylinder and per arm a ring of
``S_p`` around the column of the person nearest to it. It fails closed as the core does (no
scan yet, a silent scanner, a ray that measured nothing: every arm ``s = 0`` with the reason),
and logs each stop's begin and end (throttled). It is a lockstep participant, and the bridge's
guard: while it is silent the arms hold.

**Wired** (the bridge's ``monitor_link`` ``wired``, the default of a run with a person) the
bridge builds it in its own process (:func:`scara_collab.nodes.bridge_people.wired_monitor`),
as a real cell wires its scanner, safety controller and robot: it subscribes nothing, keeps no
sim timers and joins no lockstep; the bridge hands it the same messages (:meth:`take_state`,
:meth:`take_planned`, :meth:`take_scan`) and then its sim time (:meth:`tick`, at every state
step), and each factor goes back to the bridge at once as well as on its topic. Its clock is
the bridge's sim time, so stamps and stale checks read as on sim time. Over topics (``topics``)
it is the node described above, a process of its own.

Parameters: every key of ``config/people.yaml`` (read only), and its own ``profile``,
``marker_rate`` (Hz of sim time, may change while it runs) and ``scan_sync``.
``docs/interface.md``, ``docs/people.md``.
"""
from collections import deque
from dataclasses import replace
import math
from typing import Callable, Deque, Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Point
import numpy as np
from rclpy.node import Node
from rclpy.time_source import TimeSource
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState, LaserScan
from std_msgs.msg import ColorRGBA, Float64, Header
from visualization_msgs.msg import Marker, MarkerArray

from scara_collab.core.collision import arm_capsules
from scara_collab.core.config import load_config, Rule
from scara_collab.core.model import load_cell
from scara_collab.core.scan_tracking import range_faults, scanners_from_config
from scara_collab.core.separation_monitor import (Decision, MonitorSettings, nearest_person,
                                                  PersonSeen, SeparationMonitor)
from scara_collab.nodes import conversions as conv, lockstep, protocol as proto
from scara_collab.nodes.diagnostics import Diagnostics
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.params import declare_checked, declare_config
from scara_collab.nodes.qos import DEFAULT, LATCHED
from scara_collab.nodes.runner import run_node
from scara_collab.nodes.scan_sync import ScanSync
from scara_collab.nodes.sim_timer import every

#: the monitor's own parameters and their defaults (the rest is config/people.yaml)
PARAMETERS = {
    'profile': '',
    'marker_rate': 10.0,  # Hz of sim time, at most, for ~/markers
    'scan_sync': True,  # a scan instant's decision waits for its inputs (lockstep)
}
RULES = (Rule('profile', 'text'), Rule('marker_rate', 'positive'), Rule('scan_sync', 'bool'))
DYNAMIC = ('marker_rate',)
#: ring colour per arm, by its index in ``cell.arms`` (the viewer's planned-path colours)
ARM_COLOURS = ((0.9, 0.47, 0.08), (0.08, 0.63, 0.78))
#: s of safety joint states kept, to mute the quills where they were when a scan was taken
STATE_HISTORY = 1.0
#: s between two throttled warnings of one kind
THROTTLE = 5.0
#: sim s: ``~/status`` is said when it changes (the time aside), and at least this often
HEARTBEAT = 1.0
RING_POINTS = 48
#: the inputs besides the scans a scan instant's decision waits for (:class:`ScanSync`)
STATE_INPUTS = ('safety_joint_states', 'planned_velocity')


def _ns(stamp) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds (the scans of one instant, exactly)."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class SeparationMonitorNode(Node):
    """The speed and separation monitor: scans and states in, each arm's speed factor out."""

    def __init__(self, wired: Optional[Callable[[str, float], None]] = None, **kwargs):
        """Declare and check the parameters, load the cell, create the topics.

        :param wired: the bridge's factor input, ``wired(robot, factor)``, when the monitor
            runs in the bridge's process (the bridge's ``monitor_link`` ``wired``, module
            docstring): it then subscribes nothing, keeps no timers of its own and joins no
            lockstep; the bridge hands it each message (:meth:`take_scan`,
            :meth:`take_state`, :meth:`take_planned`) and its sim time (:meth:`tick`), and it
            hands each factor back at once. It must be built with ``use_sim_time`` false.
        :param kwargs: passed to :class:`rclpy.node.Node` (``context``, ``cli_args``, ...).
        :raises ConfigError: an invalid ``config/people.yaml`` value or own parameter.
        """
        super().__init__('separation_monitor', **kwargs)
        self.wired = wired
        self.stamps = conv.StampGate()  # joint states must carry the sim clock's time
        cfg = declare_config(self, ('people',))['people']
        params = declare_checked(self, PARAMETERS, RULES, dynamic=DYNAMIC,
                                 on_change=self._set_params)
        self._set_params(params)
        self.cell = load_cell(params['profile'] or None)
        self.settings = MonitorSettings.from_config(cfg)
        self.scanners = scanners_from_config(cfg)
        self.monitor = SeparationMonitor(self.cell, self.settings, self.scanners)
        self._index = {g.name: i for i, g in enumerate(self.scanners)}
        self._teach: List[List[np.ndarray]] = [[] for _ in self.scanners]
        self._groups: Dict[int, List[Optional[np.ndarray]]] = {}  # stamp (ns) -> scans
        self.observed: Optional[int] = None  # the newest instant observed, ns
        self._half_period = int(round(self.settings.scan_period * 0.5e9))
        rate = float(load_config('simulation')['state_rate'])
        # (stamp in ns, {robot: joints or None}) of the recent states, newest last
        self._history: Deque[Tuple[int, Dict[str, Optional[np.ndarray]]]] = deque(
            maxlen=max(2, int(STATE_HISTORY / self.settings.scan_period)))
        # each arm's (stamp in ns, joints, measured velocity), and (stamp, planned velocity)
        # (None: refused, it stops)
        self._state: Dict[str, Optional[Tuple[int, np.ndarray, np.ndarray]]] = {}
        self._ahead: Dict[str, Optional[Tuple[int, np.ndarray]]] = {}
        self.planned_stamps = conv.StampGate()
        self._stale = int(round(self.settings.stale_after * 1e9))
        self.decision: Optional[Decision] = None
        self.status: Optional[proto.SeparationStatus] = None
        # (when, what) was last said on ~/status
        self._said: Optional[Tuple[float, proto.SeparationStatus]] = None
        self._scales: Dict[str, float] = {}
        self._stopped: Dict[str, bool] = {}
        self._fault = ''
        self._decided: Optional[int] = None  # the newest instant decided on, ns
        self.checked: Optional[float] = None  # sim s of the last look (a decision or not)
        self._look_at = 0  # wired: sim time (ns) of the next tick that looks (:meth:`tick`)
        self._next_marker = 0.0
        # one logger per arm, kept: a throttled message is throttled per logger and call site
        self._logs = {a.name: self.get_logger().get_child(a.name) for a in self.cell.arms}
        self.scale_pubs = {a.name: self.create_publisher(Float64, f'{a.name}/speed_scaling',
                                                         LATCHED) for a in self.cell.arms}
        self.status_pub = self.create_publisher(DiagnosticStatus, '~/status', DEFAULT)
        self.diagnostics = Diagnostics(self)
        self.marker_pub = self.create_publisher(MarkerArray, '~/markers', DEFAULT)
        if wired is None:  # every scan and every state, in turn (two scanners' at an instant)
            self.create_subscription(LaserScan, 'safety_scanner/scan',
                                     guarded(self, self.take_scan), DEFAULT)
            self.create_subscription(JointState, 'safety_joint_states',
                                     guarded(self, self.take_state), DEFAULT)
            self.create_subscription(JointState, 'planned_velocity',
                                     guarded(self, self.take_planned), DEFAULT)
        for arm in self.cell.arms:  # held until the first decision
            self._publish_scale(arm.name, 0.0)
        # each decision on the sim clock, before the lockstep answer; at a scan instant on
        # that instant's scans and states, however the middleware ordered them and the clock
        # (wired, the bridge hands them over before it ticks: nothing to wait for)
        self.sync = ScanSync(self._decide, self.settings.scan_period,
                             params['scan_sync'] and wired is None,
                             [g.name for g in self.scanners] + list(STATE_INPUTS))
        if wired is None:
            every(self, 1.0 / rate,
                  lambda: self.sync.on_tick(self.get_clock().now().nanoseconds))
            every(self, 1.0, self._publish_diagnostics)
            self.sync.lockstep = lockstep.join(self)  # sim time waits while this node decides
        else:  # its clock is the bridge's sim time, set at each tick (no /clock to take)
            if self.get_parameter('use_sim_time').value:
                raise ValueError('a wired separation monitor takes its time from the bridge: '
                                 'build it with use_sim_time false')
            self._time = TimeSource()
            self._time.attach_clock(self.get_clock())
            self._time.ros_time_is_active = True
            self._next_diagnostics = 1.0
        self.get_logger().info(
            f'watching {", ".join(a.name for a in self.cell.arms)} with '
            f'{", ".join(g.name for g in self.scanners)}; teaching the empty cell from '
            f'{self.settings.teach_scans} scans each')

    def _set_params(self, params: dict) -> None:
        """Take the values of the dynamic parameters (at start and on a change)."""
        self.marker_period = 1.0 / float(params['marker_rate'])

    # --- what the monitor observes -----------------------------------------------------------
    def tick(self, now_ns: int) -> None:
        """Take the bridge's sim time ``now_ns`` (wired): decide on what it handed over.

        The bridge calls it at every state step, after the scans and states of the instant:
        the decision the node's own sim timers would run, and ``/diagnostics`` once a sim
        second. A tick at which nothing can have changed is skipped, its clock left at the last
        look (:meth:`_next_look`): the same decisions, at the same instants, as looking at
        every tick.
        """
        if now_ns < self._look_at:
            return
        self._time.clock_callback(ClockMsg(clock=conv.to_time(now_ns * 1e-9)))
        self.sync.on_tick(now_ns)
        now = now_ns * 1e-9
        if now >= self._next_diagnostics - 1e-9:  # on the whole sim seconds
            self._next_diagnostics = math.floor(now + 1e-9) + 1.0
            self._publish_diagnostics()
        self._look_at = self._next_look(now_ns)

    def _next_look(self, now_ns: int) -> int:
        """Return the first sim time (ns) after ``now_ns`` at which a look can change anything.

        Until inputs are handed over (each resets it), a decision stands while no instant waits
        for a missing scan (observed half a period after it), no scanner's last scan comes to
        ``stale_after`` (looked at from a millisecond before, the stale check itself deciding)
        and no diagnostics are due; with no decision yet, or a scanner stale (its cause counts
        the seconds), the next tick.
        """
        if self.decision is None:
            return now_ns + 1
        due = [int(math.floor(self._next_diagnostics * 1e9)) - 1_000_000]
        due += [t + self._half_period for t in self._groups]
        for seen in self.monitor.seen:
            if seen is not None:
                stale = int(math.floor((seen + self.settings.stale_after) * 1e9)) - 1_000_000
                due.append(stale if stale > now_ns else now_ns + 1)
        return min(due)

    def take_scan(self, msg: LaserScan) -> None:
        """Take a scanner's scan (a subscription's callback, or handed over when wired)."""
        self._look_at = 0  # something new: the next tick looks
        index = self._index.get(msg.header.frame_id)
        if index is None:
            self.get_logger().warning(
                f'ignoring a scan of frame {msg.header.frame_id!r}: not a scanner of '
                f'config/people.yaml ({", ".join(self._index)})', throttle_duration_sec=THROTTLE)
            return
        stamp = _ns(msg.header.stamp)
        try:
            ranges = conv.scan_ranges(msg, self.scanners[index])
        except conv.MessageError as exc:
            self.get_logger().warning(f'ignoring a scan: {exc}', throttle_duration_sec=THROTTLE)
            self.sync.on_input(msg.header.frame_id, stamp)  # come, and refused: not awaited
            return
        if self.observed is not None and stamp <= self.observed:
            self.get_logger().warning(
                f'ignoring a late scan of {msg.header.frame_id} at t={stamp * 1e-9:.3f} s: its '
                f'instant is observed already', throttle_duration_sec=THROTTLE)
            return
        self._learn(index, ranges)
        group = self._groups.setdefault(stamp, [None] * len(self.scanners))
        group[index] = ranges
        self._observe_ready()
        self.sync.on_input(msg.header.frame_id, stamp)

    def _observe_ready(self) -> None:
        """Observe the instants whose scans have all come, with the arms' state at them."""
        have = self._history[-1][0] if self._history else -1
        ready = [t for t, group in self._groups.items()
                 if t <= have and all(r is not None for r in group)]
        if ready:
            self._observe_until(max(ready))

    def _learn(self, index: int, ranges: np.ndarray) -> None:
        """Keep a usable scan for the contour until every scanner has ``teach_scans``."""
        if self.monitor.taught or range_faults(ranges, self.scanners[index]):
            return
        if len(self._teach[index]) < self.settings.teach_scans:
            self._teach[index].append(ranges)
        if all(len(k) >= self.settings.teach_scans for k in self._teach):
            self.monitor.teach(self._teach)
            self._teach = [[] for _ in self.scanners]
            self.get_logger().info(f'taught the empty cell from {self.settings.teach_scans} '
                                   'scans of each scanner')

    def _observe_until(self, stamp: int) -> None:
        """Observe every instant up to ``stamp`` (ns) whose scans are waiting, oldest first."""
        for t in sorted(k for k in self._groups if k <= stamp):
            scans = self._groups.pop(t)
            self.monitor.observe(t * 1e-9, scans, self._joints_at(t))
            self.observed = t

    def _joints_at(self, t: int) -> Dict[str, np.ndarray]:
        """Return the arms' finite joints of the newest state at or before ``t`` (ns)."""
        chosen = None
        for stamp, joints in reversed(self._history):
            chosen = joints
            if stamp <= t:
                break
        return {r: q for r, q in (chosen or {}).items() if q is not None}

    def take_state(self, msg: JointState) -> None:
        """Take the arms' safety joint state (subscribed, or handed over when wired)."""
        self._look_at = 0  # something new: the next tick looks
        if not conv.admit_state(self, self.stamps, msg):
            self.sync.on_input(STATE_INPUTS[0], _ns(msg.header.stamp))  # refused: not awaited
            return
        stamp = _ns(msg.header.stamp)
        for arm in self.cell.arms:
            try:
                if len(msg.velocity) != len(msg.name):  # no speed: never taken as rest
                    raise conv.MessageError('velocity and name lengths differ')
                self._state[arm.name] = (stamp, *conv.joint_state_arrays(msg, arm.joint_names))
            except conv.MessageError as exc:  # fail closed: the arm stops until a good one
                self._state[arm.name] = None
                self._logs[arm.name].warning(
                    f'refusing its joint state ({exc}); it stops', throttle_duration_sec=THROTTLE)
        self._history.append((stamp, {r: None if s is None else s[1]
                                      for r, s in self._state.items()}))
        self._observe_ready()
        self.sync.on_input(STATE_INPUTS[0], stamp)

    def take_planned(self, msg: JointState) -> None:
        """Take the arms' planned velocity (subscribed, or handed over when wired)."""
        self._look_at = 0  # something new: the next tick looks
        if not conv.admit_state(self, self.planned_stamps, msg):
            self.sync.on_input(STATE_INPUTS[1], _ns(msg.header.stamp))  # refused: not awaited
            return
        for arm in self.cell.arms:
            try:
                self._ahead[arm.name] = (_ns(msg.header.stamp),
                                         conv.velocity_arrays(msg, arm.joint_names))
            except conv.MessageError as exc:  # fail closed: the arm stops until a good one
                self._ahead[arm.name] = None
                self._logs[arm.name].warning(f'refusing its planned velocity ({exc}); it stops',
                                             throttle_duration_sec=THROTTLE)
        self.sync.on_input(STATE_INPUTS[1], _ns(msg.header.stamp))

    # --- the decision ------------------------------------------------------------------------
    def planned(self, now: float) -> Dict[str, Tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Return ``{robot: (q, planned qd, measured qd)}`` of the arms weighed at ``now``.

        An arm without a good state and planned velocity, both said within ``stale_after`` of
        ``now``, is left out (it stops).
        """
        since = int(round(now * 1e9)) - self._stale
        out = {}
        for arm in self.cell.arms:
            state, ahead = self._state.get(arm.name), self._ahead.get(arm.name)
            if state is None or ahead is None or min(state[0], ahead[0]) < since:
                continue
            out[arm.name] = (state[1], ahead[1], state[2])
        return out

    def _decide(self) -> None:
        now = self.checked = conv.now(self)
        # the instants whose missing scans are half a period late: without them
        self._observe_until(int(round(now * 1e9)) - self._half_period)
        fault = self.monitor.fault(now)
        if self.observed == self._decided and fault == self._fault and self.decision:
            return  # nothing new since the last decision: it stands
        self._decided = self.observed
        decision = self.monitor.decide(now, self.planned(now))
        self.decision = decision
        for arm in decision.arms:
            self._publish_scale(arm.robot, arm.scale)
        self._log(decision)
        self.status = proto.SeparationStatus(
            round(now, 6), scale={a.robot: a.scale for a in decision.arms},
            stop={a.robot: a.stop for a in decision.arms},
            cause={a.robot: a.cause for a in decision.arms},
            separation={a.robot: a.separation for a in decision.arms},
            margin={a.robot: a.margin for a in decision.arms},
            persons=tuple(PersonSeen.of(p) for p in decision.persons), fault=decision.fault)
        timeless = replace(self.status, time=0.0)
        if self._said is None or now - self._said[0] >= HEARTBEAT - 1e-9 or (
                timeless != self._said[1]):
            self._said = (now, timeless)
            self.status_pub.publish(self.status.to_msg())
        if now >= self._next_marker and self.marker_pub.get_subscription_count():
            self._next_marker = now + self.marker_period  # markers only for a listener
            self.marker_pub.publish(self._markers(decision))

    def _publish_scale(self, robot: str, scale: float) -> None:
        """Publish ``robot``'s factor (latched: the last one stands; the bridge times it out).

        Over topics at every decision (the bridge hears the monitor alive); wired, handed to the
        bridge at every decision and published when it changes (the topic is for others).
        """
        said = self._scales.get(robot)
        self._scales[robot] = scale
        if self.wired is None or said is None or scale != said:
            self.scale_pubs[robot].publish(Float64(data=float(scale)))
        if self.wired is not None:
            self.wired(robot, float(scale))

    def _log(self, decision: Decision) -> None:
        """Log each stop's begin and end (throttled while it stands)."""
        log = self.get_logger()
        if decision.fault:
            log.warning(f'every arm stopped: {decision.fault}', throttle_duration_sec=THROTTLE)
        elif self._fault:
            log.info(f'fault cleared ({self._fault})')
        self._fault = decision.fault
        for arm in decision.arms:
            if decision.fault:
                self._stopped[arm.robot] = True
                continue
            arm_log = self._logs[arm.robot]
            if arm.stop:
                arm_log.warning(f'protective stop: {arm.cause}', throttle_duration_sec=THROTTLE)
            elif self._stopped.get(arm.robot) and arm.scale > 0.0:
                arm_log.info(f'resuming at {arm.scale:.2f} of its speed')
            self._stopped[arm.robot] = arm.stop or arm.scale <= 0.0

    def _publish_diagnostics(self) -> None:
        if self.status is not None:
            self.diagnostics.publish(self.status.to_msg())

    def _markers(self, decision: Decision) -> MarkerArray:
        """Return the persons' columns and each arm's ``S_p`` ring around its nearest person."""
        header = Header(stamp=conv.to_time(decision.time), frame_id='world')
        out = MarkerArray()
        out.markers.append(Marker(header=header, action=Marker.DELETEALL))
        for p in decision.persons:
            m = Marker(header=header, ns='persons', id=int(p.id), type=Marker.CYLINDER,
                       action=Marker.ADD, color=ColorRGBA(r=0.9, g=0.2, b=0.2, a=0.35))
            m.pose.position = Point(x=float(p.position[0]), y=float(p.position[1]),
                                    z=p.height / 2.0)
            m.pose.orientation.w = 1.0
            m.scale.x = m.scale.y = 2.0 * p.radius
            m.scale.z = p.height
            out.markers.append(m)
        for k, arm_decision in enumerate(decision.arms):
            arm = self.cell.arm(arm_decision.robot)
            state = self._state.get(arm.name)
            s_p = arm_decision.separation - arm_decision.margin
            if state is None or not np.isfinite(s_p):
                continue
            person = nearest_person(arm, state[1], decision.persons)
            if person is None:
                continue
            r, g, b = ARM_COLOURS[k % len(ARM_COLOURS)]
            m = Marker(header=header, ns=f'{arm.name}/protective_separation', id=0,
                       type=Marker.LINE_STRIP, action=Marker.ADD,
                       color=ColorRGBA(r=r, g=g, b=b, a=0.9))
            m.scale.x = 0.03
            m.pose.orientation.w = 1.0
            radius = person.radius + s_p  # S_p from the column's surface
            z = float(arm_capsules(arm, state[1])[0][1, 2])  # at link 2's height
            a = np.linspace(0.0, 2.0 * np.pi, RING_POINTS + 1)
            m.points = [Point(x=float(person.position[0] + radius * np.cos(t)),
                              y=float(person.position[1] + radius * np.sin(t)), z=z) for t in a]
            out.markers.append(m)
        return out


def main(args=None) -> None:
    """Run the separation monitor: ``ros2 run scara_collab separation_monitor``."""
    run_node(SeparationMonitorNode, args)
