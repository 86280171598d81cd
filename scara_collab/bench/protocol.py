"""The job protocol under load and faults, through the launcher (separate processes).

Three measurements (``scripts/bench_job_protocol.py`` runs them and writes the tables):

- :func:`long_run`: the collaborative job at the default feed for a long run (600 sim s):
  missed, dropped, give-ups, wrong bin, the margin;
- :func:`mirrored_runs`: mirrored mode over several seeds: the in-step mirror error (the
  replication manager's), pairs not in step, missed;
- :func:`robustness`: the demo's run repeated while CPU hogs compete: how many complete.

Each launcher run has its own ROS domain and run folder; every figure is read from the run's
``summary.json`` (one source per figure, see :mod:`scara_collab.records.record`).
"""
from contextlib import contextmanager
import os
from pathlib import Path
import subprocess
import sys
from typing import Dict, Iterator, List, Optional, Sequence

from scara_collab.bench.job import run_launcher
from scara_collab.bench.util import Log

HOG = 'import time\nend = time.monotonic() + {limit}\nwhile time.monotonic() < end: pass\n'


@contextmanager
def cpu_hogs(n: int, limit: float) -> Iterator[None]:
    """Run ``n`` busy-looping processes (each ends by itself after ``limit`` s) meanwhile."""
    hogs = [subprocess.Popen([sys.executable, '-c', HOG.format(limit=limit)])
            for _ in range(n)]
    try:
        yield
    finally:
        for h in hogs:
            h.kill()
            h.wait()


def row(summary: Dict[str, object]) -> Dict[str, object]:
    """Return the figures of one launcher run, from its summary."""
    job = summary.get('job') or {}
    return {
        'exit_code': summary.get('exit_code'), 'exit_reason': summary.get('exit_reason'),
        'error': summary.get('error'),
        **{k: summary.get(k) for k in ('sorted', 'missed', 'dropped', 'wrong_bin', 'spawned',
                                       'in_progress', 'items_per_minute', 'min_separation_m',
                                       'mirror_error_max_m',
                                       'mirror_in_step_moves', 'mirror_not_in_step',
                                       'real_time_factor', 'sim_seconds')},
        **{k: len(summary[k]) if isinstance(summary.get(k), list) else 0
           for k in ('emergency_stops', 'protective_stops')},
        'give_ups': job.get('give_ups'), 'retries': job.get('retries'),
        'last_give_up': job.get('last_give_up'),
    }


def _env_domain(k: int) -> None:
    os.environ['ROS_DOMAIN_ID'] = str(140 + k % 90)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'


def long_run(out: Path, duration: float = 600.0, seed: Optional[int] = None,
             log: Optional[Log] = None) -> Dict[str, object]:
    """Run the collaborative job for ``duration`` sim s through the launcher."""
    _env_domain(0)
    if log:
        log(f'collaborative, {duration:g} sim s through the launcher ...')
    r = row(run_launcher('collaborative', duration, out / 'long', seed=seed,
                         timeout=duration * 3 + 300))
    if log:
        log(f'  sorted {r["sorted"]}, missed {r["missed"]}, dropped {r["dropped"]}, '
            f'give-ups {r["give_ups"]}, min separation {r["min_separation_m"]}')
    return r


def mirrored_runs(out: Path, seeds: Sequence[int] = (11, 12, 13), duration: float = 90.0,
                  log: Optional[Log] = None) -> List[Dict[str, object]]:
    """Run the mirrored job once per seed through the launcher."""
    rows = []
    for k, seed in enumerate(seeds):
        _env_domain(1 + k)
        r = row(run_launcher('mirrored', duration, out / f'mirrored_{seed}', seed=seed,
                             timeout=duration * 4 + 300))
        r['seed'] = seed
        rows.append(r)
        if log:
            err = r['mirror_error_max_m']
            log(f'mirrored seed {seed}: sorted {r["sorted"]}, missed {r["missed"]}, in-step '
                f'error {"n/a" if err is None else f"{err * 1e3:.3f} mm"} over '
                f'{r["mirror_in_step_moves"]} pairs, {r["mirror_not_in_step"]} not in step')
    return rows


def robustness(out: Path, runs: int = 5, hogs: int = 2, duration: float = 60.0,
               extra: Sequence[str] = (), log: Optional[Log] = None) -> List[Dict[str, object]]:
    """Run the demo's job ``runs`` times while ``hogs`` CPU hogs compete.

    A run *completes* when the launcher exits 0 with items sorted and none missed.
    """
    rows = []
    with cpu_hogs(hogs, runs * (duration * 4 + 200)):
        for k in range(runs):
            _env_domain(10 + k)
            r = row(run_launcher('collaborative', duration, out / f'hogs_{k + 1}',
                                 timeout=duration * 6 + 300, extra=list(extra)))
            r['completed'] = bool(r['exit_code'] == 0 and (r['sorted'] or 0) > 0
                                  and r['missed'] == 0)
            rows.append(r)
            if log:
                log(f'run {k + 1}/{runs} with {hogs} hogs: exit {r["exit_code"]}, sorted '
                    f'{r["sorted"]}, missed {r["missed"]}, dropped {r["dropped"]}, give-ups '
                    f'{r["give_ups"]}, retries {r["retries"]}: '
                    f'{"completed" if r["completed"] else "FAILED " + str(r["exit_reason"])}')
    return rows
