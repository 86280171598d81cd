"""Section 5, singularity: the seeds' loop with the pseudo-inverse and with DLS, and the planner.

The measurement is :func:`scara_collab.bench.singularity.measure`; this module is its summary
row, its Markdown and its figure.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Optional

import numpy as np

from scara_collab.bench.claims import CLAIMS
from scara_collab.bench.util import (canvas, Log, m, md_table, met, mm, num, Progress, quote, Rows,
                                     save, Section)
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import base_to_world, fk, ik, ik_both, IKError, manipulability
from scara_collab.core.model import ArmModel, load_cell
from scara_collab.core.trajectory import line_move, resolved_rate, segment_deviation


SPEED = 0.3  # m/s along every study line
GAIN = 5.0   # 1/s, the loop's position feedback
CASES = {
    'inner circle, tangent graze at 0.505 m': ((0.6, 0.505, 0.4), (-0.6, 0.505, 0.4)),
    'inner circle, radial approach to 0.5005 m': ((1.2, 0.0, 0.4), (0.5005, 0.0, 0.4)),
    'outer circle, radial approach to 2.5 m': ((1.5, 0.0, 0.4), (2.5, 0.0, 0.4)),
}
"""Study lines in the arm's base frame (m): start and end of the tool path."""
PLANNER_LINE = ((1.0, 0.85, 0.4), (-1.0, 0.85, 0.4))
"""The closest tangent graze of the inner circle that the joint limits allow (base frame)."""
FAR_TARGET = (3.0, 0.0, 0.4)
"""The seeds' target 3.0 m from the shoulder axis (base frame)."""


def study(arm: ArmModel, a, b, damping: float, threshold: float, dt: float = 0.001,
          speed: float = SPEED) -> Dict[str, object]:
    """Run the seeds' loop along ``a`` -> ``b`` (base frame) at ``speed``.

    :param damping: the DLS ``max_damping`` (0 = plain pseudo-inverse).
    :return: ``{'peak_speed' (rad/s, the faster of the two revolute joints),
        'peak_speed_joint', 'max_tool_error' (m), 'min_manipulability' (m^2),
        'elbow_deg_at_min' (|theta2| where the manipulability is smallest), 'series': {'s',
        'speed'}}``.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    duration = float(np.linalg.norm(b - a)) / speed
    s = np.linspace(0.0, 1.0, int(round(duration / dt)) + 1)
    p_ref = base_to_world(arm, a + s[:, None] * (b - a))
    v_ref = np.broadcast_to((b - a) / duration, p_ref.shape)
    q0 = ik_both(arm, p_ref[0])[0]
    qd = resolved_rate(arm, q0, p_ref, v_ref, dt, gain=GAIN, dls_threshold=threshold,
                       dls_max_damping=damping)
    q = q0 + np.cumsum(qd, axis=0) * dt
    speed_abs = np.abs(qd[:, :2]).max(axis=1)
    w = manipulability(arm, q)
    return {'peak_speed': float(speed_abs.max()),
            'peak_speed_joint': int(np.argmax(np.abs(qd[:, :2]).max(axis=0))) + 1,
            'max_tool_error': float(np.linalg.norm(fk(arm, q) - p_ref, axis=1).max()),
            'min_manipulability': float(w.min()),
            'elbow_deg_at_min': float(np.degrees(abs(q[int(np.argmin(w)), 1]))),
            'series': {'s': s, 'speed': speed_abs}}


def run_cases(dt: float = 0.001, log: Optional[Log] = None) -> Dict[str, object]:
    """Run every case with and without DLS, the planner's line and the far target.

    :param dt: the loop period, s.
    """
    arm = load_cell().leader
    traj_cfg = load_config('controllers')['trajectory']
    threshold, damping = float(traj_cfg['dls_threshold']), float(traj_cfg['dls_max_damping'])
    cases = []
    for name, (a, b) in CASES.items():
        if log:
            log(name)
        cases.append({'name': name, 'start': list(a), 'end': list(b),
                      'pinv': study(arm, a, b, 0.0, threshold, dt),
                      'dls': study(arm, a, b, damping, threshold, dt)})
    a, b = (base_to_world(arm, np.array(p)) for p in PLANNER_LINE)
    q0 = ik(arm, a).unwrap()
    line = line_move(arm, q0, b, dls_threshold=threshold, dls_max_damping=damping)
    planner = {'line': [list(p) for p in PLANNER_LINE],
               'peak_speed': float(np.abs(line.qd[:, :2]).max()),
               'duration': line.duration,
               'mean_speed': float(np.linalg.norm(b - a) / line.duration),
               'min_manipulability': float(manipulability(arm, line.q).min()),
               'max_elbow_deg': float(np.degrees(np.abs(line.q[:, 1]).max())),
               'damping_engaged': bool(manipulability(arm, line.q).min() < threshold),
               'max_deviation': float(segment_deviation(line.p, a, b).max())}
    a, b = (base_to_world(arm, np.array(p)) for p in CASES[
        'inner circle, radial approach to 0.5005 m'])
    try:
        line_move(arm, ik(arm, a).unwrap(), b)
        refused = 'accepted'
    except IKError as exc:
        refused = str(exc)
    far = ik(arm, base_to_world(arm, np.array(FAR_TARGET)))
    return {'cases': cases, 'planner': planner, 'planner_radial_inner': refused,
            'far_target': list(FAR_TARGET),
            'far_target_result': 'accepted' if far.ok else far.reasons(),
            'speed': SPEED, 'gain': GAIN, 'dt': dt, 'dls_threshold': threshold,
            'dls_max_damping': damping, 'velocity_limit': float(arm.max_velocity[0])}


@dataclass(frozen=True)
class Sizes:
    """The time step of the differential-kinematics loop."""

    singularity_dt: float = 0.001    # s


def measure(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    """Run the study lines through the loop, and the planner's line."""
    return run_cases(sizes.singularity_dt, progress.note)


def worst_inner(data: dict) -> Optional[dict]:
    """Return the radial case into the inner singularity (None if the study has none)."""
    for case in data['cases']:
        if 'inner' in case['name'] and 'radial' in case['name']:
            return case
    return None


def summary(sg: dict) -> Rows:
    """Return the summary row: peak joint speed into the inner singularity, both ways."""
    case = worst_inner(sg)
    if not case:
        return []
    return [("peak joint speed into the inner singularity (seeds' loop)",
             CLAIMS['singularity'].figure,
             f'pseudo-inverse {case["pinv"]["peak_speed"]:.3g} rad/s, DLS '
             f'{case["dls"]["peak_speed"]:.3g} rad/s; planner ≤ '
             f'{sg["planner"]["peak_speed"]:.3g} rad/s', '≤ 2 rad/s',
             met(case['dls']['peak_speed'] <= sg['velocity_limit'] + 1e-9))]


def markdown(sg: dict, results: dict) -> str:
    """Return the section's text: the claims, every study line both ways, the planner's line."""
    rows = []
    for c in sg['cases']:
        rows.append((c['name'], num(c['pinv']['min_manipulability'], 2, 'm²'),
                     f'{c["pinv"]["elbow_deg_at_min"]:.1f}°',
                     num(c['pinv']['peak_speed'], 3, 'rad/s'),
                     num(c['dls']['peak_speed'], 3, 'rad/s'),
                     mm(c['pinv']['max_tool_error'], 2), mm(c['dls']['max_tool_error'], 2),
                     CLAIMS['singularity'].figure if 'inner' in c['name'] else ''))
    pl = sg['planner']
    rows.append((f'planner: time-optimal line {tuple(pl["line"][0])} → {tuple(pl["line"][1])} '
                 '(the closest inner graze the ±150° limit allows)',
                 num(pl['min_manipulability'], 2, 'm²'), f'{pl["max_elbow_deg"]:.1f}°', '',
                 f'{pl["peak_speed"]:.3g} rad/s ('
                 f'{"DLS engaged" if pl["damping_engaged"] else "no damping needed"})', '',
                 f'{m(pl["max_deviation"], 2)} (planned)', ''))
    return '\n\n'.join([
        quote('singularity', 'unreachable', 'peak_velocity'),
        f'Straight lines (base frame of `scara_left`) at {sg["speed"]} m/s through the seeds\' '
        f'differential-kinematics loop at {1 / sg["dt"]:.0f} Hz '
        f'(`core.trajectory.resolved_rate`, position feedback {sg["gain"]:g}/s), once with the '
        'plain pseudo-inverse, once with DLS (damping up to '
        f'{sg["dls_max_damping"]} m below manipulability {sg["dls_threshold"]} m²). The inner '
        "cases need elbow angles beyond the arm's ±150° limit: they test the solver where the "
        'seeds put their claim, not a move the cell can make.',
        md_table(('path', 'smallest manipulability', 'elbow angle there', 'peak speed, '
                  'pseudo-inverse', 'peak speed, DLS', 'off the line, pseudo-inverse',
                  'off the line, DLS', "seeds' claim"), rows, 'lrrrrrrl'),
        _limits(sg),
        f'The line into the inner circle, given to the planner: *{sg["planner_radial_inner"]}*. '
        f'IK on the seeds\' target 3.0 m from the shoulder axis: *{sg["far_target_result"]}* '
        '(seeds: "rejected the command immediately").'])


def _limits(sg: dict) -> str:
    lim = sg['velocity_limit']
    over = [c['name'] for c in sg['cases'] if c['pinv']['peak_speed'] > lim]
    under = [c['name'] for c in sg['cases'] if c['pinv']['peak_speed'] <= lim]
    dls_over = [c['name'] for c in sg['cases'] if c['dls']['peak_speed'] > lim]
    text = []
    if under:
        text.append('Undamped, the joint speeds stay under the limit on: ' + '; '.join(under)
                    + ' (a tangent graze asks for no radial motion where it is closest).')
    if over:
        text.append('The pseudo-inverse exceeds the limit on: ' + '; '.join(over) + '.')
    text.append('DLS keeps every case under the limit.' if not dls_over else
                'DLS still exceeds the limit on: ' + '; '.join(dls_over) + '.')
    text.append('DLS pays with the distance off the line shown. The planner does not rely on '
                'damping for the 2 rad/s limit: it times each path so that no joint exceeds it '
                f'(peak {sg["planner"]["peak_speed"]:.3g} rad/s on its line).')
    return ' '.join(text)


def figure(data: dict, path: Path) -> None:
    """Peak revolute joint speed along each study path, pseudo-inverse vs DLS."""
    fig, ax = canvas(8.0, 3.6)
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
    save(fig, path)


SECTION = Section(
    key='singularity', title='singularity: pseudo-inverse vs DLS',
    heading='Singularity: pseudo-inverse vs damped least squares', measure=measure,
    markdown=markdown, summary=summary, figure=figure,
    figure_alt='joint speed along the study paths', full=Sizes(),
    smoke=Sizes(singularity_dt=0.01))
