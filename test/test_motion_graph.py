"""The motion graph in-process on sim time: mirroring, straight lines, yielding, bad input."""
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_harness import Graph
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core.kinematics import fk
from scara_collab.core.mirror import mirror_point
from scara_collab.core.trajectory import segment_deviation
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import protocol as proto

SIM = {'use_sim_time': 'true'}
#: rad/s or m/s: braked and held
AT_REST_CHECK = 2e-2
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)


def motion_graph(**bridge):
    """Return the motion graph on sim time, its topics collected.

    The bridge (``bridge``: more of its parameters), both planners, the replication manager
    and the monitor, once both planners have a state.
    """
    g = Graph()
    g.bridge = g.add_node_of('pybullet_bridge', real_time_factor=0.0, feed_interval=0.0,
                             **bridge, **SIM)
    names = ('left_planner', 'right_planner', 'replication_manager', 'collision_monitor')
    g.left, g.right, g.replicator, g.monitor = (g.add_node_of(n, **SIM) for n in names)
    g.states = g.collect(JointState, '/joint_states')
    g.status = {n: g.collect(DiagnosticStatus, f'/{n}/planner_status')
                for n in ('scara_left', 'scara_right')}
    g.trajs = {n: g.collect(JointTrajectory, f'/{n}/joint_trajectory')
               for n in ('scara_left', 'scara_right')}
    g.distance = g.collect(Float64, '/collision_monitor/min_distance')
    g.estop = g.collect(Bool, '/emergency_stop', LATCHED)
    assert g.spin_until(lambda: g.left.planner.joints is not None
                        and g.right.planner.joints is not None
                        and conv.now(g.left) > 0.1 and conv.now(g.right) > 0.1)
    return g


@pytest.fixture
def cell():
    """Yield the motion graph (:func:`motion_graph`)."""
    g = motion_graph()
    yield g
    g.close()


def publish(g, topic, xyz, frame='world', stamp=0.0):
    """Publish one target point on ``topic`` from the probe once a node subscribes."""
    pub = g.probe.create_publisher(PointStamped, topic, 10)
    assert g.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(conv.make_point_stamped(xyz, frame, stamp))


def run_until(g, t):
    """Spin until the simulator has passed sim time ``t`` (at most 120 s wall)."""
    assert g.spin_until(lambda: g.bridge.sim.time > t, timeout=120)


def tool_paths(g, t0=0.0):
    """Return the recorded states' stamps from ``t0`` on and both arms' tool tips."""
    left, right = g.bridge.cell.arms
    t, ql, qr = [], [], []
    for m in g.states:
        ts = conv.to_sec(m.header.stamp)
        if ts >= t0:
            t.append(ts)
            ql.append(conv.joint_state_arrays(m, left.joint_names)[0])
            qr.append(conv.joint_state_arrays(m, right.joint_names)[0])
    return np.array(t), fk(left, np.array(ql)), fk(right, np.array(qr))


def last_end(g, robot):
    """Return the end time of ``robot``'s last planned move."""
    planned = [st for st in map(proto.PlannerStatus.from_msg, g.status[robot])
               if st.state == 'planned']
    return planned[-1].end


def test_collab_target_moves_both_arms_mirrored_and_straight(cell):
    """A collab target moves both arms mirrored and the leader straight.

    Both trajectories carry the same start stamp; the follower's mirror error and the leader's
    line deviation stay within 1 mm, and the margin holds.
    """
    left, right = cell.bridge.cell.arms
    p0 = fk(left, cell.left.planner.joints)
    target = np.array([2.7, -0.7, 0.4])
    publish(cell, '/collab/target', target)
    assert cell.spin_until(lambda: all(cell.status[n] for n in cell.status))
    for n in cell.status:
        assert cell.status[n][-1].level == DiagnosticStatus.OK, cell.status[n][-1].message
    run_until(cell, max(last_end(cell, n) for n in cell.status) + 0.3)
    # both trajectories carry the same start stamp: zero lag by construction ...
    stamps = [conv.to_sec(cell.trajs[n][-1].header.stamp) for n in cell.trajs]
    assert stamps[0] == stamps[1] > 0
    # ... and measured: the follower's tool is the mirror of the leader's throughout
    t, pl, pr = tool_paths(cell)
    err = np.linalg.norm(pr - mirror_point(left, right, pl), axis=1)
    dev = segment_deviation(pl, p0, target)
    moving = np.linalg.norm(pl - p0, axis=1) > 1e-4
    onset = t[np.argmax(moving)]
    print(f'\nmirror error max {err.max() * 1e3:.3f} mm, leader line deviation '
          f'{dev.max() * 1e3:.3f} mm, start stamps {stamps}, onset {onset:.3f} s')
    assert err.max() <= 1e-3
    assert dev.max() <= 1e-3
    np.testing.assert_allclose(pl[-1], target, atol=1e-3)
    np.testing.assert_allclose(pr[-1], mirror_point(left, right, target), atol=1e-3)
    assert min(m.data for m in cell.distance) >= cell.bridge.cell.safety_margin
    assert not any(m.data for m in cell.estop)


def test_meeting_on_the_belt_centre_line_makes_the_right_arm_wait(cell):
    """Arms meeting on the belt centre line: the right arm waits until the left one leaves.

    It then goes, delayed, to its target; the margin holds and no e-stop is raised.
    """
    margin = cell.bridge.cell.safety_margin
    publish(cell, '/collab/target', [2.6, -0.03, 0.4])  # mirrors to (2.6, 0.03): they'd meet
    assert cell.spin_until(lambda: cell.status['scara_right'] and cell.status['scara_left'])
    assert cell.spin_until(lambda: any('waiting' in s.message
                                       for s in cell.status['scara_right']))
    assert cell.status['scara_left'][-1].level == DiagnosticStatus.OK  # the leader goes
    run_until(cell, last_end(cell, 'scara_left') + 0.2)
    publish(cell, '/scara_left/target', [3.3, -1.2, 0.6])  # the leader leaves the belt
    assert cell.spin_until(lambda: any(s.level == DiagnosticStatus.WARN and 'delayed' in
                                       s.message for s in cell.status['scara_right']))
    run_until(cell, last_end(cell, 'scara_right') + 0.3)
    right = cell.bridge.cell.follower
    np.testing.assert_allclose(fk(right, cell.right.planner.joints), [2.6, 0.03, 0.4], atol=1e-3)
    low = min(m.data for m in cell.distance)
    print(f'\ncentre-line meeting: right arm waited, then '
          f'{cell.status["scara_right"][-1].message}; min separation {low:.3f} m')
    assert low >= margin
    assert not any(m.data for m in cell.estop)


@pytest.mark.parametrize('xyz, frame, reason', [
    ([float('nan'), -1.0, 0.4], 'world', 'non-finite'),
    ([9.0, -2.0, 0.4], 'world', 'outer reach'),
    ([2.0, -2.0, 0.4], 'world', 'inner reach'),
    ([3.0, -1.0, 1.5], 'world', 'quill travel'),
    ([-0.3, -2.0, 0.4], 'world', 'joint limit'),
    ([3.0, -1.0, 0.4], 'map', 'unknown frame'),
])
def test_bad_targets_are_refused_and_nothing_moves(cell, xyz, frame, reason):
    """Each bad target is refused with its reason, and the arm does not move."""
    q0 = cell.left.planner.joints.copy()
    publish(cell, '/scara_left/target', xyz, frame)
    assert cell.spin_until(lambda: cell.status['scara_left'])
    last = cell.status['scara_left'][-1]
    assert last.level == DiagnosticStatus.ERROR and reason in last.message, last.message
    run_until(cell, cell.bridge.sim.time + 1.0)
    np.testing.assert_allclose(cell.left.planner.joints, q0, atol=1e-4)
    assert not cell.trajs['scara_left']


def listens_to_states(node) -> bool:
    """Return True if ``node`` subscribes ``/joint_states``."""
    return any(t == '/joint_states' for t, _ in node.get_subscriber_names_and_types_by_node(
        node.get_name(), node.get_namespace()))


def test_base_frame_targets_and_mirroring_off(cell):
    """A base-frame target reaches its world point; mirroring off leaves the follower.

    While off the manager does not take /joint_states; enabled again, it measures again.
    """
    left = cell.bridge.cell.leader
    assert listens_to_states(cell.replicator)
    res = cell.call(SetBool, '/replication_manager/enable', SetBool.Request(data=False))
    assert res.success
    # off, it has nothing to measure: it does not take /joint_states (the cost of a message)
    assert not listens_to_states(cell.replicator) and cell.replicator.error is None
    q_right = cell.right.planner.joints.copy()
    publish(cell, '/collab/target', [0.8, 1.3, 0.2], frame='scara_left_base')
    assert cell.spin_until(lambda: cell.status['scara_left'])
    run_until(cell, last_end(cell, 'scara_left') + 0.3)
    np.testing.assert_allclose(fk(left, cell.left.planner.joints),
                               left.base_position + [0.8, 1.3, 0.2],
                               atol=1e-3)
    np.testing.assert_allclose(cell.right.planner.joints, q_right, atol=1e-4)
    assert not cell.status['scara_right']
    assert cell.replicator.error is None  # no mirror error measured while off
    assert cell.call(SetBool, '/replication_manager/enable', SetBool.Request(data=True)).success
    assert listens_to_states(cell.replicator)
    assert cell.spin_until(lambda: cell.replicator.error is not None)


def _raw_crossing(g):
    """Park the left arm on the belt; return the right arm's raw move straight through it."""
    from scara_collab.core.kinematics import ik
    from scara_collab.core.trajectory import joint_move

    right = g.bridge.cell.follower
    publish(g, '/scara_left/target', [1.8, -0.2, 0.4])  # the left arm waits on the belt
    assert g.spin_until(lambda: g.status['scara_left'])
    run_until(g, last_end(g, 'scara_left') + 0.2)
    q0 = g.right.planner.joints.copy()
    return q0, joint_move(right, q0, ik(right, [1.8, -0.2, 0.4], q_current=q0).unwrap())


def _send_raw(g, move, move_id):
    """Publish ``move`` raw on the right arm's trajectory topic; return its statuses (a list)."""
    right = g.bridge.cell.follower
    executions = g.collect(DiagnosticStatus, f'/{right.name}/execution_status')
    g.raw = g.probe.create_publisher(JointTrajectory, f'/{right.name}/joint_trajectory', 10)
    g.raw.publish(conv.trajectory_msg(right.joint_names, move.t, move.q, move.qd, move.qdd,
                                      frame_id=move_id))
    return executions


def _execution(g, executions, move):
    assert g.spin_until(lambda: any(proto.ExecutionStatus.from_msg(m).move == move
                                    for m in executions))
    return next(st for st in map(proto.ExecutionStatus.from_msg, executions) if st.move == move)


def test_a_raw_crossing_trajectory_is_refused_at_the_door(cell):
    """A right-arm trajectory straight through the left arm, bypassing the planners.

    The bridge judges it against the left arm's committed motion and refuses it with the
    reason: the right arm does not move, no stop is needed, the margin is never approached.
    """
    q0, through = _raw_crossing(cell)
    st = _execution(cell, _send_raw(cell, through, 'raw/1'), 'raw/1')
    assert st.state == 'refused' and 'within 0.11 m of scara_left' in st.reason, st.reason
    run_until(cell, cell.bridge.sim.time + 1.0)
    np.testing.assert_allclose(cell.bridge.sim.arm_state('scara_right')[0], q0, atol=2e-3)
    assert not cell.monitor.stopped
    assert cell.monitor.stops.counts == {'protective': 0, 'emergency': 0}


@pytest.fixture
def open_door():
    """Yield the motion graph with the bridge's admission check off: the monitor alone."""
    g = motion_graph(admission_allowance=-1.0)
    yield g
    g.close()


def test_the_monitor_stops_a_crossing_the_door_let_through_and_resumes(open_door):
    """With the admission check off, the monitor is the second line, and it holds alone.

    It follows what the bridge runs and stops the arms protectively while they are still
    apart (the bridge brakes at the acceleration limits): the margin is never broken. Braked,
    at rest and apart, the stop ends by itself. Under an emergency stop only a move that
    parts the arms is run; then a clear releases it.
    """
    from std_srvs.srv import Trigger

    g = open_door
    margin = g.bridge.cell.safety_margin
    right = g.bridge.cell.follower
    q0, through = _raw_crossing(g)
    executions = _send_raw(g, through, 'raw/1')
    raw = g.raw
    assert g.spin_until(lambda: g.monitor.stopped, timeout=60)
    assert g.monitor.stops.kind == 'protective' and g.monitor.stops.reason.startswith('predicted')
    assert g.spin_until(lambda: not g.monitor.stopped, timeout=60)  # released by itself
    low = min(m.data for m in g.distance)
    print(f'\nraw crossing move, door open: min separation {low:.3f} m')
    assert low >= margin and g.monitor.status().minimum >= margin
    assert np.abs(g.bridge.sim.arm_state('scara_right')[1]).max() < AT_REST_CHECK
    assert g.monitor.stops.counts == {'protective': 1, 'emergency': 0}

    estop = g.probe.create_publisher(Bool, '/emergency_stop', LATCHED)
    estop.publish(Bool(data=True))
    assert g.spin_until(lambda: g.bridge.sim.estop and g.monitor.stops.kind == 'emergency')
    q = g.right.planner.joints.copy()
    from scara_collab.core.trajectory import joint_move
    closer = joint_move(right, q, q + 0.3 * (through.q[-1] - q))  # towards the left arm
    raw.publish(conv.trajectory_msg(right.joint_names, closer.t, closer.q, frame_id='raw/2'))
    refused = _execution(g, executions, 'raw/2')
    assert refused.state == 'refused' and 'away from the other' in refused.reason
    back = joint_move(right, q, q0)  # where it came from: away from the left arm
    raw.publish(conv.trajectory_msg(right.joint_names, back.t, back.q, frame_id='raw/3'))
    assert _execution(g, executions, 'raw/3').state == 'accepted'
    run_until(g, g.bridge.sim.time + back.duration + 0.3)
    res = g.call(Trigger, '/collision_monitor/clear', Trigger.Request())
    assert res.success, res.message
    assert g.spin_until(lambda: not g.bridge.sim.estop)
    assert min(m.data for m in g.distance) >= margin


def test_a_nan_state_then_a_target_leaves_the_planner_planning(cell):
    """A NaN /joint_states once killed the left planner at its next target; now it is refused.

    The monitor fails closed on it (it cannot check a NaN state), the planner keeps its last
    good state and plans the next target from it.
    """
    left = cell.bridge.cell.leader
    pub = cell.probe.create_publisher(JointState, '/joint_states', 10)
    names = [n for arm in cell.bridge.cell.arms for n in arm.joint_names]
    q_before = cell.left.planner.joints.copy()
    stamp = cell.bridge.sim.time + 0.005  # in order and on the clock: only the values are bad
    pub.publish(conv.joint_state(stamp, names, [float('nan')] * 6, [0.0] * 6, [0.0] * 6))
    assert cell.spin_until(lambda: cell.monitor.stopped)
    assert 'unusable joint state' in cell.monitor.stops.reason
    assert np.all(np.isfinite(cell.left.planner.joints))
    np.testing.assert_allclose(cell.left.planner.joints, q_before, atol=1e-3)
    publish(cell, '/scara_left/target', [2.4, -0.6, 0.5])
    assert cell.spin_until(lambda: cell.status['scara_left'])
    st = proto.PlannerStatus.from_msg(cell.status['scara_left'][-1])
    assert st.state in ('planned', 'refused'), st
    assert 'nan' not in st.reason.lower()
    assert np.all(np.isfinite(fk(left, cell.left.planner.joints)))


def offer(g, robot, traj, request_s):
    """Publish ``traj`` as ``robot``'s move for request ``request_s`` (s) on its offer topic."""
    arm = g.bridge.cell.arm(robot)
    pub = g.probe.create_publisher(JointTrajectory, f'/{robot}/target_trajectory', 10)
    assert g.spin_until(lambda: pub.get_subscription_count() > 0)
    msg = conv.trajectory_msg(arm.joint_names, traj.t, traj.q, traj.qd, traj.qdd)
    msg.header.stamp = conv.time_from_ns(int(round(request_s * 1e9)))
    pub.publish(msg)
    return pub, msg


def statuses(g, robot):
    """Return ``robot``'s planner statuses so far, typed."""
    return [proto.PlannerStatus.from_msg(m) for m in g.status[robot]]


def test_an_offered_plan_is_scheduled_as_it_is_not_planned_again(cell):
    """The job's plan of a move, offered on /<robot>/target_trajectory, is what runs.

    The planner publishes the offered points unchanged under the request's id, the arm
    arrives, and the same offer sent again is answered from the history, not re-planned.
    """
    from scara_collab.core.planning import plan_path
    left = cell.bridge.cell.leader
    target = np.array([3.3, -0.6, 0.45])
    traj = plan_path(left, cell.left.planner.joints, target, mode='line_or_joint')
    request = conv.now(cell.left) + 0.3
    pub, msg = offer(cell, 'scara_left', traj, request)
    assert cell.spin_until(lambda: cell.trajs['scara_left'])
    sent = cell.trajs['scara_left'][-1]
    _, t, q, qd, qdd = conv.trajectory_arrays(sent, left.joint_names)
    np.testing.assert_array_equal(q, traj.q)
    np.testing.assert_array_equal(qdd, traj.qdd)
    st = statuses(cell, 'scara_left')[-1]
    assert st.state == 'planned' and st.request == conv.request_id(msg.header.stamp)
    assert sent.header.frame_id == st.move and abs(st.start - request) < 1e-6
    run_until(cell, st.end + 0.3)
    np.testing.assert_allclose(fk(left, cell.left.planner.joints), target, atol=1e-3)
    n_trajs, n_status = len(cell.trajs['scara_left']), len(cell.status['scara_left'])
    pub.publish(msg)  # re-sent (a lost answer): the same answer, nothing planned or moved
    assert cell.spin_until(lambda: len(cell.status['scara_left']) > n_status)
    assert statuses(cell, 'scara_left')[-1] == st
    run_until(cell, cell.bridge.sim.time + 0.3)
    assert len(cell.trajs['scara_left']) == n_trajs


def test_an_offer_from_elsewhere_is_planned_again_to_its_end(cell):
    """A plan that does not start where the arm is: the planner plans to its last point."""
    from scara_collab.core.planning import plan_path
    left = cell.bridge.cell.leader
    target = np.array([3.3, -0.6, 0.45])
    elsewhere = cell.left.planner.joints + [0.05, -0.05, 0.0]
    traj = plan_path(left, elsewhere, target, mode='line_or_joint')
    offer(cell, 'scara_left', traj, conv.now(cell.left) + 0.3)
    assert cell.spin_until(lambda: cell.trajs['scara_left'])
    _, _, q, _, _ = conv.trajectory_arrays(cell.trajs['scara_left'][-1], left.joint_names)
    # from the arm, not the offer
    np.testing.assert_allclose(q[0], cell.left.planner.joints, atol=2e-3)
    np.testing.assert_allclose(fk(left, q[-1]), target, atol=1e-9)
    assert statuses(cell, 'scara_left')[-1].state == 'planned'


def _no_accelerations(msg):
    for p in msg.points:
        p.accelerations = []


def _past_the_limit(msg):
    msg.points[-1].positions = [3.5, *msg.points[-1].positions[1:]]


def _unknown_joint(msg):
    msg.joint_names = ['elbow', *msg.joint_names[1:]]


def _nan_velocity(msg):
    msg.points[1].velocities = [0.0, float('nan'), 0.0]


@pytest.mark.parametrize('spoil, reason', [
    (_no_accelerations, 'velocities and accelerations'),
    (_past_the_limit, 'joint limits'),
    (_unknown_joint, 'joint names'),
    (_nan_velocity, 'non-finite'),
])
def test_a_malformed_offer_is_refused_and_nothing_moves(cell, spoil, reason):
    """An offered plan that is not one is refused with the reason; the arm stays."""
    from scara_collab.core.planning import plan_path
    left = cell.bridge.cell.leader
    q0 = cell.left.planner.joints.copy()
    traj = plan_path(left, q0, [3.3, -0.6, 0.45], mode='line_or_joint')
    msg = conv.trajectory_msg(left.joint_names, traj.t, traj.q, traj.qd, traj.qdd)
    msg.header.stamp = conv.time_from_ns(int(round((conv.now(cell.left) + 0.3) * 1e9)))
    spoil(msg)
    pub = cell.probe.create_publisher(JointTrajectory, '/scara_left/target_trajectory', 10)
    assert cell.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(msg)
    assert cell.spin_until(lambda: cell.status['scara_left'])
    st = statuses(cell, 'scara_left')[-1]
    assert st.state == 'refused' and 'offered trajectory' in st.reason and reason in st.reason
    run_until(cell, cell.bridge.sim.time + 0.5)
    np.testing.assert_allclose(cell.left.planner.joints, q0, atol=1e-4)
    assert not cell.trajs['scara_left']


def test_a_mirrored_offer_reaches_both_planners_mirrored_joint_by_joint(cell):
    """The leader's plan on /collab/target_trajectory: each planner takes its share as is.

    The leader's planner publishes the offered points, the follower's their mirror image
    (both angles negated), with the same start; neither re-plans, and the pair moves mirrored.
    """
    from scara_collab.core.mirror import mirror_joints
    from scara_collab.core.planning import plan_path
    left, right = cell.bridge.cell.arms
    target = np.array([2.7, -0.7, 0.4])
    traj = plan_path(left, cell.left.planner.joints, target, mode='line_or_joint')
    pub = cell.probe.create_publisher(JointTrajectory, '/collab/target_trajectory', 10)
    assert cell.spin_until(lambda: pub.get_subscription_count() > 0)
    msg = conv.trajectory_msg(left.joint_names, traj.t, traj.q, traj.qd, traj.qdd)
    msg.header.stamp = conv.time_from_ns(int(round((conv.now(cell.left) + 0.3) * 1e9)))
    pub.publish(msg)
    assert cell.spin_until(lambda: all(cell.trajs[n] for n in cell.trajs))
    ql = conv.trajectory_arrays(cell.trajs['scara_left'][-1], left.joint_names)[2]
    qr = conv.trajectory_arrays(cell.trajs['scara_right'][-1], right.joint_names)[2]
    np.testing.assert_array_equal(ql, traj.q)
    np.testing.assert_array_equal(qr, mirror_joints(traj.q))
    stamps = {conv.request_id(cell.trajs[n][-1].header.stamp) for n in cell.trajs}
    assert stamps == {conv.request_id(msg.header.stamp)}
    run_until(cell, max(last_end(cell, n) for n in cell.status) + 0.3)
    np.testing.assert_allclose(fk(right, cell.right.planner.joints),
                               mirror_point(left, right, target),
                               atol=1e-3)
