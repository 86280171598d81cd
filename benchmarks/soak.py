"""The soak: a long launcher run, every process's resident memory sampled against sim time."""
import json
import os
from pathlib import Path
import re
import tempfile
import time
from typing import Dict, List, Optional, Tuple

from benchmarks.launched import Launch, publish, row, stamp
from benchmarks.util import Log, table

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
            return next(int(ln.split()[1]) for ln in f if ln.startswith('VmRSS:'))
    except (OSError, StopIteration):
        return None


def last_sim_time(folder: Path) -> Optional[float]:
    """Return the last sim time written to ``timeseries.csv`` (it is written in batches)."""
    try:
        with open(folder / 'timeseries.csv', 'rb') as f:
            f.seek(max(0, f.seek(0, os.SEEK_END) - 4096))
            return float(f.read().decode('ascii', 'replace').split()[-1].split(',')[0])
    except (OSError, ValueError, IndexError):
        return None


def growth(samples: List[Tuple[float, int]], warm: float) -> Dict[str, Optional[float]]:
    """Return RSS after the ``warm`` sim s and at the end (MiB), its growth per sim hour (%)."""
    after = [(t, k) for t, k in samples if t >= warm]
    if len(after) < 2 or after[-1][0] <= after[0][0]:
        return {'rss_warm_mib': None, 'rss_end_mib': None, 'growth_per_hour_pct': None}
    (t0, k0), (t1, k1) = after[0], after[-1]
    return {'rss_warm_mib': k0 / 1024.0, 'rss_end_mib': k1 / 1024.0,
            'growth_per_hour_pct': (k1 - k0) / k0 * 3600.0 / (t1 - t0) * 100.0}


def soak(out: Path, duration: float, warm: float, log: Log, every: float = 10.0) -> dict:
    """Run the job ``duration`` sim s, sampling RSS every ``every`` wall s; return its row."""
    run = Launch('collaborative', duration, out)
    samples: Dict[str, List[Tuple[float, int]]] = {}
    next_log = time.monotonic() + 60.0
    try:
        while run.proc.poll() is None:
            time.sleep(every)
            t = last_sim_time(out)
            if t is None or not (out / 'pids.json').is_file():
                continue
            # read every time: the launcher adds each node as it starts it (os.replace)
            pids = dict(json.loads((out / 'pids.json').read_text()), launcher=run.proc.pid)
            for name, pid in pids.items():
                kib = rss_kib(pid)
                if kib is not None:
                    samples.setdefault(name, []).append((t, kib))
            if time.monotonic() >= next_log:
                next_log = time.monotonic() + 60.0
                total = sum(s[-1][1] for s in samples.values()) / 1024.0
                log(f'soak: sim t={t:.0f}/{duration:g} s, RSS of {len(samples)} processes '
                    f'{total:.0f} MiB')
    finally:
        if run.proc.poll() is None:  # this loop failed: the run goes with it
            run.proc.kill()
    return dict(row(run.finish(60.0)), processes={n: growth(s, warm) for n, s in samples.items()},
                lockstep_drops=run.log('pybullet_bridge').count(DROP_WORDS),
                missed_items=missed_notes(run.log('automation_manager')), samples=samples)


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the soak into the ``soak`` block of ``page``; True if it met its targets."""
    out = Path(tempfile.mkdtemp(prefix='scara_soak_')) / 'soak'
    duration, warm = args.duration or 3600.0, 300.0 if args.warm is None else args.warm
    start = time.monotonic()
    r = soak(out, duration, warm, log)
    rows = [{'process': name, 'RSS after warm-up (MiB)': f'{g["rss_warm_mib"]:.1f}',
             'RSS at the end (MiB)': f'{g["rss_end_mib"]:.1f}',
             'growth per hour': f'{g["growth_per_hour_pct"]:+.2f} %'}
            if g['rss_warm_mib'] is not None else {'process': name, 'growth per hour': 'n/a'}
            for name, g in sorted(r['processes'].items())]
    sep = r['min_separation_m']
    text = '\n\n'.join(
        [stamp(command, start, f'{duration:g} sim s; growth from sim t={warm:g} s to the end.'),
         table(rows),
         f'Run: exit {r["exit_code"]} ({r["exit_reason"]}), sim {r["sim_seconds"]} s, sorted '
         f'{r["sorted"]}, missed {r["missed"]}, dropped {r["dropped"]}, wrong bin '
         f'{r["wrong_bin"]}, give-ups {r["give_ups"]}, e-stops {r["emergency"]}, min '
         f'separation {"n/a" if sep is None else f"{sep:.3f} m"}, lockstep drops '
         f'{r["lockstep_drops"]}, real-time factor {r["real_time_factor"] or 0:.2f}×.']
        + (["Missed, with the job's last word on each: " + '; '.join(r['missed_items']) + '.']
           if r['missed_items'] else []))
    (out / 'soak.json').write_text(json.dumps(r, indent=1))
    publish(text, page, 'soak', 'Soak: an hour of sim time through the launcher', log, out)
    grown = [g['growth_per_hour_pct'] for g in r['processes'].values()
             if g['growth_per_hour_pct'] is not None]
    return bool(r['exit_code'] == 0 and r['missed'] == 0 and r['lockstep_drops'] == 0
                and grown and max(grown) < 5.0)
