"""The job protocol under load and faults, through the launcher (separate processes).

Three measurements (``scripts/benchmark.py --only protocol`` runs them and writes the tables):

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
import tempfile
import time
from typing import Dict, Iterator, List, Optional, Sequence

from scara_collab.bench.job import run_launcher
from scara_collab.bench.report import write_block
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


def _fmt(v, scale: float = 1.0, unit: str = ' m', digits: int = 3) -> str:
    return 'n/a' if v is None else f'{v * scale:.{digits}f}{unit}'


def render(long, mirrored, hogs, sizes: Dict[str, object], command: str, wall: float) -> str:
    """Return the Markdown tables of the three measurements, headed by date and wall time."""
    lines = [f'*Generated by `{command}` on {time.strftime("%Y-%m-%d %H:%M %Z")} '
             f'({wall / 60:.1f} min wall); each row is one launcher run (separate processes, '
             'unthrottled, lockstep on), its figures from its `summary.json`.*', '']
    if long is not None:
        r = long
        lines += [f'**Collaborative, default feed, {sizes["long"]:g} sim s through the '
                  'launcher**', '', '| sorted | missed | dropped | wrong bin | give-ups | '
                  'retries | items/min | min separation | e-stops | RTF |', '|---' * 10 + '|',
                  f'| {r["sorted"]} | {r["missed"]} | {r["dropped"]} | {r["wrong_bin"]} | '
                  f'{r["give_ups"]} | {r["retries"]} | {r["items_per_minute"] or 0:.1f} | '
                  f'{_fmt(r["min_separation_m"])} | {r["emergency_stops"]} | '
                  f'{_fmt(r["real_time_factor"], unit="×", digits=2)} |', '']
        if r.get('last_give_up'):
            lines += [f'Last give-up: {r["last_give_up"]}', '']
    if mirrored:
        lines += [f'**Mirrored, {sizes["mirrored"]:g} sim s per seed** (in-step error: the '
                  "replication manager's, over pairs the bridge started at the same instant "
                  'from mirrored poses)', '', '| seed | sorted | missed | dropped | in-step '
                  'error max | in-step pairs | not in step | give-ups | RTF |', '|---' * 9 + '|']
        lines += [f'| {r["seed"]} | {r["sorted"]} | {r["missed"]} | {r["dropped"]} | '
                  f'{_fmt(r["mirror_error_max_m"], 1e3, " mm")} | {r["mirror_in_step_moves"]} '
                  f'| {r["mirror_not_in_step"]} | {r["give_ups"]} | '
                  f'{_fmt(r["real_time_factor"], unit="×", digits=2)} |' for r in mirrored]
        lines.append('')
    if hogs:
        done = sum(r['completed'] for r in hogs)
        lines += [f'**The demo ({sizes["hog_duration"]:g} sim s) with {sizes["hogs"]} CPU '
                  f'hogs: {done} of {len(hogs)} runs completed** (exit 0, items sorted, none '
                  'missed)', '', '| run | exit | sorted | missed | dropped | give-ups | '
                  'retries | min separation | RTF |', '|---' * 9 + '|']
        lines += [f'| {k + 1} | {r["exit_code"]} | {r["sorted"]} | {r["missed"]} | '
                  f'{r["dropped"]} | {r["give_ups"]} | {r["retries"]} | '
                  f'{_fmt(r["min_separation_m"])} | '
                  f'{_fmt(r["real_time_factor"], unit="×", digits=2)} |'
                  for k, r in enumerate(hogs)]
    return '\n'.join(lines).rstrip() + '\n'


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the three measurements; print the tables, write them as the ``job-protocol`` block.

    Sizes: 600 sim s collaborative, mirrored seeds 11 12 13 (``args.seeds``) 90 sim s each,
    ``args.runs`` (5) demo runs of 60 sim s beside ``args.hogs`` (2) CPU hogs; with
    ``args.smoke`` 60 s, one seed of 30 s, 2 runs of 30 s (printed, not written).

    :return: True if every demo run beside the hogs completed.
    """
    smoke = args.smoke
    sizes = {'long': 60.0 if smoke else 600.0, 'mirrored': 30.0 if smoke else 90.0,
             'hog_duration': 30.0 if smoke else 60.0, 'hogs': args.hogs or 2}
    seeds = (args.seeds or [11, 12, 13])[:1 if smoke else None]
    out = Path(tempfile.mkdtemp(prefix='scara_job_protocol_'))
    t0 = time.monotonic()
    long = long_run(out, sizes['long'], log=log)
    mirrored = mirrored_runs(out, seeds, sizes['mirrored'], log=log)
    hogs = robustness(out, args.runs or (2 if smoke else 5), sizes['hogs'],
                      sizes['hog_duration'], log=log)
    text = render(long, mirrored, hogs, sizes, command, time.monotonic() - t0)
    print(text)
    if not smoke:
        write_block(page, 'job-protocol', 'The job protocol through the launcher', text)
    log(f'run folders in {out}')
    return all(r['completed'] for r in hogs)
