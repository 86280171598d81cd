"""The launcher as a subprocess for the sections that run it; a run's row; their blocks."""
from contextlib import contextmanager
import fcntl
import json
import os
from pathlib import Path
import queue
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Dict, Iterator, List, Optional, Sequence

from benchmarks.util import Log, mm, num, table, write_block

Summary = Dict[str, object]
HOG = 'import time\nend = time.monotonic() + {limit}\nwhile time.monotonic() < end: pass\n'


@contextmanager
def cpu_hogs(n: int, limit: float) -> Iterator[None]:
    """Run ``n`` busy-looping processes (each ends by itself after ``limit`` s) meanwhile."""
    hogs = [subprocess.Popen([sys.executable, '-c', HOG.format(limit=limit)]) for _ in range(n)]
    try:
        yield
    finally:
        for h in hogs:
            h.kill()
            h.wait()


_HELD: List = []
"""The lock file of the domain this process is in (none before :func:`use_domain`)."""


def use_domain(k: int) -> int:
    """Put this process and the launchers it starts in a ROS domain of their own; return it.

    The first of 140..229 from ``140 + k % 90`` that no other process on this machine holds:
    an advisory lock in the temp folder, held until the next call or the process's end. Two
    benchmark runs side by side therefore never hear each other's launches.
    """
    while _HELD:
        _HELD.pop().close()
    for i in range(90):
        domain = 140 + (k + i) % 90
        lock = open(Path(tempfile.gettempdir()) / f'scara_collab_domain_{domain}.lock', 'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _HELD.append(lock)
        os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
        return domain
    raise RuntimeError('ROS domains 140..229 are all held by other benchmark runs on this host')


class Launch:
    """The launcher as a subprocess (no plots), its output lines collected in a thread."""

    def __init__(self, mode: str, duration: float, out: Path, rtf: float = 0.0,
                 flags: Sequence[str] = (), quiet: bool = True, env: Dict[str, str] = None):
        """Start the launcher for ``duration`` sim s into the run folder ``out``."""
        self.out, self.start = Path(out), time.monotonic()
        cmd = [sys.executable, '-m', 'scara_collab.run.launcher', '--mode', mode, '--duration',
               f'{duration:g}', '--rtf', f'{rtf:g}', '--output', str(out), '--no-plots',
               *flags, *(['--quiet'] if quiet else [])]
        self.proc = subprocess.Popen(cmd, env=dict(env or os.environ, PYTHONUNBUFFERED='1'),
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: List[str] = []
        self._queue: 'queue.Queue[str]' = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip('\n'))
            self._queue.put(line)

    def wait_for(self, pattern: str, timeout: float = 180.0) -> bool:
        """Return True once a line matches ``pattern`` (False on timeout or exit)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                if re.search(pattern, self._queue.get(timeout=0.2)):
                    return True
            except queue.Empty:
                if self.proc.poll() is not None:
                    return False
        return False

    def pid(self, node: str) -> int:
        """Return the pid of a launched node."""
        return int(json.loads((self.out / 'pids.json').read_text())[node])

    def log(self, node: str) -> str:
        """Return a node's log of the run ('' if it has none)."""
        path = self.out / 'logs' / f'{node}.log'
        return path.read_text(errors='replace') if path.is_file() else ''

    def finish(self, timeout: Optional[float]) -> Summary:
        """Wait (SIGINT, SIGKILL after ``timeout`` wall s); return ``summary.json`` and exit."""
        error = None
        for stop in (None, signal.SIGINT, signal.SIGKILL):
            if stop is not None:  # SIGINT: the launcher stops its nodes and writes its files
                self.proc.send_signal(stop)
                error = f'the launcher did not finish within {timeout:.0f} s'
            try:
                self.proc.wait(timeout=timeout if stop is None else 60)
                break
            except subprocess.TimeoutExpired:
                pass
        path = self.out / 'summary.json'
        summary = json.loads(path.read_text()) if path.is_file() else {}
        if not summary and error is None:
            error = f'no summary.json (exit code {self.proc.returncode}): ' + ' / '.join(
                self.lines[-5:])
        return dict(summary, exit_code=self.proc.returncode,
                    launcher_wall_seconds=time.monotonic() - self.start,
                    **({'error': error} if error else {}))


def run_launcher(mode: str, duration: float, output: Path, rtf: float = 0.0,
                 seed: Optional[int] = None, timeout: float = 600.0,
                 extra: Sequence[str] = ()) -> Summary:
    """Run the launcher to the end (``rtf`` 0: unthrottled); return its summary."""
    flags = list(extra) + (['--seed', str(seed)] if seed is not None else [])
    return Launch(mode, duration, output, rtf, flags).finish(timeout)


def stops(summary: Summary, kind: str) -> List[Dict[str, object]]:
    """Return the ``kind`` (``'protective'``, ``'emergency'``) stops of a run's summary."""
    value = summary.get(f'{kind}_stops')
    return list(value) if isinstance(value, list) else []


KEYS = ('exit_code', 'exit_reason', 'error', 'sorted', 'missed', 'dropped', 'wrong_bin',
        'items_per_minute', 'min_separation_m', 'mirror_error_max_m', 'mirror_in_step_moves',
        'mirror_not_in_step', 'real_time_factor', 'sim_seconds')


def row(summary: Summary) -> Dict[str, object]:
    """Return one run's figures: :data:`KEYS`, the job's give-ups, its stops, CPU, overspeed."""
    job = summary.get('job') or {}
    cpu = summary.get('cpu_per_sim_s') or {}
    protective, emergency = stops(summary, 'protective'), stops(summary, 'emergency')
    both = protective + emergency
    return {**{k: summary.get(k) for k in KEYS},
            **{k: job.get(k) for k in ('give_ups', 'retries', 'last_give_up')},
            'protective': len(protective), 'emergency': len(emergency),
            'own_moves': sum('predicted' in str(s.get('cause', '')) for s in both),
            'lost_s': round(sum(float(s.get('lost') or 0.0) for s in both), 3),
            'causes': '; '.join(sorted({str(s.get('cause', ''))[:60] for s in both})),
            'cpu_s': cpu.get('total') if isinstance(cpu, dict) else None,
            'overspeed': summary.get('overspeed_count')}


def launch(what: str, domain: int, mode: str, duration: float, out: Path, log: Log,
           hogs: int = 0, **kwargs) -> Dict[str, object]:
    """Run the launcher in ``domain`` beside ``hogs`` CPU hogs; log and return its :func:`row`."""
    use_domain(domain)
    kwargs.setdefault('timeout', duration * 3 + 300)
    with cpu_hogs(hogs, kwargs['timeout']):
        r = row(run_launcher(mode, duration, out, **kwargs))
    log(f'{what}: exit {r["exit_code"]}, sorted {r["sorted"]}, missed {r["missed"]}, dropped '
        f'{r["dropped"]}, give-ups {r["give_ups"]}, min separation {r["min_separation_m"]}, '
        f'stops {r["protective"]} protective / {r["emergency"]} emergency '
        f'({r["own_moves"]} by the job\'s own moves)')
    return r


FORMATS = {'min_separation_m': lambda v: num(v, 3, 'm'), 'real_time_factor': num,
           'mirror_error_max_m': mm}


def cells(rows: Sequence[Dict[str, object]], keys: Sequence[str]) -> str:
    """Return a Markdown table of the rows' ``keys``, headed by the keys without underscores."""
    return table([{k.replace('_', ' '): FORMATS.get(k, str)(r.get(k)) for k in keys}
                  for r in rows])


def stamp(command: str, start: float, what: str = '') -> str:
    """Return a block's first line: the command, the date, the wall minutes since ``start``."""
    return (f'*Generated by `{command}` on {time.strftime("%Y-%m-%d %H:%M %Z")} '
            f'({(time.monotonic() - start) / 60:.1f} min wall)' + (f': {what}*' if what else '*'))


def publish(text: str, page: Optional[Path], name: str, heading: str, log: Log,
            folder: Path) -> None:
    """Print a block, write it as block ``name`` of ``page`` (None: not), name the run folder."""
    print(text)
    if page is not None:
        write_block(page, name, heading, text)
    log(f'run folders in {folder}')
