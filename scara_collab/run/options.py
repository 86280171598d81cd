"""The launcher's options: one frozen value, built and checked once from its command line.

:func:`parse_options` parses ``launch_cell.py``'s arguments, refuses a bad combination with a
usage error (exit status 2) and fills in what the command line leaves to the configuration
(the real-time factors, the bridge's ``step_chunk``, the cell's namespace), so that
:class:`LaunchOptions` holds the run's settings as the launcher, its stages and the line
launcher read them. The options themselves are listed in the README's launcher section.
"""
import argparse
from dataclasses import dataclass
from pathlib import Path
import socket
from typing import Optional, Sequence, Tuple

from scara_collab import graph
from scara_collab.core.config import load_config

RUN_MODES = graph.LAUNCH_MODES
FAST_CHUNK = 0.02  # s: with the bridge's 2 ms tick, up to 10x real time
VIEWER_PORT = 8080  # --viewer without a port


@dataclass(frozen=True)
class LaunchOptions:
    """One run's settings, checked and resolved (:func:`parse_options`).

    Times are sim seconds unless they say wall; real-time factors are 0 for unthrottled.
    """

    mode: str                        # a mode of graph.LAUNCH_MODES; idle: no job
    duration: float                  # sim s of job before a clean stop
    rtf: float                       # real-time factor once the job runs
    launch_rtf: float                # while the job is stopped at the end (= rtf: no hold)
    step_chunk: Optional[float]      # the bridge's step_chunk (None: its default)
    lockstep: bool                   # sim time waits for every node
    namespace: str                   # the cell's namespace, '' = the root
    cells: int                       # cells in the line (1: a lone cell)
    line_cell: Optional[int]         # the one cell of the line run here
    discovery_server: Optional[int]  # run a discovery server on this UDP port (0: any)
    one_process: bool                # every node in one process (run.container)
    gui: bool                        # PyBullet's own window
    viewer: Optional[int]            # the live view's port
    tf: bool                         # also the state publisher
    output: Optional[Path]           # the run folder (None: runs/<timestamp>_<mode>)
    profile: Optional[str]           # link profile (None: config/cell.yaml)
    seed: Optional[int]              # item feed seed (None: config/simulation.yaml)
    feed_interval: Optional[float]   # sim s between items (None: config/simulation.yaml)
    faults: Tuple[str, ...]          # fault specs (scara_collab.run.faults)
    quiet: bool                      # errors and the report only
    ready_timeout: float             # wall s a stage may take to become ready
    stall_timeout: float             # wall s sim time may stand still
    silent_timeout: float            # wall s a node may leave a /clock unanswered
    plots: bool                      # the PNG plots of the run folder
    record: bool                     # run.mcap
    animation: bool                  # run.gif after the run
    person: Optional[str] = None     # a person's scenario: a built-in name or a YAML file's
    #                                  absolute path (None: no person, no scanner, no monitor)
    person_cell: Optional[int] = None  # with cells > 1: the one cell with the person (None: all)
    person_seed: Optional[int] = None  # the person's seed (--seed, else the item feed's)
    monitor_link: str = 'wired'        # with a person: the monitor in the bridge's process, or
    #                                  a node of its own over topics (graph.MONITOR_LINKS)

    @property
    def cell(self) -> int:
        """Return this cell's place in its line (0 for a lone cell)."""
        return 0 if self.line_cell is None else self.line_cell

    @property
    def cell_person(self) -> Optional[str]:
        """Return the person's scenario in this cell (:attr:`cell`), or None for none."""
        if self.person_cell is not None and self.person_cell != self.cell:
            return None
        return self.person

    @property
    def lockstep_name(self) -> str:
        """Return ``'on'`` or ``'off'``, as ``--lockstep`` and ``summary.json`` say it."""
        return 'on' if self.lockstep else 'off'


def port_free(port: int) -> bool:
    """Return ``True`` if a TCP server could listen on ``port`` (all interfaces) now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the viewer's server
        try:
            s.bind(('', port))
        except OSError:
            return False
    return True


def parser() -> argparse.ArgumentParser:
    """Return the command line of ``scripts/launch_cell.py``."""
    profiles = sorted(load_config('cell')['profiles'])
    p = argparse.ArgumentParser(
        prog='launch_cell.py',
        description='Start the scara_collab graph (bridge, planners, replication manager, '
        'collision monitor, automation manager) on sim time, run the sorting job, record '
        'and report it.')
    p.add_argument('--mode', choices=RUN_MODES, default='collaborative',
                   help='job mode; idle = the graph without the automation job '
                   '(default: %(default)s)')
    p.add_argument('--duration', type=float, default=180.0, metavar='SIM_SECONDS',
                   help='sim seconds of job before a clean stop (default: %(default)s)')
    p.add_argument('--rtf', type=float, default=None, metavar='FACTOR',
                   help='real-time factor of the bridge, 0 = as fast as possible '
                   '(default: config/simulation.yaml)')
    p.add_argument('--launch-rtf', type=float, default=1.0, metavar='FACTOR',
                   help='real-time factor while the job is stopped at the end, at most '
                   '--rtf (the graph starts paused); 0 = stay at --rtf (default: %(default)s)')
    p.add_argument('--step-chunk', type=float, default=None, metavar='SIM_SECONDS',
                   help='bridge step_chunk: sim time stepped per 2 ms bridge tick, which '
                   'bounds the real-time factor at step_chunk / 0.002 (default: '
                   f'{FAST_CHUNK} when the bridge is released to more than 4x, else the '
                   'bridge default)')
    p.add_argument('--lockstep', choices=('on', 'off'), default='on',
                   help='on: sim time waits for every node (lockstep_window, a repeatable '
                   'run); off: real time, the clock waits for nobody, as on hardware or in '
                   'Gazebo (bridge lockstep_window 0; the nodes still answer for the '
                   'liveness watch and the arms still hold without the collision monitor) '
                   '(default: %(default)s)')
    p.add_argument('--namespace', default='', metavar='NS',
                   help='run the cell under the namespace NS (e.g. /cell_1): every node, topic '
                   'and service of it, its clock and its lockstep, so cells in different '
                   'namespaces share a ROS domain (default: the root namespace)')
    p.add_argument('--cells', type=int, default=1, metavar='N',
                   help='a line of N cells along one belt, cell k under /cell_k with its own '
                   'processes and run folder <output>/cell_k; only cell 0 is fed, each cell '
                   'hands on what passes its belt to the next (scara_collab.run.line_launcher; '
                   'default: %(default)s, one cell in the root namespace)')
    p.add_argument('--line-cell', type=int, default=None, metavar='K',
                   help='with --cells N: run only cell K of the line, here (one machine per '
                   'cell, every machine on the same ROS domain or discovery server; give the '
                   'cells downstream a --stall-timeout long enough for the upstream ones to '
                   'start)')
    p.add_argument('--discovery-server', type=int, nargs='?', const=0, default=None,
                   metavar='PORT', help="run Fast DDS's discovery server on this host (UDP "
                   'PORT, default a free one) for the run, every node its client, instead of '
                   'simple discovery; with ROS_DISCOVERY_SERVER set, that server is used '
                   'without this option (scara_collab.run.discovery)')
    p.add_argument('--one-process', action='store_true',
                   help='run every node in one process on one executor (a component '
                   'container, scara_collab.run.container) instead of one process per node')
    p.add_argument('--gui', action='store_true', help='PyBullet GUI (bridge gui:=true)')
    p.add_argument('--viewer', type=int, nargs='?', const=VIEWER_PORT, default=None,
                   metavar='PORT', help='also start the live 3D view (cell_viewer) on '
                   f'http://localhost:PORT (default port: {VIEWER_PORT})')
    p.add_argument('--tf', action='store_true',
                   help='also start state_publisher: /robot_description, and /tf and '
                   '/tf_static where tf2_msgs is installed (./scripts/build_interfaces)')
    p.add_argument('--output', type=Path, default=None, metavar='DIR',
                   help='run folder (default: runs/<timestamp>_<mode>)')
    p.add_argument('--profile', choices=profiles, default=None,
                   help='link profile (default: config/cell.yaml)')
    p.add_argument('--seed', type=int, default=None, help='item feed seed (bridge item_seed)')
    p.add_argument('--feed-interval', type=float, default=None, metavar='S',
                   help='sim seconds between items once the job runs (default: '
                   'config/simulation.yaml feed_interval); below ~1.5 s the feed is faster '
                   'than the arms can take (capacity runs)')
    p.add_argument('--person', default=None, metavar='SCENARIO|FILE',
                   help='a person walks through the cell: a built-in scenario (pass-by, inlet, '
                   'middle, random; nobody: the scanners and the monitor with no person) or a '
                   'YAML file of waypoints (docs/people.md); the bridge simulates the person and '
                   "the safety scanners, the separation monitor scales the arms' speeds; seeded "
                   'by --seed (default: none, no person)')
    p.add_argument('--person-cell', type=int, default=None, metavar='K',
                   help='with --cells N and --person: the person in cell K only (default: in '
                   'every cell)')
    p.add_argument('--monitor-link', choices=graph.MONITOR_LINKS, default='wired',
                   help="with --person: the separation monitor runs in the bridge's process, "
                   'handed the scans and states and handing back the speed factors directly '
                   'as a safety controller wired to its scanner and robot would (wired, the '
                   'default), or as a node of its own that takes them over topics (topics)')
    p.add_argument('--fault', action='append', default=[], metavar='SPEC',
                   help='inject a fault, e.g. drop:/scara_left/gripper:2 (lose the first 2 '
                   'gripper responses), delay:/scara_right/planner_status:3:0.5, '
                   'drop:/automation_manager/start:1, latency:/joint_states:0.02:0.01 (every '
                   'message 20 +- 10 ms late, in order), crash:/pybullet_bridge:30 (its '
                   'process killed at sim t=30 s); repeatable (scara_collab.run.faults)')
    p.add_argument('--quiet', action='store_true',
                   help='no stage or progress lines; errors and the report only')
    p.add_argument('--ready-timeout', type=float, default=60.0, metavar='S',
                   help='wall seconds each stage may take to become ready (default: '
                   '%(default)s)')
    p.add_argument('--stall-timeout', type=float, default=30.0, metavar='S',
                   help='end the run if sim time stands still this many wall seconds '
                   '(default: %(default)s)')
    p.add_argument('--silent-timeout', type=float, default=10.0, metavar='S',
                   help='end the run if a node leaves a /clock unanswered on /sim/lockstep '
                   'this many wall seconds (hung or stopped; default: %(default)s)')
    p.add_argument('--no-plots', action='store_true', help='skip the PNG plots')
    p.add_argument('--record', action='store_true',
                   help='also record the topics of the run to <run folder>/run.mcap '
                   '(ros2 bag, Foxglove)')
    p.add_argument('--animation', action='store_true',
                   help='render <run folder>/run.gif after the run (items too with --record)')
    return p


def parse_options(argv: Optional[Sequence[str]] = None) -> LaunchOptions:
    """Return the options of ``argv`` (default: ``sys.argv[1:]``), checked and resolved.

    A bad value or combination exits with a usage error (status 2), as argparse does.
    """
    p = parser()
    a = p.parse_args(argv)
    if not a.duration > 0:
        p.error('--duration must be > 0')
    if a.rtf is not None and a.rtf < 0:
        p.error('--rtf must be >= 0')
    if a.launch_rtf < 0:
        p.error('--launch-rtf must be >= 0')
    if a.feed_interval is not None and not a.feed_interval > 0:
        p.error('--feed-interval must be > 0')
    if a.fault:
        from scara_collab.run.faults import parse_faults
        try:
            parse_faults(a.fault)
        except ValueError as exc:
            p.error(f'--fault: {exc}')
    if a.cells < 1:
        p.error('--cells must be >= 1')
    if a.line_cell is not None and not 0 <= a.line_cell < a.cells:
        p.error(f'--line-cell {a.line_cell} is not a cell of a line of {a.cells}')
    if a.discovery_server is not None and not 0 <= a.discovery_server <= 65535:
        p.error('--discovery-server: a UDP port, 1..65535 (or none: a free one)')
    if a.discovery_server is not None and a.line_cell is not None:
        p.error('--discovery-server starts a server for a whole line; for one cell of a line '
                "on a machine of its own, set ROS_DISCOVERY_SERVER to the line's server")
    if a.cells > 1 and a.namespace:
        p.error('--namespace and --cells: a line puts cell k under /cell_k')
    if a.cells > 1 and (a.viewer is not None or a.gui):
        p.error('--viewer and --gui show one cell; run a line without them')
    try:
        namespace = graph.namespace_of(a.namespace) or (
            graph.cell_namespace(a.line_cell, a.cells) if a.line_cell is not None else '')
    except ValueError as exc:
        p.error(f'--namespace: {exc}')
    person, person_seed = _person(p, a)
    if a.step_chunk is not None and not a.step_chunk > 0:
        p.error('--step-chunk must be > 0')
    if not a.silent_timeout > 0:
        p.error('--silent-timeout must be > 0')
    if a.viewer is not None and not 0 < a.viewer < 65536:
        p.error('--viewer PORT must be in 1..65535')
    if a.viewer is not None and not port_free(a.viewer):
        p.error(f'--viewer: port {a.viewer} is in use (another viewer?); pick another PORT')
    rtf = float(load_config('simulation')['real_time_factor'] if a.rtf is None else a.rtf)
    launch_rtf = a.launch_rtf
    if launch_rtf == 0 or (rtf != 0 and rtf <= launch_rtf):
        launch_rtf = rtf  # no hold
    step_chunk = a.step_chunk
    if step_chunk is None and launch_rtf != rtf and (rtf == 0 or rtf > 4):
        step_chunk = FAST_CHUNK
    return LaunchOptions(
        mode=a.mode, duration=a.duration, rtf=rtf, launch_rtf=launch_rtf, step_chunk=step_chunk,
        lockstep=a.lockstep == 'on', namespace=namespace, cells=a.cells, line_cell=a.line_cell,
        discovery_server=a.discovery_server, one_process=a.one_process, gui=a.gui,
        viewer=a.viewer, tf=a.tf, output=a.output, profile=a.profile, seed=a.seed,
        feed_interval=a.feed_interval, faults=tuple(a.fault), quiet=a.quiet,
        ready_timeout=a.ready_timeout, stall_timeout=a.stall_timeout,
        silent_timeout=a.silent_timeout, plots=not a.no_plots, record=a.record,
        animation=a.animation, person=person, person_cell=a.person_cell,
        person_seed=person_seed, monitor_link=a.monitor_link)


def _person(p: argparse.ArgumentParser, a: argparse.Namespace
            ) -> Tuple[Optional[str], Optional[int]]:
    """Return ``--person`` checked (a built-in name or a file's absolute path) and its seed.

    A file must exist and hold a scenario (:func:`scara_collab.sim.person_scenarios.scenario`
    builds it, as the bridge will); ``none`` is no person. A bad value exits with status 2.
    """
    if a.person_cell is not None:
        if a.person is None or a.person == 'none':
            p.error('--person-cell needs --person')
        if not 0 <= a.person_cell < a.cells:
            p.error(f'--person-cell {a.person_cell} is not a cell of a line of {a.cells}')
    if a.person is None or a.person == 'none':
        return None, None
    from scara_collab.core.config import ConfigError
    from scara_collab.core.model import load_cell
    from scara_collab.sim.person_scenarios import BUILTIN, scenario
    spec = a.person
    if spec not in BUILTIN:
        path = Path(spec).expanduser()
        if not path.is_file():
            p.error(f'--person: {spec!r} is neither a built-in scenario ({", ".join(BUILTIN)}) '
                    'nor a YAML file')
        spec = str(path.resolve())
    seed = int(load_config('simulation')['item_seed'] if a.seed is None else a.seed)
    try:
        scenario(spec, load_cell(a.profile), load_config('people'), seed)
    except (ConfigError, OSError, UnicodeDecodeError) as exc:
        p.error(f'--person: {exc}')
    return spec, seed
