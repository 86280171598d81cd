"""Section 5, singularity: the seeds' loop with the pseudo-inverse and with DLS, and the planner.

The measurement is :func:`scara_collab.bench.singularity.measure`; this module is its summary
row, its Markdown and its figure.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from scara_collab.bench import singularity
from scara_collab.bench.claims import CLAIMS
from scara_collab.bench.figures import canvas, save
from scara_collab.bench.markdown import m, md_table, met, mm, num, quote
from scara_collab.bench.sections.base import Rows, Section
from scara_collab.bench.util import Progress


@dataclass(frozen=True)
class Sizes:
    """The time step of the differential-kinematics loop."""

    singularity_dt: float = 0.001    # s


def measure(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    """Run the study lines through the loop, and the planner's line."""
    return singularity.measure(sizes.singularity_dt, progress.note)


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
