"""The PyBullet cell alone: simulation speed, and payload tracking with PID vs computed torque.

1. :func:`sim_speed`: physics steps per second and real-time factor of the full cell (both
   arms shuttling on 1.5 m lines, control on, unthrottled, one core) with items on the belt.
2. :func:`tracking`: one planned 1.5 m straight line (``core.trajectory.line_move``) executed
   with a payload hung on the tool, by the seeds' PID gains or by computed torque: max
   tracking error (joints and tool), settling time (after the trajectory ends, until the tool
   stays within 1 mm of the goal), peak effort per joint, overshoot along the line (furthest
   tool travel past the goal, % of the line).
"""
import time
from typing import Dict, Iterable, Optional, Tuple

import numpy as np

from scara_collab.bench.util import Log
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
