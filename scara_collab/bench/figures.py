"""The benchmark's figures (small PNGs), one function per section.

Each function takes that section's data (as :mod:`scara_collab.bench.suite` collects it) and
a file path, draws and saves; :func:`draw_all` draws what the results hold. Matplotlib's Agg
canvas is used directly (``matplotlib.figure.Figure``: no display, no pyplot state).
"""
from pathlib import Path
from typing import Callable, Dict

import numpy as np

from scara_collab.bench.claims import PAYLOAD_CLAIMS
from scara_collab.bench.solvers import display

DPI = 90
CONTROLLERS = {'pid': "PID (seeds' gains)", 'computed_torque': 'computed torque'}
COLOURS = {'line': 'tab:blue', 'joint': 'tab:orange', 'pid': 'tab:red',
           'computed_torque': 'tab:green', 'single': 'tab:orange',
           'collaborative': 'tab:blue', 'mirrored': 'tab:purple'}


def _figure(width: float, height: float, ncols: int = 1):
    """Return ``(figure, axes)``: a constrained-layout Agg figure with ``ncols`` axes."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(width, height), layout='constrained')
    axes = fig.subplots(1, ncols)
    return fig, axes


def _save(fig, path: Path) -> None:
    fig.savefig(path, dpi=DPI)


def paths_figure(data: dict, path: Path) -> None:
    """Plan view of both paths (planned and executed) and their deviation from the line."""
    fig, (ax, ax2) = _figure(9.5, 4.0, 2)
    start, goal = np.array(data['start']), np.array(data['goal'])
    ax.plot([start[0], goal[0]], [start[1], goal[1]], color='0.6', lw=6, alpha=0.35,
            label='straight segment')
    for method, label in (('line', 'straight line'), ('joint', 'joint interpolation')):
        s = data['series'][method]
        pp, pe = np.asarray(s['planned_p']), np.asarray(s['executed_p'])
        ax.plot(pp[:, 0], pp[:, 1], '--', color=COLOURS[method], lw=1.2,
                label=f'{label}, planned')
        ax.plot(pe[:, 0], pe[:, 1], '-', color=COLOURS[method], lw=2.0, alpha=0.6,
                label=f'{label}, executed')
        dev_e = np.maximum(np.asarray(s['executed_deviation']), 1e-9)
        dev_p = np.maximum(np.asarray(s['planned_deviation']), 1e-9)
        ax2.semilogy(s['planned_t'], dev_p * 1e3, '--', color=COLOURS[method],
                     label=f'{label}, planned')
        ax2.semilogy(s['executed_t'], dev_e * 1e3, '-', color=COLOURS[method], alpha=0.7,
                     label=f'{label}, executed')
    ax.plot(*start[:2], 'ko', ms=5)
    ax.plot(*goal[:2], 'k^', ms=6)
    ax.annotate('start', start[:2], textcoords='offset points', xytext=(6, -10), fontsize=8)
    ax.annotate('goal (belt centre)', goal[:2], textcoords='offset points', xytext=(6, 4),
                fontsize=8)
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.set_title(f'{data["length_m"]:.2f} m move, tool path seen from above', fontsize=10)
    ax.legend(fontsize=7, loc='lower left')
    ax2.axhline(1.0, color='k', lw=0.8, ls=':')
    ax2.text(0.02, 1.15, '1 mm', fontsize=7)
    ax2.set_xlabel('time from start (s)')
    ax2.set_ylabel('distance from the straight segment (mm)')
    ax2.set_ylim(1e-6, 1e3)
    ax2.set_title('deviation from the line (1e-6 mm floor)', fontsize=10)
    ax2.legend(fontsize=7, loc='lower right')
    _save(fig, path)


def solvers_figure(data: dict, path: Path) -> None:
    """Speed-up of the motion core over each reference, log scale."""
    rows = [r for r in data['rows'] if r['speedup'] is not None]
    fig, ax = _figure(8.0, 0.32 * len(rows) + 1.2)
    y = np.arange(len(rows))[::-1]
    vals = np.array([r['speedup'] for r in rows])
    ax.barh(y, vals, color=['tab:green' if v >= 1 else 'tab:red' for v in vals], alpha=0.7)
    ax.set_xscale('log')
    ax.set_xlim(min(vals.min(), 1.0) / 2, max(vals.max(), 1.0) * 4)
    ax.axvline(1.0, color='k', lw=0.8)
    ax.set_yticks(y)
    ax.set_yticklabels([f'{r["what"]} (vs {r["reference_name"]})' for r in rows], fontsize=7)
    for yi, r in zip(y, rows):
        ax.text(r['speedup'], yi, f' {display(r)["ratio"]}', va='center', fontsize=7)
    ax.set_xlabel('how many times faster ours is (log; < 1 = slower)')
    ax.set_title('motion core vs references, same run', fontsize=10)
    _save(fig, path)


def payload_figure(data: dict, path: Path) -> None:
    """Tool distance from the goal over time, PID vs computed torque, per payload."""
    fig, ax = _figure(8.0, 3.6)
    styles = {p: s for p, s in zip(sorted({r['payload'] for r in data['rows']}),
                                   ('-', '--', ':', '-.'))}
    for r in data['rows']:
        s = r['series']
        ax.semilogy(s['t'], np.maximum(s['to_goal'], 1e-6) * 1e3, styles[r['payload']],
                    color=COLOURS[r['mode']], lw=1.3,
                    label=f'{CONTROLLERS[r["mode"]]}, {r["payload"]:g} kg')
    dur = data['rows'][0]['duration']
    ax.axvline(dur, color='0.5', lw=0.8)
    ax.text(dur, 3e-2, ' trajectory ends', fontsize=7, color='0.4')
    ax.axhline(1.0, color='k', lw=0.8, ls=':')
    claims = ', '.join(f'{p:g} kg {c[0]} s' for p, c in PAYLOAD_CLAIMS.items())
    ax.set_title(f'1.5 m line with a payload: distance to the goal (seeds claim settling '
                 f'{claims})', fontsize=9)
    ax.set_xlabel('time from start (s)')
    ax.set_ylabel('tool to goal (mm)')
    ax.legend(fontsize=7, ncol=2)
    _save(fig, path)


def sync_figure(data: dict, path: Path) -> None:
    """Mirror error over each mirrored move."""
    fig, ax = _figure(8.0, 3.2)
    offset = 0.0
    for i, m in enumerate(data['moves']):
        s = m['series']
        ax.semilogy(offset + np.asarray(s['t']), np.maximum(s['mirror_error'], 1e-9) * 1e3,
                    color='tab:purple', lw=1.0)
        offset += float(s['t'][-1]) + 0.2
    ax.axhline(1.0, color='k', lw=0.8, ls=':')
    ax.axhline(4.0, color='tab:red', lw=0.8, ls='--')
    ax.text(0.0, 4.6, "seeds' claim: 4 mm average", fontsize=7, color='tab:red')
    ax.set_ylim(1e-6, 20)
    ax.set_xlabel('sim time over the moves, one after another (s)')
    ax.set_ylabel('mirror error (mm)')
    ax.set_title(f'{len(data["moves"])} mirrored moves through the ROS graph '
                 '(1e-6 mm floor)', fontsize=10)
    _save(fig, path)


def singularity_figure(data: dict, path: Path) -> None:
    """Peak revolute joint speed along each study path, pseudo-inverse vs DLS."""
    fig, ax = _figure(8.0, 3.6)
    colours = ('tab:blue', 'tab:orange', 'tab:green')
    for c, case in zip(colours, data['cases']):
        for kind, ls in (('pinv', '--'), ('dls', '-')):
            s = case[kind]['series']
            ax.plot(s['s'], s['speed'], ls, color=c, lw=1.2,
                    label=f'{case["name"]}, {"pseudo-inverse" if kind == "pinv" else "DLS"}')
    ax.axhline(data['velocity_limit'], color='k', lw=0.8, ls=':')
    ax.text(0.01, data['velocity_limit'] * 1.08, 'joint limit 2 rad/s', fontsize=7)
    ax.set_yscale('log')
    ax.set_xlabel('fraction of the path')
    ax.set_ylabel('fastest revolute joint (rad/s)')
    ax.set_title(f'straight lines at {data["speed"]} m/s through the seeds\' '
                 'differential-kinematics loop', fontsize=10)
    ax.legend(fontsize=7)
    _save(fig, path)


def foresight_figure(data: dict, path: Path) -> None:
    """Foresight of the conflicts found; separations unresolved, planned and executed."""
    pairs = data['pairs']
    conflicts = [p for p in pairs if p['conflict']]
    fig, (ax, ax2) = _figure(9.5, 3.6, 2)
    if conflicts:
        ax.hist([p['foresight_s'] for p in conflicts], bins=20, color='tab:blue', alpha=0.7,
                label='margin broken (predicted)')
        impacts = [p['impact_s'] for p in conflicts if p['impact_s'] is not None]
        if impacts:
            ax.hist(impacts, bins=20, color='tab:red', alpha=0.5, label='capsules touch')
    ax.axvline(0.2, color='k', ls='--', lw=1)
    ax.text(0.21, ax.get_ylim()[1] * 0.9, 'seeds: 200 ms', fontsize=7)
    ax.axvline(data['lead'], color='0.5', ls=':', lw=1)
    ax.text(data['lead'] + 0.01, ax.get_ylim()[1] * 0.8, 'motion starts', fontsize=7,
            color='0.4')
    ax.set_xlabel('time after the decision (s)')
    ax.set_ylabel('conflicting pairs')
    ax.set_title(f'{len(conflicts)} conflicts in {len(pairs)} crossing pairs', fontsize=10)
    ax.legend(fontsize=7)
    bins = np.linspace(-0.12, 0.42, 55)
    un = [p['unresolved_min_m'] for p in pairs if p['conflict']]
    pl = [p['planned_min_m'] for p in pairs if p['conflict'] and p['planned_min_m'] is not None]
    ex = [p['executed_min_m'] for p in pairs if p['executed_min_m'] is not None]
    for vals, colour, label in ((un, 'tab:red', 'started together (no resolution)'),
                                (pl, 'tab:blue', 'with the delay, planned'),
                                (ex, 'tab:green', 'with the delay, executed in physics')):
        if vals:
            ax2.hist(np.clip(vals, bins[0], bins[-1]), bins=bins, color=colour, alpha=0.55,
                     label=label)
    ax2.axvline(data['margin'], color='k', lw=1)
    ax2.text(data['margin'], ax2.get_ylim()[1] * 0.9, ' margin', fontsize=7)
    ax2.set_xlabel('smallest arm-to-arm distance over the pair (m)')
    ax2.set_ylabel('pairs')
    ax2.set_title('separation of the conflicting pairs', fontsize=10)
    ax2.legend(fontsize=7)
    _save(fig, path)


def throughput_figure(data: dict, path: Path) -> None:
    """Items per minute per mode and seed, with the seeds' claims."""
    fig, ax = _figure(6.0, 3.6)
    modes = list(data['modes'])
    claims = {'single': 12.0, 'collaborative': 22.0}
    for i, mode in enumerate(modes):
        vals = [r['items_per_minute'] for r in data['runs'] if r['mode'] == mode]
        ax.bar(i, np.mean(vals), color=COLOURS.get(mode, 'tab:gray'), alpha=0.5,
               yerr=np.std(vals, ddof=1) if len(vals) > 1 else None, capsize=4)
        ax.plot([i] * len(vals), vals, 'ko', ms=4)
        if mode in claims:
            ax.plot([i - 0.4, i + 0.4], [claims[mode]] * 2, 'r--', lw=1.2)
    ax.plot([], [], 'r--', label="seeds' claim")
    ax.plot([], [], 'ko', ms=4, label='one seed')
    ax.axhline(60.0 / data['feed_interval'], color='0.5', ls=':', lw=1)
    ax.text(len(modes) - 0.6, 60.0 / data['feed_interval'] - 1.8, 'item feed', fontsize=7,
            color='0.4', ha='right')
    ax.set_xticks(range(len(modes)))
    ax.set_xticklabels(modes)
    ax.set_ylabel('items sorted per sim minute')
    ax.set_title(f'capacity: an item every {data["feed_interval"]:g} s, {data["duration"]:g} '
                 'sim s per run', fontsize=10)
    ax.legend(fontsize=7, loc='lower right')
    _save(fig, path)


FIGURES: Dict[str, Callable[[dict, Path], None]] = {
    'paths': paths_figure, 'solvers': solvers_figure, 'payload': payload_figure,
    'sync': sync_figure, 'singularity': singularity_figure, 'foresight': foresight_figure,
    'throughput': throughput_figure}
"""Section key -> figure function; the file is ``<key>.png``."""


def draw_all(results: dict, directory: Path) -> Dict[str, str]:
    """Draw the figure of every section that has data; return ``{key: file name or error}``."""
    out = {}
    for key, fn in FIGURES.items():
        data = results.get(key)
        if not isinstance(data, dict) or 'error' in data or data.get('skipped'):
            continue
        name = f'{key}.png'
        try:
            fn(data, Path(directory) / name)
            out[key] = name
        except Exception as exc:  # noqa: B902 - a figure must not lose the report
            out[key] = f'error: {type(exc).__name__}: {exc}'
    return out
