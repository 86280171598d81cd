"""A line of cells: capacity against one cell's, handoffs, CPU per cell (``--only line``).

For each line length N (``--cells``, default 2 and 3) the feed is N times one cell's saturating
feed, an item every 0.9 / N s. At 0.2 m/s that is denser than the belt can carry (items are
0.1 m), so the line runs at N times the belt speed, and one cell's capacity is measured at that
speed and feed too (a share folder of its own with the faster belt: ``SCARA_COLLAB_SHARE``).
Every run goes through the launcher, each cell in one process (``--one-process``), unthrottled
in lockstep, so the figures do not depend on how busy the machine is. Items per minute are
counted at steady state, after the first :data:`WARM` sim seconds (the last cell of a line gets
its first item only after the belt has carried it through the ones before). A run's row: items
sorted per minute (line and per cell), handoffs checked, the minimum separation per cell, CPU
s per sim s per cell, the exit code. Targets (SPEC section 5, "a line of cells"): line
capacity >= 0.9 x N x one cell's, no cell below 0.85 x one cell's, the margin kept in every
cell, every handoff received once.
"""
import json
import os
from pathlib import Path
import shutil
import subprocess
import sys
import tempfile
from typing import Dict, List

import yaml

from scara_collab.bench.util import Log
from scara_collab.core.paths import share_dir
from scara_collab.records.line_report import read_events

SATURATING = 0.9  # s per item: one cell's saturating feed at 0.2 m/s
WARM = 40.0  # sim s left out of the rates: three sections at 0.6 m/s, and the job's start


def belt_share(speed: float, into: Path) -> Path:
    """Return a share folder (``urdf/``, ``config/``) whose belt runs at ``speed`` m/s."""
    src = share_dir()
    shutil.copytree(src / 'urdf', into / 'urdf', dirs_exist_ok=True)
    shutil.copytree(src / 'config', into / 'config', dirs_exist_ok=True)
    path = into / 'config' / 'cell.yaml'
    text = path.read_text(encoding='utf-8')
    tree = yaml.safe_load(text)
    old = tree['/**']['ros__parameters']['belt']['speed']
    path.write_text(text.replace(f'speed: {old}', f'speed: {speed:g}', 1), encoding='utf-8')
    return into


def run(cells: int, speed: float, feed: float, duration: float, out: Path, log: Log,
        seed: int = 1) -> Dict[str, object]:
    """Run a line of ``cells`` (1: a lone cell) at ``speed`` and ``feed``; return its row."""
    share = belt_share(speed, out.parent / f'share_{speed:g}')
    cmd = [sys.executable, '-m', 'scara_collab.run.launcher', '--cells', str(cells),
           '--one-process', '--rtf', '0', '--duration', f'{duration:g}', '--feed-interval',
           f'{feed:g}', '--seed', str(seed), '--output', str(out), '--no-plots', '--quiet']
    proc = subprocess.run(cmd, env=dict(os.environ, SCARA_COLLAB_SHARE=str(share)),
                          capture_output=True, text=True)
    row = row_of(out, cells, speed, feed, duration, proc.returncode)
    log(f'{cells} cell(s) at {speed:g} m/s, an item every {feed:g} s: exit '
        f'{proc.returncode}, {row["items_per_minute"]:.1f} items/min '
        f'({", ".join(f"{p:.1f}" for p in row["per_cell"])}), {row["handoffs"]} handoffs')
    return row


def row_of(out: Path, cells: int, speed: float, feed: float, duration: float,
           code: int) -> Dict[str, object]:
    """Return a run's row from its folder (items/min at steady state, after :data:`WARM`)."""
    s = json.loads((out / 'summary.json').read_text(encoding='utf-8'))
    rows = s.get('cells') or [dict(s, cell=0)]
    folders = [out / f'cell_{k}' for k in range(cells)] if cells > 1 else [out]
    per = [sum(1 for t, kind, _, _ in read_events(f) if kind == 'sorted' and float(t) >= WARM)
           * 60.0 / (duration - WARM) for f in folders]
    cpu = [r.get('cpu_s_per_sim_s') or (r.get('cpu_per_sim_s') or {}).get('total')
           for r in rows]
    seps = [r.get('min_separation_m') for r in rows]
    return {'cells': cells, 'belt_speed': speed, 'feed_interval': feed, 'duration': duration,
            'exit_code': code, 'items_per_minute': round(sum(per), 2),
            'per_cell': per, 'cpu_per_cell': cpu, 'min_separation_m': seps,
            'missed': s.get('missed'), 'handoffs': s.get('handoffs', 0),
            'handoff_problems': len(s.get('handoff_problems') or [])}


def measure(lines: List[int], duration: float, log: Log) -> List[Dict[str, object]]:
    """Each line length beside one cell at the same belt speed and feed; the ratios."""
    folder = Path(tempfile.mkdtemp(prefix='scara_line_'))
    log(f'run folders in {folder}')
    out = []
    for n in lines:
        speed, feed = 0.2 * n, SATURATING / n
        one = run(1, speed, feed, duration, folder / f'one_{n}', log)
        line = run(n, speed, feed, duration, folder / f'line_{n}', log)
        base = one['items_per_minute'] or float('nan')
        line['one_cell'] = base
        line['ratio'] = round(line['items_per_minute'] / (n * base), 3)
        line['worst_cell_ratio'] = round(min(line['per_cell']) / base, 3)
        out.append(line)
    return out


def markdown(rows: List[Dict[str, object]], command: str) -> str:
    """Return the runs as a Markdown page."""
    def f(v, d=2):
        return '-' if v is None else f'{v:.{d}f}'
    lines = ['# A line of cells', '', f'Measured with `{command}` (`scara_collab/bench/line.py`): '
             "each line fed N times one cell's saturating feed, at N times the belt speed, "
             'beside one cell at the same speed and feed; each cell in one process, '
             f'unthrottled, in lockstep; items per minute counted after the first {WARM:g} '
             'sim s.', '',
             '| cells | belt m/s | item every s | one cell items/min | line items/min | '
             'ratio (>= 0.9) | worst cell / one (>= 0.85) | per cell | min separation m | '
             'CPU s per sim s per cell | handoffs (problems) | exit |',
             '|' + '---|' * 12]
    for r in rows:
        lines.append(
            f'| {r["cells"]} | {r["belt_speed"]:g} | {r["feed_interval"]:.3g} | '
            f'{f(r["one_cell"], 1)} | {f(r["items_per_minute"], 1)} | {f(r["ratio"], 3)} | '
            f'{f(r["worst_cell_ratio"], 3)} | {", ".join(f(p, 1) for p in r["per_cell"])} | '
            f'{", ".join(f(s, 3) for s in r["min_separation_m"])} | '
            f'{", ".join(f(c) for c in r["cpu_per_cell"])} | {r["handoffs"]} '
            f'({r["handoff_problems"]}) | {r["exit_code"]} |')
    return '\n'.join(lines) + '\n'


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the line lengths (``--cells``, default 2 3; ``--duration``, default 240 sim s).

    Writes ``LINE.md`` beside ``page``. :return: False if a target is missed.
    """
    rows = measure(args.cells or [2, 3], args.duration or 240.0, log)
    text = markdown(rows, command)
    print(text)
    target = page.parent / 'LINE.md'
    target.write_text(text, encoding='utf-8')
    bad = [r for r in rows if r['exit_code'] or r['handoff_problems'] or r['ratio'] < 0.9
           or r['worst_cell_ratio'] < 0.85
           or any(s is None or s < 0.10 for s in r['min_separation_m'])]
    log(f'written {target}' + (f'; not met: {[r["cells"] for r in bad]}' if bad else
                               '; all met'))
    return not bad
