"""``ros2 launch scara_collab cell.launch.py``: the cell's graph for ROS installs.

The same nodes, parameters files and job-mode parameters as ``scripts/launch_cell.py``, read
from the one description of the graph (:mod:`scara_collab.graph`), every node on sim time
(the bridge is the clock). It starts the nodes; the run's files, progress and report are the
launcher script's (``scripts/launch_cell.py``), not this file's.

Arguments: ``mode`` (``collaborative``, ``single``, ``mirrored`` or ``idle``), ``tf``
(``true``: ``state_publisher`` for ``/robot_description``, ``/tf`` and ``/tf_static``),
``viewer`` (``true``: the live 3D view), ``rviz`` (``true``: RViz with ``config/cell.rviz``;
implies ``tf``), ``auto_start`` (``true``: the job starts once the graph is connected),
``lockstep`` (``true``: sim time waits for every node; ``false``: real time, the clock waits
for nobody, as on hardware or in Gazebo: the bridge's ``lockstep_window`` 0), ``namespace``
(e.g. ``/cell_1``: every node of the cell in that namespace with the graph's remaps,
:func:`scara_collab.graph.remaps`, so cells in different namespaces share a domain; default
none), ``cells`` (N > 1: a line of N cells along one belt, cell k under ``/cell_k`` with its
bridge's line parameters and its upstream cells' handoff remaps, only cell 0 fed;
:mod:`scara_collab.core.line`; with ``namespace`` the line goes under it, ``<ns>/cell_k``),
``cell`` (with ``cells``: only cell K of the line, for one machine per cell; default all),
``person`` (a person in every cell: a built-in scenario, ``pass-by``, ``inlet``, ``middle`` or
``random``, or a YAML file's path; the bridge simulates it and the safety scanners, and the
separation monitor scales the arms' speeds: :func:`scara_collab.graph.person_params`; default
none), ``person_seed`` (the person's seed; default the bridge's), ``monitor_link`` (with a
person: ``wired``, the separation monitor in the bridge's process, the default; ``topics``, a
node of its own after the bridge, among its guards).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from scara_collab import graph

PACKAGE = 'scara_collab'
ARGUMENTS = {'mode': 'collaborative', 'tf': 'false', 'viewer': 'false', 'rviz': 'false',
             'auto_start': 'true', 'lockstep': 'true', 'namespace': '', 'cells': '1',
             'cell': '', 'person': '', 'person_seed': '', 'monitor_link': 'wired'}


def _typed(value: str):
    """Return a job-mode parameter (a ``-p`` string) as its typed value."""
    if value.startswith('[') and value.endswith(']'):  # graph.param_value's string array
        return [v.strip().strip("'") for v in value[1:-1].split(',') if v.strip()]
    for number in (int, float):
        try:
            return number(value)
        except ValueError:
            pass
    return {'true': True, 'false': False}.get(str(value).lower(), value)


def nodes(context):
    """Return the graph's nodes for the arguments' values (resolved at launch time)."""
    arg = {k: LaunchConfiguration(k).perform(context) for k in ARGUMENTS}
    share = get_package_share_directory(PACKAGE)
    rviz = arg['rviz'].lower() == 'true'
    if arg['lockstep'].lower() not in ('true', 'false'):
        raise ValueError(f"lockstep must be true or false, got {arg['lockstep']!r}")
    params = graph.job_params(arg['mode'], lockstep=arg['lockstep'].lower() == 'true')
    if arg['mode'] != 'idle':
        params['automation_manager']['auto_start'] = arg['auto_start']
    try:
        cells = int(arg['cells'])
    except ValueError:
        cells = 0
    if cells < 1:
        raise ValueError(f"cells must be an integer >= 1, got {arg['cells']!r}")
    which = list(range(cells))
    if arg['cell'] != '':
        if arg['cell'] not in map(str, which):
            raise ValueError(f"cell must be one of 0..{cells - 1}, got {arg['cell']!r}")
        which = [int(arg['cell'])]
    base = graph.namespace_of(arg['namespace'])
    person = arg['person'] if arg['person'] not in ('', 'none') else None
    seed = None
    if arg['person_seed'] != '':
        try:
            seed = int(arg['person_seed'])
        except ValueError:
            raise ValueError(
                f"person_seed must be an integer, got {arg['person_seed']!r}") from None
    link = arg['monitor_link']  # checked by graph.job_nodes
    people = graph.person_params(person, seed, link)
    out = []
    for k in which:
        namespace = base + graph.cell_namespace(k, cells)
        upstream = [base + ns for ns in graph.line_upstream(k, cells)]
        line = graph.line_params(k, cells)
        placed = {'namespace': namespace, 'remappings': list(
            graph.remaps(namespace, upstream).items())} if namespace else {}
        for spec in graph.job_nodes(automation=arg['mode'] != 'idle',
                                    viewer=arg['viewer'].lower() == 'true' and k == 0,
                                    transforms=rviz or arg['tf'].lower() == 'true',
                                    people=person is not None, monitor_link=link):
            files = [os.path.join(share, 'config', f'{c}.yaml') for c in spec.configs]
            own = dict(params.get(spec.name, {}), **line.get(spec.name, {}),
                       **people.get(spec.name, {}))
            values = {key: _typed(v) for key, v in own.items()}
            out.append(Node(package=PACKAGE, executable=spec.name, name=spec.name,
                            output='screen',
                            parameters=files + [dict(values, use_sim_time=True)], **placed))
        if rviz and k == 0:
            out.append(Node(package='rviz2', executable='rviz2', name='rviz2', output='screen',
                            arguments=['-d', os.path.join(share, 'config', 'cell.rviz')],
                            parameters=[{'use_sim_time': True}], **placed))
    return out


def generate_launch_description():
    """Declare the arguments; the nodes follow from them at launch time."""
    return LaunchDescription(
        [DeclareLaunchArgument(k, default_value=v) for k, v in ARGUMENTS.items()]
        + [OpaqueFunction(function=nodes)])
