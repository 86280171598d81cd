"""The planner's own parameters: checked at start and at run time, like the config files' keys.

The config files' keys go through :func:`scara_collab.nodes.params.declare_config`
(``test_params``); the planner's own (``robot``, ``profile``, ``mode`` and the times) are
declared and checked by :func:`scara_collab.nodes.params.declare_checked`.
"""
import pytest
from rclpy.parameter import Parameter
from ros_harness import params_args

from scara_collab.core.config import ConfigError
from scara_collab.nodes.planner import Planner


def _planner(context, **overrides):
    return Planner(robot='scara_left', node_name='left_planner', context=context,
                   cli_args=params_args('controllers', overrides={'lockstep': 'false',
                                                                  **overrides}))


@pytest.mark.parametrize('overrides, message', [
    ({'mode': 'diagonal'}, "mode must be one of ('line', 'joint', 'line_or_joint'), got "
                           "'diagonal'"),
    ({'planning_lead': '0.0'}, 'planning_lead must be a number > 0, got 0.0'),
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
    assert node.arm.name == 'scara_left' and node.leader and node.mode == 'joint'
    assert (node.lead, node.max_delay, node.max_wait) == (0.05, 30.0, 5.0)
    node.destroy_node()


def test_own_parameters_change_at_run_time_only_to_valid_values(context):
    """Mode and times take valid values at run time; invalid ones, robot and profile do not."""
    node = _planner(context)
    ok = node.set_parameters([Parameter('max_delay', value=5.0),
                              Parameter('mode', value='line')])
    assert all(r.successful for r in ok)
    assert node.max_delay == 5.0 and node.mode == 'line'
    bad = node.set_parameters([Parameter('max_delay', value=-1.0)])[0]
    assert not bad.successful and 'max_delay must be a number > 0, got -1.0' in bad.reason
    assert node.max_delay == 5.0 and node.get_parameter('max_delay').value == 5.0
    bad = node.set_parameters([Parameter('mode', value='diagonal')])[0]
    assert not bad.successful and node.mode == 'line'
    assert node.set_parameters([Parameter('planning_lead', value=1)])[0].successful
    assert node.lead == 1.0
    for name, value in (('robot', 'scara_right'), ('profile', 'slim')):
        assert not node.set_parameters([Parameter(name, value=value)])[0].successful
    assert node.arm.name == 'scara_left'
    node.destroy_node()
