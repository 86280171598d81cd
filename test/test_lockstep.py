"""Lockstep: the bridge holds sim time while a participant computes, and never hangs on one.

The bridge spins in the test's thread; a participant node spins in its own executor thread and
blocks in one of its ``/clock`` callbacks, the way a planner blocks while it plans.
"""
import threading
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Graph, params_args
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Header

from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes.pybullet_bridge import PyBulletBridge


class Busy:
    """A participant that, once sim time passes ``after``, computes for ``seconds`` (wall)."""

    def __init__(self, g: Graph, after: float, seconds: float):
        """Join ``g``'s lockstep on sim time and spin in a thread; work once past ``after``."""
        self.node = Node('busy', context=g.context,
                         parameter_overrides=[Parameter('use_sim_time', value=True)])
        self.part = lockstep.join(self.node)
        self.after, self.seconds = after, seconds
        self.window = None  # (sim time of the clock that started the work, bridge time at end)
        self.working = False  # set as the work starts
        self.bridge = g.bridge
        self.node.create_subscription(Clock, '/clock', self._on_clock, 1)
        self.executor = SingleThreadedExecutor(context=g.context)
        self.executor.add_node(self.node)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        while not self.stop.is_set():
            self.executor.spin_once(timeout_sec=0.01)

    def _on_clock(self, msg: Clock) -> None:
        t = conv.to_sec(msg.clock)
        if self.window is None and t >= self.after:
            self.working = True
            time.sleep(self.seconds)
            self.window = (t, self.bridge.sim.time)

    def close(self) -> None:
        """Stop the spinning thread and destroy the node."""
        self.stop.set()
        self.thread.join(5.0)
        self.executor.shutdown()
        self.node.destroy_node()


def make_graph(window: float, timeout: float = 5.0) -> Graph:
    """Return a graph with an unthrottled bridge of this lockstep ``window`` and ``timeout``."""
    g = Graph()
    g.bridge = g.add(PyBulletBridge(context=g.context, cli_args=params_args(
        'simulation', 'controllers', overrides={
            'real_time_factor': 0.0, 'feed_interval': 0.0, 'lockstep_window': window,
            'lockstep_timeout': timeout})))
    return g


@pytest.mark.parametrize('window', [0.02, 0.0])
def test_sim_time_waits_for_a_busy_participant(window):
    """With a window sim time waits for a busy participant; without one it runs on."""
    g = make_graph(window)
    busy = Busy(g, after=0.3, seconds=0.6)
    try:
        assert g.spin_until(lambda: busy.window is not None, 30.0)
        t_clock, t_after = busy.window
        advance = t_after - t_clock
        if window > 0:
            # at most the window beyond its last answer (which was at most one clock earlier)
            assert advance <= window + 0.0105, advance
        else:  # no gate: physics ran on unthrottled while the node was busy
            assert advance > 0.2, advance
        assert g.spin_until(lambda: g.bridge.sim.time > t_after + 0.3, 20.0), 'sim went on'
        if window > 0:
            assert g.bridge.gate.waited.get('/busy', 0.0) > 0.4, g.bridge.gate.summary()
    finally:
        busy.close()
        g.close()


def test_a_silent_participant_is_dropped_and_rejoins():
    """A participant silent beyond the timeout is dropped, and rejoins when it answers."""
    g = make_graph(0.02, timeout=0.3)
    busy = Busy(g, after=0.2, seconds=1.5)
    try:
        assert g.spin_until(lambda: '/busy' in g.bridge.gate.dropped, 20.0)
        t_dropped = g.bridge.sim.time
        assert g.spin_until(lambda: g.bridge.sim.time > t_dropped + 0.2, 10.0)
        assert busy.window is None, 'the bridge went on while the node was still busy'
        assert g.spin_until(lambda: busy.window is not None, 20.0)
        assert g.spin_until(lambda: '/busy' in g.bridge.gate.reached, 10.0), 'rejoined'
        assert '/busy' not in g.bridge.gate.dropped
    finally:
        busy.close()
        g.close()


def test_a_leaving_participant_is_no_longer_waited_for():
    """A participant that leaves the lockstep frees the clock without a timeout."""
    g = make_graph(0.02, timeout=30.0)
    busy = Busy(g, after=1e9, seconds=0.0)  # never busy
    try:
        assert g.spin_until(lambda: '/busy' in g.bridge.gate.reached, 20.0)
        busy.stop.set()
        busy.thread.join(5.0)
        busy.part.leave()
        assert g.spin_until(lambda: '/busy' not in g.bridge.gate.reached, 10.0)
        t = g.bridge.sim.time
        # the participant no longer spins; with a 30 s timeout only its leaving frees the clock
        assert g.spin_until(lambda: g.bridge.sim.time > t + 0.5, 10.0)
    finally:
        busy.close()
        g.close()


def test_nodes_on_wall_time_or_opted_out_do_not_join():
    """Nodes on wall time, or with ``lockstep`` false, do not join."""
    g = Graph()
    try:
        wall = Node('wall', context=g.context)
        out = Node('out', context=g.context, parameter_overrides=[
            Parameter('use_sim_time', value=True), Parameter('lockstep', value=False)])
        assert lockstep.join(wall) is None and lockstep.join(out) is None
        wall.destroy_node()
        out.destroy_node()
    finally:
        g.close()


@pytest.mark.parametrize('overrides, reason', [
    ({'lockstep_window': 0.005}, 'clock could never advance'),  # shorter than /clock's period
    ({'pause_at': -1.0}, 'pause_at must be a sim time >= 0 s'),
])
def test_a_bad_lockstep_or_pause_setting_is_refused_at_start(overrides, reason):
    """A window shorter than the clock period, or a pause_at that is not a sim time: refused."""
    g = Graph()
    try:
        with pytest.raises(ValueError, match=reason):
            PyBulletBridge(context=g.context, cli_args=params_args(
                'simulation', 'controllers', overrides=overrides))
    finally:
        g.close()


# --- the gate's decisions, on a fake wall clock ----------------------------------------------
class Wall:
    """A wall clock the test sets by hand."""

    def __init__(self):
        """Start at wall time 0."""
        self.now = 0.0

    def __call__(self) -> float:
        """Return the wall time the test set."""
        return self.now


@pytest.fixture
def bare():
    """Yield a graph with a plain node standing in for the bridge."""
    g = Graph()
    g.node = g.add(Node('bridge_stand_in', context=g.context))
    yield g
    g.close()


def answer(gate, name: str, t: float) -> None:
    """Hand ``gate`` the lockstep answer of participant ``name`` at sim time ``t``."""
    gate.receive(Header(stamp=conv.to_time(t), frame_id=name))


def test_one_frozen_participant_is_dropped_and_the_others_are_not(bare):
    """No cascade: while sim time waits for one node, nobody else's answers can be new.

    The others' last answers are as old as the frozen one's when it is dropped; what counts
    is how long each one has held sim time back, and they start to only when the bridge
    steps on to their window.
    """
    wall = Wall()
    gate = lockstep.LockstepGate(bare.node, 0.02, 5.0, wall_clock=wall)
    for name in ('/frozen', '/b', '/c'):
        answer(gate, name, 1.00)
    assert gate.limit(1.00) == pytest.approx(1.02)
    wall.now = 0.001                 # the bridge stepped to 1.02; b and c answer, frozen not
    answer(gate, '/b', 1.02)
    answer(gate, '/c', 1.02)
    assert gate.limit(1.02) == pytest.approx(1.02)
    wall.now = 4.9
    assert gate.limit(1.02) == pytest.approx(1.02) and not gate.dropped
    wall.now = 5.1
    assert gate.limit(1.02) == pytest.approx(1.04)
    assert set(gate.dropped) == {'/frozen'} and gate.dropped['/frozen'] == 1.02
    wall.now = 5.101                 # stepped to 1.04 before b's and c's answers arrived
    assert gate.limit(1.04) == pytest.approx(1.04)
    assert set(gate.reached) == {'/b', '/c'}, 'their answers are 5.1 s old, yet they answer'
    wall.now = 5.11
    answer(gate, '/b', 1.04)
    answer(gate, '/c', 1.04)
    assert gate.limit(1.04) == pytest.approx(1.06)
    answer(gate, '/frozen', 1.04)    # thawed: it joins again
    assert '/frozen' in gate.reached and not gate.dropped
    assert gate.waited['/frozen'] == pytest.approx(5.1 - 0.0, abs=0.01)
    assert gate.waited['/b'] == pytest.approx(0.009, abs=1e-6)


def test_per_node_timeouts_override_the_default(bare):
    """Per-node timeouts drop each participant after its own wall seconds."""
    wall = Wall()
    timeouts = lockstep.parse_timeouts(['slow:20', '', '/quick:0.5'])
    assert timeouts == {'/slow': 20.0, '/quick': 0.5}
    gate = lockstep.LockstepGate(bare.node, 0.02, 5.0, timeouts=timeouts, wall_clock=wall)
    for name in ('/slow', '/quick', '/default'):
        answer(gate, name, 1.00)
    gate.limit(1.02)                 # all three hold sim time back from now on
    wall.now = 0.6
    gate.limit(1.02)
    assert set(gate.dropped) == {'/quick'}
    wall.now = 5.1
    gate.limit(1.02)
    assert set(gate.dropped) == {'/quick', '/default'}
    wall.now = 19.9
    assert gate.limit(1.02) == pytest.approx(1.02)
    wall.now = 20.1
    assert gate.limit(1.02) == float('inf')
    assert set(gate.dropped) == {'/quick', '/default', '/slow'}


@pytest.mark.parametrize('entry', ['monitor', 'monitor:0', ':2.0', 'monitor:soon', 'm:-1'])
def test_a_malformed_timeout_is_refused(entry):
    """A timeout entry without a name, or not a number > 0, is refused."""
    with pytest.raises(ValueError, match='expected <node>:<seconds > 0>'):
        lockstep.parse_timeouts([entry])


def test_a_guard_holds_the_arms_before_it_is_dropped_and_clears_when_it_answers(bare):
    """A silent guard holds the arms before it is dropped, and clears when it answers.

    A plain participant's drop raises no guard event; a guard that leaves holds the arms.
    """
    wall = Wall()
    events = []

    def on_guard(name, present, why):
        events.append((name, present, why, name in gate.reached))

    gate = lockstep.LockstepGate(bare.node, 0.02, 1.0, guards=['collision_monitor'],
                                 on_guard=on_guard, wall_clock=wall)
    answer(gate, '/collision_monitor', 1.00)
    answer(gate, '/planner', 1.02)
    gate.limit(1.02)
    wall.now = 1.5
    assert gate.limit(1.02) == pytest.approx(1.04)
    assert len(events) == 1
    name, present, why, still_waited_for = events[0]
    assert (name, present, still_waited_for) == ('/collision_monitor', False, True)
    assert why.startswith('silent for 1.5 s')
    assert gate.absent == {'/collision_monitor': why}
    wall.now = 1.6                   # the planner holds sim time back from now on
    gate.limit(1.04)
    wall.now = 9.0                   # a plain participant dropped: no guard event
    gate.limit(1.04)
    assert set(gate.dropped) == {'/collision_monitor', '/planner'} and len(events) == 1
    answer(gate, '/collision_monitor', 1.04)
    assert events[-1][:3] == ('/collision_monitor', True, 'answers again')
    assert not gate.absent
    gate.receive(Header(stamp=lockstep.END_OF_TIME, frame_id='/collision_monitor'))
    assert events[-1][:3] == ('/collision_monitor', False, 'left the lockstep')
    assert gate.absent


def test_expected_participants_hold_sim_time_from_the_start(bare):
    """``expect``: sim time waits for the named nodes before their first answer.

    One that never answers is dropped after its timeout, like any silent participant.
    """
    wall = Wall()
    gate = lockstep.LockstepGate(bare.node, 0.02, 5.0, wall_clock=wall,
                                 expect=['planner', '/monitor'])
    assert set(gate.reached) == {'/planner', '/monitor'}
    assert gate.limit(0.0) == pytest.approx(0.02)    # one window, then their first answers
    assert gate.limit(0.02) == pytest.approx(0.02)
    answer(gate, '/planner', 0.02)
    assert gate.limit(0.02) == pytest.approx(0.02), 'the monitor has not answered yet'
    wall.now = 5.1
    assert gate.limit(0.02) == pytest.approx(0.04) and set(gate.dropped) == {'/monitor'}


def test_without_a_window_a_guard_far_behind_sim_time_holds_the_arms(bare):
    """Lockstep off (window 0): nobody is waited for, but a guard is still watched.

    A guard more than its timeout behind sim time (sim s: the time the arms moved unwatched)
    holds the arms; wall time alone (a paused bridge) does not; an answer that brings it back
    within its timeout clears them, an old one does not. The others' answers are not kept.
    """
    wall = Wall()
    events = []
    gate = lockstep.LockstepGate(bare.node, 0.0, 1.0, guards=['collision_monitor'],
                                 on_guard=lambda *e: events.append(e), wall_clock=wall,
                                 expect=['collision_monitor', 'planner'])
    assert not gate.enabled and gate.reached == {'/collision_monitor': 0.0}
    assert gate.limit(0.5) == float('inf')
    answer(gate, '/planner', 0.5)
    answer(gate, '/collision_monitor', 0.5)
    assert gate.reached == {'/collision_monitor': 0.5}
    assert gate.limit(1.45) == float('inf') and not events      # 0.95 s behind
    wall.now = 100.0                                            # paused: no sim s passed
    assert gate.limit(1.45) == float('inf') and not events
    assert gate.limit(1.55) == float('inf')                     # 1.05 s behind: hold
    assert [e[:2] for e in events] == [('/collision_monitor', False)]
    assert events[0][2].startswith('silent for 1.1 s (sim)')
    assert '/collision_monitor' in gate.absent
    gate.limit(3.0)                                             # held once, not again
    answer(gate, '/collision_monitor', 1.9)                     # still 1.1 s behind
    assert len(events) == 1 and gate.absent
    answer(gate, '/collision_monitor', 2.99)
    assert events[-1] == ('/collision_monitor', True, 'answers again') and not gate.absent
    gate.receive(Header(stamp=lockstep.END_OF_TIME, frame_id='/collision_monitor'))
    assert events[-1][:3] == ('/collision_monitor', False, 'left the lockstep')
    silent = lockstep.LockstepGate(bare.node, 0.0, 1.0, guards=['/collision_monitor'],
                                   on_guard=lambda *e: events.append(e),
                                   expect=['/collision_monitor'])
    silent.limit(1.01)                                          # expected, never answered
    assert '/collision_monitor' in silent.absent


def test_without_a_window_the_bridge_holds_the_arms_for_a_guard_left_behind():
    """The bridge with ``lockstep_window`` 0 steps on, and holds the arms for a lagging guard.

    The guard computes for 1.5 s wall while the unthrottled clock runs on: more than its
    0.3 s timeout behind, the arms are held and moves refused; once it answers, cleared.
    """
    g = Graph()
    g.bridge = g.add(PyBulletBridge(context=g.context, cli_args=params_args(
        'simulation', 'controllers', overrides={
            'real_time_factor': 0.0, 'feed_interval': 0.0, 'lockstep_window': 0.0,
            'lockstep_timeouts': ['/busy:0.3'], 'lockstep_guards': ['/busy']})))
    busy = Busy(g, after=0.2, seconds=1.5)
    try:
        # unthrottled, the clock may pass the timeout before the guard's first answer: that
        # absence ends with its first answer; the one that counts comes while it works
        assert g.spin_until(lambda: busy.working and '/busy' in g.bridge.gate.absent, 20.0)
        assert 'no move until it answers again' in g.bridge.holds.blocked()
        assert busy.window is None, 'held while the guard was still busy'
        # (an answer sent before the work may still clear it meanwhile: it was within the timeout)
        assert g.spin_until(lambda: busy.window is not None and not g.bridge.gate.absent,
                            20.0), 'cleared once the guard answers again'
        assert busy.window is not None and busy.window[1] - busy.window[0] > 0.3
        assert not g.bridge.gate.waited, 'the bridge never waited'
    finally:
        busy.close()
        g.close()


def test_unthrottled_the_answer_steps_the_bridge_in_its_own_callback():
    """Unthrottled, the answer that completes a round steps the bridge, in its callback.

    One window per round of answers; no timer thread decides when.
    """
    g = Graph()
    try:
        g.bridge = g.add(PyBulletBridge(context=g.context, cli_args=params_args(
            'simulation', 'controllers', overrides={
                'real_time_factor': 0.0, 'feed_interval': 0.0, 'lockstep_window': 0.02,
                'lockstep_expect': ['/stand_in']})))
        gate = g.bridge.gate
        assert g.spin_until(lambda: g.bridge._parked, 10.0)
        assert g.bridge.sim.time == pytest.approx(0.02)  # one window, then it waits
        for _ in range(50):
            g.executor.spin_once(timeout_sec=0.005)
        assert g.bridge.sim.time == pytest.approx(0.02), 'no step without the answer'
        for k in range(1, 4):  # each answer moves the limit one window: stepped at once
            answer(gate, '/stand_in', 0.02 * k)
            assert g.bridge.sim.time == pytest.approx(0.02 * (k + 1))
            assert g.bridge._parked
    finally:
        g.close()


def test_started_paused_the_bridge_steps_only_after_resume():
    """``paused``: the bridge starts at sim time 0 and stays there until ``/sim/resume``."""
    from std_srvs.srv import Trigger
    g = Graph()
    try:
        g.bridge = g.add(PyBulletBridge(context=g.context, cli_args=params_args(
            'simulation', 'controllers', overrides={
                'real_time_factor': 0.0, 'feed_interval': 0.0, 'paused': True})))
        for _ in range(50):
            g.executor.spin_once(timeout_sec=0.005)
        assert g.bridge.sim.time == 0.0 and g.bridge.control.paused
        res = g.call(Trigger, '/sim/resume', Trigger.Request())
        assert res.success and 'resumed at sim t=0.000 s' in res.message, res.message
        assert g.spin_until(lambda: g.bridge.sim.time > 0.5, 20.0)
    finally:
        g.close()


@pytest.mark.parametrize('pause_at', [0.5, 0.207])
def test_pause_at_stops_the_clock_exactly_there(pause_at):
    """``pause_at``: the bridge pauses by itself at that sim time, and a resume runs on.

    Its clock and state are published there, even off their periods' grid (0.207 s).
    """
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger
    g = Graph()
    try:
        clocks, states = g.collect(Clock, '/clock', 50), g.collect(JointState, '/joint_states', 50)
        g.bridge = g.add(PyBulletBridge(context=g.context, cli_args=params_args(
            'simulation', 'controllers', overrides={
                'real_time_factor': 0.0, 'feed_interval': 0.0, 'pause_at': pause_at})))
        assert g.spin_until(lambda: g.bridge.control.paused, 20.0)
        assert g.bridge.sim.time == pytest.approx(pause_at, abs=1e-9)
        assert g.spin_until(lambda: clocks and conv.to_sec(clocks[-1].clock) >= pause_at - 1e-9)
        assert g.spin_until(lambda: states and conv.to_sec(states[-1].header.stamp)
                            >= pause_at - 1e-9)
        for _ in range(20):
            g.executor.spin_once(timeout_sec=0.005)
        assert g.bridge.sim.time == pytest.approx(pause_at, abs=1e-9), 'it stays paused'
        assert g.call(Trigger, '/sim/resume', Trigger.Request()).success
        assert g.spin_until(lambda: g.bridge.sim.time > pause_at + 0.2, 20.0)
    finally:
        g.close()


def test_the_graph_names_exactly_the_nodes_that_answer():
    """``graph.NodeSpec.lockstep`` matches the nodes that join the lockstep on sim time.

    The bridge and the launcher expect the nodes it names; a node that joined unnamed would
    not be waited for from the start.
    """
    from scara_collab import graph
    g = Graph()
    try:
        for spec in graph.job_nodes():
            g.add(spec.build(context=g.context, cli_args=params_args(*spec.configs)))
        expected = sorted(graph.lockstep_expect(graph.job_nodes()))

        def answering():
            return sorted(i.node_name for i in g.probe.get_publishers_info_by_topic(
                graph.resolve(lockstep.TOPIC)))
        assert g.spin_until(lambda: answering() == expected, 10.0), answering()
    finally:
        g.close()


def test_an_awaited_reply_holds_sim_time_until_it_comes_or_its_deadline():
    """A participant awaiting a reply does not answer: the bridge waits one window past it.

    The reply releases the answer (sim time goes on); a reply that never comes is given up
    after its wall deadline, with the answer owed sent then.
    """
    g = make_graph(0.02)
    try:
        node = g.add(Node('asker', context=g.context,
                          parameter_overrides=[Parameter('use_sim_time', value=True)]))
        part = lockstep.join(node)
        assert g.spin_until(lambda: g.bridge.sim.time >= 0.1, 10.0)
        part.await_reply('offer 1')
        assert g.spin_until(lambda: part.owed, 5.0)  # the next /clock came: answer held
        held_at = g.bridge.sim.time
        for _ in range(50):
            g.executor.spin_once(timeout_sec=0.005)
        assert g.bridge.sim.time <= held_at + 0.02 + 1e-9, 'stepped past the held answer'
        part.reply('someone else')  # not awaited: still held
        assert part.owed
        part.reply('offer 1')
        assert not part.owed and g.spin_until(lambda: g.bridge.sim.time > held_at + 0.05, 5.0)
        part.await_reply('lost', seconds=0.2)  # never replied: answered after 0.2 s wall
        assert g.spin_until(lambda: part.late == 1 and not part.owed, 5.0)
        t = g.bridge.sim.time
        assert g.spin_until(lambda: g.bridge.sim.time > t + 0.05, 5.0)
    finally:
        g.close()


def test_a_participant_leaves_before_its_context_shuts_down():
    """Closing a context (``shutdown.close``, as the runner does) sends its participants' leave.

    rclpy's own ``Context.on_shutdown`` runs after rcl's shutdown, when nothing can be
    published; the pre-shutdown hook runs before the nodes are destroyed.
    """
    from scara_collab.nodes import shutdown
    g = Graph()
    heard = g.collect(Header, lockstep.TOPIC, lockstep.QOS)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Node('leaver', context=ctx, parameter_overrides=[Parameter('use_sim_time', value=True)])
    try:
        part = lockstep.join(node)
        assert part is not None and not hasattr(node, 'lockstep')
        assert g.spin_until(lambda: part._pub.get_subscription_count() == 1
                            and g.probe.count_publishers('/sim/lockstep') == 1, 10.0)
        shutdown.close(ctx, [node])
        assert part.left and not ctx.ok()
        assert g.spin_until(lambda: any(h.frame_id == '/leaver' for h in heard), 10.0)
        assert heard[-1].stamp.sec == lockstep.END_OF_TIME.sec
    finally:
        rclpy.try_shutdown(context=ctx)
        g.close()


def test_a_planner_answers_once_the_bridge_has_its_move():
    """A planner that sent a move holds its answer until the bridge accepted (or refused) it.

    The trajectory and the answer travel on two topics; an answer that overtook a large
    trajectory let the bridge step on without it (0.47 s of sim time, once, under a heavy
    load). Every move the planner sends is awaited, and the reply is the bridge's status of
    it: when it comes, the bridge has the move.
    """
    from geometry_msgs.msg import PointStamped
    from scara_collab.nodes.planner import Planner
    g = make_graph(0.02)
    try:
        planner = g.add(Planner(robot='scara_left', node_name='left_planner', context=g.context,
                                cli_args=params_args('controllers', overrides={
                                    'use_sim_time': True})))
        part = planner.lockstep
        awaited, replied = [], []
        await_reply, reply = part.await_reply, part.reply

        def spy_await(key, *args):
            awaited.append(key)
            await_reply(key, *args)

        def spy_reply(key):
            if key in part.awaited:
                latest = g.bridge.sim.motion['scara_left'].latest
                replied.append((key, None if latest is None else latest.id))
            reply(key)
        part.await_reply, part.reply = spy_await, spy_reply
        assert g.spin_until(lambda: planner.planner.joints is not None and
                            g.bridge.sim.time > 0.2, 20.0)
        pub = g.probe.create_publisher(PointStamped, 'scara_left/target', 10)
        assert g.spin_until(lambda: pub.get_subscription_count() > 0)
        pub.publish(conv.make_point_stamped([3.0, -1.0, 0.3], 'world', g.bridge.sim.time + 0.5))
        assert g.spin_until(lambda: len(replied) == 1 and not part.awaited, 20.0)
        (kind, move), = awaited
        assert kind == 'move' and move.startswith('scara_left/')
        assert replied == [(('move', move), move)] and part.late == 0
    finally:
        g.close()
