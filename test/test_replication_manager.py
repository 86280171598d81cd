"""The replication manager: the leader's target mirrored onto the follower, and the mirror error.

In-process on the wall clock, with the probe standing in for the job and the bridge: a
``collab/target`` goes to both planners' topics with one stamp (the move's id), the follower's
mirrored across the belt; a plan goes on to the leader and its joint-by-joint mirror image to
the follower; turned off, only the leader moves. A pair the bridge accepted with one start is
*in step*, and only then does the error count towards ``error_max``.
"""
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
import numpy as np
from numpy.testing import assert_allclose
import pytest
from ros_harness import Graph
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core import moves
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.mirror import mirror_joints, mirror_point
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import protocol as proto


@pytest.fixture
def g():
    """Yield a graph with the replication manager on, on the wall clock, and the probe."""
    g = Graph()
    g.node = g.add_node_of('replication_manager', enabled='true', use_sim_time='false',
                           lockstep='false')
    g.cell = g.node.cell
    g.targets = {a.name: g.collect(PointStamped, f'{a.name}/target') for a in g.cell.arms}
    g.offers = {a.name: g.collect(JointTrajectory, f'{a.name}/target_trajectory')
                for a in g.cell.arms}
    yield g
    g.close()


def _publisher(g, msg_type, topic):
    pub = g.probe.create_publisher(msg_type, topic, 10)
    assert g.spin_until(lambda: pub.get_subscription_count() > 0)
    return pub


def _point(msg):
    return np.array([msg.point.x, msg.point.y, msg.point.z])


def test_a_collab_target_goes_to_both_arms_mirrored_with_one_stamp(g):
    """Same stamp for both; the follower's point is the mirror image across the belt."""
    lead, foll = g.cell.leader, g.cell.follower
    pub = _publisher(g, PointStamped, 'collab/target')
    pub.publish(conv.make_point_stamped([3.1, -0.9, 0.4], 'world', 12.5))
    assert g.spin_until(lambda: g.targets[lead.name] and g.targets[foll.name])
    to_lead, to_foll = g.targets[lead.name][0], g.targets[foll.name][0]
    assert conv.request_id(to_lead.header.stamp) == conv.request_id(to_foll.header.stamp) \
        == 12_500_000_000
    assert_allclose(_point(to_lead), [3.1, -0.9, 0.4])
    assert_allclose(_point(to_foll), mirror_point(lead, foll, [3.1, -0.9, 0.4]))


def test_a_target_stamped_zero_gets_one_common_start_ahead(g):
    """Stamp 0 ("now"): both arms are asked for now + ``collab_lead``, the same instant."""
    lead, foll = g.cell.leader, g.cell.follower
    pub = _publisher(g, PointStamped, 'collab/target')
    before = conv.now(g.node)
    pub.publish(conv.make_point_stamped([3.1, -0.9, 0.4], 'world'))
    assert g.spin_until(lambda: g.targets[lead.name] and g.targets[foll.name])
    starts = {conv.to_sec(g.targets[a.name][0].header.stamp) for a in (lead, foll)}
    assert len(starts) == 1
    assert before + g.node.lead <= starts.pop() <= conv.now(g.node) + g.node.lead


def test_a_plan_goes_on_to_the_leader_and_its_mirror_image_to_the_follower(g):
    """The leader's plan unchanged; the follower's joint by joint (same geometry)."""
    lead, foll = g.cell.leader, g.cell.follower
    q0 = ik(lead, [3.1, -0.9, 0.4]).q
    q1 = ik(lead, [2.9, -0.7, 0.3]).q
    t = np.array([0.0, 0.5, 1.0])
    q = np.vstack([q0, (q0 + q1) / 2, q1])
    qd = np.zeros_like(q)
    msg = conv.trajectory_msg(lead.joint_names, t, q, qd, qd, start=20.0)
    _publisher(g, JointTrajectory, 'collab/target_trajectory').publish(msg)
    assert g.spin_until(lambda: g.offers[lead.name] and g.offers[foll.name])
    _, _, q_lead, _, _ = conv.trajectory_arrays(g.offers[lead.name][0], lead.joint_names)
    stamp, _, q_foll, _, _ = conv.trajectory_arrays(g.offers[foll.name][0], foll.joint_names)
    assert stamp == pytest.approx(20.0)
    assert_allclose(q_lead, q)
    assert_allclose(q_foll, mirror_joints(q))
    assert_allclose(fk(foll, q_foll[-1]), mirror_point(lead, foll, fk(lead, q1)), atol=1e-9)


def test_off_only_the_leader_moves_and_on_again_both(g):
    """``~/enable`` false: the follower gets nothing; true again: both (idempotent answers)."""
    lead, foll = g.cell.leader, g.cell.follower
    for _ in range(2):
        res = g.call(SetBool, 'replication_manager/enable', SetBool.Request(data=False))
        assert res.success and res.message == 'mirroring off'
    pub = _publisher(g, PointStamped, 'collab/target')
    pub.publish(conv.make_point_stamped([3.1, -0.9, 0.4], 'world', 30.0))
    assert g.spin_until(lambda: g.targets[lead.name])
    assert not g.spin_until(lambda: g.targets[foll.name], timeout=0.5)
    assert g.call(SetBool, 'replication_manager/enable', SetBool.Request(data=True)).success
    pub.publish(conv.make_point_stamped([3.1, -0.9, 0.4], 'world', 31.0))
    assert g.spin_until(lambda: g.targets[foll.name])


def test_a_non_finite_target_is_refused_and_the_node_lives_on(g):
    """A NaN target goes nowhere; the next good one is mirrored as usual."""
    lead, foll = g.cell.leader, g.cell.follower
    pub = _publisher(g, PointStamped, 'collab/target')
    pub.publish(conv.make_point_stamped([float('nan'), -0.9, 0.4], 'world', 40.0))
    assert not g.spin_until(lambda: g.targets[lead.name], timeout=0.5)
    pub.publish(conv.make_point_stamped([3.1, -0.9, 0.4], 'world', 41.0))
    assert g.spin_until(lambda: g.targets[lead.name] and g.targets[foll.name])


def _execution(robot, state, request, start, end):
    return proto.ExecutionStatus(robot, state, moves.move_id(robot, request), start=start,
                                 end=end, time=start, stamp=start).to_msg()


def test_the_error_counts_only_while_a_pair_runs_in_step(g):
    """A pair accepted with one start is in step: its states' error counts; another does not."""
    lead, foll = g.cell.leader, g.cell.follower
    statuses = {a.name: _publisher(g, DiagnosticStatus, f'{a.name}/execution_status')
                for a in g.cell.arms}
    states = _publisher(g, JointState, 'joint_states')
    q_lead = ik(lead, [3.1, -0.9, 0.4]).q
    now = conv.now(g.node)

    def state(q_foll, t):
        msg = JointState(name=list(lead.joint_names) + list(foll.joint_names),
                         position=list(q_lead) + list(q_foll), velocity=[0.0] * 6)
        msg.header.stamp = conv.to_time(t)
        states.publish(msg)

    for robot, start in ((lead.name, now), (foll.name, now + 0.2)):  # not in step
        statuses[robot].publish(_execution(robot, 'accepted', 1, start, now + 2.0))
    assert g.spin_until(lambda: g.node.not_in_step == 1)
    state(mirror_joints(q_lead) + [0.01, 0.0, 0.0], now + 0.5)
    assert g.spin_until(lambda: g.node.error is not None and g.node.error > 0.005)
    assert g.node.error_max is None and g.node.in_step_moves == 0
    for robot in (lead.name, foll.name):  # in step: the same start and end
        statuses[robot].publish(_execution(robot, 'accepted', 2, now + 1.0, now + 3.0))
    assert g.spin_until(lambda: g.node.in_step_moves == 1)
    state(mirror_joints(q_lead), now + 1.1)  # starts mirrored
    state(mirror_joints(q_lead) + [0.002, 0.0, 0.0], now + 1.5)
    assert g.spin_until(lambda: g.node.error_max is not None and g.node.error_max > 0.001)
    assert g.node.error_max_time == pytest.approx(now + 1.5, abs=1e-6)
    status = g.node.status()
    assert (status.in_step_moves, status.not_in_step) == (1, 1)
    assert 'the follower yielded or came late' in status.last_reason
