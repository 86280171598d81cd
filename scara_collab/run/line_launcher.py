"""A line of cells: ``launch_cell.py --cells N`` starts one cell launcher per cell.

Cell ``k`` runs under ``/cell_k`` (:func:`scara_collab.graph.cell_namespace`) with its own node
processes (or one, with ``--one-process``), its own lockstep and its own run folder
``<output>/cell_k`` (everything a lone cell's run writes). Its bridge hands on what passes its
belt's end to cell ``k + 1`` and takes what cell ``k - 1`` hands on
(:mod:`scara_collab.core.line`: one belt in sections, conservative synchronisation between
cells); only cell 0 is fed. Each cell is ``python -m scara_collab.run.launcher --line-cell K``
with the line's own arguments, quiet; this launcher prints one progress line for the line
and, at the end, the line's report (:mod:`scara_collab.records.line_report`), and writes
``summary.json`` (with a ``cells`` list), ``line_report.txt`` and ``line_sorted.png`` into
``<output>``.

The cells start together. A cell waits for the frontier of the cell upstream before it steps
past the belt's transit, so a downstream cell's sim time may stand still while the one
upstream starts: the cells get a ``--stall-timeout`` that covers the start of the others.
SIGINT or SIGTERM is passed on to every cell, which stops and reports as on its own. The
line's exit code is the first non-zero code of its cells, else 7 if an item was lost or
duplicated between cells, else 0.
"""
import datetime
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Dict, List

from scara_collab.core.line import Section
from scara_collab.core.model import load_cell
from scara_collab.records import line_report as lr
from scara_collab.records.report import write_summary
from scara_collab.run.environment import node_environment
from scara_collab.run.options import LaunchOptions

#: the line launcher's own options, not passed on to the cells, and how many values follow
#: (-1: an optional number)
_OWN = {'--output': 1, '--cells': 1, '--quiet': 0, '--stall-timeout': 1, '--discovery-server': -1}
LINE_STALL = 300.0  # wall s a cell's sim time may stand still (the others starting up)


def cell_argv(argv: List[str], k: int, cells: int, output: Path, stall: float) -> List[str]:
    """Return the command line of cell ``k``'s launcher: the line's, its own place and folder.

    >>> cell_argv(['--duration', '30', '--cells', '2', '--output', 'x'], 1, 2, Path('/r'), 60)
    ['--duration', '30', '--cells', '2', '--line-cell', '1', '--output', '/r/cell_1', '--quiet', \
'--stall-timeout', '60']
    >>> cell_argv(['--discovery-server', '--seed', '3', '--discovery-server', '7', '--rtf', '0'],
    ...           0, 2, Path('/r'), 60)[:4]
    ['--seed', '3', '--rtf', '0']
    """
    out, skip = [], 0
    for a in argv:
        if skip and (skip > 0 or a.isdigit()):
            skip = max(skip - 1, 0)
            continue
        key = a.split('=', 1)[0]
        skip = 0
        if key in _OWN:
            skip = 0 if '=' in a else _OWN[key]
            continue
        out.append(a)
    return out + ['--cells', str(cells), '--line-cell', str(k), '--output',
                  str(lr.cell_folder(output, k)), '--quiet', '--stall-timeout', f'{stall:g}']


def _progress(output: Path, cells: int) -> str:
    parts = []
    for k in range(cells):
        try:
            s = json.loads((lr.cell_folder(output, k) / 'summary.json').read_text('utf-8'))
        except (OSError, ValueError):
            parts.append(f'cell {k} starting')
            continue
        parts.append(f'cell {k} {float(s.get("sim_seconds") or 0.0):5.1f} s '
                     f'sorted {s.get("sorted")} handed {s.get("handed_on")}')
    return ' | '.join(parts)


def run_line(opts: LaunchOptions, argv: List[str]) -> int:
    """Run a line of ``opts.cells`` cells (``argv``: its command line); return its exit code."""
    cells = opts.cells
    stamp = datetime.datetime.now().strftime('%Y%m%d_%H%M%S')
    output = (opts.output or Path('runs') / f'{stamp}_line{cells}_{opts.mode}').resolve()
    output.mkdir(parents=True, exist_ok=True)
    section = Section(load_cell(opts.profile))
    stall = max(LINE_STALL, opts.stall_timeout)
    say = (lambda text: None) if opts.quiet else (lambda text: print(text, flush=True))
    say(f'[line] {cells} cells at a pitch of {section.pitch:.2f} m (transit '
        f'{section.transit:.2f} s between sections), {opts.duration:g} sim s, output {output}')
    procs: Dict[int, subprocess.Popen] = {}
    logs = []
    for k in range(cells):
        folder = lr.cell_folder(output, k)
        folder.mkdir(parents=True, exist_ok=True)
        log = open(folder / 'console.log', 'w', encoding='utf-8')
        logs.append(log)
        cmd = [sys.executable, '-m', 'scara_collab.run.launcher'] + cell_argv(
            argv, k, cells, output, stall)
        procs[k] = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                    env=node_environment(os.environ), start_new_session=True)
        say(f'[line] cell {k} under /cell_{k}: pid {procs[k].pid}, log {folder}/console.log')
    signals: List[int] = []

    def on_signal(signum, _frame):
        signals.append(signum)
        for p in procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT if signum == signal.SIGINT else signal.SIGTERM)
    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    ended: Dict[int, str] = {}
    try:
        next_progress = time.monotonic() + 5.0
        while any(p.poll() is None for p in procs.values()):
            time.sleep(0.2)
            for k, p in procs.items():
                if p.returncode is not None and k not in ended:
                    ended[k] = f'cell launcher exited {p.returncode}'
                    if p.returncode != 0:
                        say(f'[line] cell {k} ended with exit {p.returncode}; see '
                            f'{lr.cell_folder(output, k)}')
            if time.monotonic() >= next_progress:
                next_progress = time.monotonic() + 5.0
                say(f'[line] {_progress(output, cells)}')
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        for log in logs:
            log.close()
    summary = lr.line_summary(output, cells, section.transit, opts.duration, section.pitch,
                              ended=ended)
    if signals:
        summary['exit_code'] = 130 if signals[0] == signal.SIGINT else 143
        summary['exit_reason'] = signal.Signals(signals[0]).name
    summary['output'] = str(output)
    write_summary(output, summary)
    text = lr.format_line_report(summary)
    (output / lr.LINE_REPORT).write_text(text + '\n', encoding='utf-8')
    if opts.plots:
        lr.plot_sorted(output, cells)
    print(text, file=sys.stderr if opts.quiet else sys.stdout, flush=True)
    return int(summary['exit_code'])
