"""Section 3, payload response: PID (design documents' gains) vs computed torque, 1.5 m line."""
from pathlib import Path

import numpy as np

from benchmarks.claims import CLAIMS, PAYLOAD_CLAIMS
from benchmarks.util import axes, finish, mm, num, Rows, table
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.model import CellModel, load_cell
from scara_collab.core.trajectory import line_move
from scara_collab.sim.cell_sim import CellSim
from scara_collab.sim.reference import HermiteReference

LINES = {'scara_left': ((3.3, -0.8, 0.5), (1.8, -0.8, 0.5)),
         'scara_right': ((3.3, 0.8, 0.5), (1.8, 0.8, 0.5))}
"""A 1.5 m line along x for each arm, clear of the belt (|y| > 0.5), tool 0.5 m up."""
SETTLED = 1e-3  # m: settled = the tool stays this close to the goal
CONTROLLERS = {'pid': "PID (design documents' gains)", 'computed_torque': 'computed torque'}


def tracking(cell: CellModel, mode: str, payload: float, settle: float) -> dict:
    """Run the left arm's line with ``payload`` kg by ``mode``, ``settle`` s more; the metrics."""
    arm = cell.leader
    start, goal = (np.array(p) for p in LINES[arm.name])
    with CellSim(cell, dict(load_config('simulation'), feed_interval=0.0),
                 control_mode=mode) as sim:
        q0 = ik(arm, start).q
        sim.reset_arm(arm.name, q0)
        if payload > 0:  # a small dense cube, so a sagging quill does not put it on the floor
            sim.grippers.attach_payload(arm.name, payload, size=0.05)
        traj = line_move(arm, q0, goal)
        t0 = sim.time
        sim.execute(arm.name, t0 + traj.t, traj.q, traj.qd, traj.qdd)
        ref = HermiteReference(t0 + traj.t, traj.q, traj.qd, traj.qdd)
        n = int(round((traj.duration + settle) / sim.dt))
        times, qs, efforts = np.empty(n), np.empty((n, 3)), np.empty((n, 3))
        for k in range(n):
            state = sim.joint_state()   # the state the servo sees at this tick
            times[k], qs[k], efforts[k] = sim.time, state.position[:3], state.effort[:3]
            sim.step(1)
        efforts = np.vstack([efforts[1:], sim.joint_state().effort[:3]])  # torque of tick k
    q_ref = np.array([ref.sample(t)[0] for t in times])
    tips = fk(arm, qs)
    to_goal = np.linalg.norm(tips - goal, axis=1)
    outside = np.nonzero(to_goal > SETTLED)[0]
    last = outside[-1] + 1 if outside.size else 0  # the first tick from which it stays settled
    settling = max(0.0, float(times[last] - t0 - traj.duration)) if last < n else None
    length = np.linalg.norm(goal - start)
    along = (tips - goal) @ ((goal - start) / length)
    every = max(1, int(round(0.01 / sim.dt)))
    return {'mode': mode, 'payload': payload, 'window': settle, 'duration': traj.duration,
            'quill_err': float(np.abs(qs[:, 2] - q_ref[:, 2]).max()),
            'tool_err': float(np.linalg.norm(tips - fk(arm, q_ref), axis=1).max()),
            'settling': settling, 'final': float(to_goal[-1]),
            'peak': np.abs(efforts).max(axis=0),
            'overshoot': float(max(0.0, along.max()) / length * 100.0),
            't': times[::every] - t0, 'to_goal': to_goal[::every]}


PAYLOADS = (0.0, 1.0, 2.5)  # kg in the gripper


def measure(smoke: bool, scratch: Path) -> dict:
    """Run :func:`tracking` for every payload with both controllers."""
    cell, windows = load_cell(), {'pid': 10.0, 'computed_torque': 2.0}  # s after the move
    return {'rows': [tracking(cell, mode, payload, window / 20 if smoke else window)
                     for payload in PAYLOADS for mode, window in windows.items()]}


def _settling(r: dict) -> str:
    return num(r['settling'], 3, 's') if r['settling'] is not None \
        else f'not within {r["window"]:g} s'


def tables(pay: dict) -> list:
    """Return every payload and controller."""
    rows = []
    for r in pay['rows']:
        claim = PAYLOAD_CLAIMS.get(float(r['payload']))
        rows.append({
            'payload': f'{r["payload"]:g} kg', 'controller': CONTROLLERS[r['mode']],
            'line (planned)': num(r['duration'], 3, 's'), 'settling to 1 mm': _settling(r),
            'peak effort θ1, θ2, quill': ', '.join(f'{v:.1f}' for v in r['peak']),
            'overshoot': f'{r["overshoot"]:.2f} %', 'max tool error vs plan': mm(r['tool_err']),
            'max quill error': mm(r['quill_err']), 'final error': mm(r['final']),
            "design documents' claim (settle, peak torque, overshoot)":
                f'{claim[0]} s, {claim[1]} N·m, {claim[2]} %' if claim else ''})
    return [table(rows, 'lllrlrrrrl')]


def summary(pay: dict) -> Rows:
    """Return the summary row: settling time per payload, both controllers."""
    by_mode = {mode: ' / '.join(_settling(r) for r in pay['rows'] if r['mode'] == mode)
               for mode in CONTROLLERS}
    return [('payload 0 / 1 / 2.5 kg: settling to 1 mm', CLAIMS['payload'].figure,
             f'computed torque: {by_mode["computed_torque"]}; PID (design documents\' gains): '
             f'{by_mode["pid"]}', '', '')]


def figure(pay: dict):
    """Tool distance from the goal over time, PID vs computed torque, per payload."""
    fig, (ax,) = axes(8.0, 3.6)
    styles = dict(zip(sorted({r['payload'] for r in pay['rows']}), ('-', '--', ':', '-.')))
    for r in pay['rows']:
        ax.semilogy(r['t'], np.maximum(r['to_goal'], 1e-6) * 1e3, styles[r['payload']],
                    color='tab:red' if r['mode'] == 'pid' else 'tab:green',
                    label=f'{CONTROLLERS[r["mode"]]}, {r["payload"]:g} kg')
    ax.axvline(pay['rows'][0]['duration'], color='0.5', lw=0.8)
    finish(ax, 'time from start (s)', 'tool to goal (mm)',
           '1.5 m line with a payload: distance to the goal (the grey line: trajectory ends)',
           {1.0: '1 mm'})
    return fig
