"""FollowJointTrajectory on the bridge, as ros2_control's joint trajectory controller serves it.

Needs control_msgs (no PyPI wheel: ``./scripts/build_interfaces`` builds it, CI does): a goal
moves an arm and succeeds with feedback; a malformed goal is rejected at the goal response and
nothing moves or stops; bad goals end with their error codes; cancel holds the arm; a new goal
preempts the running one.
"""
import numpy as np
import pytest
from ros_harness import Graph

from scara_collab.core.trajectory import joint_move
from scara_collab.nodes import conversions as conv

try:
    from action_msgs.msg import GoalStatus
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointTolerance
    from rcl_interfaces.msg import Log
    from rclpy.action import ActionClient
except ImportError:
    FollowJointTrajectory = None

pytestmark = pytest.mark.skipif(FollowJointTrajectory is None,
                                reason='control_msgs not built (./scripts/build_interfaces)')


@pytest.fixture
def graph():
    """Yield the bridge (unthrottled, no feed, no lockstep) and an action client per arm."""
    g = Graph()
    g.bridge = g.add_node_of('pybullet_bridge', real_time_factor=0.0, feed_interval=0.0,
                             lockstep_window=0.0)
    g.arm = g.bridge.cell.leader
    g.client = ActionClient(g.probe, FollowJointTrajectory,
                            f'/{g.arm.name}/follow_joint_trajectory')
    assert g.spin_until(g.client.server_is_ready)
    yield g
    g.close()


def goal_to(g, dq, names=None, path_tolerance=None):
    """Return a goal: a joint move of the leader by ``dq`` from where it is."""
    q0 = g.bridge.sim.arm_state(g.arm.name)[0]
    traj = joint_move(g.arm, q0, q0 + np.asarray(dq))
    goal = FollowJointTrajectory.Goal()
    goal.trajectory = conv.trajectory_msg(names or g.arm.joint_names, traj.t, traj.q, traj.qd)
    if path_tolerance is not None:
        goal.path_tolerance = [JointTolerance(name=n, position=path_tolerance)
                               for n in g.arm.joint_names]
    return goal, q0 + np.asarray(dq), traj.duration


def respond(g, goal, feedback=None):
    """Send ``goal``; return its handle once the goal response has come."""
    sent = g.client.send_goal_async(goal, feedback_callback=feedback)
    assert g.spin_until(sent.done)
    return sent.result()


def send(g, goal, feedback=None):
    """Send ``goal``; return its accepted handle."""
    handle = respond(g, goal, feedback)
    assert handle.accepted
    return handle


def result_of(g, handle, timeout=60.0):
    """Return ``(status, result)`` of a goal once it has ended."""
    future = handle.get_result_async()
    assert g.spin_until(future.done, timeout=timeout)
    return future.result().status, future.result().result


def test_a_goal_moves_the_arm_and_succeeds_with_feedback(graph):
    """The arm follows the goal through the bridge; feedback comes; the result is SUCCESSFUL."""
    feedback = []
    goal, target, duration = goal_to(graph, [0.4, -0.3, 0.1])
    status, result = result_of(graph, send(graph, goal, feedback.append))
    assert status == GoalStatus.STATUS_SUCCEEDED, result.error_string
    assert result.error_code == FollowJointTrajectory.Result.SUCCESSFUL
    np.testing.assert_allclose(graph.bridge.sim.arm_state(graph.arm.name)[0], target, atol=0.01)
    assert len(feedback) >= duration / 0.1 - 2
    fb = feedback[len(feedback) // 2].feedback
    assert list(fb.joint_names) == list(graph.arm.joint_names)
    np.testing.assert_allclose(np.subtract(fb.desired.positions, fb.actual.positions),
                               fb.error.positions, atol=1e-12)
    assert max(abs(v) for v in fb.error.positions) < 0.01  # it tracks


def malformed_goals(g):
    """Return ``{why: goal}``: goals the trajectory controller rejects at the goal response."""
    names = list(g.arm.joint_names)
    out = {}
    out['unknown joint'] = goal_to(g, [0.1, 0.0, 0.0], names=names[:2] + ['elbow'])[0]
    goal = goal_to(g, [0.1, 0.0, 0.0])[0]
    goal.trajectory.joint_names = names[:2]
    for pt in goal.trajectory.points:
        pt.positions, pt.velocities = pt.positions[:2], pt.velocities[:2]
    out['missing joint'] = goal
    out['repeated joint'] = goal_to(g, [0.1, 0.0, 0.0], names=names[:2] + names[:1])[0]
    goal = goal_to(g, [0.1, 0.0, 0.0])[0]
    goal.trajectory.points = []
    out['no points'] = goal
    goal = goal_to(g, [0.1, 0.0, 0.0])[0]
    goal.trajectory.points[-1].positions = goal.trajectory.points[-1].positions[:2]
    out['short positions'] = goal
    return out


def test_malformed_goals_are_rejected_and_the_arm_does_not_move(graph):
    """Unknown, missing or repeated joints, no points, short positions: REJECTED, with a warning.

    As the joint trajectory controller's goal response: the goal is never accepted, so nothing
    runs, no move is numbered, and the arm stays where it stands.
    """
    g = graph
    log = g.collect(Log, '/rosout')
    q0 = g.bridge.sim.arm_state(g.arm.name)[0]
    for why, goal in malformed_goals(g).items():
        handle = respond(g, goal)
        assert not handle.accepted, why
    assert g.spin_until(lambda: sum('goal rejected' in m.msg for m in log) >= 5)
    warned = [m.msg for m in log if 'goal rejected' in m.msg]
    unknown = f"{list(g.arm.joint_names[:2]) + ['elbow']} do not match"
    assert any(unknown in m for m in warned), warned
    assert any('no points' in m for m in warned), warned
    assert any('2 positions for 3 joints' in m for m in warned), warned
    t = g.bridge.sim.time
    assert g.spin_until(lambda: g.bridge.sim.time > t + 0.5)
    q, qd = g.bridge.sim.arm_state(g.arm.name)
    np.testing.assert_allclose(q, q0, atol=1e-4)
    assert np.abs(qd).max() < 1e-3
    assert g.bridge.actions.count == 0 and not g.bridge.actions.active
    assert g.bridge.execution.current(g.arm.name) == ''


def test_a_rejected_goal_leaves_the_running_goal_alone(graph):
    """A goal with no points sent mid-move is rejected; the running goal goes on to succeed."""
    g = graph
    goal, target, _ = goal_to(g, [0.6, -0.4, 0.0])
    running = send(g, goal)
    start = g.bridge.sim.time
    assert g.spin_until(lambda: g.bridge.sim.time > start + 0.3)
    assert not respond(g, malformed_goals(g)['no points']).accepted
    status, result = result_of(g, running)
    assert status == GoalStatus.STATUS_SUCCEEDED, result.error_string
    np.testing.assert_allclose(g.bridge.sim.arm_state(g.arm.name)[0], target, atol=0.01)


def test_bad_goals_end_with_their_error_codes(graph):
    """Accepted goals that cannot run end with their error codes, and say why.

    A tolerance for an unknown joint: INVALID_JOINTS; beyond the joint limits: INVALID_GOAL.
    """
    R = FollowJointTrajectory.Result
    goal, _, _ = goal_to(graph, [0.1, 0.0, 0.0])
    goal.goal_tolerance = [JointTolerance(name='elbow', position=0.1)]
    status, result = result_of(graph, send(graph, goal))
    assert status == GoalStatus.STATUS_ABORTED and result.error_code == R.INVALID_JOINTS
    assert "unknown joint 'elbow'" in result.error_string
    goal, _, _ = goal_to(graph, [0.1, 0.0, 0.0])
    goal.trajectory.points[-1].positions[0] = 3.0  # beyond +-150 deg
    status, result = result_of(graph, send(graph, goal))
    assert status == GoalStatus.STATUS_ABORTED and result.error_code == R.INVALID_GOAL
    assert 'limit' in result.error_string


def test_cancel_holds_the_arm_and_a_new_goal_preempts(graph):
    """Canceled mid-move the arm brakes and holds short of the goal; a second goal preempts."""
    g = graph
    goal, target, _ = goal_to(g, [1.2, 0.0, 0.0])
    handle = send(g, goal)
    start = g.bridge.sim.time
    assert g.spin_until(lambda: g.bridge.sim.time > start + 0.4)
    cancel = handle.cancel_goal_async()
    status, result = result_of(g, handle)
    assert cancel.done() and status == GoalStatus.STATUS_CANCELED, result.error_string
    t = g.bridge.sim.time
    assert g.spin_until(lambda: g.bridge.sim.time > t + 1.0)
    q, qd = g.bridge.sim.arm_state(g.arm.name)
    assert np.abs(qd).max() < 1e-3 and abs(q[0] - target[0]) > 0.2  # held, short of the goal
    first = send(g, goal_to(g, [0.8, 0.0, 0.0])[0])
    assert g.spin_until(lambda: g.bridge.sim.time > t + 1.3)
    second = send(g, goal_to(g, [-0.3, 0.0, 0.0])[0])
    status, result = result_of(g, first)
    assert status == GoalStatus.STATUS_ABORTED and 'preempted by goal' in result.error_string
    status, result = result_of(g, second)
    assert status == GoalStatus.STATUS_SUCCEEDED, result.error_string


def test_a_broken_path_tolerance_holds_the_arm(graph):
    """A path tolerance tighter than the tracking error aborts the goal and holds the arm."""
    goal, _, _ = goal_to(graph, [1.0, -0.8, 0.0], path_tolerance=1e-7)
    status, result = result_of(graph, send(graph, goal))
    assert status == GoalStatus.STATUS_ABORTED
    assert result.error_code == FollowJointTrajectory.Result.PATH_TOLERANCE_VIOLATED
    assert 'path tolerance 1e-07' in result.error_string


def test_a_destroyed_bridge_leaves_the_graph_with_its_action_servers():
    """The bridge's action servers are destroyed with it: no ghost node stays on the graph.

    (An action server left alive kept the destroyed bridge's node on the graph, and the next
    launcher in the same process group refused to start: "pybullet_bridge is already running".)
    """
    import time
    g = Graph()
    g.add_node_of('pybullet_bridge', real_time_factor=0.0, feed_interval=0.0)
    g.close()
    look = Graph()
    try:
        names = set()
        end = time.monotonic() + 3.0
        while time.monotonic() < end:  # let discovery settle: the name must stay gone
            look.executor.spin_once(timeout_sec=0.1)
            names = {n for n, _ in look.probe.get_node_names_and_namespaces()}
        assert 'pybullet_bridge' not in names, names
    finally:
        look.close()
