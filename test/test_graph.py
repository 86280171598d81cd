"""The graph's names: relative, resolved in a cell's namespace, with the remaps a cell needs."""
import pytest

from scara_collab import graph


def test_no_namespace_gives_exactly_the_root_names():
    """Without a namespace every resolved name is absolute in the root, and nothing is remapped."""
    names = [t.name for t in graph.topics()]
    assert names[:2] == ['/clock', '/joint_states'] and '/scara_left/joint_trajectory' in names
    assert all(n.startswith('/') and not n.startswith('//') for n in names)
    assert graph.remaps() == {} and graph.node_args() == [] and graph.node_args('/') == []
    assert graph.ros_args() == ['--ros-args', '-p', 'use_sim_time:=true']
    assert graph.topic('/emergency_stop') == graph.topic('emergency_stop')


@pytest.mark.parametrize('given', ['cell_1', '/cell_1', '/cell_1/'])
def test_a_namespace_moves_every_name_but_rcls_own(given):
    """In ``/cell_1`` every topic is under it (``/rosout`` excepted) and ``/clock`` is remapped."""
    root = {t.name: t for t in graph.topics()}
    moved = graph.topics(namespace=given)
    for t in moved:
        if t.name == '/rosout':
            continue
        assert t.name.startswith('/cell_1/'), t
        assert root[t.name[len('/cell_1'):]].type == t.type
    assert graph.remaps(given) == {'/clock': '/cell_1/clock'}
    args = graph.ros_args(('controllers',), {'mode': 'joint'}, namespace=given)
    assert args[:7] == ['--ros-args', '-p', 'use_sim_time:=true', '-r', '__ns:=/cell_1',
                        '-r', '/clock:=/cell_1/clock']
    assert args[-2:] == ['-p', 'mode:=joint']
    assert graph.topic('joint_states', namespace=given).name == '/cell_1/joint_states'


def test_readiness_and_lockstep_names_are_relative():
    """The launcher resolves what it waits for in the cell; the bridge resolves its expects."""
    for spec in graph.NODES:
        assert not spec.ready.name.startswith('/'), spec.name
    bridge = graph.node('pybullet_bridge')
    assert bridge.ready.describe('pybullet_bridge', {}) == 'service /sim/resume'
    assert bridge.ready.describe('pybullet_bridge', {}, '/cell_2') == 'service /cell_2/sim/resume'
    assert graph.node('state_publisher').ready.describe('state_publisher', {}) == (
        'node state_publisher publishes /robot_description')
    assert all(not n.startswith('/') for n in graph.lockstep_expect(graph.job_nodes()))


@pytest.mark.parametrize('bad', ['cell 1', '/1cell', '/a//b', '~/x', 'cell-1'])
def test_a_bad_namespace_is_refused(bad):
    """A name rcl would refuse is refused here first, with the name."""
    with pytest.raises(ValueError, match='not a ROS namespace'):
        graph.namespace_of(bad)
