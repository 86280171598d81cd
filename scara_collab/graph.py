"""The cell's ROS graph, described once, as data (no rclpy here).

Every node of the cell is one :class:`NodeSpec`: its name (the node name, the console script
and the log file), the entry point of its executable, the class that builds it (for running
several nodes in one process), the ``config/*.yaml`` files whose keys it declares as
parameters, and what "ready" means for it on the graph. :func:`job_params` says what a job
mode sets on which node, :func:`ros_args` is the one ``--ros-args`` builder. The topics the
nodes publish are :data:`TOPICS` (name, type and the publisher's QoS, one of the named profiles
of :data:`QOS`, which :mod:`scara_collab.nodes.qos` turns into rclpy profiles); the run
recorder and its MCAP log subscribe what :func:`topics` lists.

Names are relative, so a namespace moves a whole cell: every node of a cell runs in the cell's
namespace (none by default: the root, the names below) with the remaps :func:`remaps` gives,
:func:`ros_args` and :func:`node_args` put both on a node's command line, and :func:`resolve`
says what a relative name becomes in a namespace (``joint_states`` in ``/cell_1`` is
``/cell_1/joint_states``). ``/clock`` is the exception: rclpy's time source always subscribes
the absolute ``/clock``, so every node of a namespaced cell gets ``/clock:=<ns>/clock`` and the
bridge publishes the relative ``clock``. Two cells under ``/cell_0`` and ``/cell_1`` share a
ROS domain without hearing each other (rcl's own ``/rosout`` and ``/parameter_events`` stay
shared).

Everything that starts the graph reads this module: the launcher (one process per node, or
all in one container), ``setup.py`` (the console scripts, so ``ros2 run`` has the same
names), the in-process graph of the benchmarks (:func:`benchmarks.job_in_process.run_job`) and
the tests' graphs (``test/ros_harness.py``). In launch order::

    pybullet_bridge      clock, joint_states, trajectories, belt, gripper    ready: service
    left_planner         scara_left/target(_trajectory) -> trajectory        ready: subscribed
    right_planner        scara_right/target(_trajectory) -> trajectory       ready: subscribed
    replication_manager  collab/target(_trajectory) -> both arms, mirrored   ready: service
    collision_monitor    arm-to-arm distance, e-stop                         ready: service
    automation_manager   the sorting job                                     ready: service
    separation_monitor   scans -> each arm's speed factor (a person, topics) ready: subscribed
    cell_viewer          live 3D view (optional)                             ready: page answers

>>> [n.name for n in job_nodes()][:3]
['pybullet_bridge', 'left_planner', 'right_planner']
>>> job_params('mirrored')['replication_manager']
{'enabled': 'true'}
>>> ros_args((), {'mode': 'joint'}, config_dir=Path('/cfg'))
['--ros-args', '-p', 'use_sim_time:=true', '-p', 'mode:=joint']
>>> node_args('/cell_1')
['--ros-args', '-r', '__ns:=/cell_1', '-r', '/clock:=/cell_1/clock']
>>> topic('emergency_stop'), topic('emergency_stop', namespace='/cell_1').name
(Topic(name='/emergency_stop', type='std_msgs/msg/Bool', qos='latched'), '/cell_1/emergency_stop')
>>> QOS['latched']
Qos(depth=1, latched=True)
"""
from dataclasses import dataclass, field, replace
import importlib
from pathlib import Path
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

PACKAGE = 'scara_collab'
JOB_MODES = ('single', 'collaborative', 'mirrored')
#: where the speed and separation monitor runs with a person: in the bridge's process, handed
#: the scans and states and handing back the factors directly (a real cell's safety wiring),
#: or as a node of its own over topics (scara_collab.nodes.bridge_people)
MONITOR_LINKS = ('wired', 'topics')
LAUNCH_MODES = ('idle',) + JOB_MODES  # idle: the graph without the sorting job
ROBOTS = ('scara_left', 'scara_right')  # the arms' namespaces (config/cell.yaml), leader first
CLOCK = 'clock'  # the bridge's sim clock, relative: a cell's clock is in its namespace
SIM_TIME_CLOCK = '/clock'  # what rclpy's time source subscribes (use_sim_time), always absolute


def namespace_of(namespace: Optional[str]) -> str:
    """Return a cell namespace in one form: ``''`` for the root, else ``'/a/b'``.

    >>> namespace_of(None), namespace_of('/'), namespace_of('cell_1'), namespace_of('/cell_1/')
    ('', '', '/cell_1', '/cell_1')

    :raises ValueError: for a name rcl would refuse (``~``, spaces, empty parts, ...).
    """
    ns = (namespace or '').strip().strip('/')
    if not ns:
        return ''
    for part in ns.split('/'):
        if not part or part[0].isdigit() or not all(c.isalnum() or c == '_' for c in part):
            raise ValueError(f'not a ROS namespace: {namespace!r} (want e.g. /cell_1)')
    return '/' + ns


def resolve(name: str, namespace: Optional[str] = '') -> str:
    """Return the absolute name a relative ``name`` has in ``namespace`` (absolute: unchanged).

    >>> resolve('joint_states'), resolve('joint_states', '/cell_1'), resolve('/rosout', 'cell_1')
    ('/joint_states', '/cell_1/joint_states', '/rosout')
    """
    if name.startswith('/'):
        return name
    return f'{namespace_of(namespace)}/{name}'


def remaps(namespace: Optional[str] = '',
           upstream: Sequence[str] = ()) -> Dict[str, str]:
    """Return the remaps every node of a cell in ``namespace`` needs (none in the root).

    rclpy's time source subscribes the absolute ``/clock`` (:data:`SIM_TIME_CLOCK`); in a
    namespace it must hear the cell's own clock. In a line of cells, the cells ``upstream``
    (their namespaces, nearest first) hand items on: the nearest one's ``line/handoff`` is
    this cell's ``line/upstream``, the one before's its ``line/upstream2`` (should the
    nearest one die).

    >>> remaps(), remaps('cell_1')
    ({}, {'/clock': '/cell_1/clock'})
    >>> remaps('cell_2', upstream=['/cell_1', '/cell_0'])['line/upstream2']
    '/cell_0/line/handoff'
    """
    ns = namespace_of(namespace)
    out = {SIM_TIME_CLOCK: resolve(CLOCK, ns)} if ns else {}
    for name, cell in zip((LINE_UPSTREAM, LINE_UPSTREAM2), upstream):
        out[name] = resolve(LINE_HANDOFF, cell)
    return out


def node_args(namespace: Optional[str] = '', upstream: Sequence[str] = ()) -> List[str]:
    """Return the ``--ros-args`` that put a node into ``namespace`` ([] for the root)."""
    ns = namespace_of(namespace)
    out = ['--ros-args', '-r', f'__ns:={ns}'] if ns else ['--ros-args']
    for source, target in remaps(ns, upstream).items():
        out += ['-r', f'{source}:={target}']
    return out if len(out) > 1 else []


# --- a line of cells (scara_collab.core.line) -------------------------------------------------
LINE_HANDOFF = 'line/handoff'    # what a cell hands on, with its frontier (pybullet_bridge)
LINE_UPSTREAM = 'line/upstream'  # the upstream cell's line/handoff, remapped
LINE_UPSTREAM2 = 'line/upstream2'  # the handoffs of the cell before that (if the next dies)


def cell_namespace(k: int, cells: int) -> str:
    """Return the namespace of cell ``k`` of a line of ``cells`` (the root for a lone cell).

    >>> cell_namespace(0, 1), cell_namespace(0, 3), cell_namespace(2, 3)
    ('', '/cell_0', '/cell_2')
    """
    if not 0 <= k < cells:
        raise ValueError(f'cell {k} is not in a line of {cells}')
    return f'/cell_{k}' if cells > 1 else ''


def line_upstream(k: int, cells: int) -> List[str]:
    """Return the namespaces of the two cells before cell ``k`` (nearest first), if any.

    >>> line_upstream(0, 3), line_upstream(1, 3), line_upstream(2, 3)
    ([], ['/cell_0'], ['/cell_1', '/cell_0'])
    """
    cell_namespace(k, cells)
    return [cell_namespace(j, cells) for j in (k - 1, k - 2) if j >= 0]


def line_params(k: int, cells: int) -> Dict[str, Dict[str, str]]:
    """Return the parameters of cell ``k`` of a line of ``cells``, per node (none when alone).

    Every cell but the first is fed by the one upstream (its own feed off); every cell but the
    last hands on.

    >>> line_params(1, 3)['pybullet_bridge']
    {'line_cell': '1', 'line_upstream': 'true', 'line_downstream': 'true', 'feed_interval': '0.0'}
    """
    cell_namespace(k, cells)
    if cells == 1:
        return {}
    bridge = {'line_cell': str(k), 'line_upstream': str(k > 0).lower(),
              'line_downstream': str(k < cells - 1).lower()}
    if k > 0:
        bridge['feed_interval'] = '0.0'
    return {'pybullet_bridge': bridge,
            'automation_manager': {'line_cell': str(k), 'line_cells': str(cells)}}


def fed(k: int, cells: int) -> bool:
    """Return True if cell ``k`` of a line of ``cells`` has a feed of its own (the first)."""
    return 'feed_interval' not in line_params(k, cells).get('pybullet_bridge', {})


@dataclass(frozen=True)
class Readiness:
    """What a node shows on the graph once it is ready.

    ``kind``: ``'subscribed'`` (the node subscribes to the topic ``name``), ``'published'``
    (it publishes it), ``'service'`` (the service ``name`` of type ``srv_type``,
    ``'package/srv/Type'``, answers), ``'page'`` (subscribed to ``name`` and its web page
    answers on the node's ``port`` parameter). ``name`` is relative (:func:`resolve`).
    """

    kind: str
    name: str = ''
    srv_type: str = ''

    def describe(self, node: str, params: Mapping[str, str], namespace: str = '') -> str:
        """Return what the launcher waits for, in words (for its console lines)."""
        name = resolve(self.name, namespace)
        if self.kind == 'subscribed':
            return f'node {node} subscribed to {name}'
        if self.kind == 'service':
            return f'service {name}'
        if self.kind == 'published':
            return f'node {node} publishes {name}'
        return (f'node {node} subscribed to {name}, live 3D view on '
                f'http://localhost:{params.get("port", "?")}')


@dataclass(frozen=True)
class NodeSpec:
    """One node of the cell (see the module docstring)."""

    name: str                  # node name = console script = log file name
    entry: str                 # the executable: 'module:function'
    component: str             # the class that builds the node in-process: 'module:Class'
    configs: Tuple[str, ...]   # config/<name>.yaml files whose keys it declares
    ready: Readiness
    fixed: Mapping[str, str] = field(default_factory=dict)  # the class's own keywords
    optional: bool = False     # started only when asked for (the viewer, transforms)
    lockstep: bool = False     # answers clock on sim/lockstep (scara_collab.nodes.lockstep)
    guard: bool = False        # the arms hold while it is silent (bridge lockstep_guards)

    def node_class(self) -> type:
        """Return the class that builds the node (imported on call)."""
        module, cls = self.component.split(':')
        return getattr(importlib.import_module(module), cls)

    def build(self, wrap: Optional[Callable[[type], type]] = None, **kwargs):
        """Build the node in this process: ``Class(**fixed, **kwargs)`` (``context``, ...).

        :param wrap: turns the class into the one built (the launcher's ``--fault``:
            :func:`scara_collab.run.faults.hook`); None builds the class itself.
        """
        cls = self.node_class()
        return (cls if wrap is None else wrap(cls))(**self.fixed, **kwargs)


def _n(module: str) -> str:
    return f'{PACKAGE}.nodes.{module}'


NODES: Tuple[NodeSpec, ...] = (
    NodeSpec('pybullet_bridge', _n('pybullet_bridge:main'), _n('pybullet_bridge:PyBulletBridge'),
             ('simulation', 'controllers', 'people'),
             Readiness('service', 'sim/resume', 'std_srvs/srv/Trigger')),
    NodeSpec('left_planner', _n('planner:main_left'), _n('planner:Planner'), ('controllers',),
             Readiness('subscribed', f'{ROBOTS[0]}/target'),
             {'robot': ROBOTS[0], 'node_name': 'left_planner'}, lockstep=True),
    NodeSpec('right_planner', _n('planner:main_right'), _n('planner:Planner'), ('controllers',),
             Readiness('subscribed', f'{ROBOTS[1]}/target'),
             {'robot': ROBOTS[1], 'node_name': 'right_planner'}, lockstep=True),
    NodeSpec('replication_manager', _n('replication_manager:main'),
             _n('replication_manager:ReplicationManager'), (),
             Readiness('service', 'replication_manager/enable', 'std_srvs/srv/SetBool'),
             lockstep=True),
    NodeSpec('collision_monitor', _n('collision_monitor:main'),
             _n('collision_monitor:CollisionMonitor'), (),
             Readiness('service', 'collision_monitor/clear', 'std_srvs/srv/Trigger'),
             lockstep=True, guard=True),
    NodeSpec('automation_manager', _n('automation_manager:main'),
             _n('automation_manager:AutomationManager'), ('automation', 'controllers', 'people'),
             Readiness('service', 'automation_manager/start', 'std_srvs/srv/Trigger'),
             lockstep=True),
    NodeSpec('separation_monitor', _n('separation_monitor:main'),
             _n('separation_monitor:SeparationMonitorNode'), ('people',),
             Readiness('subscribed', 'safety_scanner/scan'), optional=True, lockstep=True,
             guard=True),
    NodeSpec('cell_viewer', _n('cell_viewer:main'), _n('cell_viewer:CellViewer'), (),
             Readiness('page', 'joint_states'), optional=True),
    NodeSpec('state_publisher', _n('state_publisher:main'),
             _n('state_publisher:StatePublisher'), (),
             Readiness('published', 'robot_description'), optional=True),
)
BY_NAME: Dict[str, NodeSpec] = {n.name: n for n in NODES}
BY_ENTRY: Dict[str, NodeSpec] = {n.entry: n for n in NODES}


@dataclass(frozen=True)
class Qos:
    """A named QoS profile, as data: keep the last ``depth`` messages, reliable.

    ``latched``: transient local, so a late subscriber gets the last value; else volatile.
    """

    depth: int
    latched: bool = False


#: the graph's QoS profiles by name (:mod:`scara_collab.nodes.qos` makes the rclpy profiles)
QOS: Dict[str, Qos] = {
    'default': Qos(10),                # rclpy's usual depth: states, targets, statuses
    'latest': Qos(1),                  # only the newest matters (a backlog would be stale)
    'events': Qos(100),                # a stream to keep whole (events, move statuses)
    'latched': Qos(1, latched=True),   # latched state (/emergency_stop)
    'recording': Qos(200),             # a recorder's queue: a burst while the launcher is busy
}


@dataclass(frozen=True)
class Topic:
    """One topic of the graph: name, full type name, the publisher's QoS profile.

    In :data:`TOPICS` and :data:`ROBOT_TOPICS` the names are relative (``/rosout``, rcl's,
    excepted); :func:`topics` resolves them in a cell's namespace.
    """

    name: str
    type: str                  # 'pkg/msg/Type'
    qos: str = 'default'       # a name of QOS

    @property
    def latched(self) -> bool:
        """Return True if the topic is latched: a late subscriber gets the last value."""
        return QOS[self.qos].latched


_STATUS = 'diagnostic_msgs/msg/DiagnosticStatus'
_POINT = 'geometry_msgs/msg/PointStamped'
_TRAJECTORY = 'trajectory_msgs/msg/JointTrajectory'
#: the cell-wide topics the nodes publish (not sim/lockstep: scara_collab.nodes.lockstep)
TOPICS: Tuple[Topic, ...] = (
    Topic(CLOCK, 'rosgraph_msgs/msg/Clock'),                       # pybullet_bridge
    Topic('joint_states', 'sensor_msgs/msg/JointState'),
    Topic('conveyor/items', 'visualization_msgs/msg/MarkerArray'),
    Topic('conveyor/events', _STATUS, 'events'),
    Topic(LINE_HANDOFF, _STATUS, 'events'),                        # ... in a line of cells
    Topic('collab/target', _POINT),                                # automation_manager
    Topic('collab/target_trajectory', _TRAJECTORY),                # ... its plan of a move
    Topic('collision_monitor/min_distance', 'std_msgs/msg/Float64'),
    Topic('collision_monitor/status', _STATUS),
    Topic('collision_monitor/stops', _STATUS, 'events'),           # protective / emergency
    Topic('collision_monitor/capsules', 'visualization_msgs/msg/MarkerArray'),
    Topic('replication_manager/mirror_error', 'std_msgs/msg/Float64'),
    Topic('replication_manager/status', _STATUS),
    Topic('automation_manager/stats', _STATUS),
    Topic('emergency_stop', 'std_msgs/msg/Bool', 'latched'),       # collision_monitor
    Topic('protective_stop', 'std_msgs/msg/Bool', 'latched'),      # collision_monitor
    Topic('diagnostics', 'diagnostic_msgs/msg/DiagnosticArray'),   # bridge, monitor, managers
    Topic('robot_description', 'std_msgs/msg/String', 'latched'),  # state_publisher
    Topic('safety_scanner/scan', 'sensor_msgs/msg/LaserScan'),     # bridge, with a person
    Topic('safety_joint_states', 'sensor_msgs/msg/JointState'),    # ... at each scan
    Topic('planned_velocity', 'sensor_msgs/msg/JointState'),       # ... at each scan
    Topic('person/poses', 'geometry_msgs/msg/PoseArray'),          # ... ground truth,
    Topic('person/markers', 'visualization_msgs/msg/MarkerArray'),  # for records and views
    Topic('person/truth', _STATUS),                                # ... against each arm
    Topic('separation_monitor/status', _STATUS),                   # separation_monitor
    Topic('separation_monitor/markers', 'visualization_msgs/msg/MarkerArray'),  # ... for RViz
    Topic('/rosout', 'rcl_interfaces/msg/Log', 'events'),  # rcl's (records.bag.ROSOUT_QOS)
)
#: the topics of each robot, ``{robot}`` standing for its namespace
ROBOT_TOPICS: Tuple[Topic, ...] = (
    Topic('{robot}/target', _POINT),                               # the job or the mirror
    Topic('{robot}/target_trajectory', _TRAJECTORY),               # the job's plan of a move
    Topic('{robot}/joint_trajectory', _TRAJECTORY),                # its planner
    Topic('{robot}/planned_path', 'nav_msgs/msg/Path'),
    Topic('{robot}/planner_status', _STATUS, 'events'),
    Topic('{robot}/execution_status', _STATUS, 'events'),          # pybullet_bridge
    Topic('{robot}/trajectory_clock', _STATUS, 'events'),          # ... while speeds scale
    Topic('{robot}/speed_scaling', 'std_msgs/msg/Float64', 'latched'),  # separation_monitor
)


def topics(robots: Sequence[str] = ROBOTS, namespace: Optional[str] = '') -> List[Topic]:
    """Return the topics of a run: :data:`TOPICS`, then :data:`ROBOT_TOPICS` per robot.

    The names are absolute, resolved in the cell's ``namespace`` (:func:`resolve`).

    :param robots: the robot namespaces, e.g. ``('scara_left', 'scara_right')``.
    :param namespace: the cell's namespace (default: the root).
    """
    return [replace(t, name=resolve(t.name, namespace)) for t in TOPICS] + [
        replace(t, name=resolve(t.name.format(robot=robot), namespace))
        for robot in robots for t in ROBOT_TOPICS]


def topic(name: str, robots: Sequence[str] = ROBOTS, namespace: Optional[str] = '') -> Topic:
    """Return the topic called ``name`` (relative, or absolute), resolved in ``namespace``.

    :raises KeyError: if the graph has no such topic.
    """
    full = resolve(name, namespace)
    try:
        return next(t for t in topics(robots, namespace) if t.name == full)
    except StopIteration:
        raise KeyError(f'no topic {full!r} in the graph') from None


def message_class(type_name: str):
    """Return the Python class of a message type (imported on call, like :meth:`NodeSpec.build`).

    :param type_name: ``'pkg/msg/Type'`` or ``'pkg/Type'``, e.g. ``'std_msgs/msg/Bool'``.
    """
    parts = type_name.split('/')
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[1] != 'msg'):
        raise ValueError(f'not a ROS 2 message type name: {type_name!r} (want pkg/msg/Type)')
    return getattr(importlib.import_module(f'{parts[0]}.msg'), parts[-1])


def node(name: str) -> NodeSpec:
    """Return the node called ``name``.

    :raises KeyError: with the known names, if there is none.
    """
    try:
        return BY_NAME[name]
    except KeyError:
        raise KeyError(f'no node {name!r} in the graph; one of: {", ".join(BY_NAME)}') from None


def job_nodes(automation: bool = True, viewer: bool = False,
              transforms: bool = False, people: bool = False,
              monitor_link: str = 'wired') -> List[NodeSpec]:
    """Return the nodes a run starts, in launch order.

    :param automation: with the job (the automation manager).
    :param viewer: with the live 3D view (``cell_viewer``).
    :param transforms: with ``state_publisher`` (``/robot_description``, ``/tf``).
    :param people: a person in the cell (the bridge simulates the person and the safety
        scanners).
    :param monitor_link: with a person, where the speed and separation monitor runs: in the
        bridge's process (``wired``: no node to start) or as ``separation_monitor`` of its own,
        over topics (``topics``) (:data:`MONITOR_LINKS`).

    >>> [n.name for n in job_nodes(people=True)][-1]
    'automation_manager'
    >>> [n.name for n in job_nodes(people=True, monitor_link='topics')][-1]
    'separation_monitor'
    """
    if monitor_link not in MONITOR_LINKS:
        raise ValueError(f'monitor_link must be one of {MONITOR_LINKS}, got {monitor_link!r}')
    wanted = {'cell_viewer': viewer, 'state_publisher': transforms,
              'separation_monitor': people and monitor_link == 'topics'}
    return [n for n in NODES if (automation or n.name != 'automation_manager')
            and (not n.optional or wanted.get(n.name, False))]


def lockstep_expect(nodes: Sequence[NodeSpec]) -> List[str]:
    """Return the bridge's ``lockstep_expect`` for a run of ``nodes``: those that answer.

    Relative names: the bridge resolves them in its own namespace.

    >>> lockstep_expect(job_nodes())[:2]
    ['left_planner', 'right_planner']
    """
    return [n.name for n in nodes if n.lockstep]


def lockstep_guards(nodes: Sequence[NodeSpec]) -> List[str]:
    """Return the bridge's ``lockstep_guards`` for a run of ``nodes``: the arms hold without them.

    >>> lockstep_guards(job_nodes(people=True, monitor_link='topics'))
    ['collision_monitor', 'separation_monitor']
    """
    return [n.name for n in nodes if n.guard]


def person_params(person: Optional[str], seed: Optional[int],
                  monitor_link: str = 'wired') -> Dict[str, Dict[str, str]]:
    """Return the parameters of a run with a person, per node (none without one).

    The bridge simulates the person ``person`` (a scenario's name or a YAML file's path,
    :func:`scara_collab.sim.person_scenarios.scenario`) seeded by ``seed``, with the safety
    scanners, and runs the separation monitor in its process (``monitor_link`` ``wired``), or
    holds the arms while the separation monitor node is silent, as while the collision monitor
    is (``topics``: :func:`lockstep_guards`).

    >>> person_params(None, 7)
    {}
    >>> person_params('inlet', 7)['pybullet_bridge']['person_seed']
    '7'
    >>> person_params('inlet', 7)['pybullet_bridge']['monitor_link']
    'wired'
    >>> person_params('inlet', 7, 'topics')['pybullet_bridge']['lockstep_guards']
    "['collision_monitor','separation_monitor']"
    """
    if person is None:
        return {}
    guards = lockstep_guards(job_nodes(people=True, monitor_link=monitor_link))
    bridge = {'person': person, 'monitor_link': monitor_link,
              'lockstep_guards': param_value(guards)}
    if seed is not None:
        bridge['person_seed'] = str(int(seed))
    return {'pybullet_bridge': bridge}


#: s, the planners' ``send_margin`` in real time: the planning lead, as in lockstep. A
#: trajectory reaches the bridge within milliseconds, but beside a CPU hog a shorter margin
#: lets trajectories start late, and a late start can bring the arms closer than the safety
#: margin (docs/limits.md)
REALTIME_SEND_MARGIN = 0.05


def job_params(mode: str, lockstep: bool = True) -> Dict[str, Dict[str, str]]:
    """Return the parameters a launch mode sets, per node name (string values).

    Mirrored mode feeds items in mirror pairs and slows both arms alike for a person (the
    bridge's ``speed_scaling`` ``cell``); the replication manager follows
    ``/joint_states`` only where mirrored moves are asked for (mirrored mode, and the idle
    graph a user drives by hand); the automation manager runs the mode's job. Without
    ``lockstep`` the clock waits for nobody (the bridge's ``lockstep_window`` 0), as on
    hardware, the planners send their moves :data:`REALTIME_SEND_MARGIN` ahead, and the
    automation manager decides on the newest joint state instead of waiting for the state of
    its tick's instant (``state_sync``), the separation monitor on the scans it has instead of
    waiting for those of a scan instant (``scan_sync``).

    >>> job_params('collaborative', lockstep=False)['left_planner']
    {'send_margin': '0.05'}

    :raises ValueError: for a mode not in :data:`LAUNCH_MODES`.
    """
    if mode not in LAUNCH_MODES:
        raise ValueError(f'mode must be one of {", ".join(LAUNCH_MODES)}, got {mode!r}')
    out: Dict[str, Dict[str, str]] = {n.name: {} for n in NODES}
    if mode == 'mirrored':  # a person slows both arms of a mirrored pair alike
        out['pybullet_bridge'].update(feed_pattern='mirror_pairs', speed_scaling='cell')
    out['replication_manager']['enabled'] = str(mode in ('mirrored', 'idle')).lower()
    if mode != 'idle':
        out['automation_manager']['mode'] = mode
    if not lockstep:
        out['pybullet_bridge']['lockstep_window'] = '0.0'
        for planner in (n.name for n in NODES if n.component == _n('planner:Planner')):
            out[planner]['send_margin'] = repr(REALTIME_SEND_MARGIN)
        out['automation_manager']['state_sync'] = 'false'
        out['separation_monitor']['scan_sync'] = 'false'
    return out


def param_value(value) -> str:
    """Return ``value`` as a ``-p key:=value`` string (lists as a string array)."""
    if isinstance(value, (list, tuple)):
        return '[' + ','.join(f"'{v}'" for v in value) + ']'
    if isinstance(value, bool):
        return str(value).lower()
    return str(value)


def ros_args(configs: Sequence[str] = (), params: Optional[Mapping[str, object]] = None,
             sim_time: bool = True, config_dir: Optional[Path] = None,
             namespace: Optional[str] = '', upstream: Sequence[str] = ()) -> List[str]:
    """Return a node's ``--ros-args``: sim time, ``--params-file`` per config, ``-p`` per param.

    In a ``namespace`` also the node's namespace and the cell's remaps (:func:`node_args`).

    :param configs: ``config/<name>.yaml`` files, in order (later ones override).
    :param params: single parameters, set after the files.
    :param config_dir: where the files are (default: the package's config folder).
    :param namespace: the cell's namespace (default: the root, no remaps).
    :param upstream: in a line of cells, the namespaces of the cells upstream, nearest first
        (:func:`remaps`).
    """
    if config_dir is None and configs:
        from scara_collab.core.paths import config_dir as package_config_dir
        config_dir = package_config_dir()
    out = ['--ros-args', '-p', f'use_sim_time:={"true" if sim_time else "false"}']
    out += node_args(namespace, upstream)[1:]
    for name in configs:
        out += ['--params-file', str(Path(config_dir) / f'{name}.yaml')]
    for key, value in (params or {}).items():
        out += ['-p', f'{key}:={param_value(value)}']
    return out


def console_scripts() -> List[str]:
    """Return the ``setup.py`` console scripts: one executable per node, named like it."""
    return [f'{n.name} = {n.entry}' for n in NODES]
