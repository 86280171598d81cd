"""Section 3, payload response: PID vs computed torque on a 1.5 m line, and simulator speed.

The measurements are :func:`scara_collab.bench.physics.payload_study` and
:func:`scara_collab.bench.physics.speed_study` (the simulator's speed is printed in section 7,
beside the whole graph's); this module is their summary row, Markdown and figure.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import Tuple

import numpy as np

from scara_collab.bench import physics
from scara_collab.bench.claims import PAYLOAD_CLAIMS
from scara_collab.bench.figures import canvas, save
from scara_collab.bench.markdown import md_table, mm, num, quote
from scara_collab.bench.sections.base import Rows, Section
from scara_collab.bench.util import Progress

CONTROLLERS = {'pid': "PID (seeds' gains)", 'computed_torque': 'computed torque'}
COLOURS = {'pid': 'tab:red', 'computed_torque': 'tab:green'}


@dataclass(frozen=True)
class Sizes:
    """How much of the payload and simulator-speed studies runs."""

    payloads: Tuple[float, ...] = (0.0, 1.0, 2.5)
    settle: float = 2.0              # s observed after the move, computed torque
    pid_settle: float = 10.0         # s observed after the move, PID
    speed_items: Tuple[int, ...] = (0, 5, 10)
    speed_modes: Tuple[str, ...] = ('computed_torque', 'pid')
    speed_seconds: float = 3.0
    speed_repeat: int = 3


def measure(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    """Run the payload study, with the simulator's speed under ``'speed'``."""
    out = physics.payload_study(payloads=sizes.payloads, settle=sizes.settle,
                                pid_settle=sizes.pid_settle, log=progress.note)
    out['speed'] = physics.speed_study(items=sizes.speed_items, modes=sizes.speed_modes,
                                       seconds=sizes.speed_seconds, repeat=sizes.speed_repeat,
                                       log=progress.note)
    return out


def summary(pay: dict) -> Rows:
    """Return the summary row: settling time per payload, both controllers."""
    ct = [r for r in pay['rows'] if r['mode'] == 'computed_torque']
    pid = [r for r in pay['rows'] if r['mode'] == 'pid']
    settle = [r['settling'] for r in ct]
    return [('payload 0 / 1 / 2.5 kg: settling to 1 mm', '0.45 / 0.72 / 1.15 s',
             'computed torque: ' + ' / '.join(
                 num(x, 2, 's') if x is not None else 'never' for x in settle)
             + "; PID (seeds' gains): " + ' / '.join(
                 num(r['settling'], 2, 's') if r['settling'] is not None
                 else f'not in {r["window"]:g} s' for r in pid), '', '')]


def markdown(pay: dict, results: dict) -> str:
    """Return the section's text: the claim, every payload and controller, what settles."""
    rows = []
    for r in pay['rows']:
        claim = PAYLOAD_CLAIMS.get(float(r['payload']))
        settle = num(r['settling'], 3, 's') if r['settling'] is not None \
            else f'not within {r["window"]:g} s'
        rows.append((f'{r["payload"]:g} kg', CONTROLLERS[r['mode']], settle,
                     ', '.join(f'{v:.1f}' for v in r['peak']), f'{r["overshoot"]:.2f} %',
                     mm(r['tool_err']), mm(r['final']),
                     f'{claim[0]} s, {claim[1]} N·m, {claim[2]} %' if claim else ''))
    start, goal = pay['line']
    dur = pay['rows'][0]['duration'] if pay['rows'] else float('nan')
    return '\n\n'.join([
        quote('payload'),
        f'A planned straight line {tuple(start)} → {tuple(goal)} m (`{pay["arm"]}`, 1.5 m, '
        f'{dur:.2f} s time-optimal) executed in the PyBullet cell with the payload hung on the '
        "tool (a fixed constraint, so physics feels it), by the seeds' PID gains (planar "
        '15/0.5/2, quill 10/0.1/1) and by computed torque (the Lagrangian model as '
        'feed-forward). Settling: time after the trajectory ends until the tool stays within '
        f'{mm(pay["settle_tolerance_m"], 2)} of the goal. Overshoot: furthest tool travel past '
        'the goal along the line, % of the line. Peak effort is the largest commanded joint '
        'effort over the run (N·m, N·m, N).',
        md_table(('payload', 'controller', 'settling to 1 mm', 'peak effort θ1, θ2, quill',
                  'overshoot', 'max tool error vs plan', 'final error', "seeds' claim "
                  '(settle, peak torque, overshoot)'), rows, 'llrlrrrl'),
        _settled(pay)])


def _settled(pay: dict) -> str:
    text = []
    for mode, name in (('pid', "With the seeds' PID gains"),
                       ('computed_torque', 'With computed torque')):
        runs = [r for r in pay['rows'] if r['mode'] == mode]
        if not runs:
            continue
        settled = [r for r in runs if r['settling'] is not None]
        text.append(
            f'{name}, {len(settled)} of {len(runs)} runs settle within their window; the '
            f'largest tool error against the plan is {mm(max(r["tool_err"] for r in runs))} '
            f'and the largest quill error {mm(max(r["joint_err"][2] for r in runs))}.')
    return ' '.join(text)


def figure(data: dict, path: Path) -> None:
    """Tool distance from the goal over time, PID vs computed torque, per payload."""
    fig, ax = canvas(8.0, 3.6)
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
    save(fig, path)


SECTION = Section(
    key='payload', title='payload response and simulator speed',
    heading='Payload response: PID vs computed torque', measure=measure, markdown=markdown,
    summary=summary, figure=figure,
    figure_alt='distance to the goal over time, per payload', full=Sizes(),
    smoke=Sizes(settle=0.2, pid_settle=0.5, speed_items=(0,), speed_modes=('computed_torque',),
                speed_seconds=0.5, speed_repeat=1))
