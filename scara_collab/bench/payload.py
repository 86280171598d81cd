"""Section 3, payload response: PID vs computed torque on a 1.5 m line, and simulator speed.

The measurements are :func:`scara_collab.bench.payload.payload_study` and
:func:`scara_collab.bench.payload.speed_study` (the simulator's speed is printed in section 7,
beside the whole graph's); this module is their summary row, Markdown and figure.
"""
from dataclasses import dataclass
from pathlib import Path
import time
from typing import Dict, Iterable, Optional, Tuple

import numpy as np

from scara_collab.bench.claims import PAYLOAD_CLAIMS
from scara_collab.bench.util import (canvas, Log, md_table, mm, num, Progress, quote, Rows, save,
                                     Section)
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.model import CellModel, load_cell
from scara_collab.core.trajectory import line_move
from scara_collab.sim.cell_sim import CellSim
from scara_collab.sim.reference import HermiteReference


LINES = {'scara_left': ((3.3, -0.8, 0.5), (1.8, -0.8, 0.5)),
         'scara_right': ((3.3, 0.8, 0.5), (1.8, 0.8, 0.5))}
"""A 1.5 m line along x for each arm, clear of the belt (|y| > 0.5), tool 0.5 m up."""
PAYLOAD_SIZE = 0.05  # m: a small dense cube, so a sagging quill does not put it on the floor
SETTLE_TOLERANCE = 1e-3  # m: settled = the tool stays this close to the goal
MODES = ('pid', 'computed_torque')


def sim_config(servo_rate: Optional[float] = None) -> dict:
    """Return ``simulation.yaml`` with the item feed off (and ``servo_rate`` if given)."""
    cfg = dict(load_config('simulation'), feed_interval=0.0)
    if servo_rate:
        cfg['servo_rate'] = float(servo_rate)
    return cfg


def sim_speed(cell: CellModel, mode: str, n_items: int, seconds: float,
              servo_rate: Optional[float] = None) -> Tuple[float, float, int]:
    """Measure steps per second with both arms shuttling and ``n_items`` on the belt.

    Each leg is a two-point cubic from the measured position to the other end of the arm's
    line (joint space, 75 % of the velocity limit), so it is valid whatever the tracking.

    :return: ``(steps per wall second, real-time factor, items still alive)``.
    """
    with CellSim(cell, sim_config(servo_rate), control_mode=mode) as sim:
        ends = {}
        for arm in cell.arms:
            ends[arm.name] = [ik(arm, np.array(p)).q for p in LINES[arm.name]]
            sim.reset_arm(arm.name, ends[arm.name][0])
        belt = cell.belt
        for k in range(n_items):
            sim.spawn_item(x=belt.x_start + 0.1 + 0.4 * k)
        steps = int(round(seconds / sim.dt))
        leg = {name: 1 for name in ends}
        start = time.perf_counter()
        done = 0
        while done < steps:
            for arm in cell.arms:
                if not sim.active(arm.name):
                    q_now = sim.arm_state(arm.name)[0]
                    goal = ends[arm.name][leg[arm.name] % 2]
                    span = 1.5 * np.max(np.abs(goal - q_now) / (0.75 * arm.max_velocity))
                    sim.execute(arm.name, sim.time + np.array([0.0, max(span, 0.1)]),
                                [q_now, goal])
                    leg[arm.name] += 1
            sim.step(10)
            done += 10
        wall = time.perf_counter() - start
        alive = len(sim.items())
    return done / wall, done * sim.dt / wall, alive


def speed_study(cell: Optional[CellModel] = None, items: Iterable[int] = (0, 5, 10),
                modes: Iterable[str] = ('computed_torque', 'pid'), seconds: float = 3.0,
                repeat: int = 3, servo_rate: Optional[float] = None,
                log: Optional[Log] = None) -> Dict[str, object]:
    """Run :func:`sim_speed` ``repeat`` times per case; keep the median run.

    :return: ``{'rows': [{'items', 'mode', 'steps_per_s', 'rtf'}], 'seconds', 'repeat',
        'physics_rate', 'servo_rate', 'solver_iterations'}``.
    """
    cell = cell or load_cell()
    cfg = sim_config(servo_rate)
    rows = []
    for n_items in items:
        for mode in modes:
            if log:
                log(f'simulator speed: {mode}, {n_items} items ({repeat} x {seconds:g} s)')
            runs = sorted(sim_speed(cell, mode, n_items, seconds, servo_rate)
                          for _ in range(repeat))
            sps, rtf, _ = runs[len(runs) // 2]
            rows.append({'items': n_items, 'mode': mode, 'steps_per_s': sps, 'rtf': rtf})
    return {'rows': rows, 'seconds': seconds, 'repeat': repeat,
            'physics_rate': float(cfg['physics_rate']), 'servo_rate': float(cfg['servo_rate']),
            'solver_iterations': int(cfg['solver_iterations'])}


def tracking(cell: CellModel, mode: str, payload: float, settle: float) -> Dict[str, object]:
    """Run the left arm's line with ``payload`` kg on the tool; return the metrics.

    :param mode: ``'pid'`` (the seeds' gains) or ``'computed_torque'``.
    :param settle: sim seconds observed after the trajectory ends.
    :return: ``{'duration', 'joint_err' (3,), 'tool_err', 'settling' (s or None if not
        within the window), 'final', 'peak' (3,), 'overshoot' (%), 'window', 'series':
        {'t', 'tool_err', 'to_goal'} at 100 Hz}``.
    """
    arm = cell.leader
    start, goal = (np.array(p) for p in LINES[arm.name])
    with CellSim(cell, sim_config(), control_mode=mode) as sim:
        q0 = ik(arm, start).q
        sim.reset_arm(arm.name, q0)
        if payload > 0:
            sim.grippers.attach_payload(arm.name, payload, size=PAYLOAD_SIZE)
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
    tips, tips_ref = fk(arm, qs), fk(arm, q_ref)
    tool_err = np.linalg.norm(tips - tips_ref, axis=1)
    to_goal = np.linalg.norm(tips - goal, axis=1)
    t_end = t0 + traj.duration
    outside = np.nonzero(to_goal > SETTLE_TOLERANCE)[0]
    if len(outside) == 0:
        settling = 0.0
    elif outside[-1] == n - 1:
        settling = None  # not within 1 mm at the end of the window
    else:
        settling = max(0.0, float(times[outside[-1] + 1] - t_end))
    length = np.linalg.norm(goal - start)
    along = (tips - goal) @ ((goal - start) / length)
    every = max(1, int(round(0.01 / (times[1] - times[0])))) if n > 1 else 1
    return {
        'mode': mode, 'payload': payload, 'window': settle,
        'duration': traj.duration,
        'joint_err': np.abs(qs - q_ref).max(axis=0),
        'tool_err': float(tool_err.max()),
        'settling': settling,
        'final': float(to_goal[-1]),
        'peak': np.abs(efforts).max(axis=0),
        'overshoot': float(max(0.0, along.max()) / length * 100.0),
        'series': {'t': times[::every] - t0, 'tool_err': tool_err[::every],
                   'to_goal': to_goal[::every]},
    }


def payload_study(cell: Optional[CellModel] = None, payloads: Iterable[float] = (0.0, 1.0, 2.5),
                  settle: float = 2.0, pid_settle: float = 10.0,
                  log: Optional[Log] = None) -> Dict[str, object]:
    """Run :func:`tracking` for every payload with both controllers.

    :param settle: observation window after the move for computed torque, s.
    :param pid_settle: the same for PID (much slower to settle, if at all), s.
    :return: ``{'rows': [tracking dicts], 'line': (start, goal), 'arm'}``.
    """
    cell = cell or load_cell()
    rows = []
    for payload in payloads:
        for mode in MODES:
            if log:
                log(f'payload {payload:g} kg, {mode}')
            rows.append(tracking(cell, mode, payload, pid_settle if mode == 'pid' else settle))
    arm = cell.leader
    return {'rows': rows, 'arm': arm.name, 'line': [list(p) for p in LINES[arm.name]],
            'settle_tolerance_m': SETTLE_TOLERANCE}


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
    out = payload_study(payloads=sizes.payloads, settle=sizes.settle,
                        pid_settle=sizes.pid_settle, log=progress.note)
    out['speed'] = speed_study(items=sizes.speed_items, modes=sizes.speed_modes,
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
