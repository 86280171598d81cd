"""Section 1, path deviation: the design documents' 1.5 m move, as a line and as a joint move."""
from pathlib import Path
import time

import numpy as np

from benchmarks.claims import CLAIMS
from benchmarks.util import axes, finish, fmt_seconds, met, mm, num, Rows, table
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.model import ArmModel, CellModel, load_cell
from scara_collab.core.trajectory import (joint_move, line_move, path_metrics, segment_deviation,
                                          Trajectory)
from scara_collab.sim.cell_sim import CellSim

ARRIVED = 1e-3  # m: an executed move has arrived once the tool stays this close to the goal
START, GOAL = np.array([3.2, -0.9, 0.4]), np.array([2.0, 0.0, 0.4])
"""The design documents' 1.5 m move, world frame (left arm): rest pose to the belt centre line."""
METHODS = {'joint': 'joint interp.', 'line': 'straight line'}


def execute(cell: CellModel, arm: ArmModel, traj: Trajectory, settle: float = 0.3) -> dict:
    """Execute ``traj`` in a fresh simulator, ``settle`` s more; return its path metrics."""
    with CellSim(cell, dict(load_config('simulation'), feed_interval=0.0)) as sim:
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
    done = Trajectory(t=t, q=q, qd=qd, qdd=np.gradient(qd, t, axis=0), p=fk(arm, q))
    out = path_metrics(done, START, GOAL).as_dict()
    away = np.nonzero(np.linalg.norm(done.p - GOAL, axis=1) > ARRIVED)[0]
    last = away[-1] + 1 if away.size else 0  # the first sample from which it stays there
    arrived = float(t[last]) if last < len(t) else None
    out.update(end_error=float(np.linalg.norm(done.p[-1] - GOAL)), duration=arrived,
               tracking_error=float(np.linalg.norm(done.p - fk(arm, traj.sample(t)),
                                                   axis=1).max()),
               t=t, p=done.p, deviation=segment_deviation(done.p, START, GOAL))
    return out


def measure(smoke: bool, scratch: Path) -> dict:
    """Plan the move both ways (timed), execute each; ``{'planned'|'executed': {method: …}}``."""
    cell = load_cell()
    arm = cell.leader
    qa = ik(arm, START).unwrap()
    out = {'planned': {}, 'executed': {}}
    for method in METHODS:
        t0 = time.perf_counter()
        traj = line_move(arm, qa, GOAL) if method == 'line' else \
            joint_move(arm, qa, ik(arm, GOAL, q_current=qa).unwrap())
        took = time.perf_counter() - t0
        out['planned'][method] = dict(path_metrics(traj, START, GOAL).as_dict(), plan_time=took,
                                      t=traj.t, p=traj.p,
                                      deviation=segment_deviation(traj.p, START, GOAL))
        out['executed'][method] = execute(cell, arm, traj)
    return out


ROWS = (  # metric, key, format, design documents' claim
    ('largest distance from the straight segment', 'max_deviation', mm,
     'joint 0.385 m; line < 0.001 m'),
    ('tool path length', 'path_length', lambda x: num(x, 4, 'm'), 'line 14 % shorter'),
    ('duration: planned (time-optimal) / executed (until within 1 mm of the goal)', 'duration',
     lambda x: num(x, 3, 's'), ''),
    ('peak joint speed θ1, θ2 (rad/s)', 'peak_speed', lambda x: f'{x[0]:.2f}, {x[1]:.2f}', ''),
    ('RMS tool jerk (m/s³)', 'rms_jerk', num, 'joint high, line low'),
    ('end error', 'end_error', mm, ''),
    ('largest tool error against the plan', 'tracking_error', mm, ''),
    ('planning time', 'plan_time', fmt_seconds, ''))


def tables(p: dict) -> list:
    """Return the table of both moves, planned and executed."""
    rows = []
    for label, key, fmt, claim in ROWS:
        row = {'metric': label}
        for method, name in METHODS.items():
            for kind in ('planned', 'executed'):
                value = p[kind][method].get(key)
                row[f'{name}, {kind}'] = '' if value is None else fmt(value)
        rows.append(dict(row, **{"design documents' claim": claim}))
    return [table(rows)]


def summary(p: dict) -> Rows:
    """Return the summary rows: deviation of both moves, path length saved."""
    pl, ex = p['planned'], p['executed']
    saved = 1 - pl['line']['path_length'] / pl['joint']['path_length']
    lp, le = pl['line']['max_deviation'], ex['line']['max_deviation']
    return [
        ("straight line, design documents' 1.5 m move: deviation planned / executed",
         CLAIMS['line_deviation'].figure, f'{num(lp, 2, "m")} / {mm(le)}',
         '≤ 1e-6 m / ≤ 1 mm', met(lp <= 1e-6 and le <= 1e-3)),
        ('joint interpolation, same move: deviation planned / executed',
         CLAIMS['joint_deviation'].figure,
         f'{num(pl["joint"]["max_deviation"], 3, "m")} / '
         f'{num(ex["joint"]["max_deviation"], 3, "m")}', 'reported', ''),
        ('path length saved by the line', CLAIMS['path_length'].figure, f'{saved * 100:.1f} %',
         '', '')]


def figure(p: dict):
    """Plan view of both paths (planned and executed) and their deviation from the line."""
    fig, (ax, ax2) = axes(9.5, 4.0, 2)
    ax.plot([START[0], GOAL[0]], [START[1], GOAL[1]], color='0.6', lw=6, alpha=0.35,
            label='straight segment')
    for (method, name), colour in zip(METHODS.items(), ('tab:orange', 'tab:blue')):
        for kind, style in (('planned', '--'), ('executed', '-')):
            s = p[kind][method]
            ax.plot(s['p'][:, 0], s['p'][:, 1], style, color=colour, label=f'{name}, {kind}')
            ax2.semilogy(s['t'], np.maximum(s['deviation'], 1e-9) * 1e3, style, color=colour)
    ax.set_aspect('equal', adjustable='datalim')
    finish(ax, 'x (m)', 'y (m)', '1.5 m move to the belt centre, tool path seen from above')
    ax2.set_ylim(1e-6, 1e3)
    finish(ax2, 'time from start (s)', 'distance from the straight segment (mm)',
           'deviation from the line (1e-6 mm floor)', {1.0: '1 mm'})
    return fig
