"""Section 1, path deviation: the seeds' 1.5 m move as a straight line and as a joint move.

The measurement is :func:`scara_collab.bench.paths.measure` (planned by the motion core,
executed in the PyBullet cell); this module is its summary rows, its Markdown and its figure.
"""
from pathlib import Path

import numpy as np

from scara_collab.bench import paths
from scara_collab.bench.claims import CLAIMS
from scara_collab.bench.figures import canvas, save
from scara_collab.bench.markdown import m, md_table, met, mm, num, quote
from scara_collab.bench.sections.base import Rows, Section
from scara_collab.bench.util import fmt_seconds, Progress

TARGETS = {
    'line_planned': 1e-6,          # m
    'line_executed': 1e-3,         # m
}
"""The SPEC's targets (``../shared/SPEC.md`` §5), as numbers."""
COLOURS = {'line': 'tab:blue', 'joint': 'tab:orange'}


def measure(sizes: None, progress: Progress, scratch: Path) -> dict:
    """Plan and execute the seeds' move both ways (the section has no sizes)."""
    return paths.measure()


def summary(p: dict) -> Rows:
    """Return the summary rows: deviation of both moves, path length saved."""
    lp, le = p['planned']['line']['max_deviation'], p['executed']['line']['max_deviation']
    saved = 1 - p['planned']['line']['path_length'] / p['planned']['joint']['path_length']
    return [
        ("straight line, seeds' 1.5 m move: deviation planned / executed",
         CLAIMS['line_deviation'].figure, f'{m(lp, 2)} / {mm(le)}', '≤ 1e-6 m / ≤ 1 mm',
         met(lp <= TARGETS['line_planned'] and le <= TARGETS['line_executed'])),
        ('joint interpolation, same move: deviation planned / executed',
         CLAIMS['joint_deviation'].figure,
         f'{m(p["planned"]["joint"]["max_deviation"])} / '
         f'{m(p["executed"]["joint"]["max_deviation"])}', 'reported', ''),
        ('path length saved by the line', CLAIMS['path_length'].figure, f'{saved * 100:.1f} %',
         '', ''),
    ]


def markdown(p: dict, results: dict) -> str:
    """Return the section's text: the claims, the metrics of both moves planned and executed."""
    pl, ex = p['planned'], p['executed']

    def speeds(x):
        return f'{x["peak_speed"][0]:.2f}, {x["peak_speed"][1]:.2f}'

    rows = [
        ('largest distance from the straight segment', m(pl['joint']['max_deviation']),
         m(ex['joint']['max_deviation']), m(pl['line']['max_deviation'], 2),
         mm(ex['line']['max_deviation']), 'joint 0.385 m; line < 0.001 m'),
        ('tool path length', m(pl['joint']['path_length'], 4), m(ex['joint']['path_length'], 4),
         m(pl['line']['path_length'], 4), m(ex['line']['path_length'], 4),
         'line 14 % shorter'),
        ('duration: planned (time-optimal, same joint limits) / executed (until the tool '
         'stays within 1 mm of the goal)',
         num(pl['joint']['duration'], 3, 's'), num(ex['joint']['duration'], 3, 's'),
         num(pl['line']['duration'], 3, 's'), num(ex['line']['duration'], 3, 's'), ''),
        ('peak joint speed θ1, θ2 (rad/s)', speeds(pl['joint']), speeds(ex['joint']),
         speeds(pl['line']), speeds(ex['line']), ''),
        ('RMS tool jerk, 100 Hz samples (m/s³)', num(pl['joint']['rms_jerk']),
         num(ex['joint']['rms_jerk']), num(pl['line']['rms_jerk']), num(ex['line']['rms_jerk']),
         'joint high, line low'),
        ('end error', '', mm(ex['joint']['end_error']), '', mm(ex['line']['end_error']), ''),
        ('largest tool error against the plan', '', mm(ex['joint']['max_tracking_error']), '',
         mm(ex['line']['max_tracking_error']), ''),
        ('planning time', fmt_seconds(p['plan_time_s']['joint']), '',
         fmt_seconds(p['plan_time_s']['line']), '', ''),
    ]
    saved = 1 - pl['line']['path_length'] / pl['joint']['path_length']
    start, goal = p['start'], p['goal']
    return '\n\n'.join([
        quote('joint_deviation', 'line_deviation', 'path_length'),
        f'The seeds\' "1.5m move from the rest position to the conveyor center", taken as '
        f'{tuple(start)} → {tuple(goal)} m in world for `{p["arm"]}` ({p["length_m"]:.3f} m), '
        'planned by the motion core both ways, each time-optimal under the same joint '
        'velocity and acceleration limits, then executed in the PyBullet cell '
        f'(`{p["control_mode"]}`, 1 kHz physics) and measured from the joint states at 100 Hz.',
        md_table(('metric', 'joint interp., planned', 'joint interp., executed',
                  'straight line, planned', 'straight line, executed', "seeds' claim"), rows),
        f'The straight line is {saved * 100:.1f} % shorter than the joint-interpolated path '
        f'(seeds: 14 %); joint interpolation bows {m(pl["joint"]["max_deviation"])} off the '
        'line (seeds: 0.385 m). RMS jerk is of the tool position, third difference of the '
        '100 Hz samples (the seeds give no number, only "high" and "low").'])


def figure(data: dict, path: Path) -> None:
    """Plan view of both paths (planned and executed) and their deviation from the line."""
    fig, (ax, ax2) = canvas(9.5, 4.0, 2)
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
    save(fig, path)


SECTION = Section(
    key='paths', title='path deviation: straight line vs joint interpolation',
    heading='Path deviation: straight line vs joint interpolation', measure=measure,
    markdown=markdown, summary=summary, figure=figure,
    figure_alt='tool paths seen from above and their deviation')
