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

The bridge is the clock and steps from the moment it starts. So that the launch does not burn
sim time at full speed, the bridge starts at ``--launch-rtf`` (default 1.0) and is set to
``--rtf`` (its dynamic parameter ``real_time_factor``) when the job starts; the belt feeds
items from then on too (``feed_interval`` is 0 until the job starts). The nodes run in
lockstep with the bridge (:mod:`scara_collab.nodes.lockstep`), so the job does not depend on
how fast the machine is. The bridge
picks its tick at start-up (2 ms when throttled) and steps ``step_chunk`` per tick, so when it
will be released to more than 4x (or unthrottled) the launcher also passes ``step_chunk``
0.02 s, which allows up to 10x real time (``--step-chunk`` to change it; ``--launch-rtf 0``
starts the bridge at ``--rtf`` directly, without the hold).

Liveness: a process that hangs (stopped, deadlocked, starved) does not exit, so the launcher
also watches the lockstep answers on ``/sim/lockstep`` (:class:`LockstepWatch`). A launched
node that leaves a ``/clock`` unanswered for ``--silent-timeout`` wall seconds (default 10,
longer than the bridge's ``lockstep_timeout`` so that the bridge has already held the arms
if the node is the collision monitor) ends the run, named with the sim time it reached.
Sim time that stands still with every node up to date is the bridge's stall
(``--stall-timeout``).

The run ends after ``--duration`` sim seconds of job, on SIGINT / SIGTERM, when a node
process dies or a node stops answering: the bridge is slowed back to the launch pace, the job
is stopped (``/automation_manager/stop``, short timeouts; skipped if the automation manager is
the node that stopped answering), the children get SIGINT in reverse order (SIGTERM if still
starting) and SIGCONT (so a stopped one can exit), what remains after a grace period is
killed, and the run files are written (:mod:`scara_collab.run.recorder`; the reason is
``exit_reason`` in ``summary.json``). Exit status: 0 clean run, 1 a node died / stopped
answering / was not ready / refused to start, 2 bad arguments, 130 SIGINT, 143 SIGTERM.

``--record`` also writes the run's topics to ``run.mcap`` from the launcher's own process
(:mod:`scara_collab.run.mcap_log`, closed with the other run files); ``--animation`` renders
``run.gif`` once the run's files are written (:mod:`scara_collab.run.animation`).
"""
import argparse
from dataclasses import dataclass, field
import datetime
import importlib.util
import json
import os
from pathlib import Path
import signal
import socket
import subprocess
import sys
import time
import traceback
from typing import Callable, Dict, IO, Iterable, List, Optional, Sequence, Tuple
import urllib.request

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node, NodeNameNonExistentError
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Header
from std_srvs.srv import SetBool, Trigger

from scara_collab import graph
from scara_collab.core.config import load_config
from scara_collab.core.paths import config_dir
from scara_collab.nodes import lockstep
from scara_collab.nodes.faults import call_with_faults, FaultPlan, parse_faults
from scara_collab.nodes.runner import localhost_by_default
from scara_collab.run.recorder import RunRecorder
from scara_collab.run.report import format_progress, format_report
from scara_collab.run.telemetry import CpuMeter, process_cpu_seconds

RUN_MODES = ('idle', 'single', 'collaborative', 'mirrored')
AUTOMATION_MODULE = graph.node('automation_manager').entry.split(':')[0]
SERVICE_TYPES = {'std_srvs/srv/SetBool': SetBool, 'std_srvs/srv/Trigger': Trigger}
EXIT_FAILED = 1
EXIT_USAGE = 2
FAST_CHUNK = 0.02  # s: with the bridge's 2 ms tick, up to 10x real time
VIEWER_PORT = 8080  # --viewer without a port
# the launcher's look at /sim/lockstep, taken once a second: the newest 200 answers (40 clocks
# of 5 nodes; a live node is never more than the lockstep window behind), best effort so that
# a slow launcher is never a burden on the nodes
WATCH_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.BEST_EFFORT)


@dataclass
class Stage:
    """One node process of the graph and what "ready" means for it."""

    name: str                   # node name = log file name
    entry: str                  # module:function
    configs: Tuple[str, ...]    # config/<name>.yaml files passed with --params-file
    ready: str                  # what the launcher waits for, for messages
    params: Dict[str, str] = field(default_factory=dict)
    members: Tuple['Stage', ...] = ()  # --one-process: the stages this process runs


CONTAINER = 'cell'  # --one-process: the one process's name (logs/cell.log)


@dataclass
class Child:
    """A started stage."""

    stage: Stage
    proc: subprocess.Popen
    log_path: Path
    log_file: IO
    started: float
    ready_after: Optional[float] = None


class RunEnd(Exception):
    """The run ends early: ``reason`` for the summary, ``code`` for the exit status."""

    def __init__(self, reason: str, code: int = EXIT_FAILED, details: str = ''):
        """Keep ``reason``, the exit ``code`` and optional ``details`` for the summary."""
        super().__init__(reason)
        self.reason, self.code, self.details = reason, code, details


class LockstepWatch:
    """Who answers on ``/sim/lockstep``, and who stopped (:mod:`scara_collab.nodes.lockstep`).

    A participant is *silent* when its newest answer is older than ``limit`` wall seconds and
    behind the newest sim time (there is a ``/clock`` it has not answered): it hangs, is
    stopped or starves. Sim time that stands still with every participant up to date leaves
    nobody silent; that is the bridge's stall.

    :param names: full names of the nodes to watch (``/collision_monitor``); others ignored.
    :param limit: wall seconds.
    """

    def __init__(self, names: Iterable[str], limit: float):
        """Watch the nodes ``names``; a participant is silent after ``limit`` wall seconds."""
        self.names = frozenset(names)
        self.limit = float(limit)
        self.reached: Dict[str, float] = {}  # participant -> newest sim time it answered
        self.heard: Dict[str, float] = {}    # participant -> wall time of that answer

    def answer(self, name: str, sim_t: float, wall: float) -> None:
        """Take one answer of ``name``, at sim time ``sim_t`` (the end of time: it left)."""
        if name not in self.names:
            return
        if sim_t >= lockstep.END_OF_TIME.sec:
            self.reached.pop(name, None)
            self.heard.pop(name, None)
        elif sim_t > self.reached.get(name, -1.0):
            self.reached[name], self.heard[name] = sim_t, wall

    def silent(self, sim_now: float, wall: float) -> Optional[Tuple[str, float, float]]:
        """Return ``(name, silent wall s, sim time it reached)`` of the longest silent one.

        :param sim_now: the newest sim time the launcher has heard on ``/clock``, s.
        :param wall: now, s (the clock of :meth:`answer`'s ``wall``).
        :return: ``None`` if nobody is silent beyond the limit.
        """
        front = max([sim_now, *self.reached.values()])
        late = [(wall - self.heard[n], n) for n, t in self.reached.items()
                if t < front - 1e-6 and wall - self.heard[n] > self.limit]
        if not late:
            return None
        silent, name = max(late)
        return name, silent, self.reached[name]


def tail(path: Path, lines: int = 20) -> str:
    """Last ``lines`` lines of a text file ('' if unreadable)."""
    try:
        with open(path, 'rb') as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - 16384))
            text = f.read().decode('utf-8', 'replace')
    except OSError:
        return ''
    return '\n'.join(text.splitlines()[-lines:])


def describe_exit(code: int) -> str:
    """``-9`` -> ``'code -9 (SIGKILL)'``."""
    if code is not None and code < 0:
        try:
            return f'code {code} ({signal.Signals(-code).name})'
        except ValueError:
            pass
    return f'code {code}'


def port_free(port: int) -> bool:
    """Return ``True`` if a TCP server could listen on ``port`` (all interfaces) now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the viewer's server
        try:
            s.bind(('', port))
        except OSError:
            return False
    return True


def http_ok(url: str, timeout: float = 0.5) -> bool:
    """Return ``True`` if ``url`` answers HTTP 200 (directly: no proxy from the environment)."""
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(url, timeout=timeout) as res:
            return res.status == 200
    except (OSError, ValueError):
        return False


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
                   help='real-time factor while the graph starts, at most --rtf; 0 = start '
                   'the bridge at --rtf at once (default: %(default)s)')
    p.add_argument('--step-chunk', type=float, default=None, metavar='SIM_SECONDS',
                   help='bridge step_chunk: sim time stepped per 2 ms bridge tick, which '
                   'bounds the real-time factor at step_chunk / 0.002 (default: '
                   f'{FAST_CHUNK} when the bridge is released to more than 4x, else the '
                   'bridge default)')
    p.add_argument('--one-process', action='store_true',
                   help='run every node in one process on one executor (a component '
                   'container, scara_collab.run.container) instead of one process per node')
    p.add_argument('--gui', action='store_true', help='PyBullet GUI (bridge gui:=true)')
    p.add_argument('--viewer', type=int, nargs='?', const=VIEWER_PORT, default=None,
                   metavar='PORT', help='also start the live 3D view (cell_viewer) on '
                   f'http://localhost:PORT (default port: {VIEWER_PORT})')
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
                   'drop:/automation_manager/start:1; repeatable (scara_collab.nodes.faults)')
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


def stages(args: argparse.Namespace, with_automation: bool) -> List[Stage]:
    """Return the graph for ``args``, in launch order (the nodes of :mod:`scara_collab.graph`)."""
    common = {} if args.profile is None else {'profile': args.profile}
    by_mode = graph.job_params(args.mode)
    own: Dict[str, Dict[str, str]] = {
        'pybullet_bridge': {'real_time_factor': repr(float(args.launch_rtf)),
                            # the belt feeds from when the job starts (Launcher.start_job)
                            'feed_interval': '0.0'},
        'automation_manager': {'auto_start': 'false'},  # the launcher starts the job
    }
    bridge = own['pybullet_bridge']
    if args.step_chunk is not None:
        bridge['step_chunk'] = repr(float(args.step_chunk))
    if args.gui:
        bridge['gui'] = 'true'
    if args.seed is not None:
        bridge['item_seed'] = str(args.seed)
    port = getattr(args, 'viewer', None)
    if port is not None:
        own['cell_viewer'] = {'port': str(port)}
    faults = getattr(args, 'fault', [])
    out = []
    for spec in graph.job_nodes(automation=with_automation, viewer=port is not None):
        params = dict(common, **by_mode[spec.name], **own.get(spec.name, {}))
        if faults:  # every node applies the entries naming its own publishers and clients
            params['faults'] = graph.param_value(faults)
        out.append(Stage(spec.name, spec.entry, spec.configs,
                         spec.ready.describe(spec.name, params), params))
    return out


def node_args(stage: Stage, config_dir: Path) -> List[str]:
    """Return the ``--ros-args`` of one stage's node."""
    return graph.ros_args(stage.configs, stage.params, config_dir=config_dir)


def command(stage: Stage, config_dir: Path) -> List[str]:
    """Return the command line of one stage (or of the one process running ``members``)."""
    if stage.members:
        cmd = [sys.executable, '-m', stage.entry]
        for member in stage.members:
            cmd += ['--node', member.entry] + node_args(member, config_dir)
        return cmd
    return [sys.executable, '-m', 'scara_collab.run.child', stage.entry] + node_args(
        stage, config_dir)


def one_process(members: Sequence[Stage]) -> Stage:
    """Return the stage running ``members`` in one process (:mod:`scara_collab.run.container`)."""
    return Stage(CONTAINER, 'scara_collab.run.container', (),
                 f'{len(members)} nodes on one executor', {}, tuple(members))


class Console:
    """Stage lines and progress on stdout (and in ``launch.log``); errors always shown."""

    def __init__(self, log_path: Path, quiet: bool):
        """Append the lines to ``log_path``; ``quiet`` shows errors only on stdout."""
        self.quiet = quiet
        self.tty = sys.stdout.isatty()
        self.log = open(log_path, 'a', encoding='utf-8')
        self._live = False
        self._t0 = time.monotonic()

    def _clear_live(self) -> None:
        if self._live:
            sys.stdout.write('\r\x1b[K')
            self._live = False

    def say(self, text: str, error: bool = False) -> None:
        """Log ``text`` and print it unless quiet (an ``error`` is always printed)."""
        self.log.write(f'{time.monotonic() - self._t0:7.2f} {text}\n')
        self.log.flush()
        if self.quiet and not error:
            return
        self._clear_live()
        print(text, flush=True)

    def progress(self, text: str) -> None:
        """Show ``text`` as the live line on a terminal, else as a logged line."""
        if self.quiet:
            return
        if self.tty:
            sys.stdout.write('\r' + text + '\x1b[K')
            sys.stdout.flush()
            self._live = True
        else:
            self.say(text)

    def close(self) -> None:
        """End the live line and close the log file."""
        self._clear_live()
        self.log.close()


class Launcher:
    """Start the stages, supervise the run, stop everything; see the module docstring."""

    def __init__(self, args: argparse.Namespace, output: Path, console: Console):
        """Plan the stages and set up the recorder, its executor and the lockstep watch.

        :param args: the parsed command line.
        :param output: the run folder.
        :param console: where stage lines and progress go.
        """
        self.args = args
        self.output = output
        self.console = console
        self.config_dir = config_dir()
        self.with_automation = importlib.util.find_spec(AUTOMATION_MODULE) is not None
        self.stages = stages(args, self.with_automation)
        self.children: List[Child] = []
        self.signals: List[str] = []
        self.job_started = False
        self.rtf_released = False
        self.t_launch = time.monotonic()
        self.context = rclpy.Context()
        rclpy.init(args=[], context=self.context,
                   signal_handler_options=SignalHandlerOptions.NO)
        self.recorder = RunRecorder(output, args.mode, profile=args.profile,
                                    context=self.context)
        self.node = self.recorder
        if getattr(args, 'record', False):  # raw subscriptions on the recorder; finish() closes
            from scara_collab.run.mcap_log import MCAP_FILE, McapLog
            mcap = McapLog(self.recorder, output / MCAP_FILE,
                           robots=[a.name for a in self.recorder.cell.arms])
            self.recorder.sinks.append(mcap)
            console.say(f'[launch] recording {len(mcap.topics)} topics to {mcap.path}')
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.recorder)
        self._clients: Dict[str, object] = {}
        self.faults = FaultPlan(getattr(args, 'fault', []))
        self._bridge_params: Optional[AsyncParameterClient] = None
        self.cpu = CpuMeter()
        self._next_poll = 0.0
        self._next_checkpoint = 0.0
        self.rtf = args.rtf
        self.launch_rtf = args.launch_rtf
        # liveness: the lockstep answers (hundreds a second) go to a node and an executor of
        # their own, which check() drains once a second (WATCH_QOS)
        self.watch = LockstepWatch([lockstep.full_name(s.name) for s in self.stages],
                                   getattr(args, 'silent_timeout', 10.0))
        self.silent_node: Optional[str] = None
        self._answers = 0
        self._next_watch = 0.0
        self._watch_node = Node('launch_cell_watch', context=self.context)
        self._watch_node.create_subscription(Header, lockstep.TOPIC, self._on_lockstep,
                                             WATCH_QOS)
        self._watch_executor = SingleThreadedExecutor(context=self.context)
        self._watch_executor.add_node(self._watch_node)

    # --- signals ---------------------------------------------------------------------------
    def on_signal(self, signum, _frame) -> None:
        """Handle SIGINT / SIGTERM: record it; at the second, say the nodes are killed now."""
        self.signals.append(signal.Signals(signum).name)
        if len(self.signals) == 2:
            self.console.say(f'[launch] {self.signals[-1]} again: killing the nodes now',
                             error=True)

    # --- low-level waits -------------------------------------------------------------------
    def check(self) -> None:
        """Raise :class:`RunEnd` on a signal or a dead node process."""
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
        for child in self.children:
            code = child.proc.poll()
            if code is not None:
                name = child.stage.name
                raise RunEnd(f'node {name} exited with {describe_exit(code)}', EXIT_FAILED,
                             f'[launch] last lines of {child.log_path}:\n'
                             + '\n'.join('    ' + ln for ln in tail(child.log_path).splitlines()))
        if now >= self._next_watch:
            self._next_watch = now + 1.0
            self.check_answers()

    def _on_lockstep(self, msg: Header) -> None:
        self._answers += 1
        self.watch.answer(msg.frame_id, msg.stamp.sec + msg.stamp.nanosec * 1e-9,
                          time.monotonic())

    def check_answers(self) -> None:
        """Take the lockstep answers kept since the last look; :class:`RunEnd` if one is silent."""
        idle = 0  # spin_once(0) takes a message only every other call or so: not the end yet
        for _ in range(4 * WATCH_QOS.depth):
            before = self._answers
            self._watch_executor.spin_once(timeout_sec=0.0)
            idle = idle + 1 if self._answers == before else 0
            if idle >= 3:
                break
        silent = self.watch.silent(self.recorder.sim_time, time.monotonic())
        if silent is None:
            return
        name, seconds, t = silent
        self.silent_node = name = name.lstrip('/')
        self.recorder.extra['silent_node'] = {'node': name, 'silent_s': round(seconds, 3),
                                              'last_answer_sim_time': t}
        child = self.child_of(name)
        log = child.log_path if child else self.output / 'logs' / f'{name}.log'
        raise RunEnd(f'node {name} stopped answering (silent {seconds:.1f} s, last at sim '
                     f't={t:.2f} s)', EXIT_FAILED,
                     f'[launch] it leaves /clock unanswered on {lockstep.TOPIC} but has not '
                     f'exited (stopped? hung?); last lines of {log}:\n'
                     + '\n'.join('    ' + ln for ln in tail(log).splitlines()))

    def wait_until(self, predicate: Callable[[], bool], timeout: float,
                   on_timeout: Callable[[], str], supervise: bool = True) -> None:
        """Spin the recorder until ``predicate()``; :class:`RunEnd` on timeout or trouble.

        :param supervise: also end on a signal or a dead node (:meth:`check`); without it (the
            shutdown) only a second signal cuts the wait short.
        """
        deadline = time.monotonic() + timeout
        while not predicate():
            if supervise:
                self.check()
            elif len(self.signals) > 1:
                raise RunEnd(self.signals[-1], 130)
            if time.monotonic() >= deadline:
                raise RunEnd(on_timeout())
            self.executor.spin_once(timeout_sec=0.02)

    def pause(self, seconds: float) -> None:
        """Spin the recorder for ``seconds`` (wall), supervising; never a timeout of its own.

        (A deadline just beyond the pause would fire whenever the busy machine descheduled
        the launcher longer than the difference: seen with two CPU hogs.)
        """
        until = time.monotonic() + seconds
        while time.monotonic() < until:
            self.check()
            self.executor.spin_once(timeout_sec=min(0.02, max(until - time.monotonic(), 0.0)))

    def client(self, srv_type, name: str):
        """Return the client of service ``name``, created on first use."""
        if name not in self._clients:
            self._clients[name] = self.node.create_client(srv_type, name)
        return self._clients[name]

    def call(self, srv_type, name: str, request, timeout: float, what: str,
             supervise: bool = True, attempts: int = 4, attempt_timeout: float = 5.0):
        """Call a service and return the response, repeating a request whose answer is lost.

        Waits for the service first, then sends the request up to ``attempts`` times,
        ``attempt_timeout`` wall seconds apart.

        A response can be lost (Fast DDS drops one whose client reader is not matched yet),
        so the request is repeated; the servers are idempotent, so a repeat is safe.
        """
        cli = self.client(srv_type, name)
        self.wait_until(cli.service_is_ready, timeout,
                        lambda: f'{what}: service {name} not available after {timeout:g} s',
                        supervise)
        for attempt in range(1, attempts + 1):
            answer: list = []
            call_with_faults(self.node, self.faults, cli, request, answer.append)
            try:
                self.wait_until(lambda: bool(answer), attempt_timeout, lambda: '', supervise)
            except RunEnd as exc:
                if exc.reason or attempt == attempts:
                    if not exc.reason:
                        raise RunEnd(f'{what}: {name} did not answer {attempts} requests, '
                                     f'{attempt_timeout:g} s apart') from None
                    raise
                self.console.say(f'[launch] {name}: no answer in {attempt_timeout:g} s; '
                                 f'asking again ({attempt + 1}/{attempts})')
                continue
            return answer[0]

    # --- readiness -------------------------------------------------------------------------
    def _subscribed(self, node_name: str, topic: str) -> bool:
        try:
            subs = self.node.get_subscriber_names_and_types_by_node(node_name, '/')
        except NodeNameNonExistentError:
            return False
        return any(name == topic for name, _ in subs)

    def _service_ready(self, srv_type, name: str) -> Callable[[], bool]:
        cli = self.client(srv_type, name)
        return cli.service_is_ready

    def ready_check(self, stage: Stage) -> Callable[[], bool]:
        """Return the readiness predicate of a stage (from :mod:`scara_collab.graph`)."""
        name, ready = stage.name, graph.node(stage.name).ready
        if ready.kind == 'clock':
            return lambda: self.node.get_clock().now().nanoseconds > 0
        if ready.kind == 'subscribed':
            return lambda: self._subscribed(name, ready.name)
        if ready.kind == 'service':
            return self._service_ready(SERVICE_TYPES[ready.srv_type], ready.name)
        if ready.kind == 'page':  # on the graph, and its page answers
            url = f'http://127.0.0.1:{stage.params["port"]}/'
            return lambda: self._subscribed(name, ready.name) and http_ok(url)
        raise ValueError(f'no readiness check of kind {ready.kind!r} ({name})')

    # --- processes -------------------------------------------------------------------------
    def env(self) -> Dict[str, str]:
        """Return the nodes' environment: unbuffered, uncoloured, with the launcher's pid."""
        env = dict(os.environ)
        env.update(PYTHONUNBUFFERED='1', RCUTILS_COLORIZED_OUTPUT='0',
                   SCARA_LAUNCHER_PID=str(os.getpid()))
        return env

    def start(self, stage: Stage) -> Child:
        """Start ``stage`` in its own session, its output in ``logs/<name>.log``."""
        logs = self.output / 'logs'
        logs.mkdir(parents=True, exist_ok=True)
        log_path = logs / f'{stage.name}.log'
        log_file = open(log_path, 'wb')
        cmd = command(stage, self.config_dir)
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log_file,
                                stderr=subprocess.STDOUT, env=self.env(),
                                start_new_session=True)  # Ctrl-C reaches the launcher only
        child = Child(stage, proc, log_path, log_file, time.monotonic())
        self.children.append(child)
        self.write_pids()
        self._write_launch_file()
        return child

    def child_of(self, node: str) -> Optional[Child]:
        """Return the process that runs ``node`` (its own, or the one process), if started."""
        return next((c for c in self.children if c.stage.name == node
                     or any(m.name == node for m in c.stage.members)), None)

    def write_pids(self) -> None:
        """Write ``pids.json`` (stage name -> pid) atomically."""
        pids = {c.stage.name: c.proc.pid for c in self.children}
        tmp = self.output / 'pids.json.tmp'
        tmp.write_text(json.dumps(pids, indent=2) + '\n', encoding='utf-8')
        os.replace(tmp, self.output / 'pids.json')

    def _write_launch_file(self) -> None:
        info = {
            'argv': sys.argv,
            'python': sys.executable,
            'config_dir': str(self.config_dir),
            'ROS_DOMAIN_ID': os.environ.get('ROS_DOMAIN_ID'),
            'ROS_AUTOMATIC_DISCOVERY_RANGE': os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'),
            'commands': {c.stage.name: command(c.stage, self.config_dir)
                         for c in self.children},
        }
        (self.output / 'launch.json').write_text(json.dumps(info, indent=2) + '\n',
                                                 encoding='utf-8')

    def set_bridge(self, timeout: Optional[float] = None, supervise: bool = True,
                   **values: float) -> None:
        """Set the bridge's dynamic parameters (``real_time_factor``, ``feed_interval``)."""
        timeout = timeout or self.args.ready_timeout
        if self._bridge_params is None:
            self._bridge_params = AsyncParameterClient(self.node, 'pybullet_bridge')
        client = self._bridge_params
        self.wait_until(client.services_are_ready, timeout,
                        lambda: f'pybullet_bridge parameter services not available after '
                        f'{timeout:g} s', supervise)
        future = client.set_parameters(
            [Parameter(k, Parameter.Type.DOUBLE, float(v)) for k, v in values.items()])
        self.wait_until(future.done, timeout, lambda: 'pybullet_bridge did not answer '
                        f'set_parameters within {timeout:g} s', supervise)
        results = future.result().results if future.result() is not None else []
        for (key, value), res in zip(values.items(), results):
            if not res.successful:
                raise RunEnd(f'pybullet_bridge refused {key} {value}: {res.reason}')
        if len(results) != len(values):
            raise RunEnd(f'pybullet_bridge did not set {sorted(values)}')

    def _duplicates(self, name: str) -> int:
        return sum(1 for n, ns in self.node.get_node_names_and_namespaces()
                   if n == name and ns == '/')

    def start_graph(self) -> None:
        """Start every stage in order, each once the previous one is ready."""
        domain = os.environ.get('ROS_DOMAIN_ID', '0 (default)')
        self.console.say(f'[launch] mode {self.args.mode}, {self.args.duration:g} sim s, '
                         f'rtf {format_factor(self.rtf)}, output {self.output}')
        self.console.say(f'[launch] ROS_DOMAIN_ID {domain}, discovery '
                         f'{os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")}')
        if not self.with_automation:
            self.console.say(f'[launch] {AUTOMATION_MODULE} is not installed: idle graph '
                             'without the automation manager')
        for stage in self.stages:
            if self._duplicates(stage.name):
                raise RunEnd(f'a node named {stage.name} is already running on ROS_DOMAIN_ID '
                             f'{domain}; stop it or use another ROS_DOMAIN_ID')
        container = None
        if getattr(self.args, 'one_process', False):  # every node at once, in one process
            container = self.start(one_process(self.stages))
            self.console.say(f'[launch] {container.stage.name}: {container.stage.ready} '
                             f'(pid {container.proc.pid}), log {container.log_path}')
        for stage in self.stages:
            child = container or self.start(stage)
            timeout = self.args.ready_timeout
            self.wait_until(self.ready_check(stage), timeout,
                            lambda: f'stage {stage.name} not ready after {timeout:g} s '
                            f'(waiting for {stage.ready}); see {child.log_path}')
            child.ready_after = ready_after = time.monotonic() - child.started
            extra = ''
            if stage.name == 'pybullet_bridge':
                extra = f', sim t={self.recorder.sim_time:.2f} s'
                if self.launch_rtf != self.rtf:
                    extra += f', held at rtf {self.launch_rtf:g} until the job starts'
            self.console.say(f'[launch] {stage.name:<20} ready in {ready_after:4.1f} s '
                             f'(pid {child.proc.pid}): {stage.ready}{extra}')

    def start_job(self) -> None:
        """Call ``/automation_manager/start`` (not in idle mode) and release the clock."""
        if self.args.mode != 'idle':
            # refused while its endpoints are not matched yet (DDS discovery): ask again
            deadline = time.monotonic() + self.args.ready_timeout
            while True:
                res = self.call(Trigger, '/automation_manager/start', Trigger.Request(),
                                self.args.ready_timeout, 'automation_manager')
                if res.success:
                    break
                if time.monotonic() > deadline:
                    raise RunEnd(f'automation_manager refused to start for '
                                 f'{self.args.ready_timeout:g} s: {res.message}')
                self.console.say(f'[launch] automation_manager: {res.message}; asking again')
                self.pause(0.5)
            self.job_started = True
        t0 = self.recorder.start_job()
        release = {}
        if self.args.mode != 'idle':  # the belt starts feeding now
            feed = getattr(self.args, 'feed_interval', None)
            release['feed_interval'] = float(load_config('simulation')['feed_interval']
                                             if feed is None else feed)
        if self.launch_rtf != self.rtf:
            release['real_time_factor'] = self.rtf
        if release:
            self.set_bridge(**release)
            self.rtf_released = 'real_time_factor' in release
        self.recorder.extra['launch_wall_seconds'] = time.monotonic() - self.t_launch
        self.cpu.mark(self.cpu_now(), self.recorder.sim_time)
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

    # --- cost ------------------------------------------------------------------------------
    def cpu_now(self) -> Dict[str, Optional[float]]:
        """CPU seconds used so far by each node process and by the launcher itself."""
        out = {c.stage.name: process_cpu_seconds(c.proc.pid) for c in self.children}
        out['launcher'] = time.process_time()
        return out

    def measure_cpu(self) -> None:
        """Close the job's CPU window: CPU s per sim s per process into the summary."""
        if self.cpu.marked:
            cost = self.cpu.close(self.cpu_now(), self.recorder.sim_time)
            if cost:
                self.recorder.extra['cpu_per_sim_s'] = cost

    # --- shutdown --------------------------------------------------------------------------
    def hold_clock(self) -> None:
        """Slow the bridge back to the launch pace, so the shutdown does not race sim time."""
        if self.rtf_released and len(self.signals) < 2:
            self.rtf_released = False
            bridge = self.children[0] if self.children else None
            if bridge is not None and bridge.proc.poll() is None:
                try:
                    self.set_bridge(timeout=2.0, supervise=False,
                                    real_time_factor=self.launch_rtf)
                except RunEnd:
                    pass

    def stop_job(self) -> None:
        """Ask the automation manager to stop the job (best effort, short timeout)."""
        if not self.job_started:
            return
        self.job_started = False
        auto = self.child_of('automation_manager')
        if auto is None or auto.proc.poll() is not None or len(self.signals) > 1:
            return
        if self.silent_node == 'automation_manager':
            self.recorder.extra['job_stop'] = 'not stopped: automation_manager does not answer'
            return
        try:
            res = self.call(Trigger, '/automation_manager/stop', Trigger.Request(), 5.0,
                            'automation_manager', supervise=False, attempts=2,
                            attempt_timeout=2.0)
        except RunEnd as exc:
            self.recorder.extra['job_stop'] = f'not stopped: {exc.reason}'
            return
        self.recorder.extra['job_stop'] = res.message

    def stop_children(self, grace: float = 5.0) -> None:
        """SIGINT (and SIGCONT) the children in reverse order, wait, then kill what remains.

        :param grace: wall seconds the children have to exit before SIGKILL.
        """
        t0 = time.monotonic()
        for child in reversed(self.children):
            if child.proc.poll() is None:
                # a node still starting may not handle SIGINT yet (a library can swallow the
                # KeyboardInterrupt while importing); SIGTERM ends it either way
                sig = signal.SIGINT if child.ready_after is not None else signal.SIGTERM
                try:
                    child.proc.send_signal(sig)
                    child.proc.send_signal(signal.SIGCONT)  # a stopped child handles it now
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + grace
        for child in reversed(self.children):
            while child.proc.poll() is None and time.monotonic() < deadline \
                    and len(self.signals) < 2:
                try:
                    child.proc.wait(timeout=0.05)
                except subprocess.TimeoutExpired:
                    pass
        for child in reversed(self.children):
            if child.proc.poll() is None:
                self.console.say(f'[launch] {child.stage.name} did not stop on SIGINT; killing',
                                 error=True)
                child.proc.kill()
                try:
                    child.proc.wait(timeout=5.0)
                except subprocess.TimeoutExpired:
                    pass
            child.log_file.close()
        if self.children:
            self.console.say(f'[launch] nodes stopped in {time.monotonic() - t0:.1f} s')
        self.recorder.extra['nodes'] = {
            c.stage.name: {'pid': c.proc.pid, 'exit_code': c.proc.returncode,
                           'ready_after_s': c.ready_after,
                           'log': str(c.log_path.relative_to(self.output))}
            for c in self.children}

    def close(self) -> None:
        """Shut down the executors, destroy the nodes and shut down the context."""
        self.executor.shutdown(timeout_sec=1.0)
        self._watch_executor.shutdown(timeout_sec=1.0)
        self._watch_node.destroy_node()
        self.recorder.destroy_node()
        rclpy.try_shutdown(context=self.context)


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


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the cell; returns the exit status (see the module docstring)."""
    args = parse_args(argv)
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
            summary = launcher.recorder.finish(reason, interrupted, plots=not args.no_plots)
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
