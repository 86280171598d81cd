"""A person in the simulated cell: the bridge's part (the person, the safety scanner, scaling).

Built by the bridge only when its ``person`` parameter names a scenario
(:func:`scara_collab.sim.person_scenarios.scenario`: ``pass-by``, ``inlet``, ``middle``,
``random`` or a YAML file): a cell without one has none of this and runs as before.

In the simulator's world it puts the person (:class:`scara_collab.sim.person.PersonSim`, posed
at every publication step) and the floor scanners
(:class:`scara_collab.sim.scanner.SafetyScanner`).
It publishes, on sim time:

- ``safety_scanner/scan`` (``sensor_msgs/LaserScan``, one message per scanner, its name as
  ``frame_id``), at the scanners' rate (``config/people.yaml``, 25 Hz): what the separation
  monitor decides on;
- ``person/poses`` (``geometry_msgs/PoseArray``, one pose per capsule centre) and
  ``person/markers`` (``visualization_msgs/MarkerArray``), at the markers' rate, and
  ``person/truth`` (:class:`~scara_collab.nodes.protocol.PersonTruth`: each arm's true
  separation and margin, whether it moves, a contact) with every scan while the person is in
  the cell (away: once, then once a sim second): ground truth, for the record, viewers and
  tests only;
- ``<robot>/trajectory_clock`` (:class:`~scara_collab.nodes.protocol.TrajectoryClock`) at
  a scan when the clock has changed since it was last said (its lag, its factor, the factor
  asked: with every scan while the arm runs slowed, never while it runs on at full speed):
  each arm's trajectory clock, so every node predicts the arm on it;
- ``safety_joint_states`` (``sensor_msgs/JointState``, every arm's joints: measured positions
  and velocities) and ``planned_velocity`` (``sensor_msgs/JointState``, every arm's joints,
  velocities only: per joint the planned, unscaled velocity of largest size from now to a
  reaction time and a scan period ahead), both with every scan, stamped as the scan and before
  it: what the separation monitor weighs each arm by (what a robot controller's safe interface
  gives a safety controller once a safety cycle; the monitor takes the slower of the two
  decisions, so an arm accelerating from rest is weighed at the speed it is about to reach, a
  braking one at the speed it has). The monitor alone takes them; it takes no
  ``joint_states``.

With ``monitor_link`` ``wired`` (the default) it builds the separation monitor in the bridge's
process (:func:`wired_monitor`) and hands it the safety state, the planned velocity and the
scans instead of sending them to it (published only while another node subscribes), ticks it
at every state step, and takes each factor from it directly (docs/people.md, *The safety
link*). With ``topics`` it takes each arm's speed factor from ``<robot>/speed_scaling``
(``std_msgs/Float64``, transient local: the separation monitor node's). Either way it runs the
arm's trajectories at it
(:meth:`scara_collab.sim.servo.Servo.scale`). With ``speed_scaling`` ``arm`` (the default)
each arm runs at its own factor while the two arms' committed paths cannot meet, whatever the
timing of one against the other, and both at the smaller factor, their clocks in step, while
they could (:meth:`scara_collab.sim.servo.Servo._coupled`): their moves were scheduled
against each other in time, and one factor keeps every such schedule (the arms' 0.10 m
margin) as it was, only slower. With ``cell`` (mirrored mode: the mirror keeps) both arms
always run at the smaller factor. A factor not heard for ``scaling_timeout`` sim s counts as
0 (a silent monitor is a protective stop). An arm whose path-keeping stop cannot keep up with
braking (:attr:`scara_collab.sim.servo.Servo.held_back`) is braked, and while the arms run
together the other arm too. docs/people.md, *One factor or one per arm*, has the measurements
behind the default.
"""
import math
from typing import Callable, Dict, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseArray
import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState, LaserScan
from std_msgs.msg import Float64
from visualization_msgs.msg import MarkerArray

from scara_collab.core import ssm
from scara_collab.core.model import CellModel
from scara_collab.core.scan_tracking import scanners_from_config
from scara_collab.graph import MONITOR_LINKS
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.params import flatten
from scara_collab.nodes.qos import EVENTS, LATCHED
from scara_collab.nodes.separation_monitor import SeparationMonitorNode
from scara_collab.sim.cell_sim import CellSim
from scara_collab.sim.person import arm_link_names, BodyModel, PersonSim
from scara_collab.sim.person_scenarios import Motion, PersonPath, scenario
from scara_collab.sim.scanner import SafetyScanner

#: how the arms' factors are applied (:attr:`scara_collab.sim.servo.Servo.coupling`): each
#: arm its own while their paths stay apart (the default), or one for both
SCALING_MODES = ('arm', 'cell')
#: m beyond an arm's largest protective separation its truth is a bound, not exact (so that the
#: least margin a run reports is exact below this)
FAR_SLACK = 1.0
#: rad/s | m/s: an arm with a joint faster than this moves (the truth's "while it moved")
MOVING = 1e-3
#: sim s: the truth of a person away is said once, then at least this often
HEARTBEAT = 1.0
#: s (and factor): an arm's clock is said again when its lag or factors change by more (the
#: trajectory time runs by sums of steps, so a lag at full speed moves by ulps now and then)
LAG_TOLERANCE = 1e-9


def _close(a: Tuple[float, ...], b: Tuple[float, ...]) -> bool:
    """Return True if two clocks as said differ by at most :data:`LAG_TOLERANCE` each.

    In plain floats (25 times a sim second per arm): ``np.allclose`` with ``rtol`` 0, without
    its array set-up.
    """
    return all(x == y or abs(x - y) <= LAG_TOLERANCE for x, y in zip(a, b))


class BridgePeople:
    """The person, the scanner and the speed scaling of the bridge (module docstring).

    :param node: the bridge; :param cell: the cell model; :param sim: the simulator.
    :param cfg: the ``people`` config; :param spec: the scenario; :param seed: its seed.
    :param rates: Hz of sim time: ``state``, ``markers``.
    :param hold: ``hold(robot, reason)`` brakes an arm and reports it held.
    :param mode: one of :data:`SCALING_MODES`; :param timeout: sim s a factor stays valid.
    :param link: one of :data:`MONITOR_LINKS`; :param profile: the cell's profile (the wired
        monitor's).
    :ivar monitor: the wired separation monitor (None: a node of its own, over topics).
    """

    def __init__(self, node: Node, cell: CellModel, sim: CellSim, cfg: dict, spec: str,
                 seed: int, rates: Dict[str, float], hold: Callable[[str, str], None],
                 mode: str = 'arm', timeout: float = 0.05, link: str = 'wired',
                 profile: str = ''):
        """Put the person and the scanners in the world; create the topics."""
        if mode not in SCALING_MODES:
            raise ValueError(f'speed_scaling must be one of {SCALING_MODES}, got {mode!r}')
        if link not in MONITOR_LINKS:
            raise ValueError(f'monitor_link must be one of {MONITOR_LINKS}, got {link!r}')
        self.node, self.cell, self.sim, self.hold = node, cell, sim, hold
        self.mode, self.timeout = mode, float(timeout)
        sim.servo.coupling = mode
        sim.servo.stop_allowance = float(cfg['monitor']['stop_allowance'])
        self.scenario = scenario(spec, cell, cfg, seed)
        if self.scenario is None:
            raise ValueError(f'person {spec!r} names no scenario')
        self.body = BodyModel.from_config(cfg)
        self.person = PersonSim(sim.client, self.body, PersonPath(self.scenario,
                                                                  Motion.from_config(cfg)),
                                sim.body, arm_link_names(sim.client, sim.body, cell.arms))
        self.scanner = SafetyScanner.from_config(sim.client, cfg)
        self.geometry = scanners_from_config(cfg)
        self.params = ssm.SsmParams.from_config(cfg)
        #: m: an arm's true protective separation is at most this (its truth beyond: bounds)
        self.far = {a.name: ssm.true_separation_bound(a, self.params) for a in cell.arms}
        self.rate = float(cfg['scanner']['rate'])
        #: s ahead an arm's planned speed is said for: the reaction time and a scan period
        self.horizon = self.params.reaction_time + 1.0 / self.rate
        self.rates = rates
        self.names = [n for a in cell.arms for n in a.joint_names]
        self.scan_pub = node.create_publisher(LaserScan, 'safety_scanner/scan', 10)
        self.poses_pub = node.create_publisher(PoseArray, 'person/poses', 10)
        self.markers_pub = node.create_publisher(MarkerArray, 'person/markers', 10)
        self.truth_pub = node.create_publisher(DiagnosticStatus, 'person/truth', 10)
        self.clock_pub = {a.name: node.create_publisher(DiagnosticStatus,
                                                        f'{a.name}/trajectory_clock', EVENTS)
                          for a in cell.arms}
        self.safety_pub = node.create_publisher(JointState, 'safety_joint_states', 10)
        self.planned_pub = node.create_publisher(JointState, 'planned_velocity', 10)
        #: each arm's factor as heard, and when (sim s; None: never)
        self.asked: Dict[str, float] = {a.name: 0.0 for a in cell.arms}
        self.heard: Dict[str, Optional[float]] = {a.name: None for a in cell.arms}
        self.monitor: Optional[SeparationMonitorNode] = None
        #: the wired monitor's inputs, each guarded as a subscription's callback is: a monitor
        #: that raises is logged, its factors time out and the arms stop; the bridge lives on
        self._hand: Dict[str, Callable[[object], None]] = {}
        if link == 'wired':
            self.monitor = wired_monitor(node, cfg, profile, self.take_factor)
            self._hand = {k: guarded(self.monitor, getattr(self.monitor, f'take_{k}'))
                          for k in ('scan', 'state', 'planned')}
        else:
            for a in cell.arms:
                node.create_subscription(Float64, f'{a.name}/speed_scaling', guarded(
                    node, lambda msg, r=a.name: self.take_factor(r, msg.data)), LATCHED)
        self.started = sim.time
        self._said: Dict[str, tuple] = {}  # the clock each arm was last said to run at
        self._truth_said: Optional[Tuple[float, bool]] = None  # (when, present) last said
        self._poses_said: Optional[Tuple[float, bool]] = None  # likewise the poses, markers
        node.get_logger().info(
            f'a person in the cell: {self.scenario.name}, {len(self.geometry)} safety scanners '
            f'at {self.rate:g} Hz, speed scaling per {mode}, the separation monitor '
            f'{"in this process" if self.monitor else "a node of its own"}')

    # --- inputs -----------------------------------------------------------------------------
    def take_factor(self, robot: str, value: float) -> None:
        """Take the factor the separation monitor allows ``robot`` now (clipped to [0, 1])."""
        value = float(value)
        if not math.isfinite(value):
            self.node.get_logger().warning(f'{robot}: speed_scaling {value}: taken as 0',
                                           throttle_duration_sec=5.0)
            value = 0.0
        self.asked[robot] = min(max(value, 0.0), 1.0)
        self.heard[robot] = self.sim.time

    def factor(self, robot: str) -> float:
        """Return the factor ``robot`` may run at now: as heard, 0 once not heard for a while."""
        heard = self.heard[robot]
        if heard is None:  # none yet: allowed for the first timeout, as the monitor starts
            return 1.0 if self.sim.time - self.started <= self.timeout else 0.0
        return self.asked[robot] if self.sim.time - heard <= self.timeout + 1e-9 else 0.0

    # --- every publication step -----------------------------------------------------------
    def step(self) -> None:
        """Pose the person for now, apply the factors, brake an arm that cannot keep up."""
        self.person.update(self.sim.time)
        factors = {r: self.factor(r) for r in self.asked}
        if self.mode == 'cell':
            low = min(factors.values())
            factors = {r: low for r in factors}
        for robot, f in factors.items():
            self.sim.servo.scale(robot, f)
        late = list(self.sim.servo.held_back)
        if late:
            braked = set(self.asked) if self.sim.servo.coupled else set(late)
            for robot in sorted(braked):
                self.hold(robot, 'protective stop: its path-keeping slowdown fell behind '
                          f'braking ({", ".join(late)}): braked')
            for robot in late:
                self._say_clock(robot, held_back=True)
            self.sim.servo.held_back = []

    def scan(self) -> None:
        """Publish the arms' safety state, the clocks and the truth; then the scans.

        Wired, the monitor is handed each scan and state, and they are published only while
        a node subscribes to them (a viewer, a test: the monitor is no subscriber).
        """
        t = self.sim.time
        self.state()  # the arms' state of the instant before its scans: observed with them
        for geometry, ranges in zip(self.geometry, self.scanner.scan()):
            self._send(self.scan_pub, 'scan',
                       lambda g=geometry, r=ranges: conv.laser_scan(g, r, t, 1.0 / self.rate))

    def _send(self, pub, kind: str, build: Callable[[], object]) -> None:
        """Publish ``build()`` on ``pub`` (wired: only for a listener); wired, hand it over."""
        msg = None
        if self.monitor is None or pub.get_subscription_count():
            msg = build()
            pub.publish(msg)
        if self.monitor is not None:
            self._hand[kind](msg if msg is not None else build())

    def tick(self) -> None:
        """Let the wired monitor decide at this instant (after the scans and states of it)."""
        self.monitor.tick(int(round(self.sim.time * 1e9)))

    def ground_truth(self) -> None:
        """Publish the person's capsules as poses and markers (ground truth).

        While the person is away: once when they leave (empty poses, the markers deleted),
        then once a sim second, as the truth.
        """
        t = self.sim.time
        poses = self.person.poses()
        said = self._poses_said
        if not len(poses) and said is not None and not said[1] and t - said[0] < HEARTBEAT - 1e-9:
            return
        self._poses_said = (t, bool(len(poses)))
        self.poses_pub.publish(conv.pose_array(poses, t))
        self.markers_pub.publish(conv.capsule_markers(poses, self.body.lengths[:len(poses)],
                                                      self.body.radii[:len(poses)], t))

    def state(self) -> None:
        """Publish the arms' safety state and planned velocity, every arm's clock, and the truth.

        An arm's clock is said when it has changed since it was last said.
        """
        t = self.sim.time
        _, q, qd, _ = self.sim.joint_state()
        q, qd = q.reshape(-1, 3), qd.reshape(-1, 3)
        ahead = []
        for arm in self.cell.arms:
            said = self._said.get(arm.name)
            if said is None or not _close(self._clock_of(arm.name), said):
                self._say_clock(arm.name)
            ahead.append(self.sim.servo.planned_ahead(arm.name, t, self.horizon))
        self._send(self.safety_pub, 'state',
                   lambda: conv.joint_state(t, self.names, q.ravel(), qd.ravel(), ()))
        self._send(self.planned_pub, 'planned',
                   lambda: conv.joint_velocities(t, self.names, np.concatenate(ahead)))
        truth = self._truth(t, q, qd)
        said = self._truth_said
        if truth.present or said is None or said[1] or t - said[0] >= HEARTBEAT - 1e-9:
            self._truth_said = (t, truth.present)  # away: said once, then once a sim second
            self.truth_pub.publish(truth.to_msg())

    def _clock_of(self, robot: str) -> Tuple[float, float, float]:
        """Return ``robot``'s clock as it is said: its lag, its factor and the factor asked."""
        servo = self.sim.servo
        return (float(self.sim.motion[robot].lag), servo.speed(robot),
                float(servo.factors[robot]))

    def _say_clock(self, robot: str, held_back: bool = False) -> None:
        """Publish ``robot``'s trajectory clock now."""
        servo, arm = self.sim.servo, self.cell.arm(robot)
        said = self._said[robot] = self._clock_of(robot)
        planned = servo.planned[servo.names.index(robot)]
        self.clock_pub[robot].publish(proto.TrajectoryClock(
            robot, round(self.sim.time, 6), *said,
            dict(zip(arm.joint_names, (float(v) for v in planned))), held_back).to_msg())

    def _truth(self, t: float, q: np.ndarray, qd: np.ndarray) -> proto.PersonTruth:
        caps = self.person.capsules()
        arms = self.cell.arms
        moving = {a.name: bool(np.max(np.abs(qd[k])) > MOVING) for k, a in enumerate(arms)}
        if caps is None:
            return proto.PersonTruth(round(t, 6), False, {a.name: math.inf for a in arms},
                                     {a.name: math.inf for a in arms}, moving,
                                     {a.name: False for a in arms})
        touching = {a.name for c in self.person.contacts() for a in arms
                    if c.link.startswith(a.name + '_')}
        separation, margin = {}, {}
        for k, arm in enumerate(arms):
            reach = arm.l1 + arm.l2 + arm.link_radius
            floor = float(np.min(np.hypot(*(caps.start[:, :2] - arm.base[:2, 3]).T))) - reach
            if floor > self.far[arm.name] + FAR_SLACK:  # nothing near: lower bounds
                separation[arm.name] = floor
                margin[arm.name] = floor - self.far[arm.name]
                continue
            separation[arm.name], margin[arm.name] = ssm.true_margin(
                arm, q[k], qd[k], caps.start, caps.end, caps.radius, self.params)
        return proto.PersonTruth(round(t, 6), True, separation, margin, moving,
                                 {a.name: a.name in touching for a in arms})


def wired_monitor(node: Node, cfg: dict, profile: str,
                  on_factor: Callable[[str, float], None]) -> SeparationMonitorNode:
    """Build the separation monitor in ``node``'s process, wired to the bridge.

    It is a node of its own (``separation_monitor``, in the bridge's namespace: its status,
    diagnostics, markers and factors on their topics, its parameters), configured with the
    bridge's ``people`` config and profile, off sim time (the bridge hands it its time).
    """
    overrides = [Parameter(k, value=v) for k, v in flatten(cfg).items()]
    overrides += [Parameter('profile', value=profile), Parameter('use_sim_time', value=False)]
    return SeparationMonitorNode(wired=on_factor, context=node.context,
                                 namespace=node.get_namespace(),
                                 parameter_overrides=overrides)
