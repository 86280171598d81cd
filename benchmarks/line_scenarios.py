"""A line of cells through the launcher (``--only line``): a block of the line page a scenario."""
import os
from pathlib import Path
import re
import shutil
import tempfile
from typing import Dict, List, Sequence

import yaml

from benchmarks.job_in_process import default_feed
from benchmarks.launched import Launch
from benchmarks.util import LINE_PAGE, Log, table, write_block
from scara_collab.core.line import Section
from scara_collab.core.model import load_cell
from scara_collab.core.paths import share_dir
from scara_collab.records.line_report import read_events

SATURATING = 0.9  # s per item: one cell's saturating feed at 0.2 m/s
WARM = 40.0  # sim s left out of the rates: three sections at 0.6 m/s, and the job's start
LOSSY = ('loss:/cell_{k}/line/handoff:0.3', 'repeat:/cell_{k}/line/handoff:0.3')
PACED = 0.97  # real-time factor a cell paced at 1x must keep (the start's catch-up aside)
STAMP = re.compile(r'\[(\d+\.\d+)\]')  # a ROS log line's wall stamp


def belt_share(speed: float, into: Path) -> Path:
    """Return a share folder (``urdf/``, ``config/``) whose belt runs at ``speed`` m/s."""
    src = share_dir()
    shutil.copytree(src / 'urdf', into / 'urdf', dirs_exist_ok=True)
    shutil.copytree(src / 'config', into / 'config', dirs_exist_ok=True)
    path = into / 'config' / 'cell.yaml'
    text = path.read_text(encoding='utf-8')
    old = yaml.safe_load(text)['/**']['ros__parameters']['belt']['speed']
    path.write_text(text.replace(f'speed: {old}', f'speed: {speed:g}', 1), encoding='utf-8')
    return into


def run(cells: int, speed: float, feed: float, duration: float, out: Path, log: Log,
        seed: int = 1, flags: Sequence[str] = (), rtf: float = 0.0,
        copies: int = 1) -> Dict[str, object]:
    """Run a line of ``cells`` (1: a lone cell) at ``speed`` and ``feed``; return its row.

    ``copies`` > 1: that many runs side by side (own ROS domains), so a lone cell's CPU is
    measured on a machine as busy as a line keeps it; the first run's row, the median CPU.
    """
    env = dict(os.environ)
    if speed != load_cell().belt.speed:
        env['SCARA_COLLAB_SHARE'] = str(belt_share(speed, out.parent / f'share_{speed:g}'))
    domain = int(env.get('ROS_DOMAIN_ID', '0'))
    runs = [Launch('collaborative', duration, out / f'copy_{i}' if i else out, rtf,
                   env=dict(env, ROS_DOMAIN_ID=str((domain + i) % 230)), flags=[
                       '--cells', str(cells), '--one-process', '--feed-interval', f'{feed:g}',
                       '--seed', str(seed), *flags]) for i in range(copies)]
    s, *others = [r.finish(None) for r in runs]
    rows = s.get('cells') or [dict(s, cell=0)]
    if others:
        costs = [(r.get('cpu_per_sim_s') or {}).get('total') for r in (s, *others)]
        costs = sorted(c for c in costs if c is not None)
        rows = [dict(rows[0], cpu_s_per_sim_s=costs[len(costs) // 2] if costs else None)]
    folders = [out / f'cell_{k}' for k in range(cells)] if cells > 1 else [out]
    per = [sum(1 for t, kind, _, _ in read_events(f) if kind == 'sorted' and float(t) >= WARM)
           * 60.0 / (duration - WARM) for f in folders]
    row = {'cells': cells, 'belt_speed': speed, 'feed_interval': feed, 'duration': duration,
           'rtf': rtf, 'real_time_factor': [r.get('real_time_factor') for r in rows],
           'sorted': s.get('sorted'),
           'exit_code': s['exit_code'], 'items_per_minute': round(sum(per), 2),
           'per_cell': per, 'min_separation_m': [r.get('min_separation_m') for r in rows],
           'cpu_per_cell': [r.get('cpu_s_per_sim_s')
                            or (r.get('cpu_per_sim_s') or {}).get('total') for r in rows],
           'missed': s.get('missed'), 'dropped': s.get('dropped'),
           'handoffs': s.get('handoffs', 0), 'balanced': s.get('balanced'),
           'handoff_problems': len(s.get('handoff_problems') or []), 'died': s.get('died')}
    log(f'{cells} cell(s) at {speed:g} m/s, an item every {feed:g} s: exit '
        f'{row["exit_code"]}, {row["items_per_minute"]:.1f} items/min '
        f'({", ".join(f"{p:.1f}" for p in per)}), {row["handoffs"]} handoffs')
    return row


def capacity(lines: List[int], duration: float, folder: Path,
             log: Log) -> List[Dict[str, object]]:
    """Each line length beside N lone cells at its belt speed and feed, side by side; ratios."""
    out = []
    for n in lines:
        speed, feed = 0.2 * n, SATURATING / n
        one = run(1, speed, feed, duration, folder / f'one_{n}', log, copies=n)
        line = run(n, speed, feed, duration, folder / f'line_{n}', log)
        line['one_cell'] = base = one['items_per_minute'] or float('nan')
        line['ratio'] = round(line['items_per_minute'] / (n * base), 3)
        line['worst_cell_ratio'] = round(min(line['per_cell']) / base, 3)
        line['one_cell_cpu'] = cpu = one['cpu_per_cell'][0]
        costs = [c for c in line['cpu_per_cell'] if c is not None]
        line['cpu_ratio'] = round(max(costs) / cpu, 3) if cpu and costs else None
        out.append(line)
    return out


def at_rated(n: int, duration: float, out: Path, log: Log, **kw) -> Dict[str, object]:
    """Run ``n`` cells at the rated belt speed and ``n`` times the rated feed."""
    return run(n, load_cell().belt.speed, default_feed() / n, duration, out, log, **kw)


def rated(n: int, duration: float, folder: Path, log: Log) -> Dict[str, object]:
    """N cells at N times the rated feed, handoff messages lost and repeated."""
    flags = [a for k in range(n - 1) for f in LOSSY for a in ('--fault', f.format(k=k))]
    return at_rated(n, duration, folder / f'rated_{n}', log, flags=flags)


def realtime(n: int, duration: float, folder: Path, log: Log) -> List[Dict[str, object]]:
    """N cells at N times the rated feed, unthrottled and paced at 1x: the pace each keeps."""
    return [at_rated(n, duration, folder / f'pace_{n}_{rtf:g}', log, rtf=rtf)
            for rtf in (0.0, 1.0)]


def wall_of(path: Path, text: str) -> float:
    """Return the wall stamp (s) of the first line of the log ``path`` containing ``text``."""
    line = next(ln for ln in path.read_text(errors='replace').splitlines() if text in ln)
    return float(STAMP.search(line).group(1))


def kill(duration: float, at: float, folder: Path, log: Log) -> Dict[str, object]:
    """Three cells, undisturbed and with cell 1 killed at ``at``: what the others did."""
    calm = at_rated(3, duration, folder / 'calm_3', log)
    hit = at_rated(3, duration, folder / 'kill_3', log,
                   flags=['--fault', f'crash:/cell_1/pybullet_bridge:{at:g}'])
    logs = folder / 'kill_3'
    try:
        same = [(folder / r / 'cell_0' / 'events.csv').read_bytes() for r in ('calm_3', 'kill_3')]
        again = (wall_of(logs / 'cell_2' / 'logs' / 'cell.log', 'line: sorting again')
                 - wall_of(logs / 'cell_1' / 'logs' / 'cell.log', 'fault injection: crash'))
    except (OSError, StopIteration, AttributeError):
        same, again = [b'', b'-'], None
    report = logs / 'line_report.txt'
    named = report.is_file() and 'cell 1 DIED' in report.read_text(errors='replace')
    return dict(hit, at=at, cell0_identical=same[0] == same[1], sorting_again_wall_s=again,
                lookahead_s=Section(load_cell()).transit, named=named,
                calm_exit=calm['exit_code'])


def _f(v, d=2) -> str:
    """Format a number with ``d`` decimals ('-' for none)."""
    return '-' if v is None else f'{v:.{d}f}'


def _measured(command: str, rows: List[Dict[str, object]], how: str = '') -> str:
    """Return a scenario's block: the command (and ``how`` it ran), its rows as a table."""
    return f'Measured with `{command}`{how}.\n\n{table(rows)}\n'


def capacity_text(rows: List[Dict[str, object]], command: str) -> str:
    """Return the capacity runs as a Markdown block."""
    return _measured(command, [{
        'cells': r['cells'], 'belt m/s': f'{r["belt_speed"]:g}',
        'item every s': f'{r["feed_interval"]:.3g}', 'one cell items/min': _f(r['one_cell'], 1),
        'line items/min': _f(r['items_per_minute'], 1), 'ratio (>= 0.9)': _f(r['ratio'], 3),
        'worst cell / one (>= 0.85)': _f(r['worst_cell_ratio'], 3),
        'per cell': ', '.join(_f(p, 1) for p in r['per_cell']),
        'min separation m': ', '.join(_f(s, 3) for s in r['min_separation_m']),
        'CPU s per sim s per cell (one cell)': ', '.join(_f(c) for c in r['cpu_per_cell'])
        + f' ({_f(r["one_cell_cpu"])})', 'worst CPU / one (<= 1.1)': _f(r['cpu_ratio'], 3),
        'handoffs (problems)': f'{r["handoffs"]} ({r["handoff_problems"]})',
        'exit': r['exit_code']} for r in rows], ' (`benchmarks/line_scenarios.py`)')


def rated_text(rows: List[Dict[str, object]], command: str) -> str:
    """Return the rated-feed runs as a Markdown block."""
    head = ('cells', 'duration', 'feed_interval', 'missed', 'dropped', 'handoffs',
            'handoff_problems', 'balanced', 'min_separation_m', 'exit_code')
    return _measured(command, [
        {k: ', '.join(_f(x, 3) for x in r[k]) if isinstance(r[k], list) else r[k] for k in head}
        for r in rows])


def realtime_text(rows: List[Dict[str, object]], command: str) -> str:
    """Return the paced runs as a Markdown block."""
    return _measured(command, [{
        'cells': r['cells'], 'paced': f'{r["rtf"]:g}x' if r['rtf'] else 'unthrottled',
        'sim s': f'{r["duration"]:g}',
        'real-time factor per cell': ', '.join(_f(x) for x in r['real_time_factor']),
        'line (its slowest cell)': _f(_slowest(r)),
        'CPU s per sim s per cell': ', '.join(_f(c) for c in r['cpu_per_cell']),
        'sorted': r['sorted'], 'missed': r['missed'], 'exit': r['exit_code']} for r in rows])


def _slowest(row: Dict[str, object]):
    """Return the line's real-time factor: its slowest cell's (None if one is missing)."""
    paces = row['real_time_factor']
    return None if not paces or None in paces else min(paces)


def kill_text(r: Dict[str, object], command: str) -> str:
    """Return the killed-cell run as a Markdown block."""
    return _measured(command, [{
        "cell 0's events identical": r['cell0_identical'],
        'cell 2 sorting again after the kill (wall s)': _f(r['sorting_again_wall_s'], 1),
        'target (lookahead + 10 s)': f'{r["lookahead_s"] + 10.0:.1f}',
        'report names cell 1': r['named'], 'died': r['died'],
        'exit (undisturbed, killed)': f'{r["calm_exit"]}, {r["exit_code"]}'}],
        f': three cells at three times the rated feed, {r["duration"]:g} sim s, undisturbed '
        f'and with cell 1 killed at {r["at"]:g} sim s')


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the ``--scenarios`` (capacity) into blocks of the line page; False if one missed."""
    target = page.parent / LINE_PAGE
    folder = Path(tempfile.mkdtemp(prefix='scara_line_'))
    log(f'run folders in {folder}')
    lines, bad = args.cells or [2, 3], []
    for name in args.scenarios or ['capacity']:
        if name == 'capacity':
            rows = capacity(lines, args.duration or 240.0, folder, log)
            text, heading = capacity_text(rows, command), 'Capacity'
            bad += [f'capacity {r["cells"]}' for r in rows if r['exit_code']
                    or r['handoff_problems'] or r['ratio'] < 0.9 or r['worst_cell_ratio'] < 0.85
                    or any(s is None or s < 0.10 for s in r['min_separation_m'])
                    or r['cpu_ratio'] is None or r['cpu_ratio'] > 1.1
                    or max(c or 0.0 for c in r['cpu_per_cell']) > 0.15]
        elif name == 'rated':
            rows = [rated(n, args.duration or 600.0, folder, log) for n in lines]
            text, heading = rated_text(rows, command), 'At N times the rated feed'
            bad += [f'rated {r["cells"]}' for r in rows if r['exit_code'] or r['missed']
                    or r['handoff_problems'] or not r['balanced']]
        elif name == 'realtime':
            rows = [r for n in lines for r in realtime(n, args.duration or 120.0, folder, log)]
            text, heading = realtime_text(rows, command), 'Real time'
            bad += [f'realtime {r["cells"]} at {r["rtf"]:g}x' for r in rows if r['exit_code']
                    or (_slowest(r) or 0.0) < (PACED if r['rtf'] else 1.0)]
        else:
            duration = args.duration or 330.0
            r = kill(duration, min(300.0, duration - 30.0), folder, log)
            text, heading = kill_text(r, command), 'A killed cell'
            again = r['sorting_again_wall_s']
            if not (r['cell0_identical'] and r['named'] and r['exit_code'] and again is not None
                    and again <= r['lookahead_s'] + 10.0):
                bad.append('kill')
        print(text)
        write_block(target, f'line:{name}', heading, text, title='# A line of cells')
    log(f'written {target}' + (f'; not met: {", ".join(bad)}' if bad else '; all met'))
    return not bad
