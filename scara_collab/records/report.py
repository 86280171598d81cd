"""What a run leaves for people: ``summary.json``, the plots and the printed report.

Plots are drawn from the run folder's CSV files (so they can be redrawn later with
``python -m scara_collab.records.report RUN_DIR``) with matplotlib's Agg canvas (no display, no
pyplot state):

- ``tool_paths.png``: top view of the cell (belt band, bases with their reach, bins per class)
  with both tool paths;
- ``arm_distance.png``: arm-to-arm capsule surface distance over time against the margin;
- ``item_counts.png``: cumulative sorted / missed / wrong bin / dropped / spawned items;
- ``mirror_error.png`` (mirrored mode): follower tool vs the mirror of the leader tool;
- ``separation.png`` (a run with a person): per arm the separation ``S`` from the person and
  the protective separation ``S_p`` as the separation monitor saw them, the true separation
  (dashed), the arm's protective stops shaded and its slowed time lightly shaded
  (:mod:`scara_collab.records.person`).
"""
import argparse
import csv
import json
import math
import os
from pathlib import Path
import sys
from typing import Dict, List, Optional, Union

import numpy as np

from scara_collab.core.model import CellModel
from scara_collab.records.person import SEPARATION, TRUTH
from scara_collab.records.telemetry import ARM_DISTANCE, EVENTS, MIRROR_ERROR, TIMESERIES

SUMMARY = 'summary.json'
PLOTS = ('tool_paths.png', 'arm_distance.png', 'item_counts.png', 'mirror_error.png')
#: the plot of a run with a person
PERSON_PLOT = 'separation.png'
_ARM_COLOURS = ('tab:orange', 'tab:purple')
_COUNT_COLOURS = {'sorted': 'tab:green', 'missed': 'tab:red', 'wrong_bin': 'tab:orange',
                  'dropped': 'tab:brown', 'spawned': 'tab:gray'}


# --- summary.json ------------------------------------------------------------------------------
def _json_safe(value):
    """Non-finite floats -> None (strict JSON); numpy scalars -> Python; recurse containers."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_summary(directory: Union[str, Path], summary: Dict) -> Path:
    """Write ``summary.json`` atomically (a reader never sees half a file).

    :param directory: the run folder.
    :param summary: the summary; non-finite numbers are written as null.
    :return: the path written.
    """
    path = Path(directory) / SUMMARY
    tmp = path.with_name(SUMMARY + '.tmp')
    with open(tmp, 'w', encoding='utf-8') as f:
        json.dump(_json_safe(summary), f, indent=2, allow_nan=False)
        f.write('\n')
    os.replace(tmp, path)
    return path


def read_summary(directory: Union[str, Path]) -> Dict:
    """Read a run folder's ``summary.json``."""
    with open(Path(directory) / SUMMARY, encoding='utf-8') as f:
        return json.load(f)


# --- reading the CSV files ---------------------------------------------------------------------
def load_timeseries(directory: Union[str, Path]) -> Dict[str, np.ndarray]:
    """``timeseries.csv`` as ``{column: (N,) array}``; malformed lines are skipped."""
    path = Path(directory) / TIMESERIES
    with open(path, encoding='utf-8') as f:
        header = f.readline().strip().split(',')
        rows = []
        for line in f:
            parts = line.rstrip('\n').split(',')
            if len(parts) != len(header):
                continue
            try:
                rows.append([float(p) for p in parts])
            except ValueError:
                continue
    data = np.asarray(rows, dtype=float).reshape(-1, len(header))
    return {name: data[:, k] for k, name in enumerate(header)}


def load_columns(path: Union[str, Path]) -> Dict[str, np.ndarray]:
    """Read a CSV file of numbers as ``{column: (N,) array}``; text columns, short rows skipped.

    ``inf`` stays infinite; a value that is not a number is NaN.
    """
    with open(path, encoding='utf-8', newline='') as f:
        reader = csv.reader(f)
        header = next(reader, [])
        rows = [row for row in reader if len(row) == len(header)]

    def number(text: str) -> float:
        try:
            return float(text)
        except ValueError:
            return math.nan

    out = {}
    for k, name in enumerate(header):
        values = np.array([number(row[k]) for row in rows], dtype=float)
        if not (values.size and np.all(np.isnan(values))):
            out[name] = values
    return out


def load_events(directory: Union[str, Path]) -> List[Dict[str, str]]:
    """``events.csv`` as a list of dicts (``time`` stays a string)."""
    with open(Path(directory) / EVENTS, encoding='utf-8', newline='') as f:
        return [row for row in csv.DictReader(f) if row.get('time')]


# --- plots -------------------------------------------------------------------------------------
def _figure(width: float = 8.0, height: float = 4.5):
    from matplotlib.figure import Figure  # Agg canvas by default for savefig; no pyplot
    return Figure(figsize=(width, height), layout='constrained')


def _class_colour(name: str, k: int) -> str:
    from matplotlib.colors import is_color_like
    return name if is_color_like(name) else f'C{k}'


def _job_line(ax, t0: Optional[float]) -> None:
    if t0 is not None:
        ax.axvline(t0, color='0.5', lw=0.8, ls=':', label=f'job start (t={t0:.1f} s)')


def _save(fig, ax, path: Path, xlabel: str, ylabel: str, title: str, **legend) -> Path:
    """Label the axes, title, grid and legend (``legend``: its keywords); save to ``path``."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, lw=0.3)
    ax.legend(**legend)
    fig.savefig(path, dpi=110)
    return path


def plot_tool_paths(cell: CellModel, ts: Dict[str, np.ndarray], path: Path) -> Path:
    """Top view: belt, bases and reach, bins, both tool paths; saved to ``path``."""
    from matplotlib.patches import Circle, Rectangle
    belt = cell.belt
    lo = [belt.x_start, belt.centre_y - belt.width / 2]
    hi = [belt.x_end, belt.centre_y + belt.width / 2]
    for arm in cell.arms:
        for k in (0, 1):
            lo[k] = min(lo[k], arm.base[k, 3] - arm.reach_max)
            hi[k] = max(hi[k], arm.base[k, 3] + arm.reach_max)
    aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-6)
    fig = _figure(7.0, min(max(7.0 * aspect * 0.85, 4.0), 11.0))
    ax = fig.add_subplot()
    ax.add_patch(Rectangle((belt.x_start, belt.centre_y - belt.width / 2),
                           belt.x_end - belt.x_start, belt.width, color='0.85', zorder=0,
                           label=f'belt ({belt.speed:g} m/s along +x)'))
    bin_size = cell.config['bins']['size']
    for k, cls in enumerate(cell.item_classes):
        colour = _class_colour(cls, k)
        for j, arm in enumerate(cell.arms):
            c = cell.bins[(arm.name, cls)]
            ax.add_patch(Rectangle((c[0] - bin_size[0] / 2, c[1] - bin_size[1] / 2),
                                   bin_size[0], bin_size[1], fill=False, ec=colour, lw=2,
                                   label=f'{cls} bins' if j == 0 else None))
    base_r = float(cell.config['arm'].get('base_radius', 0.12))
    for arm, colour in zip(cell.arms, _ARM_COLOURS):
        b = arm.base[:3, 3]
        ax.add_patch(Circle(b[:2], base_r, color=colour, alpha=0.6))
        ax.add_patch(Circle(b[:2], arm.reach_max, fill=False, ec=colour, ls='--', lw=0.6,
                            alpha=0.6))
        ax.annotate(arm.name, b[:2], xytext=(6, 6), textcoords='offset points', fontsize=8)
        x, y = ts.get(f'{arm.name}_tool_x'), ts.get(f'{arm.name}_tool_y')
        if x is not None and x.size:
            ax.plot(x, y, color=colour, lw=0.8, label=f'{arm.name} tool')
            ax.plot(x[-1], y[-1], 'o', color=colour, ms=4)
    ax.set_xlim(lo[0] - 0.2, hi[0] + 0.2)
    ax.set_ylim(lo[1] - 0.2, hi[1] + 0.2)
    ax.set_aspect('equal')
    return _save(fig, ax, path, 'x (m)', 'y (m)', 'Tool paths, top view (dashed: reach)',
                 loc='upper right', fontsize=7)


def plot_arm_distance(ts: Dict[str, np.ndarray], margin: float, path: Path,
                      t0: Optional[float] = None) -> Path:
    """Arm-to-arm surface distance over time with the safety margin; saved to ``path``."""
    fig = _figure()
    ax = fig.add_subplot()
    t, d = ts.get('t', np.empty(0)), ts.get(ARM_DISTANCE, np.empty(0))
    ax.plot(t, d, lw=0.8, label='arm distance (capsule surfaces)')
    ax.axhline(margin, color='tab:red', ls='--', lw=1, label=f'safety margin {margin:g} m')
    if d.size:
        k = int(np.argmin(d))
        ax.plot(t[k], d[k], 'v', color='tab:red')
        ax.annotate(f'min {d[k]:.3f} m at {t[k]:.1f} s', (t[k], d[k]), xytext=(5, -12),
                    textcoords='offset points', fontsize=8)
    _job_line(ax, t0)
    ax.set_ylim(bottom=min(0.0, float(d.min()) if d.size else 0.0))
    return _save(fig, ax, path, 'sim time (s)', 'distance (m)', 'Arm separation', fontsize=8)


def plot_item_counts(events: List[Dict[str, str]], path: Path, t_end: Optional[float] = None,
                     t0: Optional[float] = None) -> Path:
    """Cumulative item counts per kind over time; saved to ``path``."""
    fig = _figure()
    ax = fig.add_subplot()
    for kind, colour in _COUNT_COLOURS.items():
        times = sorted(float(e['time']) for e in events if e.get('kind') == kind)
        if not times and kind not in ('sorted', 'missed'):
            continue
        x = [0.0] + times + ([t_end] if t_end is not None else [])
        y = [0] + list(range(1, len(times) + 1)) + ([len(times)] if t_end is not None else [])
        ax.step(x, y, where='post', color=colour, label=f'{kind} ({len(times)})')
    _job_line(ax, t0)
    return _save(fig, ax, path, 'sim time (s)', 'items', 'Items over time (conveyor events)',
                 fontsize=8, loc='upper left')


def plot_mirror_error(ts: Dict[str, np.ndarray], path: Path, t0: Optional[float] = None,
                      target: float = 1e-3) -> Path:
    """Mirror error (mm) over time against the 1 mm target; saved to ``path``."""
    fig = _figure()
    ax = fig.add_subplot()
    t, e = ts.get('t', np.empty(0)), ts.get(MIRROR_ERROR, np.empty(0)) * 1e3
    ax.plot(t, e, lw=0.8, label='|follower tool - mirror(leader tool)|')
    ax.axhline(target * 1e3, color='tab:red', ls='--', lw=1, label=f'target {target * 1e3:g} mm')
    _job_line(ax, t0)
    ax.set_yscale('symlog', linthresh=0.1)  # sub-mm detail and the large excursions together
    ax.set_ylim(bottom=0.0)
    return _save(fig, ax, path, 'sim time (s)', 'mirror error (mm, linear below 0.1)',
                 'Mirroring', fontsize=8)


def _spans(t: np.ndarray, on: np.ndarray) -> List[tuple]:
    """Return the ``(start, end)`` of each run of ``on``, each to the next sample's time."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], on.astype(int), [0]))))
    times = np.append(t, t[-1] if t.size else 0.0)
    return [(float(times[a]), float(times[b])) for a, b in zip(edges[::2], edges[1::2])]


def plot_separation(directory: Union[str, Path], path: Path,
                    t0: Optional[float] = None) -> Path:
    """Per arm, ``S`` and ``S_p`` over time with the stops and slow-downs; saved to ``path``.

    From ``separation.csv`` (the monitor's) and ``person_truth.csv`` (the true separation,
    dashed) in ``directory``; ``inf`` (no person) is not drawn.
    """
    directory = Path(directory)
    seen = load_columns(directory / SEPARATION)
    true = load_columns(directory / TRUTH) if (directory / TRUTH).exists() else {}
    robots = [c[:-len('_scale')] for c in seen if c.endswith('_scale')]
    fig = _figure(8.0, 2.2 + 2.3 * max(len(robots), 1))
    axes = fig.subplots(max(len(robots), 1), 1, sharex=True, squeeze=False)[:, 0]
    t = seen.get('t', np.empty(0))
    t_true = true.get('t', np.empty(0))

    def finite(v: np.ndarray) -> np.ndarray:
        return np.where(np.isfinite(v), v, np.nan)

    for k, (ax, robot) in enumerate(zip(axes, robots)):
        scale = seen.get(f'{robot}_scale', np.ones_like(t))
        stopped = seen.get(f'{robot}_stopped', np.zeros_like(t)) > 0.5
        for j, (a, b) in enumerate(_spans(t, stopped)):
            ax.axvspan(a, b, color='tab:red', alpha=0.25, lw=0,
                       label='protective stop' if j == 0 else None)
        for j, (a, b) in enumerate(_spans(t, ~stopped & (scale < 1.0))):
            ax.axvspan(a, b, color='tab:orange', alpha=0.12, lw=0,
                       label='slowed' if j == 0 else None)
        ax.plot(t, finite(seen.get(f'{robot}_S_m', np.full_like(t, np.inf))), lw=0.9,
                color=_ARM_COLOURS[k % 2], label='S (monitor)')
        ax.plot(t, finite(seen.get(f'{robot}_Sp_m', np.full_like(t, np.inf))), lw=0.9,
                color='tab:blue', label='S_p (monitor, planned speed)')
        if f'{robot}_S_m' in true:
            ax.plot(t_true, finite(true[f'{robot}_S_m']), lw=0.8, ls='--', color='0.3',
                    label='S (true)')
        _job_line(ax, t0)
        ax.set_ylim(bottom=0.0)
        if k < len(robots) - 1:
            ax.set_xlabel('')
        ax.set_ylabel('m')
        ax.set_title(robot, fontsize=9)
        ax.grid(True, lw=0.3)
        ax.legend(fontsize=7, loc='upper right')
    axes[-1].set_xlabel('sim time (s)')
    fig.suptitle('Separation from the person')
    fig.savefig(path, dpi=110)
    return path


def plot_run(directory: Union[str, Path], cell: CellModel, summary: Dict) -> List[Path]:
    """Draw every plot of a run folder from its CSV files.

    :param directory: the run folder (``timeseries.csv``, ``events.csv``).
    :param cell: the cell model the run used.
    :param summary: the run summary (``mode``, ``job_start_sim_time``, ``sim_time_end``,
        ``person``).
    :return: the PNG files written.
    """
    directory = Path(directory)
    ts = load_timeseries(directory)
    events = load_events(directory)
    t0 = summary.get('job_start_sim_time')
    t_end = summary.get('sim_time_end')
    out = [plot_tool_paths(cell, ts, directory / PLOTS[0]),
           plot_arm_distance(ts, cell.safety_margin, directory / PLOTS[1], t0),
           plot_item_counts(events, directory / PLOTS[2], t_end, t0)]
    if summary.get('mode') == 'mirrored':
        out.append(plot_mirror_error(ts, directory / PLOTS[3], t0))
    if isinstance(summary.get('person'), dict) and (directory / SEPARATION).exists():
        out.append(plot_separation(directory, directory / PERSON_PLOT, t0))
    return out


# --- text --------------------------------------------------------------------------------------
def _num(value, fmt: str, none: str = 'n/a') -> str:
    return none if value is None else format(value, fmt)


def format_rtf(value: Optional[float]) -> str:
    """Real-time factor as ``'7.3x'``."""
    return 'n/a' if value is None else f'{value:.1f}x'


def format_progress(p: Dict, duration: float) -> str:
    """One progress line.

    :param p: ``sim`` (job sim s), ``sorted``, ``missed``, ``items_per_minute``,
        ``min_separation_m``, ``rtf``.
    :param duration: the run's sim duration, s.
    """
    sep = p.get('min_separation_m')
    return (f'sim {p["sim"]:6.1f}/{duration:g} s | sorted {p["sorted"]} | missed {p["missed"]}'
            f' | {p["items_per_minute"]:.1f} items/min | min sep '
            f'{_num(sep, ".3f", "-")} m | RTF {format_rtf(p.get("rtf"))}')


def _mirror_note(s: Dict) -> str:
    whole = s.get('mirror_error_whole_run_max_m')
    if not s.get('mirror_error_source') or whole is None:
        return ''
    return (f' over {s.get("mirror_in_step_moves")} moves the arms ran in step '
            f'({s.get("mirror_not_in_step")} not in step); {whole * 1e3:.2f} mm over the whole '
            'run '
            f'(t={_num(s.get("mirror_error_whole_run_time"), ".1f")} s, arms not in step)')


#: stops, silences and problems listed one a line in the report; then a count
REPORT_ITEMS = 3


def format_outcome(s: Dict) -> str:
    """Return the report's first line: the mode, how the run ended, its exit code and reason.

    A clean run: ``finished (duration reached)``; one that ended early: ``interrupted
    (SIGINT), exit 130``; one that ran to its end but failed its verdict
    (:mod:`scara_collab.records.verdict`): ``FAILED, exit 3: margin broken: ...; finished
    (duration reached)``.
    """
    head = f'scara_collab run: mode {s.get("mode")}, '
    code = s.get('exit_code') or 0
    ended = s.get('end_reason') or s.get('exit_reason')
    if s.get('interrupted'):
        return head + f'interrupted ({s.get("exit_reason")})' + (f', exit {code}' if code
                                                                 else '')
    if code:
        return head + f'FAILED, exit {code}: {s.get("exit_reason")}; finished ({ended})'
    return head + f'finished ({s.get("exit_reason")})'


def _more(lines: List[str], total: int, what: str) -> List[str]:
    """Return the first :data:`REPORT_ITEMS` of ``lines``, then a count of the rest."""
    out = lines[:REPORT_ITEMS]
    if total > len(out):
        out.append(f'... and {total - len(out)} more {what} (summary.json)')
    return out


def _block(title: str, lines: List[str]) -> List[str]:
    """Return ``lines`` under a 15-column ``title`` (the report's layout)."""
    return [f'  {title if k == 0 else "":<15}{line}' for k, line in enumerate(lines)]


def _stop_lines(s: Dict) -> List[str]:
    """Return the report's stops: count and time lost per kind, then the stops one a line."""
    kinds = [(k, s.get(f'{k}_stops')) for k in ('protective', 'emergency')]
    kinds = [(k, v) for k, v in kinds if isinstance(v, list) and v]
    if not kinds:
        return []
    head = ', '.join(f'{k} {len(v)} ({sum(x.get("lost") or 0.0 for x in v):.2f} s lost'
                     + (', STANDING at the end' if any(x.get('standing') for x in v) else '')
                     + ')' for k, v in kinds)
    each = sorted(((x.get('time') or 0.0, k, x) for k, v in kinds for x in v),
                  key=lambda e: (not e[2].get('standing'), e[0]))  # standing ones first
    items = [f'{k:<10} t={t:.2f} s, ' + ('standing' if x.get('standing')
                                         else f'{x.get("lost") or 0.0:.2f} s')
             + f': {x.get("cause")}' for t, k, x in each]
    return _block('stops', [head] + _more(items, len(items), 'stops'))


def _silence_lines(s: Dict) -> List[str]:
    """Return the report's silences: node, length (wall s, sim s behind), from when."""
    silences = s.get('silences') or []
    items = [f'{x.get("node")} {x.get("wall_s", 0.0):.1f} s wall / {x.get("lag_s", 0.0):.1f} s '
             f'sim behind from sim t={_num(x.get("sim_time"), ".2f")} s'
             + (', dropped by the bridge' if x.get('dropped') else '')
             + ('' if x.get('ended') else ', until the end') for x in silences]
    return _block('silences', _more(items, len(items), 'silences'))


def _intruder_lines(s: Dict) -> List[str]:
    """Return the report's foreign clocks and second graphs."""
    clocks = [f'sim t={_num(c.get("time"), ".2f")} s: {c.get("publishers")} /clock '
              f'publishers ({", ".join(c.get("nodes") or [])})'
              for c in s.get('foreign_clocks') or []]
    if s.get('clock_jumps_back'):
        first = s['clock_jumps_back'][0]
        clocks.append(f'/clock went backwards {s.get("clock_jumps_back_count")} time(s), first '
                      f'at sim t={first.get("time"):.3f} s (to {first.get("to"):.3f} s)')
    graphs = [f'sim t={_num(g.get("time"), ".2f")} s: ' + ', '.join(
        f'{n} x {name}' for name, n in (g.get('nodes') or {}).items())
        for g in s.get('second_graphs') or []]
    return (_block('foreign clock', _more(clocks, len(clocks), 'foreign clocks'))
            + _block('second graph', _more(graphs, len(graphs), 'second graphs')))


def _person_lines(s: Dict) -> List[str]:
    """Return the report's person lines (a run with a person only; the summary's block)."""
    p = s.get('person')
    if not isinstance(p, dict):
        return []
    n = _num
    lines = [
        f'{p.get("scenario")}: {n(p.get("intrusions"), "d")} intrusion(s), '
        f'{p.get("protective_stops")} protective stop(s) ({n(p.get("stop_seconds"), ".2f")} s), '
        f'slowed {n(p.get("slowed_seconds"), ".2f")} s, {p.get("slowdowns")} slow-down(s) '
        f'({n(p.get("false_slowdowns"), "d")} false), full speed '
        f'{n(p.get("resume_seconds_max"), ".2f", "-")} s at most after clear of S_p',
        f'while moving: min separation {n(p.get("min_separation_m"), ".3f", "-")} m, '
        f'min S - S_p {n(p.get("min_ssm_margin_m"), ".3f", "-")} m, '
        f'{p.get("contacts_while_moving")} contact(s); '
        f'{n(p.get("missed_due_to_person"), "d")} missed for the person']
    faults = p.get('faults') or []
    if p.get('fault_stops') or p.get('fault_at_end'):
        first = faults[0] if faults else {}
        lines.append(f'separation monitor faults {p.get("fault_stops")}'
                     + (f', first at t={n(first.get("time"), ".2f")} s: {first.get("fault")}'
                        if first else '')
                     + (f'; STANDING at the end: {p.get("fault_at_end")}'
                        if p.get('fault_at_end') else ''))
    return _block('person', lines)


def _problem_lines(s: Dict) -> List[str]:
    """Return the report's problems (each reason the exit code is not 0), if more than one."""
    problems = [f'exit {p.get("code")}: {p.get("text")}' for p in s.get('problems') or []]
    return _block('problems', _more(problems, len(problems), 'problems')) \
        if len(problems) > 1 else []


def format_report(s: Dict) -> str:
    """Return the final report of a run (several lines) from its summary.

    The first line says how the run ended and, if it is not 0, its exit code and the reason
    (:func:`format_outcome`).
    """
    margin = s.get('safety_margin_m') or 0.0
    sep = s.get('min_separation_m')
    verdict = ('' if sep is None else
               f'  ({"OK" if sep >= margin else "BROKEN"}: margin {margin:g} m)')
    mirror = s.get('mirror_error_max_m')
    lines = [
        format_outcome(s),
        f'  sim time       {_num(s.get("sim_seconds"), ".1f")} s    wall '
        f'{_num(s.get("wall_seconds"), ".1f")} s    real-time factor '
        f'{format_rtf(s.get("real_time_factor"))}'
        + (f'    lockstep {s["lockstep"]}' if s.get('lockstep') else ''),
        f'  items          sorted {s.get("sorted")}   missed {s.get("missed")}   wrong bin '
        f'{s.get("wrong_bin")}   dropped {s.get("dropped")}   (spawned {s.get("spawned")}; '
        f'counts from {s.get("counts_source")})',
        f'  throughput     {_num(s.get("items_per_minute"), ".1f")} items/min   (job: '
        f'{(s.get("job") or {}).get("give_ups", "n/a")} give-ups, '
        f'{(s.get("job") or {}).get("retries", "n/a")} retries)',
        f'  min arm sep.   {_num(sep, ".3f", "n/a (no joint states)")}'
        + ('' if sep is None else ' m') + verdict,
        '  mirror error   ' + ('n/a (mirrored mode only)' if mirror is None
                               else f'max {mirror * 1e3:.2f} mm' + _mirror_note(s)),
    ]
    missing = s.get('joint_states_missing') or 0
    if missing:
        rows = s.get('joint_state_rows') or 0
        lines.append(f'  telemetry      {missing} of {rows + missing} joint states not heard '
                     f'(largest gap {s.get("largest_gap_s") or 0.0:.2f} s): short of CPU?')
    fast = s.get('overspeed') or []
    if fast:
        first = fast[0]
        lines.append(f'  overspeed      {s.get("overspeed_count", len(fast))} time(s) a joint ran '
                     'faster than its limit allows (no admitted trajectory does): first '
                     f'{first["robot"]} joint {first["joint"]} {first["speed"]:.2f} (limit '
                     f'{first["limit"]:g}) at sim t={first["time"]:.2f} s')
    cost = s.get('cpu_per_sim_s') or {}
    if cost:
        parts = [f'{k.replace("_", " ")} {v:.3f}' for k, v in cost.items() if k != 'total']
        lines.append(f'  CPU per sim s  {cost.get("total", 0.0):.3f} s   (' + ', '.join(parts)
                     + ')')
    lines += (_person_lines(s) + _stop_lines(s) + _silence_lines(s) + _intruder_lines(s)
              + _problem_lines(s))
    lines.append(f'  run folder     {s.get("output")}')
    return '\n'.join(lines)


def main(argv: Optional[List[str]] = None) -> int:
    """Redraw the plots of a run folder and print its report."""
    from scara_collab.core.model import load_cell
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument('run_dir', help='a run folder written by scripts/launch_cell.py')
    args = parser.parse_args(argv)
    summary = read_summary(args.run_dir)
    plot_run(args.run_dir, load_cell(summary.get('profile') or None), summary)
    print(format_report(summary))
    return 0


if __name__ == '__main__':
    sys.exit(main())
