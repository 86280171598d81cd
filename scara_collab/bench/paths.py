"""Section 1, path deviation: the seeds' 1.5 m move as a straight line and as a joint move.

The measurement is :func:`scara_collab.bench.paths.measure` (planned by the motion core,
executed in the PyBullet cell); this module is its summary rows, its Markdown and its figure.
"""
from pathlib import Path
import time
from typing import Dict, Optional

import numpy as np

from scara_collab.bench.claims import CLAIMS
from scara_collab.bench.util import (canvas, fmt_seconds, m, md_table, met, mm, num, Progress,
                                     quote, Rows, save, Section)
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.model import ArmModel, CellModel, load_cell
from scara_collab.core.trajectory import (joint_move, line_move, path_metrics, segment_deviation,
                                          Trajectory)
from scara_collab.sim.cell_sim import CellSim


ARRIVED = 1e-3  # m: an executed move has arrived once the tool stays this close to the goal
SEEDS_MOVE = (np.array([3.2, -0.9, 0.4]), np.array([2.0, 0.0, 0.4]))
"""The seeds' 1.5 m move, world frame (left arm): from a rest pose (tool 1.5 m from the
shoulder axis) to the conveyor centre line, 1.5 m long."""


def plan(arm: ArmModel, start=SEEDS_MOVE[0], goal=SEEDS_MOVE[1]) -> Dict[str, object]:
    """Plan ``start`` -> ``goal`` as a straight line and as a joint move.

    :return: ``{'line': Trajectory, 'joint': Trajectory, 'line_plan_time_s': float,
        'joint_plan_time_s': float}``.
    """
    qa = ik(arm, start).unwrap()
    qb = ik(arm, goal, q_current=qa).unwrap()
    t0 = time.perf_counter()
    line = line_move(arm, qa, goal)
    t1 = time.perf_counter()
    joint = joint_move(arm, qa, qb)
    t2 = time.perf_counter()
    return {'line': line, 'joint': joint, 'line_plan_time_s': t1 - t0,
            'joint_plan_time_s': t2 - t1}


def execute(cell: CellModel, arm: ArmModel, traj: Trajectory, settle: float = 0.3,
            control_mode: Optional[str] = None) -> Dict[str, object]:
    """Execute ``traj`` on ``arm`` in a fresh simulator; sample the state every ``traj`` step.

    :param settle: sim seconds observed after the trajectory ends.
    :return: ``{'traj': measured Trajectory (t from the start), 'reference': planned joint
        positions at the same times, 'tracking_error': (N,) tool distance from the planned
        tool, m}``.
    """
    sim_cfg = dict(load_config('simulation'), feed_interval=0.0)
    with CellSim(cell, sim_cfg, control_mode=control_mode) as sim:
        sim.reset_arm(arm.name, traj.q[0])
        t0 = sim.time
        sim.execute(arm.name, t0 + traj.t, traj.q, traj.qd, traj.qdd)
        every = max(1, int(round(float(np.median(np.diff(traj.t))) / sim.dt)))
        n = int(np.ceil((traj.duration + settle) / (every * sim.dt)))
        t, q, qd = np.empty(n + 1), np.empty((n + 1, 3)), np.empty((n + 1, 3))
        for k in range(n + 1):
            t[k] = sim.time - t0
            q[k], qd[k] = sim.arm_state(arm.name)
            sim.step(every)
    qdd = np.gradient(qd, t, axis=0)
    measured = Trajectory(t=t, q=q, qd=qd, qdd=qdd, p=fk(arm, q))
    reference = traj.sample(t)
    return {'traj': measured, 'reference': reference,
            'tracking_error': np.linalg.norm(measured.p - fk(arm, reference), axis=1)}


def measure_paths(cell: Optional[CellModel] = None, control_mode: Optional[str] = None,
                  start=SEEDS_MOVE[0], goal=SEEDS_MOVE[1]) -> Dict[str, object]:
    """Plan and execute the move both ways; return the metrics and the paths for a figure.

    :return: ``{'start', 'goal', 'control_mode', 'planned': {method: metrics},
        'executed': {method: metrics + end and tracking errors}, 'plan_time_s': {...},
        (an executed ``duration`` is the time until the tool stays within :data:`ARRIVED`
        of the goal, None if it never does),
        'series': {method: {'planned_p', 'executed_t', 'executed_p', 'executed_deviation',
        'planned_t', 'planned_deviation'}}}`` (metrics as plain dicts, series as arrays).
    """
    cell = cell or load_cell()
    arm = cell.leader
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    plans = plan(arm, start, goal)
    mode = control_mode or load_config('controllers')['control_mode']
    out: Dict[str, object] = {
        'arm': arm.name, 'start': start.tolist(), 'goal': goal.tolist(),
        'length_m': float(np.linalg.norm(goal - start)), 'control_mode': mode,
        'plan_time_s': {'line': plans['line_plan_time_s'], 'joint': plans['joint_plan_time_s']},
        'planned': {}, 'executed': {}, 'series': {}}
    for method in ('line', 'joint'):
        traj = plans[method]
        run = execute(cell, arm, traj, control_mode=mode)
        done = run['traj']
        planned = path_metrics(traj, start, goal).as_dict()
        executed = path_metrics(done, start, goal).as_dict()
        executed['end_error'] = float(np.linalg.norm(done.p[-1] - goal))
        away = np.nonzero(np.linalg.norm(done.p - goal, axis=1) > ARRIVED)[0]
        executed['duration'] = float(done.t[away[-1] + 1]) if away.size and \
            away[-1] + 1 < len(done.t) else (0.0 if not away.size else None)
        executed['max_tracking_error'] = float(run['tracking_error'].max())
        out['planned'][method] = planned
        out['executed'][method] = executed
        out['series'][method] = {
            'planned_t': traj.t, 'planned_p': traj.p,
            'planned_deviation': segment_deviation(traj.p, start, goal),
            'executed_t': done.t, 'executed_p': done.p,
            'executed_deviation': segment_deviation(done.p, start, goal)}
    return out


TARGETS = {
    'line_planned': 1e-6,          # m
    'line_executed': 1e-3,         # m
}
"""The SPEC's targets (``../shared/SPEC.md`` §5), as numbers."""
COLOURS = {'line': 'tab:blue', 'joint': 'tab:orange'}


def measure(sizes: None, progress: Progress, scratch: Path) -> dict:
    """Plan and execute the seeds' move both ways (the section has no sizes)."""
    return measure_paths()


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
