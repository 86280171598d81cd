"""Launch the whole cell on sim time, run the job, record it, report it (``launch_cell.py``).

:func:`main` reads the options (:mod:`~scara_collab.run.options`), runs a line of cells
(:mod:`~scara_collab.run.line_launcher`) or one cell: :class:`Launcher` starts the nodes of
:mod:`scara_collab.graph` stage by stage (:mod:`~scara_collab.run.stages`, started and
stopped by :mod:`~scara_collab.run.supervisor`), starts the job and the clock, supervises
the run (:mod:`~scara_collab.run.liveness`, :mod:`~scara_collab.run.graph_client`) and stops
it. How a run starts and ends, and its files: ``docs/runs.md``; its exit status: the README.
"""
import contextlib
import datetime
import importlib.util
import os
from pathlib import Path
import signal
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
from scara_collab.nodes.recorder import RunRecorder
from scara_collab.nodes.runner import localhost_by_default, make_executor
from scara_collab.records.report import format_progress, format_report
from scara_collab.records.telemetry import CpuMeter
from scara_collab.run import discovery
from scara_collab.run.console import Console
from scara_collab.run.graph_client import GraphClient
from scara_collab.run.liveness import Liveness
from scara_collab.run.options import LaunchOptions, parse_options
from scara_collab.run.stages import crashes, one_process, stages
from scara_collab.run.supervisor import EXIT_FAILED, EXIT_USAGE, RunEnd, Supervisor

AUTOMATION_MODULE = graph.node('automation_manager').entry.split(':')[0]


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
    """Run the job: start the graph, start the job, supervise, stop (docs/runs.md).

    The parts it drives: the node processes (:class:`Supervisor`), the launcher's side of the
    graph (:class:`GraphClient` on the run recorder's node), the run's record
    (:class:`RunRecorder`), the lockstep answers (:class:`Liveness`) and the job's CPU cost
    (:class:`CpuMeter`).
    """

    def __init__(self, opts: LaunchOptions, output: Path, console: Console):
        """Plan the stages and set up the recorder, its executor and the lockstep watch.

        :param opts: the run's options.
        :param output: the run folder.
        :param console: where stage lines and progress go.
        """
        self.opts = opts
        self.output = output
        self.console = console
        self.with_automation = importlib.util.find_spec(AUTOMATION_MODULE) is not None
        self.stages = stages(opts, self.with_automation)
        self.processes = Supervisor(output, config_dir(), console, crashes(opts))
        self.signals: List[str] = []
        self.job_started = False
        self.rtf_released = False
        self.t_launch = time.monotonic()
        self.context = rclpy.Context()
        self.namespace = opts.namespace
        # the launcher asks the graph for every node: with a discovery server it must learn the
        # whole graph (a super client); its participant is made with its first node
        with discovery.super_client() as self.super_client:
            rclpy.init(args=[], context=self.context,
                       signal_handler_options=SignalHandlerOptions.NO)
            recorder = RunRecorder
            if opts.faults:  # its service calls too (drop:/.../start:1)
                from scara_collab.run.faults import hook
                recorder = hook(opts.faults)(RunRecorder)
            self.recorder = recorder(output, opts.mode, profile=opts.profile,
                                     context=self.context, namespace=self.namespace,
                                     person=opts.cell_person or '')
        self.recorder.extra['lockstep'] = opts.lockstep_name
        if opts.record:
            record_mcap(self.recorder, output, console)
        self.executor = make_executor(context=self.context)
        self.executor.add_node(self.recorder)
        self.ros = GraphClient(self.recorder, self.executor, console, self.check, self.signals,
                               opts.ready_timeout, self.namespace)
        self.cpu = CpuMeter()
        self._next_poll = self._next_checkpoint = self._next_watch = 0.0
        self.rtf = opts.rtf
        self.launch_rtf = opts.launch_rtf
        self.liveness = Liveness([] if opts.one_process else [  # nobody can be behind: no watch
            s.name for s in self.stages if graph.node(s.name).lockstep],
                                 opts.silent_timeout, self.context, self.namespace)

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
        """Raise :class:`RunEnd` on a signal, a dead node process or a silent node.

        A crash that is due (``--fault crash:``) is the supervisor's kill, at every look.
        """
        if self.signals:
            sig = self.signals[0]
            raise RunEnd(sig, 130 if sig == 'SIGINT' else 143)
        if self.processes.crashes:
            self.processes.crash_due(self.recorder.sim_time)
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
        self.console.say(f'[launch] mode {self.opts.mode}, {self.opts.duration:g} sim s, '
                         f'rtf {format_factor(self.rtf)}, lockstep '
                         f'{self.opts.lockstep_name}, output {self.output}')
        server = os.environ.get(discovery.ENV)
        self.console.say(f'[launch] ROS_DOMAIN_ID {domain}, discovery '
                         + (f'server {server} (the launcher '
                            f'{"a super client" if self.super_client else "a plain client"})'
                            if server else
                            f'{os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")}')
                         + (f', namespace {self.namespace}' if self.namespace else ''))
        if (not self.opts.lockstep and self.rtf != 0 and not self.opts.one_process
                and (os.cpu_count() or 1) <= 2):
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
        if self.opts.one_process:  # every node at once, in one process
            container = self.processes.start(one_process(self.stages))
            self.console.say(f'[launch] {container.stage.name}: {container.stage.ready} '
                             f'(pid {container.proc.pid}), log {container.log_path}')
        for stage in self.stages:
            child = container or self.processes.start(stage)
            timeout = self.opts.ready_timeout
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
        if self.opts.mode != 'idle':
            self.ros.start(self.name('automation_manager/start'), self.opts.ready_timeout,
                           'automation_manager')
            self.job_started = True
        t0 = self.recorder.start_job()
        release = {}
        if self.opts.mode != 'idle' and graph.fed(self.opts.cell, self.opts.cells):
            # the belt starts feeding now (in a line, only cell 0's: the others are handed on)
            feed = self.opts.feed_interval
            release['feed_interval'] = float(load_config('simulation')['feed_interval']
                                             if feed is None else feed)
        if self.launch_rtf != self.rtf:
            release['real_time_factor'] = self.rtf
        if release:
            self.ros.set_bridge(**release)
            self.rtf_released = 'real_time_factor' in release
        res = self.ros.call(Trigger, self.name('sim/resume'), Trigger.Request(),
                            self.opts.ready_timeout, 'pybullet_bridge')
        if not res.success:
            raise RunEnd(f'pybullet_bridge refused to resume: {res.message}')
        self.liveness.expect(time.monotonic())  # a node that never answers is silent too
        self.recorder.extra['launch_wall_seconds'] = time.monotonic() - self.t_launch
        self.cpu.mark(self.processes.cpu_now(), self.recorder.sim_time)
        job = f'{self.opts.mode} job started' if self.job_started else 'graph idle'
        self.console.say(f'[launch] {job} at sim t={t0:.2f} s after '
                         f'{time.monotonic() - self.t_launch:.1f} s; running '
                         f'{self.opts.duration:g} sim s at rtf {format_factor(self.rtf)}')

    def supervise(self) -> None:
        """Spin until the duration is reached; progress; :class:`RunEnd` on trouble."""
        end = self.recorder.job_start + self.opts.duration
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
            elif now - last_change > self.opts.stall_timeout:
                raise RunEnd(f'sim time stood still at t={sim:.2f} s for '
                             f'{self.opts.stall_timeout:g} s (is pybullet_bridge stuck?)')
            if now >= next_progress:
                next_progress = now + period
                self.console.progress(format_progress(self.recorder.progress(),
                                                      self.opts.duration))

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
    """Run the cell or the line of ``argv`` (default: ``sys.argv[1:]``); return the exit status."""
    opts = parse_options(argv)
    with contextlib.ExitStack() as stack:
        if opts.discovery_server is not None:
            try:
                address = stack.enter_context(discovery.server(opts.discovery_server or None))
            except (FileNotFoundError, RuntimeError) as exc:
                print(f'launch_cell: --discovery-server: {exc}', file=sys.stderr)
                return EXIT_USAGE
            print(f'[launch] Fast DDS discovery server on {address}', flush=True)
        return run(opts, argv)


def run(opts: LaunchOptions, argv: Optional[Sequence[str]]) -> int:
    """Run the cell or the line ``opts`` (parsed from ``argv``); return the exit status."""
    if opts.cells > 1 and opts.line_cell is None:  # a line: one launcher per cell
        from scara_collab.run.line_launcher import run_line
        return run_line(opts, list(sys.argv[1:] if argv is None else argv))
    if opts.mode != 'idle' and importlib.util.find_spec(AUTOMATION_MODULE) is None:
        print(f'launch_cell: --mode {opts.mode} needs the automation manager '
              f'({AUTOMATION_MODULE}), which is not installed; --mode idle runs the graph '
              'without it', file=sys.stderr)
        return EXIT_USAGE
    localhost_by_default()  # before rclpy.init, as every executable does
    output = (opts.output or default_output(opts.mode)).resolve()
    output.mkdir(parents=True, exist_ok=True)
    console = Console(output / 'launch.log', opts.quiet)
    try:
        launcher = Launcher(opts, output, console)
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
            summary = launcher.recorder.finish(reason, interrupted, plots=opts.plots)
            code = summary['exit_code']  # the run's verdict: this code unless it was 0
            text = format_report(summary)
            (output / 'report.txt').write_text(text + '\n', encoding='utf-8')
            console.say(text, error=True)
            if opts.animation:  # after the run: never slows it down
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
