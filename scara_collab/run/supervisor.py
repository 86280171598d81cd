"""The launcher's child processes: start them, watch them exit, stop them, say what they cost.

Each stage (:mod:`scara_collab.run.stages`) runs in its own session (Ctrl-C reaches the
launcher only) with its output in ``logs/<name>.log``; ``pids.json`` and ``launch.json`` say
what runs. A child that exits ends the run (:class:`RunEnd`, with the tail of its log); at the
end the children get SIGINT in reverse order (SIGTERM if still starting) and SIGCONT, and what
remains after the grace period is killed.

Crashes (the launcher's ``--fault crash:/<node>:T``, :func:`scara_collab.run.stages.crashes`)
are the supervisor's too: :meth:`Supervisor.crash_due` sends SIGKILL to the process that runs
the node once sim time reaches T (no goodbye, as a killed process), says so on the console and
at the end of that process's log, and the run then ends as for any process that died.
"""
from dataclasses import dataclass
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Dict, IO, List, Optional

from scara_collab.records.telemetry import process_cpu_seconds
from scara_collab.run.console import Console
from scara_collab.run.environment import node_environment
from scara_collab.run.stages import command, Stage

EXIT_FAILED = 1
EXIT_USAGE = 2


class RunEnd(Exception):
    """The run ends early: ``reason`` for the summary, ``code`` for the exit status."""

    def __init__(self, reason: str, code: int = EXIT_FAILED, details: str = ''):
        """Keep ``reason``, the exit ``code`` and optional ``details`` for the summary."""
        super().__init__(reason)
        self.reason, self.code, self.details = reason, code, details


@dataclass
class Child:
    """A started stage."""

    stage: Stage
    proc: subprocess.Popen
    log_path: Path
    log_file: IO
    started: float
    ready_after: Optional[float] = None
    crashed_at: Optional[float] = None  # sim s it was killed at (fault injection: crash)


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


class Supervisor:
    """The node processes of one run, in the order they were started.

    :param output: the run folder (``logs/``, ``pids.json``, ``launch.json``).
    :param config_dir: the folder of the ``config/*.yaml`` files the nodes read.
    :param console: where the stop lines go.
    """

    def __init__(self, output: Path, config_dir: Path, console: Console,
                 crashes: Optional[Dict[str, float]] = None):
        """Start with no child.

        :param crashes: the nodes to kill and the sim time of each (``{name: s}``).
        """
        self.output = output
        self.config_dir = config_dir
        self.console = console
        self.children: List[Child] = []
        self.crashes: Dict[str, float] = dict(crashes or {})

    def env(self) -> Dict[str, str]:
        """Return the nodes' environment: the launcher's own ROS, unbuffered, uncoloured, its pid.

        The library path and the ROS wheels' start-up are the launcher's Python environment's
        (:func:`~scara_collab.run.environment.node_environment`), whatever started it.
        """
        env = node_environment(os.environ)
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

    def running(self, node: str) -> bool:
        """Return whether the process that runs ``node`` was started and has not exited."""
        child = self.child_of(node)
        return child is not None and child.proc.poll() is None

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
            'ROS_DISCOVERY_SERVER': os.environ.get('ROS_DISCOVERY_SERVER'),
            'commands': {c.stage.name: command(c.stage, self.config_dir)
                         for c in self.children},
        }
        (self.output / 'launch.json').write_text(json.dumps(info, indent=2) + '\n',
                                                 encoding='utf-8')

    def log_tail(self, node: str) -> str:
        """Return the last lines of ``node``'s log, indented, after a line naming the file."""
        child = self.child_of(node)
        log = child.log_path if child else self.output / 'logs' / f'{node}.log'
        return f'last lines of {log}:\n' + '\n'.join('    ' + ln
                                                     for ln in tail(log).splitlines())

    def crash_due(self, sim_time: float) -> None:
        """Kill the process of each node whose crash time ``sim_time`` (s) has reached.

        SIGKILL, then a line at the end of its log (stamped with the wall time, like a ROS
        log line) and on the console.
        """
        for node, at in list(self.crashes.items()):
            child = self.child_of(node)
            if sim_time < at - 1e-9 or child is None:
                continue
            del self.crashes[node]
            if child.proc.poll() is not None:
                continue
            stamp = time.time()
            child.proc.kill()
            child.proc.wait()
            child.crashed_at = sim_time
            text = (f'fault injection: crash of {node} at sim t={sim_time:.3f} s: SIGKILL to '
                    f'pid {child.proc.pid}')
            child.log_file.write(f'[ERROR] [{stamp:.9f}] [launch]: {text}\n'.encode('utf-8'))
            child.log_file.flush()
            self.console.say(f'[launch] {text}', error=True)

    def check(self) -> None:
        """Raise :class:`RunEnd` if a child has exited (its name, code and log tail)."""
        for child in self.children:
            code = child.proc.poll()
            if code is not None:
                name = child.stage.name
                how = (f'was killed at sim t={child.crashed_at:.3f} s (fault injection: crash)'
                       if child.crashed_at is not None else f'exited with {describe_exit(code)}')
                raise RunEnd(f'node {name} {how}', EXIT_FAILED, f'[launch] {self.log_tail(name)}')

    def cpu_now(self) -> Dict[str, Optional[float]]:
        """CPU seconds used so far by each node process and by the launcher itself."""
        out = {c.stage.name: process_cpu_seconds(c.proc.pid) for c in self.children}
        out['launcher'] = time.process_time()
        return out

    def stop(self, grace: float, signals: List[str]) -> Dict[str, Dict]:
        """SIGINT (and SIGCONT) the children in reverse order, wait, then kill what remains.

        :param grace: wall seconds the children have to exit before SIGKILL.
        :param signals: the signals the launcher got so far; a second one cuts the wait short.
        :return: per child its pid, exit code, ready time and log (``nodes`` of the summary).
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
                    and len(signals) < 2:
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
        return {c.stage.name: {'pid': c.proc.pid, 'exit_code': c.proc.returncode,
                               'ready_after_s': c.ready_after,
                               'log': str(c.log_path.relative_to(self.output))}
                for c in self.children}
