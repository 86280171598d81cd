"""The bridge node in-process: clock, joint states, trajectory execution, refusals, e-stop."""
from types import SimpleNamespace

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_harness import Graph, params_args
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Header
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from scara_collab.core.trajectory import joint_move
from scara_collab.nodes import conversions as conv, lockstep
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.pybullet_bridge import PyBulletBridge

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)


def bridge_graph(**overrides) -> Graph:
    """Return a graph with an unthrottled bridge (``overrides``: more of its parameters)."""
    g = Graph()
    g.bridge = g.add(PyBulletBridge(context=g.context, cli_args=params_args(
        'simulation', 'controllers',
        overrides={'real_time_factor': 0.0, 'feed_interval': 0.0, **overrides})))
    return g


@pytest.fixture
def graph():
    """Yield a graph with an unthrottled bridge, its states and statuses collected."""
    g = bridge_graph()
    g.states = g.collect(JointState, '/joint_states')
    g.status = {a.name: g.collect(DiagnosticStatus, f'/{a.name}/execution_status')
                for a in g.bridge.cell.arms}
    yield g
    g.close()


def sim_time(g):
    """Return the bridge's sim time, s."""
    return g.bridge.sim.time


def left_q(g):
    """Return the leader's joints from the newest collected joint state."""
    names, pos = g.states[-1].name, g.states[-1].position
    arm = g.bridge.cell.leader
    return np.array([pos[list(names).index(n)] for n in arm.joint_names])


def test_clock_and_joint_states_in_sim_time(graph):
    """/clock and /joint_states run on sim time: six joints, stamps 10 ms apart."""
    clocks = graph.collect(Clock, '/clock')
    assert graph.spin_until(lambda: len(graph.states) >= 30 and len(clocks) >= 10)
    names = list(graph.states[-1].name)
    assert len(names) == 6 and set(names) == {
        n for a in graph.bridge.cell.arms for n in a.joint_names}
    stamps = np.array([conv.to_sec(m.header.stamp) for m in graph.states])
    assert np.all(np.diff(stamps) > 0)
    assert np.allclose(np.diff(stamps)[1:], 0.01, atol=1e-6), 'state_rate is 100 Hz sim time'
    ticks = [conv.to_sec(c.clock) for c in clocks]
    assert ticks == sorted(ticks) and ticks[-1] > ticks[0]
    for m in graph.states[-3:]:
        assert len(m.position) == len(m.velocity) == len(m.effort) == 6


def test_a_trajectory_is_tracked(graph):
    """A raw joint trajectory is accepted (no id) and tracked within 5 mrad / 5 mm."""
    arm = graph.bridge.cell.leader
    assert graph.spin_until(lambda: len(graph.states) > 5)
    q0 = left_q(graph)
    goal = q0 + np.array([0.4, -0.3, 0.2])
    traj = joint_move(arm, q0, goal)
    pub = graph.probe.create_publisher(JointTrajectory, f'/{arm.name}/joint_trajectory', 10)
    assert graph.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(conv.trajectory_msg(arm.joint_names, traj.t, traj.q, traj.qd, traj.qdd))
    assert graph.spin_until(lambda: any(s.level == DiagnosticStatus.OK
                                        for s in graph.status[arm.name]))
    accepted = proto.ExecutionStatus.from_msg(graph.status[arm.name][-1])
    assert accepted.state == 'accepted' and accepted.move == ''  # a raw trajectory: no id
    start = accepted.start
    end = start + traj.duration + 0.5
    assert graph.spin_until(lambda: sim_time(graph) > end, timeout=60)
    errors = []
    for m in graph.states:
        t = conv.to_sec(m.header.stamp) - start
        if 0 <= t <= traj.duration:
            q = np.array([m.position[list(m.name).index(n)] for n in arm.joint_names])
            errors.append(np.abs(q - traj.sample(t)).max())
    assert errors, 'joint states were received during the move'
    print(f'\nbridge tracking: max joint error {max(errors) * 1e3:.3f} mrad/mm during a '
          f'{traj.duration:.2f} s joint move')
    assert max(errors) < 5e-3
    np.testing.assert_allclose(left_q(graph), goal, atol=1e-3)


@pytest.mark.parametrize('mutate, reason', [
    (lambda m: setattr(m, 'joint_names', ['a', 'b', 'c']), 'do not match'),
    (lambda m: m.points[1].time_from_start.__setattr__('sec', 0), 'strictly increasing'),
    (lambda m: setattr(m.points[1], 'positions', [0.1, 0.2]), 'positions'),
    (lambda m: m.points[1].positions.__setitem__(0, float('nan')), 'non-finite'),
    (lambda m: m.points[1].positions.__setitem__(0, 3.0), 'limit'),
])
def test_bad_trajectories_are_refused_and_nothing_moves(graph, mutate, reason):
    """Each malformed or out-of-limits trajectory is refused; the arm does not move."""
    arm = graph.bridge.cell.leader
    assert graph.spin_until(lambda: len(graph.states) > 5)
    q0 = left_q(graph)
    t = np.array([0.5, 1.0, 1.5])
    msg = conv.trajectory_msg(arm.joint_names, t, np.stack([q0, q0 + 0.05, q0 + 0.1]))
    mutate(msg)
    pub = graph.probe.create_publisher(JointTrajectory, f'/{arm.name}/joint_trajectory', 10)
    assert graph.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(msg)
    assert graph.spin_until(lambda: any(s.level == DiagnosticStatus.ERROR
                                        for s in graph.status[arm.name]))
    err = [s for s in graph.status[arm.name] if s.level == DiagnosticStatus.ERROR][-1]
    assert reason in err.message and 'not executed' in err.message
    later = sim_time(graph) + 2.0
    assert graph.spin_until(lambda: sim_time(graph) > later, timeout=60)
    np.testing.assert_allclose(left_q(graph), q0, atol=1e-4)


def test_emergency_stop_holds_both_arms(graph):
    """Under the e-stop a trajectory is refused and the arm holds its pose."""
    arm = graph.bridge.cell.leader
    assert graph.spin_until(lambda: len(graph.states) > 5)
    q0 = left_q(graph)
    estop = graph.probe.create_publisher(Bool, '/emergency_stop', LATCHED)
    estop.publish(Bool(data=True))
    assert graph.spin_until(lambda: any('emergency stop' in s.message
                                        for s in graph.status[arm.name]))
    traj = joint_move(arm, q0, q0 + np.array([0.5, 0.0, 0.0]))
    pub = graph.probe.create_publisher(JointTrajectory, f'/{arm.name}/joint_trajectory', 10)
    assert graph.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(conv.trajectory_msg(arm.joint_names, traj.t, traj.q, traj.qd))
    later = sim_time(graph) + traj.duration + 0.5
    assert graph.spin_until(lambda: sim_time(graph) > later, timeout=60)
    np.testing.assert_allclose(left_q(graph), q0, atol=1e-4)
    assert graph.status[arm.name][-1].level == DiagnosticStatus.ERROR


def test_gripper_refuses_with_nothing_to_grasp_and_items_are_published(graph):
    """A grasp with nothing under the tool is refused; a release while empty succeeds.

    Spawned items are published on /conveyor/items.
    """
    res = graph.call(SetBool, '/scara_left/gripper', SetBool.Request(data=True))
    assert not res.success and res.message
    res = graph.call(SetBool, '/scara_left/gripper', SetBool.Request(data=False))
    assert res.success and 'holds nothing' in res.message  # idempotent: release while empty
    items = graph.collect(MarkerArray, '/conveyor/items')
    graph.bridge.sim.conveyor.spawn_item()
    classes = set(graph.bridge.cell.item_classes)
    assert graph.spin_until(lambda: any(m.ns in classes for a in items for m in a.markers))


def test_item_markers_read_back(cell):
    """Item markers and planned paths read back to the ids, classes, stamps and points."""
    items = [SimpleNamespace(id=3, cls=cell.item_classes[0], position=np.array([1.0, 0.1, 0.3])),
             SimpleNamespace(id=7, cls=cell.item_classes[1], position=np.array([2.0, -0.2, 0.3]))]
    back = conv.item_positions(conv.item_markers(items, cell.item_classes, cell.item_size, 4.5))
    assert sorted(back) == [3, 7]
    for it in items:
        cls, xyz, stamp = back[it.id]
        assert cls == it.cls and stamp == pytest.approx(4.5)
        np.testing.assert_allclose(xyz, it.position)
    line = np.array([[1.0, 0.0, 0.4], [2.0, 0.5, 0.3]])
    np.testing.assert_allclose(conv.path_points(conv.path_msg(line, 1.0)), line)


def test_lockstep_guard_silent_holds_both_arms_and_refuses_moves_until_it_answers():
    """A guard that stops answering: the arms are held before it is dropped, moves refused.

    The probe answers on /sim/lockstep as the guard ``/guard`` (every 5 ms wall, with the
    bridge's sim time) while ``alive``; the left arm is in the middle of a long move when it
    falls silent.
    """
    g = bridge_graph(lockstep_timeout=0.5, lockstep_guards="['/guard']")
    try:
        g.states = g.collect(JointState, '/joint_states')
        status = {a.name: g.collect(DiagnosticStatus, f'/{a.name}/execution_status')
                  for a in g.bridge.cell.arms}
        answers = g.probe.create_publisher(Header, lockstep.TOPIC, lockstep.QOS)
        guard = SimpleNamespace(alive=True)

        def answer():
            if guard.alive:
                answers.publish(Header(stamp=conv.to_time(sim_time(g)), frame_id='/guard'))

        g.probe.create_timer(0.005, answer)
        assert g.spin_until(lambda: '/guard' in g.bridge.gate.reached and len(g.states) > 5)
        arm = g.bridge.cell.leader
        traj_pub = g.probe.create_publisher(JointTrajectory, f'/{arm.name}/joint_trajectory', 10)
        assert g.spin_until(lambda: traj_pub.get_subscription_count() > 0)

        def send_move(dq):
            q0 = left_q(g)
            traj = joint_move(arm, q0, q0 + np.asarray(dq))
            traj_pub.publish(conv.trajectory_msg(arm.joint_names, traj.t, traj.q, traj.qd))
            return q0 + np.asarray(dq)

        def last(robot, state):
            msgs = [proto.ExecutionStatus.from_msg(m) for m in status[robot]]
            return next((s for s in reversed(msgs) if s.state == state), None)

        goal = send_move([1.2, -1.0, 0.0])
        assert g.spin_until(lambda: last(arm.name, 'accepted') is not None)
        moving = last(arm.name, 'accepted').start + 0.3
        assert g.spin_until(lambda: sim_time(g) > moving, timeout=60)
        guard.alive = False
        assert g.spin_until(lambda: all(last(a.name, 'held') for a in g.bridge.cell.arms))
        held = last(arm.name, 'held')
        assert '/guard silent for' in held.reason and held.reason.endswith('holding')
        assert '/guard' in g.bridge.gate.dropped and g.bridge.gate.absent
        later = held.time + 1.5
        assert g.spin_until(lambda: sim_time(g) > later, timeout=60), 'sim time goes on'
        after = np.array([[m.position[list(m.name).index(n)] for n in arm.joint_names]
                          for m in g.states if conv.to_sec(m.header.stamp) > held.time + 0.5])
        assert len(after) > 50 and np.ptp(after, axis=0).max() < 1e-3, 'the arm stands'
        assert np.abs(after[-1] - goal).max() > 0.3, 'the move was stopped, not finished'
        send_move([0.0, 0.0, 0.2])
        assert g.spin_until(lambda: last(arm.name, 'refused') is not None)
        assert 'no move until it answers again' in last(arm.name, 'refused').reason
        guard.alive = True
        assert g.spin_until(lambda: all(last(a.name, 'cleared') for a in g.bridge.cell.arms))
        assert not g.bridge.gate.absent
        n_accepted = sum(1 for m in status[arm.name] if 'accepted' in m.message)
        send_move([0.0, 0.0, 0.2])
        assert g.spin_until(lambda: sum(1 for m in status[arm.name]
                                        if 'accepted' in m.message) > n_accepted)
    finally:
        g.close()


def test_pause_step_resume_and_reset_control_the_simulation(graph):
    """Paused, sim time stands still; each step advances exactly ``sim_step_count`` steps.

    Resume runs it again; reset refuses while an arm moves (a move would be lost) and then puts
    both arms back at home, at rest. Every service is idempotent and says the sim time.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from std_srvs.srv import Trigger
    bridge, arm = graph.bridge, graph.bridge.cell.leader
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics')
    assert graph.spin_until(lambda: sim_time(graph) > 1.2 and diagnostics)
    first = proto.SimStatus.from_msg(diagnostics[0].status[0])
    assert diagnostics[0].status[0].level == DiagnosticStatus.OK and not first.paused
    res = graph.call(Trigger, '/sim/pause', Trigger.Request())
    assert res.success and res.message.startswith('paused at sim t=')
    assert graph.spin_until(lambda: proto.SimStatus.from_msg(diagnostics[-1].status[0]).paused)
    assert diagnostics[-1].status[0].level == DiagnosticStatus.WARN  # on /diagnostics too
    t0 = sim_time(graph)
    graph.spin_until(lambda: False, timeout=0.5)  # let the executor run: no step may happen
    assert sim_time(graph) == t0
    assert graph.call(Trigger, '/sim/pause', Trigger.Request()).message.startswith(
        'already paused')
    n = bridge.get_parameter('sim_step_count').value
    for k in range(1, 4):
        res = graph.call(Trigger, '/sim/step', Trigger.Request())
        assert res.success, res.message
        assert sim_time(graph) == pytest.approx(t0 + k * n * bridge.dt, abs=1e-12)
    assert res.message == f'advanced {n} physics steps to sim t={sim_time(graph):.3f} s'
    # a move asked for while paused waits; reset refuses while it is there to run
    q0 = bridge.sim.arm_state(arm.name)[0]
    traj = joint_move(arm, q0, q0 + np.array([0.3, 0.0, 0.0]))
    bridge.sim.execute(arm.name, sim_time(graph) + traj.t, traj.q, traj.qd, traj.qdd)
    res = graph.call(Trigger, '/sim/reset', Trigger.Request())
    assert not res.success and f'{arm.name} is executing a move' in res.message
    assert graph.call(Trigger, '/sim/resume', Trigger.Request()).success
    assert graph.spin_until(lambda: sim_time(graph) > t0 + traj.duration + 0.3, timeout=60)
    assert graph.call(Trigger, '/sim/resume', Trigger.Request()).message.startswith(
        'already running')
    res = graph.call(Trigger, '/sim/reset', Trigger.Request())
    assert res.success, res.message
    for a in bridge.cell.arms:
        q, qd = bridge.sim.arm_state(a.name)
        np.testing.assert_allclose(q, bridge.home[a.name], atol=1e-9)
        np.testing.assert_allclose(qd, 0.0, atol=1e-9)
    res = graph.call(Trigger, '/sim/step', Trigger.Request())
    assert not res.success and 'pause first' in res.message


def test_a_bad_sim_step_count_is_refused_at_start():
    """``sim_step_count`` below 1 stops the bridge with the reason."""
    g = Graph()
    try:
        with pytest.raises(ValueError, match='sim_step_count must be an integer >= 1'):
            bad = {'real_time_factor': 0.0, 'feed_interval': 0.0, 'sim_step_count': 0}
            PyBulletBridge(context=g.context,
                           cli_args=params_args('simulation', 'controllers', overrides=bad))
        # the refused node is gone (it kept a later bridge's test from seeing the graph empty)
        g.spin_until(lambda: False, timeout=1.0)
        assert 'pybullet_bridge' not in {n for n, _ in g.probe.get_node_names_and_namespaces()}
    finally:
        g.close()


def test_a_participant_that_hears_the_clock_late_still_hears_the_time_it_is_waited_for():
    """The bridge waits for an expected participant; the time is said again while it waits.

    A participant whose ``/clock`` subscription matches after the clock was published (DDS
    discovery on a busy machine) would wait for a clock that never comes and be dropped as
    silent: the bridge publishes the same time again every 0.25 s wall while it waits.
    """
    g = bridge_graph(lockstep_timeout=30.0, lockstep_expect="['/late']")
    try:
        assert g.spin_until(lambda: g.bridge._parked, timeout=10)  # waits for /late
        waited_at = sim_time(g)
        late = g.collect(Clock, '/clock')  # subscribes only now
        assert g.spin_until(lambda: late, timeout=5), 'the time is said again'
        assert conv.to_sec(late[-1].clock) == pytest.approx(waited_at)
        answers = g.probe.create_publisher(Header, lockstep.TOPIC, lockstep.QOS)
        answers.publish(Header(stamp=late[-1].clock, frame_id='/late'))
        assert g.spin_until(lambda: sim_time(g) > waited_at), 'its answer steps sim time on'
    finally:
        g.close()
