"""The separation monitor node: scans, states and trajectory clocks in, speed factors out.

In-process on sim time: the test publishes ``/clock``, and at each scan instant
``/safety_joint_states``, ``/planned_velocity`` and exact synthetic ``LaserScan`` messages of
the empty cell (its pillars) and of a person's legs, one sim step at a time, each step waited
for with a timeout.
"""
from contextlib import contextmanager

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
import pytest
from rclpy.parameter import Parameter
from ros_harness import Graph, params_args
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, LaserScan
from std_msgs.msg import Float64, Header
from synthetic_scans import legs, pillars, scan_circles
from visualization_msgs.msg import Marker, MarkerArray

from scara_collab import graph
from scara_collab.core.config import ConfigError, load_config
from scara_collab.core.scan_tracking import scanners_from_config
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes.protocol import SeparationStatus
from scara_collab.nodes.qos import LATCHED
from scara_collab.nodes.separation_monitor import SeparationMonitorNode

PERIOD = 1.0 / 25.0  # the scanners' period
TICK = 0.01  # a sim step: a joint state and a decision
LEFT, RIGHT = 'scara_left', 'scara_right'
#: the left arm swings as planned; a person at NEAR slows it (0.74 at this speed), not at rest
SWING = np.array([1.5, -1.0, 0.0])
NEAR = (3.5, -4.0)


class Cell:
    """The monitor node and a probe that plays the bridge: clock, safety states, scans."""

    def __init__(self, cell, **overrides):
        """Build the node on sim time (no lockstep) and wait for the probe's connections."""
        self.cell = cell
        self.g = Graph()
        self.node = self.g.add(SeparationMonitorNode(context=self.g.context, cli_args=params_args(
            'people', overrides={'use_sim_time': 'true', 'lockstep': 'false', **overrides})))
        self.scanners = scanners_from_config(load_config('people'))
        probe = self.g.probe
        self.clock = probe.create_publisher(Clock, '/clock', 10)
        self.states = probe.create_publisher(JointState, '/safety_joint_states', 10)
        self.planned = probe.create_publisher(JointState, '/planned_velocity', 10)
        self.scans = probe.create_publisher(LaserScan, '/safety_scanner/scan', 10)
        self.scaling = {a.name: self.g.collect(Float64, f'/{a.name}/speed_scaling', LATCHED)
                        for a in cell.arms}
        self.status = self.g.collect(DiagnosticStatus, '/separation_monitor/status', 100)
        pubs = [self.clock, self.states, self.planned, self.scans]
        assert self.g.spin_until(lambda: all(p.get_subscription_count() > 0 for p in pubs))
        self.q = {a.name: np.array([0.0, 1.2 if a.name == LEFT else -1.2, 0.1])
                  for a in cell.arms}
        self.qd = {a.name: np.zeros(3) for a in cell.arms}  # measured
        self.ahead = {a.name: np.zeros(3) for a in cell.arms}  # planned ahead
        self.time = 0.0
        self.rng = np.random.default_rng(3)

    def close(self):
        """Tear the graph down."""
        self.g.close()

    def scan(self, geometry, t, circles=(), nan=0):
        """Publish one scanner's scan at ``t``: the pillars and ``circles``, ``nan`` rays NaN."""
        ranges = scan_circles(geometry, pillars(self.cell) + list(circles), 0.01, self.rng)
        ranges[100:100 + nan] = np.nan
        msg = LaserScan(angle_min=geometry.angle_min, angle_max=geometry.angle_min
                        + geometry.angle_increment * (geometry.count - 1),
                        angle_increment=geometry.angle_increment, range_min=geometry.range_min,
                        range_max=geometry.range_max, ranges=ranges.tolist())
        msg.header.stamp = conv.to_time(t)
        msg.header.frame_id = geometry.name
        self.scans.publish(msg)

    def step(self, circles=(), scanners=None, nan=0, state=True, scans_first=False):
        """Advance one sim step: the arms' state and the scans due, then ``/clock``; wait.

        :param scanners: the names of the scanners that scan (default: every one).
        :param state: False: no safety state nor planned velocity at this instant.
        :param scans_first: the scans before the state (as the bridge never sends them).
        """
        t = self.time = round(self.time + TICK, 9)
        due = [g for g in self.scanners if scanners is None or g.name in scanners]
        if abs(t / PERIOD - round(t / PERIOD)) < 1e-6:  # a scan instant
            stamp = int(round(t * 1e9))
            if state and not scans_first:
                self.say_state(t)
            for geometry in due:
                self.scan(geometry, t, circles, nan)
            if due:
                assert self.g.spin_until(lambda: self.node.observed == stamp or (
                    stamp in self.node._groups and sum(r is not None for r in
                                                       self.node._groups[stamp]) == len(due)))
            if state and scans_first:
                self.say_state(t)
        self.clock.publish(Clock(clock=conv.to_time(t)))
        # looked at this instant: decided anew (new scans, a fault), or the last one stands
        assert self.g.spin_until(lambda: self.node.decision is not None
                                 and self.node.checked == pytest.approx(t, abs=1e-9))
        return self.node.decision

    def say_state(self, t, velocities=True):
        """Publish the arms' safety state and planned velocity of ``t``; wait for both."""
        stamp = int(round(t * 1e9))
        names = [j for a in self.cell.arms for j in a.joint_names]
        self.states.publish(conv.joint_state(
            t, names, np.concatenate([self.q[a.name] for a in self.cell.arms]),
            np.concatenate([self.qd[a.name] for a in self.cell.arms]) if velocities else (),
            ()))
        self.planned.publish(conv.joint_velocities(
            t, names, np.concatenate([self.ahead[a.name] for a in self.cell.arms])))
        assert self.g.spin_until(lambda: self.node._history
                                 and self.node._history[-1][0] == stamp
                                 and all(a is None or a[0] == stamp
                                         for a in self.node._ahead.values())
                                 and len(self.node._ahead) == len(self.cell.arms))

    def run(self, seconds, **kwargs):
        """Run ``seconds`` of sim time; return the decisions."""
        return [self.step(**kwargs) for _ in range(int(round(seconds / TICK)))]

    def last(self, robot):
        """Return the last factor ``robot``'s ``speed_scaling`` said (waiting for it)."""
        want = self.node.decision.arm(robot).scale
        assert self.g.spin_until(lambda: self.scaling[robot]
                                 and self.scaling[robot][-1].data == want)
        return self.scaling[robot][-1].data


@pytest.fixture
def sim(cell):
    """Yield the monitor, taught and at full speed in the empty cell."""
    c = Cell(cell)
    c.run(2.0)
    assert c.last(LEFT) == 1.0 and c.last(RIGHT) == 1.0
    yield c
    c.close()


def test_it_holds_the_arms_until_the_empty_cell_is_taught_then_releases_them(cell):
    """Held (0, latched) from the start, taught from the first scans, then full speed."""
    c = Cell(cell)
    try:
        assert c.g.spin_until(lambda: all(c.scaling[r] for r in (LEFT, RIGHT)))
        assert [c.scaling[r][-1].data for r in (LEFT, RIGHT)] == [0.0, 0.0]
        first = c.step()
        assert first.fault in ("the empty cell's contour is not taught", 'scanner_a: no scan yet')
        assert all(a.scale == 0.0 and a.stop for a in first.arms)
        s = [d.arm(LEFT).scale for d in c.run(2.0)]
        assert c.node.monitor.taught and s[-1] == 1.0 and np.all(np.diff(s) >= 0.0)
        assert c.last(LEFT) == 1.0
        st = SeparationStatus.from_msg(c.status[-1])
        assert st.scale == {LEFT: 1.0, RIGHT: 1.0} and not st.fault and st.persons == ()
    finally:
        c.close()


def test_a_person_near_an_arm_slows_it_says_why_and_leaving_restores_it(sim, cell):
    """A person stands near the left arm, which swings as planned: it slows, the right does not.

    At rest the same separation allows full speed. The status names the person and the arm;
    the markers show the person's column and each arm's ring. Gone, the arm is back at full
    speed after the track's hold, the dwell and the rise, and not sooner than the dwell.
    """
    person = legs(*NEAR)
    at_rest = sim.run(0.5, circles=person)[-1]
    assert at_rest.arm(LEFT).scale == 1.0 and len(at_rest.persons) == 1
    sim.ahead[LEFT] = SWING  # planned: weighed at it while it stands still
    markers = sim.g.collect(MarkerArray, '/separation_monitor/markers')
    slowed = sim.run(1.0, circles=person)[-1]
    left = slowed.arm(LEFT)
    assert 0.0 < left.scale < 1.0 and not left.stop
    assert sim.last(LEFT) == left.scale and sim.last(RIGHT) == 1.0
    st = SeparationStatus.from_msg(sim.status[-1])
    assert st.scale[LEFT] == left.scale and st.scale[RIGHT] == 1.0
    assert 'person 1' in st.cause[LEFT] and 'scara_left' in st.cause[LEFT]
    assert 'speed x' in st.cause[LEFT] and st.cause[RIGHT] == ''
    assert st.margin[LEFT] < 0.0 < st.separation[LEFT]
    (seen,) = st.persons
    assert np.hypot(seen.x - NEAR[0], seen.y - NEAR[1]) < 0.1
    assert sim.g.spin_until(lambda: markers)
    shown = {(m.ns, m.type) for m in markers[-1].markers if m.action == Marker.ADD}
    assert ('persons', Marker.CYLINDER) in shown
    assert {(f'{r}/protective_separation', Marker.LINE_STRIP) for r in (LEFT, RIGHT)} <= shown
    ring = next(m for m in markers[-1].markers if m.ns == f'{LEFT}/protective_separation')
    then = next(s for s in map(SeparationStatus.from_msg, sim.status)
                if s.time == pytest.approx(conv.to_sec(ring.header.stamp), abs=1e-9))
    (seen,) = then.persons
    radius = np.hypot(ring.points[0].x - seen.x, ring.points[0].y - seen.y)
    assert radius == pytest.approx(seen.radius + then.separation[LEFT] - then.margin[LEFT],
                                   rel=1e-6)
    # the person leaves
    cfg = load_config('people')['monitor']
    after = [d.arm(LEFT).scale for d in sim.run(4.0)]
    assert all(s < 1.0 for s in after[:int(round(cfg['dwell'] / TICK))])
    full = next(k for k, s in enumerate(after) if s == 1.0) * TICK
    assert full <= cfg['track_hold'] + cfg['dwell'] + 1.0 / cfg['resume_rate'] + 2 * PERIOD
    assert sim.last(LEFT) == 1.0


def test_a_silent_scanner_stops_every_arm_within_two_scan_periods(sim):
    """Scanner b stops: every arm s = 0 within two scan periods of its last scan, named."""
    last_b = sim.time
    assert round(last_b / PERIOD, 6).is_integer()  # the fixture ended on a scan
    decisions = sim.run(0.2, scanners={'scanner_a'})
    zero = next(d for d in decisions if all(a.scale == 0.0 for a in d.arms))
    assert zero.time - last_b <= 2 * PERIOD + 1e-9
    assert zero.fault.startswith('scanner_b: no scan for')
    assert all(a.stop and a.cause == zero.fault for a in zero.arms)
    assert sim.last(LEFT) == 0.0 and sim.last(RIGHT) == 0.0
    st = SeparationStatus.from_msg(sim.status[-1])
    assert st.fault.startswith('scanner_b') and st.scale == {LEFT: 0.0, RIGHT: 0.0}
    arrays = sim.g.collect(DiagnosticArray, '/diagnostics')
    sim.run(1.0, scanners={'scanner_a'})  # the once-a-second /diagnostics says so too
    assert sim.g.spin_until(lambda: arrays)
    assert [(s.name, s.level) for s in arrays[-1].status] == [
        ('separation_monitor', DiagnosticStatus.ERROR)]
    back = [d.arm(LEFT).scale for d in sim.run(2.0)]  # it scans again: the arms resume
    assert back[-1] == 1.0


def test_nan_ranges_stop_every_arm(sim):
    """A scan with NaN rays stops every arm at once, with the reason; good scans resume."""
    bad = sim.run(PERIOD, nan=3)[-1]
    assert bad.fault == 'scanner_a: 3 rays measured nothing usable'
    assert all(a.scale == 0.0 and a.stop for a in bad.arms)
    assert sim.last(LEFT) == 0.0
    assert sim.run(2.0)[-1].arm(LEFT).scale == 1.0


def test_a_scan_it_cannot_place_is_refused(sim, cell):
    """An unknown frame or another scanner's geometry is not observed: the arms stop for it."""
    geometry = sim.scanners[0]
    stranger = LaserScan(angle_increment=geometry.angle_increment, ranges=[1.0] * 5)
    stranger.header.frame_id = 'scanner_x'
    stranger.header.stamp = conv.to_time(sim.time + 0.005)
    wrong = LaserScan(angle_min=geometry.angle_min, angle_increment=geometry.angle_increment,
                      range_min=geometry.range_min, range_max=geometry.range_max,
                      ranges=[1.0] * (geometry.count - 1))
    wrong.header.frame_id = geometry.name
    wrong.header.stamp = stranger.header.stamp
    sim.scans.publish(stranger)
    sim.scans.publish(wrong)
    sim.g.spin_until(lambda: False, timeout=0.3)
    assert not sim.node._groups
    # only such scans from now on: the scanners fall silent
    decisions = sim.run(0.1, scanners=())
    assert decisions[-1].fault.startswith('scanner_a: no scan for')


def test_an_arm_with_a_non_finite_joint_state_stops_alone(sim, cell):
    """A NaN joint of the right arm stops it; the left keeps its speed; a finite state resumes."""
    sim.q[RIGHT] = np.array([np.nan, 0.0, 0.1])
    d = sim.run(0.05)[-1]
    assert d.arm(RIGHT).scale == 0.0 and 'no finite joint state' in d.arm(RIGHT).cause
    assert d.arm(LEFT).scale == 1.0
    sim.q[RIGHT] = np.array([0.0, -1.2, 0.1])
    assert sim.run(2.0)[-1].arm(RIGHT).scale == 1.0


def test_the_scans_of_an_instant_wait_for_the_arms_state_of_that_instant(sim):
    """Scans that come before the arms' state of their instant are observed once it comes."""
    t = round(sim.time + PERIOD, 9)
    stamp = int(round(t * 1e9))
    sim.run(PERIOD - TICK)  # up to the step before the scan instant
    sim.time = t
    for geometry in sim.scanners:
        sim.scan(geometry, t)
    assert sim.g.spin_until(lambda: stamp in sim.node._groups
                            and all(r is not None for r in sim.node._groups[stamp]))
    assert sim.node.observed < stamp  # every scan in, the state not yet
    sim.say_state(t)
    assert sim.node.observed == stamp
    sim.clock.publish(Clock(clock=conv.to_time(t)))
    sim.run(PERIOD - TICK)
    assert sim.step(scans_first=True).arm(LEFT).scale == 1.0  # the next instant likewise
    assert sim.node.observed == int(round(sim.time * 1e9))


def test_an_arm_without_a_recent_state_stops_until_one_comes(sim):
    """No safety state nor planned velocity for longer than a scanner may be silent: stop.

    The scans keep coming; each instant is observed half a period late with the last state
    there is. A state without velocities is refused likewise. Good states again: full speed.
    """
    stale = load_config('people')['monitor']['stale_after']
    decisions = sim.run(2 * PERIOD + stale, state=False)
    assert sim.node.observed >= int(round((sim.time - PERIOD) * 1e9))  # without their state
    last = decisions[-1]
    assert all(last.arm(r).stop and 'no finite joint state' in last.arm(r).cause
               for r in (LEFT, RIGHT))
    assert sim.run(2.0)[-1].arm(LEFT).scale == 1.0
    sim.time = round(sim.time + PERIOD, 9)  # a state without velocities: refused
    sim.say_state(sim.time, velocities=False)
    for geometry in sim.scanners:
        sim.scan(geometry, sim.time)
    sim.clock.publish(Clock(clock=conv.to_time(sim.time)))
    assert sim.g.spin_until(lambda: sim.node.checked == pytest.approx(sim.time, abs=1e-9)
                            and sim.node.decision.arm(LEFT).stop)
    assert sim.run(2.0)[-1].arm(LEFT).scale == 1.0


def test_bad_parameters_are_refused(cell):
    """A people.yaml value out of range or a bad own parameter stops the node with the reason."""
    g = Graph()
    try:
        for overrides, text in (({'monitor.teach_scans': 0}, 'teach_scans'),
                                ({'marker_rate': 0.0}, 'marker_rate')):
            with pytest.raises(ConfigError, match=text):
                SeparationMonitorNode(context=g.context, cli_args=params_args(
                    'people', overrides={'use_sim_time': 'true', **overrides}))
    finally:
        g.close()


def test_the_graph_starts_it_over_topics_and_the_bridge_guards_it():
    """Linked over topics the monitor starts after the bridge and answers lockstep; wired not.

    Wired (the default) the bridge builds it in its own process: no node to start, no guard.
    """
    topics = graph.job_nodes(people=True, monitor_link='topics')
    names = [n.name for n in topics]
    assert 'separation_monitor' in names
    assert names.index('separation_monitor') > names.index('pybullet_bridge')
    assert 'separation_monitor' not in [n.name for n in graph.job_nodes()]
    assert 'separation_monitor' not in [n.name for n in graph.job_nodes(people=True)]
    spec = graph.node('separation_monitor')
    assert spec.node_class() is SeparationMonitorNode and spec.configs == ('people',)
    assert 'separation_monitor' in graph.lockstep_expect(topics)
    assert graph.lockstep_guards(topics) == ['collision_monitor', 'separation_monitor']
    assert graph.lockstep_guards(graph.job_nodes(people=True)) == ['collision_monitor']
    with pytest.raises(ValueError, match='monitor_link'):
        graph.job_nodes(people=True, monitor_link='radio')
    assert graph.topic('separation_monitor/markers').type == 'visualization_msgs/msg/MarkerArray'


def test_in_lockstep_a_scan_instant_decides_on_its_scans_even_when_its_clock_comes_first(cell):
    """The clock of a scan instant overtakes its scans and state: the decision and the answer wait.

    A person stands near the swinging left arm from that instant on. Decided at the clock, the
    monitor would weigh the empty cell of 40 ms before (full speed) and slow the arm a clock
    later; it waits, answers the lockstep only after, and slows the arm at that very instant.
    """
    c = Cell(cell, lockstep='true')
    try:
        answers = c.g.collect(Header, '/sim/lockstep', lockstep.QOS)
        c.run(2.0)
        assert c.last(LEFT) == 1.0
        c.ahead[LEFT] = SWING
        c.run(PERIOD - TICK)  # to the step before the next scan instant
        t = c.time = round(c.time + TICK, 9)
        stamp = int(round(t * 1e9))
        c.clock.publish(Clock(clock=conv.to_time(t)))  # the clock first
        assert c.g.spin_until(lambda: c.node.sync.due is not None)
        c.g.spin_until(lambda: False, timeout=0.3)
        assert c.node.checked < t and c.node.observed < stamp  # waiting, not decided
        assert all(conv.to_sec(a.stamp) < t for a in answers)  # nor answered
        c.say_state(t)
        for geometry in c.scanners[:-1]:
            c.scan(geometry, t, legs(*NEAR))
        c.g.spin_until(lambda: False, timeout=0.3)
        assert c.node.sync.due is not None  # one scanner still to come
        c.scan(c.scanners[-1], t, legs(*NEAR))
        assert c.g.spin_until(lambda: c.node.checked == pytest.approx(t, abs=1e-9))
        assert c.node.observed == stamp and c.node.sync.due is None
        assert c.g.spin_until(lambda: any(conv.to_sec(a.stamp) == pytest.approx(t, abs=1e-9)
                                          for a in answers))
        assert len(c.node.decision.persons) == 1 and c.node.decision.time == pytest.approx(t)
    finally:
        c.close()


@contextmanager
def _bridge_alone(person: str):
    """Yield ``(graph, bridge)``: the bridge alone in one process, ``person`` in its cell.

    Unthrottled, no lockstep; the separation monitor wired into it (the default link).
    """
    from scara_collab.nodes.runner import InProcess
    params = dict(graph.person_params(person, 1)['pybullet_bridge'], real_time_factor='0.0',
                  lockstep_window='0.0')
    spec = graph.node('pybullet_bridge')
    with InProcess() as g:
        yield g, g.add(spec.build(context=g.context,
                                  cli_args=graph.ros_args(spec.configs, params)))


def test_a_wired_monitor_that_fails_stops_the_arms_and_the_bridge_lives_on():
    """Wired into the bridge, a monitor whose decision raises is logged; its factors time out.

    The bridge builds it (a node of its own, off sim time, its clock the bridge's), hands it
    the scans, states its scan instants. Broken, every arm's factor falls to 0 within the
    bridge's ``scaling_timeout`` while the simulation runs on; mended, the factors come back.
    """
    with _bridge_alone('nobody') as (g, bridge):
        people = bridge.people
        monitor = people.monitor
        assert isinstance(monitor, SeparationMonitorNode) and monitor.wired is not None
        assert monitor.get_namespace() == bridge.get_namespace()
        assert not monitor.get_parameter('use_sim_time').value
        assert not monitor.get_subscriptions_info_by_topic('/safety_scanner/scan')

        def run_until(t):
            while bridge.sim.time < t:
                g.spin_once(timeout_sec=0.01)
        run_until(1.0)
        # its clock is the bridge's sim time at its last look: a scan instant at the latest
        assert monitor.get_clock().now().nanoseconds == pytest.approx(bridge.sim.time * 1e9,
                                                                      abs=4e7)
        assert {r: people.factor(r) for r in people.asked} == {LEFT: 1.0, RIGHT: 1.0}
        decide = monitor.monitor.decide

        def broken(*args, **kwargs):
            raise RuntimeError('a bug in the decision')
        monitor.monitor.decide = broken
        run_until(1.2)
        assert {r: people.factor(r) for r in people.asked} == {LEFT: 0.0, RIGHT: 0.0}
        monitor.monitor.decide = decide
        run_until(3.0)
        assert {r: people.factor(r) for r in people.asked} == {LEFT: 1.0, RIGHT: 1.0}
        with pytest.raises(ValueError, match='use_sim_time false'):  # two clocks: refused
            SeparationMonitorNode(wired=lambda robot, factor: None, context=g.context,
                                  parameter_overrides=[Parameter('use_sim_time', value=True)])


def _wired_decisions(look_every_tick: bool, until: float = 11.0):
    """Run the bridge alone with a person (``middle``) and return every factor it was handed.

    Each as ``(sim s, robot, factor, cause)``. Scanner b says nothing from 9.0 to 9.3 s (a
    silent scanner: every arm stops; its scans again: they resume). ``look_every_tick``: the
    monitor looks at every tick, as it did before it skipped the ticks with nothing to look at.
    """
    with _bridge_alone('middle') as (g, bridge):
        people, monitor = bridge.people, bridge.people.monitor
        handed = []
        take = monitor.wired

        def wired(robot, factor):
            handed.append((round(bridge.sim.time, 6), robot, factor,
                           monitor.decision.arm(robot).cause))
            take(robot, factor)
        monitor.wired = wired
        if look_every_tick:
            monitor._next_look = lambda now_ns: now_ns + 1
        scan = people.scanner.scan

        def silent_b():
            ranges = scan()
            return ranges[:1] if 9.0 <= bridge.sim.time < 9.3 else ranges
        people.scanner.scan = silent_b
        while bridge.sim.time < until:
            g.spin_once(timeout_sec=0.01)
    return handed


def test_a_wired_monitor_skips_only_the_ticks_with_nothing_to_decide():
    """Skipping the ticks at which nothing can change decides exactly as looking at every one.

    A person comes near the (resting) arms and a scanner falls silent for 0.3 s: the factors,
    their causes and the instants they are handed at are the same to the bit.
    """
    skipping, every_tick = _wired_decisions(False), _wired_decisions(True)
    assert skipping == every_tick
    causes = {cause for _, _, _, cause in skipping}
    assert any('scanner_b: no scan for' in c for c in causes)  # the silence was decided on
    assert any('protective stop' in c for c in causes)  # and the person near them
