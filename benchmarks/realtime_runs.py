"""The cell in real time without lockstep (``--rtf 1 --lockstep off``), beside lockstep."""
import os
from pathlib import Path
import tempfile
from typing import Dict, Optional, Sequence

from benchmarks.launched import launch
from benchmarks.util import Log, table, write_block
from scara_collab import graph

#: 20 +- 10 ms on the joint states and on every status the job's timing hangs on
LATENCY = (['latency:/joint_states:0.02:0.01']
           + [f'latency:/{r}/planner_status:0.02:0.01' for r in graph.ROBOTS]
           + [f'latency:/{r}/execution_status:0.02:0.01' for r in graph.ROBOTS])
#: condition -> (lockstep on?, CPU hogs, faults); ``two_hogs`` loads the machine beyond its
#: cores: any stop must be protective and the job sorts to the end
CONDITIONS = {
    'lockstep': (True, 0, ()),
    'quiet': (False, 0, ()),
    'hog': (False, 1, ()),
    'latency': (False, 0, tuple(LATENCY)),
    'two_hogs': (False, 2, ()),
}
COLUMNS = ('condition', 'seed', 'exit_code', 'sorted', 'missed', 'dropped', 'give_ups',
           'min_separation_m', 'protective', 'emergency', 'own_moves', 'lost_s', 'overspeed',
           'cpu_s')


def run(condition: str, out: Path, duration: float, seed: int, log: Log,
        feed: Optional[float] = None, one_process: bool = False) -> Dict[str, object]:
    """Run the collaborative job in one of :data:`CONDITIONS`; return its row."""
    lockstep, hogs, faults = CONDITIONS[condition]
    flags = ['--lockstep', 'on' if lockstep else 'off'] + ['--one-process'] * one_process
    flags += [a for f in faults for a in ('--fault', f)]
    flags += ['--feed-interval', f'{feed:g}'] if feed is not None else []
    r = launch(f'{condition} seed {seed}', seed * 7 + len(condition), 'collaborative',
               duration, out / f'{condition}_{seed}', log, hogs=hogs, rtf=1.0, seed=seed,
               extra=flags)
    return dict(r, condition=condition, seed=seed)


def capacity(out: Path, seeds: Sequence[int], duration: float, log: Log,
             feed: float = 0.9, one_process: bool = False) -> Dict[str, object]:
    """Items per minute at a saturating feed, lockstep on and off (quiet); and their ratio."""
    rows = {c: [run(c, out / 'capacity', duration, s, log, feed, one_process) for s in seeds]
            for c in ('lockstep', 'quiet')}
    mean = {c: sum(float(r['items_per_minute'] or 0.0) for r in rs) / len(rs)
            for c, rs in rows.items()}
    return {'feed_interval': feed, 'duration': duration, 'seeds': list(seeds),
            'lockstep_items_per_minute': round(mean['lockstep'], 2),
            'realtime_items_per_minute': round(mean['quiet'], 2),
            'ratio': round(mean['quiet'] / mean['lockstep'], 3) if mean['lockstep'] else None,
            'rows': rows}


def markdown(rows: Sequence[Dict[str, object]], cap: Optional[Dict[str, object]],
             command: str, duration: float, one_process: bool = False) -> str:
    """Return the runs and the capacity as a Markdown block."""
    def cell(v):
        return f'{v:.3f}' if isinstance(v, float) else ('' if v is None else str(v))
    layout = 'one process' if one_process else 'one process per node'
    lines = [f'Measured with `{command}`: {layout}, {duration:g} sim s a run, on a machine of '
             f'{os.cpu_count()} cores.', '',
             table([{k: cell(r.get(k)) for k in COLUMNS} for r in rows])]
    causes = [f'- {r["condition"]} seed {r["seed"]}: {r["causes"]}' for r in rows
              if r.get('causes')]
    if causes:
        lines += ['', 'Stop causes:', ''] + causes
    if cap:
        lines += ['', f'Capacity at an item every {cap["feed_interval"]:g} s '
                  f'({cap["duration"]:g} sim s, seeds {cap["seeds"]}): lockstep '
                  f'{cap["lockstep_items_per_minute"]} items/min, real time '
                  f'{cap["realtime_items_per_minute"]} items/min, ratio {cap["ratio"]}.']
    return '\n'.join(lines) + '\n'


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the conditions and the capacity into ``page``; False if a target was missed."""
    duration, seeds, one = args.duration or 600.0, args.seeds or [1, 2, 3], args.one_process
    runs = Path(tempfile.mkdtemp(prefix='scara_realtime_'))
    log(f'run folders in {runs}')
    rows = [run(c, runs, duration, s, log, one_process=one) for s in seeds
            for c in args.conditions or list(CONDITIONS)]
    cap_s = 240.0 if args.capacity_duration is None else args.capacity_duration
    cap = capacity(runs, seeds, cap_s, log, one_process=one) if cap_s > 0 else None
    text = markdown(rows, cap, command, duration, one)
    print(text)
    write_block(page, f'realtime:{"one_process" if one else "processes"}',
                f'One process{"" if one else " per node"}, at 1×', text,
                title='# Real time, without lockstep')
    bad = [f'{r["condition"]} seed {r["seed"]}' for r in rows
           if r.get('min_separation_m') is None or r['min_separation_m'] < 0.10
           or (bool(r.get('emergency')) if r['condition'] == 'two_hogs' else
               bool(r.get('missed') or r.get('dropped') or r.get('own_moves')))]
    if cap and cap['ratio'] is not None and cap['ratio'] < 0.95:
        bad.append(f'capacity ratio {cap["ratio"]} < 0.95')
    log(f'written {page}' + (f'; not met: {", ".join(bad)}' if bad else '; all met'))
    return not bad
