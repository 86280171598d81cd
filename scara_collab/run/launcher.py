"""Launch the whole cell on sim time, run the job, record it, report it (``launch_cell.py``).

Stages, in order, are the nodes of :mod:`scara_collab.graph`, each a separate process
(``python -m scara_collab.run.child <module>:<function> --ros-args -p use_sim_time:=true
--params-file config/<file>.yaml ...``), each started only when the previous one is *ready* on
the graph as the graph's description says (``/clock`` runs, the planner subscribes to its
target topic, the manager's service answers, ...). Once the automation manager is ready its
``start`` is called (not in ``--mode idle``), again every 0.5 s while the manager refuses it
because an endpoint it uses is not matched yet. The viewer is started with ``--viewer
[PORT]`` only (http://localhost:PORT must answer; a port in use is refused at the command
line).

Every wait has a timeout that ends the launch with an error naming the stage, and a node
process that dies ends it at once (its name, exit code and the tail of its log are printed).

The bridge is the clock. It starts paused at sim time 0 (its parameter ``paused``) and
waits, once running, for the first answers of every launched node that takes part in the
lockstep (``lockstep_expect``); once the job has started the launcher sets the feed (the belt
feeds items from then on; ``feed_interval`` is 0 until then) and ``--rtf`` (its dynamic
parameter ``real_time_factor``) and calls ``/sim/resume``. So every run starts at sim time 0
with every node there, however long the start-up took. The nodes run in lockstep with the
bridge (:mod:`scara_collab.nodes.lockstep`), so the job does not depend on how fast the
machine is. ``--lockstep off`` runs them against a clock that waits for nobody, as on
ros2_control hardware or in Gazebo (the bridge's ``lockstep_window`` 0): a node that computes
or is descheduled falls behind sim time, and its messages and moves come late. The nodes
still answer each ``/clock`` (the liveness watch below reads the answers) and the bridge
still holds both arms when the collision monitor falls more than its lockstep timeout (sim s)
behind. ``lockstep`` (on | off) is in ``summary.json`` and the report. At the end the
bridge is slowed to ``--launch-rtf`` (default 1.0) while the job is stopped. The bridge
picks its tick at start-up (2 ms when throttled) and steps ``step_chunk`` per tick, so when it
will be released to more than 4x (or unthrottled) the launcher also passes ``step_chunk``
0.02 s, which allows up to 10x real time (``--step-chunk`` to change it; ``--launch-rtf 0``
starts the bridge at ``--rtf`` directly, without the hold).

Liveness: a process that hangs (stopped, deadlocked, starved) does not exit, so the launcher
also watches the lockstep answers on ``/sim/lockstep`` (:mod:`scara_collab.run.liveness`). A
launched node that leaves a ``/clock`` unanswered for ``--silent-timeout`` wall seconds
(default 10, longer than the bridge's ``lockstep_timeout`` so that the bridge has already held
the arms if the node is the collision monitor) ends the run, named with the sim time it
reached (not with ``--one-process``: a hung node there stops them all, the bridge too).
Sim time that stands still with every node up to date is the bridge's stall
(``--stall-timeout``).

The run ends after ``--duration`` sim seconds of job, on SIGINT / SIGTERM, when a node
process dies or a node stops answering: the bridge is slowed back to the launch pace, the job
is stopped (``/automation_manager/stop``, short timeouts; skipped if the automation manager is
the node that stopped answering), the children get SIGINT in reverse order (SIGTERM if still
starting) and SIGCONT (so a stopped one can exit), what remains after a grace period is
killed, and the run files are written (:mod:`scara_collab.records.record`; the reason is
``exit_reason`` in ``summary.json``). Exit status (:mod:`scara_collab.records.verdict`, the
reason on the report's first line and as ``exit_reason`` with every ``problems`` in
``summary.json``): 0 clean run, 1 a node died / stopped answering / was not ready / refused to
start, 2 bad arguments, 3 margin broken, 4 a stop (protective or emergency) left standing at
the end, 5 a node silent longer than the bridge's ``lockstep_timeout`` (every silence is
named, whatever its length), 6 a foreign ``/clock`` publisher or a second graph on the domain
(seen at any time of the run), 130 SIGINT, 143 SIGTERM.

``--namespace NS`` runs the whole cell under ``NS`` (every node with the graph's namespace
and remaps, :func:`scara_collab.graph.ros_args`; the launcher's own nodes too): its topics,
services, clock and lockstep are the cell's, its checks for a second clock or a second graph
look at the cell's names, and a cell under another namespace on the same domain is not heard.

``--record`` also writes the run's topics to ``run.mcap`` from the launcher's own process
(:mod:`scara_collab.nodes.mcap_recorder`, closed with the other run files); ``--animation``
renders ``run.gif`` once the run's files are written (:mod:`scara_collab.run.animation`).

The parts: this module is the command line, the run (:class:`Launcher`: start the graph,
start the job, supervise, stop) and :func:`main`; :mod:`~scara_collab.run.stages` plans the
processes from the graph, :mod:`~scara_collab.run.supervisor` starts, watches and stops them,
:mod:`~scara_collab.run.liveness` watches their lockstep answers,
:mod:`~scara_collab.run.graph_client` waits for and calls the nodes, and
:mod:`~scara_collab.run.console` prints; the launcher's own nodes are the run recorder
(:mod:`scara_collab.nodes.recorder`) and the lockstep watch
(:mod:`scara_collab.nodes.lockstep_watch`).
"""
import argparse
import contextlib
import datetime
import importlib.util
import os
from pathlib import Path
import signal
import socket
import sys
import time
import traceback
from typing import List, Optional, Sequence

import rclpy
from rclpy.signals import SignalHandlerOptions
from std_srvs.srv import Trigger

from scara_collab import graph
from scara_collab.core.config import load_config
from scara_collab.core.paths import config_dir
from scara_collab.nodes import lockstep
from scara_collab.nodes.faults import FaultPlan, parse_faults
from scara_collab.nodes.recorder import RunRecorder
from scara_collab.nodes.runner import localhost_by_default, make_executor
from scara_collab.records.report import format_progress, format_report
from scara_collab.records.telemetry import CpuMeter
from scara_collab.run import discovery
from scara_collab.run.console import Console
from scara_collab.run.graph_client import GraphClient
from scara_collab.run.liveness import Liveness
from scara_collab.run.stages import one_process, stages
from scara_collab.run.supervisor import EXIT_FAILED, EXIT_USAGE, RunEnd, Supervisor

RUN_MODES = graph.LAUNCH_MODES
AUTOMATION_MODULE = graph.node('automation_manager').entry.split(':')[0]
FAST_CHUNK = 0.02  # s: with the bridge's 2 ms tick, up to 10x real time
VIEWER_PORT = 8080  # --viewer without a port


def port_free(port: int) -> bool:
    """Return ``True`` if a TCP server could listen on ``port`` (all interfaces) now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the viewer's server
        try:
            s.bind(('', port))
        except OSError:
            return False
    return True


def parse_args(argv: Optional[Sequence[str]] = None) -> argparse.Namespace:
    """Command line of ``scripts/launch_cell.py``."""
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
    p.add_argument('--fault', action='append', default=[], metavar='SPEC',
                   help='inject a fault, e.g. drop:/scara_left/gripper:2 (lose the first 2 '
                   'gripper responses), delay:/scara_right/planner_status:3:0.5, '
                   'drop:/automation_manager/start:1, latency:/joint_states:0.02:0.01 (every '
                   'message 20 +- 10 ms late, in order); repeatable (scara_collab.nodes.faults)')
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
    args = p.parse_args(argv)
    if not args.duration > 0:
        p.error('--duration must be > 0')
    if args.rtf is not None and args.rtf < 0:
        p.error('--rtf must be >= 0')
    if args.launch_rtf < 0:
        p.error('--launch-rtf must be >= 0')
    if args.feed_interval is not None and not args.feed_interval > 0:
        p.error('--feed-interval must be > 0')
    try:
        parse_faults(args.fault)
    except ValueError as exc:
        p.error(f'--fault: {exc}')
    if args.cells < 1:
        p.error('--cells must be >= 1')
    if args.line_cell is not None and not 0 <= args.line_cell < args.cells:
        p.error(f'--line-cell {args.line_cell} is not a cell of a line of {args.cells}')
    if args.discovery_server is not None and not 0 <= args.discovery_server <= 65535:
        p.error('--discovery-server: a UDP port, 1..65535 (or none: a free one)')
    if args.discovery_server is not None and args.line_cell is not None:
        p.error('--discovery-server starts a server for a whole line; for one cell of a line '
                "on a machine of its own, set ROS_DISCOVERY_SERVER to the line's server")
    if args.cells > 1 and args.namespace:
        p.error('--namespace and --cells: a line puts cell k under /cell_k')
    if args.cells > 1 and (args.viewer is not None or args.gui):
        p.error('--viewer and --gui show one cell; run a line without them')
    try:
        args.namespace = graph.namespace_of(args.namespace) or (
            graph.cell_namespace(args.line_cell, args.cells) if args.line_cell is not None
            else '')
    except ValueError as exc:
        p.error(f'--namespace: {exc}')
    if args.step_chunk is not None and not args.step_chunk > 0:
        p.error('--step-chunk must be > 0')
    if not args.silent_timeout > 0:
        p.error('--silent-timeout must be > 0')
    if args.viewer is not None and not 0 < args.viewer < 65536:
        p.error('--viewer PORT must be in 1..65535')
    if args.viewer is not None and not port_free(args.viewer):
        p.error(f'--viewer: port {args.viewer} is in use (another viewer?); pick another PORT')
    if args.rtf is None:
        args.rtf = float(load_config('simulation')['real_time_factor'])
    if args.launch_rtf == 0 or (args.rtf != 0 and args.rtf <= args.launch_rtf):
        args.launch_rtf = args.rtf  # no hold
    if args.step_chunk is None and args.launch_rtf != args.rtf and (
            args.rtf == 0 or args.rtf > 4):
        args.step_chunk = FAST_CHUNK
    return args


def format_factor(rtf: float) -> str:
    """``0`` -> ``'unthrottled'``, else ``'2x'``."""
    return 'unthrottled' if rtf == 0 else f'{rtf:g}x'


def default_output(mode: str) -> Path:
    """``runs/<YYYYmmdd-HHMMSS>_<mode>`` (made unique)."""
    stamp = datetime.datetime.now().strftime('%Y%m%d-%H%M%S')
    path = Path('runs') / f'{stamp}_{mode}'
    k = 1
    while path.exists():
        k += 1
        path = Path('runs') / f'{stamp}_{mode}_{k}'
    return path


def record_mcap(recorder: RunRecorder, output: Path, console: Console) -> None:
    """Record the run's topics to MCAP too (on ``recorder``, whose finish closes the file)."""
    from scara_collab.nodes.mcap_recorder import McapRecorder
    from scara_collab.records.mcap_log import MCAP_FILE
    mcap = McapRecorder(recorder, output / MCAP_FILE, robots=[a.name for a in recorder.cell.arms],
                        urdf=recorder.cell.urdf)  # + /robot_description, /tf
    recorder.sinks.append(mcap)
    console.say(f'[launch] recording {len(mcap.topics)} topics to {mcap.path}')


class Launcher:
    """Run the job: start the graph, start the job, supervise, stop; see the module docstring.

    The parts it drives: the node processes (:class:`Supervisor`), the launcher's side of the
    graph (:class:`GraphClient` on the run recorder's node), the run's record
    (:class:`RunRecorder`), the lockstep answers (:class:`Liveness`) and the job's CPU cost
    (:class:`CpuMeter`).
    """

    def __init__(self, args: argparse.Namespace, output: Path, console: Console):
        """Plan the stages and set up the recorder, its executor and the lockstep watch.

        :param args: the parsed command line.
        :param output: the run folder.
        :param console: where stage lines and progress go.
        """
        self.args = args
        self.output = output
        self.console = console
        self.with_automation = importlib.util.find_spec(AUTOMATION_MODULE) is not None
        self.stages = stages(args, self.with_automation)
        self.processes = Supervisor(output, config_dir(), console)
        self.signals: List[str] = []
        self.job_started = False
        self.rtf_released = False
        self.t_launch = time.monotonic()
        self.context = rclpy.Context()
        self.namespace = getattr(args, 'namespace', '')
        # the launcher asks the graph for every node: with a discovery server it must learn the
        # whole graph (a super client); its participant is made with its first node
        with discovery.super_client() as self.super_client:
            rclpy.init(args=[], context=self.context,
                       signal_handler_options=SignalHandlerOptions.NO)
            self.recorder = RunRecorder(output, args.mode, profile=args.profile,
                                        context=self.context, namespace=self.namespace)
        self.recorder.extra['lockstep'] = getattr(args, 'lockstep', 'on')
        if getattr(args, 'record', False):
            record_mcap(self.recorder, output, console)
        self.executor = make_executor(context=self.context)
        self.executor.add_node(self.recorder)
        self.ros = GraphClient(self.recorder, self.executor, console,
                               FaultPlan(getattr(args, 'fault', [])), self.check, self.signals,
                               args.ready_timeout, self.namespace)
        self.cpu = CpuMeter()
        self._next_poll = self._next_checkpoint = self._next_watch = 0.0
        self.rtf = args.rtf
        self.launch_rtf = args.launch_rtf
        one_process = getattr(args, 'one_process', False)  # nobody can be behind: no watch
        self.liveness = Liveness([] if one_process else [
            s.name for s in self.stages if graph.node(s.name).lockstep],
                                 getattr(args, 'silent_timeout', 10.0), self.context,
                                 self.namespace)

    def on_signal(self, signum, _frame) -> None:
        """Handle SIGINT / SIGTERM: record it; at the second, say the nodes are killed now."""
        self.signals.append(signal.Signals(signum).name)
        if len(self.signals) == 2:
            self.console.say(f'[launch] {self.signals[-1]} again: killing the nodes now',
                             error=True)

    def name(self, relative: str) -> str:
        """Return the cell's absolute name of ``relative`` (``sim/resume`` -> ``/sim/resume``)."""
        return graph.resolve(relative, self.namespace)

    # --- supervision -----------------------------------------------------------------------
    def check(self) -> None:
        """Raise :class:`RunEnd` on a signal, a dead node process or a silent node."""
        if self.signals:
            sig = self.signals[0]
            raise RunEnd(sig, 130 if sig == 'SIGINT' else 143)
        now = time.monotonic()
        if now < self._next_poll:
            return
        self._next_poll = now + 0.1
        if now >= self._next_checkpoint:  # a summary on disk even if we are SIGKILLed
            self._next_checkpoint = now + 10.0
            self.recorder.checkpoint()
        self.processes.check()
        if now >= self._next_watch:
            self._next_watch = now + 1.0
            self.check_answers()

    def check_answers(self) -> None:
        """Take the lockstep answers kept since the last look; :class:`RunEnd` if one is silent."""
        silent = self.liveness.silent(self.recorder.sim_time, time.monotonic())
        if silent is None:
            return
        name, seconds, t = silent
        self.recorder.extra['silent_node'] = {'node': name, 'silent_s': round(seconds, 3),
                                              'last_answer_sim_time': t}
        raise RunEnd(f'node {name} stopped answering (silent {seconds:.1f} s, last at sim '
                     f't={t:.2f} s)', EXIT_FAILED,
                     f'[launch] it leaves /clock unanswered on {lockstep.TOPIC} but has not '
                     f'exited (stopped? hung?); {self.processes.log_tail(name)}')

    # --- the run ---------------------------------------------------------------------------
    def start_graph(self) -> None:
        """Start every stage in order, each once the previous one is ready."""
        domain = os.environ.get('ROS_DOMAIN_ID', '0 (default)')
        self.console.say(f'[launch] mode {self.args.mode}, {self.args.duration:g} sim s, '
                         f'rtf {format_factor(self.rtf)}, lockstep '
                         f'{getattr(self.args, "lockstep", "on")}, output {self.output}')
        server = os.environ.get(discovery.ENV)
        self.console.say(f'[launch] ROS_DOMAIN_ID {domain}, discovery '
                         + (f'server {server} (the launcher '
                            f'{"a super client" if self.super_client else "a plain client"})'
                            if server else
                            f'{os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")}')
                         + (f', namespace {self.namespace}' if self.namespace else ''))
        if (getattr(self.args, 'lockstep', 'on') == 'off' and self.rtf != 0
                and not getattr(self.args, 'one_process', False) and (os.cpu_count() or 1) <= 2):
            self.console.say(f'[launch] note: real time on {os.cpu_count() or 1} core(s): one '
                             'process per node needs about 1.3 CPU s per sim s at 1x, '
                             '--one-process about 0.8 (docs/realtime.md)')
        if not self.with_automation:
            self.console.say(f'[launch] {AUTOMATION_MODULE} is not installed: idle graph '
                             'without the automation manager')
        for stage in self.stages:
            if self.ros.duplicates(stage.name):
                raise RunEnd(f'a node named {graph.resolve(stage.name, self.namespace)} is '
                             f'already running on ROS_DOMAIN_ID {domain}; stop it or use '
                             'another ROS_DOMAIN_ID or --namespace')
        container = None
        if getattr(self.args, 'one_process', False):  # every node at once, in one process
            container = self.processes.start(one_process(self.stages))
            self.console.say(f'[launch] {container.stage.name}: {container.stage.ready} '
                             f'(pid {container.proc.pid}), log {container.log_path}')
        for stage in self.stages:
            child = container or self.processes.start(stage)
            timeout = self.args.ready_timeout
            self.ros.wait_until(self.ros.ready_check(stage), timeout,
                                lambda: f'stage {stage.name} not ready after {timeout:g} s '
                                f'(waiting for {stage.ready}); see {child.log_path}')
            child.ready_after = ready_after = time.monotonic() - child.started
            extra = ''
            if stage.name == 'pybullet_bridge':
                extra = ', paused at sim t=0 until the job starts'
            self.console.say(f'[launch] {stage.name:<20} ready in {ready_after:4.1f} s '
                             f'(pid {child.proc.pid}): {stage.ready}{extra}')

    def start_job(self) -> None:
        """Call ``/automation_manager/start`` (not in idle mode) and release the clock."""
        if self.args.mode != 'idle':
            self.ros.start(self.name('automation_manager/start'), self.args.ready_timeout,
                           'automation_manager')
            self.job_started = True
        t0 = self.recorder.start_job()
        release = {}
        if self.args.mode != 'idle' and graph.fed(getattr(self.args, 'line_cell', None) or 0,
                                                  getattr(self.args, 'cells', 1)):
            # the belt starts feeding now (in a line, only cell 0's: the others are handed on)
            feed = getattr(self.args, 'feed_interval', None)
            release['feed_interval'] = float(load_config('simulation')['feed_interval']
                                             if feed is None else feed)
        if self.launch_rtf != self.rtf:
            release['real_time_factor'] = self.rtf
        if release:
            self.ros.set_bridge(**release)
            self.rtf_released = 'real_time_factor' in release
        res = self.ros.call(Trigger, self.name('sim/resume'), Trigger.Request(),
                            self.args.ready_timeout, 'pybullet_bridge')
        if not res.success:
            raise RunEnd(f'pybullet_bridge refused to resume: {res.message}')
        self.liveness.expect(time.monotonic())  # a node that never answers is silent too
        self.recorder.extra['launch_wall_seconds'] = time.monotonic() - self.t_launch
        self.cpu.mark(self.processes.cpu_now(), self.recorder.sim_time)
        job = f'{self.args.mode} job started' if self.job_started else 'graph idle'
        self.console.say(f'[launch] {job} at sim t={t0:.2f} s after '
                         f'{time.monotonic() - self.t_launch:.1f} s; running '
                         f'{self.args.duration:g} sim s at rtf {format_factor(self.rtf)}')

    def supervise(self) -> None:
        """Spin until the duration is reached; progress; :class:`RunEnd` on trouble."""
        end = self.recorder.job_start + self.args.duration
        period = 0.25 if self.console.tty else 5.0
        next_progress = time.monotonic() + period
        last_sim, last_change = self.recorder.sim_time, time.monotonic()
        while True:
            self.executor.spin_once(timeout_sec=0.02)
            self.check()
            now = time.monotonic()
            sim = self.recorder.sim_time
            if (self.recorder.log.t_last or 0.0) >= end:  # recorded up to the end
                self.recorder.freeze(end)
                self.ros.pause(0.3)  # the events of the window still in flight
                return
            if sim > last_sim:
                last_sim, last_change = sim, now
            elif now - last_change > self.args.stall_timeout:
                raise RunEnd(f'sim time stood still at t={sim:.2f} s for '
                             f'{self.args.stall_timeout:g} s (is pybullet_bridge stuck?)')
            if now >= next_progress:
                next_progress = now + period
                self.console.progress(format_progress(self.recorder.progress(),
                                                      self.args.duration))

    def measure_cpu(self) -> None:
        """Close the job's CPU window: CPU s per sim s per process into the summary."""
        if self.cpu.marked:
            cost = self.cpu.close(self.processes.cpu_now(), self.recorder.sim_time)
            if cost:
                self.recorder.extra['cpu_per_sim_s'] = cost

    # --- shutdown --------------------------------------------------------------------------
    def hold_clock(self) -> None:
        """Slow the bridge back to the launch pace, so the shutdown does not race sim time."""
        if self.rtf_released and len(self.signals) < 2:
            self.rtf_released = False
            if self.processes.running('pybullet_bridge'):
                try:
                    self.ros.set_bridge(timeout=2.0, supervise=False,
                                        real_time_factor=self.launch_rtf)
                except RunEnd:
                    pass

    def stop_job(self) -> None:
        """Ask the automation manager to stop the job (best effort, short timeout)."""
        if not self.job_started:
            return
        self.job_started = False
        if not self.processes.running('automation_manager') or len(self.signals) > 1:
            return
        if self.liveness.silent_node == 'automation_manager':
            self.recorder.extra['job_stop'] = 'not stopped: automation_manager does not answer'
            return
        try:
            res = self.ros.call(Trigger, self.name('automation_manager/stop'), Trigger.Request(),
                                5.0, 'automation_manager', supervise=False, attempts=2,
                                attempt_timeout=2.0)
        except RunEnd as exc:
            self.recorder.extra['job_stop'] = f'not stopped: {exc.reason}'
            return
        self.recorder.extra['job_stop'] = res.message

    def stop_children(self, grace: float = 5.0) -> None:
        """Stop the node processes (:meth:`Supervisor.stop`); their fate into the summary."""
        self.recorder.extra['nodes'] = self.processes.stop(grace, self.signals)

    def close(self) -> None:
        """Shut down the executors, destroy the nodes and shut down the context."""
        self.executor.shutdown(timeout_sec=1.0)
        self.liveness.close()
        self.recorder.destroy_node()
        rclpy.try_shutdown(context=self.context)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the cell; returns the exit status (see the module docstring)."""
    args = parse_args(argv)
    with contextlib.ExitStack() as stack:
        if args.discovery_server is not None:
            try:
                address = stack.enter_context(discovery.server(args.discovery_server or None))
            except (FileNotFoundError, RuntimeError) as exc:
                print(f'launch_cell: --discovery-server: {exc}', file=sys.stderr)
                return EXIT_USAGE
            print(f'[launch] Fast DDS discovery server on {address}', flush=True)
        return run(args, argv)


def run(args: argparse.Namespace, argv: Optional[Sequence[str]]) -> int:
    """Run the cell or the line ``args`` (parsed from ``argv``); return the exit status."""
    if args.cells > 1 and args.line_cell is None:  # a line: one launcher per cell
        from scara_collab.run.line_launcher import run_line
        return run_line(args, list(sys.argv[1:] if argv is None else argv))
    if args.mode != 'idle' and importlib.util.find_spec(AUTOMATION_MODULE) is None:
        print(f'launch_cell: --mode {args.mode} needs the automation manager '
              f'({AUTOMATION_MODULE}), which is not installed; --mode idle runs the graph '
              'without it', file=sys.stderr)
        return EXIT_USAGE
    localhost_by_default()  # before rclpy.init, as every executable does
    output = (args.output or default_output(args.mode)).resolve()
    output.mkdir(parents=True, exist_ok=True)
    console = Console(output / 'launch.log', args.quiet)
    try:
        launcher = Launcher(args, output, console)
    except KeyboardInterrupt:  # Ctrl-C before anything was started
        console.close()
        return 130
    previous = {s: signal.signal(s, launcher.on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    code, reason, interrupted = 0, 'duration reached', False
    try:
        launcher.start_graph()
        launcher.start_job()
        launcher.supervise()
    except RunEnd as end:
        code, reason, interrupted = end.code, end.reason, True
        console.say(f'[launch] {"stopping" if end.code in (130, 143) else "ERROR"}: '
                    f'{end.reason}', error=True)
        if end.details:
            console.say(end.details, error=True)
    except Exception as exc:  # a bug of ours: still stop the nodes and keep the files
        code, reason, interrupted = EXIT_FAILED, f'launcher error: {exc!r}', True
        console.say('[launch] ERROR: ' + traceback.format_exc().rstrip(), error=True)
    finally:
        try:
            launcher.recorder.freeze()
            launcher.measure_cpu()
            launcher.hold_clock()
            launcher.stop_job()
            launcher.stop_children(grace=0.5 if len(launcher.signals) > 1 else 5.0)
            launcher.recorder.extra['exit_code'] = code
            launcher.recorder.extra.update(launcher.liveness.summary())  # named silences
            summary = launcher.recorder.finish(reason, interrupted, plots=not args.no_plots)
            code = summary['exit_code']  # the run's verdict: this code unless it was 0
            text = format_report(summary)
            (output / 'report.txt').write_text(text + '\n', encoding='utf-8')
            console.say(text, error=True)
            if getattr(args, 'animation', False):  # after the run: never slows it down
                from scara_collab.run.animation import render_after_run
                signals = len(launcher.signals)  # another Ctrl-C stops the rendering
                render_after_run(output, console.say, lambda: len(launcher.signals) > signals)
        finally:
            launcher.close()
            console.close()
            for s, handler in previous.items():
                signal.signal(s, handler)
    return code


if __name__ == '__main__':
    sys.exit(main())
