"""launch/cell.launch.py, loaded without ROS's launch (not on PyPI), checked against the graph.

``launch``, ``launch_ros`` and ``ament_index_python`` are stood in for by recorders of what
the file builds; where the real ``launch_ros`` exists, the file is also loaded by it.
"""
import importlib.util
from pathlib import Path
import sys
import types

import pytest
import yaml

from scara_collab import graph
from scara_collab.core.config import validate

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = ROOT / 'launch' / 'cell.launch.py'


class _Recorded:
    """An action or description: keeps its arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _Config:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context[self.name]


def stand_ins(monkeypatch):
    """Put recorders in place of ``launch``, ``launch_ros`` and ``ament_index_python``."""
    modules = {
        'launch': {'LaunchDescription': _Recorded},
        'launch.actions': {'DeclareLaunchArgument': _Recorded, 'OpaqueFunction': _Recorded},
        'launch.substitutions': {'LaunchConfiguration': _Config},
        'launch_ros': {}, 'launch_ros.actions': {'Node': _Recorded},
        'ament_index_python': {},
        'ament_index_python.packages': {'get_package_share_directory': lambda p: str(ROOT)},
    }
    for name, attrs in modules.items():
        module = types.ModuleType(name)
        module.__dict__.update(attrs)
        monkeypatch.setitem(sys.modules, name, module)


def load(monkeypatch):
    """Return the launch file as a module, on the stand-ins."""
    stand_ins(monkeypatch)
    spec = importlib.util.spec_from_file_location('cell_launch', LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize('mode', graph.LAUNCH_MODES)
def test_the_launch_file_starts_the_graphs_nodes_with_their_files(monkeypatch, mode):
    """Each node of the mode's graph, by its executable, with its existing, valid params files.

    Sim time everywhere, the job-mode parameters typed, RViz and the state publisher on request.
    """
    module = load(monkeypatch)
    description = module.generate_launch_description()
    declared = {a.args[0]: a.kwargs['default_value'] for a in description.args[0][:-1]}
    assert declared == module.ARGUMENTS
    opaque = description.args[0][-1]
    context = dict(module.ARGUMENTS, mode=mode)
    nodes = opaque.kwargs['function'](context)
    expected = [n.name for n in graph.job_nodes(automation=mode != 'idle')]
    assert [n.kwargs['name'] for n in nodes] == expected
    scripts = {line.split(' = ')[0] for line in graph.console_scripts()}
    for node in nodes:
        kw = node.kwargs
        assert kw['package'] == 'scara_collab' and kw['executable'] in scripts
        *files, own = kw['parameters']
        assert own['use_sim_time'] is True
        assert [Path(f).stem for f in files] == list(graph.node(kw['name']).configs)
        for f in files:
            tree = yaml.safe_load(Path(f).read_text())['/**']['ros__parameters']
            validate(Path(f).stem, tree)  # the installed file is a valid config
        for key, value in own.items():
            assert not isinstance(value, str) or value not in ('true', 'false'), (key, value)
    params = {n.kwargs['name']: n.kwargs['parameters'][-1] for n in nodes}
    if mode != 'idle':
        assert params['automation_manager']['mode'] == mode
        assert params['automation_manager']['auto_start'] is True
    assert params['replication_manager']['enabled'] is (mode in ('mirrored', 'idle'))
    with_rviz = opaque.kwargs['function'](dict(context, rviz='true'))
    names = [n.kwargs['name'] for n in with_rviz]
    assert names[-2:] == ['state_publisher', 'rviz2']
    rviz = with_rviz[-1].kwargs['arguments'][1]
    assert Path(rviz).is_file() and yaml.safe_load(Path(rviz).read_text())[
        'Visualization Manager']['Global Options']['Fixed Frame'] == 'world'


def test_an_unknown_mode_is_refused(monkeypatch):
    """The mode argument goes through the graph's own check."""
    module = load(monkeypatch)
    opaque = module.generate_launch_description().args[0][-1]
    with pytest.raises(ValueError, match='mode must be one of'):
        opaque.kwargs['function'](dict(module.ARGUMENTS, mode='fast'))


def test_lockstep_false_runs_the_bridge_without_a_window(monkeypatch):
    """``lockstep:=false``: the bridge's ``lockstep_window`` 0 (real time); true keeps it."""
    module = load(monkeypatch)
    opaque = module.generate_launch_description().args[0][-1]

    def bridge(lockstep):
        nodes = opaque.kwargs['function'](dict(module.ARGUMENTS, lockstep=lockstep))
        return next(n for n in nodes if n.kwargs['name'] == 'pybullet_bridge').kwargs[
            'parameters'][-1]
    assert module.ARGUMENTS['lockstep'] == 'true'
    assert 'lockstep_window' not in bridge('true')
    assert bridge('false')['lockstep_window'] == 0.0
    assert bridge('False')['lockstep_window'] == 0.0
    planner = next(n for n in opaque.kwargs['function'](dict(module.ARGUMENTS, lockstep='false'))
                   if n.kwargs['name'] == 'left_planner').kwargs['parameters'][-1]
    assert planner['send_margin'] == graph.REALTIME_SEND_MARGIN
    with pytest.raises(ValueError, match='lockstep must be true or false'):
        bridge('off')


def test_cells_3_starts_a_line_of_cells_in_their_namespaces(monkeypatch):
    """``cells:=3``: every node of cell k under ``/cell_k``, the bridges joined into a line."""
    module = load(monkeypatch)
    opaque = module.generate_launch_description().args[0][-1]
    nodes = opaque.kwargs['function'](dict(module.ARGUMENTS, cells='3'))
    per_cell = len(graph.job_nodes())
    assert len(nodes) == 3 * per_cell
    bridges = [n for n in nodes if n.kwargs['name'] == 'pybullet_bridge']
    assert [b.kwargs['namespace'] for b in bridges] == ['/cell_0', '/cell_1', '/cell_2']
    own = [b.kwargs['parameters'][-1] for b in bridges]
    assert [(o['line_cell'], o['line_upstream'], o['line_downstream']) for o in own] == [
        (0, False, True), (1, True, True), (2, True, False)]
    assert 'feed_interval' not in own[0] and own[1]['feed_interval'] == 0.0
    remaps = dict(bridges[2].kwargs['remappings'])
    assert remaps['/clock'] == '/cell_2/clock'
    assert remaps['line/upstream'] == '/cell_1/line/handoff'
    assert remaps['line/upstream2'] == '/cell_0/line/handoff'
    lone = opaque.kwargs['function'](dict(module.ARGUMENTS))  # cells:=1: today's cell
    assert 'namespace' not in lone[0].kwargs and 'line_cell' not in lone[0].kwargs[
        'parameters'][-1]
    with pytest.raises(ValueError, match='cells must be an integer >= 1'):
        opaque.kwargs['function'](dict(module.ARGUMENTS, cells='0'))
    # cell:=1: that cell alone, as on a machine of its own, with the same line parameters
    one = opaque.kwargs['function'](dict(module.ARGUMENTS, cells='3', cell='1'))
    assert len(one) == per_cell and {n.kwargs['namespace'] for n in one} == {'/cell_1'}
    assert next(n for n in one if n.kwargs['name'] == 'pybullet_bridge').kwargs[
        'parameters'][-1] == own[1]
    with pytest.raises(ValueError, match='cell must be one of 0..2'):
        opaque.kwargs['function'](dict(module.ARGUMENTS, cells='3', cell='3'))


def test_a_person_starts_the_separation_monitor_and_gives_the_bridge_the_scenario(monkeypatch):
    """``person:=inlet``: the bridge simulates the person and runs the monitor in its process.

    With ``monitor_link:=topics`` the monitor is a node after the bridge, guarding it. Without
    ``person`` the cell is today's: no monitor, no new bridge parameter.
    """
    module = load(monkeypatch)
    opaque = module.generate_launch_description().args[0][-1]
    assert module.ARGUMENTS['person'] == ''
    nodes = opaque.kwargs['function'](dict(module.ARGUMENTS, person='inlet', person_seed='4'))
    names = [n.kwargs['name'] for n in nodes]
    assert names == [n.name for n in graph.job_nodes(people=True)]
    assert 'separation_monitor' not in names
    bridge = nodes[0].kwargs['parameters'][-1]
    assert (bridge['person'], bridge['person_seed']) == ('inlet', 4)
    assert (bridge['monitor_link'], bridge['lockstep_guards']) == ('wired', ['collision_monitor'])
    nodes = opaque.kwargs['function'](dict(module.ARGUMENTS, person='inlet', person_seed='4',
                                           monitor_link='topics'))
    names = [n.kwargs['name'] for n in nodes]
    assert names == [n.name for n in graph.job_nodes(people=True, monitor_link='topics')]
    bridge = nodes[0].kwargs['parameters'][-1]
    assert bridge['lockstep_guards'] == ['collision_monitor', 'separation_monitor']
    with pytest.raises(ValueError, match='monitor_link must be one of'):
        opaque.kwargs['function'](dict(module.ARGUMENTS, person='inlet', monitor_link='x'))
    monitor = nodes[names.index('separation_monitor')].kwargs['parameters']
    assert [Path(f).stem for f in monitor[:-1]] == ['people']
    plain = opaque.kwargs['function'](dict(module.ARGUMENTS))
    assert [n.kwargs['name'] for n in plain] == [n.name for n in graph.job_nodes()]
    assert not {'person', 'person_seed', 'lockstep_guards'} & set(
        plain[0].kwargs['parameters'][-1])
    none = opaque.kwargs['function'](dict(module.ARGUMENTS, person='none'))
    assert len(none) == len(plain)
    with pytest.raises(ValueError, match='person_seed must be an integer'):
        opaque.kwargs['function'](dict(module.ARGUMENTS, person='inlet', person_seed='x'))
