"""Config files as ROS parameters: declared with the file's defaults, validated, dynamic keys."""
import pytest
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from scara_collab.core.config import ConfigError, load_config
from scara_collab.graph import ros_args
from scara_collab.nodes.params import declare_config, flatten, unflatten


def test_flatten_and_unflatten_are_inverse():
    """Nested keys join with dots and split back into the same tree."""
    tree = {'a': {'b': 1, 'c': {'d': [1.0, 2.0]}}, 'e': 'x'}
    flat = flatten(tree)
    assert flat == {'a.b': 1, 'a.c.d': [1.0, 2.0], 'e': 'x'}
    assert unflatten(flat) == tree
    assert unflatten(flatten(load_config('simulation'))) == load_config('simulation')


def _node(ctx, name, **params):
    return Node(name, context=ctx, cli_args=ros_args((), params, sim_time=False))


def test_a_node_gets_the_files_defaults_and_overrides(context):
    """Every key of the file is a parameter with its default; ``-p`` overrides one."""
    node = _node(context, 'params_probe', feed_interval=2.5)
    trees = declare_config(node, ('simulation',))
    want = load_config('simulation')
    assert trees['simulation']['feed_interval'] == 2.5
    assert trees['simulation']['physics_rate'] == want['physics_rate']
    assert node.get_parameter('feed_interval').value == 2.5
    node.destroy_node()


def test_an_invalid_override_stops_the_node_with_the_files_reason(context):
    """A value the file's rules refuse raises ConfigError naming the node and the file."""
    node = _node(context, 'params_bad', physics_rate=-1.0)
    with pytest.raises(ConfigError, match='params_bad'):
        declare_config(node, ('simulation',))
    node.destroy_node()


def test_only_dynamic_keys_change_at_run_time_and_only_to_valid_values(context):
    """A dynamic key takes a valid value (and the callback hears it); others are refused."""
    node = _node(context, 'params_dyn')
    heard = []
    trees = declare_config(node, ('simulation',), dynamic=('feed_interval',),
                           on_change=lambda name, tree: heard.append(tree['feed_interval']))
    ok = node.set_parameters([Parameter('feed_interval', value=3.0)])[0]
    assert isinstance(ok, SetParametersResult) and ok.successful
    assert trees['simulation']['feed_interval'] == 3.0 and heard == [3.0]
    bad = node.set_parameters([Parameter('feed_interval', value=-1.0)])[0]
    assert not bad.successful and trees['simulation']['feed_interval'] == 3.0
    fixed = node.set_parameters([Parameter('physics_rate', value=500.0)])[0]
    assert not fixed.successful  # read-only: not a dynamic key
    node.destroy_node()


@pytest.mark.parametrize('node, configs, bad, reason', [
    ('pybullet_bridge', ('simulation', 'controllers'), {'markers_rate': 0.0},
     'markers_rate must be a number > 0'),
    ('pybullet_bridge', ('simulation', 'controllers'), {'step_chunk': -0.01},
     'step_chunk must be a number > 0'),
    ('pybullet_bridge', ('simulation', 'controllers'), {'lockstep_timeout': 0.0},
     'lockstep_timeout must be a number > 0'),
    ('automation_manager', ('automation', 'controllers'), {'tick': 0.0},
     'tick must be a number > 0'),
    ('automation_manager', ('automation', 'controllers'), {'auto_start': 'yes please'},
     'auto_start must be true or false'),
    ('replication_manager', (), {'collab_lead': -0.5}, 'collab_lead must be a number > 0'),
])
def test_a_nodes_own_bad_parameter_stops_it_with_the_reason(context, node, configs, bad, reason):
    """Node parameters outside the config files are checked at the door like the files' keys.

    (A zero ``markers_rate`` divided by zero in the bridge; a zero ``tick`` made the job's
    timer spin.)
    """
    from scara_collab import graph
    from scara_collab.core.paths import config_dir
    spec = graph.node(node)
    with pytest.raises(ConfigError, match=f'{node}: {reason}'):
        spec.build(context=context,
                   cli_args=ros_args(configs, bad, config_dir=config_dir()))
