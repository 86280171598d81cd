"""A line of cells' summary, report and plot, from its cells' run folders (no rclpy).

Each cell of a line writes its own run folder (``cell_k/``: ``summary.json``, ``events.csv``,
its plots and logs, :mod:`scara_collab.records.record`). :func:`line_summary` reads them
together:

- per cell: sorted, missed, handed on, received, dropped, wrong bin, still in the cell, stops,
  the minimum separation, CPU s per sim s and its exit;
- the line: ``spawned`` (cell 0's feed), ``sorted``, ``missed`` (at the end of the last cell,
  or knocked off a belt), ``items_per_minute``, and the **handoff check**: every item cell
  ``k`` handed on was received by cell ``k + 1`` exactly once, with the same class, except
  those still between the two sections when the run ended (crossed less than a transit
  before the end), and no cell received an item nobody handed on. Then the items balance:
  ``spawned = sorted + wrong_bin + missed + dropped + in the cells + between cells``.

The line's exit code is the first non-zero code of its cells (cell order), else
:data:`EXIT_HANDOFF` if the handoff check fails, else 0; ``exit_reason`` says which cell or
what. :func:`format_line_report` prints it, :func:`plot_sorted` draws items sorted per cell
over time.

>>> ev = {0: [('1.0', 'spawned', '1', 'red'), ('6.0', 'handed_on', '1', 'red')],
...       1: [('7.0', 'received', '1', 'red'), ('12.0', 'sorted', '1', 'red')]}
>>> check_handoffs(ev, transit=1.0, end=20.0)['ok']
True
>>> ev[1].append(('7.5', 'received', '1', 'red'))  # the same item twice
>>> check_handoffs(ev, transit=1.0, end=20.0)['problems']
['cell 1 received item 1 twice']
"""
import json
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple, Union

from scara_collab.records.report import load_events
from scara_collab.records.telemetry import EVENTS

EXIT_HANDOFF = 7
#: what the line's summary keeps of each cell's summary
CELL_KEYS = ('spawned', 'received', 'sorted', 'missed', 'handed_on', 'wrong_bin', 'dropped',
             'in_progress', 'items_per_minute', 'min_separation_m', 'sim_seconds',
             'real_time_factor', 'exit_code', 'exit_reason')
LINE_REPORT = 'line_report.txt'
LINE_PLOT = 'line_sorted.png'

Event = Tuple[str, str, str, str]  # time, kind, item, class (as events.csv has them)


def cell_folder(output: Union[str, Path], k: int) -> Path:
    """Return the run folder of cell ``k`` of a line whose folder is ``output``."""
    return Path(output) / f'cell_{k}'


def read_events(folder: Union[str, Path]) -> List[Event]:
    """Return a cell's item events (``events.csv``, :func:`report.load_events`), or []."""
    if not (Path(folder) / EVENTS).exists():
        return []
    return [(r['time'], r['kind'], r['item'], r['class']) for r in load_events(folder)]


def check_handoffs(events: Mapping[int, Sequence[Event]], transit: float, end: float,
                   died: Optional[Mapping[int, float]] = None) -> Dict[str, object]:
    """Check that every handoff between neighbours arrived once, and only those.

    :param events: per cell index, its item events.
    :param transit: s an item rides between two sections.
    :param end: the run's end, sim s (items that crossed after ``end - transit`` may still be
        between the sections).
    :param died: the cells that died, with the sim time they reached. Past a dead cell the
        next one also takes what the dead section carried: the items the dead cell had
        received and the ones handed to it (``through``); what was handed to it after it died
        is not expected in it.
    :return: ``ok``, ``handoffs`` (checked), ``in_transit``, ``through`` and ``problems``
        (in words).
    """
    died = dict(died or {})
    problems: List[str] = []
    handoffs = in_transit = through = into_dead = 0
    kinds: Dict[int, Dict[str, Dict[str, Tuple[float, str]]]] = {}
    for k, evs in events.items():
        kinds[k] = {'handed_on': {}, 'received': {}, 'spawned': {}}
        for t, kind, item, cls in evs:
            if kind in kinds[k]:
                kinds[k][kind].setdefault(item, (float(t), cls))
    for k in sorted(events):
        if k + 1 not in events:
            continue
        handed = kinds[k]['handed_on']
        if k in died:  # the dead section carried on what it had and what came to it
            dead_sources = {**kinds[k]['received'], **kinds[k]['spawned'],
                            **kinds.get(k - 1, {}).get('handed_on', {})}
        got: Dict[str, int] = {}
        for t, kind, item, cls in events[k + 1]:
            if kind != 'received':
                continue
            got[item] = got.get(item, 0) + 1
            if got[item] == 2:
                problems.append(f'cell {k + 1} received item {item} twice')
            source = handed.get(item)
            if source is None and k in died and item in dead_sources:
                through += got[item] == 1
                source = dead_sources[item]
            if source is None:
                problems.append(f'cell {k + 1} received item {item}, which cell {k} never '
                                'handed on')
            elif source[1] != cls:
                problems.append(f'item {item} left cell {k} as {source[1]} and came '
                                f'into cell {k + 1} as {cls}')
        stop = min(end, died.get(k + 1, end))
        for item, (t, _) in handed.items():
            handoffs += 1
            if item in got:
                continue
            if k + 1 in died and t + transit > stop - 1e-6:
                into_dead += 1  # handed to a dead cell: its section carried it on
            elif t + transit > stop - 1e-6:
                in_transit += 1
            else:
                problems.append(f'item {item}, handed on by cell {k} at t={t:.2f} s, never '
                                f'came into cell {k + 1}')
    return {'ok': not problems, 'handoffs': handoffs, 'in_transit': in_transit,
            'through': through, 'into_dead': into_dead, 'problems': problems}


def line_summary(output: Union[str, Path], cells: int, transit: float, duration: float,
                 pitch: float, cpu: Optional[Mapping[int, float]] = None,
                 ended: Optional[Mapping[int, str]] = None) -> Dict[str, object]:
    """Read the cells' run folders under ``output``; return the line's summary.

    :param cells: how many cells the line has.
    :param transit: s between sections; :param duration: the job's sim s; :param pitch: m.
    :param cpu: CPU s per sim s per cell where measured by the caller (else the cell's own).
    :param ended: per cell, how its launcher ended, where it did not write a summary.
    """
    rows, events = [], {}
    for k in range(cells):
        folder = cell_folder(output, k)
        try:
            s = json.loads((folder / 'summary.json').read_text(encoding='utf-8'))
        except (OSError, ValueError):
            s = {'exit_code': 1, 'exit_reason': (ended or {}).get(k, 'no summary written')}
        row = {'cell': k, 'namespace': f'/cell_{k}', 'folder': str(folder)}
        row.update({key: s.get(key) for key in CELL_KEYS})
        sim = s.get('sim_seconds')
        reached = sim is not None and sim >= duration - 1e-3
        row['died_at'] = None if not s.get('exit_code') or reached else sim
        row['stops'] = len(s.get('protective_stops') or []) + len(s.get('emergency_stops') or [])
        own_cpu = s.get('cpu_per_sim_s') or {}
        row['cpu_s_per_sim_s'] = (cpu or {}).get(k, own_cpu.get('total')
                                                 if isinstance(own_cpu, dict) else None)
        rows.append(row)
        events[k] = read_events(folder)
    died = {r['cell']: float(r['died_at'] or 0.0) for r in rows
            if r['died_at'] is not None or r.get('sim_seconds') is None}
    check = check_handoffs(events, transit, duration, died)

    def total(key):
        return sum(int(r.get(key) or 0) for r in rows)
    summary: Dict[str, object] = {
        'cells': rows, 'line_cells': cells, 'pitch_m': pitch, 'transit_s': transit,
        'sim_seconds': duration,
        'spawned': int(rows[0].get('spawned') or 0), 'sorted': total('sorted'),
        'missed': total('missed'), 'wrong_bin': total('wrong_bin'), 'dropped': total('dropped'),
        'in_cells': total('in_progress'), 'between_cells': check['in_transit'],
        'handoffs': check['handoffs'], 'handoff_problems': check['problems'],
        'died': sorted(died), 'through_dead': check['through'],
    }
    summary['items_per_minute'] = round(summary['sorted'] * 60.0 / duration, 2)
    paces = [r.get('real_time_factor') for r in rows]  # a line goes at its slowest cell's pace
    summary['real_time_factor'] = None if None in paces or not paces else min(paces)
    gone = sum(summary[k] for k in ('sorted', 'wrong_bin', 'missed', 'dropped', 'in_cells',
                                    'between_cells'))
    # items held in a dead cell, or on their way through it at the end, are not counted
    summary['balanced'] = None if died else gone == summary['spawned']
    bad = next((r for r in rows if r.get('exit_code')), None)
    if bad is not None:
        summary['exit_code'] = int(bad['exit_code'])
        summary['exit_reason'] = f'cell {bad["cell"]}: {bad.get("exit_reason")}'
    elif not check['ok'] or summary['balanced'] is False:
        summary['exit_code'] = EXIT_HANDOFF
        summary['exit_reason'] = ('handoffs: ' + '; '.join(check['problems'][:3])
                                  if check['problems'] else
                                  f'items do not balance: {summary["spawned"]} spawned, '
                                  f'{gone} accounted for')
    else:
        summary['exit_code'], summary['exit_reason'] = 0, 'duration reached'
    return summary


def format_line_report(s: Mapping[str, object]) -> str:
    """Return the line's report: its outcome first, a row per cell, the totals."""
    code = s['exit_code']
    head = (f'line of {s["line_cells"]} cells finished ({s["exit_reason"]})' if code == 0 else
            f'line of {s["line_cells"]} cells FAILED, exit {code}: {s["exit_reason"]}')
    lines = [head, f'  {"cell":<6} {"sorted":>6} {"missed":>6} {"handed":>6} {"recvd":>6} '
             f'{"drop":>5} {"stops":>5} {"min sep m":>9} {"CPU s/sim s":>11} {"RTF":>6}  exit']
    for r in s['cells']:
        sep = r.get('min_separation_m')
        cpu, rtf = r.get('cpu_s_per_sim_s'), r.get('real_time_factor')
        lines.append(f'  {r["cell"]:<6} {r.get("sorted") or 0:>6} {r.get("missed") or 0:>6} '
                     f'{r.get("handed_on") or 0:>6} {r.get("received") or 0:>6} '
                     f'{r.get("dropped") or 0:>5} {r.get("stops") or 0:>5} '
                     f'{"-" if sep is None else f"{sep:.3f}":>9} '
                     f'{"-" if cpu is None else f"{cpu:.2f}":>11} '
                     f'{"-" if rtf is None else f"{rtf:.2f}x":>6}  {r.get("exit_code")}')
    lines.append(f'  line: spawned {s["spawned"]}, sorted {s["sorted"]} '
                 f'({s["items_per_minute"]} items/min), missed {s["missed"]}, dropped '
                 f'{s["dropped"]}, wrong bin {s["wrong_bin"]}; {s["in_cells"]} in cells and '
                 f'{s["between_cells"]} between cells at the end'
                 + ('' if s.get('real_time_factor') is None else
                    f'; {s["real_time_factor"]:.2f}x real time (its slowest cell)'))
    lines.append(f'  handoffs: {s["handoffs"]} checked, '
                 + ('each received once' if not s['handoff_problems'] else
                    f'{len(s["handoff_problems"])} problem(s): {s["handoff_problems"][0]}')
                 + {True: '; items balance', False: '; items DO NOT balance',
                    None: '; balance not checked (a cell died)'}[s['balanced']])
    for r in s['cells']:
        if r.get('died_at') is not None or r.get('sim_seconds') is None:
            at = r.get('died_at')
            lines.append(f'  cell {r["cell"]} DIED' + (f' at sim t={at:.1f} s' if at else '')
                         + f' ({r.get("exit_reason")}); {s["through_dead"]} item(s) rode '
                         'through its section to the next cell')
    return '\n'.join(lines)


def plot_sorted(output: Union[str, Path], cells: int) -> Optional[Path]:
    """Draw items sorted per cell over sim time (``line_sorted.png``); None without events."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 4))
    drawn = False
    for k in range(cells):
        times = sorted(float(t) for t, kind, _, _ in read_events(cell_folder(output, k))
                       if kind == 'sorted')
        if times:
            ax.step([0.0] + times, range(len(times) + 1), where='post', label=f'cell {k}')
            drawn = True
    if not drawn:
        plt.close(fig)
        return None
    ax.set_xlabel('sim time, s')
    ax.set_ylabel('items sorted')
    ax.set_title(f'A line of {cells} cells: items sorted per cell')
    ax.legend()
    ax.grid(True, alpha=0.3)
    path = Path(output) / LINE_PLOT
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
