"""The planner node, a shell around :class:`scara_collab.core.arm_planner.ArmPlanner`.

Its own parameters are checked at start and at run time, like the config files' keys (those go
through :func:`scara_collab.nodes.params.declare_config`, ``test_params``; the planner's own,
``robot``, ``profile``, ``mode`` and the times, through
:func:`scara_collab.nodes.params.declare_checked`). Its topics are relative, so a namespace
moves them, and messages go in and out as the protocol says (the decisions themselves are
tested without ROS in ``test_arm_planner``).
"""
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
import numpy as np
import pytest
from rclpy.parameter import Parameter
from ros_harness import Graph, params_args
from trajectory_msgs.msg import JointTrajectory

from scara_collab.core.config import ConfigError
from scara_collab.core.kinematics import ik
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.planner import Planner


def _planner(context, namespace='', **overrides):
    return Planner(robot='scara_left', node_name='left_planner', context=context,
                   cli_args=params_args('controllers', overrides={'lockstep': 'false',
                                                                  **overrides},
                                        namespace=namespace))


@pytest.mark.parametrize('overrides, message', [
    ({'mode': 'diagonal'}, "mode must be one of ('line', 'joint', 'line_or_joint'), got "
                           "'diagonal'"),
    ({'send_margin': '0.0'}, 'send_margin must be a number > 0, got 0.0'),
    ({'max_delay': '-1.0'}, 'max_delay must be a number > 0, got -1.0'),
    ({'max_wait': 'long'}, "max_wait must be a number > 0, got 'long'"),
    ({'robot': 'scara_middle'}, "robot must be one of ['scara_left', 'scara_right'], got "
                                "'scara_middle'"),
])
def test_an_invalid_own_parameter_stops_the_planner(context, overrides, message):
    """An invalid value of the planner's own parameters raises, naming node, key and value."""
    with pytest.raises(ConfigError) as err:
        _planner(context, **overrides)
    assert str(err.value) == f'left_planner: {message}'


def test_the_defaults_and_valid_overrides_are_taken(context):
    """The defaults hold unless overridden; a whole number is a valid time."""
    node = _planner(context, mode='joint', max_wait='5')
    settings = node.planner.settings
    assert node.arm.name == 'scara_left' and node.planner.leader and settings.mode == 'joint'
    assert (settings.leads.planning, settings.leads.send, settings.max_delay,
            settings.max_wait) == (0.05, 0.05, 30.0, 5.0)  # a lockstep's send margin
    assert settings.margin == pytest.approx(node.cell.safety_margin + 0.03)
    node.destroy_node()


def test_own_parameters_change_at_run_time_only_to_valid_values(context):
    """Mode and times take valid values at run time; invalid ones, robot and profile do not."""
    node = _planner(context)
    ok = node.set_parameters([Parameter('max_delay', value=5.0),
                              Parameter('mode', value='line')])
    assert all(r.successful for r in ok)
    settings = node.planner.settings
    assert settings.max_delay == 5.0 and settings.mode == 'line'
    bad = node.set_parameters([Parameter('max_delay', value=-1.0)])[0]
    assert not bad.successful and 'max_delay must be a number > 0, got -1.0' in bad.reason
    assert node.planner.settings.max_delay == 5.0
    assert node.get_parameter('max_delay').value == 5.0
    bad = node.set_parameters([Parameter('mode', value='diagonal')])[0]
    assert not bad.successful and node.planner.settings.mode == 'line'
    assert node.set_parameters([Parameter('send_margin', value=1)])[0].successful
    assert node.planner.settings.leads.send == 1.0
    for name, value in (('robot', 'scara_right'), ('profile', 'slim')):
        assert not node.set_parameters([Parameter(name, value=value)])[0].successful
    assert node.arm.name == 'scara_left'
    node.destroy_node()


def test_the_topics_are_relative_so_a_namespace_moves_them(context):
    """Under ``/cell_1`` every topic of the planner is the cell's, none is at the root."""
    node = _planner(context, namespace='/cell_1')
    published = {name for name, _ in node.get_publisher_names_and_types_by_node(
        'left_planner', '/cell_1')}
    subscribed = {name for name, _ in node.get_subscriber_names_and_types_by_node(
        'left_planner', '/cell_1')}
    assert {'/cell_1/scara_left/joint_trajectory', '/cell_1/scara_left/planned_path',
            '/cell_1/scara_left/planner_status'} <= published
    assert {'/cell_1/joint_states', '/cell_1/scara_left/target',
            '/cell_1/scara_left/target_trajectory', '/cell_1/scara_right/joint_trajectory',
            '/cell_1/scara_right/execution_status',
            '/cell_1/scara_left/execution_status'} <= subscribed
    node.destroy_node()


@pytest.fixture
def shell():
    """Yield a graph with the left planner on the wall clock and the probe's topics."""
    g = Graph()
    g.node = g.add(Planner(robot='scara_left', node_name='left_planner', context=g.context,
                           cli_args=params_args('controllers', overrides={
                               'lockstep': 'false', 'use_sim_time': 'false'})))
    g.status = g.collect(DiagnosticStatus, 'scara_left/planner_status', 50)
    g.trajs = g.collect(JointTrajectory, 'scara_left/joint_trajectory')
    g.paths = g.collect(Path, 'scara_left/planned_path')
    yield g
    g.close()


def _publish(g, msg_type, topic, msg):
    pub = g.probe.create_publisher(msg_type, topic, 10)
    assert g.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(msg)


def test_a_target_goes_out_as_a_trajectory_its_path_and_a_status(shell, cell):
    """The move's id in the trajectory's frame, its start as the stamp; re-sent: status only.

    Before a joint state it is refused with the reason; a second copy of a planned request is
    answered with the same status and no new trajectory.
    """
    g = shell
    stamp = conv.now(g.node) + 1.0
    target = conv.make_point_stamped([3.0, -1.0, 0.3], 'world', stamp)
    _publish(g, PointStamped, 'scara_left/target', target)
    assert g.spin_until(lambda: len(g.status) == 1)
    refused = proto.PlannerStatus.from_msg(g.status[0])
    assert (refused.state, refused.reason) == ('refused',
                                               'no joint state yet (is the bridge up?)')
    tools = ([2.8, -1.2, 0.4], [2.8, 1.2, 0.4])  # each arm out on its own side
    q = np.concatenate([ik(a, xyz).q for a, xyz in zip(cell.arms, tools)])
    names = [n for a in cell.arms for n in a.joint_names]
    state = conv.joint_state(conv.now(g.node), names, q, np.zeros(6), np.zeros(6))
    _publish(g, type(state), 'joint_states', state)
    assert g.spin_until(lambda: g.node.planner.joints is not None)
    target.header.stamp = conv.to_time(stamp + 0.5)  # a new request
    _publish(g, PointStamped, 'scara_left/target', target)
    assert g.spin_until(lambda: len(g.status) == 2 and g.trajs and g.paths)
    st = proto.PlannerStatus.from_msg(g.status[1])
    traj = g.trajs[0]
    assert st.state == 'planned' and st.kind == 'line' and g.status[1].level == DiagnosticStatus.OK
    assert traj.header.frame_id == st.move == f'scara_left/{conv.request_id(target.header.stamp)}'
    assert conv.to_sec(traj.header.stamp) == pytest.approx(st.start, abs=1e-9)
    assert len(g.paths[0].poses) == len(traj.points)
    _publish(g, PointStamped, 'scara_left/target', target)  # the same request again
    assert g.spin_until(lambda: len(g.status) == 3)
    assert g.status[2] == g.status[1] and len(g.trajs) == 1
