"""A long run through the launcher with the memory of every process sampled (the soak).

:func:`soak` starts the launcher (one process per node), samples each process's resident
memory (``VmRSS`` from ``/proc/<pid>/status``) against the run's sim time while it runs, and
returns the run's summary figures with, per process, the RSS after the warm-up and at the end
and the growth per sim hour between them. Lockstep drops are counted from the bridge's log.
``scripts/benchmark.py --only soak`` prints the table and writes it into the docs.
"""
import json
import os
from pathlib import Path
import re
import subprocess
import sys
import tempfile
import time
from typing import Dict, List, Optional, Tuple

from scara_collab.bench.protocol import row
from scara_collab.bench.report import write_block
from scara_collab.bench.util import Log

#: the bridge's words when it stops waiting for a silent node (scara_collab.nodes.lockstep)
DROP_WORDS = 'not waiting for it any more'
#: the job's line for a missed item (scara_collab.core.job.SortingJob.on_item_event)
MISSED = re.compile(r'item (\d+) missed; last: (.*)$', re.M)


def missed_notes(log_text: str) -> List[str]:
    """Return ``'item N: <the job's last word on it>'`` for each missed item in a job log.

    >>> missed_notes('[WARN] [1.0] [automation_manager]: item 588 missed; last: scara_left '
    ...              'ranked it #3 of 5 at t=1096.40 s')
    ['item 588: scara_left ranked it #3 of 5 at t=1096.40 s']
    """
    return [f'item {m.group(1)}: {m.group(2).strip()}' for m in MISSED.finditer(log_text)]


def rss_kib(pid: int) -> Optional[int]:
    """Return the resident set size of ``pid`` in KiB, or None if it is gone."""
    try:
        with open(f'/proc/{pid}/status', encoding='ascii') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1])
    except (OSError, ValueError):
        return None
    return None


def _sim_time(folder: Path) -> Optional[float]:
    """Return the last sim time written to ``timeseries.csv`` (it is written in batches)."""
    try:
        with open(folder / 'timeseries.csv', 'rb') as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - 4096))
            last = f.read().decode('ascii', 'replace').strip().splitlines()[-1]
        return float(last.split(',')[0])
    except (OSError, ValueError, IndexError):
        return None


def growth(samples: List[Tuple[float, int]], warm: float) -> Dict[str, Optional[float]]:
    """Return RSS after the warm-up, at the end and the growth per sim hour between them.

    :param samples: ``(sim s, KiB)`` in time order.
    :param warm: sim s of warm-up left out (imports, caches, the first items).
    """
    after = [(t, k) for t, k in samples if t >= warm]
    if len(after) < 2 or after[-1][0] - after[0][0] <= 0:
        return {'rss_warm_mib': None, 'rss_end_mib': None, 'growth_per_hour_pct': None}
    (t0, k0), (t1, k1) = after[0], after[-1]
    per_hour = (k1 - k0) / k0 * 3600.0 / (t1 - t0) * 100.0
    return {'rss_warm_mib': k0 / 1024.0, 'rss_end_mib': k1 / 1024.0,
            'growth_per_hour_pct': per_hour}


def soak(out: Path, duration: float = 3600.0, warm: float = 300.0, every: float = 10.0,
         extra: Tuple[str, ...] = (), log: Optional[Log] = None) -> Dict[str, object]:
    """Run the collaborative job ``duration`` sim s through the launcher, sampling RSS.

    :param warm: sim s before the growth is measured from.
    :param every: wall s between samples.
    :return: :func:`scara_collab.bench.protocol.row` of the summary plus ``processes``
        (name -> :func:`growth`), ``lockstep_drops``, ``missed_items`` (the job's last word on
        each, :func:`missed_notes`) and ``samples`` per process.
    """
    out = Path(out)
    cmd = [sys.executable, '-c',
           'import sys; from scara_collab.run.launcher import main; sys.exit(main(sys.argv[1:]))',
           '--mode', 'collaborative', '--duration', f'{duration:g}', '--rtf', '0', '--output',
           str(out), '--quiet', '--no-plots', *extra]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    samples: Dict[str, List[Tuple[float, int]]] = {}
    pids: Dict[str, int] = {}
    next_log = time.monotonic() + 60.0
    try:
        while proc.poll() is None:
            time.sleep(every)
            # read every time: the launcher adds each node as it starts it
            if (out / 'pids.json').is_file():
                try:
                    pids = dict(json.loads((out / 'pids.json').read_text()))
                except ValueError:  # never half-written (os.replace), but be sure
                    pass
                pids['launcher'] = proc.pid
            t = _sim_time(out)
            if t is None:
                continue
            for name, pid in pids.items():
                kib = rss_kib(pid)
                if kib is not None:
                    samples.setdefault(name, []).append((t, kib))
            if log and time.monotonic() >= next_log:
                next_log = time.monotonic() + 60.0
                total = sum(s[-1][1] for s in samples.values() if s) / 1024.0
                log(f'soak: sim t={t:.0f}/{duration:g} s, RSS of {len(samples)} processes '
                    f'{total:.0f} MiB')
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    summary_path = out / 'summary.json'
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    summary['exit_code'] = proc.returncode
    bridge_log = out / 'logs' / 'pybullet_bridge.log'
    drops = bridge_log.read_text(errors='replace').count(DROP_WORDS) \
        if bridge_log.is_file() else None
    job_log = out / 'logs' / 'automation_manager.log'
    missed = missed_notes(job_log.read_text(errors='replace')) if job_log.is_file() else []
    result = row(summary)
    result.update(processes={n: growth(s, warm) for n, s in samples.items()},
                  lockstep_drops=drops, missed_items=missed, samples=samples, warm=warm,
                  duration=duration)
    return result


def render(r: dict, command: str, wall: float) -> str:
    """Return the Markdown table of each process's memory growth, headed by the run."""
    when = time.strftime('%Y-%m-%d %H:%M %Z')
    lines = [f'*Generated by `{command}` on {when} ({wall / 60:.1f} min wall): '
             f'collaborative, default feed, {r["duration"]:g} sim s through the launcher '
             f'(unthrottled, lockstep on); RSS from `/proc/<pid>/status` every 10 wall s; '
             f'growth from sim t={r["warm"]:g} s to the end, per sim hour.*', '',
             '| process | RSS after warm-up | RSS at the end | growth per hour |',
             '|---|---|---|---|']
    for name, g in sorted(r['processes'].items()):
        if g['rss_warm_mib'] is None:
            lines.append(f'| {name} | n/a | n/a | n/a |')
            continue
        lines.append(f'| {name} | {g["rss_warm_mib"]:.1f} MiB | {g["rss_end_mib"]:.1f} MiB | '
                     f'{g["growth_per_hour_pct"]:+.2f} % |')
    sep = r['min_separation_m']
    lines += ['', f'Run: exit {r["exit_code"]} ({r["exit_reason"]}), sim {r["sim_seconds"]} s, '
              f'sorted {r["sorted"]}, missed {r["missed"]}, dropped {r["dropped"]}, wrong bin '
              f'{r["wrong_bin"]}, give-ups {r["give_ups"]}, e-stops {r["emergency_stops"]}, '
              f'min separation {"n/a" if sep is None else f"{sep:.3f} m"}, lockstep drops '
              f'{r["lockstep_drops"]}, real-time factor '
              f'{r["real_time_factor"] or 0:.2f}× (targets: growth < 5 % per hour, 0 missed, '
              '0 lockstep drops).']
    if r.get('missed_items'):
        lines += ['', "Missed, with the job's last word on each: "
                  + '; '.join(r['missed_items']) + '.']
    return '\n'.join(lines)


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the soak; print the table and write it as the ``soak`` block of ``page``.

    ``args.duration``: sim s (default 3600); ``args.warm``: sim s left out (default 300).

    :return: True if the run ended cleanly, missed nothing, had no lockstep drop and every
        process grew < 5 % per sim hour.
    """
    out = Path(tempfile.mkdtemp(prefix='scara_soak_')) / 'soak'
    start = time.monotonic()
    r = soak(out, args.duration or 3600.0, 300.0 if args.warm is None else args.warm, log=log)
    text = render(r, command, time.monotonic() - start)
    print(text)
    (out / 'soak.json').write_text(json.dumps(r, indent=1))
    write_block(page, 'soak', 'Soak: an hour of sim time through the launcher', text)
    log(f'run folder {out}')
    grown = [g['growth_per_hour_pct'] for g in r['processes'].values()
             if g['growth_per_hour_pct'] is not None]
    return bool(r['exit_code'] == 0 and r['missed'] == 0 and r['lockstep_drops'] == 0
                and grown and max(grown) < 5.0)
